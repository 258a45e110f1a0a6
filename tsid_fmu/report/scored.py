"""What a study scores and starts from, in words: its experiments' windows and initial states."""

from __future__ import annotations

from tsid_fmu.result import IdentificationResult
from tsid_fmu.study.schema import IDENTIFY

__all__ = ["experiment_notes", "initial_note", "per_experiment_note", "windows_note"]


def windows_note(result: IdentificationResult) -> str:
    """Return a sentence naming the time windows each experiment scores ("" if none)."""
    parts = []
    for e in result.study.experiments if result.study is not None else ():
        if not (e.windows or e.warmup):
            continue
        spans = ", ".join(f"{a:g} to {b:g} s" for a, b in e.windows) or "the whole record"
        warm = e.warmup if isinstance(e.warmup, list) else [e.warmup]
        extra = f", after a warm-up of {', '.join(f'{w:g}' for w in warm)} s" if any(warm) else ""
        weights = (
            f", weights {', '.join(f'{w:g}' for w in e.window_weights)}" if e.window_weights else ""
        )
        parts.append(f"{e.name}: {spans}{extra}{weights}")
    if not parts:
        return ""
    return (
        "Scored time windows (shaded in the figures; the whole record is simulated, the "
        "fit, the noise and the residual diagnostics use the scored samples only): "
        + "; ".join(parts)
        + "."
    )


def initial_note(result: IdentificationResult) -> str:
    """Return a sentence naming the initial states set from the data ("" if none)."""
    parts = [
        f"{e.name}: " + ", ".join(f"{k} ({v})" for k, v in mine.items())
        for e in (result.study.experiments if result.study is not None else ())
        if (mine := {k: v for k, v in e.initial.items() if v != IDENTIFY})
    ]
    if not parts:
        return ""
    return "Initial states set from the record's first sample: " + "; ".join(parts) + "."


def per_experiment_note(result: IdentificationResult) -> str:
    """Return a sentence naming the per-experiment parameters and their copies ("" if none)."""
    copies = result.study.copies if result.study is not None else []
    by_variable: dict[str, list[str]] = {}
    for c in copies:
        by_variable.setdefault(c.variable, []).append(c.name)
    if not by_variable:
        return ""
    parts = [f"{v} ({', '.join(names)})" for v, names in by_variable.items()]
    return (
        "Identified per experiment (one row each in the parameter table): "
        + "; ".join(parts)
        + ". The arrays ran over the shared parameters with these held at the centre of "
        "their first levels; the least-squares refinement moved them with the shared ones "
        "over every experiment's residuals, and their intervals come from that joint fit."
    )


def experiment_notes(result: IdentificationResult) -> list[str]:
    """Return the notes on the experiments' windows, initial states and own parameters."""
    notes = (windows_note(result), initial_note(result), per_experiment_note(result))
    return [n for n in notes if n]

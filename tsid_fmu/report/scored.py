"""What a study scores and starts from, in words: its experiments' windows and initial states."""

from __future__ import annotations

from tsid_fmu.result import IdentificationResult

__all__ = ["experiment_notes", "initial_note", "windows_note"]


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
        f"{e.name}: " + ", ".join(f"{k} ({v})" for k, v in e.initial.items())
        for e in (result.study.experiments if result.study is not None else ())
        if e.initial
    ]
    if not parts:
        return ""
    return "Initial states set from the record's first sample: " + "; ".join(parts) + "."


def experiment_notes(result: IdentificationResult) -> list[str]:
    """Return the notes on the experiments' windows and initial states (none if neither)."""
    return [n for n in (windows_note(result), initial_note(result)) if n]

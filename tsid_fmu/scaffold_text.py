"""The text of the study ``tsid init`` writes: paths as written, windows, initial states, method."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

__all__: list[str] = []


def _window_hint(first: float, last: float) -> list[str]:
    """Commented keys that score only parts of the record (README, "Time windows")."""
    start = first + 0.1 * (last - first)
    return [
        "# to score only parts of the record (skip a start-up the model does not describe),",
        "# uncomment; the whole record is still simulated from its start:",
        f"# windows = [[{start:.6g}, {last:.6g}]]  # seconds; in time order, not overlapping",
        "# warmup = 0.0            # seconds at each window's start simulated, not scored",
        "# window_weights = [1.0]  # one weight per window",
    ]


def _initial_hint(states: list[str], outputs: Mapping[str, str]) -> list[str]:
    """Commented ``initial`` key: states set from the data's first sample (README)."""
    compared = [s for s in states if s in outputs]
    value = (
        ", ".join(f'{s} = "from_data"' for s in compared)
        if compared
        else 'STATE = "from_data:COLUMN"'
    )
    state = compared[0] if compared else "STATE"
    return [
        "# to start a state (or the parameter that sets it, such as x0) at the data's first",
        '# sample, uncomment ("from_data": the column the state is compared with):',
        f"# initial = {{ {value} }}",
        "# or identify its start in each experiment (one value per experiment, beside the",
        "# shared parameters), with its range given in [parameters]:",
        f'#   initial = {{ {state} = "identify" }}',
        f"#   [parameters] {state} = {{ levels = [LOW, MID, HIGH] }}",
    ]


def _method_lines(array: str, count: int, n: int) -> list[str]:
    """Return the study's ``[method]`` table and the commented ``[design]`` hint."""
    return [
        "",
        "[method]",
        f'array = "{array}"      # the smallest standard array for {count} '
        f"{'five' if n == 5 else 'three'}-level factors",
        'cost = "sse"         # sum of squared errors ...',
        'weighting = "noise"  # ... each output weighted by 1/noise², noise from the data',
        "replicates = 1       # no input-noise replicates",
        "# sampled intervals beside the profile ones, a check that does not linearise:",
        "# re-fits (about 5 simulations each) to a block bootstrap of the residuals",
        '# uncertainty = "bootstrap"   # or "monte_carlo": noise from their AR model',
        "# uncertainty_replicates = 100",
        "",
        "# what to measure next: tsid design STUDY --result DIR proposes the input that",
        "# determines what these data leave open, inside the limits the rig can apply",
        "# [design]",
        "# inputs = { INPUT = [-1.0, 1.0] }  # [min, max]; default: the range the data applied",
        "# band = [0.1, 10.0]                # Hz; default 2 periods a record to 1/20 of the rate",
        '# kinds = ["steps", "chirp", "multisine", "prbs"]',
        "",
    ]


def _as_written(path: Path, base: Path) -> Path:
    """``path`` as a person would write it in a file in ``base``.

    Relative where it lies in ``base``'s tree or one or two folders up (a study beside
    its data); absolute where the relative path would climb further (``../../../``).
    """
    path = path.resolve()
    try:
        rel = Path(os.path.relpath(path, base))
    except ValueError:  # another drive on Windows
        return path
    return path if rel.parts[:3] == ("..", "..", "..") else rel

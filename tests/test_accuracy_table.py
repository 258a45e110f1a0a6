"""The accuracy table of docs/benchmarks/accuracy.md: its fast rows reproduce (issue 27).

``python benchmarks/accuracy.py local_minima --de-budget 1000 --markdown`` (the lightly
damped resonance: every method on it runs in about 40 s on 2 shared cores) prints the
page's rows of that problem; this test runs it and compares them with the page's,
so it fails when either drifts. The other four problems take 3-8 minutes each (the
differential evolution's 1000 simulations of the DC motor's pythonfmu FMU alone take
minutes) and are left to the benchmark.

Tolerances: simulation counts are compared exactly (every method is deterministic: DE
is seeded); cost ratios to 1e-5 and worst errors to 1 % relative, since the last digits
of a least-squares answer may move with the platform's BLAS.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "benchmarks" / "accuracy.md"
LABEL = "| lightly damped resonance (local minima) |"


def _rows(text: str) -> list[list[str]]:
    """The six table rows of the resonance in ``text``, as lists of cells."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(LABEL))
    return [[c.strip() for c in line.strip("|").split("|")] for line in lines[start : start + 6]]


def _numbers(cell: str) -> list[float]:
    return [float(v) for v in re.findall(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?", cell)]


@pytest.mark.slow
def test_the_resonance_rows_of_the_accuracy_table_reproduce():
    command = [sys.executable, "benchmarks/accuracy.py", "local_minima", "--de-budget", "1000"]
    readme = PAGE.read_text(encoding="utf-8")
    assert "python benchmarks/accuracy.py --de-budget 1000" in readme
    out = subprocess.run(
        [*command, "--markdown"], cwd=REPO, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr[-2000:]
    fresh, written = _rows(out.stdout), _rows(readme)
    assert [r[:2] for r in fresh] == [r[:2] for r in written]  # the same methods
    for new, old in zip(fresh, written, strict=True):
        assert _numbers(new[2]) == _numbers(old[2]), (new, old)  # simulations
        assert _numbers(new[3]) == pytest.approx(_numbers(old[3]), rel=1e-5), (new, old)
        assert _numbers(new[4]) == pytest.approx(_numbers(old[4]), rel=1e-2), (new, old)

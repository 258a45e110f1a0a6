"""The generalisation benchmark's quick subset runs and prints its summary.

Only that it runs: whether tsid succeeds often enough is the benchmark's own verdict
(``python benchmarks/generalise.py --seeds eval --check``), not a test's.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_generalise_quick_runs_and_prints_the_summary() -> None:
    proc = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "generalise.py"), "--quick", "--workers", "1"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = proc.stdout
    assert "Summary (success" in out
    assert "tsid false convergence" in out
    assert "total wall time" in out
    assert "ERROR" not in out, out
    for family in ("duffing", "second_order", "local_minima"):
        assert f"{family} " in out

"""What an FMU prints on its own stdout never reaches tsid's stdout (issue 43).

OpenModelica's runtime ``printf``'s its asserts (``assert | debug | division by zero
...``) to descriptor 1, in whichever process runs the FMU; on tsid's stdout they broke
``--json``. The chatty lag FMU prints such a line at every run's first step.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fmu_factory import LAG_TOML, build_c_fmu, lag_response

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("chatty")
    build_c_fmu(d, "Lag", interfaces=("cs",), chatty=True)
    t = np.arange(0, 4.0 + 1e-9, 0.01)
    u = np.where((t % 2.0) < 1.0, 1.0, -0.5)
    y = lag_response(t, u, 0.37, 0.8) + np.random.default_rng(0).normal(0, 0.005, t.shape)
    pd.DataFrame({"time": t, "u": u, "y": y}).to_csv(d / "d.csv", index=False)
    (d / "study.toml").write_text(LAG_TOML.replace("max_iterations = 8", "max_iterations = 2"))
    return d / "study.toml"


@pytest.mark.parametrize("where", [["--workers", "1"], ["--workers", "1", "--timeout", "0"]])
def test_json_on_stdout_parses_whatever_the_fmu_prints(study, tmp_path, where):
    cmd = [sys.executable, "-m", "tsid_fmu", "identify", str(study), "--out",
           str(tmp_path / "out"), "--json", "-q", "--no-plots", *where]  # fmt: skip
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode in (0, 1), proc.stderr
    summary = json.loads(proc.stdout)  # nothing but the JSON
    assert summary["nfev"] > 0
    assert "chatty FMU | debug | first step" in proc.stderr  # not lost: on stderr

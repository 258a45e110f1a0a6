"""What an FMU prints on its own stdout never reaches tsid's stdout (issue 43).

OpenModelica's runtime ``printf``'s its asserts (``assert | debug | division by zero
...``) to descriptor 1, in whichever process runs the FMU; on tsid's stdout they broke
``--json``. The chatty lag FMU prints such a line at every run's first step. Each
run's printed text is kept: on stderr, in the study folder's ``fmu_output.log``, and at
the end of a failed run's reason.
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

from tsid_fmu.errors import SimulationError
from tsid_fmu.fmu import FMUSession

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


@pytest.mark.slow
@pytest.mark.parametrize("where", [["--workers", "1"], ["--workers", "1", "--timeout", "0"]])
def test_json_on_stdout_parses_whatever_the_fmu_prints(study, tmp_path, where):
    cmd = [sys.executable, "-m", "tsid_fmu", "identify", str(study), "--out",
           str(tmp_path / "out"), "--json", "-q", "--no-plots", *where]  # fmt: skip
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode in (0, 1), proc.stderr
    summary = json.loads(proc.stdout)  # nothing but the JSON
    assert summary["nfev"] > 0
    assert "chatty FMU | debug | first step" in proc.stderr  # not lost: on stderr
    log = (tmp_path / "out" / "fmu_output.log").read_text()
    assert "== parameter set: tau = " in log and "chatty FMU | debug | first step" in log


@pytest.fixture(scope="module")
def chatty(tmp_path_factory) -> Path:
    return build_c_fmu(tmp_path_factory.mktemp("chatty_fmu"), "Lag", interfaces=("cs",),
                       chatty=True)  # fmt: skip


def _run(fmu: Path, t_fail: float, capture: bool) -> tuple[FMUSession, object]:
    t = np.linspace(0.0, 1.0, 11)
    names = ["tau", "t_fail"]
    session = FMUSession(fmu, ["u"], ["y"], parameters=names, capture_output=capture)
    try:
        return session, session.simulate(t, np.ones(11), {"tau": 0.5, "t_fail": t_fail})
    except SimulationError as exc:
        return session, exc


def test_a_run_keeps_what_the_fmu_printed_and_echoes_it_on_stderr(chatty, capfd):
    session, y = _run(chatty, 10.0, capture=True)
    with session:
        assert isinstance(y, np.ndarray)
        assert session.printed == "chatty FMU | debug | first step, tau=0.5\n"
    out, err = capfd.readouterr()
    assert "first step" not in out and "first step, tau=0.5" in err


def test_a_failed_run_quotes_what_the_fmu_printed(chatty):
    session, exc = _run(chatty, 0.35, capture=True)
    with session:
        assert isinstance(exc, SimulationError)
        assert "t_fail=0.35 exceeded" in str(exc)  # the FMI log, as before
        assert str(exc).endswith("The FMU printed: chatty FMU | debug | first step, tau=0.5")


def test_without_capture_nothing_is_kept(chatty):
    session, exc = _run(chatty, 0.35, capture=False)
    with session:
        assert session.printed == "" and "The FMU printed" not in str(exc)


def test_the_solver_fidelity_check_captures_and_records_what_the_fmu_prints(study, tmp_path, capfd):
    """Its runs were uncaptured: on stderr without limit, none in fmu_output.log (issue 66, 9)."""
    from tsid_fmu.fmu.native import KEPT, recording
    from tsid_fmu.study import Study, prepare
    from tsid_fmu.uncertainty.solvers import Solver, SolverRuns

    loaded = Study.from_toml(study)
    x = {p.name: p.levels[len(p.levels) // 2] for p in loaded.parameters}
    log = tmp_path / "fmu_output.log"
    with recording(log):
        SolverRuns(prepare(loaded), x).run(Solver("cs"), 0)
    text = log.read_text()
    assert "[solver fidelity check, Co-Simulation" in text
    assert "chatty FMU | debug | first step" in text and "== parameter set: " in text
    out, err = capfd.readouterr()
    assert "first step" not in out and "chatty FMU | debug | first step" in err  # echoed
    assert len(err) <= KEPT + 200

"""The progress display of a study: a status bar on a terminal, nothing off one."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

import tsid_fmu.report.console as console
from tsid_fmu.cli import main
from tsid_fmu.errors import StudyError
from tsid_fmu.report.console import ConsoleProgress

REPO = Path(__file__).resolve().parents[1]


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _record(index: int, best: float, nfev: int) -> SimpleNamespace:
    return SimpleNamespace(
        errors=[None] * 9, best_cost=best, nfev_total=nfev, stage="taguchi", index=index,
        array="L9", decision=SimpleNamespace(message="re-levelled"),
    )  # fmt: skip


def test_the_terminal_bar_shows_stage_iteration_runs_simulations_best_cost_and_eta():
    now = [0.0]
    term = _Terminal()
    progress = ConsoleProgress(term, clock=lambda: now[0])
    progress("stage", {"message": "taguchi on step"})
    progress("start", {"stage": "taguchi", "cost": 4.5, "source": "start"})
    progress("iteration", {"stage": "taguchi", "iteration": 1})
    progress("iteration done", {"record": _record(1, 0.25, 10)})
    progress("iteration", {"stage": "taguchi", "iteration": 2})
    now[0] += 3.0
    progress("row", {"stage": "taguchi", "iteration": 2, "done": 3, "total": 9, "nfev": 13})
    bar = term.getvalue().rsplit("\r", 1)[-1]
    assert bar.startswith("taguchi, iteration 2 [")
    assert "3/9 runs" in bar and "13 simulations" in bar
    assert "best 0.25" in bar and "ETA 6 s" in bar
    progress("iteration done", {"record": _record(2, 0.125, 19)})
    last = term.getvalue().split("\n")[-2]
    assert "\033[K\r\033[Ktaguchi, iteration 2 (L9)" in last  # the bar is wiped first


def test_the_compile_notice_is_said_once():
    out = io.StringIO()
    progress = ConsoleProgress(out)
    said = "compiling the simulation loop (first run only) ..."
    progress("compiling", {"message": said})
    progress("compiling", {"message": said})
    assert out.getvalue() == said + "\n"
    assert console.COMPILING == said


def _progress_given(monkeypatch: pytest.MonkeyPatch, argv: list[str]) -> object:
    import tsid_fmu.identify  # noqa: F401  (the package's name is the function)

    seen: dict[str, object] = {}

    def fake(*args: object, **kwargs: object) -> None:
        seen.update(kwargs)
        raise StudyError("stop here")

    monkeypatch.setattr(sys.modules["tsid_fmu.identify"], "identify", fake)
    assert main(["identify", "study.toml", *argv]) == 2
    return seen["progress"]


def test_the_cli_shows_progress_on_any_stderr_and_never_with_q(monkeypatch):
    """Off a terminal too (a CI log, a notebook cell): a plain line per iteration (issue 64)."""
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # a pipe or a log file
    assert _progress_given(monkeypatch, []) is True
    assert _progress_given(monkeypatch, ["-q"]) is False
    monkeypatch.setattr(sys, "stderr", _Terminal())
    assert _progress_given(monkeypatch, []) is True
    assert _progress_given(monkeypatch, ["-q"]) is False


def test_off_a_terminal_progress_is_plain_lines_without_a_bar():
    log = io.StringIO()
    progress = ConsoleProgress(log)
    progress("stage", {"message": "taguchi on step"})
    progress("iteration", {"stage": "taguchi", "iteration": 1})
    progress("row", {"stage": "taguchi", "iteration": 1, "done": 3, "total": 9, "nfev": 13})
    progress("iteration done", {"record": _record(1, 0.25, 10)})
    text = log.getvalue()
    assert "\r" not in text and "\033" not in text  # no terminal control
    lines = text.splitlines()
    assert lines[0] == "== taguchi on step"
    assert lines[-1].startswith("taguchi, iteration 1 (L9): best cost 0.25")


_COMPILE = """
from tsid_fmu.fmu.compiled import CompileNotice, warm_up
notice = CompileNotice(lambda: print("NOTICE"))
warm_up()
warm_up()
notice.close()
"""


@pytest.mark.slow
def test_a_first_numba_compile_is_announced_and_a_cached_load_is_not(tmp_path):
    pytest.importorskip("numba")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(REPO)}
    env.pop("TSID_FMU_LOOP", None)
    run = [sys.executable, "-c", _COMPILE]
    first = subprocess.run(run, env=env, capture_output=True, text=True, timeout=300, cwd=REPO)
    assert first.returncode == 0, first.stderr
    assert first.stdout.split() == ["NOTICE"]
    again = subprocess.run(run, env=env, capture_output=True, text=True, timeout=300, cwd=REPO)
    assert again.returncode == 0, again.stderr
    assert again.stdout.split() == []


def test_the_bar_s_best_follows_the_array_s_runs_and_its_eta_says_something():
    """On a terminal the bar's "best" did not follow the array's runs, and its ETA read
    0 s (issue 64)."""
    now = [0.0]
    term = _Terminal()
    progress = ConsoleProgress(term, clock=lambda: now[0])
    progress("iteration", {"stage": "taguchi", "iteration": 1})
    now[0] += 0.5
    progress("row", {"stage": "taguchi", "iteration": 1, "done": 1, "total": 9, "cost": 7.5})
    bar = term.getvalue().rsplit("\r", 1)[-1]
    assert "best 7.5" in bar and "ETA" not in bar  # one run: no ETA yet
    now[0] += 0.5
    progress("row", {"stage": "taguchi", "iteration": 1, "done": 2, "total": 9, "cost": 2.5})
    bar = term.getvalue().rsplit("\r", 1)[-1]
    assert "best 2.5" in bar and "ETA 4 s" in bar
    now[0] += 0.5
    progress("row", {"stage": "taguchi", "iteration": 1, "done": 3, "total": 9, "cost": 9.0})
    assert "best 2.5" in term.getvalue().rsplit("\r", 1)[-1]


def test_the_evaluator_keeps_the_cost_of_the_set_it_last_scored(tmp_path):
    from fmu_factory import lag_study

    from tsid_fmu.study import serial_evaluator

    study = lag_study(tmp_path, replicates=1)
    with serial_evaluator(study) as ev:
        seen = []
        out = ev.evaluate([{"tau": 0.37, "x0": 0.8}, {"tau": 1.0, "x0": 0.0}],
                          progress=lambda d, t: seen.append(ev.last_cost))  # fmt: skip
    assert seen == [float(out.costs[0, 0]), float(out.costs[1, 0])]

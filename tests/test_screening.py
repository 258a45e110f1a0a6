"""Sensitivity screening (issue 29, item 1): Morris / Sobol over the first ranges, eq. (7)
from an L25 beside it, the parameters set apart, and ``tsid screen``.

The toy model has known sensitivities: output ``y1`` feels only ``a``, output ``y2``
only ``b`` (three times less strongly than ``y1`` feels ``a``), and nothing feels ``c``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from tsid_fmu import Experiment, Method, Parameter, Study, StudyError
from tsid_fmu.evaluate import Evaluation
from tsid_fmu.screening import screen
from tsid_fmu.screening.indices import array_contribution, array_design

ROOT = Path(__file__).resolve().parents[1]
T = np.linspace(0.0, 1.0, 50)
TRUTH = {"a": 2.0, "b": 2.0, "c": 2.0}


def _model(a: float, b: float, c: float) -> np.ndarray:
    return np.column_stack([3.0 * a * np.sin(6 * T), b * np.cos(6 * T)])


class ToyEvaluator:
    """Two outputs of a plain model, scored as a study's ``sse`` cost; no FMU."""

    n_replicates = 1

    def __init__(self, fail_above: float = math.inf) -> None:
        self.measured = _model(**TRUTH)
        self.spec = SimpleNamespace(
            experiments=[
                SimpleNamespace(
                    output_names=("y1", "y2"), measured=self.measured, scored=lambda x: x
                )
            ]
        )
        self.nfev, self.memo, self.fail_above = 0, {}, fail_above

    def evaluate(self, sets, progress=None) -> Evaluation:
        costs, residuals, errors, ran = [], [], [], 0
        for s in sets:
            key = tuple(s[n] for n in ("a", "b", "c"))
            if key not in self.memo:
                ran += 1
                self.memo[key] = (_model(**s) - self.measured).reshape(-1)
            r = self.memo[key]
            bad = s["a"] > self.fail_above
            costs.append([math.inf if bad else float(r @ r)])
            residuals.append(None if bad else r)
            errors.append("failed" if bad else None)
        self.nfev += ran
        return Evaluation(np.array(costs), errors, ran, residuals)


def _study(**levels) -> Study:
    data = pd.DataFrame({"time": T, "y1": 0.0 * T, "y2": 0.0 * T})
    lv = {"a": [1.0, 2.0, 3.0], "b": [1.0, 2.0, 3.0], "c": [1.0, 2.0, 3.0], **levels}
    return Study(
        fmu=ROOT / "no-such.fmu",
        parameters=[Parameter(n, v, 0.0, math.inf) for n, v in lv.items()],
        experiments=[Experiment(data, inputs={}, outputs={"y1": "y1", "y2": "y2"})],
        method=Method(cost="sse", weighting="none", replicates=1),
    )


def test_morris_sets_apart_the_parameter_without_effect_and_ranks_the_others():
    ev = ToyEvaluator()
    res = screen(_study(), "morris", n=10, evaluator=ev)
    assert res.set_apart == ["c"]
    assert res.ranking() == ["a", "b", "c"]  # y1 feels a nine times as much as y2 feels b
    assert res.not_felt["y1"] == ["b", "c"] and res.not_felt["y2"] == ["a", "c"]
    assert res.ranking("y2")[0] == "b"
    # each index: mu* of the cost, normalised by the largest
    assert res.indices["cost"]["a"]["mu_star_norm"] == 1.0
    assert res.indices["cost"]["c"]["mu_star"] == 0.0
    # the memo runs a point repeated by the trajectories once: never more than r (k + 1)
    assert res.nfev_screen == ev.nfev - res.nfev_contribution <= 10 * 4
    assert res.nfev == ev.nfev


def test_a_parameter_felt_by_one_output_only_is_not_set_apart():
    # b moves only y2, whose SSE is small beside y1's: the cost alone would drop it
    res = screen(_study(), "morris", n=10, threshold=0.2, evaluator=ToyEvaluator())
    assert "b" in res.not_felt["cost"]
    assert res.set_apart == ["c"]


def test_sobol_gives_total_indices_with_confidence_and_sets_apart_c():
    res = screen(_study(), "sobol", n=64, evaluator=ToyEvaluator())
    st = {n: v["ST"] for n, v in res.indices["cost"].items()}
    assert st["a"] > st["b"] > st["c"] and st["c"] < 0.01
    assert res.indices["y2"]["b"]["ST"] > 0.9  # y2 feels b alone
    assert res.set_apart == ["c"]
    assert all(v["ST_conf"] >= 0 for v in res.indices["cost"].values())


def test_eq7_from_the_l25_agrees_with_morris_on_the_toy_and_its_runs_are_counted():
    res = screen(_study(), "morris", n=10, evaluator=ToyEvaluator())
    assert res.array == "L25" and res.nfev_contribution <= 25
    assert res.contribution_ranking() == ["a", "b", "c"]
    assert res.contribution["cost"]["c"] == pytest.approx(0.0, abs=1e-9)
    assert res.contribution_set_apart == ["c"]
    assert res.disagreements() == []
    table = res.table()
    assert list(table.index) == ["a", "b", "c"]
    assert table.loc["c", "set apart (morris)"] and table.loc["c", "set apart (eq7)"]


def test_eq7_from_an_array_is_the_spread_of_the_level_means_over_the_mean():
    _, s = array_design(2)
    y = 10.0 + 4.0 * s[:, 0]  # level means 8 .. 12, mean 10: 40 %; the other: 0 %
    got = array_contribution(s, ["p", "q"], y)
    assert got["p"] == pytest.approx(40.0) and got["q"] == pytest.approx(0.0)


def test_disagreements_are_named():
    res = screen(_study(), "morris", n=10, evaluator=ToyEvaluator())
    res.contribution["cost"] = {"a": 1.0, "b": 50.0, "c": 0.5}
    notes = res.disagreements()
    assert any(n.startswith("cost: ranks differ") and "a 1 vs 2" in n for n in notes)


def test_log_spaced_levels_are_screened_in_log10():
    # a over three decades: its design points are spread evenly in log10, as the search
    ev = ToyEvaluator()
    res = screen(_study(a=[0.01, 0.1, 10.0]), "morris", n=6, evaluator=ev, contribution=False)
    assert res.log == {"a": True, "b": False, "c": False}
    a = sorted({k[0] for k in ev.memo})
    assert np.allclose(np.diff(np.log10(a)), np.log10(a[1] / a[0]))


def test_failed_points_count_as_the_largest_value_and_are_reported():
    res = screen(_study(), "morris", n=10, evaluator=ToyEvaluator(fail_above=2.5))
    assert res.failed > 0
    assert np.isfinite(res.indices["cost"]["a"]["mu_star"]) and res.ranking()[0] == "a"


@pytest.mark.parametrize(
    ("kw", "words"),
    [
        ({"method": "fast"}, "screening method must be one of"),
        ({"method": "sobol", "n": 48}, "power of two"),
        ({"method": "morris", "n": 1}, "at least 2 trajectories"),
        ({"method": "morris", "n": 2.5}, "whole number"),
        ({"method": "morris", "threshold": 1.5}, "threshold must be between"),
    ],
)
def test_bad_options_are_study_errors(kw, words):
    with pytest.raises(StudyError, match=words):
        screen(_study(), evaluator=ToyEvaluator(), **kw)


def test_the_result_round_trips_to_json_and_pandas():
    res = screen(_study(), "morris", n=4, evaluator=ToyEvaluator())
    back = json.loads(json.dumps(res.to_dict()))
    assert back["set_apart"] == ["c"] and back["ranking"]["cost"][0] == "a"
    frame = res.to_pandas()
    assert frame.loc[("y1", "a"), "mu_star_norm"] == 1.0 and "eq7 %" in frame.columns


# -- tsid screen ---------------------------------------------------------------------------

SISO = ROOT / "examples" / "lsea_siso" / "study.toml"


@pytest.mark.slow
def test_tsid_screen_on_the_siso_example_prints_the_table_and_writes_the_files(tmp_path, capsys):
    from tsid_fmu.cli import main

    out = tmp_path / "screen"
    assert main(["screen", str(SISO), "--n", "4", "-o", str(out), "--workers", "1"]) == 0
    text = capsys.readouterr().out
    header = text.splitlines()[0]
    assert "mu_star_norm cost" in header and "eq7 % cost" in header
    assert all(p in text for p in ("F_cm", "F_vm", "M_m", "K_s", "B_s"))
    assert "set apart (morris):" in text and "simulations" in text
    frame = pd.read_csv(out / "screening.csv")
    assert set(frame["quantity"]) == {"cost", "F_o", "x_m"} and len(frame) == 15
    saved = json.loads((out / "screening.json").read_text())
    assert saved["nfev"] <= 4 * 6 + 25 and saved["array"] == "L25"
    assert (out / "screening.png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["screen", "no-such-study.toml"], "no-such-study.toml"),
        (["screen", str(SISO), "--method", "sobol", "--n", "48"], "power of two"),
    ],
)
def test_tsid_screen_bad_input_is_one_line_and_exit_2(argv, words, tmp_path, capsys):
    from tsid_fmu.cli import main

    assert main([*argv, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv", [["--n", "1"], ["--method", "fast"], ["--n", "x"]])
def test_tsid_screen_bad_options_stop_at_parsing(argv, capsys):
    from tsid_fmu.cli import main

    with pytest.raises(SystemExit) as stop:
        main(["screen", str(SISO), *argv])
    assert stop.value.code == 2
    assert "Traceback" not in capsys.readouterr().err

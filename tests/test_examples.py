"""The bundled examples of the two papers, end to end on the committed FMUs.

Their data come from independent solutions of the equations (``examples/*/make_data.py``),
never from the FMUs, with a rig's conventions: held commands, continuous measured
signals, one noise level per sensor.
"""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tsid_fmu import identify
from tsid_fmu.fmu import FMUSession
from tsid_fmu.study import load_study

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SISO_TRUTH = {"F_cm": 88.5, "F_vm": 51.5, "M_m": 4.3, "K_s": 8600.0, "B_s": 2.5}
MISO_TRUTH = {"m1": 0.45, "m2": 0.2, "K_s": 5000.0, "C_d": 5.0, "C_1": 20.0, "C_2": 2.0}


def rel_err(x, truth):
    return {k: abs(x[k] / truth[k] - 1) for k in truth}


def test_siso_force_alone_hardly_sees_the_scale():
    """Scaling M_m, F_vm, K_s and B_s together leaves F_o unchanged within the noise (only
    the dry-friction stick threshold carries the scale), while the motor position x_m
    scales: why the example records the encoder."""
    data = pd.read_csv(EXAMPLES / "lsea_siso" / "measured.csv")
    t, u = data["time"].to_numpy(), data[["F_m"]].to_numpy()
    scaled = dict(SISO_TRUTH)
    for k in ("F_vm", "M_m", "K_s", "B_s"):
        scaled[k] *= 0.8
    fmu = EXAMPLES.parents[0] / "fmus" / "LSEA_SISO.fmu"
    with FMUSession(fmu, ["F_m"], ["F_o", "x_m"], parameters=list(SISO_TRUTH)) as s:
        a = s.simulate(t, u, SISO_TRUTH)
        b = s.simulate(t, u, scaled)
    peak_f, peak_x = np.abs(a).max(axis=0)
    assert np.abs(a[:, 0] - b[:, 0]).max() < 0.01 * peak_f  # below the 1 % output noise
    assert np.abs(a[:, 1] - b[:, 1]).max() > 0.15 * peak_x  # the encoder sees the scale


def siso_misses(params, intervals) -> list[str]:
    """What is wrong with an answer to the SISO example, judged on what the data determine.

    F_cm, M_m and K_s are determined (within 1 % of the truth). F_vm and B_s act on the
    motion through their sum, which the data fix (within 1 %) and their split they do
    not: B_s's 95 % interval is open, so neither is judged on its own value, only on
    its interval holding the truth, as every parameter's interval must.
    """
    misses = []
    err = rel_err(params, SISO_TRUTH)
    for name in ("F_cm", "M_m", "K_s"):
        if not err[name] < 0.01:
            misses.append(f"{name} {params[name]:.6g}: {100 * err[name]:.2f} % from the truth")
    total, true_total = params["F_vm"] + params["B_s"], SISO_TRUTH["F_vm"] + SISO_TRUTH["B_s"]
    if not abs(total / true_total - 1) < 0.01:
        misses.append(f"F_vm + B_s {total:.6g}: not within 1 % of {true_total}")
    for name, value in SISO_TRUTH.items():
        low, high = intervals[name]
        if not ((low is None or low <= value) and (high is None or value <= high)):
            misses.append(f"{name}'s 95 % interval {low} .. {high} misses the truth {value}")
    if None not in intervals["B_s"]:
        misses.append(f"B_s's interval {intervals['B_s']} is closed: the data do not fix it")
    return misses


SISO_ANSWER = {"F_cm": 88.5003, "F_vm": 51.7431, "M_m": 4.30001, "K_s": 8600.03, "B_s": 2.25708}
SISO_INTERVALS = {
    "F_cm": (88.474, 88.527),
    "F_vm": (48.85, 53.56),
    "M_m": (4.2994, 4.3006),
    "K_s": (8597.6, 8602.5),
    "B_s": (None, 5.0117),
}


def test_the_siso_checks_judge_only_what_the_data_determine():
    """A deliberate perturbation: along F_vm + B_s the checks pass, elsewhere they fail."""
    assert siso_misses(SISO_ANSWER, SISO_INTERVALS) == []
    for shift in (-2.0, -0.2, 0.2, 2.0):  # the split of the determined sum moves
        moved = {**SISO_ANSWER, "F_vm": SISO_ANSWER["F_vm"] + shift}
        moved["B_s"] -= shift
        assert siso_misses(moved, SISO_INTERVALS) == [], shift
    for name in ("F_cm", "M_m", "K_s"):  # a determined figure 2 % wrong
        wrong = {**SISO_ANSWER, name: SISO_ANSWER[name] * 1.02}
        assert [m for m in siso_misses(wrong, SISO_INTERVALS) if m.startswith(name)], name
    wrong = {**SISO_ANSWER, "B_s": SISO_ANSWER["B_s"] + 1.0}  # the sum moves
    assert any("F_vm + B_s" in m for m in siso_misses(wrong, SISO_INTERVALS))
    missing = {**SISO_INTERVALS, "K_s": (8601.0, 8605.0)}
    assert any("K_s's 95 % interval" in m for m in siso_misses(SISO_ANSWER, missing))
    closed = {**SISO_INTERVALS, "B_s": (1.0, 5.0)}
    assert any("closed" in m for m in siso_misses(SISO_ANSWER, closed))


@pytest.mark.slow
def test_siso_example_identifies_the_parameters(tmp_path):
    study = load_study(EXAMPLES / "lsea_siso" / "study.toml")
    res = identify(study, tmp_path / "out", plots=False)
    assert res.success, res.message
    # F_vm and B_s act through their sum: the refinement crawls along that valley and goes
    # on in the combination, one stage (README, "Set up and run";
    # docs/explanation/procedure.md, step 5)
    assert [s.kind for s in res.stages] == ["taguchi", "refinement"]
    assert [p[:2] for p in res.stages[1].pairs] == [["F_vm", "B_s"]]
    assert res.stages[1].crawled["cost"] > res.fun
    assert siso_misses(res.params, res.intervals) == []
    assert res.nfev <= 200  # 149 measured; the arrays to their end: 437
    assert res.fit["measured"]["F_o"]["fit_percent"] > 97
    assert (tmp_path / "out" / "report.md").is_file()
    # the FMU's Co-Simulation matches an accurate solution: no solver warning (issue 16)
    assert res.fidelity["interface"] == "cs"
    assert not any(w.startswith("solver fidelity") for w in res.warnings), res.warnings


@pytest.mark.slow
def test_miso_example_contribution_phases_and_validation(tmp_path):
    study = load_study(EXAMPLES / "lsea_miso" / "study.toml")
    res = identify(study, tmp_path / "out", plots=False)
    plan = res.stages[0]
    assert plan.kind == "contribution"
    # Step i: the force input produces the larger output, so its subsystem comes first
    assert plan.contribution.input["experiments"][0] == "force only"
    # Step ii: m1 and K_s are in the first group; m2 and C_2 do not act with the stage
    # locked, so they are left for the motion experiment
    first = plan.contribution.groups["force only"][0]
    assert {"m1", "K_s"} <= set(first)
    assert plan.contribution.percent["force only"]["m2"] == 0
    assert plan.contribution.percent["force only"]["C_2"] == 0
    phases = [s for s in res.stages if s.kind == "phase"]
    assert phases[0].experiments == ["force only"]
    assert any(s.experiments == ["motion only"] for s in phases)
    # the superposition check on both inputs together is reported
    assert np.isfinite(res.validation["both inputs"]["cost"])
    # the force-only data fix only ratios to K_s; together the experiments fix them well
    x = res.params
    assert abs((x["m1"] / x["K_s"]) / (0.45 / 5000.0) - 1) < 0.02
    assert abs((x["C_1"] / x["K_s"]) / (20.0 / 5000.0) - 1) < 0.02
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## Stages" in report and "contribution" in report
    assert "Input contribution" in report and "Superposition check" in report
    # the same study without grouping, side by side (cost and simulations)
    comp = res.comparison
    assert comp["phased"]["nfev"] > 0 and comp["ungrouped"]["nfev"] > 0
    assert np.isfinite(comp["phased"]["cost"]) and np.isfinite(comp["ungrouped"]["cost"])
    assert "Why grouping: the same study without it" in report
    assert res.fidelity["interface"] == "cs"
    assert not any(w.startswith("solver fidelity") for w in res.warnings), res.warnings
    _miso_matches_the_tutorial(res)


def _miso_claims() -> dict[str, float]:
    """The MISO example's figures, as the tutorial states them."""
    import re

    page = EXAMPLES.parent / "docs" / "tutorial" / "first-identification.md"
    text = " ".join(page.read_text(encoding="utf-8").split())
    para = text[text.index("SISO as above; MISO") :]
    para = para[: para.index("grouping does not pay")]
    rms = re.search(r"residual RMS ends within ([\d.]+) %", para)
    ratios = re.search(r"m1/K_s and C_1/K_s come within ([\d.]+) % and ([\d.]+) %", para)
    sims = re.search(
        r"exit status 0, (\d+) simulations in all \((\d+) for the contribution analyses, "
        r"(\d+) for the refinement\)",
        para,
    )
    ungrouped = re.search(r"reaches the same cost in (\d+) simulations", para)
    assert rms and ratios and sims and ungrouped, para
    assert "every 95 % interval holds the truth" in para
    return {
        "rms": float(rms[1]) / 100,
        "m1/K_s": float(ratios[1]) / 100,
        "C_1/K_s": float(ratios[2]) / 100,
        "nfev": float(sims[1]),
        "contribution": float(sims[2]),
        "refinement": float(sims[3]),
        "ungrouped": float(ungrouped[1]),
    }


def _miso_matches_the_tutorial(res) -> None:
    """What the tutorial says of the MISO example, to its precision (issues 27, 64).

    Tolerances: the RMS and the ratios are bounds the page states (``within 1.6 %``); the
    simulation counts (in all, the contribution analyses', the refinement's, the ungrouped
    comparison's) to 10 % of the page's, the project's convention for counts, which are
    the same from run to run on one machine but not from one machine to another; the
    ungrouped comparison's cost to 1e-4 of the phased one.
    """
    claims = _miso_claims()
    assert res.status == 0 and res.success, res.message
    x = res.params
    assert abs((x["m1"] / x["K_s"]) / (0.45 / 5000.0) - 1) < claims["m1/K_s"]
    assert abs((x["C_1"] / x["K_s"]) / (20.0 / 5000.0) - 1) < claims["C_1/K_s"]
    for name, value in MISO_TRUTH.items():  # an open bound holds the truth
        low, high = res.intervals[name]
        assert (low is None or low <= value) and (high is None or value <= high), name
    for exp, outputs in res.fit.items():
        for out, fit in outputs.items():
            assert abs(fit["rmse"] / res.noise[exp][out] - 1) < claims["rms"], (exp, out)
    # simulation counts to within 10 %; the ungrouped comparison at the same cost
    assert abs(res.nfev / claims["nfev"] - 1) <= 0.10, res.nfev
    stages = {s.kind: s.nfev for s in res.stages if s.kind in ("contribution", "refinement")}
    for kind in ("contribution", "refinement"):
        assert abs(stages[kind] / claims[kind] - 1) <= 0.10, (kind, stages)
    comp = res.comparison
    assert abs(comp["ungrouped"]["nfev"] / claims["ungrouped"] - 1) <= 0.10, comp
    assert comp["ungrouped"]["cost"] == pytest.approx(comp["phased"]["cost"], rel=1e-4)


def test_the_tutorial_states_the_miso_figures():
    """The paragraph the slow MISO test reads is there and parses (fast)."""
    claims = _miso_claims()
    assert set(claims) == {
        "rms", "m1/K_s", "C_1/K_s", "nfev", "contribution", "refinement", "ungrouped"
    }  # fmt: skip
    assert all(v > 0 for v in claims.values()), claims

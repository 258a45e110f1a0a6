"""``tsid design``: the experiment that determines what a study left open, or why none can."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_pythonfmu, lag_study, pythonfmu_available

from tsid_fmu import Experiment, Method, Parameter, Study, StudyError, identify
from tsid_fmu.cli import main
from tsid_fmu.design import DesignOptions, design, write_design
from tsid_fmu.design.signals import candidates
from tsid_fmu.study.toml import design_options


def test_every_candidate_stays_inside_the_limits_and_the_kinds_differ():
    t = np.arange(0, 5.0 + 1e-9, 0.01)
    found = candidates(t, [(-2.0, 3.0), (0.0, 1.0)], (0.2, 5.0), ["steps", "chirp",
                       "multisine", "prbs"], 2, 0)  # fmt: skip
    assert {s.kind for s in found} == {"steps", "chirp", "multisine", "prbs"}
    for s in found:
        assert s.values.shape == (t.size, 2)
        assert s.values[:, 0].min() >= -2.0 - 1e-12 and s.values[:, 0].max() <= 3.0 + 1e-12
        assert s.values[:, 1].min() >= -1e-12 and s.values[:, 1].max() <= 1.0 + 1e-12
    # a multisine per band with one input alone moving: the other held at its middle
    alone = [s for s in found if s.name.endswith("input 2 alone")]
    assert alone and np.all(alone[0].values[:, 0] == 0.5)


@pytest.mark.parametrize(
    ("table", "says"),
    [
        ({"criterion": "E"}, "[design] criterion"),
        ({"band": [5.0, 1.0]}, "[design] band"),
        ({"inputs": {"u": [1.0, 1.0]}}, "[design] inputs.u"),
        ({"kinds": ["noise"]}, "[design] kinds"),
        ({"bands": 0}, "[design] bands"),
        ({"wobble": 1}, "wobble"),
    ],
)
def test_a_wrong_design_table_is_refused_naming_the_key(table, says):
    with pytest.raises(StudyError, match=rf"{__import__('re').escape(says)}"):
        design_options({"design": table}, "study.toml")


def _lag(tmp_path):
    study = lag_study(tmp_path, method=Method(max_iterations=6))
    return identify(study, tmp_path / "out", plots=False, workers=1, timeout=0)


def test_a_design_proposes_an_input_inside_the_limits_and_predicts_narrower_intervals(tmp_path):
    result = _lag(tmp_path)
    said: list[str] = []
    d = design(result, DesignOptions(inputs={"u": [-1.0, 1.0]}, bands=2), progress=said.append)
    assert d.proposal is not None and not d.structural
    # a line before each batch of simulations: a slow FMU's user sees where it is
    assert [line.split()[0] for line in said] == ["the", str(len(d.candidates)), "proposal"]
    assert "candidate inputs" in said[1] and "analysis" in said[2]
    assert d._repr_markdown_() == d.markdown()
    assert d.proposal.values.min() >= -1.0 and d.proposal.values.max() <= 1.0
    # the study's information, every candidate's, then the study's analysis with the
    # proposal (two experiments a parameter set)
    assert d.nfev > (2 * 2 + 1) * (1 + len(d.candidates)) + 2 * (2 * 2 + 1)
    for j, name in enumerate(d.names):
        low, high = d.after[j]
        study_low, study_high = result.intervals[name]
        # the study plus the proposal: narrower than the study alone, around the answer
        assert low < float(result.params[name]) < high
        assert high - low < study_high - study_low
    files = write_design(d, tmp_path / "design")
    csv = pd.read_csv(tmp_path / "design" / "design_input.csv")
    assert list(csv.columns) == ["time", "u"] and len(csv) == d.time.size
    assert {p.name for p in files} >= {"design.png", "design.json", "design.md", "design.html"}
    assert "predicted, with the proposal" in (tmp_path / "design" / "design.md").read_text()


def test_the_prediction_is_for_the_study_started_around_the_answer(tmp_path, monkeypatch):
    """The predicted intervals are those of the study the user runs next: the proposal
    added, first levels from half to twice each answer (the intervals' resolution and
    the finite differences' steps are fractions of a first range), and the report says
    which levels."""
    from tsid_fmu.design import plan as plan_module
    from tsid_fmu.design import run as run_module

    result = _lag(tmp_path)
    spaces = []
    real = run_module.predicted_intervals

    def spy(spec, proposal, outputs, noise, space, x, *args, **kwargs):
        spaces.append((space, dict(x)))
        return real(spec, proposal, outputs, noise, space, x, *args, **kwargs)

    monkeypatch.setattr(run_module, "predicted_intervals", spy)
    d = design(result, DesignOptions(inputs={"u": [-1.0, 1.0]}, bands=2))
    ((space, x),) = spaces
    # every first range of that study runs from half to twice the answer
    assert np.allclose(space.to_s({n: 0.5 * v for n, v in x.items()}), -0.5)
    assert np.allclose(space.to_s({n: 2.0 * v for n, v in x.items()}), 0.5)
    for name in d.names:
        want = [float(result.params[name]) * f for f in plan_module.FOLLOW_UP]
        assert d.levels[name] == pytest.approx(want)
        assert d.to_dict()["parameters"][d.names.index(name)]["first_levels"] == pytest.approx(want)
    assert "first levels" in d.markdown() and "half to twice each value" in d.markdown()


def test_the_synthetic_noise_is_centred_so_the_answer_is_its_optimum(tmp_path):
    """The prediction's noise has no part along the proposal's sensitivities, so its
    profiles start at the optimum, as the achieved ones do: each predicted interval sits
    around the answer (off-centre, every interval came out wider)."""
    from tsid_fmu.design.predict import centred

    rng = np.random.default_rng(4)
    sigma = np.array([0.5, 2.0])
    jac = rng.normal(size=(200 * 2, 3))
    noise = rng.normal(size=(200, 2)) * sigma
    out = centred(noise, jac, sigma)
    assert np.abs(jac.T @ (out / sigma).ravel()).max() < 1e-9
    assert 0 < np.abs(out - noise).max() < 0.5 * np.abs(noise).max()
    bad = jac.copy()
    bad[0, 0] = np.nan
    assert centred(noise, bad, sigma) is noise

    result = _lag(tmp_path)
    d = design(result, DesignOptions(inputs={"u": [-1.0, 1.0]}, bands=2))
    for j, name in enumerate(d.names):
        low, high = d.after[j]
        mid, half = 0.5 * (low + high), 0.5 * (high - low)
        assert abs(mid - float(result.params[name])) < 0.1 * half, (name, low, high)


def test_follow_up_levels_keep_the_studys_own_where_the_answer_leaves_no_range():
    from tsid_fmu.design.plan import follow_up_levels

    own = {"a": [1.0, 2.0, 4.0], "b": [0.5, 1.0, 2.0], "c": [0.5, 1.0, 1.5], "d": [-3, -1, 1]}
    bounds = {"a": (0.0, math.inf), "b": (-math.inf, 3.0), "c": (0.0, 2.0), "d": (-9, 9)}
    study = SimpleNamespace(first_levels=lambda: own, bounds=lambda: bounds)
    levels = follow_up_levels(study, {"a": 0.0, "b": 2.0, "c": 2.0, "d": -1.0})
    assert levels["a"] == [1.0, 2.0, 4.0]  # an answer of 0: no range around it
    assert levels["b"] == [1.0, 1.4, 2.0, 2.8, 3.0]  # the upper bound clips
    assert levels["c"] == [0.5, 1.0, 1.5]  # on its bound: three levels would merge
    assert levels["d"] == [-2.0, -1.4, -1.0, -0.7, -0.5]  # a negative answer: in order


def test_the_criterion_ranks_the_candidates_and_the_proposal_is_the_best(tmp_path):
    result = _lag(tmp_path)
    for criterion in ("D", "A"):
        d = design(result, DesignOptions(inputs={"u": [-1.0, 1.0]}, bands=2,
                                         criterion=criterion))  # fmt: skip
        best = max(d.candidates, key=lambda c: c["score"])
        assert d.proposal.name == best["name"]
        assert len({round(c["score"], 9) for c in d.candidates}) > 1  # they differ


def test_tsid_design_writes_its_files_and_prints_json(tmp_path, capsys):
    result = _lag(tmp_path)
    study = tmp_path / "study.toml"
    result.study.to_toml(study)
    with study.open("a") as fh:
        fh.write('\n[design]\ninputs = { u = [-0.5, 0.5] }\nbands = 1\nkinds = ["chirp"]\n')
    assert main(["design", str(study), "--result", str(tmp_path / "out"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["inputs"] == {"u": [-0.5, 0.5]}
    assert out["proposal"].startswith("chirp")
    assert [c["kind"] for c in out["candidates"]] == ["chirp"]
    frame = pd.read_csv(tmp_path / "out.design" / "design_input.csv")
    assert frame.u.min() >= -0.5 and frame.u.max() <= 0.5
    # the page stands alone (its plot embedded) and has the report's tables and style
    page = (tmp_path / "out.design" / "design.html").read_text()
    assert page.count("<table") == 1 and "<style>" in page and "data:image/png;base64" in page
    assert "predicted, with the proposal" in page and out["verdict"].split(":")[0] in page
    md = (tmp_path / "out.design" / "design.md").read_text()
    assert "with the outputs and sensors of experiment '" in md
    # on the terminal: plain text in aligned columns, not raw markdown (issue 64)
    assert main(["design", str(study), "--result", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "|" not in printed and "**" not in printed and "## " not in printed, printed
    assert printed.splitlines()[0] == out["verdict"]
    head = next(x for x in printed.splitlines() if x.startswith("parameter"))
    assert "  " in head  # columns, aligned


def test_tsid_design_on_a_missing_result_is_one_line_and_exit_2(tmp_path, capsys):
    study = lag_study(tmp_path)
    path = tmp_path / "study.toml"
    study.to_toml(path)
    assert main(["design", str(path), "--result", str(tmp_path / "nothing")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nothing" in err[0]


@pytest.mark.skipif(not pythonfmu_available(), reason="needs pythonfmu and a shared libpython")
def test_an_exact_symmetry_is_reported_as_structural_and_nothing_is_proposed(tmp_path):
    """The lag with tau = R C: no input separates R and C. The design says so, names the
    product the data fix, and proposes no experiment; it fails when the direction is not
    followed by simulation (a finite-difference Fisher matrix sees the solver's noise)."""
    fmu = build_pythonfmu(tmp_path, "RCLag", rc=True)
    t = np.round(np.arange(0.0, 2.0 + 1e-9, 0.02), 10)
    u = np.where(t < 0.7, 1.0, 0.2) + 0.3 * np.sin(5 * t)
    pd.DataFrame({"time": t, "u": u, "y": 0.0 * t}).to_csv(tmp_path / "d.csv", index=False)
    study = Study(
        fmu=fmu,
        # ranges over decades: log coordinates, in which the symmetry is straight
        parameters=[
            Parameter("R", [0.1, 1.0, 10.0], min=0.0),
            Parameter("C", [0.03, 0.3, 3.0], min=0.0),
        ],
        experiments=[
            Experiment(tmp_path / "d.csv", inputs={"u": "u"}, outputs={"y": "y"}, noise={"y": 0.01})
        ],
        cost="sse",
        replicates=1,
    )
    result = SimpleNamespace(
        study=study,
        params={"R": 1.0, "C": 0.3},
        intervals={"R": [None, None], "C": [None, None]},
        uncertainty=None,
        noise={},
    )
    d = design(result, DesignOptions(inputs={"u": [0.0, 1.0]}, bands=1, kinds=["chirp", "prbs"]))
    assert d.proposal is None and d.after is None
    (s,) = d.structural
    assert sorted(s.members) == ["C", "R"]
    (fixed,) = s.fixed
    assert fixed["name"] in ("R C", "C R") and fixed["value"] == pytest.approx(0.3)
    assert "no input of this kind separates" in d.verdict
    assert d.to_dict()["parameters"][0]["predicted_after"] is None


def test_tsid_init_writes_a_design_table_to_uncomment(tmp_path):
    from fmu_factory import lag_data

    from tsid_fmu.scaffold import init_study

    fmu, data = lag_data(tmp_path, 0.37, 0.8)
    frame = pd.read_csv(data).rename(columns={"y_meas": "y"})
    frame.to_csv(data, index=False)
    text = init_study(fmu, data, tmp_path / "study.toml")
    assert "# [design]" in text
    opened = text.replace("# [design]", "[design]").replace("# inputs = { INPUT", "inputs = { u")
    opened = opened.replace("# band = [", "band = [")
    (tmp_path / "study.toml").write_text(opened)
    study = Study.from_toml(tmp_path / "study.toml")  # the whole file still reads
    from tsid_fmu.study.toml import read_design

    options = read_design(tmp_path / "study.toml")
    assert study.fmu == fmu.resolve()
    assert options.inputs == {"u": [-1.0, 1.0]} and options.band == [0.1, 10.0]


def test_structures_the_data_cannot_tell_apart_get_the_input_that_separates_them(tmp_path):
    """The lag's integer gain: a free decay from x0 (no input) gives the same output with
    gain 1 from x0 and gain 2 from x0 / 2, so the study's structures tie; any input that
    moves separates them (y tends to u against 2 u). The design proposes one, and says
    how little the study's own input separates them."""
    from fmu_factory import build_c_fmu, lag_response

    from tsid_fmu import Choice

    fmu = build_c_fmu(tmp_path)
    t = np.arange(0, 3.0 + 1e-9, 0.01)
    y = lag_response(t, np.zeros_like(t), 0.37, 0.8)
    pd.DataFrame({"time": t, "u": 0.0 * t, "y": y}).to_csv(tmp_path / "d.csv", index=False)
    study = Study(
        fmu=fmu,
        parameters=[
            Parameter("tau", [0.1, 1.0], min=0.0),
            Parameter("x0", [-1.0, 2.0]),
            Choice("gain", [1, 2]),
        ],
        experiments=[
            Experiment(tmp_path / "d.csv", inputs={"u": "u"}, outputs={"y": "y"}, noise={"y": 0.01})
        ],
        cost="sse",
        replicates=1,
    )
    rows = [
        {"structure": "gain=1", "values": {"gain": 1}, "x": {"tau": 0.37, "x0": 0.8}},
        {"structure": "gain=2", "values": {"gain": 2}, "x": {"tau": 0.37, "x0": 0.4}},
    ]
    result = SimpleNamespace(
        study=study,
        params={"tau": 0.37, "x0": 0.8, "gain": 1.0},
        intervals={"tau": [0.36, 0.38], "x0": [0.79, 0.81]},
        uncertainty=None,
        noise={},
        structures=rows,
        structure={"chosen": "gain=1", "indistinguishable": ["gain=2"]},
    )
    d = design(result, DesignOptions(inputs={"u": [-1.0, 1.0]}, bands=1))
    found = d.discrimination
    assert found is not None and found["structures"] == ["gain=1", "gain=2"]
    assert found["now"]["gain=1 / gain=2"] < 1e-6  # the free decay: the same output
    best = found["chi2"]["gain=1 / gain=2"]
    assert best > 1e4 and best == max(found["scores"])
    assert d.separating.name == d.candidates[found["best"]]["name"]
    write_design(d, tmp_path / "design")
    frame = pd.read_csv(tmp_path / "design" / "design_structures_input.csv")
    assert frame.u.abs().max() <= 1.0 and frame.u.abs().max() > 0.5
    assert "Structures the study cannot tell apart" in d.markdown()
    # a study whose structures were told apart gets no such proposal
    result.structure = {"chosen": "gain=1", "indistinguishable": []}
    assert design(result, DesignOptions(inputs={"u": [-1.0, 1.0]}, bands=1)).separating is None


def test_a_smooth_input_gets_sines_not_steps():
    """A position whose derivatives feed the model must not jump: where a square wave is
    asked for it gets a sine at that frequency (and the multisine over one frequency was
    no sine at all: its Schroeder phases cancelled to rounding noise)."""
    t = np.round(np.arange(0, 10.0 + 1e-9, 0.001), 9)
    found = candidates(t, [(-1.0, 1.0), (-0.036, 0.036)], (0.2, 10.0), ["steps", "prbs"], 3, 0,
                       smooth=[False, True])  # fmt: skip
    for s in found:
        position = s.values[:, 1]
        step = np.abs(np.diff(position)).max()
        # at most the slope of a sine at the band's top, sampled at 1 kHz
        assert step <= 0.036 * 2 * np.pi * 10.0 * 0.001 * 1.01, s.name
        assert np.ptp(position) > 0.036  # and it moves
    assert {np.abs(np.diff(s.values[:, 0])).max() for s in found if s.kind == "steps"} == {2.0}


def test_a_differentiated_column_is_designed_only_where_der_is_accurate():
    """der() is a Savitzky-Golay derivative of 21 samples: at 1 kHz the second
    derivative of a 10 Hz sine comes out 3 % low, and the MISO stage designed up to 10 Hz
    gave intervals that excluded the truth on every seed. The band of such a column ends
    where der() is accurate to DER_ERROR."""
    import sys

    plan = sys.modules["tsid_fmu.design.plan"]
    cap = plan._cap(["der(x_o)", "der(x_o, 2)"], "x_o", 1e-3, (0.2, 10.0))
    assert 1.0 < cap < 2.5
    assert plan._cap(["der(x_o)"], "x_o", 1e-3, (0.2, 10.0)) > cap  # the first order: higher
    assert plan._cap(["F_of - F_or"], "x_o", 1e-3, (0.2, 10.0)) == 10.0  # no der(): no cap
    t = np.round(np.arange(0, 10.0 + 1e-9, 0.001), 9)
    found = candidates(t, [(-1.0, 1.0), (-0.036, 0.036)], (0.2, 10.0), ["chirp", "steps"], 3,
                       0, smooth=[False, True], caps=[10.0, cap])  # fmt: skip
    for s in found:
        spectrum = np.abs(np.fft.rfft(s.values[:, 1] - s.values[:, 1].mean()))
        freqs = np.fft.rfftfreq(t.size, 0.001)
        assert freqs[np.argmax(spectrum)] <= cap * 1.05, s.name


def test_offsets_that_act_through_one_sum_are_named_as_that_sum():
    """Three position offsets of which the output sees only a + b + c / 2 (OpenModelica's
    Mass_Damper: the housing's offset, the spring's length and half the mass's): two
    directions no input separates, and one combination across them, named as a sum
    whatever the rotation of the two directions."""
    import sys

    from tsid_fmu.doe.options import LevelingOptions
    from tsid_fmu.search.space import Space

    across = sys.modules["tsid_fmu.design.across"]
    levels = {n: [0.0, 2.0] for n in ("a", "b", "c")}
    space = Space(levels, {n: (-10.0, 10.0) for n in levels}, LevelingOptions(scale="linear"))
    fixed = np.array([1.0, 1.0, 0.5]) * space.width  # the functional, in search coordinates
    null = np.linalg.svd(np.eye(3) - np.outer(fixed, fixed) / (fixed @ fixed))[0][:, :2]
    rotation = np.array([[0.6, -0.8], [0.8, 0.6]])
    x = {"a": 0.3, "b": 0.4, "c": 0.6}
    cov = 1e-6 * np.outer(fixed, fixed) / (fixed @ fixed)
    for basis in (null, null @ rotation):
        members, found = across.combinations_across(space, x, basis, cov)
        assert members == ["a", "b", "c"]
        (combo,) = found
        assert combo["name"] == "a + b + 0.5 c"
        assert combo["value"] == pytest.approx(0.3 + 0.4 + 0.3)
        low, high = combo["interval"]
        assert low < combo["value"] < high


def test_a_study_whose_outputs_never_moved_leaves_every_axis_weak():
    """A nut held below its break-away force: the outputs do not depend on any
    parameter, the study's information is zero, and every open parameter is weak along
    its own axis (a regularised inverse of zero had overflowed to nan)."""
    import sys

    from tsid_fmu.doe.options import LevelingOptions
    from tsid_fmu.search.space import Space

    run = sys.modules["tsid_fmu.design.run"]
    space = Space({"a": [1.0, 10.0], "b": [1.0, 10.0]}, {"a": (0, 100), "b": (0, 100)},
                  LevelingOptions())  # fmt: skip
    result = SimpleNamespace(intervals={"a": [None, None], "b": [None, None]}, uncertainty=None)
    weak = run._weak(result, space, np.zeros((2, 2)))
    assert np.all(np.isfinite(weak)) and weak.shape == (2, 2)


def test_the_readme_and_the_cli_reference_show_tsid_design():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    readme = (root / "README.md").read_text(encoding="utf-8")
    assert "tsid design study.toml --result results/plant" in readme
    assert "docs/how-to/experiment-design.md" in readme
    assert "tsid design STUDY.toml --result DIR" in (root / "docs/reference/cli.md").read_text()


def test_a_candidate_that_leaves_a_target_unseen_scores_worst_not_nan():
    """np.argmax takes a nan for the largest: an A score must never be nan."""
    import sys

    run = sys.modules["tsid_fmu.design.run"]
    keep, targets = np.eye(2), np.eye(2)[:, :1]
    blind = run._score(np.diag([0.0, 4.0]), keep, targets, "A")
    seeing = run._score(np.diag([1.0, 4.0]), keep, targets, "A")
    assert math.isfinite(blind) and seeing > blind
    assert int(np.argmax([blind, seeing])) == 1


def test_the_design_simulates_through_the_interface_the_identification_chose(tmp_path):
    """The design re-simulates at the answer: through the interface identify's solver
    fidelity check chose (Mass_Damper's Co-Simulation, a fixed Euler step, had left
    residuals 330 times the noise where Model Exchange had been chosen)."""
    import sys

    from tsid_fmu.uncertainty.fidelity import chosen_interface

    make_plan = sys.modules["tsid_fmu.design.plan"].make_plan
    result = _lag(tmp_path)
    options = DesignOptions(inputs={"u": [-1.0, 1.0]}, bands=2)
    for chosen in ("me", "cs"):
        result.fidelity = {"interface": chosen}
        assert chosen_interface(result.fidelity) == chosen
        assert make_plan(result, options).spec.interface == chosen
    assert chosen_interface({}) is None and chosen_interface(None) is None

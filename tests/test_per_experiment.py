"""Per-experiment parameters (issue 29, items 2 and 3): ``per_experiment = true`` and
``initial = { x0 = "identify" }``.

Two records of the first-order lag (``der(x) = (u - x) / tau``, ``y = x``), each from
its own initial position, made by SciPy's ``solve_ivp`` (not by the FMU): the time
constant is shared, the initial state ``x0`` differs per experiment.
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_c_fmu
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

from tsid_fmu import Experiment, Parameter, Phase, Study, identify, load
from tsid_fmu.errors import StudyError
from tsid_fmu.report.html import html_report
from tsid_fmu.report.markdown import markdown_report
from tsid_fmu.report.scored import initial_note, per_experiment_note
from tsid_fmu.scaffold import init_study
from tsid_fmu.study.prepare import prepare, serial_evaluator

TAU, SIGMA = 0.37, 0.002
X0 = {"a": 0.8, "b": -0.5}


@pytest.fixture(scope="module")
def lag_fmu(tmp_path_factory):
    return build_c_fmu(tmp_path_factory.mktemp("lag"), interfaces=("cs",))


def lag_ivp(t: np.ndarray, u: np.ndarray, tau: float, x0: float) -> np.ndarray:
    """The lag's state at ``t`` by ``solve_ivp``, ``u[k]`` held over each sample interval."""
    x = np.empty(t.size)
    x[0] = x0
    for k in range(t.size - 1):
        sol = solve_ivp(
            lambda _t, s, uk=u[k]: (uk - s) / tau, (t[k], t[k + 1]), [x[k]], rtol=1e-10, atol=1e-12
        )
        x[k + 1] = sol.y[0, -1]
    return x


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    folder = tmp_path_factory.mktemp("records")
    out = {}
    for k, (name, x0) in enumerate(X0.items()):
        t = np.arange(0, 3.0 + 1e-9, 0.01)
        u = np.where((t % 2.0) < 1.0, 1.0, -0.5) + 0.3 * np.sin(3 * t + k)
        y = lag_ivp(t, u, TAU, x0) + np.random.default_rng(k).normal(0, SIGMA, t.size)
        pd.DataFrame({"time": t, "u": u, "y": y}).to_csv(folder / f"{name}.csv", index=False)
        out[name] = folder / f"{name}.csv"
    return out


def study(fmu, records, x0: Parameter | None, initial=None, **method) -> Study:
    params = [Parameter("tau", [0.1, 0.4, 1.6], min=0.01, unit="s")]
    params += [x0] if x0 is not None else []
    exps = [
        Experiment(
            data=path,
            name=name,
            inputs={"u": "u"},
            outputs={"y": "y"},
            initial=dict((initial or {}).get(name, {})),
        )
        for name, path in records.items()
    ]
    options = {"cost": "sse", "weighting": "noise", "replicates": 1, **method}
    return Study(fmu=fmu, parameters=params, experiments=exps, **options)


def per_experiment(**kw) -> Parameter:
    return Parameter("x0", [-1.0, 0.0, 1.0], per_experiment=True, **kw)


def joint_optimum(s: Study, start: dict[str, float]) -> float:
    """The least-squares optimum of the stacked residuals by SciPy, from ``start``."""
    names = s.parameter_names
    with serial_evaluator(s) as ev:

        def residuals(v: np.ndarray) -> np.ndarray:
            return np.asarray(ev.evaluate([dict(zip(names, v, strict=True))]).residuals[0])

        fit = least_squares(residuals, [start[n] for n in names], x_scale="jac", xtol=1e-12)
    return float(np.sum(fit.fun**2))


@pytest.mark.slow
def test_each_experiment_gets_its_own_initial_position(lag_fmu, records, tmp_path):
    s = study(lag_fmu, records, per_experiment())
    assert s.parameter_names == ["tau", "x0[a]", "x0[b]"]
    res = identify(s, tmp_path / "out", plots=False, workers=1)
    truth = {"tau": TAU, **{f"x0[{n}]": v for n, v in X0.items()}}
    for name, value in truth.items():
        low, high = res.intervals[name]
        assert low <= value <= high, (name, value, low, high)
    # the shared parameter and the copies at the least-squares optimum of the joint cost
    assert res.fun <= 1.001 * joint_optimum(s, truth)
    # the arrays ran over the shared parameter only: copies held, not factors
    taguchi = next(st for st in res.stages if st.kind == "taguchi")
    assert all(rec.parameters == ["tau"] for rec in taguchi.records)
    # each copy is reported, and reads back from the output folder
    assert {"x0[a]", "x0[b]"} <= set(res.parameters_frame().index)
    note = "Identified per experiment (one row each in the parameter table): x0 (x0[a], x0[b])"
    assert note in html_report(res) and note in markdown_report(res)
    assert "| x0[b] |" in markdown_report(res)
    again = load(tmp_path / "out", study=s)
    assert again.params == pytest.approx(res.params)
    assert not again.warnings or all("changed" not in w for w in again.warnings)
    assert set(again.parameters_frame().index) == set(s.parameter_names)
    saved = json.loads((tmp_path / "out" / "result.json").read_text())
    assert set(saved["params"]) >= {"x0[a]", "x0[b]"}


@pytest.mark.slow
def test_one_shared_initial_position_cannot_fit_both(lag_fmu, records):
    own = identify(study(lag_fmu, records, per_experiment()), plots=False, workers=1)
    shared = identify(
        study(lag_fmu, records, Parameter("x0", [-1.0, 0.0, 1.0])), plots=False, workers=1
    )
    assert shared.fun > 10 * own.fun
    low, high = own.intervals["tau"]
    assert not low <= shared.params["tau"] <= high


def test_identify_is_a_per_experiment_parameter(lag_fmu, records):
    s = study(
        lag_fmu,
        records,
        Parameter("x0", [-1.0, 0.0, 1.0]),
        initial={n: {"x0": "identify"} for n in records},
    )
    marked = study(lag_fmu, records, per_experiment())
    assert s.parameter_names == marked.parameter_names == ["tau", "x0[a]", "x0[b]"]
    spec = prepare(s)
    assert [e.copies for e in spec.experiments] == [{"x0[a]": "x0"}, {"x0[b]": "x0"}]
    assert all("x0" not in e.start_values for e in spec.experiments)
    # the report says they were identified, not set from the data
    assert initial_note(SimpleNamespace(study=s)) == ""
    assert "x0 (x0[a], x0[b])" in per_experiment_note(SimpleNamespace(study=s))


def test_a_copy_moves_its_own_experiment_only(lag_fmu, records):
    s = study(lag_fmu, records, per_experiment())
    n = len(pd.read_csv(records["a"]))
    with serial_evaluator(s) as ev:
        one, other = ev.evaluate(
            [
                {"tau": TAU, "x0[a]": 0.8, "x0[b]": -0.5},
                {"tau": TAU, "x0[a]": 0.8, "x0[b]": 0.3},
            ]
        ).residuals
        nfev = ev.nfev
    assert np.array_equal(one[:n], other[:n])  # experiment a: the same
    assert not np.allclose(one[n:], other[n:])  # experiment b: moved
    assert abs(one[n]) < 5 and abs(other[n]) > 100  # b's first sample, in noise units
    # a's outputs were reused for the second set (the Jacobian's block-sparse columns):
    # three simulations, not four, and the same residuals as a fresh run
    assert nfev == 3
    with serial_evaluator(s) as fresh:
        alone = fresh.evaluate([{"tau": TAU, "x0[a]": 0.8, "x0[b]": 0.3}]).residuals[0]
    assert np.array_equal(alone, other)


def test_held_copies_and_one_experiment(lag_fmu, records):
    """The arrays' runs hold each copy in its own experiment; one experiment: one copy."""
    from tsid_fmu.evaluators import StudyEvaluators

    s = study(lag_fmu, records, per_experiment())
    spec = StudyEvaluators(s, {}, None).spec(["tau"], ["a", "b"], {"x0[a]": 0.3, "x0[b]": -0.2})
    assert [e.start_values for e in spec.experiments] == [{"x0": 0.3}, {"x0": -0.2}]
    assert spec.start_values == {}
    alone = study(lag_fmu, {"a": records["a"]}, per_experiment())
    assert alone.parameter_names == ["tau", "x0[a]"]


def test_an_experiment_that_fixes_it_has_no_copy(lag_fmu, records):
    s = study(lag_fmu, records, per_experiment(), initial={"b": {"x0": "from_data:y"}})
    assert s.parameter_names == ["tau", "x0[a]"]
    first = float(pd.read_csv(records["b"])["y"].iloc[0])
    assert prepare(s).experiments[1].start_values == {"x0": first}


def _refused(fmu, records, case: str) -> Study:
    if case == "no range":
        return study(fmu, records, None, initial={"a": {"x0": "identify"}})
    if case == "unknown":
        return study(fmu, records, Parameter("x00", [0, 1], per_experiment=True))
    if case == "not settable":
        return study(fmu, records, Parameter("y", [0, 1]), initial={"a": {"y": "identify"}})
    if case == "all":
        s = study(fmu, records, per_experiment())
        return Study(s.fmu, [per_experiment()], s.experiments, s.method)
    if case == "validate":
        s = study(fmu, records, per_experiment())
        s.experiments[1].role = "validate"
        return Study(s.fmu, s.parameters, s.experiments, s.method)
    if case == "every fixes":
        start = {n: {"x0": "from_data:y"} for n in records}
        return study(fmu, records, per_experiment(), initial=start)
    if case == "no refinement":
        return study(fmu, records, per_experiment(), refine="none")
    if case == "iae":
        return study(fmu, records, per_experiment(), cost="iae", weighting="none")
    s = study(fmu, records, per_experiment())
    return Study(s.fmu, s.parameters, s.experiments, s.method, phases=[Phase(["tau"])])


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("no range", "experiment 'a': initial 'x0' = \"identify\" needs a range"),
        ("unknown", "experiment 'a': per-experiment parameter 'x00': FirstOrderLag.fmu: unknown"),
        ("not settable", "experiment 'a': per-experiment parameter 'y': FirstOrderLag.fmu does"),
        ("all", "every parameter is per experiment"),
        ("validate", "experiment 'b' (role 'validate'): 'x0' is identified per experiment"),
        ("every fixes", "parameter 'x0' is per experiment, but every experiment fixes it"),
        ("no refinement", "refine = 'none'"),
        ("iae", "refine = 'auto' with cost = 'iae'"),
        ("phases", "cannot be combined with [[phases]]"),
    ],
)
def test_what_cannot_be_identified_per_experiment_is_refused(lag_fmu, records, case, message):
    with pytest.raises(StudyError) as err:
        prepare(_refused(lag_fmu, records, case))
    assert message in str(err.value)


def test_per_experiment_and_identify_read_and_write_as_toml(lag_fmu, records, tmp_path):
    (tmp_path / "s.toml").write_text(
        f'[study]\nfmu = "{lag_fmu}"\n[method]\ncost = "sse"\n'
        f'[[experiments]]\nfile = "{records["a"]}"\ninputs = {{ u = "u" }}\n'
        'outputs = { y = "y" }\ninitial = { x0 = "identify" }\n'
        f'[[experiments]]\nfile = "{records["b"]}"\ninputs = {{ u = "u" }}\n'
        'outputs = { y = "y" }\n'
        "[parameters]\ntau = { levels = [0.1, 1.0] }\n"
        "x0 = { levels = [-1, 1], per_experiment = true }\n"
    )
    s = Study.from_toml(tmp_path / "s.toml")
    assert s.parameter_names == ["tau", "x0[a]", "x0[b]"]
    assert s.experiments[0].initial == {"x0": "identify"}
    assert Study.from_toml(s.to_toml(tmp_path / "again.toml")) == s
    text = (tmp_path / "s.toml").read_text().replace("per_experiment = true", "per_experiment = 1")
    (tmp_path / "bad.toml").write_text(text)
    with pytest.raises(StudyError, match=r"\[parameters\] x0 per_experiment must be true or false"):
        Study.from_toml(tmp_path / "bad.toml")


def test_init_writes_an_identify_hint_that_reads_back(tmp_path):
    from test_init import SISO

    text = init_study(
        SISO.parents[1] / "fmus" / "LSEA_SISO.fmu", SISO / "measured.csv", tmp_path / "s.toml"
    )
    assert '#   initial = { x_m = "identify" }' in text
    assert "per_experiment = true in an entry identifies one value per experiment" in text
    lines = text.replace('#   initial = { x_m = "identify" }', 'initial = { x_m = "identify" }')
    lines = lines.replace(
        "[parameters]\n", '[parameters]\nx_m = { levels = [-0.01, 0, 0.01], unit = "m" }\n', 1
    )
    (tmp_path / "s2.toml").write_text(lines)
    s = Study.from_toml(tmp_path / "s2.toml")
    assert [n for n in s.parameter_names if n.startswith("x_m")] == ["x_m[measured]"]
    assert prepare(s).experiments[0].copies == {"x_m[measured]": "x_m"}


def test_screening_screens_each_copy(lag_fmu, records):
    from tsid_fmu import screen

    found = screen(study(lag_fmu, records, per_experiment()), n=4, workers=1, timeout=0)
    assert found.parameters == ["tau", "x0[a]", "x0[b]"]

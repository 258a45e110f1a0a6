"""Bad input to the newer features ends in one clear line, or a correct result (issue 44).

Each test is one of the issue's reproducers: discrete choices, choices among FMU files,
windows and weights, ``initial``, the sampled uncertainty, ``tsid screen``, the command
line's counts and the Python API.
"""

from __future__ import annotations

import re
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_c_fmu
from spec_helpers import experiment, lag_frame, make_spec
from test_choices import DESCRIPTION

from tsid_fmu import Choice, Experiment, Method, Parameter, Study, StudyError, identify
from tsid_fmu.cli import main
from tsid_fmu.evaluate import PoolEvaluator
from tsid_fmu.load import load
from tsid_fmu.screening import screen
from tsid_fmu.study import load_study

REPO = Path(__file__).resolve().parents[1]
SISO = REPO / "examples" / "lsea_siso" / "study.toml"
FMUS = REPO / "fmus"


def _switches(folder: Path, description: str = DESCRIPTION) -> Study:
    fmu = folder / "Switches.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", description.format("{1234}"))
    (folder / "d.csv").write_text("time,y\n0,0\n1,1\n")
    return fmu


def _with(folder: Path, *choices, description: str = DESCRIPTION) -> Study:
    return Study(
        fmu=_switches(folder, description),
        parameters=[Parameter("D", [1.0, 2.0, 3.0]), *choices],
        experiments=[Experiment(folder / "d.csv", outputs={"y": "y"})],
    )


# -- 1, 2: integer choices the FMU cannot hold ------------------------------------------


@pytest.mark.parametrize("big", [2147483648, 1e20, -2147483649])
def test_an_integer_choice_outside_32_bits_is_refused(tmp_path, big):
    with pytest.raises(StudyError, match=r"'masses': .* does not fit an FMI Integer"):
        _with(tmp_path, Choice("masses", [1, big]))


def test_an_integer_choice_outside_the_declared_range_is_refused(tmp_path):
    declared = DESCRIPTION.replace('<Integer start="1"/>', '<Integer start="1" max="3"/>')
    with pytest.raises(StudyError, match=r"'masses': 4 is outside the range the FMU declares"):
        _with(tmp_path, Choice("masses", [1, 4]), description=declared)
    assert _with(tmp_path, Choice("masses", [1, 3]), description=declared).choices


# -- 3, 4, 5: choices among FMU files ------------------------------------------------------


@pytest.fixture
def variants(tmp_path) -> Path:
    for name in ("LagA", "LagB"):
        build_c_fmu(tmp_path, name)
    pd.DataFrame({"time": [0.0, 0.1, 0.2], "u": [1.0] * 3, "y": [0, 0.1, 0.2]}).to_csv(
        tmp_path / "d.csv", index=False
    )
    return tmp_path


def _variant_study(folder: Path, params: str, study: str = "") -> Study:
    text = f"""[study]\n{study}
[data]
file = "d.csv"
inputs = {{ u = "u" }}
outputs = {{ y = "y" }}
[method]
weighting = "none"  # exact data: no noise to weight by
[parameters]
tau = {{ levels = [0.5, 1.0, 2.0], min = 0.01 }}
variant = {{ fmus = ["LagA.fmu", "LagB.fmu"] }}
{params}"""
    (folder / "s.toml").write_text(text)
    return Study.from_toml(folder / "s.toml")


def test_an_unknown_parameter_beside_fmu_variants_is_refused(variants):
    with pytest.raises(StudyError, match=r"unknown parameter\(s\) 'Foo': no FMU variant"):
        _variant_study(variants, "Foo = { levels = [1, 2, 3] }")


def test_a_study_fmu_that_is_no_variant_is_refused(variants):
    build_c_fmu(variants, "Other")
    with pytest.raises(StudyError, match=r"\[study\] fmu Other\.fmu is not one of the FMU"):
        _variant_study(variants, "", 'fmu = "Other.fmu"')
    assert _variant_study(variants, "", 'fmu = "LagB.fmu"').variants is not None


@pytest.mark.parametrize("order", [("LSEA_SISO", "LSEA_SISO_Friction"), ("LSEA_SISO_Friction",
                                   "LSEA_SISO")])  # fmt: skip
def test_a_choice_only_one_variant_has_does_not_depend_on_their_order(tmp_path, order):
    for name in order:
        shutil.copy(FMUS / f"{name}.fmu", tmp_path)
    data = pd.read_csv(REPO / "examples" / "lsea_siso" / "measured.csv").iloc[:50]
    data.assign(F_o=data["F_of"] - data["F_or"]).to_csv(tmp_path / "d.csv", index=False)
    files = ", ".join(f'"{n}.fmu"' for n in order)
    (tmp_path / "s.toml").write_text(f"""[data]
file = "d.csv"
inputs = {{ F_m = "F_m" }}
outputs = {{ F_o = "F_o" }}
[parameters]
K_s = {{ levels = [4000, 8000, 12000] }}
friction = {{ choices = [1, 2] }}
model = {{ fmus = [{files}] }}
""")
    study = Study.from_toml(tmp_path / "s.toml")
    assert [c.name for c in study.choices] == ["friction", "model"]


# -- 6, 7, 13: keys that clash, do nothing or overflow ------------------------------------


def test_study_start_values_and_an_experiments_initial_clash(tmp_path):
    text = SISO.read_text().replace(
        'outputs = { F_o = "F_o", x_m = "x_m" }',
        'outputs = { F_o = "F_o", x_m = "x_m" }\ninitial = { V_z = "from_data:x_m" }',
    )
    (tmp_path / "s.toml").write_text(text.replace('"../../fmus', f'"{FMUS}').replace(
        'file = "measured.csv"', f'file = "{SISO.parent / "measured.csv"}"'))  # fmt: skip
    with pytest.raises(StudyError, match=r"initial 'V_z' is also fixed in \[study\] start_values"):
        load_study(tmp_path / "s.toml")


def test_uncertainty_replicates_without_sampled_uncertainty_is_refused():
    with pytest.raises(StudyError, match="uncertainty_replicates = 50 has no effect"):
        Method(uncertainty_replicates=50)
    Method(cost="sse", uncertainty="bootstrap", uncertainty_replicates=50)


@pytest.mark.parametrize("key", ["window_weights", "weights"])
def test_a_weight_that_overflows_the_cost_is_refused(tmp_path, key):
    frame = pd.DataFrame({"time": [0.0, 1.0, 2.0], "y": [0.0, 1.0, 2.0]})
    kw = (
        {"windows": [[0, 1], [1.5, 2]], "window_weights": [1e308, 1e308]}
        if key == "window_weights"
        else {"weights": {"y": 1e300}}
    )
    with pytest.raises(StudyError, match=rf"{key}: 1e\+30\d is above 1e\+12"):
        Experiment(frame, outputs={"y": "y"}, **kw)


# -- 8, 9, 11, 16, 20: the command line's counts -------------------------------------------


@pytest.mark.parametrize(
    "option",
    [["--max-iterations", "0"], ["--max-iterations", "-1"], ["--pause-after", "-1"],
     ["--pause-after", "0"], ["--resume", "--continue-from-run", "0"],
     ["--resume", "--continue-from-run", "-1"]],
)  # fmt: skip
def test_counts_below_1_are_refused_by_the_command_line(tmp_path, capsys, option):
    with pytest.raises(SystemExit) as stop:
        main(["identify", str(SISO), "--out", str(tmp_path / "o"), *option])
    assert stop.value.code == 2
    assert re.search(rf"{option[-2]}: .*must be at least 1", capsys.readouterr().err)


@pytest.mark.slow
def test_continue_from_a_run_the_iteration_does_not_have_is_bad_input(tmp_path, capsys):
    out = tmp_path / "o"
    args = ["identify", str(SISO), "--out", str(out), "--workers", "1", "-q", "--no-plots"]
    assert main([*args, "--pause-after", "1"]) == 3
    capsys.readouterr()
    assert main([*args, "--resume", "--continue-from-run", "999"]) == 2
    err = capsys.readouterr().err
    assert "continue from run 999: iteration 1 of taguchi has runs 1 to 25" in err


def test_too_many_workers_are_refused_naming_the_override(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("TSID_FMU_MAX_WORKERS", raising=False)
    assert main(["identify", str(SISO), "--out", str(tmp_path / "o"), "--workers", "10000"]) == 2
    assert "set TSID_FMU_MAX_WORKERS=10000 to allow it" in capsys.readouterr().err


def test_an_interrupted_screen_does_not_offer_resume(capsys):
    from tsid_fmu.cli_exits import interrupted as _interrupted

    assert _interrupted(True, ["screen", "study.toml"]) == 143
    assert "--resume" not in capsys.readouterr().err
    assert _interrupted(False, ["identify", "study.toml"]) == 130
    assert "continue with --resume" in capsys.readouterr().err


# -- 17: a result without its checksum ---------------------------------------------------


def test_a_result_without_its_checksum_is_not_said_to_be_old_only(tmp_path):
    import json

    from fmu_factory import lag_study

    study = lag_study(tmp_path, max_iterations=2)
    identify(study, tmp_path / "o", plots=False, workers=1, timeout=0)
    path = tmp_path / "o" / "result.json"
    data = json.loads(path.read_text())
    del data["digest"]
    data["params"]["tau"] = 9.0
    path.write_text(json.dumps(data))
    res = load(tmp_path / "o")
    note = next(w for w in res.warnings if "no checksum" in w)
    assert "or the checksum was removed" in note and "not a forger" in note


# -- 18, 19: the screening's size ----------------------------------------------------------


def test_a_screening_too_large_or_too_small_says_so(tmp_path):
    from fmu_factory import lag_study

    pytest.importorskip("SALib")
    study = lag_study(tmp_path)
    with pytest.raises(StudyError, match=r"n = 1000000000 asks for 3,000,000,000 parameter"):
        screen(study, "morris", 1_000_000_000)
    res = screen(study, "sobol", 2, workers=1, timeout=0, contribution=False)
    assert any("Sobol with n = 2 base samples" in w for w in res.warnings)


# -- 21: a time limit shorter than every simulation ---------------------------------------


def test_a_time_limit_holds_for_simulations_that_finish_before_it_is_checked(lag_crash_fmus):
    spec = make_spec(
        lag_crash_fmus["lag"],
        ["tau", "x0"],
        [experiment(lag_frame(1), {"u": "u"}, {"y": "y"}, name="a", index=0)],
        cost="sse",
    )
    with PoolEvaluator(spec, workers=1, timeout=1e-9) as ev:
        got = ev.evaluate([{"tau": 0.1, "x0": 0.0}, {"tau": 0.2, "x0": 0.0}])
    assert all(e is not None and "time limit of 1e-09 s" in e for e in got.errors), got.errors
    assert np.isinf(got.costs).all()


# -- 22, 23: the Python API -----------------------------------------------------------------


def test_numpy_scalars_are_numbers():
    p = Parameter("K_s", [np.int64(1000), np.float32(2000.5), 3000], min=np.float64(0))
    assert p.levels == [1000.0, 2000.5, 3000.0]
    assert Method(max_iterations=np.int64(5)).max_iterations == 5
    with pytest.raises(StudyError):
        Parameter("K_s", [np.bool_(True), 2.0])


@pytest.mark.parametrize(
    ("make", "error", "message"),
    [
        (lambda s: Study(s.fmu, s.parameters, "abc"), TypeError, "experiments must be a list"),
        (lambda s: Study(s.fmu, "F_cm", s.experiments), TypeError, "parameters must be a list"),
        (lambda s: Experiment(data=None, outputs={"x": "x"}), TypeError, "data must be a file"),
        (lambda s: Experiment(SISO.parent / "measured.csv", outputs={"x_m": "x_m"}, inputs=5),
         TypeError, "inputs must be a mapping"),
        (lambda s: identify(s, None, workers="x"), TypeError, "workers must be a whole number"),
        (lambda s: identify(s, None, timeout="abc"), TypeError, "timeout must be a number"),
        (lambda s: identify(s, None, pause_after="1"), TypeError, "pause_after must be a whole"),
        (lambda s: identify(s, None, max_iterations=0), StudyError, "max_iterations must be at"),
    ],
)  # fmt: skip
def test_the_api_names_the_bad_argument(make, error, message):
    with pytest.raises(error, match=message):
        make(load_study(SISO))


def test_the_api_takes_a_numpy_array_of_parameters_and_none_for_empty_mappings():
    s = load_study(SISO)
    again = Study(s.fmu, np.array(s.parameters, dtype=object), s.experiments)
    assert again.parameter_names == s.parameter_names
    e = Experiment(SISO.parent / "measured.csv", outputs={"x_m": "x_m"}, initial=None)
    assert e.initial == {}


# -- 12, 15: a study with choices cannot pause; a tie's reason matches the pick -------------


def test_a_study_with_choices_refuses_to_pause(variants):
    study = _variant_study(variants, "")
    with pytest.raises(StudyError, match="a study with choices runs whole; it cannot pause"):
        identify(study, variants / "o", pause_after=1)


def test_a_tie_between_equally_simple_structures_does_not_claim_the_simpler():
    import math

    from tsid_fmu.search.structure.selection import Candidate, decide

    n = 100
    a = Candidate("A", {"s": 0.0}, {}, 1.0, 100.0, n, 2, ["x", "y"])
    b = Candidate("B", {"s": 1.0}, {}, 1.0, 99.9, n, 2, ["x", "y"])
    chosen, tied = decide([a, b])
    assert chosen == 1 and tied == [0] and math.isclose(b.chi2, 99.9)
    assert "the lowest BIC is reported" in b.why and "the simpler" not in b.why
    c = Candidate("C", {"s": 2.0}, {}, 1.0, 99.8, n, 3, ["x", "y", "z"])
    chosen, tied = decide([a, c])  # c's lower chi2 does not pay its extra parameter
    assert chosen == 0 and ("the simpler is reported" in a.why or not tied)


# -- 10, 14: tsid simulate and the study's choices -----------------------------------------


def _simulate(folder: Path, capsys, *sets: str) -> tuple[int, str]:
    argv = ["simulate", str(folder / "s.toml"), "--plot", str(folder / "fit.png")]
    for s in sets:
        argv += ["--set", s]
    code = main(argv)
    return code, capsys.readouterr().err


def test_simulate_takes_a_variant_by_name_and_refuses_what_the_study_does_not_choose(
    variants, capsys
):
    _variant_study(variants, "")
    code, err = _simulate(variants, capsys)
    assert code == 2 and "say which with --set variant=VARIANT (LagA, LagB)" in err
    for bad in ("variant=5", "variant=Nope"):
        code, err = _simulate(variants, capsys, bad)
        assert code == 2 and "not one of the study's choices for variant (LagA, LagB)" in err
    code, err = _simulate(variants, capsys, "Foo=3", "variant=LagB")
    assert code == 2 and "Foo" in err
    assert _simulate(variants, capsys, "variant=LagB")[0] == 0
    assert _simulate(variants, capsys, "variant=1")[0] == 0


def test_simulate_refuses_a_value_outside_a_choice(tmp_path, capsys):
    shutil.copy(FMUS / "LSEA_SISO_Friction.fmu", tmp_path)
    data = pd.read_csv(REPO / "examples" / "lsea_siso" / "measured.csv").iloc[:50]
    data.assign(F_o=data["F_of"] - data["F_or"]).to_csv(tmp_path / "d.csv", index=False)
    (tmp_path / "s.toml").write_text("""[study]
fmu = "LSEA_SISO_Friction.fmu"
[data]
file = "d.csv"
inputs = { F_m = "F_m" }
outputs = { F_o = "F_o" }
[method]
array = "L18"
weighting = "none"
[parameters]
K_s = { levels = [4000, 8000, 12000] }
friction = { choices = [1, 2] }
""")
    code, err = _simulate(tmp_path, capsys, "friction=7")
    assert (
        code == 2 and "--set friction=7: not one of the study's choices for friction (1, 2)" in err
    )
    assert _simulate(tmp_path, capsys, "friction=2")[0] == 0

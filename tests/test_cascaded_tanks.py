"""The Cascaded Tanks example (real measurements, issue 63): a short window of the
records fitted fast; (slow) the full example with its Val RMSE in volts, and its
structure chosen by tsid on Est."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pandas as pd
import pytest

from tsid_fmu.cli import main
from tsid_fmu.numerics.tuning import MAX_CANDIDATES

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "cascaded_tanks"

SHORT = """\
[study]
fmu = "{fmu}"
start_values = {{ k5 = 1, k_of = 0.096, x1max = 10, x2max = 11.8, x1_0 = 6.2 }}
[[experiments]]
name = "est"
file = "est.csv"
inputs = {{ u = "u" }}
outputs = {{ y = "y" }}
[[experiments]]
name = "val"
file = "val.csv"
inputs = {{ u = "u" }}
outputs = {{ y = "y" }}
role = "validate"
[method]
start = "centre"
max_iterations = 2
fidelity = false
[parameters]
k1 = {{ levels = [0.02, 0.045, 0.1], min = 0 }}
k3 = {{ levels = [0.02, 0.04, 0.08], min = 0 }}
c = {{ levels = [-2, -1, 0], unit = "V" }}
x2_0 = {{ levels = [5, 7, 9], min = 0, unit = "V" }}
"""


def test_a_short_window_of_the_records_fits_and_validates_in_volts(tmp_path, capsys):
    """The first 100 samples (400 s) of each record, four parameters, others fixed."""
    for name in ("est", "val"):
        pd.read_csv(EXAMPLE / f"{name}.csv").iloc[:100].to_csv(
            tmp_path / f"{name}.csv", index=False
        )
    study = tmp_path / "study.toml"
    study.write_text(SHORT.format(fmu=(REPO / "fmus" / "CascadedTanks.fmu").as_posix()))
    rc = main(["identify", str(study), "--out", str(tmp_path / "out"), "-q", "--no-plots",
               "--workers", "1"])  # fmt: skip
    printed = capsys.readouterr().out
    assert rc in (0, 1), printed
    fit = re.search(r"^fit est: RMSE y (\S+) V, NRMSE \S+, fit \S+ %$", printed, re.M)
    val = re.search(r"^validation val: RMSE y (\S+) V, NRMSE \S+, fit \S+ %; cost", printed, re.M)
    assert fit and val, printed
    assert 0 < float(fit[1]) < 1.0 and 0 < float(val[1]) < 2.0, printed


@pytest.mark.slow
def test_the_full_example_converges_and_prints_the_val_rmse_in_volts(tmp_path, capsys):
    """The example as committed: exit 0, Val RMSE in V at most 0.343 (issue 63: below the
    published NLSS2's 0.34 as rounded; measured 0.2449), in the simulations measured
    (1732; the issue's 2000)."""
    rc = main(["identify", str(EXAMPLE / "study.toml"), "--out", str(tmp_path / "out"),
               "--no-plots"])  # fmt: skip
    printed = capsys.readouterr().out
    assert rc == 0, printed
    val = re.search(r"^validation val: RMSE y (\S+) V, NRMSE \S+, fit \S+ %; cost", printed, re.M)
    assert val, printed
    assert float(val[1]) <= 0.343, printed
    ran = re.search(r"^converged: the answer is stationary \((\d+) simulations\)", printed, re.M)
    assert ran and int(ran[1]) <= 2000, printed


@pytest.mark.slow
def test_the_structure_is_chosen_on_est_by_tsid_itself(tmp_path, capsys):
    """``structure.toml``: the FMU's four switches as choices (24 structures), chosen by BIC
    on Est. The mixed arrays' eight best candidates miss the structure BIC chooses among
    all (measured: their choice, Torricelli's exponents and a linear pump, Est RMSE
    0.255 V); the comparison's neighbours of its choice reach it (issue 63, item 3)."""
    out = tmp_path / "out"
    rc = main(["identify", str(EXAMPLE / "structure.toml"), "--out", str(out), "--no-plots"])
    printed = capsys.readouterr().out
    assert rc == 0, printed
    chosen = "outflow=1, pump=1, overflow=1, rim=1"
    assert re.search(rf"^structure: {chosen}: the lowest BIC", printed, re.M), printed
    result = json.loads((out / "result.json").read_text())
    rows = next(s for s in result["stages"] if s["kind"] == "comparison")["extra"]["structures"]
    assert len(rows) > MAX_CANDIDATES  # neighbours of the choice were refined too
    fit = re.search(r"^fit est: RMSE y (\S+) V", printed, re.M)
    val = re.search(r"^validation val: RMSE y (\S+) V, NRMSE \S+, fit \S+ %; cost", printed, re.M)
    assert fit and float(fit[1]) <= 0.165, printed  # the example's 0.162
    assert val and float(val[1]) <= 0.343, printed
    # every structure is a poor fit here (model error): own studies for it stop once one
    # changes nothing (measured 13195 simulations; an own study for each: 30217)
    ran = re.search(r"^converged: the answer is stationary \((\d+) simulations\)", printed, re.M)
    assert ran and int(ran[1]) <= 16000, printed

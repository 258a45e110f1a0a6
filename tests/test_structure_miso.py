"""The MISO plant's load side chosen from independent data: a choice among two FMU files.

``benchmarks/structure_miso.py`` on one noise seed per true load side: data from
``examples/lsea_miso/make_data.py`` (not the FMUs), models ``fmus/LSEA_MISO_OneMass.fmu``
(one mass: the load cells carry the spring force) and ``fmus/LSEA_MISO.fmu`` (two
masses). Each must be chosen on its own data, with the least-squares optimum of its
parameters, and the answer must carry only the chosen file's parameters.
"""

from __future__ import annotations

import functools
import importlib.util
import zipfile
from pathlib import Path

import pandas as pd
import pytest

from tsid_fmu import load
from tsid_fmu.report.notebook import parameter_rows
from tsid_fmu.uncertainty.fidelity import start_point

ROOT = Path(__file__).resolve().parents[1]


@functools.cache
def _bench():
    path = ROOT / "benchmarks" / "structure_miso.py"
    spec = importlib.util.spec_from_file_location("bench_structure_miso", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return bench


def test_the_start_point_names_the_study_fmu_among_the_files():
    """The solver check at the start simulates one set: it must name a variant.

    Without a number for the choice the set names no FMU file, and the check stopped the
    study with "model = None names no FMU variant" (found on the MISO load side).
    """
    bench = _bench()
    study = bench.study(2, 1)
    assert study.fmu == bench.FMUS[1].resolve()
    x = start_point(study)
    assert x["model"] == 0.0 and set(x) == {*bench.PARAMS[2], "model"}
    other = start_point(type(study)(**{**study.__dict__, "fmu": bench.FMUS[2]}))
    assert other["model"] == 1.0


@pytest.fixture(scope="module")
def routes(tmp_path_factory):
    """Each true load side's structure route, run once, with its output folder."""
    done: dict[int, tuple[dict, Path]] = {}

    def run(masses: int) -> tuple[dict, Path]:
        if masses not in done:
            folder = tmp_path_factory.mktemp(f"masses{masses}")
            done[masses] = (_bench().structure_route(masses, 1, folder), folder)
        return done[masses]

    return run


@pytest.mark.slow
@pytest.mark.parametrize("masses", [1, 2])
def test_the_true_load_side_is_chosen_with_the_optimum_of_its_parameters(routes, masses):
    r, folder = routes(masses)
    assert r["chosen"] == masses and not r["tied"], r
    assert r["ratio"] <= 1.001, r
    # the answer has the chosen file's parameters only (and the choice's number) ...
    names = _bench().PARAMS[masses]
    assert r["params"] == sorted([*names, "model"]), r
    # ... and so have the tables a person reads: parameters.csv, the report, the CLI's
    table = pd.read_csv(folder / "parameters.csv")
    assert list(table["parameter"]) == names
    assert [row[0] for row in parameter_rows(load(folder))] == [*names, "model"]
    with zipfile.ZipFile(folder / "model.ssp") as ssp:
        packed = [n for n in ssp.namelist() if n.endswith(".fmu")]
    assert packed == [f"resources/{_bench().FMUS[masses].name}"]

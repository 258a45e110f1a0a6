"""Initial states on the SISO rig (issue 29, item 3): ``from_data`` and ``identify``.

Two 2 s records of the LSEA SISO plant whose nut starts away from rest (x_m = 4 mm and
-3 mm), made by the example's independent piecewise-exact solver
(``examples/lsea_siso/make_data.py``: its plant, load cells and encoder), not by the
FMU. The spring stiffness and the moving mass are identified; the friction and damping
are fixed at their truth.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tsid_fmu import Experiment, Parameter, Study, identify

ROOT = Path(__file__).resolve().parents[1]
X0 = {"first": 0.004, "second": -0.003}


def _generator():
    path = ROOT / "examples" / "lsea_siso" / "make_data.py"
    spec = importlib.util.spec_from_file_location("tsid_test_siso_make_data", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


GEN = _generator()


def rig_record(path: Path, x0: float, seed: int, duration: float = 2.0) -> Path:
    """A rig record whose nut starts at ``x0`` (at rest), as ``make_data`` logs one."""
    t = GEN.sample_times(duration)
    f_m = GEN.motor_force(t + 2.0 * seed)  # another stretch of the command per record
    plant = GEN._Plant(GEN.TRUTH, GEN.V_Z)
    z = np.array([x0, 0.0, 0.0, 1.0])
    states = np.zeros((t.size, 2))
    states[0] = z[:2]
    for k in range(t.size - 1):
        z[2] = f_m[k]
        z, _ = GEN._hold_interval(plant, z, float(t[k + 1] - t[k]), GEN.EVENT_TOL)
        states[k + 1] = z[:2]
    x_m, v_m = states.T
    f_o = GEN.TRUTH["B_s"] * v_m + GEN.TRUTH["K_s"] * x_m
    front, rear = GEN.load_cells(
        f_o, GEN.NOISE["F_of"], GEN.NOISE["F_or"], np.random.default_rng(seed)
    )
    encoder = GEN.quantise(x_m, GEN.ENCODER_STEP)
    frame = pd.DataFrame({"time": t, "F_m": f_m, "F_of": front, "F_or": rear, "x_m": encoder})
    frame.to_csv(path, index=False)
    return path


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rig")
    return {n: rig_record(folder / f"{n}.csv", x0, k + 1) for k, (n, x0) in enumerate(X0.items())}


def rig_study(records, how: str | None) -> Study:
    params = [Parameter("K_s", [4000, 8000, 12000], min=1), Parameter("M_m", [2, 5, 8], min=0.01)]
    if how == "identify":  # the range of each experiment's start position
        params.append(Parameter("x_m", [-0.01, 0.0, 0.01], min=-0.05, max=0.05, unit="m"))
    fixed = {k: GEN.TRUTH[k] for k in ("F_cm", "F_vm", "B_s")}
    experiments = [
        Experiment(
            data=path,
            name=name,
            derived={"F_o": "F_of - F_or"},
            inputs={"F_m": "F_m"},
            outputs={"F_o": "F_o", "x_m": "x_m"},
            noise={"x_m": GEN.NOISE["x_m"]},
            initial={"x_m": how} if how else {},
        )
        for name, path in records.items()
    ]
    return Study(
        fmu=ROOT / "fmus" / "LSEA_SISO.fmu",
        parameters=params,
        experiments=experiments,
        start_values={"V_z": GEN.V_Z, **fixed},
        cost="sse",
        weighting="noise",
        replicates=1,
        start="centre",
    )


def inside(result, truth: dict[str, float]) -> dict[str, bool]:
    return {n: result.intervals[n][0] <= v <= result.intervals[n][1] for n, v in truth.items()}


@pytest.mark.slow
def test_both_initial_options_recover_a_start_away_from_zero(records):
    shared = {"K_s": GEN.TRUTH["K_s"], "M_m": GEN.TRUTH["M_m"]}
    ident = identify(rig_study(records, "identify"), plots=False, workers=1)
    copies = {f"x_m[{n}]": x0 for n, x0 in X0.items()}
    assert all(inside(ident, {**shared, **copies}).values()), ident.intervals
    from_data = identify(rig_study(records, "from_data"), plots=False, workers=1)
    assert all(inside(from_data, shared).values()), from_data.intervals
    # the nut at rest at 0 instead: the FMU's start, which these records do not have
    plain = identify(rig_study(records, None), plots=False, workers=1)
    assert plain.fun > 1e3 * max(ident.fun, from_data.fun)
    assert any("mismatch" in w for w in plain.warnings)
    assert not any("mismatch" in w for w in ident.warnings + from_data.warnings)

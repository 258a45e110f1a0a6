"""Close the loop of ``tsid design``'s structure discrimination on the friction-law plant.

Data of friction law 2 (Coulomb + viscous) whose excitation leaves the laws
indistinguishable: a 1 Hz sine of 80 N, below the break-away force (88.5 N), so the
nut never moves and every law explains the data alike (the structure study reports
them indistinguishable). ``tsid design`` proposes the input that best separates the
tied laws at their fitted values (``design_structures_input.csv``); that input's data
are made with the plant's independent simulator (``examples/lsea_siso/friction_laws.py``)
at law 2's truth, added to the study, and the structure study runs again. Counted: on
how many noise seeds the true law is chosen. A measurement, not a test: it exits 0.

Run (about 2 minutes per seed on two cores)::

    python benchmarks/design_structures.py --seeds 10
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "examples" / "lsea_siso"))
sys.path.insert(0, str(HERE.parent / "examples"))
sys.path.insert(0, str(HERE))

import friction_laws as laws  # noqa: E402
import structure as bench  # noqa: E402
from _datagen import load_cells, quantise, sample_times  # noqa: E402

from tsid_fmu import Experiment, Study, identify  # noqa: E402
from tsid_fmu.design import DesignOptions, design  # noqa: E402

TRUE_LAW = 2
AMPLITUDE = 80.0  # N: below the break-away force, so the nut never moves


def _rig(t: np.ndarray, f_m: np.ndarray, seed: int) -> pd.DataFrame:
    x_m, _, f_o = laws.simulate(t, f_m, TRUE_LAW, laws.TRUTH[TRUE_LAW])
    rng = np.random.default_rng(seed)
    front, rear = load_cells(f_o, laws.base.NOISE["F_of"], laws.base.NOISE["F_or"], rng)
    encoder = quantise(x_m, laws.base.ENCODER_STEP)
    return pd.DataFrame({"time": t, "F_m": f_m, "F_of": front, "F_or": rear, "x_m": encoder})


def _experiment(data: pd.DataFrame, name: str) -> Experiment:
    return Experiment(data, inputs={"F_m": "F_m"}, outputs={"F_o": "F_o", "x_m": "x_m"},
                      derived={"F_o": "F_of - F_or"}, noise={"x_m": bench.ENCODER_SIGMA},
                      name=name)  # fmt: skip


def _study(experiments: list[Experiment]) -> Study:
    template = bench.study(TRUE_LAW, 1)
    return Study(fmu=template.fmu, parameters=[*template.parameters, *template.choices],
                 experiments=experiments, start_values=template.start_values,
                 method=template.method, name="tied laws")  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--workers", type=int, default=1)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="tsid-design-laws-"))
    started = time.perf_counter()
    t = sample_times()
    stuck = _experiment(_rig(t, AMPLITUDE * np.sin(2 * np.pi * t), 1), "stuck")
    first = identify(_study([stuck]), work / "first", plots=False, workers=args.workers)
    info = first.structure or {}
    print(f"first study: chose {info.get('chosen')}, indistinguishable "
          f"{info.get('indistinguishable')} ({first.nfev} simulations)")  # fmt: skip
    d = design(first, DesignOptions(inputs={"F_m": [-300.0, 300.0]}), workers=args.workers)
    if d.separating is None:
        print("no discriminating proposal: nothing to verify")
        return 0
    found = d.discrimination or {}
    print(
        f"design ({d.nfev} simulations): to separate {', '.join(found['structures'])}, "
        f"run {d.separating.name}"
    )
    for pair, value in found["chi2"].items():
        print(f"  {pair}: expected chi-square {found['now'][pair]:.3g} on the study's input, "
              f"{value:.3g} with the proposal")  # fmt: skip
    chosen = []
    for seed in range(args.seeds):
        second = _experiment(_rig(d.time, d.separating.values[:, 0], 2000 + seed), "designed")
        res = identify(_study([stuck, second]), work / f"seed{seed}", plots=False,
                       workers=args.workers)  # fmt: skip
        pick = (res.structure or {}).get("chosen")
        chosen.append(pick)
        print(f"seed {seed}: chose {pick} ({res.nfev} simulations)", flush=True)
    right = sum(c == f"friction={TRUE_LAW}" for c in chosen)
    print(f"\nthe true law (friction={TRUE_LAW}) chosen on {right} of {args.seeds} seeds")
    print(f"{time.perf_counter() - started:.0f} s; work folder {work}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

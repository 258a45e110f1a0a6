"""Close the loop of ``tsid design``: predicted against achieved intervals.

``--case siso`` (the default): for the SISO example (``examples/lsea_siso``), identify
the study as shipped (B_s open), run the design, make the proposed experiment's data
with the example's independent simulator at the truth (``examples/lsea_siso/
make_data.py``: the equations solved piecewise exactly, the rig's load cells and
encoder, a new noise draw per seed), add it to the study as a second experiment,
identify again (``--levels around``, the default: five levels from half to twice each
parameter's first answer; ``--levels study``: with the study's own first levels, as a
user adding the experiment to the study file unchanged would), and compare, per parameter, the
achieved 95 % interval with the predicted one (the ratio of their widths, and of their
widths each relative to its own answer; and whether the achieved one holds the truth).
The two ratios differ where the first answer is off along a direction the study left
open (the MISO example's common scale): a width relative to a value that is off by a
factor is off by it too.

``--case motor``: a structural symmetry in two directions (issue 65, case B): a DC
motor measured by its speed only (``benchmarks/problems/motor_speed.py``: five
parameters, three coefficients), one study per noise seed of its data. Counted: the
design proposing nothing and calling the five parameters structural in two directions,
naming ``L Kt^-1 J`` (the leading coefficient), and each combination's interval holding
its value at the truth. Needs pythonfmu.

``--case drag``: a structure whose parameter vanishes and a nesting at a bound (issue
65): the vendor Drag FMU's study choosing ``law`` (``benchmarks/problems/
drag_switch.py``). On data of ``law = 0`` the chosen law leaves ``q`` without a value:
counted, the design proposing an input from that result, and the study run again with
it (the proposal's data from SciPy at the truth) choosing ``law = 0`` with ``tau``'s
interval holding the truth and its width against the predicted one. On data of
``law = 1`` (``q`` = 0.8): the study choosing ``law = 1``, and the nesting test's degrees
of freedom (at least 1). Needs pythonfmu.

``--case miso``: the MISO example's force-only experiment alone (which fixes only the
ratios of m1, K_s, C_d and C_1, not their scale), designed over the motor force and
the stage position (``examples/lsea_miso/make_data.py``'s simulator, the stage
following a cubic spline through the designed positions).

A measurement, not a test: it exits 0 whatever the rows say.
``docs/benchmarks/design.md`` holds the tables of the last run.

Run (about 1 minute per seed on two cores)::

    python benchmarks/design.py --seeds 10 [--workers 2] [--case miso]
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "lsea_siso"


def _make_data_module(example: str):
    path = ROOT / "examples" / example / "make_data.py"
    spec = importlib.util.spec_from_file_location(f"{example}_make_data", path)
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


def _rig_data(md, t: np.ndarray, f_m: np.ndarray, seed: int) -> pd.DataFrame:
    """The proposed experiment as the rig would log it (make_data.py's sensors)."""
    x_m, _, f_o = md.simulate(t, f_m, md.TRUTH)
    rng = np.random.default_rng(seed)
    sys.path.insert(0, str(EXAMPLE.parent))
    from _datagen import load_cells, quantise

    front, rear = load_cells(f_o, md.NOISE["F_of"], md.NOISE["F_or"], rng)
    encoder = quantise(x_m, md.ENCODER_STEP)
    return pd.DataFrame({"time": t, "F_m": f_m, "F_of": front, "F_or": rear, "x_m": encoder})


def _width(iv) -> float:
    if not iv or iv[0] is None or iv[1] is None:
        return math.inf
    return float(iv[1]) - float(iv[0])


class _SplineStage:
    """A stage that follows the designed position samples: a cubic spline through them."""

    def __init__(self, t: np.ndarray, x: np.ndarray) -> None:
        from scipy.interpolate import CubicSpline

        self.x = CubicSpline(t, x)
        self.v, self.a = self.x.derivative(1), self.x.derivative(2)

    def __call__(self, t):
        return self.x(t), self.v(t), self.a(t)

    def position_velocity(self, t: float) -> tuple[float, float]:
        return float(self.x(t)), float(self.v(t))


MISO_STUDY = """\
[study]
name = "LSEA MISO, force only"
fmu = "{fmu}"
[[experiments]]
name = "force only"
file = "{data}"
derived = {{ F_o = "F_of - F_or", v_o = "der(x_o)", a_o = "der(x_o, 2)" }}
inputs = {{ F_m = "F_m", x_o = "x_o", v_o = "v_o", a_o = "a_o" }}
hold = {{ x_o = "linear", v_o = "linear", a_o = "linear" }}
outputs = {{ F_o = "F_o" }}
[method]
cost = "sse"
weighting = "noise"
replicates = 1
max_iterations = 20
refine = "least_squares"
start = "centre"
[parameters]
m1 = {{ levels = [0.15, 0.4, 1.0], min = 0.01, unit = "kg" }}
K_s = {{ levels = [3000, 6000, 12000], min = 10, unit = "N/m" }}
C_d = {{ levels = [0.5, 2, 10], min = 0, unit = "N.s/m" }}
C_1 = {{ levels = [8, 16, 32], min = 0, unit = "N.s/m" }}
# the motor's force limit and the stage's stroke (the example's data: 150 N, 34 mm);
# the highest frequency the stage follows (--miso-band)
[design]
inputs = {{ F_m = [-150.0, 150.0], x_o = [-0.036, 0.036] }}
band = [0.2, {band}]
"""


def _case(name: str, work: Path, band: float = 10.0):
    """Return the case's study file, its independent data maker and its truth."""
    if name == "siso":
        md = _make_data_module("lsea_siso")

        def make(d, seed: int) -> pd.DataFrame:
            return _rig_data(md, d.time, d.proposal.values[:, 0], seed)

        return EXAMPLE / "study.toml", make, md.TRUTH
    md = _make_data_module("lsea_miso")
    study = work / "miso.toml"
    study.write_text(
        MISO_STUDY.format(
            fmu=ROOT / "fmus" / "LSEA_MISO.fmu",
            data=ROOT / "examples" / "lsea_miso" / "force_only.csv",
            band=band,
        )
    )

    def make_miso(d, seed: int) -> pd.DataFrame:
        sys.path.insert(0, str(EXAMPLE.parent))
        from _datagen import load_cells, quantise

        f_m, x_o = (d.proposal.values[:, d.inputs.index(c)] for c in ("F_m", "x_o"))
        f_o = md.simulate(d.time, f_m, _SplineStage(d.time, x_o), md.TRUTH)
        front, rear = load_cells(
            f_o, md.NOISE["F_of"], md.NOISE["F_or"], np.random.default_rng(seed)
        )
        return pd.DataFrame(
            {
                "time": d.time,
                "F_m": f_m,
                "x_o": quantise(x_o, md.ENCODER_STEP),
                "F_of": front,
                "F_or": rear,
            }
        )

    return study, make_miso, md.TRUTH


def _motor(seeds: int, workers: int) -> int:
    """``--case motor``: the design's verdict on a symmetry of two directions, per seed."""
    import tsid_fmu
    from tsid_fmu.design import design

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from problems import motor_speed as motor

    work = Path(tempfile.mkdtemp(prefix="tsid-design-motor-"))
    motor.build(work)
    started, tally = time.perf_counter(), {"none": 0, "two": 0, "named": 0, "hold": 0}
    print(f"{'seed':>4} {'study sims':>10} {'design sims':>11}  verdict")
    for seed in range(seeds):
        study = motor.write_case(work, seed=1 + seed)
        res = tsid_fmu.identify(study, work / f"seed{seed}", plots=False, workers=workers)
        d = design(res, workers=workers)
        fixed = [f for s in d.structural for f in s.fixed]
        two = len(d.structural) == 1 and len(d.structural[0].terms) == 2
        named = any(f.get("coefficients") == {"L": 1.0, "Kt": -1.0, "J": 1.0} for f in fixed)
        hold = bool(fixed) and all(
            f["interval"][0] <= motor.value_of(f, motor.TRUTH) <= f["interval"][1] for f in fixed
        )
        for key, ok in (("none", d.proposal is None), ("two", two), ("named", named),
                        ("hold", hold)):  # fmt: skip
            tally[key] += ok
        print(f"{seed:>4} {res.nfev:>10} {d.nfev:>11}  {d.verdict[:90]}", flush=True)
        for f in fixed:
            print(f"{'':>28}{f['name']} = {f['value']:.5g} {f['interval']} "
                  f"(truth {motor.value_of(f, motor.TRUTH):.5g})")  # fmt: skip
    print(f"\nno proposal {tally['none']}/{seeds}; structural in two directions "
          f"{tally['two']}/{seeds}; J L / Kt named {tally['named']}/{seeds}; every "
          f"combination's interval holds the truth {tally['hold']}/{seeds}")  # fmt: skip
    print(f"{time.perf_counter() - started:.0f} s; work folder {work}")
    return 0


def _drag(seeds: int, workers: int) -> int:
    """``--case drag``: designs from a structure that drops ``q``; the nesting's test."""
    import tsid_fmu
    from tsid_fmu.design import design
    from tsid_fmu.study.definition import fields_of

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from problems import drag_switch as drag

    work = Path(tempfile.mkdtemp(prefix="tsid-design-drag-"))
    drag.build(work)
    started = time.perf_counter()
    tally = {"law0": 0, "proposed": 0, "again": 0, "inside": 0, "law1": 0, "dof": 0}
    ratios = []
    print(f"{'seed':>4}  law 0 data: chosen, design, again (tau achieved/predicted)   "
          "law 1 data: chosen, k of the laws")  # fmt: skip
    for seed in range(seeds):
        study_file = drag.write_case(work, 0, 100 + seed)
        first = tsid_fmu.identify(study_file, work / f"zero{seed}", plots=False,
                                  workers=workers)  # fmt: skip
        chosen0 = first.params.get("law") == 0.0 and "q" not in first.params
        d = design(first, workers=workers)
        cells = [f"law={first.params.get('law'):g}", d.proposal.name if d.proposal else "none"]
        if d.proposal is not None:
            t = d.time
            u = d.proposal.values[:, 0]
            y = drag.response(t, u, drag.TRUTHS[0])
            y = y + np.random.default_rng(1000 + seed).normal(0.0, drag.NOISE, t.size)
            study = tsid_fmu.Study.from_toml(study_file)
            base = study.experiments[0]
            extra = tsid_fmu.Experiment(pd.DataFrame({"time": t, "u": u, "v": y}),
                                        inputs=dict(base.inputs), outputs=dict(base.outputs),
                                        noise=dict(base.noise), name="designed")  # fmt: skip
            two = tsid_fmu.Study(**{**fields_of(study), "experiments": [base, extra],
                                    "name": "with the design"})  # fmt: skip
            res = tsid_fmu.identify(two, work / f"again{seed}", plots=False, workers=workers)
            got, want = res.intervals.get("tau"), d.after[d.names.index("tau")]
            ratio = _width(got) / _width(want)
            inside = got is not None and None not in got and got[0] <= 0.4 <= got[1]
            tally["again"] += res.params.get("law") == 0.0
            tally["inside"] += bool(inside)
            ratios.append(ratio)
            cells.append(f"law={res.params.get('law'):g} {ratio:.2f} {'in' if inside else 'OUT'}")
        tally["law0"] += chosen0
        tally["proposed"] += d.proposal is not None
        rich = drag.write_case(work, 1, 200 + seed)
        other = tsid_fmu.identify(rich, work / f"one{seed}", plots=False, workers=workers)
        ks = {r["structure"]: r["k"] for r in other.structures or []}
        tally["law1"] += other.params.get("law") == 1.0
        tally["dof"] += len(ks) == 2 and abs(ks.get("law=1", 0) - ks.get("law=0", 0)) >= 1
        print(f"{seed:>4}  {' / '.join(cells):<58} law={other.params.get('law'):g}, k {ks}",
              flush=True)  # fmt: skip
    shown = f"{statistics.median(ratios):.2f}" if ratios else "-"
    print(
        f"\nlaw 0 data: law 0 chosen {tally['law0']}/{seeds}; a proposal "
        f"{tally['proposed']}/{seeds}; with it, law 0 chosen {tally['again']} and tau's "
        f"interval holding the truth {tally['inside']}; achieved/predicted median {shown}"
    )
    print(f"law 1 data: law 1 chosen {tally['law1']}/{seeds}; the laws' k differ by at least "
          f"1 {tally['dof']}/{seeds}")  # fmt: skip
    print(f"{time.perf_counter() - started:.0f} s; work folder {work}")
    return 0


def main() -> int:
    import tsid_fmu
    from tsid_fmu.design import design

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--case", choices=["siso", "miso", "motor", "drag"], default="siso")
    ap.add_argument("--miso-band", type=float, default=10.0, help="the stage's band (Hz)")
    ap.add_argument("--levels", choices=["study", "around"], default="around",
                    help="the second study's first levels: the study's own, or around the "
                         "first answer (half to twice)")  # fmt: skip
    args = ap.parse_args()
    if args.case in ("motor", "drag"):  # pythonfmu FMUs: in worker processes
        return (_motor if args.case == "motor" else _drag)(args.seeds, max(args.workers, 2))
    work = Path(tempfile.mkdtemp(prefix="tsid-design-"))
    study_file, make, truth = _case(args.case, work, args.miso_band)
    started = time.perf_counter()
    base = tsid_fmu.identify(study_file, work / "base", plots=False, workers=args.workers)
    d = design(base, workers=args.workers)
    names = d.names
    predicted = dict(zip(names, d.after or [None] * len(names), strict=True))
    print(f"study as shipped: {base.nfev} simulations; design: {d.nfev} simulations")
    print(f"proposal: {d.verdict}")
    limits = ", ".join(
        f"{n} in [{a:g}, {b:g}]" for n, (a, b) in zip(d.inputs, d.limits, strict=True)
    )
    print(f"inputs: {limits}\n")
    if d.proposal is None:
        return 0
    study = tsid_fmu.Study.from_toml(study_file)
    first = study.experiments[0]
    # "around": the first levels the design predicts for and reports (half to twice
    # each answer, inside its bounds: Design.levels); "study": the experiment added to
    # the study file as it is, its own first levels
    around = study.parameters if args.levels == "study" else [
        tsid_fmu.Parameter(p.name, d.levels[p.name], min=p.min, max=p.max, unit=p.unit)
        if p.name in d.levels else p
        for p in study.parameters
    ]  # fmt: skip
    ratios: dict[str, list[float]] = {n: [] for n in names}
    relative: dict[str, list[float]] = {n: [] for n in names}
    holds: dict[str, int] = {n: 0 for n in names}
    header = f"{'seed':>4} " + " ".join(f"{n + ' achieved/predicted':>24}" for n in names)
    print(header + "   (widths; relative to each answer in brackets)")
    for seed in range(args.seeds):
        extra = tsid_fmu.Experiment(
            make(d, 1000 + seed),
            inputs=dict(first.inputs),
            outputs=dict(first.outputs),
            derived=dict(first.derived),
            noise=dict(first.noise),
            hold=dict(first.hold),
            name="designed",
        )
        two = tsid_fmu.Study(study.fmu, around, [first, extra], method=study.method,
                             start_values=study.start_values, name="with the design")  # fmt: skip
        res = tsid_fmu.identify(two, work / f"seed{seed}", plots=False, workers=args.workers)
        cells = []
        for n in names:
            got, want = res.intervals.get(n), predicted[n]
            r = _width(got) / _width(want) if math.isfinite(_width(want)) else math.nan
            # a log-scale interval scales with its value; the prediction is made at the
            # first answer, the achieved interval at the second
            rel = r * float(base.params[n]) / float(res.params[n])
            ratios[n].append(r)
            relative[n].append(rel)
            inside = (
                got is not None
                and got[0] is not None
                and got[1] is not None
                and (got[0] <= truth[n] <= got[1])
            )
            holds[n] += bool(inside)
            cells.append(f"{r:>13.2f} ({rel:.2f}) {'in ' if inside else 'OUT'}")
        print(f"{seed:>4} " + " ".join(cells), flush=True)
    print("\nper parameter over the seeds (achieved / predicted width; relative to each answer):")
    print(f"{'parameter':<10} {'predicted interval':>24} {'median ratio':>13} {'range':>15} "
          f"{'within +-30 %':>14} {'relative: median':>17} {'within +-30 %':>14} "
          f"{'truth inside':>13}")  # fmt: skip
    for n in names:
        rs = [r for r in ratios[n] if math.isfinite(r)]
        rel = [r for r in relative[n] if math.isfinite(r)]
        iv = predicted[n]
        shown = "open" if not math.isfinite(_width(iv)) else f"{iv[0]:.5g} .. {iv[1]:.5g}"
        within = sum(0.7 <= r <= 1.3 for r in rs)
        within_rel = sum(0.7 <= r <= 1.3 for r in rel)
        rel_median = statistics.median(rel) if rel else math.nan
        print(f"{n:<10} {shown:>24} {statistics.median(rs) if rs else math.nan:>13.2f} "
              f"{(min(rs) if rs else math.nan):>7.2f}..{(max(rs) if rs else math.nan):<7.2f} "
              f"{within:>10}/{len(rs):<3} "
              f"{rel_median:>17.2f} {within_rel:>10}/{len(rel):<3} "
              f"{holds[n]:>9}/{args.seeds}")  # fmt: skip
    print(f"\n{time.perf_counter() - started:.0f} s; work folder {work}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

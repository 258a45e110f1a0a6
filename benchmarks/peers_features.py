"""Run the peers' calibration features on our FMU, so the table of
docs/benchmarks/peer-features.md says only what ran.

Issue 29 asks for a table comparing tsid with modestpy, AixCaliBuHA and estim8 "only
with what you ran". Each probe below is a short script, run by the peer's own Python
(the peers pin package versions that clash with each other and with ours: modestpy
0.1.1 still calls ``DataFrame.append``, removed in pandas 2, so it needs its own
environment). A probe prints one ``RESULT {json}`` line; this script collects them and
prints a table of what each peer did, with its time.

The probes use ``fmus/LSEA_SISO.fmu`` (FMI 2, Model Exchange and Co-Simulation) and the
first two seconds of ``examples/lsea_siso/measured.csv`` (the SISO rig data from the
independent simulator). Budgets are kept small: the probes show that a feature runs
and what it returns, not which optimiser is best (``benchmarks/accuracy.py`` does that
for tsid against SciPy and CMA-ES).

Set-up (outside this project; none of it is a dependency of tsid)::

    python3 -m venv /tmp/peers && /tmp/peers/bin/pip install aixcalibuha estim8 pygmo
    python3 -m venv /tmp/peers-modest && /tmp/peers-modest/bin/pip install modestpy \
        "pyDOE<0.4" "pandas<2" "numpy<2" "scipy<1.14"
    python benchmarks/peers_features.py --modestpy /tmp/peers-modest/bin/python \
        --aixcalibuha /tmp/peers/bin/python --estim8 /tmp/peers/bin/python
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FMU = ROOT / "fmus" / "LSEA_SISO.fmu"
RIG = ROOT / "examples" / "lsea_siso" / "measured.csv"

_DATA = """
import json, time, numpy as np, pandas as pd
def emit(**kw):
    print("RESULT " + json.dumps(kw, default=float), flush=True)
rig = pd.read_csv({rig!r})
rig["F_o"] = rig.F_of - rig.F_or
FMU = {fmu!r}
EST = {{"F_cm": (60.0, 10, 110), "F_vm": (40.0, 1, 80), "M_m": (8.0, 4, 12),
        "K_s": (5500.0, 1000, 10000), "B_s": (10.0, 0.1, 20)}}
"""

_AIX = """
import pathlib, tempfile
from ebcpy import FMU_API, TimeSeriesData
from aixcalibuha import TunerParas, Goals, CalibrationClass
wd = pathlib.Path(tempfile.mkdtemp())
d = rig[rig.time <= 2.0 + 1e-9].set_index("time")
def setup(fmu, est, **kw):
    api = FMU_API(model_name=fmu, working_directory=wd / "sim", log_fmu=False, n_cpu=1)
    api.set_sim_setup({"output_interval": 0.001, "stop_time": 2.0})
    names = list(est)
    tuner = TunerParas(names=names, initial_values=[est[n][0] for n in names],
                       bounds=[est[n][1:] for n in names])
    goals = Goals(meas_target_data=TimeSeriesData(d[["F_o", "x_m"]].copy()),
                  variable_names={"F_o": ["F_o", "F_o"], "x_m": ["x_m", "x_m"]},
                  statistical_measure="NRMSE", weightings=[0.5, 0.5])
    cls = CalibrationClass(name="probe", start_time=0.0, stop_time=2.0, goals=goals,
                           tuner_paras=tuner, inputs=TimeSeriesData(d[["F_m"]].copy()), **kw)
    return api, cls
"""

PROBES: dict[str, dict[str, str]] = {
    "modestpy": {
        "measured inputs, global + local search": """
import tempfile
from modestpy import Estimation
d = rig[rig.time <= 2.0 + 1e-9].set_index("time")
t = time.time()
e = Estimation(tempfile.mkdtemp(), FMU, d[["F_m"]], {"V_z": 0.001}, EST, d[["F_o", "x_m"]],
               lp_n=1, lp_frame=(0.0, 2.0), vp=(0.0, 2.0), methods=("MODESTGA", "PS"),
               modestga_opts={"generations": 5, "pop_size": 10, "workers": 1},
               ps_opts={"maxiter": 30})
found = e.estimate()
emit(ok=True, seconds=time.time() - t, what="GA (5 x 10) then pattern search (30)",
     estimate=found)
""",
        "time windows and initial states from data": """
import tempfile
from modestpy import Estimation
d = rig.set_index("time")
t = time.time()
e = Estimation(tempfile.mkdtemp(), FMU, d[["F_m"]], {"V_z": 0.001}, EST, d[["F_o", "x_m"]],
               lp_n=2, lp_len=2, lp_frame=(0, 10), vp=(0, 10), ic_param={"x_m": "x_m"},
               methods=("PS",), ps_opts={"maxiter": 10})
e.estimate()
emit(ok=True, seconds=time.time() - t, what="learning periods (random, whole seconds) "
     "and ic_param x_m from the data", windows=e.lp)
""",
    },
    "aixcalibuha": {
        "measured inputs, a scored window": _AIX
        + """
from aixcalibuha import Calibrator
api, cls = setup(FMU, EST, relevant_intervals=[(0.5, 2.0)])
t = time.time()
cal = Calibrator(working_directory=wd / "cal", sim_api=api, calibration_class=cls,
                 show_plot=False, create_tsd_plot=False, save_tsd_plot=False,
                 max_itercount=60, verbose_logging=False)
res = cal.calibrate(framework="scipy_differential_evolution", method="best1bin",
                    maxiter=2, popsize=3, polish=False)
emit(ok=True, seconds=time.time() - t, what="differential evolution, window 0.5-2 s scored",
     estimate={k: float(v) for k, v in res.items()})
api.close()
""",
        "sensitivity screening (Morris, Sobol)": _AIX
        + """
from aixcalibuha import MorrisAnalyzer, SobolAnalyzer
api, cls = setup(FMU, EST)
t = time.time()
morris = MorrisAnalyzer(sim_api=api, num_samples=4, cd=wd / "m", analysis_variable="mu_star")
rm = morris.run(calibration_classes=[cls], plot_result=False)[0]
sobol = SobolAnalyzer(sim_api=api, num_samples=8, cd=wd / "s", analysis_variable="S1")
rs = sobol.run(calibration_classes=[cls], plot_result=False)[0]
mu = rm.xs("mu_star", level="Analysis variable").iloc[0]
emit(ok=True, seconds=time.time() - t, what="Morris (4 trajectories) and Sobol (8 samples)",
     morris_rank=list(mu.sort_values(ascending=False).index))
api.close()
""",
        "a discrete factor (an Integer switch)": _AIX
        + """
from aixcalibuha import Calibrator
est = {"friction": (2, 1, 3), "F_cm": (60.0, 10, 110), "F_vm": (40.0, 1, 80)}
api, cls = setup(FMU.replace("LSEA_SISO", "LSEA_SISO_Friction"), est)
t = time.time()
cal = Calibrator(working_directory=wd / "cal", sim_api=api, calibration_class=cls,
                 show_plot=False, create_tsd_plot=False, save_tsd_plot=False,
                 max_itercount=30, verbose_logging=False)
res = cal.calibrate(framework="scipy_differential_evolution", method="best1bin",
                    maxiter=1, popsize=3, polish=False)
emit(ok=True, seconds=time.time() - t, what="the Integer 'friction' as a tuner parameter "
     "(1..3): searched as a real number", estimate={k: float(v) for k, v in res.items()})
api.close()
""",
    },
    "estim8": {
        "measured inputs": """
import inspect
from estim8.models import FmuModel
src = inspect.getsource(FmuModel.simulate)
emit(ok="input" in src, seconds=0.0, what="FmuModel.simulate's source checked for an input "
     "argument to fmpy.simulate_fmu", passes_input="input=" in src)
""",
        "per-replicate parameters, Monte Carlo, profile": """
import fmpy
from estim8 import Estimator
from estim8.datatypes import Experiment
from estim8.models import FmuModel
from estim8.utils import ModelHelpers
rng = np.random.default_rng(0)
data = {}
for rid, x0 in (("A", 0.03), ("B", 0.05)):  # free responses: estim8 drives no inputs
    r = fmpy.simulate_fmu(FMU, stop_time=1.0, output_interval=0.01, start_values={"x_m": x0},
                          output=["F_o"])
    v = pd.DataFrame({"F_o": r["F_o"] + rng.normal(0, 1.0, len(r))},
                     index=pd.Index(r["time"], name="time"))
    data[rid] = Experiment(v, replicate_ID=rid,
                           errors=pd.DataFrame(1.0, index=v.index, columns=v.columns))
mapping = [ModelHelpers.ParameterMapper("x_m", "A", value=0.03, local_name="x_m_A"),
           ModelHelpers.ParameterMapper("x_m", "B", value=0.05, local_name="x_m_B")]
bounds = {"K_s": [1000, 10000], "F_vm": [1, 80], "x_m_A": [0.0, 0.1], "x_m_B": [0.0, 0.1]}
est = Estimator(model=FmuModel(FMU, fmi_type="ModelExchange"), bounds=bounds, data=data,
                t=[0, 1.0, 0.01], metric="SS", parameter_mapping=mapping)
t = time.time()
p, _ = est.estimate(method="de", max_iter=3, n_jobs=1)
t1 = time.time()
mc = est.mc_sampling(method="de", max_iter=2, n_samples=3, n_jobs=1)
t2 = time.time()
pl = est.profile_likelihood(p_opt=p, method="local", max_iter=20, max_steps=3,
                            stepsize=0.05, p_inv=["K_s"])
emit(ok=True, seconds=time.time() - t, what="x_m per replicate (2), DE 3 iterations; "
     "Monte Carlo 3 re-fits; profile of K_s", estimate=p, truth_x_m=[0.03, 0.05],
     mc_samples=len(mc), mc_seconds=t2 - t1, profile_points=int(len(pl["K_s"])))
""",
        "island model (pygmo)": """
from estim8 import Estimator
from estim8.models import FmuModel
import fmpy
if __name__ == "__main__":
    r = fmpy.simulate_fmu(FMU, stop_time=1.0, output_interval=0.01, start_values={"x_m": 0.04},
                          output=["F_o"])
    v = pd.DataFrame({"F_o": r["F_o"]}, index=pd.Index(r["time"], name="time"))
    est = Estimator(model=FmuModel(FMU, fmi_type="ModelExchange"),
                    bounds={"K_s": [1000, 10000], "F_vm": [1, 80]}, data=v, t=[0, 1.0, 0.01])
    t = time.time()
    p, _ = est.estimate(method=["de1220", "pso"], max_iter=1, n_jobs=2)
    emit(ok=True, seconds=time.time() - t, what="two islands (de1220, pso), 1 evolution",
         estimate=p)
""",
    },
}


def _run(python: str, name: str, body: str, folder: Path, timeout: float) -> dict:
    """Run one probe with the peer's interpreter and return its RESULT line."""
    script = folder / f"{name}.py"
    head = _DATA.format(rig=str(RIG), fmu=str(FMU))
    script.write_text(head + textwrap.dedent(body))
    t = time.time()
    try:
        done = subprocess.run(
            [python, str(script)], capture_output=True, text=True, timeout=timeout, cwd=folder
        )
    except subprocess.TimeoutExpired:
        return {"ok": False, "what": f"timed out after {timeout:.0f} s"}
    for line in done.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    last = (done.stderr.strip().splitlines() or ["no output"])[-1]
    return {"ok": False, "seconds": time.time() - t, "what": f"failed: {last[:160]}"}


def main(argv: list[str] | None = None) -> int:
    """Run every probe whose peer has an interpreter given, and print the results."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    for peer in PROBES:
        parser.add_argument(f"--{peer}", metavar="PYTHON", help=f"{peer}'s interpreter")
    parser.add_argument("--timeout", type=float, default=300.0, help="seconds per probe")
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory(prefix="tsid-peers-") as tmp:
        for peer, probes in PROBES.items():
            python = getattr(args, peer)
            if not python:
                continue
            for i, (feature, body) in enumerate(probes.items()):
                folder = Path(tmp) / f"{peer}{i}"
                folder.mkdir()
                res = _run(python, f"probe{i}", body, folder, args.timeout)
                rows.append((peer, feature, res))
                print(f"{peer:12s} {feature:50s} {json.dumps(res, default=str)}", flush=True)
    if not rows:
        parser.error("give at least one peer's interpreter")
    print("\n| peer | feature | ran | seconds | what |\n|---|---|---|---|---|")
    for peer, feature, res in rows:
        secs = res.get("seconds")
        print(
            f"| {peer} | {feature} | {'yes' if res.get('ok') else 'no'} | "
            f"{'' if secs is None else f'{secs:.1f}'} | {res.get('what', '')} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

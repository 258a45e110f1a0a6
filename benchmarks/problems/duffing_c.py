"""A forced Duffing oscillator as a hand-written C FMU (the test suite's C factory).

Plant: ``m der(v) = u - c v - k x - k3 x^3``, ``der(x) = v``, from rest; output ``x``,
input the force ``u``, parameters ``m, c, k, k3``.  The FMU is FMI 2.0 Co-Simulation,
compiled with ``tests/fmu_factory.py``'s ``fmi2_source`` and ``pack_c_fmu`` (gcc against
FMPy's headers): the exporter is neither the project's Modelica build nor pythonfmu.
Its ``fmi2DoStep`` takes classical RK4 steps of at most ``FIXED_STEP`` (a compile-time
constant: 1 ms for the accurate build, 20 ms, i.e. one RK4 step per communication step,
for the "coarse solver" mismatch).  Built on demand into ``benchmarks/.cache/``.

Run:  python benchmarks/problems/duffing_c.py   (self-check: FMU vs solve_ivp)
"""

import sys
from pathlib import Path

if not __package__:  # run as a script, or loaded from a file path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from problems.base import REPO, cached_build

NAME = "DuffingC"

_C = r"""
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct { double u, x, v, m, c, k, k3, time; } Model;
#define M ((Model *)c)

static void defaults(Model *m) {
    m->u = 0.0; m->x = 0.0; m->v = 0.0;
    m->m = 1.0; m->c = 0.5; m->k = 40.0; m->k3 = 40.0; m->time = 0.0; }
static double acc(const Model *m, double x, double v) {
    return (m->u - m->c * v - m->k * x - m->k3 * x * x * x) / m->m; }
static int get(const Model *m, unsigned vr, double *v) {
    switch (vr) {
    case 0: *v = m->u; return 0;
    case 1: *v = m->x; return 0;
    case 2: *v = m->m; return 0;
    case 3: *v = m->c; return 0;
    case 4: *v = m->k; return 0;
    case 5: *v = m->k3; return 0;
    case 6: *v = m->v; return 0;
    default: return 1;
    }
}
static int set(Model *m, unsigned vr, double v) {
    switch (vr) {
    case 0: m->u = v; return 0;
    case 2: m->m = v; return 0;
    case 3: m->c = v; return 0;
    case 4: m->k = v; return 0;
    case 5: m->k3 = v; return 0;
    default: return 1;
    }
}
"""

_FUNCTIONS = r"""
/* Co-Simulation: classical RK4 at FIXED_STEP (or the communication step if shorter) */
int fmi2DoStep(void *c, double t, double h, int ns) {
    (void)ns;
    if (M->m <= 0.0) return 3;
    int n = (int)ceil(h / FIXED_STEP - 1e-9);
    if (n < 1) n = 1;
    double dt = h / n;
    for (int i = 0; i < n; i++) {
        double x = M->x, v = M->v;
        double k1x = v, k1v = acc(M, x, v);
        double k2x = v + 0.5 * dt * k1v, k2v = acc(M, x + 0.5 * dt * k1x, v + 0.5 * dt * k1v);
        double k3x = v + 0.5 * dt * k2v, k3v = acc(M, x + 0.5 * dt * k2x, v + 0.5 * dt * k2v);
        double k4x = v + dt * k3v, k4v = acc(M, x + dt * k3x, v + dt * k3v);
        M->x = x + dt / 6.0 * (k1x + 2 * k2x + 2 * k3x + k4x);
        M->v = v + dt / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v);
    }
    M->time = t + h;
    return isfinite(M->x) && isfinite(M->v) ? 0 : 3;
}
"""

# name, value reference, causality, variability, initial, start, unit
_VARIABLES = [
    ("u", 0, "input", "continuous", None, "0", "N"),
    ("x", 1, "output", "continuous", "exact", "0", "m"),
    ("m", 2, "parameter", "fixed", "exact", "1", "kg"),
    ("c", 3, "parameter", "fixed", "exact", "0.5", "N.s/m"),
    ("k", 4, "parameter", "fixed", "exact", "40", "N/m"),
    ("k3", 5, "parameter", "fixed", "exact", "40", "N/m3"),
    ("v", 6, "local", "continuous", "exact", "0", "m/s"),
]


def _model_description(guid: str) -> str:
    rows = []
    for name, vr, causality, variability, initial, start, unit in _VARIABLES:
        init = f' initial="{initial}"' if initial else ""
        rows.append(
            f'    <ScalarVariable name="{name}" valueReference="{vr}" causality="{causality}" '
            f'variability="{variability}"{init}><Real start="{start}" unit="{unit}"/>'
            "</ScalarVariable>"
        )
    units = sorted({u for *_, u in _VARIABLES})
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<fmiModelDescription fmiVersion="2.0" modelName="{NAME}" guid="{guid}" '
        'generationTool="tsid-fmu benchmarks/problems/duffing_c.py" '
        'numberOfEventIndicators="0" description="forced Duffing oscillator, RK4">\n'
        f'  <CoSimulation modelIdentifier="{NAME}" '
        'canHandleVariableCommunicationStepSize="true"/>\n'
        "  <UnitDefinitions>"
        + "".join(f'<Unit name="{u}"/>' for u in units)
        + "</UnitDefinitions>\n"
        '  <DefaultExperiment startTime="0" stopTime="10" stepSize="0.01"/>\n'
        "  <ModelVariables>\n" + "\n".join(rows) + "\n  </ModelVariables>\n"
        "  <ModelStructure>\n"
        '    <Outputs><Unknown index="2"/></Outputs>\n'
        "  </ModelStructure>\n</fmiModelDescription>\n"
    )


def build_fmu(fixed_step: float = 1e-3) -> Path:
    """The Duffing FMU with RK4 steps of at most ``fixed_step`` (cached build)."""
    if str(REPO / "tests") not in sys.path:
        sys.path.insert(0, str(REPO / "tests"))
    source_key = f"{_C}{_FUNCTIONS}{_VARIABLES}{fixed_step!r}"

    def build(folder: Path) -> Path:
        from fmu_factory import fmi2_source, new_guid, pack_c_fmu

        guid = new_guid()
        source = fmi2_source(_C, _FUNCTIONS)
        return pack_c_fmu(
            folder,
            NAME,
            source,
            _model_description(guid),
            guid,
            defines=[f"-DFIXED_STEP={float(fixed_step)!r}"],
            hidden=False,
        )

    return cached_build(NAME, source_key, build)


def rhs(params: dict[str, float]):
    """``der([x, v])`` of the plant for a force ``u`` held over the step."""
    m, c, k, k3 = (params[n] for n in ("m", "c", "k", "k3"))

    def f(_t: float, s, u: float) -> list[float]:
        return [s[1], (u - c * s[1] - k * s[0] - k3 * s[0] ** 3) / m]

    return f


def self_check() -> None:
    """Build both FMUs and compare them with the independent solution at one truth."""
    import numpy as np

    from problems.base import rms_over_sigma, sample_times, simulate_fmu
    from problems.generalise_draw import integrate, multilevel

    truth = {"m": 1.0, "c": 0.6, "k": 40.0, "k3": 60.0}
    t = sample_times(10.0, 100.0)
    u = multilevel(np.random.default_rng(1), t, 60.0, (0.3, 2.0))
    ref = integrate(rhs(truth), [0.0, 0.0], t, u)[:, 0]
    for step in (1e-3, 0.02):
        y = simulate_fmu(build_fmu(step), t, {"u": u}, ["x"], truth)[:, 0]
        rms, peak = rms_over_sigma(y, ref, 1.0)
        print(
            f"FIXED_STEP {step}: FMU vs solve_ivp: RMS {rms:.2e} m (max {peak:.2e}), "
            f"peak |x| {np.abs(ref).max():.3f} m"
        )


if __name__ == "__main__":
    self_check()

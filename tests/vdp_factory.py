"""Build a van der Pol oscillator FMU whose Co-Simulation is a coarse forward Euler.

``build_vdp_fmu(tmp_dir, name, interfaces=("cs", "me"), fixed_step=0.01)`` writes an
FMI 2.0 FMU of

    der(x0) = x1,   der(x1) = mu * (1 - x0**2) * x1 - x0,   x0(0) = 2, x1(0) = 0

with outputs ``x0``, ``x1`` and the parameter ``mu`` (start 1), as the Modelica
Association's Reference-FMUs ``VanDerPol`` has them. Its Model Exchange interface gives
the exact derivatives (no event indicators), so a Model Exchange solver at a tight
tolerance integrates it exactly. Its Co-Simulation integrates with forward Euler, as the
Reference-FMUs do, at ``fixed_step`` (10 ms) or, for a shorter communication step, at
that step (each ``fmi2DoStep`` takes ``ceil(h / fixed_step)`` equal Euler steps): the
cheap fixed-step solver many vendor FMUs ship.

``vdp_solution(time, mu)`` is the accurate solution (SciPy's DOP853 at ``rtol=1e-12``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from fmu_factory import fmi2_source, new_guid, pack_c_fmu

_C = r"""
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct { double x0, x1, mu, time; } Model;
typedef struct { int needed, terminate, nominals, values, defined; double next; } EventInfo;
#define M ((Model *)c)

static void defaults(Model *m) { m->x0 = 2.0; m->x1 = 0.0; m->mu = 1.0; m->time = 0.0; }
static double der0(const Model *m) { return m->x1; }
static double der1(const Model *m) { return m->mu * (1.0 - m->x0 * m->x0) * m->x1 - m->x0; }
static int get(const Model *m, unsigned vr, double *v) {
    switch (vr) {
    case 0: *v = m->x0; return 0;
    case 1: *v = der0(m); return 0;
    case 2: *v = m->x1; return 0;
    case 3: *v = der1(m); return 0;
    case 4: *v = m->mu; return 0;
    default: return 1;
    }
}
static int set(Model *m, unsigned vr, double v) {
    switch (vr) {
    case 0: m->x0 = v; return 0;
    case 2: m->x1 = v; return 0;
    case 4: m->mu = v; return 0;
    default: return 1;
    }
}

"""

_FUNCTIONS = r"""
/* Model Exchange: exact derivatives, no events */
int fmi2EnterEventMode(void *c) { (void)c; return 0; }
int fmi2NewDiscreteStates(void *c, void *e) {
    (void)c; memset(e, 0, sizeof(EventInfo)); return 0; }
int fmi2EnterContinuousTimeMode(void *c) { (void)c; return 0; }
int fmi2CompletedIntegratorStep(void *c, int ns, int *ev, int *term) {
    (void)c; (void)ns; *ev = 0; *term = 0; return 0; }
int fmi2SetTime(void *c, double t) { M->time = t; return 0; }
int fmi2SetContinuousStates(void *c, const double x[], size_t n) {
    (void)n; M->x0 = x[0]; M->x1 = x[1]; return 0; }
int fmi2GetContinuousStates(void *c, double x[], size_t n) {
    (void)n; x[0] = M->x0; x[1] = M->x1; return 0; }
int fmi2GetDerivatives(void *c, double d[], size_t n) {
    (void)n; d[0] = der0(M); d[1] = der1(M); return 0; }
int fmi2GetEventIndicators(void *c, double z[], size_t n) {
    (void)c; (void)z; (void)n; return 0; }
int fmi2GetNominalsOfContinuousStates(void *c, double x[], size_t n) {
    (void)c; (void)n; x[0] = 1.0; x[1] = 1.0; return 0; }

/* Co-Simulation: forward Euler at FIXED_STEP (or the communication step if shorter) */
int fmi2DoStep(void *c, double t, double h, int ns) {
    (void)ns;
    int n = (int)ceil(h / FIXED_STEP - 1e-9);
    if (n < 1) n = 1;
    double dt = h / n;
    for (int k = 0; k < n; k++) {
        double d0 = der0(M), d1 = der1(M);
        M->x0 += dt * d0; M->x1 += dt * d1;
    }
    M->time = t + h;
    return 0;
}
"""

# name, value reference, causality, variability, initial, start, derivative of (index)
_VARIABLES = [
    ("x0", 0, "output", "continuous", "exact", "2", None),
    ("der(x0)", 1, "local", "continuous", "calculated", None, 1),
    ("x1", 2, "output", "continuous", "exact", "0", None),
    ("der(x1)", 3, "local", "continuous", "calculated", None, 3),
    ("mu", 4, "parameter", "fixed", "exact", "1", None),
]


def _model_description(name: str, guid: str, interfaces: Sequence[str]) -> str:
    rows = []
    for vname, vr, causality, variability, initial, start, of in _VARIABLES:
        real = (f' start="{start}"' if start else "") + (f' derivative="{of}"' if of else "")
        rows.append(
            f'    <ScalarVariable name="{vname}" valueReference="{vr}" causality="{causality}" '
            f'variability="{variability}" initial="{initial}"><Real{real}/></ScalarVariable>'
        )
    me = f'  <ModelExchange modelIdentifier="{name}"/>\n' if "me" in interfaces else ""
    cs = (
        f'  <CoSimulation modelIdentifier="{name}" '
        'canHandleVariableCommunicationStepSize="true"/>\n'
        if "cs" in interfaces
        else ""
    )
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{guid}" '
        'generationTool="tsid-fmu tests/vdp_factory.py" numberOfEventIndicators="0" '
        'description="van der Pol oscillator; Co-Simulation by forward Euler">\n'
        f"{me}{cs}"
        '  <DefaultExperiment startTime="0" stopTime="20" stepSize="0.01"/>\n'
        "  <ModelVariables>\n" + "\n".join(rows) + "\n  </ModelVariables>\n"
        "  <ModelStructure>\n"
        '    <Outputs><Unknown index="1"/><Unknown index="3"/></Outputs>\n'
        '    <Derivatives><Unknown index="2"/><Unknown index="4"/></Derivatives>\n'
        '    <InitialUnknowns><Unknown index="2"/><Unknown index="4"/></InitialUnknowns>\n'
        "  </ModelStructure>\n</fmiModelDescription>\n"
    )


def build_vdp_fmu(
    tmp_dir: Path,
    name: str = "VanDerPol",
    *,
    interfaces: Sequence[str] = ("cs", "me"),
    fixed_step: float = 0.01,
) -> Path:
    """Build ``<tmp_dir>/<name>.fmu`` (see the module docstring) and return its path."""
    guid = new_guid()
    source = fmi2_source(_C, _FUNCTIONS)
    return pack_c_fmu(
        tmp_dir,
        name,
        source,
        _model_description(name, guid, interfaces),
        guid,
        defines=[f"-DFIXED_STEP={float(fixed_step)!r}"],
        hidden=False,
    )


def vdp_solution(time: np.ndarray, mu: float) -> np.ndarray:
    """Return ``[x0, x1]`` at ``time`` (shape ``(n, 2)``), solved accurately by SciPy."""
    from scipy.integrate import solve_ivp

    sol = solve_ivp(
        lambda t, x: [x[1], mu * (1.0 - x[0] ** 2) * x[1] - x[0]],
        (float(time[0]), float(time[-1])),
        [2.0, 0.0],
        method="DOP853",
        t_eval=time,
        rtol=1e-12,
        atol=1e-12,
    )
    return sol.y.T

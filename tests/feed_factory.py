"""Build a feed-through-and-integrator test FMU (FMI 2.0 or 3.0 Co-Simulation).

``build_feed_fmu(tmp_dir, name, fmi_version="2.0", can_interpolate=False)`` writes an FMU
with two Real inputs ``a``, ``b`` and the outputs

    ya = a(t),  yb = b(t)                    (direct feed-through)
    za = integral of a dt,  zb = integral of b dt
    nder = number of fmi2SetRealInputDerivatives calls

Between communication points the FMU sees each input as ``value + derivative * (t -
t_set)``: the derivative is 0 unless the importer sets it with
``fmi2SetRealInputDerivatives`` (order 1; FMI 2.0 only), and setting a value resets it
to 0.  The integrals are exact for such piecewise-linear inputs:
``z += h * u(t) + 0.5 * h**2 * du``.  ``can_interpolate`` declares
``canInterpolateInputs`` in the model description (FMI 2.0).

So a zero-order hold gives left Riemann sums, a linear input interpolated by the FMU
gives the trapezoidal rule, and any lag of the feed-through shows in ``ya``.
"""

from __future__ import annotations

from pathlib import Path

import fmpy
from fmu_factory import _FMI3_STUBS, fmi2_source, new_guid, pack_c_fmu

CALCULATED = ' initial="calculated"'

# name, vr, causality
VARIABLES = [
    ("a", 0, "input"),
    ("b", 1, "input"),
    ("ya", 2, "output"),
    ("yb", 3, "output"),
    ("za", 4, "output"),
    ("zb", 5, "output"),
    ("nder", 6, "output"),
]

_MODEL = r"""
#include <stdlib.h>
#include <string.h>

typedef struct { double u[2], du[2], tu[2], z[2], nder, time; } Model;
#define M ((Model *)c)

static double value(const Model *m, int i) { return m->u[i] + m->du[i] * (m->time - m->tu[i]); }
static void defaults(Model *m) { memset(m, 0, sizeof *m); }
static int get(const Model *m, unsigned vr, double *v) {
    switch (vr) {
    case 0: case 1: *v = m->u[vr]; return 0;
    case 2: case 3: *v = value(m, vr - 2); return 0;
    case 4: case 5: *v = m->z[vr - 4]; return 0;
    case 6: *v = m->nder; return 0;
    default: return 3;
    }
}
static int set(Model *m, unsigned vr, double v) {
    if (vr > 1) return 3;
    m->u[vr] = v; m->du[vr] = 0.0; m->tu[vr] = m->time; return 0;
}
static void step(Model *m, double t, double h) {
    for (int i = 0; i < 2; i++) {
        double u = m->u[i] + m->du[i] * (t - m->tu[i]);
        m->z[i] += h * u + 0.5 * h * h * m->du[i];
    }
    m->time = t + h;
}
"""

_FMI2 = fmi2_source(
    _MODEL,
    r"""
int fmi2SetRealInputDerivatives(void *c, const unsigned vr[], size_t n, const int order[],
                                const double v[]) {
    M->nder += 1;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] > 1 || order[i] != 1) return 3;
        M->du[vr[i]] = v[i];
    }
    return 0;
}
int fmi2DoStep(void *c, double t, double h, int ns) { (void)ns; step(M, t, h); return 0; }
""",
)

_FMI3 = (
    "#include <stdbool.h>\n#include <stddef.h>\n"
    + _MODEL
    + r"""
#define EXPORT __attribute__((visibility("default")))
EXPORT const char *fmi3GetVersion(void) { return "3.0"; }
EXPORT int fmi3SetDebugLogging(void *c, bool on, size_t n, const char *const cat[]) {
    (void)c; (void)on; (void)n; (void)cat; return 0; }
EXPORT void *fmi3InstantiateCoSimulation(const char *name, const char *token,
        const char *res, bool visible, bool loggingOn, bool eventMode, bool earlyReturn,
        const unsigned *req, size_t nreq, void *env, void *log, void *intermediate) {
    (void)name; (void)res; (void)visible; (void)loggingOn; (void)eventMode;
    (void)earlyReturn; (void)req; (void)nreq; (void)env; (void)log; (void)intermediate;
    if (strcmp(token, GUID) != 0) return NULL;
    Model *m = malloc(sizeof *m); defaults(m); return m;
}
EXPORT void fmi3FreeInstance(void *c) { free(c); }
EXPORT int fmi3EnterInitializationMode(void *c, bool tolDef, double tol, double start,
                                       bool stopDef, double stop) {
    (void)tolDef; (void)tol; (void)stopDef; (void)stop; M->time = start; return 0; }
EXPORT int fmi3ExitInitializationMode(void *c) { (void)c; return 0; }
EXPORT int fmi3Terminate(void *c) { (void)c; return 0; }
EXPORT int fmi3Reset(void *c) { defaults(M); return 0; }
EXPORT int fmi3GetFloat64(void *c, const unsigned vr[], size_t n, double v[], size_t nv) {
    (void)nv; for (size_t i = 0; i < n; i++) if (get(M, vr[i], &v[i])) return 3;
    return 0; }
EXPORT int fmi3SetFloat64(void *c, const unsigned vr[], size_t n, const double v[], size_t nv) {
    (void)nv; for (size_t i = 0; i < n; i++) if (set(M, vr[i], v[i])) return 3;
    return 0; }
EXPORT int fmi3SetInt32(void *c, const unsigned vr[], size_t n, const int v[], size_t nv) {
    (void)c; (void)vr; (void)n; (void)v; (void)nv; return 3; }
EXPORT int fmi3SetBoolean(void *c, const unsigned vr[], size_t n, const bool v[], size_t nv) {
    (void)c; (void)vr; (void)n; (void)v; (void)nv; return 3; }
EXPORT int fmi3DoStep(void *c, double t, double h, bool ns, bool *event, bool *term,
                      bool *early, double *last) {
    (void)ns; *event = false; *term = false; *early = false;
    step(M, t, h); *last = t + h; return 0;
}
"""
    + "".join(f"EXPORT int {name}(void) {{ return 3; }}\n" for name in _FMI3_STUBS)
)


def _model_description(name: str, guid: str, fmi_version: str, can_interpolate: bool) -> str:
    start = ' start="0"'
    if fmi_version == "2.0":
        rows = [
            f'    <ScalarVariable name="{n}" valueReference="{vr}" causality="{c}" '
            f'variability="continuous"{"" if c == "input" else CALCULATED}>'
            f"<Real{start if c == 'input' else ''}/></ScalarVariable>"
            for n, vr, c in VARIABLES
        ]
        outputs = "".join(f'<Unknown index="{i + 1}"/>' for i in range(2, len(VARIABLES)))
        structure = f"    <Outputs>{outputs}</Outputs>\n    <InitialUnknowns>{outputs}"
        structure += "</InitialUnknowns>\n"
        head = f'fmiVersion="2.0" modelName="{name}" guid="{guid}"'
        interp = ' canInterpolateInputs="true"' * can_interpolate
    else:
        rows = [
            '    <Float64 name="time" valueReference="99" causality="independent" '
            'variability="continuous"/>'
        ] + [
            f'    <Float64 name="{n}" valueReference="{vr}" causality="{c}" '
            f'variability="continuous"{start if c == "input" else ""}/>'
            for n, vr, c in VARIABLES
        ]
        structure = "".join(
            f'    <Output valueReference="{vr}"/>\n' for _, vr, c in VARIABLES if c == "output"
        )
        head = f'fmiVersion="3.0" modelName="{name}" instantiationToken="{guid}"'
        interp = ""
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<fmiModelDescription {head} generationTool="tsid-fmu tests/feed_factory.py">\n'
        f'  <CoSimulation modelIdentifier="{name}" '
        f'canHandleVariableCommunicationStepSize="true"{interp}/>\n'
        "  <ModelVariables>\n" + "\n".join(rows) + "\n  </ModelVariables>\n"
        f"  <ModelStructure>\n{structure}  </ModelStructure>\n</fmiModelDescription>\n"
    )


def build_feed_fmu(
    tmp_dir: Path, name: str = "Feed", *, fmi_version: str = "2.0", can_interpolate: bool = False
) -> Path:
    """Build ``<tmp_dir>/<name>.fmu`` (see the module docstring) and return its path."""
    guid = new_guid()
    if fmi_version == "2.0":
        platform_dir = fmpy.platform
        source = _FMI2
    else:
        platform_dir = fmpy.platform_tuple
        source = _FMI3
    xml = _model_description(name, guid, fmi_version, can_interpolate)
    return pack_c_fmu(
        tmp_dir, name, source, xml, guid, platform_dir=platform_dir, hidden=fmi_version != "2.0"
    )

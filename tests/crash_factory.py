"""Build a feed-through test FMU that can crash, hang or run slowly on demand.

``build_crash_fmu(tmp_dir, name)`` writes an FMI 2.0 Co-Simulation FMU of

    y = gain * u + bias

whose ``fmi2DoStep`` misbehaves when ``gain`` crosses a threshold parameter (the
highest threshold crossed wins):

* ``gain > hang_above``: never returns (sleeps in a loop);
* ``gain > segv_above``: writes through a NULL pointer (SIGSEGV);
* ``gain > abort_above``: calls ``abort()`` (the process dies of SIGABRT);
* ``delay`` > 0: busy-waits ``delay`` seconds in every step (a deliberately slow FMU);
  ``delay`` < 0 sleeps ``-delay`` seconds per step instead (slow without using the CPU).

All thresholds default to ``1e300`` and ``delay`` to 0, so by default the FMU is the
trivial feed-through used by the loop benchmark. The C source does not include the FMI
headers: the functions a master needs are real, every other ``fmi2*`` symbol that FMPy
looks up is a stub returning ``fmi2Error``.
"""

from __future__ import annotations

from pathlib import Path

from fmu_factory import new_guid, pack_c_fmu

# name, vr, causality, variability, initial, start
VARIABLES = [
    ("u", 0, "input", "continuous", None, "0"),
    ("y", 1, "output", "continuous", "calculated", None),
    ("gain", 2, "parameter", "fixed", "exact", "1"),
    ("bias", 3, "parameter", "fixed", "exact", "0"),
    ("abort_above", 4, "parameter", "fixed", "exact", "1e300"),
    ("segv_above", 5, "parameter", "fixed", "exact", "1e300"),
    ("hang_above", 6, "parameter", "fixed", "exact", "1e300"),
    ("delay", 7, "parameter", "fixed", "exact", "0"),
]

_STUBS = """
fmi2SetDebugLogging fmi2GetInteger fmi2GetBoolean fmi2GetString fmi2SetInteger
fmi2SetBoolean fmi2SetString fmi2GetFMUstate fmi2SetFMUstate fmi2FreeFMUstate
fmi2SerializedFMUstateSize fmi2SerializeFMUstate fmi2DeSerializeFMUstate
fmi2GetDirectionalDerivative fmi2SetRealInputDerivatives fmi2GetRealOutputDerivatives
fmi2CancelStep fmi2GetStatus fmi2GetRealStatus fmi2GetIntegerStatus fmi2GetBooleanStatus
fmi2GetStringStatus
""".split()

_SOURCE = r"""
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

typedef struct { double v[8]; } Model;   /* v[vr]; v[1] = y is computed */
#define M ((Model *)c)

static double now(void) {
    struct timespec ts; clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}
static void defaults(Model *m) {
    memset(m, 0, sizeof *m);
    m->v[2] = 1.0; m->v[4] = 1e300; m->v[5] = 1e300; m->v[6] = 1e300;
}

const char *fmi2GetTypesPlatform(void) { return "default"; }
const char *fmi2GetVersion(void) { return "2.0"; }
void *fmi2Instantiate(const char *name, int type, const char *guid, const char *res,
                      const void *cb, int visible, int loggingOn) {
    (void)name; (void)type; (void)res; (void)cb; (void)visible; (void)loggingOn;
    if (strcmp(guid, GUID) != 0) return NULL;
    Model *m = malloc(sizeof *m); defaults(m); return m;
}
void fmi2FreeInstance(void *c) { free(c); }
int fmi2SetupExperiment(void *c, int a, double b, double d, int e, double f) {
    (void)c; (void)a; (void)b; (void)d; (void)e; (void)f; return 0; }
int fmi2EnterInitializationMode(void *c) { (void)c; return 0; }
int fmi2ExitInitializationMode(void *c) { (void)c; return 0; }
int fmi2Terminate(void *c) { (void)c; return 0; }
int fmi2Reset(void *c) { defaults(M); return 0; }
int fmi2GetReal(void *c, const unsigned vr[], size_t n, double v[]) {
    for (size_t i = 0; i < n; i++) {
        if (vr[i] > 7) return 3;
        v[i] = vr[i] == 1 ? M->v[2] * M->v[0] + M->v[3] : M->v[vr[i]];
    }
    return 0;
}
int fmi2SetReal(void *c, const unsigned vr[], size_t n, const double v[]) {
    for (size_t i = 0; i < n; i++) { if (vr[i] > 7 || vr[i] == 1) return 3; M->v[vr[i]] = v[i]; }
    return 0;
}
int fmi2DoStep(void *c, double t, double h, int ns) {
    (void)t; (void)h; (void)ns;
    double gain = M->v[2];
    if (gain > M->v[6]) for (;;) usleep(1000);
    else if (gain > M->v[5]) { volatile int *p = NULL; *p = 1; }
    else if (gain > M->v[4]) abort();
    if (M->v[7] > 0) { double end = now() + M->v[7]; while (now() < end) {} }
    if (M->v[7] < 0) { struct timespec ts = {0, (long)(-M->v[7] * 1e9)}; nanosleep(&ts, NULL); }
    return 0;
}
"""


def _model_description(name: str, guid: str) -> str:
    rows = []
    for vname, vr, causality, variability, initial, start in VARIABLES:
        attrs = f'name="{vname}" valueReference="{vr}" causality="{causality}" '
        attrs += f'variability="{variability}"'
        if initial is not None:
            attrs += f' initial="{initial}"'
        real = f'<Real start="{start}"/>' if start is not None else "<Real/>"
        rows.append(f"    <ScalarVariable {attrs}>{real}</ScalarVariable>")
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{guid}" '
        'generationTool="tsid-fmu tests/crash_factory.py" numberOfEventIndicators="0">\n'
        f'  <CoSimulation modelIdentifier="{name}" '
        'canHandleVariableCommunicationStepSize="true"/>\n'
        '  <DefaultExperiment startTime="0" stopTime="1" stepSize="0.001"/>\n'
        "  <ModelVariables>\n" + "\n".join(rows) + "\n  </ModelVariables>\n"
        '  <ModelStructure>\n    <Outputs><Unknown index="2"/></Outputs>\n'
        '    <InitialUnknowns><Unknown index="2"/></InitialUnknowns>\n'
        "  </ModelStructure>\n</fmiModelDescription>\n"
    )


def build_crash_fmu(tmp_dir: Path, name: str = "Crashy") -> Path:
    """Build ``<tmp_dir>/<name>.fmu`` (see the module docstring) and return its path."""
    guid = new_guid()
    source = _SOURCE + "".join(f"int {s}(void) {{ return 3; }}\n" for s in _STUBS)
    return pack_c_fmu(tmp_dir, name, source, _model_description(name, guid), guid, hidden=False)

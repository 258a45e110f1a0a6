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
headers: ``fmu_factory.fmi2_source`` adds the shared entry points to the model and its
``fmi2DoStep``, and stubs every other ``fmi2*`` symbol that FMPy looks up.
"""

from __future__ import annotations

from pathlib import Path

from fmu_factory import fmi2_source, new_guid, pack_c_fmu

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

_MODEL = r"""
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

typedef struct { double v[8], time; } Model;   /* v[vr]; v[1] = y is computed */
#define M ((Model *)c)

static double now(void) {
    struct timespec ts; clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}
static void defaults(Model *m) {
    memset(m, 0, sizeof *m);
    m->v[2] = 1.0; m->v[4] = 1e300; m->v[5] = 1e300; m->v[6] = 1e300;
}
static int get(const Model *m, unsigned vr, double *v) {
    if (vr > 7) return 3;
    *v = vr == 1 ? m->v[2] * m->v[0] + m->v[3] : m->v[vr];
    return 0;
}
static int set(Model *m, unsigned vr, double v) {
    if (vr > 7 || vr == 1) return 3;
    m->v[vr] = v;
    return 0;
}
"""

_DO_STEP = r"""
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
    source = fmi2_source(_MODEL, _DO_STEP)
    return pack_c_fmu(tmp_dir, name, source, _model_description(name, guid), guid, hidden=False)

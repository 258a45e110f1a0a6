"""Build small test FMUs inside the test suite (no network, no Modelica tool).

The builders write a hand-made C model of a first-order lag, compile it with the
system C compiler against FMPy's FMI headers and zip it into an FMU.  They are meant
to be reused by every test module that needs a real FMU:

``build_c_fmu(tmp_dir, name, ...)``
    FMI 2.0 (Co-Simulation and/or Model Exchange) or FMI 3.0 Co-Simulation FMU of

        der(x) = (u - x) / tau,   x(0) = x0,
        y      = gain * x + (offset_on ? 1 : 0)

    with fault injection through parameters: ``tau <= 0`` or ``time > t_fail`` make
    ``doStep`` return an error status (with a log message), ``time > t_nan`` makes
    ``y`` NaN.  Co-Simulation steps are exact for a zero-order-hold input:
    ``x(t + h) = u + (x(t) - u) exp(-h / tau)``.
``build_stub_library(tmp_dir, name)``
    A tiny shared library an FMU can be linked against (``link_library=``) and that a
    test deletes afterwards to produce an unloadable FMU.
``build_pythonfmu(tmp_dir, ...)``
    The same lag written as a ``pythonfmu`` slave (explicit Euler), when
    ``pythonfmu`` can build on this machine.
``lag_response(time, u, tau, x0, gain, offset)``
    The analytic output of the lag for a zero-order-hold input.
``lag_case(tmp_dir, dt)``, ``lag_data(tmp_dir, tau, x0)``
    The lag FMU with an exact step response, or with a noisy measurement to identify.
``fmi2_source(model, functions)`` and ``pack_c_fmu(tmp_dir, name, source, ...)``
    What the other factories (``crash_factory``, ``feed_factory``, ``vdp_factory``) build
    their hand-written FMI 2.0 models with: the shared entry points and stubs, and the
    compile-and-zip step.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import sysconfig
import textwrap
import uuid
import zipfile
from collections.abc import Sequence
from pathlib import Path

import fmpy
import numpy as np
import pandas as pd

HEADERS = Path(fmpy.__file__).parent / "c-code"

# value references, in modelDescription order (index = vr + 1)
VARIABLES = [
    # name, vr, type, causality, variability, initial, start, description
    ("u", 0, "Real", "input", "continuous", None, "0", "input signal"),
    ("y", 1, "Real", "output", "continuous", "calculated", None, "output gain*x+offset"),
    ("tau", 2, "Real", "parameter", "fixed", "exact", "1.0", "time constant"),
    ("x0", 3, "Real", "parameter", "fixed", "exact", "0.0", "initial state"),
    ("t_fail", 4, "Real", "parameter", "fixed", "exact", "1e300", "doStep fails after"),
    ("t_nan", 5, "Real", "parameter", "fixed", "exact", "1e300", "y is NaN after"),
    ("gain", 6, "Integer", "parameter", "fixed", "exact", "1", "integer output gain"),
    ("offset_on", 7, "Boolean", "parameter", "fixed", "exact", "false", "add 1 to y"),
    ("x", 8, "Real", "local", "continuous", "calculated", None, "state"),
    ("der_x", 9, "Real", "local", "continuous", "calculated", None, "state derivative"),
    ("c_const", 10, "Real", "local", "constant", "exact", "2.0", "a constant"),
]

_C_COMMON = r"""
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef LINK_DEP
extern int tsid_dep_value(void);
#endif

/* quirks (issue 62), each a -D define: STALE_CLOCK: reset keeps the FMU's clock, so a step
   to a time it has passed does nothing, and fmi2SetupExperiment restores the default
   parameters (20-sim 4.6); NONDETERMINISTIC: y grows by 1e-3 per run of the library;
   LOOSE_TOLERANCE: the CS step integrates explicit Euler on an internal grid of step
   0.5 sqrt(tol), whatever the communication step, where tol is the tolerance set up (1e-2
   when none is defined), as a variable-step CS solver whose default tolerance is loose;
   ASSERT_RANGE: a step fails on an assertion where tau > TAU_MAX (as Dymola's "outside
   scope of model"); NO_EFFECT: a parameter spare that acts on nothing; NUMERICAL_SETTING:
   the CS step integrates explicit Euler on an internal grid of step timestep, a parameter
   (as Hopsan's) */
#define TAU_MAX 1.2
static int tsid_runs = 0;

typedef struct {
    double u, tau, x0, t_fail, t_nan, x, time, clock;
    double tol, tg, xg;  /* LOOSE_TOLERANCE: the set-up tolerance, the grid's time, state */
    double spare, timestep;  /* NO_EFFECT, NUMERICAL_SETTING */
    int gain, offset_on;
    void *env;
    const char *name;
    LOGGER_FIELD
} Model;

static double model_y(const Model *m) {
    if (m->time > m->t_nan) return NAN;
#ifdef NONDETERMINISTIC
    return m->gain * m->x + (m->offset_on ? 1.0 : 0.0) + 1e-3 * tsid_runs;
#else
    (void)tsid_runs;
    return m->gain * m->x + (m->offset_on ? 1.0 : 0.0);
#endif
}

static double model_get(const Model *m, unsigned vr) {
    switch (vr) {
    case 0: return m->u;
    case 1: return model_y(m);
    case 2: return m->tau;
    case 3: return m->x0;
    case 4: return m->t_fail;
    case 5: return m->t_nan;
    case 8: return m->x;
    case 9: return (m->u - m->x) / m->tau;
    case 10: return 2.0;
    case 11: return m->spare;
    case 12: return m->timestep;
    default: return NAN;
    }
}

static int model_set(Model *m, unsigned vr, double v) {
    switch (vr) {
    case 0: m->u = v; return 1;
    case 2: m->tau = v; return 1;
    case 3: m->x0 = v; return 1;
    case 4: m->t_fail = v; return 1;
    case 5: m->t_nan = v; return 1;
    case 11: m->spare = v; return 1;
    case 12: m->timestep = v; return 1;
    default: return 0;
    }
}

static void model_defaults(Model *m) {
    m->u = 0.0; m->tau = 1.0; m->x0 = 0.0; m->t_fail = 1e300; m->t_nan = 1e300;
    m->gain = 1; m->offset_on = 0; m->x = 0.0; m->time = 0.0; m->tol = 1e-2;
    m->spare = 1.0; m->timestep = 1e-3;
}

static void model_setup(Model *m, int tolDef, double tol, double start) {
    m->time = start;
    if (tolDef) m->tol = tol;
}

static void model_init(Model *m) {  /* leaving initialization mode */
    m->x = m->x0; m->tg = m->time; m->xg = m->x0;
}

/* explicit Euler on the internal grid of step hi from the grid's last point to end */
static void euler_to(Model *m, double end, double hi) {
    while (m->tg + hi <= end) { m->xg += hi * (m->u - m->xg) / m->tau; m->tg += hi; }
    m->x = m->xg + (end - m->tg) * (m->u - m->xg) / m->tau;
}

/* 0: ok, 1: tau <= 0, 2: time limit, 3: assertion tau <= TAU_MAX */
static int model_step(Model *m, double t, double h) {
    if (m->tau <= 0.0) return 1;
    if (t + h > m->t_fail) return 2;
#ifdef ASSERT_RANGE
    if (m->tau > TAU_MAX) return 3;
#endif
#ifdef STALE_CLOCK
    if (t + h <= m->clock) { m->time = t + h; return 0; }  /* "already there" */
    m->clock = t + h;
#endif
#if defined(LOOSE_TOLERANCE)
    euler_to(m, t + h, 0.5 * sqrt(m->tol));
#elif defined(NUMERICAL_SETTING)
    if (m->timestep <= 0.0) return 1;
    euler_to(m, t + h, m->timestep);
#else
    m->x = m->u + (m->x - m->u) * exp(-h / m->tau);
#endif
    m->time = t + h;
    return 0;
}
"""

_C_FMI2 = (
    r"""
#include "fmi2Functions.h"
#define LOGGER_FIELD fmi2CallbackFunctions cb;
"""
    + _C_COMMON
    + r"""
#define M ((Model *)c)
#define LOG(status, ...) do { if (M->cb.logger) M->cb.logger(M->cb.componentEnvironment, \
    M->name, status, "logStatusError", __VA_ARGS__); } while (0)

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n,
                               const fmi2String cat[]) { (void)c; (void)on; (void)n; (void)cat;
    return fmi2OK; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                              fmi2String res, const fmi2CallbackFunctions *cb,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)type; (void)res; (void)visible; (void)loggingOn;
    if (strcmp(guid, GUID) != 0) return NULL;
#ifdef NEEDS_RESOURCES  /* as JModelica.org's FMUs: no resources folder, no instance */
    if (res == NULL || strncmp(res, "file://", 7) != 0) return NULL;
    {
        const char *path = res + 7;
        char probe[4096];
        if (strncmp(path, "localhost/", 10) == 0) path += 9;
        snprintf(probe, sizeof probe, "%s/.", path);
        FILE *f = fopen(probe, "r");
        if (f == NULL) {  /* says why only when logging is on, as many exporters do */
            if (loggingOn && cb->logger) cb->logger(cb->componentEnvironment, name,
                fmi2Fatal, "logStatusFatal", "cannot open the resources folder %s", path);
            return NULL;
        }
        fclose(f);
    }
#endif
    Model *m = (Model *)calloc(1, sizeof(Model));
    m->cb = *cb;
    m->name = name;
    model_defaults(m);
#ifdef LINK_DEP
    m->x0 = 0.0 * tsid_dep_value();
#endif
    return m;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol,
                               fmi2Real start, fmi2Boolean stopDef, fmi2Real stop) {
    (void)stopDef; (void)stop; model_setup(M, tolDef, tol, start);
#ifdef STALE_CLOCK
    M->tau = 1.0; M->x0 = 0.0;
#endif
    return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    if (M->tau <= 0.0) { LOG(fmi2Error, "tau must be positive"); return fmi2Error; }
    tsid_runs++; model_init(M); return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { model_defaults(M); return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       fmi2Real v[]) {
    for (size_t i = 0; i < n; i++) v[i] = model_get(M, vr[i]);
    return fmi2OK; }
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          fmi2Integer v[]) {
    for (size_t i = 0; i < n; i++) { if (vr[i] != 6) return fmi2Error; v[i] = M->gain; }
    return fmi2OK; }
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          fmi2Boolean v[]) {
    for (size_t i = 0; i < n; i++) { if (vr[i] != 7) return fmi2Error; v[i] = M->offset_on; }
    return fmi2OK; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                         fmi2String v[]) { (void)c; (void)vr; (void)n; (void)v; return fmi2Error; }
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       const fmi2Real v[]) {
    for (size_t i = 0; i < n; i++) if (!model_set(M, vr[i], v[i])) {
        LOG(fmi2Error, "cannot set value reference %u", vr[i]); return fmi2Error; }
    return fmi2OK; }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          const fmi2Integer v[]) {
    for (size_t i = 0; i < n; i++) { if (vr[i] != 6) return fmi2Error; M->gain = v[i]; }
    return fmi2OK; }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          const fmi2Boolean v[]) {
    for (size_t i = 0; i < n; i++) { if (vr[i] != 7) return fmi2Error; M->offset_on = v[i]; }
    return fmi2OK; }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                         const fmi2String v[]) {
    (void)c; (void)vr; (void)n; (void)v; return fmi2Error; }

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) {
    (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)c; (void)s; (void)n; return fmi2Error; }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)c; (void)s; (void)b; (void)n; return fmi2Error; }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n,
                                   fmi2FMUstate *s) { (void)c; (void)s; (void)b; (void)n;
    return fmi2Error; }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference a[], size_t na,
        const fmi2ValueReference b[], size_t nb, const fmi2Real d[], fmi2Real e[]) {
    (void)c; (void)a; (void)na; (void)b; (void)nb; (void)d; (void)e; return fmi2Error; }

/* Model Exchange */
fmi2Status fmi2EnterEventMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *e) {
    (void)c; memset(e, 0, sizeof(*e)); return fmi2OK; }
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean ns, fmi2Boolean *ev,
                                       fmi2Boolean *term) {
    (void)ns; *ev = fmi2False; *term = fmi2False;
    if (M->time > M->t_fail) { LOG(fmi2Error, "time limit t_fail exceeded at t=%g", M->time);
        return fmi2Error; }
    return fmi2OK; }
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { M->time = t; return fmi2OK; }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t n) {
    (void)n; M->x = x[0]; return fmi2OK; }
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real d[], size_t n) {
    (void)n; d[0] = (M->u - M->x) / M->tau; return fmi2OK; }
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t n) {
    (void)c; (void)z; (void)n; return fmi2OK; }
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t n) {
    (void)n; x[0] = M->x; return fmi2OK; }
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t n) {
    (void)c; (void)n; x[0] = 1.0; return fmi2OK; }

/* Co-Simulation */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
        size_t n, const fmi2Integer o[], const fmi2Real v[]) {
    (void)c; (void)vr; (void)n; (void)o; (void)v; return fmi2Error; }
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
        size_t n, const fmi2Integer o[], fmi2Real v[]) {
    (void)c; (void)vr; (void)n; (void)o; (void)v; return fmi2Error; }
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean ns) {
    (void)ns;
#ifdef CHATTY  /* as OpenModelica's runtime does: straight to descriptor 1 */
    if (t == 0) { printf("chatty FMU | debug | first step, tau=%g\n", M->tau); fflush(stdout); }
#endif
    switch (model_step(M, t, h)) {
    case 1: LOG(fmi2Error, "tau must be positive, got %g", M->tau); return fmi2Error;
    case 2: LOG(fmi2Error, "time limit t_fail=%g exceeded at t=%g", M->t_fail, t + h);
            return fmi2Error;
    case 3: LOG(fmi2Error, "assertion: tau = %g outside scope of model (at most %g)",
                M->tau, TAU_MAX); return fmi2Error;
    default: return fmi2OK;
    }
}
fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v) {
    (void)c; (void)k; (void)v; return fmi2Error; }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v) {
    (void)c; (void)k; (void)v; return fmi2Error; }
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v) {
    (void)c; (void)k; (void)v; return fmi2Error; }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v) {
    (void)c; (void)k; (void)v; return fmi2Error; }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v) {
    (void)c; (void)k; (void)v; return fmi2Error; }
"""
)

# FMI 3.0: only the functions FMPy's FMU3Slave calls on a Co-Simulation FMU are real; every
# other fmi3* symbol FMPy looks up is a stub returning fmi3Error (FMPy requires the symbols).
_FMI3_STUBS = """
fmi3InstantiateModelExchange fmi3InstantiateScheduledExecution fmi3EnterEventMode
fmi3GetFloat32 fmi3GetInt8 fmi3GetUInt8 fmi3GetInt16 fmi3GetUInt16 fmi3GetInt32 fmi3GetUInt32
fmi3GetInt64 fmi3GetUInt64 fmi3GetBoolean fmi3GetString fmi3GetBinary fmi3GetClock
fmi3SetFloat32 fmi3SetInt8 fmi3SetUInt8 fmi3SetInt16 fmi3SetUInt16 fmi3SetUInt32
fmi3SetInt64 fmi3SetUInt64 fmi3SetString fmi3SetBinary fmi3SetClock
fmi3GetNumberOfVariableDependencies fmi3GetVariableDependencies fmi3GetFMUState
fmi3SetFMUState fmi3FreeFMUState fmi3SerializedFMUStateSize fmi3SerializeFMUState
fmi3DeserializeFMUState fmi3GetDirectionalDerivative fmi3GetAdjointDerivative
fmi3EnterConfigurationMode fmi3ExitConfigurationMode fmi3GetIntervalDecimal
fmi3GetIntervalFraction fmi3GetShiftDecimal fmi3GetShiftFraction fmi3SetIntervalDecimal
fmi3SetIntervalFraction fmi3SetShiftDecimal fmi3SetShiftFraction fmi3EvaluateDiscreteStates
fmi3UpdateDiscreteStates fmi3EnterContinuousTimeMode fmi3CompletedIntegratorStep fmi3SetTime
fmi3SetContinuousStates fmi3GetContinuousStateDerivatives fmi3GetEventIndicators
fmi3GetContinuousStates fmi3GetNominalsOfContinuousStates fmi3GetNumberOfEventIndicators
fmi3GetNumberOfContinuousStates fmi3EnterStepMode fmi3GetOutputDerivatives
fmi3ActivateModelPartition
""".split()

_C_FMI3 = (
    r"""
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
typedef void (*logfn)(void *env, int status, const char *category, const char *message);
#define LOGGER_FIELD logfn log;
"""
    + _C_COMMON
    + r"""
#define EXPORT __attribute__((visibility("default")))
#define M ((Model *)c)
#define LOG(status, ...) do { if (M->log) { char buf_[256]; snprintf(buf_, sizeof buf_, \
    __VA_ARGS__); M->log(M->env, status, "logStatusError", buf_); } } while (0)

EXPORT const char *fmi3GetVersion(void) { return "3.0"; }
EXPORT int fmi3SetDebugLogging(void *c, bool on, size_t n, const char *const cat[]) {
    (void)c; (void)on; (void)n; (void)cat; return 0; }
EXPORT void *fmi3InstantiateCoSimulation(const char *name, const char *token,
        const char *res, bool visible, bool loggingOn, bool eventMode, bool earlyReturn,
        const unsigned *req, size_t nreq, void *env, logfn log, void *intermediate) {
    (void)res; (void)visible; (void)loggingOn; (void)eventMode; (void)earlyReturn;
    (void)req; (void)nreq; (void)intermediate;
    if (strcmp(token, GUID) != 0) return NULL;
    Model *m = (Model *)calloc(1, sizeof(Model));
    m->log = log; m->env = env; m->name = name;
    model_defaults(m);
#ifdef LINK_DEP
    m->x0 = 0.0 * tsid_dep_value();
#endif
    return m;
}
EXPORT void fmi3FreeInstance(void *c) { free(c); }
EXPORT int fmi3EnterInitializationMode(void *c, bool tolDef, double tol, double start,
                                       bool stopDef, double stop) {
    (void)stopDef; (void)stop; model_setup(M, tolDef, tol, start); return 0; }
EXPORT int fmi3ExitInitializationMode(void *c) {
    if (M->tau <= 0.0) { LOG(3, "tau must be positive"); return 3; }
    tsid_runs++; model_init(M); return 0; }
EXPORT int fmi3Terminate(void *c) { (void)c; return 0; }
EXPORT int fmi3Reset(void *c) { model_defaults(M); return 0; }
EXPORT int fmi3GetFloat64(void *c, const unsigned vr[], size_t n, double v[], size_t nv) {
    (void)nv; for (size_t i = 0; i < n; i++) v[i] = model_get(M, vr[i]); return 0; }
EXPORT int fmi3SetFloat64(void *c, const unsigned vr[], size_t n, const double v[], size_t nv) {
    (void)nv; for (size_t i = 0; i < n; i++) if (!model_set(M, vr[i], v[i])) {
        LOG(3, "cannot set value reference %u", vr[i]); return 3; }
    return 0; }
EXPORT int fmi3SetInt32(void *c, const unsigned vr[], size_t n, const int32_t v[], size_t nv) {
    (void)nv; for (size_t i = 0; i < n; i++) { if (vr[i] != 6) return 3; M->gain = v[i]; }
    return 0; }
EXPORT int fmi3SetBoolean(void *c, const unsigned vr[], size_t n, const bool v[], size_t nv) {
    (void)nv; for (size_t i = 0; i < n; i++) { if (vr[i] != 7) return 3; M->offset_on = v[i]; }
    return 0; }
EXPORT int fmi3DoStep(void *c, double t, double h, bool ns, bool *event, bool *term,
                      bool *early, double *last) {
    (void)ns; *event = false; *term = false; *early = false;
    switch (model_step(M, t, h)) {
    case 1: LOG(3, "tau must be positive, got %g", M->tau); return 3;
    case 2: LOG(3, "time limit t_fail=%g exceeded at t=%g", M->t_fail, t + h); return 3;
    case 3: LOG(3, "assertion: tau = %g outside scope of model (at most %g)", M->tau, TAU_MAX);
            return 3;
    default: *last = t + h; return 0;
    }
}
"""
    + "".join(f"EXPORT int {name}(void) {{ return 3; }}\n" for name in _FMI3_STUBS)
)


QUIRK_VARIABLES = {
    "NO_EFFECT": [("spare", 11, "Real", "parameter", "fixed", "exact", "1.0", "acts on nothing")],
    "NUMERICAL_SETTING": [
        ("timestep", 12, "Real", "parameter", "fixed", "exact", "0.001", "integration time step")
    ],
}
"""The variables a quirk adds after :data:`VARIABLES` (their indices follow its own)."""


def _variables(quirks: Sequence[str]) -> list[tuple]:
    return VARIABLES + [v for q in quirks for v in QUIRK_VARIABLES.get(q, [])]


def _model_description_fmi2(
    name: str, guid: str, interfaces: Sequence[str], quirks: Sequence[str] = ()
) -> str:
    rows = []
    for vname, vr, vtype, causality, variability, initial, start, desc in _variables(quirks):
        attrs = f'name="{vname}" valueReference="{vr}" causality="{causality}" '
        attrs += f'variability="{variability}" description="{desc}"'
        if initial is not None and causality != "input":
            attrs += f' initial="{initial}"'
        type_attrs = ""
        if start is not None:
            type_attrs += f' start="{start}"'
        if vname == "der_x":
            type_attrs += ' derivative="9"'
        if vname in ("tau", "timestep"):
            type_attrs += ' unit="s"'
        rows.append(
            f"    <ScalarVariable {attrs}>\n      <{vtype}{type_attrs}/>\n    </ScalarVariable>"
        )
    cs = (
        (
            f'  <CoSimulation modelIdentifier="{name}" '
            'canHandleVariableCommunicationStepSize="true"/>\n'
        )
        if "cs" in interfaces
        else ""
    )
    me = f'  <ModelExchange modelIdentifier="{name}"/>\n' if "me" in interfaces else ""
    derivatives = (
        '    <Derivatives><Unknown index="10"/></Derivatives>\n' if "me" in interfaces else ""
    )
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{guid}" '
        'generationTool="tsid-fmu tests/fmu_factory.py" numberOfEventIndicators="0" '
        'description="first-order lag der(x) = (u - x)/tau">\n'
        f"{me}{cs}"
        '  <UnitDefinitions><Unit name="s"><BaseUnit s="1"/></Unit></UnitDefinitions>\n'
        '  <DefaultExperiment startTime="0" stopTime="1" stepSize="0.001"/>\n'
        "  <ModelVariables>\n" + "\n".join(rows) + "\n  </ModelVariables>\n"
        '  <ModelStructure>\n    <Outputs><Unknown index="2"/></Outputs>\n'
        + derivatives
        + '    <InitialUnknowns><Unknown index="2"/><Unknown index="9"/>'
        '<Unknown index="10"/></InitialUnknowns>\n'
        "  </ModelStructure>\n</fmiModelDescription>\n"
    )


def _model_description_fmi3(name: str, guid: str, quirks: Sequence[str] = ()) -> str:
    type3 = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}
    rows = [
        '    <Float64 name="time" valueReference="99" causality="independent" '
        'variability="continuous"/>'
    ]
    for vname, vr, vtype, causality, variability, initial, start, desc in _variables(quirks):
        if vname == "der_x":
            continue
        attrs = f'name="{vname}" valueReference="{vr}" causality="{causality}" '
        attrs += f'variability="{variability if vtype == "Real" else "fixed"}"'
        attrs += f' description="{desc}"'
        if initial is not None and causality != "input":
            attrs += f' initial="{initial}"'
        if start is not None:
            attrs += f' start="{start}"'
        rows.append(f"    <{type3[vtype]} {attrs}/>")
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<fmiModelDescription fmiVersion="3.0" modelName="{name}" '
        f'instantiationToken="{guid}" generationTool="tsid-fmu tests/fmu_factory.py">\n'
        f'  <CoSimulation modelIdentifier="{name}" '
        'canHandleVariableCommunicationStepSize="true"/>\n'
        '  <DefaultExperiment startTime="0" stopTime="1" stepSize="0.001"/>\n'
        "  <ModelVariables>\n" + "\n".join(rows) + "\n  </ModelVariables>\n"
        '  <ModelStructure>\n    <Output valueReference="1"/>\n'
        '    <InitialUnknown valueReference="1"/>\n  </ModelStructure>\n'
        "</fmiModelDescription>\n"
    )


def _compile(
    source: Path, output: Path, defines: Sequence[str], libs: Sequence[str], *, hidden: bool = True
) -> None:
    """gcc ``source`` into the shared library ``output`` (symbols hidden unless exported)."""
    visibility = ["-fvisibility=hidden"] if hidden else []
    cmd = ["gcc", "-shared", "-fPIC", "-O2", *visibility, f"-I{HEADERS}", "-o", str(output),
           str(source), *defines, *libs, "-lm"]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"gcc failed:\n{' '.join(cmd)}\n{proc.stderr[:2000]}")


def new_guid() -> str:
    """A fresh ``{...}`` GUID for a model description."""
    return "{" + str(uuid.uuid4()) + "}"


# Every fmi2* function FMPy looks up in an FMI 2.0 binary (common, Model Exchange,
# Co-Simulation); fmi2_source() stubs the ones a hand-written model leaves out.
_FMI2_FUNCTIONS = """
fmi2GetTypesPlatform fmi2GetVersion fmi2SetDebugLogging fmi2Instantiate fmi2FreeInstance
fmi2SetupExperiment fmi2EnterInitializationMode fmi2ExitInitializationMode fmi2Terminate
fmi2Reset fmi2GetReal fmi2GetInteger fmi2GetBoolean fmi2GetString fmi2SetReal fmi2SetInteger
fmi2SetBoolean fmi2SetString fmi2GetFMUstate fmi2SetFMUstate fmi2FreeFMUstate
fmi2SerializedFMUstateSize fmi2SerializeFMUstate fmi2DeSerializeFMUstate
fmi2GetDirectionalDerivative
fmi2EnterEventMode fmi2NewDiscreteStates fmi2EnterContinuousTimeMode
fmi2CompletedIntegratorStep fmi2SetTime fmi2SetContinuousStates fmi2GetDerivatives
fmi2GetEventIndicators fmi2GetContinuousStates fmi2GetNominalsOfContinuousStates
fmi2SetRealInputDerivatives fmi2GetRealOutputDerivatives fmi2DoStep fmi2CancelStep
fmi2GetStatus fmi2GetRealStatus fmi2GetIntegerStatus fmi2GetBooleanStatus fmi2GetStringStatus
""".split()

# The FMI 2.0 life cycle and Real access of a hand-written model without the FMI headers.
_FMI2_ENTRY_POINTS = r"""
#include <stdlib.h>
#include <string.h>

const char *fmi2GetTypesPlatform(void) { return "default"; }
const char *fmi2GetVersion(void) { return "2.0"; }
int fmi2SetDebugLogging(void *c, int on, size_t n, const char *const cat[]) {
    (void)c; (void)on; (void)n; (void)cat; return 0; }
void *fmi2Instantiate(const char *name, int type, const char *guid, const char *res,
                      const void *cb, int visible, int loggingOn) {
    (void)name; (void)type; (void)res; (void)cb; (void)visible; (void)loggingOn;
    if (strcmp(guid, GUID) != 0) return NULL;
    Model *m = malloc(sizeof *m); defaults(m); return m;
}
void fmi2FreeInstance(void *c) { free(c); }
int fmi2SetupExperiment(void *c, int tolDef, double tol, double start, int stopDef,
                        double stop) {
    (void)tolDef; (void)tol; (void)stopDef; (void)stop; M->time = start; return 0; }
int fmi2EnterInitializationMode(void *c) { (void)c; return 0; }
int fmi2ExitInitializationMode(void *c) { (void)c; return 0; }
int fmi2Terminate(void *c) { (void)c; return 0; }
int fmi2Reset(void *c) { defaults(M); return 0; }
int fmi2GetReal(void *c, const unsigned vr[], size_t n, double v[]) {
    for (size_t i = 0; i < n; i++) if (get(M, vr[i], &v[i])) return 3;
    return 0; }
int fmi2SetReal(void *c, const unsigned vr[], size_t n, const double v[]) {
    for (size_t i = 0; i < n; i++) if (set(M, vr[i], v[i])) return 3;
    return 0; }
"""


def fmi2_source(model: str, functions: str = "") -> str:
    """The C source of an FMI 2.0 FMU from a hand-written ``model`` and its own ``functions``.

    ``model`` defines ``Model`` (with a ``double time`` that ``fmi2SetupExperiment`` sets),
    the macro ``M`` (``c`` as a ``Model *``), ``defaults(Model *)``, and ``get(const Model *,
    unsigned vr, double *)`` and ``set(Model *, unsigned vr, double)`` returning nonzero for
    a value reference they do not read or write. The shared entry points (instantiation,
    modes, ``fmi2GetReal``/``fmi2SetReal``) follow it, then ``functions`` (``fmi2DoStep``,
    the Model Exchange functions, ...), then a stub returning ``fmi2Error`` for every other
    function FMPy looks up.
    """
    source = model + _FMI2_ENTRY_POINTS + functions
    missing = [f for f in _FMI2_FUNCTIONS if not re.search(rf"\b{f}\(", source)]
    return source + "".join(f"int {f}(void) {{ return 3; }}\n" for f in missing)


def pack_c_fmu(
    tmp_dir: Path,
    name: str,
    source: str,
    model_description: str,
    guid: str,
    *,
    platform_dir: str | None = None,
    defines: Sequence[str] = (),
    libs: Sequence[str] = (),
    hidden: bool = True,
) -> Path:
    """Compile ``source`` and zip it with ``model_description`` into ``<tmp_dir>/<name>.fmu``.

    The library goes to ``binaries/<platform_dir>/<name>.so`` (FMPy's FMI 2 platform
    folder by default), compiled with ``-DGUID="<guid>"`` and ``defines``; the source is
    kept under ``sources/``. Returns the FMU's path.
    """
    tmp_dir = Path(tmp_dir)
    work = tmp_dir / f"{name}_build"
    if work.exists():
        shutil.rmtree(work)
    bindir = work / "binaries" / (platform_dir or fmpy.platform)
    bindir.mkdir(parents=True)
    (work / "sources").mkdir()
    src = work / "sources" / f"{name}.c"
    src.write_text(source)
    (work / "modelDescription.xml").write_text(model_description)
    _compile(src, bindir / f"{name}.so", [f'-DGUID="{guid}"', *defines], libs, hidden=hidden)
    fmu = tmp_dir / f"{name}.fmu"
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as zf:
        for file in sorted(work.rglob("*")):
            if file.is_file():
                zf.write(file, file.relative_to(work).as_posix())
    shutil.rmtree(work)
    return fmu


def build_stub_library(tmp_dir: Path, name: str = "tsiddep") -> Path:
    """Compile ``lib<name>.so`` exporting ``int tsid_dep_value(void)``; return its path."""
    tmp_dir = Path(tmp_dir)
    tmp_dir.mkdir(parents=True, exist_ok=True)
    src = tmp_dir / f"{name}.c"
    src.write_text(
        '__attribute__((visibility("default")))\nint tsid_dep_value(void) { return 0; }\n'
    )
    lib = tmp_dir / f"lib{name}.so"
    _compile(src, lib, [], [])
    return lib


def build_c_fmu(
    tmp_dir: Path,
    name: str = "FirstOrderLag",
    *,
    fmi_version: str = "2.0",
    interfaces: Sequence[str] = ("cs", "me"),
    link_library: Path | None = None,
    chatty: bool = False,
    needs_resources: bool = False,
    quirks: Sequence[str] = (),
) -> Path:
    """Build the first-order-lag FMU ``<tmp_dir>/<name>.fmu`` and return its path.

    ``chatty`` (FMI 2): the FMU prints a line on its native stdout at each run's first
    step, as OpenModelica's runtime prints its asserts. ``needs_resources`` (FMI 2): the
    FMU fails to instantiate unless its resources folder exists, as JModelica.org's do;
    the archive then holds that folder as an empty member.

    ``fmi_version`` is ``"2.0"`` (Co-Simulation and/or Model Exchange, per ``interfaces``)
    or ``"3.0"`` (Co-Simulation only).  ``link_library`` (from :func:`build_stub_library`)
    makes the FMU's shared library depend on it, so deleting it afterwards gives an FMU
    whose binary cannot be loaded.

    ``quirks`` (issue 62): ``"STALE_CLOCK"`` -- reset keeps the FMU's clock, so after
    the first run no step integrates and ``y`` stays at its initial value (and FMI 2's
    ``fmi2SetupExperiment`` restores the default parameters), as 20-sim 4.6's FMUs do;
    ``"NONDETERMINISTIC"`` -- ``y`` grows by 1e-3 with every run of the loaded library;
    ``"LOOSE_TOLERANCE"`` -- Co-Simulation integrates explicit Euler on an internal grid of
    step ``0.5 sqrt(tol)`` independent of the communication step, ``tol`` the tolerance
    passed to ``fmi2SetupExperiment`` / ``fmi3EnterInitializationMode`` (1e-2 when none is
    defined): about 7 % of bias on ``tau`` = 0.37 s at the default, none at 1e-8;
    ``"ASSERT_RANGE"`` -- a Co-Simulation step fails on an assertion ("tau = ... outside
    scope of model") where ``tau`` > 1.2, as Dymola's models assert on a temperature;
    ``"NO_EFFECT"`` -- a parameter ``spare`` (start 1) that acts on nothing;
    ``"NUMERICAL_SETTING"`` -- Co-Simulation integrates explicit Euler on an internal grid
    of step ``timestep`` (a parameter, unit s, start 1e-3, "integration time step"),
    as Hopsan's FMUs expose their time step.
    """
    guid = new_guid()
    if fmi_version == "2.0":
        platform_dir = fmpy.platform
        source, xml = _C_FMI2, _model_description_fmi2(name, guid, interfaces, quirks)
    elif fmi_version == "3.0":
        platform_dir = fmpy.platform_tuple
        source, xml = _C_FMI3, _model_description_fmi3(name, guid, quirks)
    else:
        raise ValueError(f"unsupported FMI version {fmi_version}")
    defines: list[str] = ["-DCHATTY"] if chatty else []
    defines += ["-DNEEDS_RESOURCES"] if needs_resources else []
    defines += [f"-D{q}" for q in quirks]
    libs: list[str] = []
    if link_library is not None:
        link_library = Path(link_library)
        defines.append("-DLINK_DEP")
        libs = [f"-L{link_library.parent}", f"-l{link_library.stem.removeprefix('lib')}"]
    fmu = pack_c_fmu(
        tmp_dir, name, source, xml, guid, platform_dir=platform_dir, defines=defines, libs=libs
    )
    if needs_resources:  # an empty folder is a member of its own, as JModelica.org packs it
        with zipfile.ZipFile(fmu, "a") as zf:
            zf.writestr(zipfile.ZipInfo("resources/"), b"")
    return fmu


def copy_without(fmu: Path, dest: Path, prefix: str) -> Path:
    """Copy ``fmu`` to ``dest`` leaving out every member whose name starts with ``prefix``."""
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(dest, "w") as dst:
        for item in src.infolist():
            if not item.filename.startswith(prefix):
                dst.writestr(item, src.read(item.filename))
    return dest


def lag_response(
    time: np.ndarray,
    u: np.ndarray,
    tau: float,
    x0: float = 0.0,
    gain: int = 1,
    offset: float = 0.0,
) -> np.ndarray:
    """Exact output of the lag for input ``u[k]`` held over ``[time[k], time[k+1])``."""
    x = np.empty(len(time))
    x[0] = x0
    for k in range(len(time) - 1):
        h = time[k + 1] - time[k]
        x[k + 1] = u[k] + (x[k] - u[k]) * np.exp(-h / tau)
    return gain * x + offset


def lag_case(tmp_dir: Path, dt: float = 0.01) -> Path:
    """Build a Co-Simulation lag ``Lag.fmu`` and its exact step response ``good.csv``.

    One second at ``dt``, input 1 until 0.5 s, then 0, tau 0.3 s. Returns the FMU's path.
    """
    fmu = build_c_fmu(tmp_dir, "Lag", interfaces=("cs",))
    t = np.arange(0, 1.0 + 1e-9, dt)
    u = np.where(t < 0.5, 1.0, 0.0)
    pd.DataFrame({"time": t, "u": u, "y": lag_response(t, u, 0.3)}).to_csv(
        Path(tmp_dir) / "good.csv", index=False
    )
    return fmu


def lag_data(tmp_dir: Path, tau: float, x0: float) -> tuple[Path, Path]:
    """Build the lag FMU (both interfaces) and a noisy measurement ``lag.csv`` of it.

    Five seconds at 10 ms of a square wave (1, then -0.5, period 2 s) plus ``0.3 sin(3t)``
    as ``u``, and as ``y_meas`` the lag's response for ``tau``, ``x0`` with Gaussian noise
    of 1 % of its standard deviation (``default_rng(0)``). Returns the FMU's and the CSV's
    paths.
    """
    fmu = build_c_fmu(tmp_dir)
    t = np.arange(0, 5.0 + 1e-9, 0.01)
    u = np.where((t % 2.0) < 1.0, 1.0, -0.5) + 0.3 * np.sin(3 * t)
    y = lag_response(t, u, tau, x0)
    y = y + np.random.default_rng(0).normal(0, 0.01 * np.std(y), y.shape)
    data = Path(tmp_dir) / "lag.csv"
    pd.DataFrame({"time": t, "u": u, "y_meas": y}).to_csv(data, index=False)
    return fmu, data


def lag_study(tmp_dir: Path, **options):
    """The study of :func:`lag_data` (tau 0.37, x0 0.8): tau in s and x0 over three levels.

    ``options`` go to :class:`tsid_fmu.Study` (``name``, ``replicates``, ...).
    """
    from tsid_fmu import Experiment, Parameter, Study

    fmu, data = lag_data(tmp_dir, 0.37, 0.8)
    # the SISO paper's method, which these tests were written for (not the defaults)
    if "method" not in options:
        options = {"cost": "iae", "weighting": "none", "replicates": 2, **options}
    return Study(
        fmu=fmu,
        parameters=[
            Parameter("tau", [0.05, 0.5, 2.0], min=0.0, unit="s"),
            Parameter("x0", [-1.0, 0.0, 2.0]),
        ],
        experiments=[Experiment(data=data, inputs={"u": "u"}, outputs={"y": "y_meas"})],
        **options,
    )


LAG_TOML = """\
[study]
fmu = "Lag.fmu"
[data]
file = "d.csv"
inputs = { u = "u" }
outputs = { y = "y" }
[method]
seed = 7
max_iterations = 8
cost = "iae"  # the SISO paper's cost: these tests were written for it
weighting = "none"
replicates = 2
[leveling]
tolerance = 0.0001
[parameters]
tau = { levels = [0.05, 0.5, 2.0], min = 0 }
x0 = { levels = [-1.0, 0.0, 2.0] }
"""
"""A lag study on ``Lag.fmu`` and ``d.csv`` in its folder, for the signal and resume tests."""


PYLAG_TOML = """\
[study]
fmu = "{fmu}"
[data]
file = "d.csv"
inputs = {{ u = "u" }}
outputs = {{ y = "y" }}
[method]
seed = 7
max_iterations = 4
cost = "iae"  # the SISO paper's cost: these tests were written for it
weighting = "none"
replicates = 2
[parameters]
tau = {{ levels = [0.05, 0.5, 2.0], min = 0.001 }}
"""
"""A lag study of a pythonfmu FMU (``{fmu}``, :func:`build_pythonfmu`) on ``d.csv``: the
vendor-exit test and ``benchmarks/exit_abort.py``."""


_PYTHONFMU_SLAVE = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class {name}(Fmi2Slave):
    """First-order lag der(y) = (u - y)/tau, explicit Euler."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.y = 0.0
        self.tau = 1.0
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))
        self.register_variable(Real("tau", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.tunable))

    def do_step(self, current_time, step_size):
        self.y += step_size * (self.u - self.y) / self.tau
        return True
'''


_PYTHONFMU_COUNTER = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class {name}(Fmi2Slave):
    """A discrete-time accumulator: y += increment * u at every communication step."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.y = 0.0
        self.increment = 1.0
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))
        self.register_variable(Real("increment", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.tunable))

    def do_step(self, current_time, step_size):
        self.y += self.increment * self.u
        return True
'''


_PYTHONFMU_RC = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class {name}(Fmi2Slave):
    """First-order lag der(y) = (u - y)/(R C), 20 explicit Euler steps per step."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.y = 0.0
        self.R = 1.0
        self.C = 1.0
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))
        for name in ("R", "C"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.tunable))

    def do_step(self, current_time, step_size):
        h = step_size / 20.0
        for _ in range(20):
            self.y += h * (self.u - self.y) / (self.R * self.C)
        return True
'''


def pythonfmu_available() -> bool:
    """True when ``pythonfmu`` is importable and this Python has a shared libpython."""
    try:
        import pythonfmu  # noqa: F401
    except ImportError:
        return False
    return bool(sysconfig.get_config_var("Py_ENABLE_SHARED"))


def build_pythonfmu(
    tmp_dir: Path, name: str = "PyLag", *, counter: bool = False, rc: bool = False
) -> Path:
    """Build the lag as a ``pythonfmu`` Co-Simulation FMU and return its path.

    ``counter``: instead, a discrete-time accumulator ``y += increment * u`` once per
    communication step (as PythonFMU3's ``FMU3Model`` adds ``increment`` per step).
    ``rc``: instead, the lag with ``tau = R * C`` (parameters ``R`` and ``C``): the
    outputs depend on their product only, whatever the input (as modestpy's
    ``Simple2R1C`` on R1 C and R2 C).
    """
    tmp_dir = Path(tmp_dir)
    script = tmp_dir / f"{name.lower()}_slave.py"
    source = _PYTHONFMU_COUNTER if counter else _PYTHONFMU_RC if rc else _PYTHONFMU_SLAVE
    script.write_text(textwrap.dedent(source.format(name=name)))
    proc = subprocess.run(
        [sys.executable, "-m", "pythonfmu", "build", "-f", str(script), "-d", str(tmp_dir)],
        capture_output=True,
        text=True,
        check=False,
    )
    fmu = tmp_dir / f"{name}.fmu"
    if proc.returncode != 0 or not fmu.exists():
        raise RuntimeError(f"pythonfmu build failed:\n{proc.stdout}\n{proc.stderr}")
    return fmu

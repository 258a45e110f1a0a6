/*
 * Model-independent core of the tsid-fmu FMUs (see tsid_core.h).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */

#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tsid_core.h"

/* Event location in Co-Simulation: bisection until the bracket is this short [s], at
 * most this many located events per internal step (the rest of the step is then taken
 * as is). */
#define EVENT_TIME_TOL 1e-10
#define MAX_EVENTS_PER_STEP 8
/* Slopes of the indicators: finite differences along the flow over this fraction of
 * fixedStepSize. A rest of a step shorter than MIN_PROBED_STEP [s] is only checked at
 * its end. */
#define SLOPE_REL_STEP 1e-6
#define MIN_PROBED_STEP 1e-9
/* Newton search for the first crossing: at most this many steps to a predicted zero,
 * each that much beyond it (relative), plus EVENT_TIME_TOL. */
#define NEWTON_PROBES 6
#define NEWTON_OVERSHOOT 1e-3
/* Return code of an internal step whose relations do not settle (see csModes). */
#define STEP_UNSETTLED 2

#define X(d) ((d)->r + X_OFF)
#define DX(d) ((d)->r + DX_OFF)
#define U(d) ((d)->r + U_OFF)
#define W(d) ((d)->r + W_OFF)
#define P(d) ((d)->r + P_OFF)

/* ----------------------------------------------------------------- housekeeping */

CoreStatus coreReset(Core *core) {
    CoreData *d;
    if (!core) return CoreError;
    d = &core->d;
    memset(d, 0, sizeof(*d));
    memcpy(d->r, model_start, sizeof(d->r));
    d->dirty = 1;
    core->state = StateInstantiated;
    core->eventIterations = 0;
    core->tRequested = -HUGE_VAL;
    return CoreOK;
}

Core *coreNew(size_t size, const char *instanceName, int isModelExchange, int loggingOn,
              CoreLogger log) {
    Core *core = (Core *)calloc(1, size);
    size_t n = strlen(instanceName) + 1;
    if (!core) return NULL;
    core->instanceName = (char *)malloc(n);
    if (!core->instanceName) {
        free(core);
        return NULL;
    }
    memcpy(core->instanceName, instanceName, n);
    core->isModelExchange = isModelExchange;
    core->loggingOn = loggingOn;
    core->log = log;
    core->requestInputs = NULL;
    coreReset(core);
    return core;
}

CoreStatus coreSetDebugLogging(Core *core, int loggingOn) {
    if (!core) return CoreError;
    core->loggingOn = loggingOn;
    return CoreOK;
}

void coreFree(Core *core) {
    if (!core) return;
    free(core->instanceName);
    free(core);
}

void coreLog(Core *core, CoreStatus status, const char *category, const char *fmt, ...) {
    char buf[1024];
    va_list args;
    if (!core || !core->log) return;
    if (status == CoreOK && !core->loggingOn) return;
    va_start(args, fmt);
    vsnprintf(buf, sizeof(buf), fmt, args);
    va_end(args);
    core->log(core, status, category, buf);
}

CoreStatus coreFail(Core *core, const char *caller, const char *message) {
    coreLog(core, CoreError, "logStatusError", "%s: %s", caller, message);
    return CoreError;
}

int coreAllowed(Core *core, int mask, const char *caller) {
    if (!core) return 0;
    if (core->state & mask) return 1;
    coreLog(core, CoreError, "logStatusError", "%s: illegal call sequence", caller);
    return 0;
}

int coreIsInput(unsigned int vr) { return vr >= U_OFF && vr < U_OFF + NU; }

static int isState(unsigned int vr) { return vr < X_OFF + NX; }

static int isParameter(unsigned int vr) { return vr >= P_OFF && vr <= VR_FIXED_STEP; }

static int inInitPhase(const Core *core) { return (core->state & INIT_PHASE) != 0; }

/* Checks that vr may be set now. */
static CoreStatus checkSet(Core *core, unsigned int vr, const char *caller) {
    int init = inInitPhase(core);
    if (core->state == StateIntermediateUpdateMode && !coreIsInput(vr)) {
        return coreFail(core, caller, "only inputs can be set in Intermediate Update Mode");
    }
    if (vr >= N_REAL) {
        coreLog(core, CoreError, "logStatusError", "%s: unknown value reference %u", caller, vr);
        return CoreError;
    }
    if (isParameter(vr) && !init) {
        coreLog(core, CoreError, "logStatusError",
                "%s: parameter %s is fixed after initialization", caller, model_names[vr]);
        return CoreError;
    }
    if (isState(vr) && !init) {
        coreLog(core, CoreError, "logStatusError",
                "%s: %s can only be set before or during initialization", caller,
                model_names[vr]);
        return CoreError;
    }
    if (!coreIsInput(vr) && !isParameter(vr) && !isState(vr)) {
        coreLog(core, CoreError, "logStatusError",
                "%s: %s is not an input, state or parameter", caller, model_names[vr]);
        return CoreError;
    }
    return CoreOK;
}

void coreInvalidate(Core *core, int initPhase) {
    core->d.dirty = 1;
    if (initPhase) core->d.modesValid = 0;
}

static int allFinite(const double *v, int n, int *bad) {
    int i;
    for (i = 0; i < n; i++) {
        if (!isfinite(v[i])) {
            *bad = i;
            return 0;
        }
    }
    return 1;
}

/* ------------------------------------------------------------------ evaluation */

/* Initialization Mode: the states whose initial value is an expression of the
 * parameters take it, from the parameter values set so far (model_init). */
static CoreStatus initialStates(Core *core, const char *caller) {
#if NX_INIT > 0
    CoreData *d = &core->d;
    double x0[NX + 1];
    int bad = 0;
    if (core->state != StateInitializationMode) return CoreOK;
    if (model_init(X(d), P(d), x0) != 0 || !allFinite(x0, NX, &bad)) {
        coreLog(core, CoreError, "logStatusError",
                "%s: the initial value of %s computed from the parameters is not finite",
                caller, model_names[X_OFF + bad]);
        return CoreError;
    }
    memcpy(X(d), x0, NX * sizeof(double));
#else
    (void)core;
    (void)caller;
#endif
    return CoreOK;
}

CoreStatus coreEvaluate(Core *core, const char *caller) {
    CoreData *d = &core->d;
    int bad = 0, rc;
    if (!d->dirty) return CoreOK;
    if (initialStates(core, caller) != CoreOK) return CoreError;
    if (core->isModelExchange) {
        if (!d->modesValid && coreInitModes(core, caller) != CoreOK) return CoreError;
        rc = model_eval_me(d->time, X(d), U(d), P(d), d->c, DX(d), W(d));
    } else {
        rc = model_eval(d->time, X(d), U(d), P(d), DX(d), W(d));
    }
    if (rc != 0) {
        coreLog(core, CoreError, "logStatusError",
                "%s: evaluation of the model equations failed at t = %g", caller, d->time);
        return CoreError;
    }
    d->dirty = 0;
    if (!allFinite(DX(d), NX, &bad)) {
        coreLog(core, CoreError, "logStatusError", "%s: non-finite value of %s at t = %g",
                caller, model_names[DX_OFF + bad], d->time);
        return CoreError;
    }
    if (!allFinite(W(d), NW, &bad)) {
        coreLog(core, CoreError, "logStatusError", "%s: non-finite value of %s at t = %g",
                caller, model_names[W_OFF + bad], d->time);
        return CoreError;
    }
    return CoreOK;
}

CoreStatus coreRefresh(Core *core, const char *caller) {
    CoreStatus s = CoreOK;
    if (core->d.dirty && !(core->state & (StateInstantiated | StateError))) {
        s = coreEvaluate(core, caller);
        /* report once; values are returned as they are */
        if (s != CoreOK) core->d.dirty = 0;
    }
    return s;
}

CoreStatus coreSetReals(Core *core, const unsigned int vr[], size_t nvr, const double value[],
                        const char *caller) {
    size_t i;
    for (i = 0; i < nvr; i++) {
        if (checkSet(core, vr[i], caller) != CoreOK) return CoreError;
    }
    for (i = 0; i < nvr; i++) core->d.r[vr[i]] = value[i];
    coreInvalidate(core, inInitPhase(core));
    return CoreOK;
}

/* ------------------------------------------------------- initialization, FMU state */

CoreStatus coreSetupExperiment(Core *core, int toleranceDefined, double tolerance,
                               double startTime, int stopTimeDefined, double stopTime,
                               const char *caller) {
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    if (!coreAllowed(core, StateInstantiated, caller)) return CoreError;
    core->d.time = startTime;
    core->d.startTime = startTime;
    core->d.nSteps = 0;
    coreInvalidate(core, 1);
    return CoreOK;
}

CoreStatus coreEnterInitializationMode(Core *core, const char *caller) {
    if (!coreAllowed(core, StateInstantiated, caller)) return CoreError;
    core->state = StateInitializationMode;
    coreInvalidate(core, 1);
    return CoreOK;
}

CoreStatus coreExitInitializationMode(Core *core, const char *caller) {
    double h;
    if (!coreAllowed(core, StateInitializationMode, caller)) return CoreError;
    h = core->d.r[VR_FIXED_STEP];
    if (!(h > 0.0) || !isfinite(h)) {
        coreLog(core, CoreError, "logStatusError", "%s: fixedStepSize = %g must be > 0",
                caller, h);
        core->state = StateError;
        return CoreError;
    }
    coreInvalidate(core, 1);
    if (initialStates(core, caller) != CoreOK ||
        (core->isModelExchange && coreInitModes(core, caller) != CoreOK) ||
        coreEvaluate(core, caller) != CoreOK) {
        core->state = StateError;
        return CoreError;
    }
    core->state = core->isModelExchange ? StateEventMode : StateStepMode;
    return CoreOK;
}

CoreStatus coreTerminate(Core *core, const char *caller) {
    if (!coreAllowed(core, StateEventMode | StateContinuousTimeMode | StateStepMode, caller)) {
        return CoreError;
    }
    core->state = StateTerminated;
    return CoreOK;
}

CoreStatus coreGetFMUState(Core *core, void **state, const char *caller) {
    CoreData *copy;
    if (!coreAllowed(core, ANY_STATE, caller)) return CoreError;
    if (!state) return coreFail(core, caller, "NULL argument");
    copy = *state ? (CoreData *)*state : (CoreData *)malloc(sizeof(CoreData));
    if (!copy) return coreFail(core, caller, "out of memory");
    *copy = core->d;
    *state = copy;
    return CoreOK;
}

CoreStatus coreSetFMUState(Core *core, const void *state, const char *caller) {
    if (!coreAllowed(core, ANY_STATE, caller)) return CoreError;
    if (!state) return coreFail(core, caller, "NULL state");
    core->d = *(const CoreData *)state;
    core->d.dirty = 1;
    return CoreOK;
}

CoreStatus coreFreeFMUState(Core *core, void **state) {
    (void)core;
    if (state && *state) {
        free(*state);
        *state = NULL;
    }
    return CoreOK;
}

/* -------------------------------------------------------------- Model Exchange */

static CoreStatus relations(Core *core, double z[], double s[], const char *caller) {
    CoreData *d = &core->d;
    if (model_rel(d->time, X(d), U(d), P(d), d->c, z, s) != 0) {
        coreLog(core, CoreError, "logStatusError",
                "%s: evaluation of the event indicators failed at t = %g", caller, d->time);
        return CoreError;
    }
    return CoreOK;
}

static double hysteresis(double s) {
    double eps = TSID_HYSTERESIS * s;
    return eps >= DBL_MIN ? eps : DBL_MIN;
}

/* Relations evaluated as written (no hysteresis), repeated until they agree with the
 * values they were computed with (relations may depend on other relations). */
CoreStatus coreInitModes(Core *core, const char *caller) {
    CoreData *d = &core->d;
    double z[NREL + 1], s[NREL + 1];
    int it, k, changed;
    for (it = 0; it <= NREL + 1; it++) {
        if (relations(core, z, s, caller) != CoreOK) return CoreError;
        changed = 0;
        for (k = 0; k < NREL; k++) {
            double v = (model_rel_strict[k] ? z[k] > 0.0 : z[k] >= 0.0) ? 1.0 : 0.0;
            if (v != d->c[k]) {
                d->c[k] = v;
                changed = 1;
            }
        }
        if (!changed) {
            d->modesValid = 1;
            d->dirty = 1;
            return CoreOK;
        }
    }
    coreLog(core, CoreError, "logStatusError",
            "%s: the relations do not settle at t = %g (they depend on each other)", caller,
            d->time);
    return CoreError;
}

static CoreStatus indicators(Core *core, double e[], const char *caller) {
    CoreData *d = &core->d;
    double z[NREL + 1], s[NREL + 1];
    int k;
    if (!core->isModelExchange || !d->modesValid) {
        if (coreInitModes(core, caller) != CoreOK) return CoreError;
    }
    if (relations(core, z, s, caller) != CoreOK) return CoreError;
    for (k = 0; k < NREL; k++) {
        double eps = hysteresis(s[k]);
        e[k] = d->c[k] != 0.0 ? z[k] + eps : z[k] - eps;
    }
    return CoreOK;
}

CoreStatus coreEventIndicators(Core *core, double e[], const char *caller) {
    return indicators(core, e, caller);
}

static CoreStatus updateModes(Core *core, int *changed, const char *caller) {
    CoreData *d = &core->d;
    double e[NREL + 1];
    int k;
    *changed = 0;
    if (NREL == 0) return CoreOK;
    if (indicators(core, e, caller) != CoreOK) return CoreError;
    for (k = 0; k < NREL; k++) {
        double v = e[k] > 0.0 ? 1.0 : 0.0;
        if (v != d->c[k]) {
            coreLog(core, CoreOK, "logEvents", "t = %.17g: relation %s becomes %s", d->time,
                    model_rel_text[k], v != 0.0 ? "true" : "false");
            d->c[k] = v;
            *changed = 1;
        }
    }
    if (*changed) {
        d->dirty = 1;
        if (++core->eventIterations > TSID_MAX_EVENT_ITERATIONS) {
            coreLog(core, CoreError, "logStatusError",
                    "%s: the relations keep changing at t = %g (more than %d event "
                    "iterations)", caller, d->time, TSID_MAX_EVENT_ITERATIONS);
            return CoreError;
        }
    } else {
        core->eventIterations = 0;
    }
    return CoreOK;
}

void coreEnterEventMode(Core *core) {
    core->state = StateEventMode;
    core->eventIterations = 0;
}

CoreStatus coreUpdateModes(Core *core, int *changed, const char *caller) {
    if (updateModes(core, changed, caller) == CoreOK) return CoreOK;
    core->state = StateError;
    return CoreError;
}

CoreStatus coreModeChangePending(Core *core, int *pending, const char *caller) {
    double e[NREL + 1];
    int k;
    *pending = 0;
    if (NREL == 0) return CoreOK;
    if (indicators(core, e, caller) != CoreOK) return CoreError;
    for (k = 0; k < NREL; k++) {
        if ((e[k] > 0.0) != (core->d.c[k] != 0.0)) *pending = 1;
    }
    return CoreOK;
}

void coreSetTime(Core *core, double time) {
    core->d.time = time;
    coreInvalidate(core, inInitPhase(core));
}

/* Checks an array of the continuous states passed to caller: its size n and pointer p. */
static CoreStatus checkStates(Core *core, const void *p, size_t n, const char *caller) {
    if (n != NX) return coreFail(core, caller, "wrong number of states");
    if (n > 0 && !p) return coreFail(core, caller, "NULL argument");
    return CoreOK;
}

CoreStatus coreSetContinuousStates(Core *core, const double x[], size_t n, const char *caller) {
    size_t i;
    if (checkStates(core, x, n, caller) != CoreOK) return CoreError;
    for (i = 0; i < n; i++) {
        if (!isfinite(x[i])) {
            coreLog(core, CoreError, "logStatusError", "%s: non-finite value of state %s",
                    caller, model_names[X_OFF + i]);
            return CoreError;
        }
        core->d.r[X_OFF + i] = x[i];
    }
    coreInvalidate(core, 0);
    return CoreOK;
}

CoreStatus coreGetContinuousStates(Core *core, double x[], size_t n, const char *caller) {
    size_t i;
    if (!coreAllowed(core, ANY_STATE, caller)) return CoreError;
    if (checkStates(core, x, n, caller) != CoreOK) return CoreError;
    for (i = 0; i < n; i++) x[i] = core->d.r[X_OFF + i];
    return CoreOK;
}

CoreStatus coreGetNominals(Core *core, double nominals[], size_t n, const char *caller) {
    size_t i;
    if (!coreAllowed(core, ANY_STATE, caller)) return CoreError;
    if (checkStates(core, nominals, n, caller) != CoreOK) return CoreError;
    for (i = 0; i < n; i++) nominals[i] = 1.0;
    return CoreOK;
}

CoreStatus coreGetDerivatives(Core *core, double dx[], size_t n, const char *caller) {
    CoreStatus s;
    size_t i;
    if (checkStates(core, dx, n, caller) != CoreOK) return CoreError;
    s = coreEvaluate(core, caller);
    for (i = 0; i < n; i++) dx[i] = core->d.r[DX_OFF + i];
    return s;
}

CoreStatus coreGetEventIndicators(Core *core, double e[], size_t ni, const char *caller) {
    if (ni != NREL) return coreFail(core, caller, "wrong number of event indicators");
    if (ni == 0) return CoreOK;
    if (!e) return coreFail(core, caller, "NULL argument");
    return indicators(core, e, caller);
}

/* --------------------------------------------------------------- Co-Simulation */

CoreStatus coreSetInputDerivative(Core *core, unsigned int vr, int order, double value,
                                  const char *caller) {
    if (!coreIsInput(vr)) {
        coreLog(core, CoreError, "logStatusError", "%s: value reference %u is not an input",
                caller, vr);
        return CoreError;
    }
    if (order < 1) {
        coreLog(core, CoreError, "logStatusError", "%s: derivative order %d of %s (must be >= 1)",
                caller, order, model_names[vr]);
        return CoreError;
    }
    if (order > 1) {
        coreLog(core, CoreWarning, "logStatusWarning",
                "%s: derivative of order %d of %s ignored (inputs are interpolated linearly)",
                caller, order, model_names[vr]);
        return CoreWarning;
    }
    if (!isfinite(value)) {
        coreLog(core, CoreError, "logStatusError", "%s: non-finite derivative of %s", caller,
                model_names[vr]);
        return CoreError;
    }
    core->d.du[vr - U_OFF] = value;
    core->d.hasDu = 1;
    return CoreOK;
}

/* Inputs at time t of the communication step that started at tc: the values set (held),
 * interpolated with du, or set by the importer for time t (FMI 3.0). NULL on failure. */
static const double *inputsAt(Core *core, double tc, double t, double *buf) {
    CoreData *d = &core->d;
    int i;
    if (core->requestInputs) {
        if (t != core->tRequested) {
            core->tRequested = t;
            if (core->requestInputs(core, t)) return NULL;
        }
        return U(d);
    }
    if (!d->hasDu) return U(d);
    for (i = 0; i < NU; i++) buf[i] = U(d)[i] + d->du[i] * (t - tc);
    return buf;
}

/* ----------------------------------------- Co-Simulation: modes and indicators
 *
 * With relations (NREL > 0), Co-Simulation integrates like Model Exchange: each relation
 * is frozen at its value c[k] (d->c) over an internal step, so that every RK4 stage
 * evaluates the same smooth branch, and the indicators are z_k = hi - lo of the
 * relations (model_rel, no hysteresis): a crossing is a relation whose value at the end
 * of a step differs from c[k]. Where the bisection then tries a shorter step, that step
 * follows the smooth continuation of the branch, so the crossing is located where that
 * branch meets it, not where a stage happened to see the next branch. Without
 * relations, the live indicators model_zc (relations inside noEvent) are used with the
 * live equations. */

#if NREL > 0
/* Right-hand side of the Co-Simulation integrator at a stage: the frozen equations. */
static int csRhs(Core *core, double t, const double *x, const double *u, double *dx) {
    double w[NW + 1];
    return model_eval_me(t, x, u, P(&core->d), core->d.c, dx, w);
}

/* Indicators of the Co-Simulation integrator at (t, x, u), with the modes d->c. */
static int csIndicators(Core *core, double t, const double *x, const double *u, double *z) {
    double s[NREL + 1];
    return model_rel(t, x, u, P(&core->d), core->d.c, z, s);
}

/* Sign class of indicator k: the value of its relation. */
static int csClass(int k, double z) { return model_rel_strict[k] ? z > 0.0 : z >= 0.0; }
#else
/* Without relations: the live equations and, if any, the live indicators. */
static int csRhs(Core *core, double t, const double *x, const double *u, double *dx) {
    return model_ode(t, x, u, P(&core->d), dx);
}

#if NZ_CS > 0
static int csIndicators(Core *core, double t, const double *x, const double *u, double *z) {
    return model_zc(t, x, u, P(&core->d), z);
}

static int csClass(int k, double z) {
    (void)k;
    return z >= 0.0;
}
#endif
#endif

#if NZ_CS > 0
/* Index of the first indicator whose sign class differs, or -1. */
static int crossed(const double *z0, const double *z1) {
    int i;
    for (i = 0; i < NZ_CS; i++) {
        if (csClass(i, z0[i]) != csClass(i, z1[i])) return i;
    }
    return -1;
}

/* Time over which the slopes of the indicators are taken as finite differences along
 * the flow (the inputs are taken as constant over it). */
static double slopeDelta(const Core *core) {
    return SLOPE_REL_STEP * core->d.r[VR_FIXED_STEP];
}
#endif

/* One classical Runge-Kutta step of size h from time t. With slope0 != NULL, also the
 * slope of the indicators at the start (forward difference along the first stage, with
 * the inputs of time t; d->z must hold the indicators there); with k4 != NULL, the last
 * stage (the direction of the flow at the end). */
static int rk4Step(Core *core, double tc, double t, double h, double *slope0, double *k4) {
    CoreData *d = &core->d;
    double k1[NX + 1], k2[NX + 1], k3[NX + 1], k4b[NX + 1], xt[NX + 1], ub[NU + 1];
    double *x = X(d);
    const double *u;
    int i;
    if (!k4) k4 = k4b;
    if (!(u = inputsAt(core, tc, t, ub)) || csRhs(core, t, x, u, k1)) return 1;
#if NZ_CS > 0
    if (slope0) {
        double zs[NZ_CS + 1], delta = slopeDelta(core);
        for (i = 0; i < NX; i++) xt[i] = x[i] + delta * k1[i];
        if (csIndicators(core, t + delta, xt, u, zs)) return 1;
        for (i = 0; i < NZ_CS; i++) slope0[i] = (zs[i] - d->z[i]) / delta;
    }
#else
    (void)slope0;
#endif
    for (i = 0; i < NX; i++) xt[i] = x[i] + 0.5 * h * k1[i];
    if (!(u = inputsAt(core, tc, t + 0.5 * h, ub)) || csRhs(core, t + 0.5 * h, xt, u, k2)) {
        return 1;
    }
    for (i = 0; i < NX; i++) xt[i] = x[i] + 0.5 * h * k2[i];
    if (csRhs(core, t + 0.5 * h, xt, u, k3)) return 1;
    for (i = 0; i < NX; i++) xt[i] = x[i] + h * k3[i];
    if (!(u = inputsAt(core, tc, t + h, ub)) || csRhs(core, t + h, xt, u, k4)) return 1;
    for (i = 0; i < NX; i++) x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    return 0;
}

#if NZ_CS > 0
/* Slope of the indicators z at the state after a step that ended at time t: backward
 * difference along k4, the last stage of that step. */
static int endSlope(Core *core, double tc, double t, const double *z, const double *k4,
                    double *slope) {
    double ub[NU + 1], xb[NX + 1], zb[NZ_CS + 1], delta = slopeDelta(core);
    const double *x = X(&core->d), *u = inputsAt(core, tc, t, ub);
    int i;
    if (!u) return 1;
    for (i = 0; i < NX; i++) xb[i] = x[i] - delta * k4[i];
    if (csIndicators(core, t - delta, xb, u, zb)) return 1;
    for (i = 0; i < NZ_CS; i++) slope[i] = (z[i] - zb[i]) / delta;
    return 0;
}

/* Indicators z at the state after a step that ended at time t; with slope != NULL
 * also their slope there (endSlope). */
static int zcAt(Core *core, double tc, double t, double *z, const double *k4,
                double *slope) {
    double ub[NU + 1];
    const double *u = inputsAt(core, tc, t, ub);
    if (!u || csIndicators(core, t, X(&core->d), u, z)) return 1;
    return slope ? endSlope(core, tc, t, z, k4, slope) : 0;
}

/* Modes (relations as written at the current state, time t) and the indicators d->z
 * that go with them. Relations that depend on relations are iterated. Returns 0, 1 if
 * an evaluation failed, STEP_UNSETTLED if the relations do not settle. */
static int csModes(Core *core, double tc, double t) {
#if NREL > 0
    CoreData *d = &core->d;
    int it, k, changed = 1;
    for (it = 0; changed && it <= NREL + 1; it++) {
        if (zcAt(core, tc, t, d->z, NULL, NULL)) return 1;
        changed = 0;
        for (k = 0; k < NREL; k++) {
            double v = csClass(k, d->z[k]) ? 1.0 : 0.0;
            if (v != d->c[k]) {
                d->c[k] = v;
                changed = 1;
            }
        }
    }
    return changed ? STEP_UNSETTLED : 0;
#else
    return zcAt(core, tc, t, core->d.z, NULL, NULL);
#endif
}

/* Shortest time in which an indicator, now z with slope s, reaches zero at that rate,
 * among those still in their sign class of the start of the step (z0) and moving
 * towards zero. -1: none. */
static double timeToZero(const double *z0, const double *z, const double *s) {
    double best = -1.0;
    int i;
    for (i = 0; i < NZ_CS; i++) {
        int side = csClass(i, z0[i]);
        double toward = side ? -s[i] : s[i], tz;
        if (csClass(i, z[i]) != side || !(toward > 0.0)) continue;
        tz = fabs(z[i]) / toward;
        if (best < 0.0 || tz < best) best = tz;
    }
    return best;
}

/* Earliest time in (after, h) at which an indicator that has the same sign class at
 * both ends of a step of size h may have crossed zero and come back: where the
 * tangents at both ends intersect, if they meet on the other side of zero. That point
 * bounds a concave (convex) indicator from above (below). -1: none. */
static double doubleCrossing(const double *z0, const double *s0, const double *z1,
                             const double *s1, double h, double after) {
    double best = -1.0;
    int i;
    for (i = 0; i < NZ_CS; i++) {
        int side = csClass(i, z0[i]);
        double toward = side ? -s0[i] : s0[i], away = side ? s1[i] : -s1[i], tx;
        if (csClass(i, z1[i]) != side || !(toward > 0.0 && away > 0.0)) continue;
        tx = (z1[i] - z0[i] - s1[i] * h) / (s0[i] - s1[i]);
        if (!(tx > after && tx < h) || csClass(i, z0[i] + s0[i] * tx) == side) continue;
        if (best < 0.0 || tx < best) best = tx;
    }
    return best;
}

/* Takes a step of size tx from (t, x0): sets *changed if the sign classes differ from
 * d->z at its end, and there the indicators z and, with slope != NULL, their slope. */
static int probeAt(Core *core, double tc, double t, double tx, const double *x0, double *z,
                   double *slope, int *changed) {
    double k4[NX + 1];
    memcpy(X(&core->d), x0, sizeof(double) * (NX + 1));
    if (rk4Step(core, tc, t, tx, NULL, k4)) return 1;
    if (zcAt(core, tc, t + tx, z, k4, slope)) return 1;
    *changed = crossed(core->d.z, z) >= 0;
    return 0;
}

/* Shortest step from (t, x0) after which a bracket [0, hi] is known to hold a change of
 * the sign classes from d->z, within a step of size h whose end has the indicators z1
 * and the slopes s1 (s0: at its start; both NULL: only the end is checked).
 *
 * 1. Newton: while an indicator, at its slope, would reach zero inside the step, step
 *    to just past that point and look again from there. Until the first change the
 *    step follows the smooth branch of the modes of its start, so this finds the first
 *    crossing of an indicator that moves towards zero, however the branch would go on
 *    after it (a band crossed and left again inside one step, say).
 * 2. The end of the step: its sign classes, and where the tangents at both ends say an
 *    indicator may have crossed zero and come back (doubleCrossing), checked by a step
 *    to that point.
 * hi = -1: no change found; the state is then the one after the step of size h. */
static int firstChange(Core *core, double tc, double t, double h, const double *x0,
                       const double *z1, const double *s0, const double *s1, double *hi) {
    CoreData *d = &core->d;
    double x1[NX + 1], zx[NZ_CS + 1], sx[NZ_CS + 1], zp[NZ_CS + 1], sp[NZ_CS + 1];
    double tp = 0.0, tx;
    int it, changed = 0;
    *hi = crossed(d->z, z1) >= 0 ? h : -1.0;
    if (!s0) return 0;
    memcpy(x1, X(d), sizeof(double) * (NX + 1));
    memcpy(zp, d->z, sizeof(double) * NZ_CS);
    memcpy(sp, s0, sizeof(double) * NZ_CS);
    for (it = 0; it < NEWTON_PROBES; it++) {
        double tz = timeToZero(d->z, zp, sp);
        if (tz < 0.0) break;
        tx = tp + tz * (1.0 + NEWTON_OVERSHOOT) + EVENT_TIME_TOL;
        if (tx >= (*hi > 0.0 ? *hi : h)) break;
        if (probeAt(core, tc, t, tx, x0, zx, sx, &changed)) return 1;
        if (changed) {
            *hi = tx;
            return 0;
        }
        tp = tx;
        memcpy(zp, zx, sizeof(double) * NZ_CS);
        memcpy(sp, sx, sizeof(double) * NZ_CS);
    }
    tx = doubleCrossing(d->z, s0, z1, s1, h, tp);
    while (tx > 0.0 && (*hi < 0.0 || tx < *hi)) {
        if (probeAt(core, tc, t, tx, x0, zx, NULL, &changed)) return 1;
        if (changed) {
            *hi = tx;
            return 0;
        }
        tx = doubleCrossing(d->z, s0, z1, s1, h, tx);
    }
    memcpy(X(d), x1, sizeof(double) * (NX + 1));
    return 0;
}
#endif

/* One internal step of size h from t with event location. d->z must hold the
 * indicators at (t, x) (csModes); on return it holds them at the new state. Returns 0,
 * 1 if an evaluation failed, STEP_UNSETTLED if the relations do not settle.
 *
 * The first change of the sign classes inside the (rest of the) step (firstChange) is
 * located by bisection, the step is taken up to just before it and then over it, the
 * modes are updated there, and the rest of the step is checked again in the same way. */
static int stepWithEvents(Core *core, double tc, double t, double h) {
#if NZ_CS > 0
    CoreData *d = &core->d;
    double x0[NX + 1], z1[NZ_CS + 1], s0[NZ_CS + 1], s1[NZ_CS + 1], k4[NX + 1];
    double tau = 0.0; /* part of the step already taken */
    int events = 0, rc;
    while (h - tau > 0.0) {
        double rest = h - tau, lo = 0.0, hi = -1.0;
        int probe = rest > MIN_PROBED_STEP;
        memcpy(x0, X(d), sizeof(double) * (NX + 1));
        if (rk4Step(core, tc, t + tau, rest, probe ? s0 : NULL, k4)) return 1;
        if (zcAt(core, tc, t + h, z1, NULL, NULL)) return 1;
        if (events >= MAX_EVENTS_PER_STEP) {
            /* the rest of the step is taken as is; modes from where it ends */
            return csModes(core, tc, t + h);
        }
        /* the probes of firstChange can only find a change if an indicator, at its
         * slope, reaches zero within the step; the slope at the end costs an evaluation
         * of the indicators, so it is taken only then (the margin of 2 keeps the
         * rounding of the probes' own tests out of this one) */
        if (probe) {
            double tz = timeToZero(d->z, d->z, s0);
            probe = !(tz == -1.0 || tz >= 2.0 * rest);
        }
        if (probe && endSlope(core, tc, t + h, z1, k4, s1)) return 1;
        if (firstChange(core, tc, t + tau, rest, x0, z1, probe ? s0 : NULL, s1, &hi)) {
            return 1;
        }
        if (hi < 0.0) {
            memcpy(d->z, z1, sizeof(double) * NZ_CS);
            return 0;
        }
        while (hi - lo > EVENT_TIME_TOL) {
            double mid = 0.5 * (lo + hi);
            memcpy(X(d), x0, sizeof(double) * (NX + 1));
            if (rk4Step(core, tc, t + tau, mid, NULL, NULL)) return 1;
            if (zcAt(core, tc, t + tau + mid, z1, NULL, NULL)) return 1;
            if (crossed(d->z, z1) >= 0) hi = mid; else lo = mid;
        }
        /* advance to just before the first change, so that no stage of the step sees
         * the branch after it, then over it by at most EVENT_TIME_TOL, and continue
         * from there with the modes there */
        memcpy(X(d), x0, sizeof(double) * (NX + 1));
        if (lo > 0.0 && rk4Step(core, tc, t + tau, lo, NULL, NULL)) return 1;
        if (rk4Step(core, tc, t + tau + lo, hi - lo, NULL, NULL)) return 1;
        if ((rc = csModes(core, tc, t + tau + hi)) != 0) return rc;
        tau += hi;
        events++;
    }
    return 0;
#else
    return rk4Step(core, tc, t, h, NULL, NULL);
#endif
}

static CoreStatus stepFailed(Core *core, double tc, double tEnd, int bad, const char *caller) {
    CoreData *d = &core->d;
    if (bad == -STEP_UNSETTLED) {
        coreLog(core, CoreError, "logStatusError",
                "%s: the relations do not settle in [%g, %g] (they depend on each other)",
                caller, tc, tEnd);
    } else if (bad < 0) {
        coreLog(core, CoreError, "logStatusError",
                "%s: evaluation of the model equations failed in [%g, %g]", caller, tc, tEnd);
    } else {
        coreLog(core, CoreError, "logStatusError",
                "%s: the state %s became non-finite (%g) between t = %g and t = %g; the "
                "integration diverged (parameters too stiff for fixedStepSize = %g?)",
                caller, model_names[X_OFF + bad], d->r[X_OFF + bad], tc, tEnd,
                d->r[VR_FIXED_STEP]);
    }
    return CoreError;
}

/* Checks the arguments of a communication step. */
static CoreStatus checkStep(Core *core, double tc, double hc, const char *caller) {
    CoreData *d = &core->d;
    if (!(hc > 0.0)) {
        coreLog(core, CoreError, "logStatusError",
                "%s: communicationStepSize = %g must be > 0", caller, hc);
        return CoreError;
    }
    if (fabs(tc - d->time) > 1e-9 * (1.0 + fabs(d->time))) {
        coreLog(core, CoreError, "logStatusError",
                "%s: currentCommunicationPoint = %.17g does not match the FMU time %.17g",
                caller, tc, d->time);
        return CoreError;
    }
    return CoreOK;
}

/* Integrates from tc to tc + hc and evaluates the outputs there. */
static CoreStatus integrate(Core *core, double tc, double hc, const char *caller) {
    CoreData *d = &core->d;
    double h = d->r[VR_FIXED_STEP], tEnd = tc + hc, nReal, hSub;
    long long n, k;
    int bad = -1, i, rc;
    core->tRequested = -HUGE_VAL;
#if NZ_CS > 0
    /* inputs may have changed since the last step: modes and indicators at this point */
    if ((rc = csModes(core, tc, tc)) != 0) return stepFailed(core, tc, tEnd, -rc, caller);
#endif
    nReal = hc / h;
    n = (long long)floor(nReal + 0.5);
    if (n >= 1 && fabs(nReal - (double)n) <= 1e-9 * nReal) {
        /* communication step is a multiple of the internal step: t = t0 + k*h */
        for (k = 0; k < n; k++) {
            double t = d->startTime + (double)d->nSteps * h;
            if ((rc = stepWithEvents(core, tc, t, h)) != 0) {
                return stepFailed(core, tc, tEnd, -rc, caller);
            }
            d->nSteps++;
            if (!allFinite(X(d), NX, &bad)) return stepFailed(core, tc, tEnd, bad, caller);
        }
        d->time = d->startTime + (double)d->nSteps * h;
    } else {
        /* otherwise split the communication step into equal sub-steps <= h */
        n = (long long)ceil(nReal - 1e-9);
        if (n < 1) n = 1;
        hSub = hc / (double)n;
        for (k = 0; k < n; k++) {
            if ((rc = stepWithEvents(core, tc, tc + (double)k * hSub, hSub)) != 0) {
                return stepFailed(core, tc, tEnd, -rc, caller);
            }
            if (!allFinite(X(d), NX, &bad)) return stepFailed(core, tc, tEnd, bad, caller);
        }
        d->time = tEnd;
        d->startTime = tEnd; /* restart the step counter at the new time base */
        d->nSteps = 0;
    }
    if (d->hasDu) {
        /* the inputs are now those at the end of the step; derivatives must be set anew */
        for (i = 0; i < NU; i++) {
            U(d)[i] += d->du[i] * (d->time - tc);
            d->du[i] = 0.0;
        }
        d->hasDu = 0;
    }
    d->dirty = 1;
    return coreEvaluate(core, caller);
}

CoreStatus coreDoStep(Core *core, double tc, double hc, const char *caller) {
    CoreStatus s;
    /* bad arguments: the instance stays usable */
    if (checkStep(core, tc, hc, caller) != CoreOK) return CoreError;
    s = integrate(core, tc, hc, caller);
    if (s != CoreOK) core->state = StateError;
    return s;
}

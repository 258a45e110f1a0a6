/*
 * Generic FMI 2.0 wrapper of tsid-fmu (Model Exchange and Co-Simulation).
 *
 * Hand-written, model independent. The model part is generated per model
 * (model.h, model.c, model_casadi.c) and provides:
 *   - the layout of the real array (model.h: NX, NU, NW, NP, *_OFF, N_REAL),
 *   - start values and names (model_start[], model_names[]),
 *   - model_ode(t, x, u, p, dx) and model_eval(t, x, u, p, dx, w).
 *
 * All variables are reals; a value reference is the index into the instance's
 * real array r[]: states, derivatives, inputs, outputs+locals, parameters,
 * fixedStepSize.
 *
 * Co-Simulation integrates with the classical fourth-order Runge-Kutta method at
 * the fixed internal step fixedStepSize, inputs held constant over a communication
 * step. Time is taken from a step counter (t = t0 + n*h), not accumulated. The
 * event indicators of the model (one per relation in its if-conditions) are
 * checked after every internal step; when one changes sign, the step is cut at the
 * crossing (bisection on the step length) and continued from there, so that e.g.
 * the stick/slip switching of dry friction happens at the right state, not one
 * step late. A step that produces a non-finite state or output returns fmi2Error
 * with a log message.
 *
 * Model Exchange provides states and derivatives. It exposes no event indicators
 * (numberOfEventIndicators = 0): with the stick band of dry friction, an ME
 * solver's root finding chatters at the band edge, so discontinuities are left
 * to the solver's step-size control. There are no discrete states.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "model.h"

typedef enum {
    StateInstantiated = 1 << 0,
    StateInitializationMode = 1 << 1,
    StateEventMode = 1 << 2,
    StateContinuousTimeMode = 1 << 3,
    StateStepComplete = 1 << 4,
    StateTerminated = 1 << 5,
    StateError = 1 << 6
} ModelState;

#define ANY_STATE 0x7f

typedef struct {
    double r[N_REAL];   /* all real variables, index = value reference */
    double time;        /* current time */
    double startTime;   /* time base of the step counter */
    long long nSteps;   /* internal steps since startTime (Co-Simulation) */
    int dirty;          /* derived variables (derivatives, outputs) must be recomputed */
    double z[NZ + 1];   /* event indicators at the current state (Co-Simulation) */
} InstanceData;

/* Event location: bisection until the bracket is this short [s], at most this many
 * located events per internal step (the rest of the step is then taken as is). */
#define EVENT_TIME_TOL 1e-10
#define MAX_EVENTS_PER_STEP 8

typedef struct {
    InstanceData d;
    fmi2Type type;
    ModelState state;
    char *instanceName;
    fmi2CallbackFunctions cb;
    fmi2Boolean loggingOn;
} Instance;

/* --------------------------------------------------------------------- logging */

static void logMessage(Instance *comp, fmi2Status status, const char *category,
                       const char *fmt, ...) {
    char buf[1024];
    va_list args;
    if (!comp || !comp->cb.logger) return;
    if (status == fmi2OK && !comp->loggingOn) return;
    va_start(args, fmt);
    vsnprintf(buf, sizeof(buf), fmt, args);
    va_end(args);
    comp->cb.logger(comp->cb.componentEnvironment, comp->instanceName, status, category,
                    "%s", buf);
}

static fmi2Status fail(Instance *comp, const char *fmt, const char *arg) {
    logMessage(comp, fmi2Error, "logStatusError", fmt, arg);
    return fmi2Error;
}

static int allowed(Instance *comp, const char *f, int mask) {
    if (!comp) return 0;
    if (comp->state & mask) return 1;
    logMessage(comp, fmi2Error, "logStatusError", "%s: illegal call sequence", f);
    return 0;
}

#define CHECK(f, mask)                               \
    do {                                             \
        if (!allowed(comp, f, mask)) return fmi2Error; \
    } while (0)

/* ------------------------------------------------------------------ evaluation */

#define X(d) ((d)->r + X_OFF)
#define DX(d) ((d)->r + DX_OFF)
#define U(d) ((d)->r + U_OFF)
#define W(d) ((d)->r + W_OFF)
#define P(d) ((d)->r + P_OFF)

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

/* Recompute derivatives and algebraic variables from states, inputs, parameters. */
static fmi2Status evaluate(Instance *comp, const char *caller) {
    InstanceData *d = &comp->d;
    int bad = 0;
    if (!d->dirty) return fmi2OK;
    if (model_eval(d->time, X(d), U(d), P(d), DX(d), W(d)) != 0) {
        logMessage(comp, fmi2Error, "logStatusError",
                   "%s: evaluation of the model equations failed at t = %g", caller, d->time);
        return fmi2Error;
    }
    d->dirty = 0;
    if (!allFinite(DX(d), NX, &bad)) {
        logMessage(comp, fmi2Error, "logStatusError",
                   "%s: non-finite value of %s at t = %g", caller, model_names[DX_OFF + bad],
                   d->time);
        return fmi2Error;
    }
    if (!allFinite(W(d), NW, &bad)) {
        logMessage(comp, fmi2Error, "logStatusError",
                   "%s: non-finite value of %s at t = %g", caller, model_names[W_OFF + bad],
                   d->time);
        return fmi2Error;
    }
    return fmi2OK;
}

static void resetData(InstanceData *d) {
    memcpy(d->r, model_start, sizeof(d->r));
    d->time = 0.0;
    d->startTime = 0.0;
    d->nSteps = 0;
    d->dirty = 1;
}

/* One classical Runge-Kutta step of size h from time t (inputs held constant). */
static int rk4Step(InstanceData *d, double t, double h) {
    double k1[NX + 1], k2[NX + 1], k3[NX + 1], k4[NX + 1], xt[NX + 1];
    double *x = X(d);
    const double *u = U(d), *p = P(d);
    int i;
    if (model_ode(t, x, u, p, k1)) return 1;
    for (i = 0; i < NX; i++) xt[i] = x[i] + 0.5 * h * k1[i];
    if (model_ode(t + 0.5 * h, xt, u, p, k2)) return 1;
    for (i = 0; i < NX; i++) xt[i] = x[i] + 0.5 * h * k2[i];
    if (model_ode(t + 0.5 * h, xt, u, p, k3)) return 1;
    for (i = 0; i < NX; i++) xt[i] = x[i] + h * k3[i];
    if (model_ode(t + h, xt, u, p, k4)) return 1;
    for (i = 0; i < NX; i++) x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    return 0;
}

#if NZ > 0
/* Index of the first indicator whose sign class (z >= 0) differs, or -1. */
static int crossed(const double *z0, const double *z1) {
    int i;
    for (i = 0; i < NZ; i++) {
        if ((z0[i] >= 0.0) != (z1[i] >= 0.0)) return i;
    }
    return -1;
}
#endif

/* One internal step of size h from t with event location. d->z must hold the event
 * indicators at (t, x); on return it holds them at the new state. */
static int stepWithEvents(InstanceData *d, double t, double h) {
#if NZ > 0
    double x0[NX + 1], z1[NZ + 1];
    const double *u = U(d), *p = P(d);
    double tau = 0.0; /* part of the step already taken */
    int events = 0;
    while (h - tau > 0.0) {
        double rest = h - tau;
        memcpy(x0, X(d), sizeof(double) * (NX + 1));
        if (rk4Step(d, t + tau, rest)) return 1;
        if (model_zc(t + h, X(d), u, p, z1)) return 1;
        if (events < MAX_EVENTS_PER_STEP && crossed(d->z, z1) >= 0) {
            double lo = 0.0, hi = rest;
            while (hi - lo > EVENT_TIME_TOL) {
                double mid = 0.5 * (lo + hi);
                memcpy(X(d), x0, sizeof(double) * (NX + 1));
                if (rk4Step(d, t + tau, mid)) return 1;
                if (model_zc(t + tau + mid, X(d), u, p, z1)) return 1;
                if (crossed(d->z, z1) >= 0) hi = mid; else lo = mid;
            }
            /* advance to just past the first crossing and continue from there */
            memcpy(X(d), x0, sizeof(double) * (NX + 1));
            if (rk4Step(d, t + tau, hi)) return 1;
            if (model_zc(t + tau + hi, X(d), u, p, z1)) return 1;
            memcpy(d->z, z1, sizeof(double) * NZ);
            tau += hi;
            events++;
            continue;
        }
        memcpy(d->z, z1, sizeof(double) * NZ);
        break;
    }
    return 0;
#else
    return rk4Step(d, t, h);
#endif
}

/* ------------------------------------------------------------- common functions */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    Instance *comp = (Instance *)c;
    (void)nCategories;
    (void)categories;
    if (!comp) return fmi2Error;
    comp->loggingOn = loggingOn;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    Instance *comp;
    size_t n;
    (void)fmuResourceLocation;
    (void)visible;
    if (!functions || !functions->logger) return NULL;
    if (!instanceName || !instanceName[0]) {
        functions->logger(functions->componentEnvironment, "?", fmi2Error, "logStatusError",
                          "fmi2Instantiate: missing instance name");
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, INSTANTIATION_TOKEN) != 0) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                          "logStatusError", "fmi2Instantiate: wrong GUID %s, expected %s",
                          fmuGUID ? fmuGUID : "(null)", INSTANTIATION_TOKEN);
        return NULL;
    }
    comp = (Instance *)calloc(1, sizeof(Instance));
    if (!comp) return NULL;
    n = strlen(instanceName) + 1;
    comp->instanceName = (char *)malloc(n);
    if (!comp->instanceName) {
        free(comp);
        return NULL;
    }
    memcpy(comp->instanceName, instanceName, n);
    comp->cb = *functions;
    comp->type = fmuType;
    comp->loggingOn = loggingOn;
    comp->state = StateInstantiated;
    resetData(&comp->d);
    return comp;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *comp = (Instance *)c;
    if (!comp) return;
    free(comp->instanceName);
    free(comp);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Instance *comp = (Instance *)c;
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    CHECK("fmi2SetupExperiment", StateInstantiated);
    comp->d.time = startTime;
    comp->d.startTime = startTime;
    comp->d.nSteps = 0;
    comp->d.dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2EnterInitializationMode", StateInstantiated);
    comp->state = StateInitializationMode;
    comp->d.dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *comp = (Instance *)c;
    fmi2Status s;
    double h;
    CHECK("fmi2ExitInitializationMode", StateInitializationMode);
    h = comp->d.r[VR_FIXED_STEP];
    if (!(h > 0.0) || !isfinite(h)) {
        logMessage(comp, fmi2Error, "logStatusError",
                   "fmi2ExitInitializationMode: fixedStepSize = %g must be > 0", h);
        comp->state = StateError;
        return fmi2Error;
    }
    comp->d.dirty = 1;
    s = evaluate(comp, "fmi2ExitInitializationMode");
    if (s != fmi2OK) {
        comp->state = StateError;
        return s;
    }
    comp->state = comp->type == fmi2ModelExchange ? StateEventMode : StateStepComplete;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2Terminate", StateEventMode | StateContinuousTimeMode | StateStepComplete);
    comp->state = StateTerminated;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Instance *comp = (Instance *)c;
    if (!comp) return fmi2Error;
    resetData(&comp->d);
    comp->state = StateInstantiated;
    return fmi2OK;
}

/* ----------------------------------------------------------------- get and set */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    Instance *comp = (Instance *)c;
    size_t i;
    fmi2Status s = fmi2OK;
    CHECK("fmi2GetReal", ANY_STATE);
    if (nvr > 0 && (!vr || !value)) return fail(comp, "fmi2GetReal: %s", "NULL argument");
    for (i = 0; i < nvr; i++) {
        if (vr[i] >= N_REAL) return fail(comp, "fmi2GetReal: %s", "unknown value reference");
    }
    if (comp->d.dirty && !(comp->state & (StateInstantiated | StateError))) {
        s = evaluate(comp, "fmi2GetReal");
        if (s != fmi2OK) comp->d.dirty = 0; /* report once; values are returned as they are */
    }
    for (i = 0; i < nvr; i++) value[i] = comp->d.r[vr[i]];
    return s;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    Instance *comp = (Instance *)c;
    size_t i;
    CHECK("fmi2SetReal", StateInstantiated | StateInitializationMode | StateEventMode |
                             StateContinuousTimeMode | StateStepComplete);
    if (nvr > 0 && (!vr || !value)) return fail(comp, "fmi2SetReal: %s", "NULL argument");
    for (i = 0; i < nvr; i++) {
        fmi2ValueReference v = vr[i];
        int isInput = v >= U_OFF && v < U_OFF + NU;
        int isState = v < X_OFF + NX;
        int isParam = v >= P_OFF && v <= VR_FIXED_STEP;
        if (v >= N_REAL) return fail(comp, "fmi2SetReal: %s", "unknown value reference");
        if (isParam && !(comp->state & (StateInstantiated | StateInitializationMode))) {
            return fail(comp, "fmi2SetReal: parameter %s is fixed after initialization",
                        model_names[v]);
        }
        if (isState && !(comp->state & (StateInstantiated | StateInitializationMode))) {
            return fail(comp, "fmi2SetReal: %s can only be set before or during initialization",
                        model_names[v]);
        }
        if (!isInput && !isParam && !isState) {
            return fail(comp, "fmi2SetReal: %s is not an input, state or parameter",
                        model_names[v]);
        }
    }
    for (i = 0; i < nvr; i++) comp->d.r[vr[i]] = value[i];
    comp->d.dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[]) {
    (void)vr;
    (void)value;
    if (nvr == 0) return fmi2OK;
    return fail((Instance *)c, "fmi2GetInteger: %s", "the model has no Integer variables");
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[]) {
    (void)vr;
    (void)value;
    if (nvr == 0) return fmi2OK;
    return fail((Instance *)c, "fmi2GetBoolean: %s", "the model has no Boolean variables");
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[]) {
    (void)vr;
    (void)value;
    if (nvr == 0) return fmi2OK;
    return fail((Instance *)c, "fmi2GetString: %s", "the model has no String variables");
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    (void)vr;
    (void)value;
    if (nvr == 0) return fmi2OK;
    return fail((Instance *)c, "fmi2SetInteger: %s", "the model has no Integer variables");
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
    (void)vr;
    (void)value;
    if (nvr == 0) return fmi2OK;
    return fail((Instance *)c, "fmi2SetBoolean: %s", "the model has no Boolean variables");
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
    (void)vr;
    (void)value;
    if (nvr == 0) return fmi2OK;
    return fail((Instance *)c, "fmi2SetString: %s", "the model has no String variables");
}

/* ------------------------------------------------------------------- FMU state */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    Instance *comp = (Instance *)c;
    InstanceData *copy;
    CHECK("fmi2GetFMUstate", ANY_STATE);
    if (!FMUstate) return fail(comp, "fmi2GetFMUstate: %s", "NULL argument");
    copy = *FMUstate ? (InstanceData *)*FMUstate : (InstanceData *)malloc(sizeof(InstanceData));
    if (!copy) return fail(comp, "fmi2GetFMUstate: %s", "out of memory");
    *copy = comp->d;
    *FMUstate = copy;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2SetFMUstate", ANY_STATE);
    if (!FMUstate) return fail(comp, "fmi2SetFMUstate: %s", "NULL state");
    comp->d = *(InstanceData *)FMUstate;
    comp->d.dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    (void)c;
    if (FMUstate && *FMUstate) {
        free(*FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    (void)FMUstate;
    (void)size;
    return fail((Instance *)c, "fmi2SerializedFMUstateSize: %s", "not supported");
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte bytes[],
                                 size_t size) {
    (void)FMUstate;
    (void)bytes;
    (void)size;
    return fail((Instance *)c, "fmi2SerializeFMUstate: %s", "not supported");
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[],
                                   size_t size, fmi2FMUstate *FMUstate) {
    (void)serializedState;
    (void)size;
    (void)FMUstate;
    return fail((Instance *)c, "fmi2DeSerializeFMUstate: %s", "not supported");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[],
                                        size_t nUnknown, const fmi2ValueReference vKnown[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    (void)vUnknown;
    (void)nUnknown;
    (void)vKnown;
    (void)nKnown;
    (void)dvKnown;
    (void)dvUnknown;
    return fail((Instance *)c, "fmi2GetDirectionalDerivative: %s", "not supported");
}

/* ---------------------------------------------------------------- Model Exchange */

fmi2Status fmi2EnterEventMode(fmi2Component c) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2EnterEventMode", StateEventMode | StateContinuousTimeMode);
    comp->state = StateEventMode;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2NewDiscreteStates", StateEventMode);
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2EnterContinuousTimeMode", StateEventMode);
    comp->state = StateContinuousTimeMode;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation) {
    Instance *comp = (Instance *)c;
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK("fmi2CompletedIntegratorStep", StateContinuousTimeMode);
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2SetTime", StateInstantiated | StateInitializationMode | StateEventMode |
                             StateContinuousTimeMode);
    comp->d.time = time;
    comp->d.dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    Instance *comp = (Instance *)c;
    size_t i;
    CHECK("fmi2SetContinuousStates", StateEventMode | StateContinuousTimeMode);
    if (nx != NX) return fail(comp, "fmi2SetContinuousStates: %s", "wrong number of states");
    for (i = 0; i < nx; i++) {
        if (!isfinite(x[i])) {
            return fail(comp, "fmi2SetContinuousStates: non-finite value of state %s",
                        model_names[X_OFF + i]);
        }
        comp->d.r[X_OFF + i] = x[i];
    }
    comp->d.dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    Instance *comp = (Instance *)c;
    size_t i;
    fmi2Status s;
    CHECK("fmi2GetDerivatives", StateInitializationMode | StateEventMode |
                                    StateContinuousTimeMode | StateTerminated | StateError);
    if (nx != NX) return fail(comp, "fmi2GetDerivatives: %s", "wrong number of states");
    s = evaluate(comp, "fmi2GetDerivatives");
    for (i = 0; i < nx; i++) derivatives[i] = comp->d.r[DX_OFF + i];
    return s;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    Instance *comp = (Instance *)c;
    (void)eventIndicators;
    CHECK("fmi2GetEventIndicators", ANY_STATE);
    if (ni != 0) return fail(comp, "fmi2GetEventIndicators: %s", "the FMU exposes none");
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    Instance *comp = (Instance *)c;
    size_t i;
    CHECK("fmi2GetContinuousStates", ANY_STATE);
    if (nx != NX) return fail(comp, "fmi2GetContinuousStates: %s", "wrong number of states");
    for (i = 0; i < nx; i++) x[i] = comp->d.r[X_OFF + i];
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    Instance *comp = (Instance *)c;
    size_t i;
    CHECK("fmi2GetNominalsOfContinuousStates", ANY_STATE);
    if (nx != NX) {
        return fail(comp, "fmi2GetNominalsOfContinuousStates: %s", "wrong number of states");
    }
    for (i = 0; i < nx; i++) x_nominal[i] = 1.0;
    return fmi2OK;
}

/* ------------------------------------------------------------------ Co-Simulation */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return fail((Instance *)c, "fmi2SetRealInputDerivatives: %s", "not supported");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return fail((Instance *)c, "fmi2GetRealOutputDerivatives: %s", "not supported");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentCommunicationPoint) {
    Instance *comp = (Instance *)c;
    InstanceData *d;
    double h, tEnd, nReal, hSub;
    long long n, k;
    int bad = 0;
    fmi2Status s;
    (void)noSetFMUStatePriorToCurrentCommunicationPoint;
    CHECK("fmi2DoStep", StateStepComplete);
    d = &comp->d;
    h = d->r[VR_FIXED_STEP];
    if (communicationStepSize <= 0.0) {
        logMessage(comp, fmi2Error, "logStatusError",
                   "fmi2DoStep: communicationStepSize = %g must be > 0", communicationStepSize);
        return fmi2Error;
    }
    if (fabs(currentCommunicationPoint - d->time) > 1e-9 * (1.0 + fabs(d->time))) {
        logMessage(comp, fmi2Error, "logStatusError",
                   "fmi2DoStep: currentCommunicationPoint = %.17g does not match the FMU time "
                   "%.17g",
                   currentCommunicationPoint, d->time);
        return fmi2Error;
    }
    tEnd = currentCommunicationPoint + communicationStepSize;
    /* inputs may have changed since the last step: indicators at the current point */
    if (NZ > 0 && model_zc(d->time, X(d), U(d), P(d), d->z)) goto evalfail;
    nReal = communicationStepSize / h;
    n = (long long)floor(nReal + 0.5);
    if (n >= 1 && fabs(nReal - (double)n) <= 1e-9 * nReal) {
        /* communication step is a multiple of the internal step: t = t0 + k*h */
        for (k = 0; k < n; k++) {
            double t = d->startTime + (double)d->nSteps * h;
            if (stepWithEvents(d, t, h)) goto evalfail;
            d->nSteps++;
            if (!allFinite(X(d), NX, &bad)) goto nonfinite;
        }
        d->time = d->startTime + (double)d->nSteps * h;
    } else {
        /* otherwise split the communication step into equal sub-steps <= h */
        n = (long long)ceil(nReal - 1e-9);
        if (n < 1) n = 1;
        hSub = communicationStepSize / (double)n;
        for (k = 0; k < n; k++) {
            if (stepWithEvents(d, currentCommunicationPoint + (double)k * hSub, hSub)) {
                goto evalfail;
            }
            if (!allFinite(X(d), NX, &bad)) goto nonfinite;
        }
        d->time = tEnd;
        d->startTime = tEnd; /* restart the step counter at the new time base */
        d->nSteps = 0;
    }
    d->dirty = 1;
    s = evaluate(comp, "fmi2DoStep");
    if (s != fmi2OK) comp->state = StateError;
    return s;

nonfinite:
    logMessage(comp, fmi2Error, "logStatusError",
               "fmi2DoStep: the state %s became non-finite (%g) between t = %g and t = %g; "
               "the integration diverged (parameters too stiff for fixedStepSize = %g?)",
               model_names[X_OFF + bad], d->r[X_OFF + bad], currentCommunicationPoint, tEnd, h);
    comp->state = StateError;
    return fmi2Error;
evalfail:
    logMessage(comp, fmi2Error, "logStatusError",
               "fmi2DoStep: evaluation of the model equations failed in [%g, %g]",
               currentCommunicationPoint, tEnd);
    comp->state = StateError;
    return fmi2Error;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    return fail((Instance *)c, "fmi2CancelStep: %s", "not supported (doStep is synchronous)");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s;
    (void)value;
    return fail((Instance *)c, "fmi2GetStatus: %s", "not supported");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    Instance *comp = (Instance *)c;
    if (s == fmi2LastSuccessfulTime && comp && value) {
        *value = comp->d.time;
        return fmi2OK;
    }
    return fail(comp, "fmi2GetRealStatus: %s", "not supported");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s;
    (void)value;
    return fail((Instance *)c, "fmi2GetIntegerStatus: %s", "not supported");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    (void)s;
    (void)value;
    return fail((Instance *)c, "fmi2GetBooleanStatus: %s", "not supported");
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)s;
    (void)value;
    return fail((Instance *)c, "fmi2GetStringStatus: %s", "not supported");
}

/*
 * Generic FMI 2.0 wrapper of tsid-fmu (Model Exchange and Co-Simulation).
 *
 * Hand-written, model independent: the FMI 2.0 API on top of the shared core
 * (tsid_core.c, also used by the FMI 3.0 wrapper), which holds the instance data,
 * evaluates the generated equations (model.c, model_casadi.c) and integrates.
 *
 * All variables are reals; a value reference is the index into the instance's real
 * array r[]: states, derivatives, inputs, outputs+locals, parameters, fixedStepSize.
 *
 * Co-Simulation integrates with the classical fourth-order Runge-Kutta method at the
 * fixed internal step fixedStepSize. Time is taken from a step counter (t = t0 + n*h),
 * not accumulated. The sign changes of the relations in the model's if-conditions are
 * located inside a step by bisection, so that e.g. the stick/slip switching of dry
 * friction happens at the right state, not one step late. Inputs are held over a
 * communication step unless fmi2SetRealInputDerivatives gave their first derivatives
 * (canInterpolateInputs): then u(t) = u + du*(t - tc) in every internal stage, and at
 * the end of the step the inputs hold their interpolated values at the new time (the
 * derivatives apply to that one step; set them again for the next). A step that
 * produces a non-finite state or output returns fmi2Error with a log message.
 *
 * Model Exchange: every relation of the model (outside noEvent) is a discrete state
 * that changes only in Event Mode (fmi2NewDiscreteStates, with event iteration); its
 * event indicator, with a small hysteresis, is exposed (numberOfEventIndicators), so
 * the right-hand side is smooth between events and a variable-step solver locates
 * every switch of an if-expression (see tsid_core.h).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "tsid_core.h"

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
#define INIT_PHASE (StateInstantiated | StateInitializationMode)

typedef struct {
    Core core; /* first member: a Core * is an Instance * */
    fmi2Type type;
    ModelState state;
    char *instanceName;
    fmi2CallbackFunctions cb;
} Instance;

/* --------------------------------------------------------------------- logging */

static void logToFmi2(Core *core, CoreStatus status, const char *category, const char *msg) {
    Instance *comp = (Instance *)core;
    if (!comp->cb.logger) return;
    comp->cb.logger(comp->cb.componentEnvironment, comp->instanceName, (fmi2Status)status,
                    category, "%s", msg);
}

static fmi2Status fail(Instance *comp, const char *fmt, const char *arg) {
    if (comp) coreLog(&comp->core, CoreError, "logStatusError", fmt, arg);
    return fmi2Error;
}

static int allowed(Instance *comp, const char *f, int mask) {
    if (!comp) return 0;
    if (comp->state & mask) return 1;
    coreLog(&comp->core, CoreError, "logStatusError", "%s: illegal call sequence", f);
    return 0;
}

#define CHECK(f, mask)                                 \
    do {                                               \
        if (!allowed(comp, f, mask)) return fmi2Error; \
    } while (0)

/* ------------------------------------------------------------- common functions */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    Instance *comp = (Instance *)c;
    (void)nCategories;
    (void)categories;
    if (!comp) return fmi2Error;
    comp->core.loggingOn = loggingOn;
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
    comp->state = StateInstantiated;
    coreInit(&comp->core, fmuType == fmi2ModelExchange);
    comp->core.loggingOn = loggingOn;
    comp->core.log = logToFmi2;
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
    comp->core.d.time = startTime;
    comp->core.d.startTime = startTime;
    comp->core.d.nSteps = 0;
    coreInvalidate(&comp->core, 1);
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2EnterInitializationMode", StateInstantiated);
    comp->state = StateInitializationMode;
    coreInvalidate(&comp->core, 1);
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *comp = (Instance *)c;
    const char *f = "fmi2ExitInitializationMode";
    double h;
    CHECK(f, StateInitializationMode);
    h = comp->core.d.r[VR_FIXED_STEP];
    if (!(h > 0.0) || !isfinite(h)) {
        coreLog(&comp->core, CoreError, "logStatusError", "%s: fixedStepSize = %g must be > 0",
                f, h);
        comp->state = StateError;
        return fmi2Error;
    }
    coreInvalidate(&comp->core, 1);
    if ((comp->core.isModelExchange && coreInitModes(&comp->core, f) != CoreOK) ||
        coreEvaluate(&comp->core, f) != CoreOK) {
        comp->state = StateError;
        return fmi2Error;
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
    coreResetData(&comp->core);
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
    if (comp->core.d.dirty && !(comp->state & (StateInstantiated | StateError))) {
        s = (fmi2Status)coreEvaluate(&comp->core, "fmi2GetReal");
        /* report once; values are returned as they are */
        if (s != fmi2OK) comp->core.d.dirty = 0;
    }
    for (i = 0; i < nvr; i++) value[i] = comp->core.d.r[vr[i]];
    return s;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    Instance *comp = (Instance *)c;
    size_t i;
    int initPhase;
    CHECK("fmi2SetReal", StateInstantiated | StateInitializationMode | StateEventMode |
                             StateContinuousTimeMode | StateStepComplete);
    if (nvr > 0 && (!vr || !value)) return fail(comp, "fmi2SetReal: %s", "NULL argument");
    initPhase = (comp->state & INIT_PHASE) != 0;
    for (i = 0; i < nvr; i++) {
        if (coreCheckSet(&comp->core, vr[i], initPhase, "fmi2SetReal") != CoreOK) {
            return fmi2Error;
        }
    }
    for (i = 0; i < nvr; i++) comp->core.d.r[vr[i]] = value[i];
    coreInvalidate(&comp->core, initPhase);
    return fmi2OK;
}

#define NO_VARIABLES(F, T, CONST, KIND)                                                 \
    fmi2Status F(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,          \
                 CONST T value[]) {                                                    \
        (void)vr;                                                                      \
        (void)value;                                                                   \
        if (nvr == 0) return fmi2OK;                                                   \
        return fail((Instance *)c, #F ": %s", "the model has no " KIND " variables"); \
    }

NO_VARIABLES(fmi2GetInteger, fmi2Integer, , "Integer")
NO_VARIABLES(fmi2GetBoolean, fmi2Boolean, , "Boolean")
NO_VARIABLES(fmi2GetString, fmi2String, , "String")
NO_VARIABLES(fmi2SetInteger, fmi2Integer, const, "Integer")
NO_VARIABLES(fmi2SetBoolean, fmi2Boolean, const, "Boolean")
NO_VARIABLES(fmi2SetString, fmi2String, const, "String")

/* ------------------------------------------------------------------- FMU state */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    Instance *comp = (Instance *)c;
    CoreData *copy;
    CHECK("fmi2GetFMUstate", ANY_STATE);
    if (!FMUstate) return fail(comp, "fmi2GetFMUstate: %s", "NULL argument");
    copy = *FMUstate ? (CoreData *)*FMUstate : (CoreData *)malloc(sizeof(CoreData));
    if (!copy) return fail(comp, "fmi2GetFMUstate: %s", "out of memory");
    *copy = comp->core.d;
    *FMUstate = copy;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2SetFMUstate", ANY_STATE);
    if (!FMUstate) return fail(comp, "fmi2SetFMUstate: %s", "NULL state");
    comp->core.d = *(CoreData *)FMUstate;
    comp->core.d.dirty = 1;
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
    comp->core.eventIterations = 0;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    Instance *comp = (Instance *)c;
    int changed = 0;
    CHECK("fmi2NewDiscreteStates", StateEventMode);
    if (!info) return fail(comp, "fmi2NewDiscreteStates: %s", "NULL argument");
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    if (coreUpdateModes(&comp->core, &changed, "fmi2NewDiscreteStates") != CoreOK) {
        comp->state = StateError;
        return fmi2Error;
    }
    info->newDiscreteStatesNeeded = changed ? fmi2True : fmi2False;
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
    int pending = 0;
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK("fmi2CompletedIntegratorStep", StateContinuousTimeMode);
    if (!enterEventMode || !terminateSimulation) {
        return fail(comp, "fmi2CompletedIntegratorStep: %s", "NULL argument");
    }
    /* a relation whose indicator changed sign without the solver stopping there */
    if (coreModeChangePending(&comp->core, &pending, "fmi2CompletedIntegratorStep") != CoreOK) {
        return fmi2Error;
    }
    *enterEventMode = pending ? fmi2True : fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2SetTime", StateInstantiated | StateInitializationMode | StateEventMode |
                             StateContinuousTimeMode);
    comp->core.d.time = time;
    coreInvalidate(&comp->core, (comp->state & INIT_PHASE) != 0);
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    Instance *comp = (Instance *)c;
    size_t i;
    CHECK("fmi2SetContinuousStates", StateEventMode | StateContinuousTimeMode);
    if (nx != NX) return fail(comp, "fmi2SetContinuousStates: %s", "wrong number of states");
    if (nx > 0 && !x) return fail(comp, "fmi2SetContinuousStates: %s", "NULL argument");
    for (i = 0; i < nx; i++) {
        if (!isfinite(x[i])) {
            return fail(comp, "fmi2SetContinuousStates: non-finite value of state %s",
                        model_names[X_OFF + i]);
        }
        comp->core.d.r[X_OFF + i] = x[i];
    }
    coreInvalidate(&comp->core, 0);
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    Instance *comp = (Instance *)c;
    size_t i;
    fmi2Status s;
    CHECK("fmi2GetDerivatives", StateInitializationMode | StateEventMode |
                                    StateContinuousTimeMode | StateTerminated | StateError);
    if (nx != NX) return fail(comp, "fmi2GetDerivatives: %s", "wrong number of states");
    if (nx > 0 && !derivatives) return fail(comp, "fmi2GetDerivatives: %s", "NULL argument");
    s = (fmi2Status)coreEvaluate(&comp->core, "fmi2GetDerivatives");
    for (i = 0; i < nx; i++) derivatives[i] = comp->core.d.r[DX_OFF + i];
    return s;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    Instance *comp = (Instance *)c;
    double e[NREL + 1];
    size_t i;
    CHECK("fmi2GetEventIndicators", StateInitializationMode | StateEventMode |
                                        StateContinuousTimeMode | StateTerminated | StateError);
    if (ni != NREL) {
        return fail(comp, "fmi2GetEventIndicators: %s", "wrong number of event indicators");
    }
    if (ni == 0) return fmi2OK;
    if (!eventIndicators) return fail(comp, "fmi2GetEventIndicators: %s", "NULL argument");
    if (coreEventIndicators(&comp->core, e, "fmi2GetEventIndicators") != CoreOK) {
        return fmi2Error;
    }
    for (i = 0; i < ni; i++) eventIndicators[i] = e[i];
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    Instance *comp = (Instance *)c;
    size_t i;
    CHECK("fmi2GetContinuousStates", ANY_STATE);
    if (nx != NX) return fail(comp, "fmi2GetContinuousStates: %s", "wrong number of states");
    if (nx > 0 && !x) return fail(comp, "fmi2GetContinuousStates: %s", "NULL argument");
    for (i = 0; i < nx; i++) x[i] = comp->core.d.r[X_OFF + i];
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    Instance *comp = (Instance *)c;
    size_t i;
    CHECK("fmi2GetNominalsOfContinuousStates", ANY_STATE);
    if (nx != NX) {
        return fail(comp, "fmi2GetNominalsOfContinuousStates: %s", "wrong number of states");
    }
    if (nx > 0 && !x_nominal) {
        return fail(comp, "fmi2GetNominalsOfContinuousStates: %s", "NULL argument");
    }
    for (i = 0; i < nx; i++) x_nominal[i] = 1.0;
    return fmi2OK;
}

/* ------------------------------------------------------------------ Co-Simulation */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    Instance *comp = (Instance *)c;
    const char *f = "fmi2SetRealInputDerivatives";
    CoreStatus s = CoreOK;
    size_t i;
    CHECK(f, StateInstantiated | StateInitializationMode | StateStepComplete);
    if (comp->type != fmi2CoSimulation) return fail(comp, "%s: only in Co-Simulation", f);
    if (nvr > 0 && (!vr || !order || !value)) return fail(comp, "%s: NULL argument", f);
    for (i = 0; i < nvr; i++) {
        CoreStatus si = coreSetInputDerivative(&comp->core, vr[i], order[i], value[i], f);
        if (si == CoreError) return fmi2Error;
        if (si > s) s = si;
    }
    return (fmi2Status)s;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return fail((Instance *)c, "fmi2GetRealOutputDerivatives: %s",
                "not supported (maxOutputDerivativeOrder = 0)");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentCommunicationPoint) {
    Instance *comp = (Instance *)c;
    CoreStatus s;
    (void)noSetFMUStatePriorToCurrentCommunicationPoint;
    CHECK("fmi2DoStep", StateStepComplete);
    if (coreCheckStep(&comp->core, currentCommunicationPoint, communicationStepSize,
                      "fmi2DoStep") != CoreOK) {
        return fmi2Error; /* bad arguments: the instance stays usable */
    }
    s = coreDoStep(&comp->core, currentCommunicationPoint, communicationStepSize, "fmi2DoStep");
    if (s != CoreOK) comp->state = StateError;
    return (fmi2Status)s;
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
        *value = comp->core.d.time;
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

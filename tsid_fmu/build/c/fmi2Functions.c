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

#include <string.h>

#include "fmi2Functions.h"
#include "tsid_core.h"

typedef struct {
    Core core; /* first member: a Core * is an Instance * */
    fmi2Type type;
    fmi2CallbackFunctions cb;
} Instance;

/* --------------------------------------------------------------------- logging */

static void logToFmi2(Core *core, CoreStatus status, const char *category, const char *msg) {
    Instance *comp = (Instance *)core;
    if (!comp->cb.logger) return;
    comp->cb.logger(comp->cb.componentEnvironment, core->instanceName, (fmi2Status)status,
                    category, "%s", msg);
}

static fmi2Status fail(fmi2Component c, const char *f, const char *message) {
    return (fmi2Status)coreFail((Core *)c, f, message);
}

#define CHECK(f, mask) CORE_CHECK(c, mask, f, fmi2Error)

/* ------------------------------------------------------------- common functions */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    (void)nCategories;
    (void)categories;
    return (fmi2Status)coreSetDebugLogging((Core *)c, loggingOn);
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    Instance *comp;
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
    comp = (Instance *)coreNew(sizeof(Instance), instanceName, fmuType == fmi2ModelExchange,
                               loggingOn, logToFmi2);
    if (!comp) return NULL;
    comp->cb = *functions;
    comp->type = fmuType;
    return comp;
}

void fmi2FreeInstance(fmi2Component c) { coreFree((Core *)c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    return (fmi2Status)coreSetupExperiment((Core *)c, toleranceDefined, tolerance, startTime,
                                           stopTimeDefined, stopTime, "fmi2SetupExperiment");
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    return (fmi2Status)coreEnterInitializationMode((Core *)c, "fmi2EnterInitializationMode");
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    return (fmi2Status)coreExitInitializationMode((Core *)c, "fmi2ExitInitializationMode");
}

fmi2Status fmi2Terminate(fmi2Component c) {
    return (fmi2Status)coreTerminate((Core *)c, "fmi2Terminate");
}

fmi2Status fmi2Reset(fmi2Component c) { return (fmi2Status)coreReset((Core *)c); }

/* ----------------------------------------------------------------- get and set */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    Core *core = (Core *)c;
    size_t i;
    fmi2Status s;
    CHECK("fmi2GetReal", ANY_STATE);
    if (nvr > 0 && (!vr || !value)) return fail(c, "fmi2GetReal", "NULL argument");
    for (i = 0; i < nvr; i++) {
        if (vr[i] >= N_REAL || model_is_integer[vr[i]])
            return fail(c, "fmi2GetReal", "unknown value reference");
    }
    s = (fmi2Status)coreRefresh(core, "fmi2GetReal");
    for (i = 0; i < nvr; i++) value[i] = core->d.r[vr[i]];
    return s;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    size_t i;
    CHECK("fmi2SetReal", INIT_PHASE | StateEventMode | StateContinuousTimeMode | StateStepMode);
    if (nvr > 0 && (!vr || !value)) return fail(c, "fmi2SetReal", "NULL argument");
    for (i = 0; i < nvr; i++) {
        if (vr[i] < N_REAL && model_is_integer[vr[i]])
            return fail(c, "fmi2SetReal", "unknown value reference");
    }
    return (fmi2Status)coreSetReals((Core *)c, vr, nvr, value, "fmi2SetReal");
}

/* Integer parameters live in the real array (as doubles) under their own references. */
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[]) {
    Core *core = (Core *)c;
    size_t i;
    CHECK("fmi2GetInteger", ANY_STATE);
    if (nvr > 0 && (!vr || !value)) return fail(c, "fmi2GetInteger", "NULL argument");
    for (i = 0; i < nvr; i++) {
        if (vr[i] >= N_REAL || !model_is_integer[vr[i]])
            return fail(c, "fmi2GetInteger", "unknown value reference");
    }
    for (i = 0; i < nvr; i++) value[i] = (fmi2Integer)core->d.r[vr[i]];
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    size_t i;
    double v;
    CHECK("fmi2SetInteger", INIT_PHASE | StateEventMode | StateContinuousTimeMode | StateStepMode);
    if (nvr > 0 && (!vr || !value)) return fail(c, "fmi2SetInteger", "NULL argument");
    for (i = 0; i < nvr; i++) {
        if (vr[i] >= N_REAL || !model_is_integer[vr[i]])
            return fail(c, "fmi2SetInteger", "unknown value reference");
    }
    for (i = 0; i < nvr; i++) {
        v = (double)value[i];
        if (coreSetReals((Core *)c, &vr[i], 1, &v, "fmi2SetInteger") != CoreOK) return fmi2Error;
    }
    return fmi2OK;
}

/* The get and set functions of a type the model has no variables of: nothing to do for
 * no value references, an error otherwise. */
static fmi2Status noVariables(fmi2Component c, size_t nvr, const char *f, const char *message) {
    if (nvr == 0) return fmi2OK;
    return fail(c, f, message);
}

#define NO_VARIABLES(T)                                                                 \
    fmi2Status fmi2Get##T(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,    \
                          fmi2##T value[]) {                                           \
        (void)vr;                                                                      \
        (void)value;                                                                   \
        return noVariables(c, nvr, "fmi2Get" #T, "the model has no " #T " variables"); \
    }                                                                                  \
    fmi2Status fmi2Set##T(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,    \
                          const fmi2##T value[]) {                                     \
        (void)vr;                                                                      \
        (void)value;                                                                   \
        return noVariables(c, nvr, "fmi2Set" #T, "the model has no " #T " variables"); \
    }

NO_VARIABLES(Boolean)
NO_VARIABLES(String)

/* ------------------------------------------------------------------- FMU state */

/* fmi2GetFMUstate, fmi2SetFMUstate, fmi2FreeFMUstate: a copy of the instance data in
 * memory; fmi2SerializedFMUstateSize, fmi2SerializeFMUstate, fmi2DeSerializeFMUstate: not
 * supported. Defined as in FMI 3.0 by CORE_FMU_STATE_FUNCTIONS (tsid_core.h). */
CORE_FMU_STATE_FUNCTIONS(fmi2Status, fmi2Component, fmi2FMUstate, fmi2Byte, fmi2GetFMUstate,
                         fmi2SetFMUstate, fmi2FreeFMUstate, fmi2SerializedFMUstateSize,
                         fmi2SerializeFMUstate, fmi2DeSerializeFMUstate)

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
    return fail(c, "fmi2GetDirectionalDerivative", "not supported");
}

/* ---------------------------------------------------------------- Model Exchange */

fmi2Status fmi2EnterEventMode(fmi2Component c) {
    CHECK("fmi2EnterEventMode", StateEventMode | StateContinuousTimeMode);
    coreEnterEventMode((Core *)c);
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    int changed = 0;
    CHECK("fmi2NewDiscreteStates", StateEventMode);
    if (!info) return fail(c, "fmi2NewDiscreteStates", "NULL argument");
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    if (coreUpdateModes((Core *)c, &changed, "fmi2NewDiscreteStates") != CoreOK) {
        return fmi2Error;
    }
    info->newDiscreteStatesNeeded = changed ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    CHECK("fmi2EnterContinuousTimeMode", StateEventMode);
    ((Core *)c)->state = StateContinuousTimeMode;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation) {
    int pending = 0;
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK("fmi2CompletedIntegratorStep", StateContinuousTimeMode);
    if (!enterEventMode || !terminateSimulation) {
        return fail(c, "fmi2CompletedIntegratorStep", "NULL argument");
    }
    /* a relation whose indicator changed sign without the solver stopping there */
    if (coreModeChangePending((Core *)c, &pending, "fmi2CompletedIntegratorStep") != CoreOK) {
        return fmi2Error;
    }
    *enterEventMode = pending ? fmi2True : fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    CHECK("fmi2SetTime", INIT_PHASE | StateEventMode | StateContinuousTimeMode);
    coreSetTime((Core *)c, time);
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    CHECK("fmi2SetContinuousStates", StateEventMode | StateContinuousTimeMode);
    return (fmi2Status)coreSetContinuousStates((Core *)c, x, nx, "fmi2SetContinuousStates");
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    CHECK("fmi2GetDerivatives", StateInitializationMode | StateEventMode |
                                    StateContinuousTimeMode | StateTerminated | StateError);
    return (fmi2Status)coreGetDerivatives((Core *)c, derivatives, nx, "fmi2GetDerivatives");
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    CHECK("fmi2GetEventIndicators", StateInitializationMode | StateEventMode |
                                        StateContinuousTimeMode | StateTerminated | StateError);
    return (fmi2Status)coreGetEventIndicators((Core *)c, eventIndicators, ni,
                                              "fmi2GetEventIndicators");
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    return (fmi2Status)coreGetContinuousStates((Core *)c, x, nx, "fmi2GetContinuousStates");
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    return (fmi2Status)coreGetNominals((Core *)c, x_nominal, nx,
                                       "fmi2GetNominalsOfContinuousStates");
}

/* ------------------------------------------------------------------ Co-Simulation */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    Instance *comp = (Instance *)c;
    const char *f = "fmi2SetRealInputDerivatives";
    CoreStatus s = CoreOK;
    size_t i;
    CHECK(f, INIT_PHASE | StateStepMode);
    if (comp->type != fmi2CoSimulation) return fail(c, f, "only in Co-Simulation");
    if (nvr > 0 && (!vr || !order || !value)) return fail(c, f, "NULL argument");
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
    return fail(c, "fmi2GetRealOutputDerivatives", "not supported (maxOutputDerivativeOrder = 0)");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentCommunicationPoint) {
    (void)noSetFMUStatePriorToCurrentCommunicationPoint;
    CHECK("fmi2DoStep", StateStepMode);
    return (fmi2Status)coreDoStep((Core *)c, currentCommunicationPoint, communicationStepSize,
                                  "fmi2DoStep");
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    return fail(c, "fmi2CancelStep", "not supported (doStep is synchronous)");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    if (s == fmi2LastSuccessfulTime && c && value) {
        *value = ((Core *)c)->d.time;
        return fmi2OK;
    }
    return fail(c, "fmi2GetRealStatus", "not supported");
}

/* Status queries other than the last successful time: not supported. */
#define NO_STATUS(F, T)                                                   \
    fmi2Status F(fmi2Component c, const fmi2StatusKind s, T *value) {    \
        (void)s;                                                          \
        (void)value;                                                      \
        return fail(c, #F, "not supported");                              \
    }

NO_STATUS(fmi2GetStatus, fmi2Status)
NO_STATUS(fmi2GetIntegerStatus, fmi2Integer)
NO_STATUS(fmi2GetBooleanStatus, fmi2Boolean)
NO_STATUS(fmi2GetStringStatus, fmi2String)

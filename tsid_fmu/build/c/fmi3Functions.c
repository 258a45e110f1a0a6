/*
 * Generic FMI 3.0 wrapper of tsid-fmu (Model Exchange and Co-Simulation).
 *
 * Hand-written, model independent: the FMI 3.0 API on top of the shared core
 * (tsid_core.c, also used by the FMI 2.0 wrapper), so both versions of an FMU compute
 * the same equations with the same integrator and the same event handling.
 *
 * All variables are Float64. Value references: the index into the instance's real
 * array r[] (states, derivatives, inputs, outputs+locals, parameters, fixedStepSize),
 * then time (VR_TIME) and the event indicators (VR_EVENT_INDICATOR_OFF + k), which
 * FMI 3.0 requires to be variables.
 *
 * Co-Simulation (no Event Mode: hasEventMode = false): classical RK4 at the fixed
 * internal step fixedStepSize with event location, as in FMI 2.0. Input interpolation
 * follows FMI 3.0 (which has no fmi3SetInputDerivatives): if the importer gives an
 * intermediateUpdate callback and lists inputs in requiredIntermediateVariables,
 * fmi3DoStep calls the callback (intermediateVariableSetRequested = true) at every
 * time inside the step at which the integrator evaluates the inputs, and the importer
 * sets their values for that time with fmi3SetFloat64. Otherwise the inputs are held.
 *
 * Model Exchange: every relation of the model is a discrete state that changes only in
 * fmi3UpdateDiscreteStates (event iteration), with one event indicator per relation
 * (with hysteresis, see tsid_core.h); fmi3CompletedIntegratorStep asks for an event if
 * an indicator changed sign without the solver stopping there.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */

#include <string.h>

#include "fmi3Functions.h"
#include "tsid_core.h"

#define RUNNING (StateEventMode | StateContinuousTimeMode | StateStepMode)

typedef struct {
    Core core; /* first member: a Core * is an Instance * */
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback logMessage;
    fmi3IntermediateUpdateCallback intermediateUpdate;
} Instance;

/* --------------------------------------------------------------------- logging */

static void logToFmi3(Core *core, CoreStatus status, const char *category, const char *msg) {
    Instance *comp = (Instance *)core;
    if (!comp->logMessage) return;
    comp->logMessage(comp->env, (fmi3Status)status, category, msg);
}

static fmi3Status fail(fmi3Instance instance, const char *f, const char *message) {
    return (fmi3Status)coreFail((Core *)instance, f, message);
}

#define CHECK(f, mask) CORE_CHECK(instance, mask, f, fmi3Error)

/* ---------------------------------------------------------------- instantiation */

static Instance *newInstance(fmi3String instanceName, fmi3String token, int isModelExchange,
                             fmi3Boolean loggingOn, fmi3InstanceEnvironment env,
                             fmi3LogMessageCallback logMessage) {
    Instance *comp;
    if (!instanceName || !instanceName[0]) {
        if (logMessage) logMessage(env, fmi3Error, "logStatusError", "missing instance name");
        return NULL;
    }
    if (!token || strcmp(token, INSTANTIATION_TOKEN) != 0) {
        if (logMessage) {
            logMessage(env, fmi3Error, "logStatusError",
                       "wrong instantiationToken, expected " INSTANTIATION_TOKEN);
        }
        return NULL;
    }
    comp = (Instance *)coreNew(sizeof(Instance), instanceName, isModelExchange, loggingOn,
                               logToFmi3);
    if (!comp) return NULL;
    comp->env = env;
    comp->logMessage = logMessage;
    return comp;
}

/* The FMI 3.0 intermediate update: the importer sets the inputs for time t. */
static int requestInputs(Core *core, double t) {
    Instance *comp = (Instance *)core;
    fmi3Boolean earlyReturnRequested = fmi3False;
    fmi3Float64 earlyReturnTime = t;
    core->state = StateIntermediateUpdateMode;
    comp->intermediateUpdate(comp->env, t, fmi3True, fmi3False, fmi3False, fmi3False,
                             &earlyReturnRequested, &earlyReturnTime);
    core->state = StateStepMode;
    return 0;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn,
                               size_t nCategories, const fmi3String categories[]) {
    (void)nCategories;
    (void)categories;
    return (fmi3Status)coreSetDebugLogging((Core *)instance, loggingOn);
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName,
                                          fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)resourcePath;
    (void)visible;
    return newInstance(instanceName, instantiationToken, 1, loggingOn, instanceEnvironment,
                       logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    Instance *comp;
    size_t i;
    (void)resourcePath;
    (void)visible;
    (void)earlyReturnAllowed;
    if (eventModeUsed) {
        if (logMessage) {
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "fmi3InstantiateCoSimulation: eventModeUsed = true, but the FMU has no "
                       "Event Mode in Co-Simulation (hasEventMode = false)");
        }
        return NULL;
    }
    for (i = 0; i < nRequiredIntermediateVariables; i++) {
        if (!requiredIntermediateVariables ||
            !coreIsInput((unsigned int)requiredIntermediateVariables[i])) {
            if (logMessage) {
                logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                           "fmi3InstantiateCoSimulation: only inputs can be intermediate "
                           "variables");
            }
            return NULL;
        }
    }
    comp = newInstance(instanceName, instantiationToken, 0, loggingOn, instanceEnvironment,
                       logMessage);
    if (comp && intermediateUpdate && nRequiredIntermediateVariables > 0) {
        comp->intermediateUpdate = intermediateUpdate;
        comp->core.requestInputs = requestInputs;
    }
    return comp;
}

fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName;
    (void)instantiationToken;
    (void)resourcePath;
    (void)visible;
    (void)loggingOn;
    (void)clockUpdate;
    (void)lockPreemption;
    (void)unlockPreemption;
    if (logMessage) {
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "Scheduled Execution is not supported");
    }
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) { coreFree((Core *)instance); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    /* FMI 2.0's fmi2SetupExperiment and fmi2EnterInitializationMode in one */
    const char *f = "fmi3EnterInitializationMode";
    if (coreSetupExperiment((Core *)instance, toleranceDefined, tolerance, startTime,
                            stopTimeDefined, stopTime, f) != CoreOK) {
        return fmi3Error;
    }
    return (fmi3Status)coreEnterInitializationMode((Core *)instance, f);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    return (fmi3Status)coreExitInitializationMode((Core *)instance, "fmi3ExitInitializationMode");
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    CHECK("fmi3EnterEventMode", StateContinuousTimeMode);
    coreEnterEventMode((Core *)instance);
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    return (fmi3Status)coreTerminate((Core *)instance, "fmi3Terminate");
}

fmi3Status fmi3Reset(fmi3Instance instance) { return (fmi3Status)coreReset((Core *)instance); }

/* ----------------------------------------------------------------- get and set */

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues) {
    Core *core = (Core *)instance;
    const char *f = "fmi3GetFloat64";
    double e[NREL + 1] = {0.0};
    size_t i;
    int needE = 0;
    fmi3Status s;
    CHECK(f, ANY_STATE);
    if (nValueReferences == 0) return fmi3OK;
    if (!valueReferences || !values) return fail(instance, f, "NULL argument");
    if (nValues != nValueReferences) return fail(instance, f, "expected one value per reference");
    for (i = 0; i < nValueReferences; i++) {
        fmi3ValueReference vr = valueReferences[i];
        if (vr >= VR_EVENT_INDICATOR_OFF + NREL || (vr < N_REAL && model_is_integer[vr]))
            return fail(instance, f, "unknown value reference");
        if (vr >= VR_EVENT_INDICATOR_OFF) needE = 1;
    }
    s = (fmi3Status)coreRefresh(core, f);
    if (needE && coreEventIndicators(core, e, f) != CoreOK) return fmi3Error;
    for (i = 0; i < nValueReferences; i++) {
        fmi3ValueReference vr = valueReferences[i];
        if (vr < N_REAL) values[i] = core->d.r[vr];
        else if (vr == VR_TIME) values[i] = core->d.time;
        else values[i] = e[vr - VR_EVENT_INDICATOR_OFF];
    }
    return s;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues) {
    const char *f = "fmi3SetFloat64";
    size_t i;
    CHECK(f, INIT_PHASE | RUNNING | StateIntermediateUpdateMode | StateTerminated);
    if (nValueReferences == 0) return fmi3OK;
    if (!valueReferences || !values) return fail(instance, f, "NULL argument");
    if (nValues != nValueReferences) return fail(instance, f, "expected one value per reference");
    for (i = 0; i < nValueReferences; i++) {
        if (valueReferences[i] < N_REAL && model_is_integer[valueReferences[i]])
            return fail(instance, f, "unknown value reference");
    }
    return (fmi3Status)coreSetReals((Core *)instance, valueReferences, nValueReferences, values,
                                    f);
}

/* Int32 parameters live in the real array (as doubles) under their own references. */
fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Int32 values[], size_t nValues) {
    Core *core = (Core *)instance;
    const char *f = "fmi3GetInt32";
    size_t i;
    CHECK(f, ANY_STATE);
    if (nValueReferences == 0) return fmi3OK;
    if (!valueReferences || !values) return fail(instance, f, "NULL argument");
    if (nValues != nValueReferences) return fail(instance, f, "expected one value per reference");
    for (i = 0; i < nValueReferences; i++) {
        if (valueReferences[i] >= N_REAL || !model_is_integer[valueReferences[i]])
            return fail(instance, f, "unknown value reference");
    }
    for (i = 0; i < nValueReferences; i++) values[i] = (fmi3Int32)core->d.r[valueReferences[i]];
    return fmi3OK;
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Int32 values[], size_t nValues) {
    const char *f = "fmi3SetInt32";
    size_t i;
    double v;
    CHECK(f, INIT_PHASE | RUNNING | StateTerminated);
    if (nValueReferences == 0) return fmi3OK;
    if (!valueReferences || !values) return fail(instance, f, "NULL argument");
    if (nValues != nValueReferences) return fail(instance, f, "expected one value per reference");
    for (i = 0; i < nValueReferences; i++) {
        if (valueReferences[i] >= N_REAL || !model_is_integer[valueReferences[i]])
            return fail(instance, f, "unknown value reference");
    }
    for (i = 0; i < nValueReferences; i++) {
        v = (double)values[i];
        if (coreSetReals((Core *)instance, &valueReferences[i], 1, &v, f) != CoreOK)
            return fmi3Error;
    }
    return fmi3OK;
}

/* The functions of variables the model does not have (of other types than Float64, and
 * Clocks): nothing to do for no value references, an error otherwise. */
static fmi3Status noVariables(fmi3Instance instance, size_t nValueReferences, const char *f,
                              const char *message) {
    if (nValueReferences == 0) return fmi3OK;
    return fail(instance, f, message);
}

/* Marks the arrays of such a function as unused. */
static void unused(const void *array, ...) { (void)array; }

#define NO_VARIABLES(T)                                                                     \
    fmi3Status fmi3Get##T(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                          size_t nValueReferences, fmi3##T values[], size_t nValues) {       \
        (void)nValues;                                                                      \
        unused(valueReferences, values);                                                    \
        return noVariables(instance, nValueReferences, "fmi3Get" #T,                        \
                           "the model has no " #T " variables");                            \
    }                                                                                       \
    fmi3Status fmi3Set##T(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                          size_t nValueReferences, const fmi3##T values[], size_t nValues) { \
        (void)nValues;                                                                      \
        unused(valueReferences, values);                                                    \
        return noVariables(instance, nValueReferences, "fmi3Set" #T,                        \
                           "the model has no " #T " variables");                            \
    }

NO_VARIABLES(Float32)
NO_VARIABLES(Int8)
NO_VARIABLES(UInt8)
NO_VARIABLES(Int16)
NO_VARIABLES(UInt16)
NO_VARIABLES(UInt32)
NO_VARIABLES(Int64)
NO_VARIABLES(UInt64)
NO_VARIABLES(Boolean)
NO_VARIABLES(String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, size_t valueSizes[], fmi3Binary values[],
                         size_t nValues) {
    (void)nValues;
    unused(valueReferences, valueSizes, values);
    return noVariables(instance, nValueReferences, "fmi3GetBinary",
                       "the model has no Binary variables");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    (void)nValues;
    unused(valueReferences, valueSizes, values);
    return noVariables(instance, nValueReferences, "fmi3SetBinary",
                       "the model has no Binary variables");
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                               fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference;
    (void)nDependencies;
    return fail(instance, "fmi3GetNumberOfVariableDependencies",
                "not supported (see ModelStructure)");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent;
    (void)elementIndicesOfDependent;
    (void)independents;
    (void)elementIndicesOfIndependents;
    (void)dependencyKinds;
    (void)nDependencies;
    return fail(instance, "fmi3GetVariableDependencies",
                "not supported (see ModelStructure)");
}

/* ------------------------------------------------------------------- FMU state */

/* fmi3GetFMUState, fmi3SetFMUState, fmi3FreeFMUState: a copy of the instance data in
 * memory; fmi3SerializedFMUStateSize, fmi3SerializeFMUState, fmi3DeserializeFMUState: not
 * supported. Defined as in FMI 2.0 by CORE_FMU_STATE_FUNCTIONS (tsid_core.h). */
CORE_FMU_STATE_FUNCTIONS(fmi3Status, fmi3Instance, fmi3FMUState, fmi3Byte, fmi3GetFMUState,
                         fmi3SetFMUState, fmi3FreeFMUState, fmi3SerializedFMUStateSize,
                         fmi3SerializeFMUState, fmi3DeserializeFMUState)

#define NO_DERIVATIVES(F)                                                                   \
    fmi3Status F(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns, \
                 const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[], \
                 size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {              \
        (void)unknowns;                                                                     \
        (void)nUnknowns;                                                                    \
        (void)knowns;                                                                       \
        (void)nKnowns;                                                                      \
        (void)seed;                                                                         \
        (void)nSeed;                                                                        \
        (void)sensitivity;                                                                  \
        (void)nSensitivity;                                                                 \
        return fail(instance, #F, "not supported");                      \
    }

NO_DERIVATIVES(fmi3GetDirectionalDerivative)
NO_DERIVATIVES(fmi3GetAdjointDerivative)

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    return fail(instance, "fmi3EnterConfigurationMode",
                "the model has no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    return fail(instance, "fmi3ExitConfigurationMode",
                "the model has no structural parameters");
}

/* ------------------------------------------------------------------- Clocks */

/* The model has no Clocks. */
static fmi3Status noClocks(fmi3Instance instance, size_t nValueReferences, const char *f) {
    return noVariables(instance, nValueReferences, f, "the model has no Clocks");
}

/* Defines the Clock function F(instance, valueReferences, nValueReferences, ...): the
 * model has no Clocks (noClocks). The parameters after nValueReferences follow the names
 * of its arrays in parentheses; those arrays are not used. */
#define NO_CLOCKS(F, arrays, ...)                                                        \
    fmi3Status F(fmi3Instance instance, const fmi3ValueReference valueReferences[],      \
                 size_t nValueReferences, __VA_ARGS__) {                                 \
        unused(valueReferences);                                                         \
        unused arrays;                                                                   \
        return noClocks(instance, nValueReferences, #F);                                 \
    }

NO_CLOCKS(fmi3GetClock, (values), fmi3Clock values[])
NO_CLOCKS(fmi3SetClock, (values), const fmi3Clock values[])
NO_CLOCKS(fmi3GetIntervalDecimal, (intervals, qualifiers), fmi3Float64 intervals[],
          fmi3IntervalQualifier qualifiers[])
NO_CLOCKS(fmi3GetIntervalFraction, (counters, resolutions, qualifiers), fmi3UInt64 counters[],
          fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[])
NO_CLOCKS(fmi3GetShiftDecimal, (shifts), fmi3Float64 shifts[])
NO_CLOCKS(fmi3GetShiftFraction, (counters, resolutions), fmi3UInt64 counters[],
          fmi3UInt64 resolutions[])
NO_CLOCKS(fmi3SetIntervalDecimal, (intervals), const fmi3Float64 intervals[])
NO_CLOCKS(fmi3SetIntervalFraction, (counters, resolutions), const fmi3UInt64 counters[],
          const fmi3UInt64 resolutions[])
NO_CLOCKS(fmi3SetShiftDecimal, (shifts), const fmi3Float64 shifts[])
NO_CLOCKS(fmi3SetShiftFraction, (counters, resolutions), const fmi3UInt64 counters[],
          const fmi3UInt64 resolutions[])

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    return fail(instance, "fmi3EvaluateDiscreteStates",
                "not supported (providesEvaluateDiscreteStates = false)");
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    const char *f = "fmi3UpdateDiscreteStates";
    int changed = 0;
    CHECK(f, StateEventMode);
    if (!discreteStatesNeedUpdate || !terminateSimulation ||
        !nominalsOfContinuousStatesChanged || !valuesOfContinuousStatesChanged ||
        !nextEventTimeDefined || !nextEventTime) {
        return fail(instance, f, "NULL argument");
    }
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = fmi3False;
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    if (coreUpdateModes((Core *)instance, &changed, f) != CoreOK) return fmi3Error;
    *discreteStatesNeedUpdate = changed ? fmi3True : fmi3False;
    return fmi3OK;
}

/* ---------------------------------------------------------------- Model Exchange */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    CHECK("fmi3EnterContinuousTimeMode", StateEventMode);
    ((Core *)instance)->state = StateContinuousTimeMode;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    const char *f = "fmi3CompletedIntegratorStep";
    int pending = 0;
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK(f, StateContinuousTimeMode);
    if (!enterEventMode || !terminateSimulation) return fail(instance, f, "NULL argument");
    if (coreModeChangePending((Core *)instance, &pending, f) != CoreOK) return fmi3Error;
    *enterEventMode = pending ? fmi3True : fmi3False;
    *terminateSimulation = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    CHECK("fmi3SetTime", StateEventMode | StateContinuousTimeMode);
    coreSetTime((Core *)instance, time);
    return fmi3OK;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    const char *f = "fmi3SetContinuousStates";
    CHECK(f, StateEventMode | StateContinuousTimeMode);
    return (fmi3Status)coreSetContinuousStates((Core *)instance, continuousStates,
                                               nContinuousStates, f);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    const char *f = "fmi3GetContinuousStateDerivatives";
    CHECK(f, StateInitializationMode | StateEventMode | StateContinuousTimeMode |
                 StateTerminated);
    return (fmi3Status)coreGetDerivatives((Core *)instance, derivatives, nContinuousStates, f);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators) {
    const char *f = "fmi3GetEventIndicators";
    CHECK(f, StateInitializationMode | StateEventMode | StateContinuousTimeMode |
                 StateTerminated);
    return (fmi3Status)coreGetEventIndicators((Core *)instance, eventIndicators,
                                              nEventIndicators, f);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    return (fmi3Status)coreGetContinuousStates((Core *)instance, continuousStates,
                                               nContinuousStates, "fmi3GetContinuousStates");
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    return (fmi3Status)coreGetNominals((Core *)instance, nominals, nContinuousStates,
                                       "fmi3GetNominalsOfContinuousStates");
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    CHECK("fmi3GetNumberOfEventIndicators", ANY_STATE);
    if (!nEventIndicators) return fail(instance, "fmi3GetNumberOfEventIndicators", "NULL argument");
    *nEventIndicators = NREL;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    CHECK("fmi3GetNumberOfContinuousStates", ANY_STATE);
    if (!nContinuousStates) {
        return fail(instance, "fmi3GetNumberOfContinuousStates", "NULL argument");
    }
    *nContinuousStates = NX;
    return fmi3OK;
}

/* ------------------------------------------------------------------ Co-Simulation */

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    return fail(instance, "fmi3EnterStepMode",
                "the FMU has no Event Mode in Co-Simulation (hasEventMode = false)");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance,
                                    const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues) {
    (void)valueReferences;
    (void)nValueReferences;
    (void)orders;
    (void)values;
    (void)nValues;
    return fail(instance, "fmi3GetOutputDerivatives",
                "not supported (maxOutputDerivativeOrder = 0)");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    Core *core = (Core *)instance;
    const char *f = "fmi3DoStep";
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK(f, StateStepMode);
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime) {
        return fail(instance, f, "NULL argument");
    }
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = core->d.time;
    if (coreDoStep(core, currentCommunicationPoint, communicationStepSize, f) != CoreOK) {
        return fmi3Error;
    }
    *lastSuccessfulTime = core->d.time;
    return fmi3OK;
}

/* ------------------------------------------------------------ Scheduled Execution */

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference;
    (void)activationTime;
    return fail(instance, "fmi3ActivateModelPartition",
                "Scheduled Execution is not supported");
}

/*
 * Model-independent core of the tsid-fmu FMUs, shared by the FMI 2.0 and FMI 3.0
 * wrappers (fmi2Functions.c, fmi3Functions.c): the instance (its mode, name and
 * logger) and all that both FMI versions do alike, from the checks of arguments and
 * log messages to initialization, FMU states, event handling and the Co-Simulation
 * step. A wrapper keeps what is version-specific: the signatures, the modes in which
 * each function may be called where the versions differ in them, and the importer's
 * callbacks; where the versions agree, the core function checks the mode itself (each
 * says which). The core knows the model only through the generated model.h / model.c:
 *   - the real array r[] (value reference = index): states, derivatives, inputs,
 *     outputs + locals, parameters, fixedStepSize;
 *   - live equations: model_ode, model_eval, model_zc;
 *   - frozen equations: model_eval_me and model_rel, in which every relation of the
 *     model (outside noEvent) is a discrete state c[k] in {0, 1}.
 *
 * Co-Simulation: classical RK4 at the fixed internal step fixedStepSize on the frozen
 * equations (the live ones if the model has no relation), the relations set as written
 * at the start of each communication step and after each switch; switches located by
 * bisection, also one that flips back within an internal step (see tsid_core.c).
 * Inputs held over a communication step, or interpolated: first order with FMI 2.0
 * input derivatives, or set by the importer at each stage time through the FMI 3.0
 * intermediate update. Outputs at communication points from the live equations.
 *
 * Model Exchange: relation k is the discrete state c[k]; between events the right-hand
 * side is smooth. Its event indicator is e_k = z_k + eps_k if c[k] = 1 and
 * z_k - eps_k if c[k] = 0, with z_k = hi - lo of the relation and the hysteresis
 * eps_k = TSID_HYSTERESIS * (|lo| + |hi|) (at least DBL_MIN): e_k > 0 exactly while
 * c[k] = 1 stays valid, and a relation that just changed starts 2 eps_k away from its
 * switching point, so a solver's root finder cannot chatter at it. At an event, c[k]
 * becomes (e_k > 0) for every k, and this is repeated (event iteration) until no
 * relation changes.
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */
#ifndef TSID_CORE_H
#define TSID_CORE_H

#include <stddef.h>

#include "model.h"

/* Indicators of the Co-Simulation integrator: the relations (as in Model Exchange, see
 * tsid_core.c), or without them the live indicators (relations inside noEvent). */
#if NREL > 0
#define NZ_CS NREL
#else
#define NZ_CS NZ
#endif

/* Relative hysteresis of the Model Exchange relations (see above). */
#define TSID_HYSTERESIS 1e-10
/* Event iterations (relation changes at one event instant) before giving up. */
#define TSID_MAX_EVENT_ITERATIONS 100

/* Same values as fmi2Status / fmi3Status. */
typedef enum { CoreOK = 0, CoreWarning = 1, CoreDiscard = 2, CoreError = 3 } CoreStatus;

/* Modes of an instance, one bit each, so that the modes in which a function may be
 * called form a mask. FMI 2.0 calls StateStepMode stepComplete and has no Intermediate
 * Update Mode. */
typedef enum {
    StateInstantiated = 1 << 0,
    StateInitializationMode = 1 << 1,
    StateEventMode = 1 << 2,
    StateContinuousTimeMode = 1 << 3,
    StateStepMode = 1 << 4,
    StateIntermediateUpdateMode = 1 << 5,
    StateTerminated = 1 << 6,
    StateError = 1 << 7
} CoreState;

#define ANY_STATE 0xff
#define INIT_PHASE (StateInstantiated | StateInitializationMode)

/* Everything an FMU state (fmi2GetFMUstate / fmi3GetFMUState) saves. */
typedef struct {
    double r[N_REAL];  /* all real variables, index = value reference */
    double time;       /* current time */
    double startTime;  /* time base of the step counter (Co-Simulation) */
    long long nSteps;  /* internal steps since startTime (Co-Simulation) */
    int dirty;         /* derivatives and outputs must be recomputed */
    int modesValid;    /* Model Exchange: c[] was set from the relations */
    double z[NZ_CS + 1]; /* Co-Simulation: indicators at the current state */
    double c[NREL + 1]; /* relation values, discrete states (ME and CS) */
    double du[NU + 1]; /* Co-Simulation: first derivatives of the inputs (FMI 2.0) */
    int hasDu;         /* some du[] was set for the next communication step */
} CoreData;

typedef struct Core Core;

/* Writes a message through the FMI logger of the wrapper. */
typedef void (*CoreLogger)(Core *core, CoreStatus status, const char *category,
                           const char *message);

/* The first member of a wrapper's instance, so that a Core * is an instance pointer. */
struct Core {
    CoreData d;
    CoreState state;
    char *instanceName;
    int isModelExchange;
    int eventIterations;
    int loggingOn;
    CoreLogger log;
    /* FMI 3.0 intermediate update: lets the importer set the inputs for time t.
     * NULL: inputs are held (or interpolated with du). Returns 0 on success. */
    int (*requestInputs)(Core *core, double t);
    double tRequested; /* time of the last requestInputs call */
};

/* Allocates a zeroed instance of `size` bytes (its first member a Core) in
 * StateInstantiated, with a copy of instanceName. NULL if out of memory. */
Core *coreNew(size_t size, const char *instanceName, int isModelExchange, int loggingOn,
              CoreLogger log);
void coreFree(Core *core);
/* Start values, time 0, StateInstantiated (CoreError if core is NULL). */
CoreStatus coreReset(Core *core);
CoreStatus coreSetDebugLogging(Core *core, int loggingOn);
void coreLog(Core *core, CoreStatus status, const char *category, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;
/* Logs "caller: message" as an error (if core is not NULL); returns CoreError. */
CoreStatus coreFail(Core *core, const char *caller, const char *message);
/* 1 if the instance exists and is in one of the modes of mask, else 0 (logged). */
int coreAllowed(Core *core, int mask, const char *caller);
/* In an FMI function: returns `error` unless `instance` is in one of the modes of mask. */
#define CORE_CHECK(instance, mask, caller, error)                           \
    do {                                                                    \
        if (!coreAllowed((Core *)(instance), mask, caller)) return error;   \
    } while (0)

/* Value-reference classes. */
int coreIsInput(unsigned int vr);
/* Marks derived values stale (and, in initPhase, the relation values). */
void coreInvalidate(Core *core, int initPhase);

/* Initialization: the experiment (only its start time matters: the Co-Simulation
 * integrator has a fixed step and no stop time) and Initialization Mode, both only in
 * StateInstantiated; then the end of Initialization Mode (only in it): checks
 * fixedStepSize, sets the modes and evaluates the model, then StateEventMode (Model
 * Exchange) or StateStepMode. */
CoreStatus coreSetupExperiment(Core *core, int toleranceDefined, double tolerance,
                               double startTime, int stopTimeDefined, double stopTime,
                               const char *caller);
CoreStatus coreEnterInitializationMode(Core *core, const char *caller);
CoreStatus coreExitInitializationMode(Core *core, const char *caller);
/* StateTerminated, from Event, Continuous-Time or Step Mode. */
CoreStatus coreTerminate(Core *core, const char *caller);

/* Derivatives and algebraic variables of the current state. */
CoreStatus coreEvaluate(Core *core, const char *caller);
/* Brings the derived values up to date before they are read (not before initialization
 * nor after an error); an error is reported once, the values are then returned as they
 * are. */
CoreStatus coreRefresh(Core *core, const char *caller);
/* Sets the real variables vr[i] = value[i] after checking that each may be set now
 * (value references are unsigned int, as fmi2ValueReference and, where the FMUs are
 * built, fmi3ValueReference = uint32_t). */
CoreStatus coreSetReals(Core *core, const unsigned int vr[], size_t nvr, const double value[],
                        const char *caller);

/* FMU state: a copy of the CoreData, in *state (allocated if *state is NULL); get and
 * set in any mode. */
CoreStatus coreGetFMUState(Core *core, void **state, const char *caller);
CoreStatus coreSetFMUState(Core *core, const void *state, const char *caller);
CoreStatus coreFreeFMUState(Core *core, void **state);

/* Defines the FMU-state functions of an FMI version, the same in FMI 2.0 and 3.0: get,
 * set and free keep a copy of the instance data in memory (coreGetFMUState ...), and
 * the serialization of an FMU state is not supported. Status, Instance, FMUState and
 * Byte are the version's types; the other arguments name the functions (as the FMI
 * headers declare them), so that each stands in its wrapper by name. */
#define CORE_FMU_STATE_FUNCTIONS(Status, Instance, FMUState, Byte, get, set, freeState,     \
                                 serializedSize, serialize, deserialize)                  \
    Status get(Instance instance, FMUState *state) {                                      \
        return (Status)coreGetFMUState((Core *)instance, state, #get);                    \
    }                                                                                     \
    Status set(Instance instance, FMUState state) {                                       \
        return (Status)coreSetFMUState((Core *)instance, state, #set);                    \
    }                                                                                     \
    Status freeState(Instance instance, FMUState *state) {                                \
        return (Status)coreFreeFMUState((Core *)instance, state);                         \
    }                                                                                     \
    Status serializedSize(Instance instance, FMUState state, size_t *size) {              \
        (void)state;                                                                      \
        (void)size;                                                                       \
        return (Status)coreFail((Core *)instance, #serializedSize, "not supported");      \
    }                                                                                     \
    Status serialize(Instance instance, FMUState state, Byte serializedState[],           \
                     size_t size) {                                                       \
        (void)state;                                                                      \
        (void)serializedState;                                                            \
        (void)size;                                                                       \
        return (Status)coreFail((Core *)instance, #serialize, "not supported");           \
    }                                                                                     \
    Status deserialize(Instance instance, const Byte serializedState[], size_t size,      \
                       FMUState *state) {                                                 \
        (void)serializedState;                                                            \
        (void)size;                                                                       \
        (void)state;                                                                      \
        return (Status)coreFail((Core *)instance, #deserialize, "not supported");         \
    }

/* Model Exchange. */
CoreStatus coreInitModes(Core *core, const char *caller);
CoreStatus coreEventIndicators(Core *core, double e[], const char *caller);
/* Event Mode: the event iteration (coreUpdateModes) starts anew; an error in it puts the
 * instance into StateError. */
void coreEnterEventMode(Core *core);
CoreStatus coreUpdateModes(Core *core, int *changed, const char *caller);
CoreStatus coreModeChangePending(Core *core, int *pending, const char *caller);
void coreSetTime(Core *core, double time);
/* Arrays of the continuous states: n must be NX (ni: NREL). Their getters (not those of
 * the derivatives and event indicators) in any mode. */
CoreStatus coreSetContinuousStates(Core *core, const double x[], size_t n, const char *caller);
CoreStatus coreGetContinuousStates(Core *core, double x[], size_t n, const char *caller);
CoreStatus coreGetNominals(Core *core, double nominals[], size_t n, const char *caller);
CoreStatus coreGetDerivatives(Core *core, double dx[], size_t n, const char *caller);
CoreStatus coreGetEventIndicators(Core *core, double e[], size_t ni, const char *caller);

/* Co-Simulation. */
CoreStatus coreSetInputDerivative(Core *core, unsigned int vr, int order, double value,
                                  const char *caller);
/* Integrates from tc to tc + hc and evaluates the outputs there. Bad arguments leave
 * the instance usable; a failed step puts it into StateError. */
CoreStatus coreDoStep(Core *core, double tc, double hc, const char *caller);

#endif

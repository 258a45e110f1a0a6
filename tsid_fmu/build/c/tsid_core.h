/*
 * Model-independent core of the tsid-fmu FMUs, shared by the FMI 2.0 and FMI 3.0
 * wrappers (fmi2Functions.c, fmi3Functions.c). It knows the model only through the
 * generated model.h / model.c:
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

struct Core {
    CoreData d;
    int isModelExchange;
    int eventIterations;
    int loggingOn;
    /* Writes a message through the FMI logger of the wrapper. */
    void (*log)(Core *core, CoreStatus status, const char *category, const char *message);
    /* FMI 3.0 intermediate update: lets the importer set the inputs for time t.
     * NULL: inputs are held (or interpolated with du). Returns 0 on success. */
    int (*requestInputs)(Core *core, double t);
    double tRequested; /* time of the last requestInputs call */
};

void coreInit(Core *core, int isModelExchange);
void coreResetData(Core *core);
void coreLog(Core *core, CoreStatus status, const char *category, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;

/* Value-reference classes. */
int coreIsInput(unsigned int vr);
int coreIsState(unsigned int vr);
int coreIsParameter(unsigned int vr);
/* Checks that vr may be set now; initPhase: instantiated or initialization mode. */
CoreStatus coreCheckSet(Core *core, unsigned int vr, int initPhase, const char *caller);
/* Marks derived values stale (and, in initPhase, the relation values). */
void coreInvalidate(Core *core, int initPhase);

/* Derivatives and algebraic variables of the current state. */
CoreStatus coreEvaluate(Core *core, const char *caller);

/* Model Exchange. */
CoreStatus coreInitModes(Core *core, const char *caller);
CoreStatus coreEventIndicators(Core *core, double e[], const char *caller);
CoreStatus coreUpdateModes(Core *core, int *changed, const char *caller);
CoreStatus coreModeChangePending(Core *core, int *pending, const char *caller);

/* Co-Simulation. */
CoreStatus coreSetInputDerivative(Core *core, unsigned int vr, int order, double value,
                                  const char *caller);
/* Checks the arguments of a communication step (the instance stays usable). */
CoreStatus coreCheckStep(Core *core, double tc, double hc, const char *caller);
/* Integrates from tc to tc + hc and evaluates the outputs there. */
CoreStatus coreDoStep(Core *core, double tc, double hc, const char *caller);

#endif

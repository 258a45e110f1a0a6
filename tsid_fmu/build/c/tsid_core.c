/*
 * Model-independent core of the tsid-fmu FMUs (see tsid_core.h).
 *
 * SPDX-License-Identifier: BSD-3-Clause
 */

#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "tsid_core.h"

/* Event location in Co-Simulation: bisection until the bracket is this short [s], at
 * most this many located events per internal step (the rest of the step is then taken
 * as is). */
#define EVENT_TIME_TOL 1e-10
#define MAX_EVENTS_PER_STEP 8

#define X(d) ((d)->r + X_OFF)
#define DX(d) ((d)->r + DX_OFF)
#define U(d) ((d)->r + U_OFF)
#define W(d) ((d)->r + W_OFF)
#define P(d) ((d)->r + P_OFF)

/* ----------------------------------------------------------------- housekeeping */

void coreResetData(Core *core) {
    CoreData *d = &core->d;
    memset(d, 0, sizeof(*d));
    memcpy(d->r, model_start, sizeof(d->r));
    d->dirty = 1;
    core->eventIterations = 0;
    core->tRequested = -HUGE_VAL;
}

void coreInit(Core *core, int isModelExchange) {
    core->isModelExchange = isModelExchange;
    core->loggingOn = 0;
    core->log = NULL;
    core->requestInputs = NULL;
    coreResetData(core);
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

int coreIsInput(unsigned int vr) { return vr >= U_OFF && vr < U_OFF + NU; }

int coreIsState(unsigned int vr) { return vr < X_OFF + NX; }

int coreIsParameter(unsigned int vr) { return vr >= P_OFF && vr <= VR_FIXED_STEP; }

CoreStatus coreCheckSet(Core *core, unsigned int vr, int initPhase, const char *caller) {
    if (vr >= N_REAL) {
        coreLog(core, CoreError, "logStatusError", "%s: unknown value reference %u", caller, vr);
        return CoreError;
    }
    if (coreIsParameter(vr) && !initPhase) {
        coreLog(core, CoreError, "logStatusError",
                "%s: parameter %s is fixed after initialization", caller, model_names[vr]);
        return CoreError;
    }
    if (coreIsState(vr) && !initPhase) {
        coreLog(core, CoreError, "logStatusError",
                "%s: %s can only be set before or during initialization", caller,
                model_names[vr]);
        return CoreError;
    }
    if (!coreIsInput(vr) && !coreIsParameter(vr) && !coreIsState(vr)) {
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

CoreStatus coreEvaluate(Core *core, const char *caller) {
    CoreData *d = &core->d;
    int bad = 0, rc;
    if (!d->dirty) return CoreOK;
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

CoreStatus coreUpdateModes(Core *core, int *changed, const char *caller) {
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

/* One classical Runge-Kutta step of size h from time t. */
static int rk4Step(Core *core, double tc, double t, double h) {
    CoreData *d = &core->d;
    double k1[NX + 1], k2[NX + 1], k3[NX + 1], k4[NX + 1], xt[NX + 1], ub[NU + 1];
    double *x = X(d);
    const double *p = P(d), *u;
    int i;
    if (!(u = inputsAt(core, tc, t, ub)) || model_ode(t, x, u, p, k1)) return 1;
    for (i = 0; i < NX; i++) xt[i] = x[i] + 0.5 * h * k1[i];
    if (!(u = inputsAt(core, tc, t + 0.5 * h, ub)) || model_ode(t + 0.5 * h, xt, u, p, k2)) {
        return 1;
    }
    for (i = 0; i < NX; i++) xt[i] = x[i] + 0.5 * h * k2[i];
    if (model_ode(t + 0.5 * h, xt, u, p, k3)) return 1;
    for (i = 0; i < NX; i++) xt[i] = x[i] + h * k3[i];
    if (!(u = inputsAt(core, tc, t + h, ub)) || model_ode(t + h, xt, u, p, k4)) return 1;
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

/* Live indicators z after a step that ended at time t. */
static int zcAt(Core *core, double tc, double t, double *z) {
    double ub[NU + 1];
    const double *u = inputsAt(core, tc, t, ub);
    return !u || model_zc(t, X(&core->d), u, P(&core->d), z);
}
#endif

/* One internal step of size h from t with event location. d->z must hold the
 * indicators at (t, x); on return it holds them at the new state. */
static int stepWithEvents(Core *core, double tc, double t, double h) {
#if NZ > 0
    CoreData *d = &core->d;
    double x0[NX + 1], z1[NZ + 1];
    double tau = 0.0; /* part of the step already taken */
    int events = 0;
    while (h - tau > 0.0) {
        double rest = h - tau;
        memcpy(x0, X(d), sizeof(double) * (NX + 1));
        if (rk4Step(core, tc, t + tau, rest)) return 1;
        if (zcAt(core, tc, t + h, z1)) return 1;
        if (events < MAX_EVENTS_PER_STEP && crossed(d->z, z1) >= 0) {
            double lo = 0.0, hi = rest;
            while (hi - lo > EVENT_TIME_TOL) {
                double mid = 0.5 * (lo + hi);
                memcpy(X(d), x0, sizeof(double) * (NX + 1));
                if (rk4Step(core, tc, t + tau, mid)) return 1;
                if (zcAt(core, tc, t + tau + mid, z1)) return 1;
                if (crossed(d->z, z1) >= 0) hi = mid; else lo = mid;
            }
            /* advance to just before the first crossing, so that no stage of the step
             * sees the branch after it, then over the crossing by at most
             * EVENT_TIME_TOL, and continue from there */
            memcpy(X(d), x0, sizeof(double) * (NX + 1));
            if (lo > 0.0 && rk4Step(core, tc, t + tau, lo)) return 1;
            if (rk4Step(core, tc, t + tau + lo, hi - lo)) return 1;
            if (zcAt(core, tc, t + tau + hi, z1)) return 1;
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
    return rk4Step(core, tc, t, h);
#endif
}

static CoreStatus stepFailed(Core *core, double tc, double tEnd, int bad, const char *caller) {
    CoreData *d = &core->d;
    if (bad < 0) {
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

CoreStatus coreCheckStep(Core *core, double tc, double hc, const char *caller) {
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

CoreStatus coreDoStep(Core *core, double tc, double hc, const char *caller) {
    CoreData *d = &core->d;
    double h = d->r[VR_FIXED_STEP], tEnd = tc + hc, nReal, hSub;
    long long n, k;
    int bad = -1, i;
    if (coreCheckStep(core, tc, hc, caller) != CoreOK) return CoreError;
    core->tRequested = -HUGE_VAL;
    /* inputs may have changed since the last step: indicators at the current point */
    if (NZ > 0 && model_zc(d->time, X(d), U(d), P(d), d->z)) {
        return stepFailed(core, tc, tEnd, -1, caller);
    }
    nReal = hc / h;
    n = (long long)floor(nReal + 0.5);
    if (n >= 1 && fabs(nReal - (double)n) <= 1e-9 * nReal) {
        /* communication step is a multiple of the internal step: t = t0 + k*h */
        for (k = 0; k < n; k++) {
            double t = d->startTime + (double)d->nSteps * h;
            if (stepWithEvents(core, tc, t, h)) return stepFailed(core, tc, tEnd, -1, caller);
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
            if (stepWithEvents(core, tc, tc + (double)k * hSub, hSub)) {
                return stepFailed(core, tc, tEnd, -1, caller);
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

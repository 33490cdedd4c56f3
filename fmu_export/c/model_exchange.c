/* Model Exchange of the native reference FMU (model_exchange.h says what each function does): the
   state machine of its calls and the checks of their arguments, over the model's locked right-hand
   side (switching.c). The states' nominal values are all 1, the scale of per-unit quantities and
   radians. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "model_exchange.h"
#include "switching.h"
#include "variables.h"

/* (the model description has the groups it reads only where they are not empty) */
ModelStatus exchange_get_real(const ModelState *m, unsigned int vr, double *value)
{
#if OPFMU_N_STATES > 0
    if (IN_GROUP(vr, VR_FIRST_DERIVATIVE, OPFMU_N_STATES)) {
        double dx[OPFMU_X_SIZE];
        locked_derivatives(m, dx);
        *value = dx[vr - VR_FIRST_DERIVATIVE];
        return MODEL_OK;
    }
#endif
#if OPFMU_N_SWITCHING > 0
    if (IN_GROUP(vr, VR_FIRST_INDICATOR, OPFMU_N_SWITCHING)) {
        double g[OPFMU_G_SIZE];
        switching_functions(m, g);
        *value = g[vr - VR_FIRST_INDICATOR];
        return MODEL_OK;
    }
#endif
    (void)m;
    (void)value;
    return MODEL_ERROR;
}

/* nonzero (logged) unless the instance is one for Model Exchange in one of the states `allowed` */
static int refused(Instance *inst, const char *function, int allowed)
{
    if (!inst) return 1;
    if (!inst->model_exchange) {
        log_message(inst, STATUS_ERROR, "logStatusError", "%s: the instance was instantiated for co-simulation, not "
                    "Model Exchange", function);
        return 1;
    }
    return not_allowed(inst, function, allowed);
}

/* nonzero (logged) unless the array of n values is there (or n = 0) and n is `expected`, what it holds */
static int bad_array(Instance *inst, const char *function, const void *values, size_t n, size_t expected,
                     const char *what)
{
    if (n != expected) {
        log_message(inst, STATUS_ERROR, "logStatusError", "%s: %lu values for the FMU's %lu %s", function,
                    (unsigned long)n, (unsigned long)expected, what);
        return 1;
    }
    if (n > 0 && !values) {
        log_message(inst, STATUS_ERROR, "logStatusError", "%s: NULL array", function);
        return 1;
    }
    return 0;
}

/* the states in which the model's values at its time, state and inputs can be read: after
   initialisation */
#define ST_EVALUATED (ST_EVENT | ST_CONTINUOUS | ST_TERMINATED | ST_ERROR)

Status me_set_time(Instance *inst, const char *function, double time)
{
    char message[512];
    if (refused(inst, function, ST_EVENT | ST_CONTINUOUS)) return STATUS_ERROR;
    if (!isfinite(time)) {
        snprintf(message, sizeof message, "%s: time %g is not a finite number", function, time);
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    inst->model.time = time;
    return STATUS_OK;
}

Status me_set_states(Instance *inst, const char *function, const double x[], size_t n)
{
    char message[512];
    if (refused(inst, function, ST_CONTINUOUS)) return STATUS_ERROR;
    if (bad_array(inst, function, x, n, OPFMU_N_STATES, "continuous states")) return STATUS_ERROR;
    const int i = first_non_finite(x, (int)n);
    if (i >= 0) {
        snprintf(message, sizeof message, "%s: state %d: %g is not a finite number (the states are left as they were)",
                 function, i, x[i]);
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    if (n > 0) memcpy(inst->model.x, x, n * sizeof *x);
    return STATUS_OK;
}

Status me_get_states(Instance *inst, const char *function, double out[], size_t n)
{
    if (refused(inst, function, ST_EVALUATED)) return STATUS_ERROR;
    if (bad_array(inst, function, out, n, OPFMU_N_STATES, "continuous states")) return STATUS_ERROR;
    if (n > 0) memcpy(out, inst->model.x, n * sizeof *out);
    return STATUS_OK;
}

Status me_get_derivatives(Instance *inst, const char *function, double out[], size_t n)
{
    double dx[OPFMU_X_SIZE];
    if (refused(inst, function, ST_EVALUATED)) return STATUS_ERROR;
    if (bad_array(inst, function, out, n, OPFMU_N_STATES, "continuous states")) return STATUS_ERROR;
    locked_derivatives(&inst->model, dx);
    if (n > 0) memcpy(out, dx, n * sizeof *out);
    /* the right-hand side outside its domain at this state, time and inputs (with the branches locked
       at the last event): the FMI's Discard, so that the integrator tries a smaller step */
    const int i = first_non_finite(dx, OPFMU_N_STATES);
    if (i >= 0) {
        char message[512];
        snprintf(message, sizeof message, "%s: the derivative of state %d is %g at time %g (the right-hand side is "
                 "outside its domain at these states and inputs): try a smaller step", function, i, dx[i],
                 inst->model.time);
        return fail(inst, STATUS_DISCARD, "%s", message);
    }
    return STATUS_OK;
}

Status me_get_indicators(Instance *inst, const char *function, double out[], size_t n)
{
    double g[OPFMU_G_SIZE];
    if (refused(inst, function, ST_EVALUATED)) return STATUS_ERROR;
    if (bad_array(inst, function, out, n, OPFMU_N_SWITCHING, "event indicators")) return STATUS_ERROR;
    switching_functions(&inst->model, g);
    if (n > 0) memcpy(out, g, n * sizeof *out);
    return STATUS_OK;
}

Status me_get_nominals(Instance *inst, const char *function, double out[], size_t n)
{
    if (refused(inst, function, ST_ANY)) return STATUS_ERROR;
    if (bad_array(inst, function, out, n, OPFMU_N_STATES, "continuous states")) return STATUS_ERROR;
    for (size_t i = 0; i < n; ++i) out[i] = 1.0;
    return STATUS_OK;
}

Status me_enter_event_mode(Instance *inst, const char *function)
{
    if (refused(inst, function, ST_EVENT | ST_CONTINUOUS)) return STATUS_ERROR;
    inst->state = ST_EVENT;
    return STATUS_OK;
}

#if OPFMU_N_SWITCHING > 0
#define PROBE_TIME 1e-9 /* [s] how far along the locked rate a condition at its switching point is probed */

/* A condition locked at its switching point (g_k = 0 exactly: a state just placed on its limit,
   a clip at rest on its bound) takes the branch that holds a moment later, PROBE_TIME along the
   locked rate dx/dt, where that branch differs: the importer sees no sign change of an indicator that
   starts at 0, and the co-simulation step locates this change within its first solver step. */
static void lock_touching(ModelState *m)
{
    double g[N_G], after[N_G], dx[OPFMU_N_STATES], probe[OPFMU_N_STATES];
    int mode[N_G], touching = 0;
    model_switching(m->x, m->u, m->p, g, mode);
    for (int k = 0; k < N_G; ++k) touching |= g[k] == 0.0;
    if (!touching) return;
    model_derivatives_locked(m->x, m->u, m->p, m->mode, dx);
    for (int i = 0; i < OPFMU_N_STATES; ++i) probe[i] = m->x[i] + PROBE_TIME * dx[i];
    model_switching(probe, m->u, m->p, after, mode);
    for (int k = 0; k < N_G; ++k)
        if (g[k] == 0.0) m->mode[k] = mode[k];
}
#endif

Status me_update_discrete_states(Instance *inst, const char *function, int *values_changed)
{
    if (refused(inst, function, ST_EVENT)) return STATUS_ERROR;
    if (!values_changed) return fail(inst, STATUS_ERROR, "%s: NULL argument", function);
    ModelState *m = &inst->model;
    *values_changed = 0;
#if OPFMU_N_SWITCHING > 0
    /* the resets where co-simulation starts a communication step (the first event, inputs that
       changed, a reset the last integrator step asked for) or locks at a located switching (the
       branches that hold change dx/dt); the branches locked at every event, so that they follow the
       indicators' signs */
    if (m->lock_due || memcmp(m->u, m->u_locked, sizeof m->u) != 0 || branches_changed(m->x, m->u, m->p, m->mode)) {
        double before[OPFMU_N_STATES];
        memcpy(before, m->x, sizeof before);
        relock(m->x, m->u, m->p, m->mode);
        *values_changed = memcmp(before, m->x, sizeof before) != 0;
    } else {
        double g[N_G];
        model_switching(m->x, m->u, m->p, g, m->mode);
    }
    lock_touching(m);
#endif
    memcpy(m->u_locked, m->u, sizeof m->u_locked);
    m->lock_due = 0;
    return STATUS_OK;
}

Status me_enter_continuous_time_mode(Instance *inst, const char *function)
{
    if (refused(inst, function, ST_EVENT)) return STATUS_ERROR;
    inst->state = ST_CONTINUOUS;
    return STATUS_OK;
}

Status me_completed_integrator_step(Instance *inst, const char *function, int *enter_event_mode)
{
    if (refused(inst, function, ST_CONTINUOUS)) return STATUS_ERROR;
    if (!enter_event_mode) return fail(inst, STATUS_ERROR, "%s: NULL argument", function);
#if OPFMU_N_SWITCHING > 0
    ModelState *m = &inst->model;
    if (reset_moves(m->x, m->u, m->p)) m->lock_due = 1;
    *enter_event_mode = m->lock_due || branches_changed(m->x, m->u, m->p, m->mode);
#else
    *enter_event_mode = 0;
#endif
    return STATUS_OK;
}

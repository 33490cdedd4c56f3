/* The surrogate FMU's variable table: get and set by value reference, the kind of each variable and
   the range checks of the inputs and parameters. Value references come from the generated
   variables.h (the model description's table): the component's inputs, states, derived outputs and
   initial-state parameters as contiguous groups, then the surrogate's own variables by name. */
#include <math.h>
#include <stdio.h>

#include "engine.h"
#include "variables.h"

static const unsigned char REAL_KINDS[VR_REAL_COUNT] = VR_REAL_KINDS;

/* value reference vr lies in the group of n starting at first */
#define IN_GROUP(vr, first, n) ((unsigned int)((vr) - (first)) < (unsigned int)(n))

int model_real_kind(unsigned int vr)
{
    return vr < VR_REAL_COUNT ? (int)REAL_KINDS[vr] : -1;
}

ModelStatus model_get_real(const ModelState *m, unsigned int vr, double *value)
{
    if (IN_GROUP(vr, VR_FIRST_INPUT, N_U)) {
        *value = m->u[vr - VR_FIRST_INPUT];
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_STATE, N_X)) {
        *value = m->x[vr - VR_FIRST_STATE];
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_OUTPUT, OPFMU_N_OUTPUTS)) {
        double y[OPFMU_N_OUTPUTS];
        model_outputs(m->x, m->u, y);
        *value = y[vr - VR_FIRST_OUTPUT];
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_START, N_X)) {
        *value = m->x_start[vr - VR_FIRST_START];
        return MODEL_OK;
    }
    switch (vr) {
    case VR_RESIDUAL: *value = window_residual(m); return MODEL_OK;
    case VR_ROLLOVER_HORIZON: *value = m->rollover_horizon; return MODEL_OK;
    case VR_RESIDUAL_LIMIT: *value = m->residual_limit; return MODEL_OK;
    case VR_RESTART_JUMP: *value = m->restart_jump; return MODEL_OK;
    case VR_REST_RADIUS: *value = m->rest_radius; return MODEL_OK;
    case VR_SLOW_WEIGHT: *value = m->slow_weight; return MODEL_OK;
    case VR_SWING_WEIGHT: *value = m->swing_weight; return MODEL_OK;
    default: return MODEL_ERROR;
    }
}

/* Sets a parameter that must be >= 0 (zero_means: what 0 does, for the refusal message). */
static ModelStatus set_nonnegative(double *field, double value, const char *name, const char *zero_means,
                                   char *message, size_t size)
{
    if (value < 0.0) {
        snprintf(message, size, "%s = %g must be >= 0 (%s)", name, value, zero_means);
        return MODEL_ERROR;
    }
    *field = value;
    return MODEL_OK;
}

/* Sets a weight that must lie in [0, 1] (what: the correction 0 turns off, for the refusal message). */
static ModelStatus set_weight(double *field, double value, const char *name, const char *what, char *message,
                              size_t size)
{
    if (!(value >= 0.0 && value <= 1.0)) {
        snprintf(message, size, "%s = %g must lie in [0, 1] (0 turns %s off)", name, value, what);
        return MODEL_ERROR;
    }
    *field = value;
    return MODEL_OK;
}

ModelStatus model_set_real(ModelState *m, unsigned int vr, double value, char *message, size_t size)
{
    if (!isfinite(value)) {
        snprintf(message, size, "value reference %u: %g is not a finite number", vr, value);
        return MODEL_ERROR;
    }
    if (IN_GROUP(vr, VR_FIRST_INPUT, N_U)) {
        const unsigned int c = vr - VR_FIRST_INPUT;
        if (value < OPFMU_INPUT_MIN[c]) {
            snprintf(message, size, "%s = %g %s is below its lower bound %g %s", OPFMU_INPUT_NAMES[c], value,
                     OPFMU_INPUT_UNITS[c], OPFMU_INPUT_MIN[c], OPFMU_INPUT_UNITS[c]);
            return MODEL_ERROR;
        }
        m->u[c] = value;
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_START, N_X)) {
        m->x_start[vr - VR_FIRST_START] = value;
        return MODEL_OK;
    }
    switch (vr) {
    case VR_ROLLOVER_HORIZON:
        if (!(value >= 10 * SENSOR_DT && value <= OPFMU_HORIZON + TIME_EPS)) {
            snprintf(message, size, "rollover_horizon = %g s must lie in [%g, %g] s (the trained horizon)",
                     value, 10 * SENSOR_DT, OPFMU_HORIZON);
            return MODEL_ERROR;
        }
        m->rollover_horizon = value;
        return MODEL_OK;
    case VR_RESIDUAL_LIMIT:
        return set_nonnegative(&m->residual_limit, value, "residual_limit", "0 turns the check off", message, size);
    case VR_RESTART_JUMP:
        return set_nonnegative(&m->restart_jump, value, "restart_jump",
                               "0: windows start at the rollover horizon only", message, size);
    case VR_REST_RADIUS:
        return set_nonnegative(&m->rest_radius, value, "rest_radius", "0 turns the rest correction off", message, size);
    case VR_SLOW_WEIGHT:
        return set_weight(&m->slow_weight, value, "slow_weight", "the slow-mode correction", message, size);
    case VR_SWING_WEIGHT:
        return set_weight(&m->swing_weight, value, "swing_weight", "the exact step of the affine states", message,
                          size);
    default:
        snprintf(message, size, "value reference %u is not a settable Real variable", vr);
        return MODEL_ERROR;
    }
}

int model_boolean_exists(unsigned int vr) { return vr == VR_BOOL_IN_ENVELOPE; }

int model_get_boolean(const ModelState *m, unsigned int vr) { (void)vr; return m->in_envelope; }

/* The surrogate FMU's own variables (after the component's, variables.c): the residual, the
   window and correction parameters with their range checks, the Boolean in_envelope, and the
   inputs' derivatives (fmi2SetRealInputDerivatives: the inputs linear over the next steps, window.c). */
#include <math.h>
#include <stdio.h>

#include "engine.h"
#include "variables.h"

ModelStatus model_get_extra(const ModelState *m, unsigned int vr, double *value)
{
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

ModelStatus model_set_extra(ModelState *m, unsigned int vr, double value, char *message, size_t size)
{
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

const char *model_no_derivative(unsigned int vr)
{
    if (vr == VR_RESIDUAL)
        return "residual is a diagnostic (the RMS of the operator's physics residual), not a function of the "
               "inputs with a derivative; fmi2GetDirectionalDerivative does not provide one";
    return NULL;
}

ModelStatus model_set_input_derivative(ModelState *m, unsigned int c, double value, char *message, size_t size)
{
    if (!isfinite(value)) {
        snprintf(message, size, "the derivative of %s: %g is not a finite number", OPFMU_INPUT_NAMES[c], value);
        return MODEL_ERROR;
    }
    m->du[c] = value;
    return MODEL_OK;
}

/* The surrogate FMU's own variables (after the component's, variables.c): the residual, the
   window and correction parameters with their range checks, and the Boolean in_envelope. */
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

/* The range check of the surrogate parameter vr (message: why value is refused): the one both a
   setter and a state check apply. */
static ModelStatus parameter_in_range(unsigned int vr, double value, char *message, size_t size)
{
    const char *name = NULL, *zero_means = NULL, *weight_of = NULL;
    switch (vr) {
    case VR_ROLLOVER_HORIZON: name = "rollover_horizon"; break;
    case VR_RESIDUAL_LIMIT: name = "residual_limit", zero_means = "0 turns the check off"; break;
    case VR_RESTART_JUMP: name = "restart_jump", zero_means = "0: windows start at the rollover horizon only"; break;
    case VR_REST_RADIUS: name = "rest_radius", zero_means = "0 turns the rest correction off"; break;
    case VR_SLOW_WEIGHT: name = "slow_weight", weight_of = "the slow-mode correction"; break;
    case VR_SWING_WEIGHT: name = "swing_weight", weight_of = "the exact step of the affine states"; break;
    default:
        snprintf(message, size, "value reference %u is not a settable Real variable", vr);
        return MODEL_ERROR;
    }
    if (!isfinite(value)) {
        snprintf(message, size, "%s = %g is not a finite number", name, value);
        return MODEL_ERROR;
    }
    if (vr == VR_ROLLOVER_HORIZON && !(value >= OPFMU_SHORTEST_ROLLOVER - TIME_EPS && value <= OPFMU_HORIZON + TIME_EPS)) {
        snprintf(message, size, "rollover_horizon = %g s must lie in [%g, %g] s (the trained horizon)", value,
                 OPFMU_SHORTEST_ROLLOVER, OPFMU_HORIZON);
        return MODEL_ERROR;
    }
    if (zero_means && value < 0.0) {
        snprintf(message, size, "%s = %g must be >= 0 (%s)", name, value, zero_means);
        return MODEL_ERROR;
    }
    if (weight_of && !(value >= 0.0 && value <= 1.0)) {
        snprintf(message, size, "%s = %g must lie in [0, 1] (0 turns %s off)", name, value, weight_of);
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

/* the field of parameter vr, or NULL */
static double *parameter_field(ModelState *m, unsigned int vr)
{
    switch (vr) {
    case VR_ROLLOVER_HORIZON: return &m->rollover_horizon;
    case VR_RESIDUAL_LIMIT: return &m->residual_limit;
    case VR_RESTART_JUMP: return &m->restart_jump;
    case VR_REST_RADIUS: return &m->rest_radius;
    case VR_SLOW_WEIGHT: return &m->slow_weight;
    case VR_SWING_WEIGHT: return &m->swing_weight;
    default: return NULL;
    }
}

ModelStatus model_set_extra(ModelState *m, unsigned int vr, double value, char *message, size_t size)
{
    double *field = parameter_field(m, vr);
    if (parameter_in_range(vr, value, message, size) != MODEL_OK) return MODEL_ERROR;
    *field = value; /* a vr in range is a parameter's */
    return MODEL_OK;
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

/* a flag that is neither 0 nor 1 */
static int not_a_flag(int value) { return value != 0 && value != 1; }

ModelStatus model_check_state(const ModelState *m, char *why, size_t size)
{
    static const unsigned int PARAMETERS[] = {VR_ROLLOVER_HORIZON, VR_RESIDUAL_LIMIT, VR_RESTART_JUMP,
                                              VR_REST_RADIUS, VR_SLOW_WEIGHT, VR_SWING_WEIGHT};
    /* the state's arrays and numbers that need only be finite */
    const struct {
        const char *name;
        const double *values;
        int n;
    } finite[] = {
        {"x_operator", m->x_operator, N_X}, {"x_window", m->x_window, N_X}, {"x_window_f", m->x_window_f, N_X},
        {"frame", &m->frame.a, 1}, {"frame shift", &m->frame.shift, 1}, {"frame speed", &m->frame.c, 1},
        {"sensors", m->sensors, N_U * OPFMU_N_SENSORS}, {"z_base", m->z_base, OPFMU_Z_SIZE},
        {"z_past", m->z_past, OPFMU_Z_SIZE}, {"last_u", m->last_u, N_U}, {"last_du", m->last_du, N_U},
        {"input_time", &m->input_time, 1}, {"prev_end_u", m->prev_end_u, N_U}, {"prev_du", m->prev_du, N_U},
        {"trunk", m->trunk, OPFMU_TRUNK_CACHE}, {"coef", m->coef, OPFMU_COEF_CAP}, {"x_rest", m->x_rest, N_X},
        {"rest_coef", m->rest_coef, OPFMU_COEF_CAP}, {"slow_left", m->slow_left, N_X},
        {"slow_right", m->slow_right, N_X}, {"slow_start", &m->slow_start, 1},
        {"slow_integral", &m->slow_integral, 1}, {"corrected_for", m->corrected_for, N_U},
    };
    char reason[256];
    int i;
    if (check_component_state(m, why, size) != MODEL_OK) return MODEL_ERROR;
    for (size_t p = 0; p < sizeof PARAMETERS / sizeof *PARAMETERS; ++p) {
        double value = *parameter_field((ModelState *)m, PARAMETERS[p]);
        if (parameter_in_range(PARAMETERS[p], value, reason, sizeof reason) != MODEL_OK) {
            snprintf(why, size, "%s", reason);
            return MODEL_ERROR;
        }
    }
    for (size_t f = 0; f < sizeof finite / sizeof *finite; ++f) {
        if ((i = first_non_finite(finite[f].values, finite[f].n)) >= 0) {
            snprintf(why, size, "%s[%d] = %g is not a finite number", finite[f].name, i, finite[f].values[i]);
            return MODEL_ERROR;
        }
    }
    /* the window started at or before the current time, and its end is not behind it */
    if (!(m->window_start <= m->time + TIME_EPS && m->time - m->window_start <= m->rollover_horizon + TIME_EPS)) {
        snprintf(why, size, "window start %.9g s is not within the rollover horizon %g s before the time %.9g s",
                 m->window_start, m->rollover_horizon, m->time);
        return MODEL_ERROR;
    }
    /* window times of the last step: within the trained horizon */
    if (!(m->last_start >= -TIME_EPS && m->last_start <= OPFMU_HORIZON + 2 * TIME_EPS && m->last_end >= -TIME_EPS &&
          m->last_end <= OPFMU_HORIZON + 2 * TIME_EPS)) {
        snprintf(why, size, "the last step's window times %g, %g s do not lie in [0, %g] s", m->last_start, m->last_end,
                 OPFMU_HORIZON);
        return MODEL_ERROR;
    }
    if (m->filled < 0 || m->filled > OPFMU_N_SENSORS) {
        snprintf(why, size, "filled sensor slots %d do not lie in [0, %d]", m->filled, OPFMU_N_SENSORS);
        return MODEL_ERROR;
    }
    if (not_a_flag(m->residual_alarm) || not_a_flag(m->in_envelope) || not_a_flag(m->slow_on)) {
        snprintf(why, size, "a flag (residual_alarm %d, in_envelope %d, slow_on %d) is neither 0 nor 1",
                 m->residual_alarm, m->in_envelope, m->slow_on);
        return MODEL_ERROR;
    }
    for (int k = 0; k < OPFMU_TRUNK_SLOTS; ++k) {
        if (not_a_flag(m->trunk_ready[k])) {
            snprintf(why, size, "trunk_ready[%d] = %d is neither 0 nor 1", k, m->trunk_ready[k]);
            return MODEL_ERROR;
        }
    }
    if (!(m->rest_weight >= 0.0 && m->rest_weight <= 1.0)) {
        snprintf(why, size, "rest_weight = %g does not lie in [0, 1]", m->rest_weight);
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

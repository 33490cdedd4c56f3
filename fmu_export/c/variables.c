/* The component's variables of either native FMU, by value reference: its inputs, states, derived
   outputs and initial-state parameters (contiguous groups, from the generated variables.h, the model
   description's table), the kind of every Real, the checks of what may be written, the inputs'
   derivatives, and the check of the component's fields of a state. The model's own variables (those
   after the groups) are the model's: model_get_extra, model_set_extra. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "model.h"
#include "variables.h"

static const unsigned char REAL_KINDS[VR_REAL_COUNT] = VR_REAL_KINDS;

int model_real_kind(unsigned int vr)
{
    return vr < VR_REAL_COUNT ? (int)REAL_KINDS[vr] : -1;
}

void component_defaults(ModelState *m)
{
    memset(m, 0, sizeof *m);
    memcpy(m->u, OPFMU_START_U, sizeof m->u);
    memcpy(m->x_start, OPFMU_DEFAULT_X0, sizeof m->x_start);
    memcpy(m->x, m->x_start, sizeof m->x);
}

ModelStatus model_get_real(const ModelState *m, unsigned int vr, double *value)
{
    if (IN_GROUP(vr, VR_FIRST_INPUT, OPFMU_N_INPUTS)) {
        *value = m->u[vr - VR_FIRST_INPUT];
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_STATE, OPFMU_N_STATES)) {
        *value = m->x[vr - VR_FIRST_STATE];
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_OUTPUT, OPFMU_N_OUTPUTS)) { /* from the inputs as they are now */
        double y[OPFMU_N_OUTPUTS];
        model_outputs(m->x, m->u, y);
        *value = y[vr - VR_FIRST_OUTPUT];
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_START, OPFMU_N_STATES)) {
        *value = m->x_start[vr - VR_FIRST_START];
        return MODEL_OK;
    }
    return model_get_extra(m, vr, value);
}

ModelStatus model_set_real(ModelState *m, unsigned int vr, double value, char *message, size_t size)
{
    if (!isfinite(value)) {
        snprintf(message, size, "value reference %u: %g is not a finite number", vr, value);
        return MODEL_ERROR;
    }
    if (IN_GROUP(vr, VR_FIRST_INPUT, OPFMU_N_INPUTS)) {
        const unsigned int c = vr - VR_FIRST_INPUT;
        if (value < OPFMU_INPUT_MIN[c]) {
            snprintf(message, size, "%s = %g %s is below its lower bound %g %s", OPFMU_INPUT_NAMES[c], value,
                     OPFMU_INPUT_UNITS[c], OPFMU_INPUT_MIN[c], OPFMU_INPUT_UNITS[c]);
            return MODEL_ERROR;
        }
        m->u[c] = value;
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_START, OPFMU_N_STATES)) {
        m->x_start[vr - VR_FIRST_START] = value;
        return MODEL_OK;
    }
    return model_set_extra(m, vr, value, message, size);
}

void model_output_jacobian(const ModelState *m, double J[OPFMU_N_OUTPUTS * OPFMU_N_COLUMNS])
{
    component_output_jacobian(m->x, m->u, J);
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

int first_non_finite(const double *v, int n)
{
    for (int i = 0; i < n; ++i)
        if (!isfinite(v[i])) return i;
    return -1;
}

ModelStatus check_component_state(const ModelState *m, char *why, size_t size)
{
    int i;
    if (!isfinite(m->time)) {
        snprintf(why, size, "time %g is not a finite number", m->time);
        return MODEL_ERROR;
    }
    for (int c = 0; c < OPFMU_N_INPUTS; ++c) {
        if (!isfinite(m->u[c]) || m->u[c] < OPFMU_INPUT_MIN[c]) {
            snprintf(why, size, "input %s = %g %s is not a finite number at or above its lower bound %g %s",
                     OPFMU_INPUT_NAMES[c], m->u[c], OPFMU_INPUT_UNITS[c], OPFMU_INPUT_MIN[c], OPFMU_INPUT_UNITS[c]);
            return MODEL_ERROR;
        }
        if (!isfinite(m->du[c])) {
            snprintf(why, size, "the derivative of input %s: %g is not a finite number", OPFMU_INPUT_NAMES[c], m->du[c]);
            return MODEL_ERROR;
        }
    }
    if ((i = first_non_finite(m->x, OPFMU_N_STATES)) >= 0) {
        snprintf(why, size, "state %d: %g is not a finite number", i, m->x[i]);
        return MODEL_ERROR;
    }
    if ((i = first_non_finite(m->x_start, OPFMU_N_STATES)) >= 0) {
        snprintf(why, size, "initial state %d: %g is not a finite number", i, m->x_start[i]);
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

ModelStatus check_inputs_at_step_end(const ModelState *m, const double u_end[OPFMU_N_INPUTS], char *message,
                                     size_t size)
{
    for (int c = 0; c < OPFMU_N_INPUTS; ++c) {
        if (m->du[c] != 0.0 && (!isfinite(u_end[c]) || u_end[c] < OPFMU_INPUT_MIN[c])) {
            snprintf(message, size, "t = %.9g s: %s = %g %s with derivative %g %s/s reaches %g %s at the end of the "
                     "step, below its lower bound %g %s", m->time, OPFMU_INPUT_NAMES[c], m->u[c], OPFMU_INPUT_UNITS[c],
                     m->du[c], OPFMU_INPUT_UNITS[c], u_end[c], OPFMU_INPUT_UNITS[c], OPFMU_INPUT_MIN[c],
                     OPFMU_INPUT_UNITS[c]);
            return MODEL_ERROR;
        }
    }
    return MODEL_OK;
}

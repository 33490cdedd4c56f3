/* The component's variables of either native FMU, by value reference: its inputs, states, derived
   outputs, initial-state parameters and parameters (contiguous groups, from the generated
   variables.h, the model description's table), the kind of every Real, the checks of what may be
   written (a parameter: the rules that read it alone, model_check_parameters; the derived parameters
   follow it), the inputs' derivatives, and the check of the component's fields of a state. The model's own variables (those
   after the groups) are the model's: model_get_extra, model_set_extra.

   Where the FMU has the bus port's outputs (VR_FIRST_BUS: fmu_export.variables.BUS_OUTPUTS) they are
   computed here from the component's bus current and its exact derivatives: the Norton equivalent
   for the step to come, I = I_N + Y_N V with Y_N = d(I_re, I_im)/d(V_re, V_im) at the current state
   and inputs (the chain rule from the port's polar inputs: V_re = Vm cos(Va), V_im = Vm sin(Va)) and
   I_N = I - Y_N V, and the power into the bus P + jQ = V conj(I).

   Where the FMU starts from the load flow (OPFMU_SELF_START: fmu_export/self_start.py) its start
   parameters (V_lf, theta_lf, P_lf, Q_lf, <y>_init) and calculated parameters (<u>_init) are here too.
   component_settle_start solves the start from them (self_start.c) where the importer set a start
   parameter to another value than its default and no initial-state parameter <state>0 to another
   value than its own; else the FMU starts at the initial-state parameters (set, or built: the built
   rest). It solves when a
   variable is read in initialisation mode and when initialisation ends, again wherever anything was
   set since (a bus voltage input set by the importer keeps its value; one left unset takes V_lf,
   theta_lf).

   An input's lower bound is kept with a tolerance: a value at most BOUND_TOLERANCE max(1, |bound|)
   below it (a magnitude of -1e-12 pu from a host's round-off) is taken as the bound itself. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "model.h"
#include "variables.h"

static const unsigned char REAL_KINDS[VR_REAL_COUNT] = VR_REAL_KINDS;

#define BOUND_TOLERANCE 1e-6 /* [the input's unit] per unit of max(1, |bound|) */

/* value if it is at or above input c's lower bound, the bound if it lies within the tolerance
   below it; NAN (refused) if it is further below or not a number */
static double within_bound(int c, double value)
{
    const double bound = OPFMU_INPUT_MIN[c];
    if (value >= bound) return value;
    return value >= bound - BOUND_TOLERANCE * fmax(1.0, fabs(bound)) ? bound : NAN;
}

int model_real_kind(unsigned int vr)
{
    return vr < VR_REAL_COUNT ? (int)REAL_KINDS[vr] : -1;
}

/* the size of an array of the outputs' Jacobian: at least 1, as C requires */
#define JACOBIAN_SIZE (OPFMU_N_OUTPUTS > 0 ? OPFMU_N_OUTPUTS * OPFMU_N_COLUMNS : 1)

#ifdef VR_FIRST_BUS
#define VR_BUS_POWER (VR_FIRST_BUS + 6u) /* P_bus, then Q_bus: after the six Norton outputs */
#define MAGNITUDE_FLOOR 1e-9 /* [pu] the smallest voltage magnitude the admittance is evaluated at */

/* the bus voltage's real and imaginary part [pu] at the current inputs */
static void bus_voltage(const ModelState *m, double v[2])
{
    v[0] = m->u[BUS_VOLTAGE_MAGNITUDE] * cos(m->u[BUS_VOLTAGE_ANGLE]);
    v[1] = m->u[BUS_VOLTAGE_MAGNITUDE] * sin(m->u[BUS_VOLTAGE_ANGLE]);
}

/* the bus current's real and imaginary part [pu] at the current state and inputs */
static void bus_current(const ModelState *m, double i[2])
{
    model_get_real(m, VR_BUS_CURRENT_REAL, &i[0]);
    model_get_real(m, VR_BUS_CURRENT_IMAGINARY, &i[1]);
}

/* the bus port's outputs (BUS_OUTPUTS' order): I_N_re, I_N_im, Y_N_11, Y_N_12, Y_N_21, Y_N_22, P_bus,
   Q_bus. The current's derivatives with respect to the magnitude Vm and angle Va give, by the chain
   rule, d/dV_re = cos(Va) d/dVm - sin(Va)/Vm d/dVa and d/dV_im = sin(Va) d/dVm + cos(Va)/Vm d/dVa;
   they are taken at a magnitude of at least MAGNITUDE_FLOOR (the same for a current affine in V,
   whose admittance does not depend on V; for another, the limit as the magnitude falls to 0). */
static void bus_outputs(const ModelState *m, double out[BUS_N_OUTPUTS])
{
    double J[JACOBIAN_SIZE], u[OPFMU_N_INPUTS], v[2], i[2];
    const double c = cos(m->u[BUS_VOLTAGE_ANGLE]), s = sin(m->u[BUS_VOLTAGE_ANGLE]);
    memcpy(u, m->u, sizeof u);
    if (fabs(u[BUS_VOLTAGE_MAGNITUDE]) < MAGNITUDE_FLOOR) u[BUS_VOLTAGE_MAGNITUDE] = MAGNITUDE_FLOOR;
    component_output_jacobian(m->x, u, m->p, J);
    bus_voltage(m, v);
    bus_current(m, i);
    const unsigned int parts[2] = {VR_BUS_CURRENT_REAL, VR_BUS_CURRENT_IMAGINARY};
    for (int r = 0; r < 2; ++r) {
        const double by_magnitude = model_partial(m, J, parts[r], VR_FIRST_INPUT + BUS_VOLTAGE_MAGNITUDE);
        const double by_angle = model_partial(m, J, parts[r], VR_FIRST_INPUT + BUS_VOLTAGE_ANGLE)
                                / u[BUS_VOLTAGE_MAGNITUDE];
        double *y = &out[2 + 2 * r];
        y[0] = c * by_magnitude - s * by_angle;
        y[1] = s * by_magnitude + c * by_angle;
        out[r] = i[r] - y[0] * v[0] - y[1] * v[1];
    }
    out[6] = v[0] * i[0] + v[1] * i[1];
    out[7] = v[1] * i[0] - v[0] * i[1];
}

/* d (P_bus or Q_bus) / d input c, from the bus current's partial derivatives in J: P + jQ = V conj(I) */
static double bus_power_partial(const ModelState *m, const double J[], unsigned int unknown, unsigned int known)
{
    const int c = (int)(known - VR_FIRST_INPUT);
    const double vm = m->u[BUS_VOLTAGE_MAGNITUDE], va = m->u[BUS_VOLTAGE_ANGLE];
    const double dv_re = c == BUS_VOLTAGE_MAGNITUDE ? cos(va) : c == BUS_VOLTAGE_ANGLE ? -vm * sin(va) : 0.0;
    const double dv_im = c == BUS_VOLTAGE_MAGNITUDE ? sin(va) : c == BUS_VOLTAGE_ANGLE ? vm * cos(va) : 0.0;
    const double di_re = model_partial(m, J, VR_BUS_CURRENT_REAL, known);
    const double di_im = model_partial(m, J, VR_BUS_CURRENT_IMAGINARY, known);
    double v[2], i[2];
    bus_voltage(m, v);
    bus_current(m, i);
    if (unknown == VR_BUS_POWER) return dv_re * i[0] + v[0] * di_re + dv_im * i[1] + v[1] * di_im;
    return dv_im * i[0] + v[1] * di_re - dv_re * i[1] - v[0] * di_im;
}
#endif

double model_partial(const ModelState *m, const double J[], unsigned int unknown, unsigned int known)
{
    (void)m;
    if (IN_GROUP(unknown, VR_FIRST_OUTPUT, OPFMU_N_OUTPUTS))
        return J[(unknown - VR_FIRST_OUTPUT) * OPFMU_N_COLUMNS + OPFMU_N_STATES + (known - VR_FIRST_INPUT)];
#ifdef VR_FIRST_BUS
    if (IN_GROUP(unknown, VR_BUS_POWER, 2)) return bus_power_partial(m, J, unknown, known);
#endif
    return 0.0;
}

int model_partials_from_jacobian(unsigned int vr)
{
#ifdef VR_FIRST_BUS
    if (IN_GROUP(vr, VR_BUS_POWER, 2)) return 1;
#endif
    return IN_GROUP(vr, VR_FIRST_OUTPUT, OPFMU_N_OUTPUTS);
}

const char *component_no_derivative(unsigned int vr)
{
#ifdef VR_FIRST_BUS
    if (IN_GROUP(vr, VR_FIRST_BUS, 6))
        return "the Norton equivalent is itself the derivative of the bus current: its own derivatives (second "
               "derivatives of the current) are not provided";
#endif
    (void)vr;
    return NULL;
}

void component_defaults(ModelState *m)
{
    memset(m, 0, sizeof *m);
    memcpy(m->u, OPFMU_START_U, sizeof m->u);
    memcpy(m->x_start, OPFMU_DEFAULT_X0, sizeof m->x_start);
    memcpy(m->x, m->x_start, sizeof m->x);
    memcpy(m->p, OPFMU_PARAM_START, OPFMU_N_PARAMS * sizeof *m->p);
    model_derive(m->p);
#ifdef OPFMU_SELF_START
    memcpy(m->start.flow, SELF_START_FLOW_DEFAULT, sizeof m->start.flow);
    memcpy(m->start.delivered, SELF_START_DELIVER_DEFAULT, sizeof m->start.delivered);
    for (int k = 0; k < SELF_START_N_SOLVES; ++k) m->start.solved[k] = OPFMU_START_U[SELF_START_SOLVES[k]];
#endif
}

ModelStatus component_settle_start(ModelState *m, char *why, size_t size)
{
#ifdef OPFMU_SELF_START
    /* start at x_start unless the importer set a start parameter off its default and no initial state
       other than the built one */
    if (memcmp(m->x_start, OPFMU_DEFAULT_X0, sizeof m->x_start)
        || (!memcmp(m->start.flow, SELF_START_FLOW_DEFAULT, sizeof m->start.flow)
            && !memcmp(m->start.delivered, SELF_START_DELIVER_DEFAULT, sizeof m->start.delivered))) {
        m->start.in_x = 0;
        return MODEL_OK;
    }
    if (m->start.stale || !m->start.in_x) {
        if (self_start_solve(m, why, size) != MODEL_OK) return MODEL_ERROR;
        m->start.stale = 0;
        m->start.in_x = 1;
    }
#else
    (void)m;
    (void)why;
    (void)size;
#endif
    return MODEL_OK;
}

ModelStatus component_initial_state(ModelState *m, char *why, size_t size)
{
    if (component_settle_start(m, why, size) != MODEL_OK) return MODEL_ERROR;
#ifdef OPFMU_SELF_START
    if (m->start.in_x) return MODEL_OK; /* x holds the solved start */
#endif
    memcpy(m->x, m->x_start, sizeof m->x);
    return MODEL_OK;
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
        model_outputs(m->x, m->u, m->p, y);
        *value = y[vr - VR_FIRST_OUTPUT];
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_START, OPFMU_N_STATES)) {
        *value = m->x_start[vr - VR_FIRST_START];
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_PARAM, OPFMU_N_PARAMS)) {
        *value = m->p[vr - VR_FIRST_PARAM];
        return MODEL_OK;
    }
#ifdef VR_FIRST_BUS
    if (IN_GROUP(vr, VR_FIRST_BUS, BUS_N_OUTPUTS)) {
        double out[BUS_N_OUTPUTS];
        bus_outputs(m, out);
        *value = out[vr - VR_FIRST_BUS];
        return MODEL_OK;
    }
#endif
#ifdef OPFMU_SELF_START
    if (IN_GROUP(vr, VR_FIRST_FLOW, 4 * SELF_START_LOAD_FLOW)) {
        *value = m->start.flow[vr - VR_FIRST_FLOW];
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_DELIVERED, SELF_START_N_DELIVERS)) {
        *value = m->start.delivered[vr - VR_FIRST_DELIVERED];
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_SOLVED, SELF_START_N_SOLVES)) {
        *value = m->start.solved[vr - VR_FIRST_SOLVED];
        return MODEL_OK;
    }
#endif
    return model_get_extra(m, vr, value);
}

static ModelStatus set_real(ModelState *m, unsigned int vr, double value, char *message, size_t size)
{
    if (!isfinite(value)) {
        snprintf(message, size, "value reference %u: %g is not a finite number", vr, value);
        return MODEL_ERROR;
    }
    if (IN_GROUP(vr, VR_FIRST_INPUT, OPFMU_N_INPUTS)) {
        const unsigned int c = vr - VR_FIRST_INPUT;
        const double kept = within_bound((int)c, value);
        if (isnan(kept)) {
            snprintf(message, size, "%s = %g %s is below its lower bound %g %s", OPFMU_INPUT_NAMES[c], value,
                     OPFMU_INPUT_UNITS[c], OPFMU_INPUT_MIN[c], OPFMU_INPUT_UNITS[c]);
            return MODEL_ERROR;
        }
        m->u[c] = kept;
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_START, OPFMU_N_STATES)) {
        m->x_start[vr - VR_FIRST_START] = value;
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_PARAM, OPFMU_N_PARAMS)) { /* checked on a copy: a refused value changes nothing */
        double p[OPFMU_P_SIZE];
        const int i = (int)(vr - VR_FIRST_PARAM);
        memcpy(p, m->p, sizeof p);
        p[i] = value;
        model_derive(p);
        if (model_check_parameters(p, i, message, size) != MODEL_OK) return MODEL_ERROR;
        memcpy(m->p, p, sizeof p);
        return MODEL_OK;
    }
#ifdef OPFMU_SELF_START
    if (IN_GROUP(vr, VR_FIRST_FLOW, 4 * SELF_START_LOAD_FLOW)) {
        m->start.flow[vr - VR_FIRST_FLOW] = value;
        return MODEL_OK;
    }
    if (IN_GROUP(vr, VR_FIRST_DELIVERED, SELF_START_N_DELIVERS)) {
        m->start.delivered[vr - VR_FIRST_DELIVERED] = value;
        return MODEL_OK;
    }
#endif
    return model_set_extra(m, vr, value, message, size);
}

ModelStatus model_set_real(ModelState *m, unsigned int vr, double value, char *message, size_t size)
{
    if (set_real(m, vr, value, message, size) != MODEL_OK) return MODEL_ERROR;
#ifdef OPFMU_SELF_START
    m->start.stale = 1;
#if SELF_START_LOAD_FLOW
    if (vr == VR_FIRST_INPUT + BUS_VOLTAGE_MAGNITUDE || vr == VR_FIRST_INPUT + BUS_VOLTAGE_ANGLE) m->start.bus_voltage_set = 1;
#endif
#endif
    return MODEL_OK;
}



void model_output_jacobian(const ModelState *m, double J[OPFMU_N_OUTPUTS * OPFMU_N_COLUMNS])
{
    component_output_jacobian(m->x, m->u, m->p, J);
}

ModelStatus model_set_input_derivative(ModelState *m, unsigned int c, int order, double value, char *message,
                                       size_t size)
{
    if (!isfinite(value)) {
        snprintf(message, size, "the derivative of %s: %g is not a finite number", OPFMU_INPUT_NAMES[c], value);
        return MODEL_ERROR;
    }
#if OPFMU_INPUT_ORDER > 1
    if (order == 2) {
        m->d2u[c] = value;
        return MODEL_OK;
    }
#else
    (void)order;
#endif
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
#if OPFMU_INPUT_ORDER > 1
        if (!isfinite(m->d2u[c])) {
            snprintf(why, size, "the second derivative of input %s: %g is not a finite number", OPFMU_INPUT_NAMES[c],
                     m->d2u[c]);
            return MODEL_ERROR;
        }
#endif
    }
    if ((i = first_non_finite(m->x, OPFMU_N_STATES)) >= 0) {
        snprintf(why, size, "state %d: %g is not a finite number", i, m->x[i]);
        return MODEL_ERROR;
    }
    if ((i = first_non_finite(m->x_start, OPFMU_N_STATES)) >= 0) {
        snprintf(why, size, "initial state %d: %g is not a finite number", i, m->x_start[i]);
        return MODEL_ERROR;
    }
    if ((i = first_non_finite(m->p, OPFMU_N_PARAMS)) >= 0) {
        snprintf(why, size, "parameter %s: %g is not a finite number", OPFMU_PARAM_NAMES[i], m->p[i]);
        return MODEL_ERROR;
    }
#ifdef OPFMU_SELF_START
    if (first_non_finite(m->start.flow, 4) >= 0 || first_non_finite(m->start.delivered, SELF_START_N_DELIVERS) >= 0
        || first_non_finite(m->start.solved, SELF_START_N_SOLVES) >= 0) {
        snprintf(why, size, "a start parameter is not a finite number");
        return MODEL_ERROR;
    }
    if ((m->start.in_x != 0 && m->start.in_x != 1) || (m->start.stale != 0 && m->start.stale != 1)
        || (m->start.bus_voltage_set != 0 && m->start.bus_voltage_set != 1)) {
        snprintf(why, size, "the start's flags %d, %d, %d are not 0 or 1", m->start.in_x, m->start.stale,
                 m->start.bus_voltage_set);
        return MODEL_ERROR;
    }
#endif
    double p[OPFMU_P_SIZE];
    memcpy(p, m->p, sizeof p);
    model_derive(p);
    if (memcmp(p, m->p, sizeof p)) {
        snprintf(why, size, "the derived parameters are not those of the parameters");
        return MODEL_ERROR;
    }
    return model_check_parameters(m->p, -1, why, size);
}

ModelStatus check_inputs_at_step_end(const ModelState *m, double u_end[OPFMU_N_INPUTS], char *message, size_t size)
{
    for (int c = 0; c < OPFMU_N_INPUTS; ++c) {
#if OPFMU_INPUT_ORDER > 1
        if (m->du[c] == 0.0 && m->d2u[c] == 0.0) continue;
#else
        if (m->du[c] == 0.0) continue;
#endif
        const double kept = within_bound(c, u_end[c]);
        if (isfinite(kept)) {
            u_end[c] = kept;
            continue;
        }
        snprintf(message, size, "t = %.9g s: %s = %g %s with derivative %g %s/s reaches %g %s at the end of the step, "
                 "below its lower bound %g %s", m->time, OPFMU_INPUT_NAMES[c], m->u[c], OPFMU_INPUT_UNITS[c], m->du[c],
                 OPFMU_INPUT_UNITS[c], u_end[c], OPFMU_INPUT_UNITS[c], OPFMU_INPUT_MIN[c], OPFMU_INPUT_UNITS[c]);
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

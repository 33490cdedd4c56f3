/* The surrogate's window-and-sensor engine: the operator evaluated from a buffer of input sensors
   (docs/fmu.md, "The surrogate FMU"), for any component with the sizes of config.h.

   A window starts at (window_start, x_window). The input over a step is written into every sensor
   slot from the current time on: held, or, where the master set its derivative du
   (fmi2SetRealInputDerivatives, canInterpolateInputs), the ramp u(t) + du (s - t) in the slots the
   step covers; slots not yet known hold the latest value, the one at t + h. The state at t + h is
   the operator at t + h - window_start, corrected (corrections.c, with the input at the start and
   at the end of the step where it uses both). When a window's horizon is reached, a new one starts
   from the state there; a step that crosses the horizon is split at it, and a ramp goes on in the
   new window from its value there. An input change above restart_jump starts a new window at once:
   the step's input against the value the previous one ended at (a ramp carried on is no jump).
   After a step the inputs are those at t + h and their derivatives stay set (as the native
   reference FMU's). With every derivative 0 each step is what it is without them, bit for bit.

   The window frame (reference_models/drift.py): for a component with a drift symmetry the operator
   learned its windows in their own frame, which turns with the window's start: the first angle
   input at the window start is the angle origin a and the speed state there is the frame's speed c.
   The engine keeps the state raw and the operator's view in the frame: the sensors hold u - a R -
   c (R tau + T), held inputs ramp in the frame over their step (a held angle stands still while the
   frame turns) and hold their last value in the frame after it, and the operator's states come back
   as x_f + (shift + c tau) A + c W. Angles and speeds that drifted with a network thus reach the
   network only as what it was trained on. The frame tables are zeros for other components. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "engine.h"

void model_defaults(ModelState *m)
{
    component_defaults(m);
    m->rollover_horizon = OPFMU_ROLLOVER_HORIZON;
    m->residual_limit = OPFMU_RESIDUAL_LIMIT;
    m->restart_jump = OPFMU_RESTART_JUMP;
    m->rest_radius = OPFMU_REST_RADIUS;
    m->slow_weight = OPFMU_SLOW_WEIGHT;
    m->swing_weight = OPFMU_SWING_WEIGHT;
    memcpy(m->x_operator, m->x, sizeof m->x);
    m->in_envelope = 1;
}

void input_after(const ModelState *m, const double u0[N_U], double dt, double u[N_U])
{
    for (int c = 0; c < N_U; ++c) u[c] = m->du[c] != 0.0 ? u0[c] + m->du[c] * dt : u0[c];
}

static int any_nonzero(const double v[N_U])
{
    for (int c = 0; c < N_U; ++c)
        if (v[c] != 0.0) return 1;
    return 0;
}

#if OPFMU_FIRST_LAYER > 0
/* sum over slots k0 <= k < k1 of the sensor layer's slope along the frame's input ramp R times
   min(s_k, tau): what the ramp of a held input in the frame adds to z */
static void ramp_sum(int k0, int k1, double tau, double out[OPFMU_FIRST_LAYER])
{
    long knee = (long)ceil(tau / SENSOR_DT - 1e-6);
    int mid = knee < k0 ? k0 : (knee > k1 ? k1 : (int)knee);
    for (int h = 0; h < OPFMU_FIRST_LAYER; ++h) {
        double flat = 0.0; /* slots from `mid` on see tau itself */
        for (int c = 0; c < N_U; ++c)
            if (OPFMU_FRAME_INPUT_RATES[c] != 0.0)
                flat += OPFMU_FRAME_INPUT_RATES[c] * OPFMU_FRAME_SPEED_SCALE * (SUFFIX(mid, c, h) - SUFFIX(k1, c, h));
        out[h] = RAMP_SUFFIX(k0, h) - RAMP_SUFFIX(mid, h) + tau * flat;
    }
}

/* what inputs ramping at du from window time tau0 to tau1 (and holding their value there after it)
   add to z in slots k0 <= k < k1 beyond their value at tau0: the sum over those slots and the
   inputs of du_c slope_{k,c} (min(s_k, tau1) - tau0) */
static void input_ramp_sum(int k0, int k1, double tau0, double tau1, const double du[N_U],
                           double out[OPFMU_FIRST_LAYER])
{
    long knee = (long)ceil(tau1 / SENSOR_DT - 1e-6);
    int mid = knee < k0 ? k0 : (knee > k1 ? k1 : (int)knee);
    for (int h = 0; h < OPFMU_FIRST_LAYER; ++h) {
        double sum = 0.0;
        for (int c = 0; c < N_U; ++c)
            if (du[c] != 0.0)
                sum += du[c] * (TIME_SUFFIX(k0, c, h) - TIME_SUFFIX(mid, c, h) + tau1 * (SUFFIX(mid, c, h) - SUFFIX(k1, c, h))
                                - tau0 * (SUFFIX(k0, c, h) - SUFFIX(k1, c, h)));
        out[h] = sum;
    }
}
#endif

#if OPFMU_TRUNK_SIZE > 0
/* The sensor slot window time tau is on, or -1 when it lies between sensor times. */
static long sensor_slot(double tau)
{
    double slot = tau / SENSOR_DT;
    long k = lround(slot);
    return k >= 0 && k < OPFMU_N_SENSORS && fabs(slot - (double)k) <= 1e-6 ? k : -1;
}

/* The trunk values at window time tau: those kept for the sensor time tau is on, if any, else
   computed into `scratch`. */
static const double *trunk_seen(const ModelState *m, double tau, double scratch[OPFMU_TRUNK_SIZE])
{
    long k = sensor_slot(tau);
    if (k >= 0 && m->trunk_ready[k])
        return m->trunk + k * OPFMU_TRUNK_SIZE;
    opfmu_trunk(tau, scratch);
    return scratch;
}

/* The trunk values at window time tau: kept per sensor time (a step that ends on the sensor grid, as
   steps of whole milliseconds do, reuses them), computed into `scratch` for any other time. */
static const double *trunk_at(ModelState *m, double tau, double scratch[OPFMU_TRUNK_SIZE])
{
    long k = sensor_slot(tau);
    if (k < 0) {
        opfmu_trunk(tau, scratch);
        return scratch;
    }
    if (!m->trunk_ready[k]) {
        opfmu_trunk((double)k * SENSOR_DT, m->trunk + k * OPFMU_TRUNK_SIZE);
        m->trunk_ready[k] = 1;
    }
    return m->trunk + k * OPFMU_TRUNK_SIZE;
}

/* d x/dt of the operator at window time tau with the coefficients of the last evaluation, by a
   central difference over one sensor interval (one-sided at the ends): two products with kept trunk
   values, not two network evaluations */
static void operator_rate(const ModelState *m, double tau, double rate[N_X])
{
    double lo = fmax(tau - SENSOR_DT, 0.0), hi = fmin(tau + SENSOR_DT, OPFMU_HORIZON);
    double a[N_X], b[N_X], scratch_lo[OPFMU_TRUNK_SIZE], scratch_hi[OPFMU_TRUNK_SIZE];
    const double *basis_lo = trunk_seen(m, lo, scratch_lo), *basis_hi = trunk_seen(m, hi, scratch_hi);
    opfmu_head(m->coef, basis_lo, a);
    opfmu_head(m->coef, basis_hi, b);
    for (int i = 0; i < N_X; ++i) rate[i] = (b[i] - a[i]) / (hi - lo) + m->frame.c * OPFMU_FRAME_SPEED_SCALE * OPFMU_FRAME_ANGLES[i];
    if (m->rest_weight > 0.0) /* the rest correction moves with window time too */
        rest_correct_rate(m, basis_lo, basis_hi, hi - lo, rate);
}

#else
/* d x/dt of the operator at window time tau, by a central difference (one-sided at the ends) */
static void operator_rate(const ModelState *m, double tau, double rate[N_X])
{
    const double d = 1e-4;
    double lo = fmax(tau - d, 0.0), hi = fmin(tau + d, OPFMU_HORIZON);
    double a[N_X], b[N_X];
    opfmu_operator(m->x_window_f, m->sensors, lo, a);
    opfmu_operator(m->x_window_f, m->sensors, hi, b);
    for (int i = 0; i < N_X; ++i) rate[i] = (b[i] - a[i]) / (hi - lo) + m->frame.c * OPFMU_FRAME_SPEED_SCALE * OPFMU_FRAME_ANGLES[i];
}
#endif

/* The operator's rate against f at its own state (before the exact step of the affine states, which
   would hide the operator's error there: the residual_limit was set on the operator alone) */
double window_residual(const ModelState *m)
{
    double rate[N_X], f[N_X], sum = 0.0;
    operator_rate(m, m->time - m->window_start, rate);
    model_derivatives(m->x_operator, m->u, TRAINED_P, f);
    if (m->slow_on) { /* the slow coordinate moves at l . f (slow_weight of it) */
        double shift = m->slow_weight * (dot(m->slow_left, f) - dot(m->slow_left, rate));
        for (int i = 0; i < N_X; ++i) rate[i] += shift * m->slow_right[i];
    }
    int known = 0;
    for (int i = 0; i < N_X; ++i) {
        if (OPFMU_RESIDUAL_SCALE[i] == 0.0) continue; /* a learned rate: no equation to hold it to */
        double r = (rate[i] - f[i]) / OPFMU_RESIDUAL_SCALE[i];
        sum += r * r;
        ++known;
    }
    return known > 0 ? sqrt(sum / (double)known) : 0.0;
}

static int outside(const double *v, const double *lo, const double *hi, int n)
{
    for (int i = 0; i < n; ++i)
        if (v[i] < lo[i] - 1e-6 || v[i] > hi[i] + 1e-6) return 1;
    return 0;
}

/* appends text, or one number in a printf format, at message + *used, never past size */
static void append(char *message, size_t size, size_t *used, const char *text)
{
    if (*used >= size) return;
    int n = snprintf(message + *used, size - *used, "%s", text);
    if (n > 0) *used += (size_t)n;
}

static void append_number(char *message, size_t size, size_t *used, const char *format, double value)
{
    char text[64];
    snprintf(text, sizeof text, format, value);
    append(message, size, used, text);
}

/* Checks a window start state and the input over the next h seconds (at their start and end, or the
   window's end if that comes first) against the envelope, in the window frame (sticky flag). */
static ModelStatus check_envelope(ModelState *m, double h, char *message, size_t size)
{
    size_t used = 0;
    double tau = m->time - m->window_start, u_start[N_U], u_end[N_U], u_last[N_U];
    if (!m->in_envelope) return MODEL_OK;
    const double tau_end = fmin(tau + h, m->rollover_horizon);
    input_in_frame(&m->frame, m->u, tau, u_start);
    input_after(m, m->u, tau_end - tau, u_last);
    input_in_frame(&m->frame, u_last, tau_end, u_end);
    if (outside(u_start, OPFMU_ENV_U_MIN, OPFMU_ENV_U_MAX, N_U) || outside(u_end, OPFMU_ENV_U_MIN, OPFMU_ENV_U_MAX, N_U)) {
        m->in_envelope = 0;
        append_number(message, size, &used, "t = %.6g s: input (", m->time);
        for (int c = 0; c < N_U; ++c) {
            append(message, size, &used, c ? ", " : "");
            append(message, size, &used, OPFMU_INPUT_NAMES[c]);
            append_number(message, size, &used, " %.4g ", u_start[c]);
            append(message, size, &used, OPFMU_INPUT_UNITS[c]);
        }
        append(message, size, &used, OPFMU_FRAME ? ", in the window frame) left the trained envelope (" : ") left the trained envelope (");
        for (int c = 0; c < N_U; ++c) {
            append(message, size, &used, c ? ", " : "");
            append(message, size, &used, OPFMU_INPUT_NAMES[c]);
            append_number(message, size, &used, " [%.4g, ", OPFMU_ENV_U_MIN[c]);
            append_number(message, size, &used, "%.4g]", OPFMU_ENV_U_MAX[c]);
        }
        append(message, size, &used, "); results are extrapolated");
        return MODEL_WARNING;
    }
    if (outside(m->x_window_f, OPFMU_ENV_X0_MIN, OPFMU_ENV_X0_MAX, N_X)) {
        m->in_envelope = 0;
        append_number(message, size, &used, "t = %.6g s: window start state (", m->window_start);
        for (int i = 0; i < N_X; ++i) append_number(message, size, &used, i ? ", %.4g" : "%.4g", m->x_window_f[i]);
        if (OPFMU_FRAME) append(message, size, &used, " in the window frame");
        append(message, size, &used, ") left the trained envelope; results are extrapolated");
        return MODEL_WARNING;
    }
    return MODEL_OK;
}

static void start_window(ModelState *m)
{
    double level[N_U];
    m->window_start = m->time;
    memcpy(m->x_window, m->x, sizeof m->x);
    memcpy(m->x_operator, m->x, sizeof m->x); /* an anchored operator starts from the window's state */
    m->frame = window_frame(m->x, m->u);
    state_in_frame(&m->frame, m->x_window, 0.0, m->x_window_f);
    input_in_frame(&m->frame, m->u, 0.0, level);
    for (int k = 0; k < OPFMU_N_SENSORS; ++k) memcpy(m->sensors + k * N_U, level, sizeof level);
    m->filled = 0;
    m->last_start = m->last_end = 0.0;
    memcpy(m->last_u, m->u, sizeof m->u);
    memset(m->last_du, 0, sizeof m->last_du); /* every slot holds the level */
#if OPFMU_FIRST_LAYER > 0
    first_layer_base(m->x_window_f, m->z_base);
    memset(m->z_past, 0, sizeof m->z_past);
#endif
#if OPFMU_TRUNK_SIZE > 0
    held_coefficients(m->x_window_f, m->z_base, level, m->coef); /* so the residual at the window start is the new window's */
#endif
    start_corrections(m, 1);
}

/* The operator at window time tau after the input over a step from window time tau0 to tau was
   written from slot `first` on (in the frame: its level, ramping with the frame and along its
   derivatives until tau, then held). Per step this costs the network after its sensor layer plus
   O(layer width), not the whole sensor layer. */
static void evaluate(ModelState *m, int first, double tau0, double tau)
{
    double level[N_U], x_f[N_X]; /* the step's input in the frame at window time 0 (its ramps apart) */
    input_in_frame(&m->frame, m->u, 0.0, level);
    const int ramps = any_nonzero(m->du), ramped = any_nonzero(m->last_du);
    (void)ramps; /* unused by a kernel without a sensor layer or a trunk */
    (void)ramped;
    /* a held input equal to the held one the slots from `filled` on hold leaves the sensors as they
       were (unless the frame turns: its ramp goes on), so the coefficients of the last evaluation (or
       of the window's start) are still those of this window: a step costs a product with the trunk values */
#if OPFMU_TRUNK_SIZE > 0
    const int sensors_changed = memcmp(m->u, m->last_u, sizeof m->u) != 0 || m->frame.c != 0.0 || ramps || ramped;
#else
    const int sensors_changed = 1; /* z is computed anew each step */
#endif
#if OPFMU_TRUNK_SIZE == 0 /* the sensors themselves: for the kernel and its rate (residual) */
    if (sensors_changed)
        for (int k = first; k < OPFMU_N_SENSORS; ++k) {
            const double s = fmin((double)k * SENSOR_DT, tau);
            double u[N_U];
            input_after(m, m->u, s - tau0, u);
            input_in_frame(&m->frame, u, s, m->sensors + k * N_U);
        }
#endif
#if OPFMU_FIRST_LAYER > 0
    double z[OPFMU_FIRST_LAYER], ramp[OPFMU_FIRST_LAYER];
    if (sensors_changed) {
        if (first > m->filled) { /* slots [filled, first) keep what the last step wrote */
            double last_level[N_U];
            input_in_frame(&m->frame, m->last_u, 0.0, last_level);
            for (int h = 0; h < OPFMU_FIRST_LAYER; ++h)
                for (int c = 0; c < N_U; ++c)
                    m->z_past[h] += (SUFFIX(m->filled, c, h) - SUFFIX(first, c, h)) * last_level[c];
            if (m->frame.c != 0.0) {
                ramp_sum(m->filled, first, m->last_end, ramp);
                for (int h = 0; h < OPFMU_FIRST_LAYER; ++h) m->z_past[h] -= m->frame.c * ramp[h];
            }
            if (ramped) {
                input_ramp_sum(m->filled, first, m->last_start, m->last_end, m->last_du, ramp);
                for (int h = 0; h < OPFMU_FIRST_LAYER; ++h) m->z_past[h] += ramp[h];
            }
            m->filled = first;
        }
        for (int h = 0; h < OPFMU_FIRST_LAYER; ++h) {
            double sum = m->z_base[h] + m->z_past[h];
            for (int c = 0; c < N_U; ++c) sum += SUFFIX(first, c, h) * level[c];
            z[h] = sum;
        }
        if (m->frame.c != 0.0) {
            ramp_sum(first, OPFMU_N_SENSORS, tau, ramp);
            for (int h = 0; h < OPFMU_FIRST_LAYER; ++h) z[h] -= m->frame.c * ramp[h];
        }
        if (ramps) {
            input_ramp_sum(first, OPFMU_N_SENSORS, tau0, tau, m->du, ramp);
            for (int h = 0; h < OPFMU_FIRST_LAYER; ++h) z[h] += ramp[h];
        }
    }
#if OPFMU_TRUNK_SIZE > 0
    double scratch[OPFMU_TRUNK_SIZE];
    const double *basis = trunk_at(m, tau, scratch);
    if (sensors_changed) opfmu_coefficients(m->x_window_f, z, m->coef);
    opfmu_head(m->coef, basis, x_f);
    if (m->rest_weight > 0.0) rest_correct(m, basis, x_f);
#else
    opfmu_from_first_layer(m->x_window_f, z, tau, x_f);
#endif
#else
    opfmu_operator(m->x_window_f, m->sensors, tau, x_f);
#endif
    state_from_frame(&m->frame, x_f, tau, m->x);
    memcpy(m->last_u, m->u, sizeof m->u);
    memcpy(m->last_du, m->du, sizeof m->du);
    m->last_start = tau0;
    m->last_end = tau;
}

ModelStatus model_initialize(ModelState *m, double start_time, char *message, size_t size)
{
    if (component_initial_state(m, message, size) != MODEL_OK) return MODEL_ERROR;
    m->time = start_time;
    m->in_envelope = 1;
    m->input_time = start_time;
    memcpy(m->prev_end_u, m->u, sizeof m->u);
    memset(m->prev_du, 0, sizeof m->prev_du);
    start_window(m);
    return check_envelope(m, 0.0, message, size);
}

/* an input differs from the one the previous step ended at by more than restart_jump: a held one
   with both seen in the window frame at the times they were set (an angle a master advances with a
   network turning at the frame's speed does not jump), a ramped one against its value at the end of
   its ramp (a ramp carried on does not jump) */
static int input_jumped(const ModelState *m)
{
    for (int c = 0; c < N_U; ++c) {
        double turned = m->prev_du[c] != 0.0 ? 0.0
                        : m->frame.c * OPFMU_FRAME_INPUT_RATES[c] * OPFMU_FRAME_SPEED_SCALE * (m->time - m->input_time);
        if (fabs(m->u[c] - m->prev_end_u[c] - turned) > m->restart_jump) return 1;
    }
    return 0;
}

ModelStatus model_do_step(ModelState *m, double h, char *message, size_t size)
{
    const double start = m->time, stop = m->time + h;
    double u_start[N_U], u_stop[N_U]; /* the inputs at the step's start and end */
    memcpy(u_start, m->u, sizeof u_start);
    input_after(m, u_start, h, u_stop);
    if (check_inputs_at_step_end(m, u_stop, message, size) != MODEL_OK) return MODEL_ERROR;
    /* an input jump starts a new window here, so the jump is at window time 0, where the operator
       learned its transients (every training window starts with one) */
    if (m->restart_jump > 0.0 && m->time > m->window_start + TIME_EPS && input_jumped(m))
        start_window(m);
    /* a window that has not run yet starts from the input held over its first step: its frame's
       origin is that input's angle (theta_f(0) = 0, as in every training window) */
    if (m->time < m->window_start + TIME_EPS && memcmp(m->u, m->last_u, sizeof m->u) != 0)
        start_window(m);
    m->input_time = m->time;
    ModelStatus status = check_envelope(m, h, message, size);
    while (m->time < stop - TIME_EPS) {
        double window_end = m->window_start + m->rollover_horizon;
        double end = fmin(stop, window_end);
        if (!(end > m->time)) { /* at this time a double cannot resolve the rollover horizon: no progress */
            snprintf(message, size, "t = %.9g s: the window's end %.9g s is not after the current time (a double does "
                     "not resolve the rollover horizon %g s at this time)", m->time, window_end, m->rollover_horizon);
            return MODEL_ERROR;
        }
        /* the input from the current time on (m->u: its value now): the first slot at or after m->time */
        int first = (int)ceil((m->time - m->window_start) / SENSOR_DT - 1e-6);
        if (m->time < m->window_start + TIME_EPS)
            start_corrections(m, 0); /* for the input at the start of the window's first step */
        double rate_start = m->slow_on ? slow_rate(m, m->x) : 0.0;
        double x_step[N_X], g_start[N_AFFINE_CAP], k_start[N_AFFINE_CAP];
        memcpy(x_step, m->x, sizeof x_step);
        if (m->swing_weight > 0.0) affine_drive(m->x, m->u, g_start, k_start);
        first = first < 0 ? 0 : (first > OPFMU_N_SENSORS ? OPFMU_N_SENSORS : first);
        evaluate(m, first, m->time - m->window_start, fmin(end - m->window_start, OPFMU_HORIZON));
        if (end < stop) /* the input at the end of this part: the corrections' end values, a new window's start */
            input_after(m, u_start, end - start, m->u);
        else
            memcpy(m->u, u_stop, sizeof m->u);
        if (m->slow_on) slow_correct(m, end - m->time, rate_start);
        memcpy(m->x_operator, m->x, sizeof m->x);
        if (m->swing_weight > 0.0) affine_step(m, x_step, g_start, k_start, end - m->time);
        m->time = end;
        for (int i = 0; i < N_X; ++i) {
            if (!isfinite(m->x[i])) {
                snprintf(message, size, "t = %.6g s: the operator returned a non-finite state", m->time);
                return MODEL_ERROR;
            }
        }
        if (m->time >= window_end - TIME_EPS) {
            start_window(m);
            if (status == MODEL_OK) status = check_envelope(m, stop - m->time, message, size);
        }
    }
    m->time = stop;
    memcpy(m->u, u_stop, sizeof m->u); /* the inputs at the new communication point */
    memcpy(m->prev_end_u, m->u, sizeof m->u);
    memcpy(m->prev_du, m->du, sizeof m->du);
    if (m->residual_limit > 0.0) {
#if OPFMU_TRUNK_SIZE > 0
        double tau = m->time - m->window_start, scratch[OPFMU_TRUNK_SIZE]; /* keep the trunk values the rate needs */
        trunk_at(m, fmax(tau - SENSOR_DT, 0.0), scratch);
        trunk_at(m, fmin(tau + SENSOR_DT, OPFMU_HORIZON), scratch);
#endif
        double r = window_residual(m);
        if (r > m->residual_limit && !m->residual_alarm) {
            m->residual_alarm = 1;
            if (status == MODEL_OK) {
                snprintf(message, size, "t = %.6g s: physics residual %.3g exceeds residual_limit %.3g: the surrogate "
                         "is likely leaving the reference here (an input or state it was not trained for)",
                         m->time, r, m->residual_limit);
                status = MODEL_WARNING;
            }
        } else if (r < 0.5 * m->residual_limit) {
            m->residual_alarm = 0; /* warn again at the next excursion */
        }
    }
    return status;
}

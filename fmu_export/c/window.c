/* The surrogate's window-and-sensor engine: the operator evaluated from a buffer of input sensors
   (DESIGN section 5), for any component with the sizes of config.h.

   A window starts at (window_start, x_window). The input held over a step is written into every
   sensor slot from the current time on (slots not yet known hold the latest value), and the state
   at t + h is the operator at t + h - window_start, corrected (corrections.c). When a window's
   horizon is reached, a new one starts from the state there; a step that crosses the horizon is
   split at it. An input change above restart_jump starts a new window at once. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "engine.h"

#if OPFMU_FIRST_LAYER > 0
static const double ZERO_SENSORS[N_U * OPFMU_N_SENSORS];
#endif

void model_defaults(ModelState *m)
{
    memset(m, 0, sizeof *m);
    memcpy(m->u, OPFMU_START_U, sizeof m->u);
    memcpy(m->x_start, OPFMU_DEFAULT_X0, sizeof m->x_start);
    m->rollover_horizon = OPFMU_ROLLOVER_HORIZON;
    m->residual_limit = OPFMU_RESIDUAL_LIMIT;
    m->restart_jump = OPFMU_RESTART_JUMP;
    m->rest_radius = OPFMU_REST_RADIUS;
    m->slow_weight = OPFMU_SLOW_WEIGHT;
    m->swing_weight = OPFMU_SWING_WEIGHT;
    memcpy(m->x, m->x_start, sizeof m->x);
    memcpy(m->x_operator, m->x, sizeof m->x);
    m->in_envelope = 1;
}

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
    for (int i = 0; i < N_X; ++i) rate[i] = (b[i] - a[i]) / (hi - lo);
    if (m->rest_weight > 0.0) /* the rest correction moves with window time too */
        rest_correct_rate(m, basis_lo, basis_hi, hi - lo, rate);
}

void first_layer_base(const double x0[N_X], double base[OPFMU_FIRST_LAYER])
{
    opfmu_first_layer(x0, ZERO_SENSORS, base);
}

void held_coefficients(const double x0[N_X], const double base[OPFMU_FIRST_LAYER], const double u[N_U],
                       double coef[OPFMU_COEF_SIZE])
{
    double z[OPFMU_FIRST_LAYER];
    for (int h = 0; h < OPFMU_FIRST_LAYER; ++h) {
        double sum = base[h];
        for (int c = 0; c < N_U; ++c) sum += SUFFIX(0, c, h) * u[c];
        z[h] = sum;
    }
    opfmu_coefficients(x0, z, coef);
}
#else
/* d x/dt of the operator at window time tau, by a central difference (one-sided at the ends) */
static void operator_rate(const ModelState *m, double tau, double rate[N_X])
{
    const double d = 1e-4;
    double lo = fmax(tau - d, 0.0), hi = fmin(tau + d, OPFMU_HORIZON);
    double a[N_X], b[N_X];
    opfmu_operator(m->x_window, m->sensors, lo, a);
    opfmu_operator(m->x_window, m->sensors, hi, b);
    for (int i = 0; i < N_X; ++i) rate[i] = (b[i] - a[i]) / (hi - lo);
}
#endif

/* The operator's rate against f at its own state (before the exact step of the affine states, which
   would hide the operator's error there: the residual_limit was set on the operator alone) */
double window_residual(const ModelState *m)
{
    double rate[N_X], f[N_X], sum = 0.0;
    operator_rate(m, m->time - m->window_start, rate);
    model_derivatives(m->x_operator, m->u, f);
    if (m->slow_on) { /* the slow coordinate moves at l . f (slow_weight of it) */
        double shift = m->slow_weight * (dot(m->slow_left, f) - dot(m->slow_left, rate));
        for (int i = 0; i < N_X; ++i) rate[i] += shift * m->slow_right[i];
    }
    for (int i = 0; i < N_X; ++i) {
        double r = (rate[i] - f[i]) / OPFMU_RESIDUAL_SCALE[i];
        sum += r * r;
    }
    return sqrt(sum / (double)N_X);
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

/* Checks a window start state and the held input against the envelope (sticky flag). */
static ModelStatus check_envelope(ModelState *m, char *message, size_t size)
{
    size_t used = 0;
    if (!m->in_envelope) return MODEL_OK;
    if (outside(m->u, OPFMU_ENV_U_MIN, OPFMU_ENV_U_MAX, N_U)) {
        m->in_envelope = 0;
        append_number(message, size, &used, "t = %.6g s: input (", m->time);
        for (int c = 0; c < N_U; ++c) {
            append(message, size, &used, c ? ", " : "");
            append(message, size, &used, OPFMU_INPUT_NAMES[c]);
            append_number(message, size, &used, " %.4g ", m->u[c]);
            append(message, size, &used, OPFMU_INPUT_UNITS[c]);
        }
        append(message, size, &used, ") left the trained envelope (");
        for (int c = 0; c < N_U; ++c) {
            append(message, size, &used, c ? ", " : "");
            append(message, size, &used, OPFMU_INPUT_NAMES[c]);
            append_number(message, size, &used, " [%.4g, ", OPFMU_ENV_U_MIN[c]);
            append_number(message, size, &used, "%.4g]", OPFMU_ENV_U_MAX[c]);
        }
        append(message, size, &used, "); results are extrapolated");
        return MODEL_WARNING;
    }
    if (outside(m->x_window, OPFMU_ENV_X0_MIN, OPFMU_ENV_X0_MAX, N_X)) {
        m->in_envelope = 0;
        append_number(message, size, &used, "t = %.6g s: window start state (", m->window_start);
        for (int i = 0; i < N_X; ++i) append_number(message, size, &used, i ? ", %.4g" : "%.4g", m->x_window[i]);
        append(message, size, &used, ") left the trained envelope; results are extrapolated");
        return MODEL_WARNING;
    }
    return MODEL_OK;
}

static void start_window(ModelState *m)
{
    m->window_start = m->time;
    memcpy(m->x_window, m->x, sizeof m->x);
    memcpy(m->x_operator, m->x, sizeof m->x); /* an anchored operator starts from the window's state */
    for (int k = 0; k < OPFMU_N_SENSORS; ++k) memcpy(m->sensors + k * N_U, m->u, sizeof m->u);
    m->filled = 0;
    memcpy(m->last_u, m->u, sizeof m->u);
#if OPFMU_FIRST_LAYER > 0
    opfmu_first_layer(m->x_window, ZERO_SENSORS, m->z_base);
    memset(m->z_past, 0, sizeof m->z_past);
#endif
#if OPFMU_TRUNK_SIZE > 0
    held_coefficients(m->x_window, m->z_base, m->u, m->coef); /* so the residual at the window start is the new window's */
#endif
    start_corrections(m, 1);
}

/* The operator at window time tau after the held input was written from slot `first` on. Per step
   this costs the network after its sensor layer plus O(layer width), not the whole sensor layer. */
static void evaluate(ModelState *m, int first, double tau)
{
#if OPFMU_FIRST_LAYER > 0
    double z[OPFMU_FIRST_LAYER];
#if OPFMU_TRUNK_SIZE > 0
    /* An input equal to the one the slots from `filled` on hold leaves the sensors as they were, so the
       coefficients of the last evaluation (or of the window's start) are still those of this window:
       with a held input a step costs a product with the trunk values, not the network. */
    const int sensors_changed = memcmp(m->u, m->last_u, sizeof m->u) != 0;
#else
    const int sensors_changed = 1;
#endif
    if (sensors_changed) {
        if (first > m->filled) { /* slots [filled, first) keep the input they last got */
            for (int h = 0; h < OPFMU_FIRST_LAYER; ++h)
                for (int c = 0; c < N_U; ++c)
                    m->z_past[h] += (SUFFIX(m->filled, c, h) - SUFFIX(first, c, h)) * m->last_u[c];
            m->filled = first;
        }
        memcpy(m->last_u, m->u, sizeof m->u);
        for (int h = 0; h < OPFMU_FIRST_LAYER; ++h) {
            double sum = m->z_base[h] + m->z_past[h];
            for (int c = 0; c < N_U; ++c) sum += SUFFIX(first, c, h) * m->u[c];
            z[h] = sum;
        }
    }
#if OPFMU_TRUNK_SIZE > 0
    double scratch[OPFMU_TRUNK_SIZE];
    const double *basis = trunk_at(m, tau, scratch);
    if (sensors_changed) opfmu_coefficients(m->x_window, z, m->coef);
    opfmu_head(m->coef, basis, m->x);
    if (m->rest_weight > 0.0) rest_correct(m, basis, m->x);
#else
    opfmu_from_first_layer(m->x_window, z, tau, m->x);
#endif
#else
    (void)first;
    opfmu_operator(m->x_window, m->sensors, tau, m->x);
#endif
}

ModelStatus model_initialize(ModelState *m, double start_time, char *message, size_t size)
{
    m->time = start_time;
    memcpy(m->x, m->x_start, sizeof m->x);
    m->in_envelope = 1;
    start_window(m);
    return check_envelope(m, message, size);
}

/* an input differs from the one written last by more than restart_jump */
static int input_jumped(const ModelState *m)
{
    for (int c = 0; c < N_U; ++c)
        if (fabs(m->u[c] - m->last_u[c]) > m->restart_jump) return 1;
    return 0;
}

ModelStatus model_do_step(ModelState *m, double h, char *message, size_t size)
{
    ModelStatus status = check_envelope(m, message, size);
    double stop = m->time + h;
    /* an input jump starts a new window here, so the jump is at window time 0, where the operator
       learned its transients (every training window starts with one) */
    if (m->restart_jump > 0.0 && m->time > m->window_start + TIME_EPS && input_jumped(m))
        start_window(m);
    while (m->time < stop - TIME_EPS) {
        double window_end = m->window_start + m->rollover_horizon;
        double end = fmin(stop, window_end);
        /* the held input from the current time on: the first slot at or after m->time */
        int first = (int)ceil((m->time - m->window_start) / SENSOR_DT - 1e-6);
        if (m->time < m->window_start + TIME_EPS)
            start_corrections(m, 0); /* for the input held over the window's first step */
        double rate_start = m->slow_on ? slow_rate(m, m->x) : 0.0;
        double x_step[N_X], g_start[N_AFFINE_CAP], k_start[N_AFFINE_CAP];
        memcpy(x_step, m->x, sizeof x_step);
        if (m->swing_weight > 0.0) affine_drive(m->x, m->u, g_start, k_start);
        first = first < 0 ? 0 : (first > OPFMU_N_SENSORS ? OPFMU_N_SENSORS : first);
        /* slots from the previous step's first one on hold last_u: rewritten only when the input changed */
        if (memcmp(m->u, m->last_u, sizeof m->u) != 0)
            for (int k = first; k < OPFMU_N_SENSORS; ++k) memcpy(m->sensors + k * N_U, m->u, sizeof m->u);
        evaluate(m, first, fmin(end - m->window_start, OPFMU_HORIZON));
        if (m->slow_on) slow_correct(m, end - m->time, rate_start);
        memcpy(m->x_operator, m->x, sizeof m->x);
        if (m->swing_weight > 0.0) affine_step(m, x_step, g_start, k_start, end - m->time);
        memcpy(m->last_u, m->u, sizeof m->u);
        m->time = end;
        for (int i = 0; i < N_X; ++i) {
            if (!isfinite(m->x[i])) {
                snprintf(message, size, "t = %.6g s: the operator returned a non-finite state", m->time);
                return MODEL_ERROR;
            }
        }
        if (m->time >= window_end - TIME_EPS) {
            start_window(m);
            if (status == MODEL_OK) status = check_envelope(m, message, size);
        }
    }
    m->time = stop;
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

/* SM4 surrogate: the operator evaluated from a buffer of input sensors (DESIGN section 5).

   A window starts at (window_start, x_window). The input held over a step is written into every
   sensor slot from the current time on (slots not yet known hold the latest value), and the state
   at t + h is the operator at t + h - window_start. When a window's horizon is reached, a new one
   starts from the state there; a step that crosses the horizon is split at it.

   Rest correction (DeepONet kernels): rolled over window after window, the operator's small error at
   a state of rest does not stay small. The co-simulation settles where one window maps the state onto
   itself, which lies off the true equilibrium by about that error / (1 - exp(-T / 11 s)), 12 times it
   for T = 1 s (the slowest mode, -0.09 1/s, hardly decays within a window). So each window also
   evaluates the operator from the equilibrium x_rest of its first step's input, held, where the true answer
   is x_rest itself, and subtracts that error: x = G(x_window, u) - w (G(x_rest, u_start) - x_rest).
   The weight w falls from 1 at x_rest to 0 at REST_RADIUS (times the parameter rest_radius) from it,
   since the error at rest says little about the error far from rest. A machine at rest under a held
   input thus stays exactly at rest.

   Slow-mode correction (any kernel): away from rest the same accumulation remains along the slowest
   mode. Each window takes the Jacobian of the right-hand side at its start state and input, and its
   slowest eigenvalue's left and right eigenvectors l and r (l . r = 1), found by inverse iteration; the
   correction applies when that iteration converges (the mode is real and clearly slower than the
   next; in the built-in scenarios it is real and at most 0.19 times the next one). The slow
   coordinate l . x then follows the physics: its rate l . f(x, u) is integrated over each step by the
   trapezoid rule, and the operator's state is moved along r by slow_weight times its difference from
   that integral. l . f is insensitive to errors in the fast directions (l J = lambda l), so the
   operator's fast dynamics carry the integral while the physics carries the slow drift.

   Exact swing step (any kernel): the swing equation is linear in omega, d omega/dt = g - k omega with
   g = Wb/(2H) (Pm - Pe) and k = Wb D/(2H) (62 1/s), and Pe depends on delta, Ed_p, Eq_p and the input
   alone, which the operator gets right to within a few 1e-4. Omega is the state it finds hardest (the
   16 ms transient at every input jump: at the onset of a deep fault its swing came out 8% short), so
   over each step omega is integrated exactly from where it was, with g taken linear in time between
   its values at the step's start and end states under the held input. omega then moves swing_weight of
   the way from the operator's value to that solution. An error in g of e gives an error in omega of
   e / k, and an error in omega decays as exp(-k t): nothing accumulates. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "model.h"
#include "sm4_equations.h"

void opfmu_operator(const double x0[4], const double u[2 * OPFMU_N_SENSORS], double t, double x[4]);
#if OPFMU_FIRST_LAYER > 0
void opfmu_first_layer(const double x0[4], const double u[2 * OPFMU_N_SENSORS], double z[OPFMU_FIRST_LAYER]);
void opfmu_from_first_layer(const double x0[4], const double z[OPFMU_FIRST_LAYER], double t, double x[4]);
extern const double OPFMU_SENSOR_SUFFIX[(OPFMU_N_SENSORS + 1) * 2 * OPFMU_FIRST_LAYER];
static const double ZERO_SENSORS[2 * OPFMU_N_SENSORS];
#define SUFFIX(k, c, h) OPFMU_SENSOR_SUFFIX[((k) * 2 + (c)) * OPFMU_FIRST_LAYER + (h)]
#endif
#if OPFMU_TRUNK_SIZE > 0
void opfmu_trunk(double t, double tau[OPFMU_TRUNK_SIZE]);
void opfmu_coefficients(const double x0[4], const double z[OPFMU_FIRST_LAYER], double c[OPFMU_COEF_SIZE]);
void opfmu_head(const double c[OPFMU_COEF_SIZE], const double tau[OPFMU_TRUNK_SIZE], double x[4]);
static void start_coefficients(ModelState *m);
static void start_rest_correction(ModelState *m);
#endif
static void start_slow_correction(ModelState *m);
static void start_corrections(ModelState *m, int always);

enum {
    VR_VS, VR_THETA, VR_DELTA, VR_OMEGA, VR_ED, VR_EQ, VR_ID, VR_IQ, VR_IRE, VR_IIM, VR_P, VR_Q,
    VR_DELTA0, VR_OMEGA0, VR_ED0, VR_EQ0, VR_RESIDUAL, VR_HORIZON, VR_RESIDUAL_LIMIT,
    VR_RESTART_JUMP, VR_REST_RADIUS, VR_SLOW_WEIGHT, VR_SWING_WEIGHT, VR_COUNT
};
enum { VR_IN_ENVELOPE = 0 };

static const double SENSOR_DT = OPFMU_HORIZON / (OPFMU_N_SENSORS - 1);
static const double TIME_EPS = 1e-9;
/* how far from x_rest the rest correction reaches (rad, rad/s, pu, pu), times rest_radius */
static const double REST_RADIUS[4] = {0.5, 0.25, 0.1, 0.1};

void model_defaults(ModelState *m)
{
    memset(m, 0, sizeof *m);
    m->Vs = 1.0;
    m->theta_vs = 0.0;
    memcpy(m->x_start, OPFMU_DEFAULT_X0, sizeof m->x_start);
    m->rollover_horizon = OPFMU_ROLLOVER_HORIZON;
    m->residual_limit = OPFMU_RESIDUAL_LIMIT;
    m->restart_jump = OPFMU_RESTART_JUMP;
    m->rest_radius = OPFMU_REST_RADIUS;
    m->slow_weight = OPFMU_SLOW_WEIGHT;
    m->swing_weight = OPFMU_SWING_WEIGHT;
    memcpy(m->x, m->x_start, sizeof m->x);
    m->omega_operator = m->x[1];
    m->in_envelope = 1;
}

int model_real_kind(unsigned int vr)
{
    if (vr == VR_VS || vr == VR_THETA) return VAR_INPUT;
    if ((vr >= VR_DELTA0 && vr <= VR_EQ0) || vr == VR_HORIZON || vr == VR_RESIDUAL_LIMIT || vr == VR_RESTART_JUMP ||
        vr == VR_REST_RADIUS || vr == VR_SLOW_WEIGHT || vr == VR_SWING_WEIGHT)
        return VAR_PARAMETER;
    if (vr < VR_COUNT) return VAR_OUTPUT;
    return -1;
}

#if OPFMU_TRUNK_SIZE > 0
/* The trunk values at window time tau: those kept for the sensor time tau is on, if any, else
   computed into `scratch`. */
/* The sensor slot window time tau is on, or -1 when it lies between sensor times. */
static long sensor_slot(double tau)
{
    double slot = tau / SENSOR_DT;
    long k = lround(slot);
    return k >= 0 && k < OPFMU_N_SENSORS && fabs(slot - (double)k) <= 1e-6 ? k : -1;
}

static const double *trunk_seen(const ModelState *m, double tau, double scratch[OPFMU_TRUNK_SIZE])
{
    long k = sensor_slot(tau);
    if (k >= 0 && m->trunk_ready[k])
        return m->trunk + k * OPFMU_TRUNK_SIZE;
    opfmu_trunk(tau, scratch);
    return scratch;
}

/* d x/dt of the operator at window time tau with the coefficients of the last evaluation, by a
   central difference over one sensor interval (one-sided at the ends): two products with kept trunk
   values, not two network evaluations */
static void operator_rate(const ModelState *m, double tau, double rate[4])
{
    double lo = fmax(tau - SENSOR_DT, 0.0), hi = fmin(tau + SENSOR_DT, OPFMU_HORIZON);
    double a[4], b[4], ra[4], rb[4], scratch[OPFMU_TRUNK_SIZE];
    opfmu_head(m->coef, trunk_seen(m, lo, scratch), a);
    opfmu_head(m->coef, trunk_seen(m, hi, scratch), b);
    for (int i = 0; i < 4; ++i) rate[i] = (b[i] - a[i]) / (hi - lo);
    if (m->rest_weight > 0.0) { /* the rest correction moves with window time too */
        opfmu_head(m->rest_coef, trunk_seen(m, lo, scratch), ra);
        opfmu_head(m->rest_coef, trunk_seen(m, hi, scratch), rb);
        for (int i = 0; i < 4; ++i) rate[i] -= m->rest_weight * (rb[i] - ra[i]) / (hi - lo);
    }
}
#else
/* d x/dt of the operator at window time tau, by a central difference (one-sided at the ends) */
static void operator_rate(const ModelState *m, double tau, double rate[4])
{
    const double d = 1e-4;
    double lo = fmax(tau - d, 0.0), hi = fmin(tau + d, OPFMU_HORIZON);
    double a[4], b[4];
    opfmu_operator(m->x_window, m->sensors, lo, a);
    opfmu_operator(m->x_window, m->sensors, hi, b);
    for (int i = 0; i < 4; ++i) rate[i] = (b[i] - a[i]) / (hi - lo);
}
#endif

static double dot4(const double a[4], const double b[4]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]; }

/* The operator's physics residual: its rate against f at its own state (omega before the exact swing
   step, which would hide the operator's omega error: the residual_limit was set on the operator alone) */
static double residual(const ModelState *m)
{
    double rate[4], f[4], u[2] = {m->Vs, m->theta_vs}, x[4] = {m->x[0], m->omega_operator, m->x[2], m->x[3]};
    double sum = 0.0;
    operator_rate(m, m->time - m->window_start, rate);
    sm4_derivatives(x, u, f);
    if (m->slow_on) { /* the slow coordinate moves at l . f (slow_weight of it) */
        double shift = m->slow_weight * (dot4(m->slow_left, f) - dot4(m->slow_left, rate));
        for (int i = 0; i < 4; ++i) rate[i] += shift * m->slow_right[i];
    }
    for (int i = 0; i < 4; ++i) {
        double r = (rate[i] - f[i]) / OPFMU_RESIDUAL_SCALE[i];
        sum += r * r;
    }
    return sqrt(sum / 4.0);
}

ModelStatus model_get_real(const ModelState *m, unsigned int vr, double *value)
{
    double u[2] = {m->Vs, m->theta_vs}, y[6];
    switch (vr) {
    case VR_VS: *value = m->Vs; return MODEL_OK;
    case VR_THETA: *value = m->theta_vs; return MODEL_OK;
    case VR_DELTA: case VR_OMEGA: case VR_ED: case VR_EQ: *value = m->x[vr - VR_DELTA]; return MODEL_OK;
    case VR_ID: case VR_IQ: case VR_IRE: case VR_IIM: case VR_P: case VR_Q:
        sm4_outputs(m->x, u, y);
        *value = y[vr - VR_ID];
        return MODEL_OK;
    case VR_DELTA0: case VR_OMEGA0: case VR_ED0: case VR_EQ0: *value = m->x_start[vr - VR_DELTA0]; return MODEL_OK;
    case VR_RESIDUAL: *value = residual(m); return MODEL_OK;
    case VR_HORIZON: *value = m->rollover_horizon; return MODEL_OK;
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
    switch (vr) {
    case VR_VS:
        if (value < 0.0) {
            snprintf(message, size, "Vs = %g pu is negative", value);
            return MODEL_ERROR;
        }
        m->Vs = value;
        return MODEL_OK;
    case VR_THETA: m->theta_vs = value; return MODEL_OK;
    case VR_DELTA0: case VR_OMEGA0: case VR_ED0: case VR_EQ0: m->x_start[vr - VR_DELTA0] = value; return MODEL_OK;
    case VR_HORIZON:
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
        return set_weight(&m->swing_weight, value, "swing_weight", "the exact swing step", message, size);
    default:
        snprintf(message, size, "value reference %u is not a settable Real variable", vr);
        return MODEL_ERROR;
    }
}

int model_boolean_exists(unsigned int vr) { return vr == VR_IN_ENVELOPE; }

int model_get_boolean(const ModelState *m, unsigned int vr) { (void)vr; return m->in_envelope; }

static int outside(const double *v, const double *lo, const double *hi, int n)
{
    for (int i = 0; i < n; ++i)
        if (v[i] < lo[i] - 1e-6 || v[i] > hi[i] + 1e-6) return 1;
    return 0;
}

/* Checks a window start state and the held input against the envelope (sticky flag). */
static ModelStatus check_envelope(ModelState *m, char *message, size_t size)
{
    double u[2] = {m->Vs, m->theta_vs};
    if (!m->in_envelope) return MODEL_OK;
    if (outside(u, OPFMU_ENV_U_MIN, OPFMU_ENV_U_MAX, 2)) {
        m->in_envelope = 0;
        snprintf(message, size, "t = %.6g s: input (Vs %.4g pu, theta_vs %.4g rad) left the trained envelope "
                 "(Vs [%.4g, %.4g], theta_vs [%.4g, %.4g]); results are extrapolated", m->time, u[0], u[1],
                 OPFMU_ENV_U_MIN[0], OPFMU_ENV_U_MAX[0], OPFMU_ENV_U_MIN[1], OPFMU_ENV_U_MAX[1]);
        return MODEL_WARNING;
    }
    if (outside(m->x_window, OPFMU_ENV_X0_MIN, OPFMU_ENV_X0_MAX, 4)) {
        m->in_envelope = 0;
        snprintf(message, size, "t = %.6g s: window start state (%.4g, %.4g, %.4g, %.4g) left the trained "
                 "envelope; results are extrapolated", m->window_start, m->x_window[0], m->x_window[1],
                 m->x_window[2], m->x_window[3]);
        return MODEL_WARNING;
    }
    return MODEL_OK;
}

static void start_window(ModelState *m)
{
    m->window_start = m->time;
    memcpy(m->x_window, m->x, sizeof m->x);
    m->omega_operator = m->x[1]; /* an anchored operator starts from the window's state */
    for (int k = 0; k < OPFMU_N_SENSORS; ++k) {
        m->sensors[2 * k] = m->Vs;
        m->sensors[2 * k + 1] = m->theta_vs;
    }
    m->filled = 0;
    m->last_u[0] = m->Vs;
    m->last_u[1] = m->theta_vs;
#if OPFMU_FIRST_LAYER > 0
    opfmu_first_layer(m->x_window, ZERO_SENSORS, m->z_base);
    memset(m->z_past, 0, sizeof m->z_past);
#endif
#if OPFMU_TRUNK_SIZE > 0
    start_coefficients(m); /* so the residual at the window start is the new window's */
#endif
    start_corrections(m, 1);
}

#if OPFMU_TRUNK_SIZE > 0
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
#endif

#if OPFMU_TRUNK_SIZE > 0
/* The coefficients of a window just started: every sensor slot holds the current input. */
static void start_coefficients(ModelState *m)
{
    double z[OPFMU_FIRST_LAYER];
    for (int h = 0; h < OPFMU_FIRST_LAYER; ++h)
        z[h] = m->z_base[h] + SUFFIX(0, 0, h) * m->Vs + SUFFIX(0, 1, h) * m->theta_vs;
    opfmu_coefficients(m->x_window, z, m->coef);
}
#endif

/* d f / d x of the SM4 at (x, u) [4 x 4], by central differences */
static void jacobian(const double x[4], const double u[2], double J[4][4])
{
    for (int j = 0; j < 4; ++j) {
        double d = 1e-6 * fmax(1.0, fabs(x[j])), hi[4], lo[4], fh[4], fl[4];
        memcpy(hi, x, sizeof hi);
        memcpy(lo, x, sizeof lo);
        hi[j] += d;
        lo[j] -= d;
        sm4_derivatives(hi, u, fh);
        sm4_derivatives(lo, u, fl);
        for (int i = 0; i < 4; ++i) J[i][j] = (fh[i] - fl[i]) / (2.0 * d);
    }
}

/* LU factors of A in place (partial pivoting; row i of the factors is row perm[i] of A); 0 if singular */
static int lu_factor(double A[4][4], int perm[4])
{
    for (int i = 0; i < 4; ++i) perm[i] = i;
    for (int c = 0; c < 4; ++c) {
        int pivot = c;
        for (int r = c + 1; r < 4; ++r)
            if (fabs(A[r][c]) > fabs(A[pivot][c])) pivot = r;
        if (!(fabs(A[pivot][c]) >= 1e-14)) return 0;
        if (pivot != c) {
            for (int k = 0; k < 4; ++k) {
                double swap = A[c][k];
                A[c][k] = A[pivot][k];
                A[pivot][k] = swap;
            }
            int swap = perm[c];
            perm[c] = perm[pivot];
            perm[pivot] = swap;
        }
        for (int r = c + 1; r < 4; ++r) {
            A[r][c] /= A[c][c];
            for (int k = c + 1; k < 4; ++k) A[r][k] -= A[r][c] * A[c][k];
        }
    }
    return 1;
}

/* x = A^-1 b from the factors of lu_factor (x and b distinct) */
static void lu_solve(const double F[4][4], const int perm[4], const double b[4], double x[4])
{
    for (int i = 0; i < 4; ++i) {
        x[i] = b[perm[i]];
        for (int k = 0; k < i; ++k) x[i] -= F[i][k] * x[k];
    }
    for (int i = 3; i >= 0; --i) {
        for (int k = i + 1; k < 4; ++k) x[i] -= F[i][k] * x[k];
        x[i] /= F[i][i];
    }
}

/* The equilibrium of the SM4 under the held input u nearest `x` (Newton on the right-hand side from
   x); 0 if Newton does not converge within 30 iterations. */
static int equilibrium(const double x[4], const double u[2], double rest[4])
{
    memcpy(rest, x, 4 * sizeof *rest);
    for (int iteration = 0; iteration < 30; ++iteration) {
        double f[4], J[4][4], step[4];
        int perm[4];
        sm4_derivatives(rest, u, f);
        double norm = fabs(f[0]) + fabs(f[1]) + fabs(f[2]) + fabs(f[3]);
        if (!isfinite(norm)) return 0;
        if (norm < 1e-12) return 1;
        jacobian(rest, u, J);
        if (!lu_factor(J, perm)) return 0;
        lu_solve(J, perm, f, step);
        for (int i = 0; i < 4; ++i) rest[i] -= step[i];
    }
    return 0;
}

/* The eigenvector v [4] of A's eigenvalue of least magnitude, by 60 steps of inverse iteration with
   A's LU factors F; 1 if it converged (|A v - lambda v| <= 1e-6 |lambda|), which needs that
   eigenvalue real and clearly smaller in magnitude than the next one. */
static int slowest_mode(const double A[4][4], const double F[4][4], const int perm[4], double v[4])
{
    const double start[4] = {1.0, 0.7, 0.4, 0.1};
    memcpy(v, start, sizeof start);
    for (int iteration = 0; iteration < 60; ++iteration) {
        double w[4];
        lu_solve(F, perm, v, w);
        int big = 0;
        for (int i = 1; i < 4; ++i)
            if (fabs(w[i]) > fabs(w[big])) big = i;
        if (!isfinite(w[big]) || w[big] == 0.0) return 0;
        for (int i = 0; i < 4; ++i) v[i] = w[i] / w[big]; /* signed: no flip from a negative eigenvalue */
    }
    double Av[4], lambda, miss = 0.0;
    for (int i = 0; i < 4; ++i) Av[i] = dot4(A[i], v);
    lambda = dot4(v, Av) / dot4(v, v);
    for (int i = 0; i < 4; ++i) miss = fmax(miss, fabs(Av[i] - lambda * v[i]));
    return miss <= 1e-6 * fabs(lambda);
}

/* The slow-mode correction of a window just started (see the top of this file). */
static void start_slow_correction(ModelState *m)
{
    double u[2] = {m->Vs, m->theta_vs}, J[4][4], Jt[4][4], F[4][4], Ft[4][4];
    int perm[4], perm_t[4];
    m->slow_on = 0;
    if (m->slow_weight <= 0.0) return;
    jacobian(m->x_window, u, J);
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) Jt[i][j] = J[j][i];
    memcpy(F, J, sizeof F);
    memcpy(Ft, Jt, sizeof Ft);
    if (!lu_factor(F, perm) || !lu_factor(Ft, perm_t)) return;
    if (!slowest_mode(J, F, perm, m->slow_right) || !slowest_mode(Jt, Ft, perm_t, m->slow_left)) return;
    double overlap = dot4(m->slow_left, m->slow_right);
    if (!(fabs(overlap) > 1e-9)) return;
    for (int i = 0; i < 4; ++i) m->slow_left[i] /= overlap;
    m->slow_start = dot4(m->slow_left, m->x_window);
    m->slow_integral = 0.0;
    m->slow_on = 1;
}

/* The rest and slow-mode corrections of a window just started, for the current input; unless `always`,
   only if they were computed for another input (a window starts at the end of a step, before the
   input of its first step is known). */
static void start_corrections(ModelState *m, int always)
{
    if (!always && m->corrected_for[0] == m->Vs && m->corrected_for[1] == m->theta_vs) return;
    m->corrected_for[0] = m->Vs;
    m->corrected_for[1] = m->theta_vs;
#if OPFMU_TRUNK_SIZE > 0
    start_rest_correction(m);
#endif
    start_slow_correction(m);
}

/* l . f(x, u): the rate of the slow coordinate under the held input */
static double slow_rate(const ModelState *m, const double x[4])
{
    double f[4], u[2] = {m->Vs, m->theta_vs};
    sm4_derivatives(x, u, f);
    return dot4(m->slow_left, f);
}

/* After a step of length h that started at slow rate `rate_start`: adds the step's trapezoid integral
   and moves the state along r by slow_weight times its slow coordinate's miss of the integral. */
static void slow_correct(ModelState *m, double h, double rate_start)
{
    m->slow_integral += 0.5 * h * (rate_start + slow_rate(m, m->x));
    double shift = m->slow_weight * (m->slow_start + m->slow_integral - dot4(m->slow_left, m->x));
    for (int i = 0; i < 4; ++i) m->x[i] += shift * m->slow_right[i];
}

/* g of the swing equation d omega/dt = g - k omega at state x under input u (see the top of this file),
   and k: both from the right-hand side, which is affine in omega */
static double swing_drive(const double x[4], const double u[2], double *k)
{
    const double at_rest[4] = {x[0], 0.0, x[2], x[3]}, moving[4] = {x[0], 1.0, x[2], x[3]};
    double f_rest[4], f_moving[4];
    sm4_derivatives(at_rest, u, f_rest);
    sm4_derivatives(moving, u, f_moving);
    *k = f_rest[1] - f_moving[1];
    return f_rest[1];
}

/* omega after a step of length h from omega_start, solving d omega/dt = g - k omega exactly for g linear
   in time from g_start to g_end */
static double swing_omega(double omega_start, double g_start, double g_end, double k, double h)
{
    if (!(k * h > 1e-8)) /* no damping to speak of: the trapezoid rule is exact for linear g */
        return omega_start + 0.5 * h * (g_start + g_end);
    const double decay = exp(-k * h), reach = -expm1(-k * h) / k; /* reach: integral of exp(-k (h - s)) */
    return decay * omega_start + g_start * reach + (g_end - g_start) * (h - reach) / (k * h);
}

/* The rest correction of a window just started (see the top of this file): x_rest, its weight and the
   operator's coefficients from x_rest under the start input held. */
static void start_rest_correction(ModelState *m)
{
    double u[2] = {m->Vs, m->theta_vs}, distance = 0.0;
    m->rest_weight = 0.0;
    if (m->rest_radius <= 0.0 || !equilibrium(m->x_window, u, m->x_rest)) return;
    for (int i = 0; i < 4; ++i)
        distance = fmax(distance, fabs(m->x_window[i] - m->x_rest[i]) / (m->rest_radius * REST_RADIUS[i]));
    if (distance >= 1.0) return;
    m->rest_weight = 1.0 - distance;
    double base[OPFMU_FIRST_LAYER], z[OPFMU_FIRST_LAYER];
    opfmu_first_layer(m->x_rest, ZERO_SENSORS, base);
    for (int h = 0; h < OPFMU_FIRST_LAYER; ++h)
        z[h] = base[h] + SUFFIX(0, 0, h) * m->Vs + SUFFIX(0, 1, h) * m->theta_vs;
    opfmu_coefficients(m->x_rest, z, m->rest_coef);
}

/* The operator at window time tau after the held input was written from slot `first` on. Per step
   this costs the network after its sensor layer plus O(layer width), not the whole sensor layer. */
static void evaluate(ModelState *m, int first, double tau)
{
#if OPFMU_FIRST_LAYER > 0
    double z[OPFMU_FIRST_LAYER];
    if (first > m->filled) { /* slots [filled, first) keep the input they last got */
        for (int h = 0; h < OPFMU_FIRST_LAYER; ++h)
            for (int c = 0; c < 2; ++c)
                m->z_past[h] += (SUFFIX(m->filled, c, h) - SUFFIX(first, c, h)) * m->last_u[c];
        m->filled = first;
    }
    m->last_u[0] = m->Vs;
    m->last_u[1] = m->theta_vs;
    for (int h = 0; h < OPFMU_FIRST_LAYER; ++h)
        z[h] = m->z_base[h] + m->z_past[h] + SUFFIX(first, 0, h) * m->Vs + SUFFIX(first, 1, h) * m->theta_vs;
#if OPFMU_TRUNK_SIZE > 0
    double scratch[OPFMU_TRUNK_SIZE];
    const double *basis = trunk_at(m, tau, scratch);
    opfmu_coefficients(m->x_window, z, m->coef);
    opfmu_head(m->coef, basis, m->x);
    if (m->rest_weight > 0.0) {
        double at_rest[4];
        opfmu_head(m->rest_coef, basis, at_rest);
        for (int i = 0; i < 4; ++i) m->x[i] -= m->rest_weight * (at_rest[i] - m->x_rest[i]);
    }
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

ModelStatus model_do_step(ModelState *m, double h, char *message, size_t size)
{
    ModelStatus status = check_envelope(m, message, size);
    double stop = m->time + h;
    /* an input jump starts a new window here, so the jump is at window time 0, where the operator
       learned its transients (every training window starts with one) */
    if (m->restart_jump > 0.0 && m->time > m->window_start + TIME_EPS &&
        (fabs(m->Vs - m->last_u[0]) > m->restart_jump || fabs(m->theta_vs - m->last_u[1]) > m->restart_jump))
        start_window(m);
    while (m->time < stop - TIME_EPS) {
        double window_end = m->window_start + m->rollover_horizon;
        double end = fmin(stop, window_end);
        /* the held input from the current time on: the first slot at or after m->time */
        int first = (int)ceil((m->time - m->window_start) / SENSOR_DT - 1e-6);
        if (m->time < m->window_start + TIME_EPS)
            start_corrections(m, 0); /* for the input held over the window's first step */
        double rate_start = m->slow_on ? slow_rate(m, m->x) : 0.0;
        double u[2] = {m->Vs, m->theta_vs}, k = 0.0, omega_start = m->x[1];
        double drive_start = m->swing_weight > 0.0 ? swing_drive(m->x, u, &k) : 0.0;
        first = first < 0 ? 0 : (first > OPFMU_N_SENSORS ? OPFMU_N_SENSORS : first);
        for (int k = first; k < OPFMU_N_SENSORS; ++k) {
            m->sensors[2 * k] = m->Vs;
            m->sensors[2 * k + 1] = m->theta_vs;
        }
        evaluate(m, first, fmin(end - m->window_start, OPFMU_HORIZON));
        if (m->slow_on) slow_correct(m, end - m->time, rate_start);
        m->omega_operator = m->x[1];
        if (m->swing_weight > 0.0) {
            double exact = swing_omega(omega_start, drive_start, swing_drive(m->x, u, &k), k, end - m->time);
            m->x[1] += m->swing_weight * (exact - m->x[1]);
        }
        m->last_u[0] = m->Vs;
        m->last_u[1] = m->theta_vs;
        m->time = end;
        for (int i = 0; i < 4; ++i) {
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
        double r = residual(m);
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

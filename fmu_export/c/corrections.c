/* The corrections of the operator's answer, generic over the component (its right-hand side is
   model_derivatives; its sizes, state scales and affine states come from config.h).

   Rest correction (DeepONet kernels): rolled over window after window, the operator's small error at
   a state of rest does not stay small. The co-simulation settles where one window maps the state onto
   itself, which lies off the true equilibrium by about that error / (1 - exp(-T / tau_slow)): for SM4,
   12 times it for T = 1 s (the slowest mode, -0.09 1/s, hardly decays within a window). So each window
   also evaluates the operator from the equilibrium x_rest of its first step's input, held, where the
   true answer is x_rest itself, and subtracts that error: x = G(x_window, u) - w (G(x_rest, u_start) -
   x_rest). The weight w falls from 1 at x_rest to 0 at OPFMU_STATE_SCALE (times the parameter
   rest_radius) from it, since the error at rest says little about the error far from rest. A
   component at rest under a held input thus stays exactly at rest. All of it is in the window frame
   (window.c): a machine turning with its network at the frame's speed is at rest there.

   Slow-mode correction (any kernel): away from rest the same accumulation remains along the slowest
   mode. Each window takes the Jacobian of the right-hand side at its start state and input, and its
   slowest eigenvalue's left and right eigenvectors l and r (l . r = 1), found by inverse iteration; the
   correction applies when that iteration converges (the mode is real and clearly slower than the
   next; for SM4 in the built-in scenarios it is real and at most 0.19 times the next one). The slow
   coordinate l . x then follows the physics: its rate l . f(x, u) is integrated over each step by the
   trapezoid rule, and the operator's state is moved along r by slow_weight times its difference from
   that integral. l . f is insensitive to errors in the fast directions (l J = lambda l), so the
   operator's fast dynamics carry the integral while the physics carries the slow drift.

   Exact step of the affine states (any kernel): a state x_i the component declares affine has the
   rate dx_i/dt = g - k x_i with k >= 0 (constant, or constant on pieces: a PI's anti-windup, taken
   at the step's start) and g a function of the other states and the input
   (for SM4, omega: g = Wb/(2H) (Pm - Pe), k = Wb D/(2H), 62 1/s, and the operator finds omega's 16 ms
   transient at every input jump hardest). Over each step x_i is integrated exactly from where it
   was, with g taken linear in time between its values at the step's start and end states under the
   held input, and moves swing_weight of the way from the operator's value to that solution. An error
   in g of e gives an error in x_i of e / k, and an error in x_i decays as exp(-k t): nothing
   accumulates. With k = 0 (SM4 with D = 0) the trapezoid rule is the exact solution. */
#include <math.h>
#include <string.h>

#include "engine.h"

/* d f / d x_j at (x, u), by central differences */
static void column(const double x[N_X], const double u[N_U], int j, double out[N_X])
{
    double d = 1e-6 * fmax(1.0, fabs(x[j])), hi[N_X], lo[N_X], fh[N_X], fl[N_X];
    memcpy(hi, x, sizeof hi);
    memcpy(lo, x, sizeof lo);
    hi[j] += d;
    lo[j] -= d;
    model_derivatives(hi, u, TRAINED_P, fh);
    model_derivatives(lo, u, TRAINED_P, fl);
    for (int i = 0; i < N_X; ++i) out[i] = (fh[i] - fl[i]) / (2.0 * d);
}

/* d f / d x at (x, u) */
static void jacobian(const double x[N_X], const double u[N_U], Matrix J)
{
    for (int j = 0; j < N_X; ++j) {
        double c[N_X];
        column(x, u, j, c);
        for (int i = 0; i < N_X; ++i) J[i][j] = c[i];
    }
}

#if OPFMU_TRUNK_SIZE > 0
/* The equilibrium under the held input u nearest `x` (Newton on the right-hand side from x); 0 if
   Newton does not converge within 30 iterations. */
static int equilibrium(const double x[N_X], const double u[N_U], double rest[N_X])
{
    memcpy(rest, x, N_X * sizeof *rest);
    for (int iteration = 0; iteration < 30; ++iteration) {
        double f[N_X], step[N_X], norm = 0.0;
        Matrix J;
        int perm[N_X];
        model_derivatives(rest, u, TRAINED_P, f);
        for (int i = 0; i < N_X; ++i) norm += fabs(f[i]);
        if (!isfinite(norm)) return 0;
        if (norm < 1e-12) return 1;
        jacobian(rest, u, J);
        if (!lu_factor(J, perm)) return 0;
        lu_solve(J, perm, f, step);
        for (int i = 0; i < N_X; ++i) rest[i] -= step[i];
    }
    return 0;
}

/* The rest correction of a window just started: x_rest, its weight and the operator's coefficients
   from x_rest under the start input held. */
static void start_rest_correction(ModelState *m)
{
    double distance = 0.0, level[N_U];
    m->rest_weight = 0.0;
    input_in_frame(&m->frame, m->u, 0.0, level); /* at rest in the window frame: the machine turning with it */
    if (m->rest_radius <= 0.0 || !equilibrium(m->x_window_f, level, m->x_rest)) return;
    for (int i = 0; i < N_X; ++i)
        distance = fmax(distance, fabs(m->x_window_f[i] - m->x_rest[i]) / (m->rest_radius * OPFMU_STATE_SCALE[i]));
    if (distance >= 1.0) return;
    m->rest_weight = 1.0 - distance;
    double base[OPFMU_FIRST_LAYER];
    first_layer_base(m->x_rest, base);
    held_coefficients(m->x_rest, base, level, m->rest_coef);
}

void rest_correct(const ModelState *m, const double *basis, double x[N_X])
{
    double at_rest[N_X];
    opfmu_head(m->rest_coef, basis, at_rest);
    for (int i = 0; i < N_X; ++i) x[i] -= m->rest_weight * (at_rest[i] - m->x_rest[i]);
}

void rest_correct_rate(const ModelState *m, const double *lo, const double *hi, double span, double rate[N_X])
{
    double ra[N_X], rb[N_X];
    opfmu_head(m->rest_coef, lo, ra);
    opfmu_head(m->rest_coef, hi, rb);
    for (int i = 0; i < N_X; ++i) rate[i] -= m->rest_weight * (rb[i] - ra[i]) / span;
}
#endif

/* The eigenvector v of A's eigenvalue of least magnitude, by 60 steps of inverse iteration with A's
   LU factors F from OPFMU_MODE_START; 1 if it converged (|A v - lambda v| <= 1e-6 |lambda|), which
   needs that eigenvalue real and clearly smaller in magnitude than the next one. */
static int slowest_mode(const Matrix A, const Matrix F, const int perm[N_X], double v[N_X])
{
    memcpy(v, OPFMU_MODE_START, N_X * sizeof *v);
    for (int iteration = 0; iteration < 60; ++iteration) {
        double w[N_X];
        lu_solve(F, perm, v, w);
        int big = 0;
        for (int i = 1; i < N_X; ++i)
            if (fabs(w[i]) > fabs(w[big])) big = i;
        if (!isfinite(w[big]) || w[big] == 0.0) return 0;
        for (int i = 0; i < N_X; ++i) v[i] = w[i] / w[big]; /* signed: no flip from a negative eigenvalue */
    }
    double Av[N_X], lambda, miss = 0.0;
    for (int i = 0; i < N_X; ++i) Av[i] = dot(A[i], v);
    lambda = dot(v, Av) / dot(v, v);
    for (int i = 0; i < N_X; ++i) miss = fmax(miss, fabs(Av[i] - lambda * v[i]));
    return miss <= 1e-6 * fabs(lambda);
}

/* The slow-mode correction of a window just started. */
static void start_slow_correction(ModelState *m)
{
    Matrix J, Jt, F, Ft;
    int perm[N_X], perm_t[N_X];
    m->slow_on = 0;
    if (m->slow_weight <= 0.0) return;
    jacobian(m->x_window, m->u, J);
    for (int i = 0; i < N_X; ++i)
        for (int j = 0; j < N_X; ++j) Jt[i][j] = J[j][i];
    memcpy(F, J, sizeof F);
    memcpy(Ft, Jt, sizeof Ft);
    if (!lu_factor(F, perm) || !lu_factor(Ft, perm_t)) return;
    if (!slowest_mode(J, F, perm, m->slow_right) || !slowest_mode(Jt, Ft, perm_t, m->slow_left)) return;
    double overlap = dot(m->slow_left, m->slow_right);
    if (!(fabs(overlap) > 1e-9)) return;
    for (int i = 0; i < N_X; ++i) m->slow_left[i] /= overlap;
    m->slow_start = dot(m->slow_left, m->x_window);
    m->slow_integral = 0.0;
    m->slow_on = 1;
}

void start_corrections(ModelState *m, int always)
{
    if (!always) {
        int same = 1;
        for (int c = 0; c < N_U; ++c) same = same && m->corrected_for[c] == m->u[c];
        if (same) return;
    }
    memcpy(m->corrected_for, m->u, sizeof m->u);
#if OPFMU_TRUNK_SIZE > 0
    start_rest_correction(m);
#endif
    start_slow_correction(m);
}

double slow_rate(const ModelState *m, const double x[N_X])
{
    double f[N_X];
    model_derivatives(x, m->u, TRAINED_P, f);
    return dot(m->slow_left, f);
}

void slow_correct(ModelState *m, double h, double rate_start)
{
    m->slow_integral += 0.5 * h * (rate_start + slow_rate(m, m->x));
    double shift = m->slow_weight * (m->slow_start + m->slow_integral - dot(m->slow_left, m->x));
    for (int i = 0; i < N_X; ++i) m->x[i] += shift * m->slow_right[i];
}

/* g and k of each affine state i at x: k = -d f_i / d x_i (a state affine in itself has one k; a
   piecewise affine one, a PI with its anti-windup, that of the piece it is on) and g = f_i + k x_i,
   so that f_i = g - k x_i there */
void affine_drive(const double x[N_X], const double u[N_U], double g[N_AFFINE_CAP], double k[N_AFFINE_CAP])
{
    double f[N_X];
    model_derivatives(x, u, TRAINED_P, f);
    for (int a = 0; a < OPFMU_N_AFFINE; ++a) {
        const int i = OPFMU_AFFINE_STATES[a];
        double c[N_X];
        column(x, u, i, c);
        k[a] = -c[i];
        g[a] = f[i] + k[a] * x[i];
    }
}

/* x_i after a step of length h from x_start, solving dx_i/dt = g - k x_i exactly for g linear in time
   from g_start to g_end */
static double affine_solution(double x_start, double g_start, double g_end, double k, double h)
{
    if (!(fabs(k * h) > 1e-8)) /* no decay to speak of: the trapezoid rule is exact for linear g */
        return x_start + 0.5 * h * (g_start + g_end);
    const double decay = exp(-k * h), reach = -expm1(-k * h) / k; /* reach: integral of exp(-k (h - s)) */
    return decay * x_start + g_start * reach + (g_end - g_start) * (h - reach) / (k * h);
}

/* k is constant over the step (the start's), so g at the end is f_i + k x_i there; in the component's
   order, so that each affine state's end value reads the exact end values of the affine states before
   it (a plant controller's filter before the PI that reads it) */
void affine_step(ModelState *m, const double x_start[N_X], const double g_start[N_AFFINE_CAP],
                 const double k_start[N_AFFINE_CAP], double h)
{
    for (int a = 0; a < OPFMU_N_AFFINE; ++a) {
        const int i = OPFMU_AFFINE_STATES[a];
        double f[N_X];
        model_derivatives(m->x, m->u, TRAINED_P, f);
        double g_end = f[i] + k_start[a] * m->x[i];
        double exact = affine_solution(x_start[i], g_start[a], g_end, k_start[a], h);
        m->x[i] += m->swing_weight * (exact - m->x[i]);
    }
}

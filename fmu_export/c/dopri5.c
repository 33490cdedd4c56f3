/* Dormand-Prince 5(4) with a PI step-size controller (see dopri5.h).

   The method: J. R. Dormand and P. J. Prince, A family of embedded Runge-Kutta formulae, J. Comp.
   Appl. Math. 6 (1980); the controller and the initial step guess: E. Hairer, S. P. Norsett and
   G. Wanner, Solving Ordinary Differential Equations I, sections II.4 (step size selection,
   starting step size), II.5 (dense output: the continuous extension of order 4, coefficients D1-D7)
   and IV.2 (PI control, beta = 0.04 for this method).

   Event location (dopri5_events): the caller's right-hand side takes the branches it is locked to,
   so it is smooth within each step. After each accepted step the caller says whether the locked
   branches still hold at its end (`crossed`); where they do not, the first instant they stop holding
   is bracketed by bisection on the step's dense output to the time resolution DOPRI5_EVENT_RESOLUTION,
   the step ends at the bracket's right end (on the dense output, where the new branches hold), the
   right-hand side is locked there (`lock`), and the integration restarts from that point. */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dopri5.h"

/* the tableau: nodes c, stages a, 5th-order weights b (the 7th stage is the new state's rate:
   first same as last) and error weights e = b - b_hat (b_hat: the embedded 4th-order weights) */
static const double C2 = 1.0 / 5.0, C3 = 3.0 / 10.0, C4 = 4.0 / 5.0, C5 = 8.0 / 9.0;
static const double A21 = 1.0 / 5.0;
static const double A31 = 3.0 / 40.0, A32 = 9.0 / 40.0;
static const double A41 = 44.0 / 45.0, A42 = -56.0 / 15.0, A43 = 32.0 / 9.0;
static const double A51 = 19372.0 / 6561.0, A52 = -25360.0 / 2187.0, A53 = 64448.0 / 6561.0, A54 = -212.0 / 729.0;
static const double A61 = 9017.0 / 3168.0, A62 = -355.0 / 33.0, A63 = 46732.0 / 5247.0, A64 = 49.0 / 176.0,
                    A65 = -5103.0 / 18656.0;
static const double B1 = 35.0 / 384.0, B3 = 500.0 / 1113.0, B4 = 125.0 / 192.0, B5 = -2187.0 / 6784.0,
                    B6 = 11.0 / 84.0;
static const double D1 = -12715105075.0 / 11282082432.0, D3 = 87487479700.0 / 32700410799.0,
                    D4 = -10690763975.0 / 1880347072.0, D5 = 701980252875.0 / 199316789632.0,
                    D6 = -1453857185.0 / 822651844.0, D7 = 69997945.0 / 29380423.0;
static const double E1 = 71.0 / 57600.0, E3 = -71.0 / 16695.0, E4 = 71.0 / 1920.0, E5 = -17253.0 / 339200.0,
                    E6 = 22.0 / 525.0, E7 = -1.0 / 40.0;

/* the controller: h_new = h * SAFETY * err^-ALPHA * err_previous^BETA, the factor within
   [FAC_MIN, FAC_MAX]; no growth right after a rejected step */
static const double SAFETY = 0.9, BETA = 0.04, ALPHA = 0.2 - 0.75 * 0.04, FAC_MIN = 0.2, FAC_MAX = 10.0;
static const double ERR_FLOOR = 1e-4; /* the previous error the controller starts from, and its floor */

static int all_finite(int n, const double *v)
{
    for (int i = 0; i < n; ++i)
        if (!isfinite(v[i])) return 0;
    return 1;
}

/* Hairer's starting step: from the sizes of x0, f(x0) and an estimate of f's second derivative
   (one explicit Euler step, one more evaluation), a step whose error would be about 1% of the
   tolerance, at most 100 times the first guess and at most the interval. */
static double initial_step(Dopri5Rhs f, void *ctx, int n, double t0, double span, const double *x, const double *f0,
                           double rtol, double atol, double *y, double *f1, DopriStats *st)
{
    double d0 = 0.0, d1 = 0.0, d2 = 0.0;
    for (int i = 0; i < n; ++i) {
        const double sc = atol + rtol * fabs(x[i]);
        d0 += (x[i] / sc) * (x[i] / sc);
        d1 += (f0[i] / sc) * (f0[i] / sc);
    }
    d0 = sqrt(d0 / n);
    d1 = sqrt(d1 / n);
    double h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
    if (!(h0 > 0.0) || !isfinite(h0)) h0 = 1e-6; /* a norm overflowed (rates huge against the tolerance) */
    h0 = fmin(h0, span);
    for (int i = 0; i < n; ++i) y[i] = x[i] + h0 * f0[i];
    f(ctx, t0 + h0, y, f1);
    st->evaluations++;
    for (int i = 0; i < n; ++i) {
        const double sc = atol + rtol * fabs(x[i]), d = (f1[i] - f0[i]) / sc;
        d2 += d * d;
    }
    d2 = sqrt(d2 / n) / h0;
    const double big = fmax(d1, d2); /* fmax ignores a NaN d2 (f not finite after the Euler step) */
    const double h1 = big <= 1e-15 ? fmax(1e-6, 1e-3 * h0) : pow(0.01 / big, 0.2);
    const double h = fmin(100.0 * h0, h1);
    return isfinite(h) && h > 0.0 ? fmin(h, span) : h0;
}

/* the dense output of the step of size h from x (stages k1..k7, new state x_new) at the fraction theta
   of the step: Hairer's continuous extension of order 4 */
static void dense(int n, double theta, double h, const double *x, const double *x_new, const double *k1,
                  const double *k3, const double *k4, const double *k5, const double *k6, const double *k7,
                  double *out)
{
    const double s = 1.0 - theta;
    for (int i = 0; i < n; ++i) {
        const double r2 = x_new[i] - x[i], r3 = h * k1[i] - r2, r4 = r2 - h * k7[i] - r3;
        const double r5 = h * (D1 * k1[i] + D3 * k3[i] + D4 * k4[i] + D5 * k5[i] + D6 * k6[i] + D7 * k7[i]);
        out[i] = x[i] + theta * (r2 + s * (r3 + theta * (r4 + s * r5)));
    }
}

/* the integration proper, in the workspace `work` [10 n] */
static int integrate(Dopri5Rhs f, void *ctx, int n, double t0, double t1, double *x_out, double rtol, double atol,
                     double *h_guess, DopriStats *st, const Dopri5Events *events, Dopri5Observer observer,
                     void *observer_ctx, double *work)
{
    double *k1 = work, *k2 = k1 + n, *k3 = k2 + n, *k4 = k3 + n, *k5 = k4 + n, *k6 = k5 + n, *k7 = k6 + n;
    double *y = k7 + n, *x_new = y + n, *x = x_new + n;
    double t = t0, h, log_err_old = log(ERR_FLOOR);
    int rejected_last = 0, not_finite = 0;

    memcpy(x, x_out, (size_t)n * sizeof *x);
    if (events) events->lock(events->ctx, t, x);
    f(ctx, t, x, k1);
    st->evaluations++;
    if (!all_finite(n, x) || !all_finite(n, k1)) return DOPRI5_NOT_FINITE;
    if (h_guess && *h_guess > 0.0 && isfinite(*h_guess))
        h = *h_guess;
    else
        h = initial_step(f, ctx, n, t0, t1 - t0, x, k1, rtol, atol, y, k2, st);

    for (;;) {
        if (st->accepted + st->rejected >= DOPRI5_MAX_STEPS) return DOPRI5_TOO_MANY_STEPS;
        const double h_try = h;
        const int last = t + 1.01 * h >= t1; /* the step reaches (or nearly reaches) the end: it ends there */
        if (last)
            h = t1 - t;
        else if (h < 10.0 * DBL_EPSILON * fmax(fabs(t), fabs(t1)))
            return not_finite ? DOPRI5_NOT_FINITE : DOPRI5_STEP_UNDERFLOW;
        st->h_last = h;

        for (int i = 0; i < n; ++i) y[i] = x[i] + h * A21 * k1[i];
        f(ctx, t + C2 * h, y, k2);
        for (int i = 0; i < n; ++i) y[i] = x[i] + h * (A31 * k1[i] + A32 * k2[i]);
        f(ctx, t + C3 * h, y, k3);
        for (int i = 0; i < n; ++i) y[i] = x[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
        f(ctx, t + C4 * h, y, k4);
        for (int i = 0; i < n; ++i) y[i] = x[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
        f(ctx, t + C5 * h, y, k5);
        for (int i = 0; i < n; ++i)
            y[i] = x[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
        const double t_new = last ? t1 : t + h;
        f(ctx, t_new, y, k6);
        for (int i = 0; i < n; ++i)
            x_new[i] = x[i] + h * (B1 * k1[i] + B3 * k3[i] + B4 * k4[i] + B5 * k5[i] + B6 * k6[i]);
        f(ctx, t_new, x_new, k7);
        st->evaluations += 6;

        double sum = 0.0;
        for (int i = 0; i < n; ++i) {
            const double e = h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
            const double r = e / (atol + rtol * fmax(fabs(x[i]), fabs(x_new[i])));
            sum += r * r;
        }
        const double err = sqrt(sum / n);
        if (!isfinite(err) || !all_finite(n, x_new)) { /* a stage or the new state is not finite: try a smaller step */
            not_finite = 1;
            st->rejected++;
            rejected_last = 1;
            h *= FAC_MIN;
            continue;
        }
        not_finite = 0;
        const double log_err = log(err); /* -inf for err = 0: the factor below is then its maximum */
        if (err <= 1.0) {
            /* h_new = h / fac, fac = err^ALPHA / err_old^BETA / SAFETY, within [1/FAC_MAX, 1/FAC_MIN] */
            const double fac = fmax(1.0 / FAC_MAX, fmin(1.0 / FAC_MIN, exp(ALPHA * log_err - BETA * log_err_old) / SAFETY));
            double h_new = h / fac;
            if (rejected_last) h_new = fmin(h_new, h);
            log_err_old = log(fmax(err, ERR_FLOOR));
            st->accepted++;
            if (events && events->crossed(events->ctx, t_new, x_new)) {
                /* the locked branches stop holding within the step: bracket the first instant by
                   bisection on the dense output, end the step at the bracket's right end */
                double lo = t, hi = t_new;
                const double resolution = DOPRI5_EVENT_RESOLUTION * fmax(1.0, fabs(t_new));
                for (int it = 0; it < 200 && hi - lo > resolution; ++it) {
                    const double mid = lo + 0.5 * (hi - lo);
                    if (mid <= lo || mid >= hi) break;
                    dense(n, (mid - t) / h, h, x, x_new, k1, k3, k4, k5, k6, k7, y);
                    if (events->crossed(events->ctx, mid, y))
                        hi = mid;
                    else
                        lo = mid;
                }
                if (hi < t_new) {
                    dense(n, (hi - t) / h, h, x, x_new, k1, k3, k4, k5, k6, k7, y);
                    memcpy(x_new, y, (size_t)n * sizeof *x);
                }
                st->events++;
                if (observer) {
                    f(ctx, hi, x_new, k2); /* the rate at the step's end on the branches it was taken on */
                    st->evaluations++;
                    observer(observer_ctx, t, x, k1, hi, x_new, k2);
                }
                events->lock(events->ctx, hi, x_new);
                f(ctx, hi, x_new, k1); /* the new branches' rate: the next step's first stage */
                st->evaluations++;
                memcpy(x, x_new, (size_t)n * sizeof *x);
                if (!all_finite(n, k1)) return DOPRI5_NOT_FINITE;
                t = hi;
                rejected_last = 0;
                if (hi >= t1) {
                    double next = h < h_try ? fmax(h_new, h_try) : h_new;
                    if (h_guess) *h_guess = fmin(next, 10.0 * (t1 - t0));
                    memcpy(x_out, x, (size_t)n * sizeof *x);
                    return DOPRI5_OK;
                }
                h = h_new;
                continue;
            }
            if (observer) observer(observer_ctx, t, x, k1, t_new, x_new, k7);
            double *swap = k1;
            k1 = k7; /* first same as last */
            k7 = swap;
            memcpy(x, x_new, (size_t)n * sizeof *x);
            t = t_new;
            rejected_last = 0;
            if (last) {
                /* a step cut short to end at t1 says little about the next one: keep the longer of
                   the step tried and the one the controller proposes, at most 10 intervals */
                double next = h < h_try ? fmax(h_new, h_try) : h_new;
                if (h_guess) *h_guess = fmin(next, 10.0 * (t1 - t0));
                memcpy(x_out, x, (size_t)n * sizeof *x);
                return DOPRI5_OK;
            }
            h = h_new;
        } else {
            h /= fmin(1.0 / FAC_MIN, exp(ALPHA * log_err) / SAFETY);
            st->rejected++;
            rejected_last = 1;
        }
    }
}

int dopri5(Dopri5Rhs f, void *ctx, int n, double t0, double t1, double *x, double rtol, double atol,
           double *h_guess, DopriStats *stats)
{
    return dopri5_events(f, ctx, n, t0, t1, x, rtol, atol, h_guess, stats, NULL, NULL, NULL);
}

int dopri5_observed(Dopri5Rhs f, void *ctx, int n, double t0, double t1, double *x, double rtol, double atol,
                    double *h_guess, DopriStats *stats, Dopri5Observer observer, void *observer_ctx)
{
    return dopri5_events(f, ctx, n, t0, t1, x, rtol, atol, h_guess, stats, NULL, observer, observer_ctx);
}

int dopri5_events(Dopri5Rhs f, void *ctx, int n, double t0, double t1, double *x, double rtol, double atol,
                  double *h_guess, DopriStats *stats, const Dopri5Events *events, Dopri5Observer observer,
                  void *observer_ctx)
{
    DopriStats local;
    DopriStats *st = stats ? stats : &local;
    memset(st, 0, sizeof *st);
    if (!f || !x || n < 1 || !isfinite(t0) || !isfinite(t1) || t1 < t0 || !(rtol >= 10.0 * DBL_EPSILON) ||
        !isfinite(rtol) || !(atol > 0.0) || !isfinite(atol) || (events && (!events->crossed || !events->lock)))
        return DOPRI5_BAD_ARGUMENT;
    if (t1 == t0) return DOPRI5_OK;
    double stack[10 * DOPRI5_STACK_N], *work = stack;
    if (n > DOPRI5_STACK_N) {
        work = (double *)malloc(10 * (size_t)n * sizeof *work);
        if (!work) return DOPRI5_NO_MEMORY;
    }
    const int rc = integrate(f, ctx, n, t0, t1, x, rtol, atol, h_guess, st, events, observer, observer_ctx, work);
    if (work != stack) free(work);
    return rc;
}

const char *dopri5_message(int code)
{
    switch (code) {
    case DOPRI5_OK: return "success";
    case DOPRI5_BAD_ARGUMENT: return "invalid arguments (size, interval or tolerances)";
    case DOPRI5_STEP_UNDERFLOW: return "the step size fell below the resolution of the time";
    case DOPRI5_TOO_MANY_STEPS: return "more steps than the limit per call";
    case DOPRI5_NOT_FINITE: return "the state or its rate is not finite";
    case DOPRI5_NO_MEMORY: return "out of memory for the workspace";
    default: return "unknown error";
    }
}

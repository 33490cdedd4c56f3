/* Checks of the generic Dormand-Prince 5(4) integrator (fmu_export/c/dopri5.c) on problems with known
   solutions, its step size guess carried between calls, its workspace beyond the stack size, and its
   error codes. Prints one line per failed check; exit 0 when all hold.
   build: gcc -O2 -I fmu_export/c tests/c/dopri5_check.c fmu_export/c/dopri5.c -lm */
#include <math.h>
#include <stdio.h>

#include "dopri5.h"

static int failures;

#define CHECK(condition, ...)                  \
    do {                                       \
        if (!(condition)) {                    \
            ++failures;                        \
            printf("FAILED %s: ", #condition); \
            printf(__VA_ARGS__);               \
            printf("\n");                      \
        }                                      \
    } while (0)

static void oscillator(void *ctx, double t, const double *x, double *dx)
{
    (void)ctx;
    (void)t;
    dx[0] = x[1];
    dx[1] = -x[0];
}

/* x' = -k x + t (ctx: k per component), exact: x(t) = (x0 - 1/k^2) e^{-kt} + t/k - ... see exact_forced */
static void forced_decay(void *ctx, double t, const double *x, double *dx)
{
    const double *k = (const double *)ctx;
    for (int i = 0; i < 40; ++i) dx[i] = -k[i] * x[i] + t;
}

static double exact_forced(double x0, double k, double t)
{
    return (x0 + 1.0 / (k * k)) * exp(-k * t) + t / k - 1.0 / (k * k);
}

static void blow_up(void *ctx, double t, const double *x, double *dx)
{
    (void)ctx;
    (void)t;
    dx[0] = x[0] * x[0]; /* x = 1 / (1 - t): infinite at t = 1 */
}

static void not_a_number(void *ctx, double t, const double *x, double *dx)
{
    (void)ctx;
    (void)t;
    (void)x;
    dx[0] = NAN;
}

/* the observer's record: steps seen, whether they tile the interval, the worst cubic Hermite error
   of cos at the steps' midpoints */
typedef struct {
    long steps;
    double end, worst;
    int gaps;
} Seen;

static void observe(void *ctx, double t0, const double *x0, const double *f0, double t1, const double *x1,
                    const double *f1)
{
    Seen *seen = (Seen *)ctx;
    const double h = t1 - t0, mid = 0.5 * (x0[0] + x1[0]) + 0.125 * h * (f0[0] - f1[0]);
    seen->gaps += t0 != seen->end;
    seen->end = t1;
    seen->steps++;
    seen->worst = fmax(seen->worst, fabs(mid - cos(t0 + 0.5 * h)));
}

int main(void)
{
    DopriStats st;
    /* one call over [0, 10] and 1000 calls of 0.01 with the step size guess carried */
    double x[2] = {1.0, 0.0}, h = 0.0;
    int rc = dopri5(oscillator, NULL, 2, 0.0, 10.0, x, 1e-10, 1e-12, &h, &st);
    CHECK(rc == DOPRI5_OK, "rc %d", rc);
    CHECK(fabs(x[0] - cos(10.0)) < 1e-8 && fabs(x[1] + sin(10.0)) < 1e-8, "error %g", fabs(x[0] - cos(10.0)));
    CHECK(st.accepted > 10 && st.evaluations == 6 * (st.accepted + st.rejected) + 2, "stats %ld %ld %ld",
          st.accepted, st.rejected, st.evaluations);
    CHECK(h > 0.0 && h <= 100.0, "guess %g", h);
    double y[2] = {1.0, 0.0}, g = 0.0;
    long steps = 0, evaluations = 0;
    for (int k = 0; k < 1000; ++k) {
        rc = dopri5(oscillator, NULL, 2, 0.01 * k, 0.01 * (k + 1), y, 1e-10, 1e-12, &g, &st);
        CHECK(rc == DOPRI5_OK, "rc %d at chunk %d", rc, k);
        steps += st.accepted;
        evaluations += st.evaluations;
    }
    CHECK(fabs(y[0] - cos(10.0)) < 1e-8 && fabs(y[1] + sin(10.0)) < 1e-8, "chunked error %g", fabs(y[0] - cos(10.0)));
    CHECK(steps <= 1100 && evaluations <= 7 * steps + 2, "carried guess: %ld steps, %ld evaluations", steps,
          evaluations);

    /* every accepted step observed, end to end */
    double o[2] = {1.0, 0.0}, ho = 0.0;
    Seen seen = {0, 0.0, 0.0, 0};
    rc = dopri5_observed(oscillator, NULL, 2, 0.0, 10.0, o, 1e-10, 1e-12, &ho, &st, observe, &seen);
    CHECK(rc == DOPRI5_OK && seen.steps == st.accepted && !seen.gaps && seen.end == 10.0, "observed %ld of %ld, "
          "gaps %d, end %g", seen.steps, st.accepted, seen.gaps, seen.end);
    CHECK(o[0] == x[0] && o[1] == x[1], "observing changed the answer");
    CHECK(seen.worst < 1e-6, "Hermite midpoint error %g", seen.worst);

    /* 40 components (beyond the stack workspace), time-dependent rate */
    double k40[40], x40[40], h40 = 0.0;
    for (int i = 0; i < 40; ++i) {
        k40[i] = 0.5 + i;
        x40[i] = 1.0 - 0.05 * i;
    }
    rc = dopri5(forced_decay, k40, 40, 0.0, 2.0, x40, 1e-10, 1e-12, &h40, NULL);
    CHECK(rc == DOPRI5_OK, "rc %d", rc);
    double worst = 0.0;
    for (int i = 0; i < 40; ++i) worst = fmax(worst, fabs(x40[i] - exact_forced(1.0 - 0.05 * i, k40[i], 2.0)));
    CHECK(worst < 1e-8, "forced decay error %g", worst);

    /* an empty interval, no guess pointer */
    double z[2] = {0.3, 0.4};
    CHECK(dopri5(oscillator, NULL, 2, 1.0, 1.0, z, 1e-8, 1e-10, NULL, NULL) == DOPRI5_OK && z[0] == 0.3, "empty");
    CHECK(dopri5(oscillator, NULL, 2, 0.0, 1.0, z, 1e-8, 1e-10, NULL, NULL) == DOPRI5_OK, "no guess");

    /* refusals leave x and the guess alone */
    double w[1] = {1.0}, hw = 0.125;
    CHECK(dopri5(blow_up, NULL, 0, 0.0, 1.0, w, 1e-8, 1e-10, &hw, NULL) == DOPRI5_BAD_ARGUMENT, "n = 0");
    CHECK(dopri5(blow_up, NULL, 1, 1.0, 0.0, w, 1e-8, 1e-10, &hw, NULL) == DOPRI5_BAD_ARGUMENT, "t1 < t0");
    CHECK(dopri5(blow_up, NULL, 1, 0.0, NAN, w, 1e-8, 1e-10, &hw, NULL) == DOPRI5_BAD_ARGUMENT, "NaN t1");
    CHECK(dopri5(blow_up, NULL, 1, 0.0, 1.0, w, 1e-17, 1e-10, &hw, NULL) == DOPRI5_BAD_ARGUMENT, "rtol");
    CHECK(dopri5(blow_up, NULL, 1, 0.0, 1.0, w, 1e-8, 0.0, &hw, NULL) == DOPRI5_BAD_ARGUMENT, "atol");
    CHECK(dopri5(NULL, NULL, 1, 0.0, 1.0, w, 1e-8, 1e-10, &hw, NULL) == DOPRI5_BAD_ARGUMENT, "no f");
    rc = dopri5(blow_up, NULL, 1, 0.0, 2.0, w, 1e-8, 1e-10, &hw, &st);
    CHECK(rc == DOPRI5_STEP_UNDERFLOW || rc == DOPRI5_TOO_MANY_STEPS || rc == DOPRI5_NOT_FINITE, "blow-up rc %d", rc);
    CHECK(w[0] == 1.0 && hw == 0.125, "blow-up changed x %g or the guess %g", w[0], hw);
    rc = dopri5(not_a_number, NULL, 1, 0.0, 1.0, w, 1e-8, 1e-10, &hw, NULL);
    CHECK(rc == DOPRI5_NOT_FINITE && w[0] == 1.0, "NaN rate rc %d", rc);
    CHECK(dopri5(oscillator, NULL, 2, 0.0, 1e9, x, 1e-12, 1e-14, &h, &st) == DOPRI5_TOO_MANY_STEPS,
          "a billion seconds of oscillation");
    CHECK(st.accepted + st.rejected == DOPRI5_MAX_STEPS, "stopped after %ld steps", st.accepted + st.rejected);
    for (int code = 0; code >= -6; --code) CHECK(dopri5_message(code)[0] != '\0', "message %d", code);

    if (!failures) printf("ok\n");
    return failures ? 1 : 0;
}

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

/* a lag x' = u(t) - x (T = 1 s) of u(t) = 3 - t with a non-windup upper limit 1 (ANDES' LagAntiWindup),
   its branches locked between events: mode[0] = (x >= 1), mode[1] = (rate > 0). Exact from x(0) = 0:
   x = 4 - t - 4 e^-t up to t_hit (x = 1), held at 1 until t = 2 (the rate u - x turns negative), then
   x = 4 - t - e^-(t - 2). */
typedef struct {
    int mode[2];
    int locks;
    double lock_time[8];
} Limited;

static const double T_HIT_GUESS = 0.45; /* s: near the root of 4 - t - 4 e^-t = 1, refined in main */

static void limited_rhs_modes(const int mode[2], double t, const double *x, double *dx)
{
    const double rate = 3.0 - t - x[0];
    dx[0] = mode[0] ? (mode[1] ? 0.0 : rate) : rate;
}

static void limited_modes(double t, const double *x, int mode[2])
{
    mode[0] = x[0] >= 1.0;
    mode[1] = 3.0 - t - x[0] > 0.0;
}

static void limited_rhs(void *ctx, double t, const double *x, double *dx)
{
    limited_rhs_modes(((Limited *)ctx)->mode, t, x, dx);
}

static int limited_crossed(void *ctx, double t, const double *x)
{
    const Limited *l = (const Limited *)ctx;
    int now[2];
    double a, b;
    limited_modes(t, x, now);
    if (now[0] == l->mode[0] && now[1] == l->mode[1]) return 0;
    limited_rhs_modes(l->mode, t, x, &a);
    limited_rhs_modes(now, t, x, &b);
    return a != b;
}

static void limited_lock(void *ctx, double t, const double *x)
{
    Limited *l = (Limited *)ctx;
    limited_modes(t, x, l->mode);
    if (l->locks < 8) l->lock_time[l->locks] = t;
    l->locks++;
}

/* the same lag with its conditions evaluated as they are met (no locking, no event location) */
static void limited_live(void *ctx, double t, const double *x, double *dx)
{
    int mode[2];
    (void)ctx;
    limited_modes(t, x, mode);
    limited_rhs_modes(mode, t, x, dx);
}

static double limited_exact(double t, double t_hit)
{
    if (t <= t_hit) return 4.0 - t - 4.0 * exp(-t);
    if (t <= 2.0) return 1.0;
    return 4.0 - t - exp(-(t - 2.0));
}

/* the observer's record of the limited lag: as Seen, the Hermite error against limited_exact */
typedef struct {
    Seen seen;
    double t_hit;
} SeenLimited;

static void observe_limited(void *ctx, double t0, const double *x0, const double *f0, double t1, const double *x1,
                            const double *f1)
{
    SeenLimited *s = (SeenLimited *)ctx;
    const double h = t1 - t0, mid = 0.5 * (x0[0] + x1[0]) + 0.125 * h * (f0[0] - f1[0]);
    s->seen.gaps += t0 != s->seen.end;
    s->seen.end = t1;
    s->seen.steps++;
    s->seen.worst = fmax(s->seen.worst, fabs(mid - limited_exact(t0 + 0.5 * h, s->t_hit)));
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

    /* a non-windup limit: the state stops at the limit at the located instant, is held without
       chattering, leaves it when its rate turns back; two events, a bounded number of steps */
    double t_hit = T_HIT_GUESS;
    for (int k = 0; k < 50; ++k) /* Newton on 3 - t - 4 e^-t = 0 */
        t_hit -= (3.0 - t_hit - 4.0 * exp(-t_hit)) / (-1.0 + 4.0 * exp(-t_hit));
    Limited lim = {{0, 0}, 0, {0.0}};
    const Dopri5Events ev = {limited_crossed, limited_lock, &lim};
    double xl[1] = {0.0}, hl = 0.0;
    rc = dopri5_events(limited_rhs, &lim, 1, 0.0, 4.0, xl, 1e-10, 1e-12, &hl, &st, &ev, NULL, NULL);
    CHECK(rc == DOPRI5_OK && fabs(xl[0] - limited_exact(4.0, t_hit)) < 1e-9, "rc %d, x(4) error %g", rc,
          xl[0] - limited_exact(4.0, t_hit));
    CHECK(st.events == 2 && lim.locks == 3, "events %ld, locks %d", st.events, lim.locks);
    CHECK(fabs(lim.lock_time[1] - t_hit) < 1e-11 && fabs(lim.lock_time[2] - 2.0) < 1e-11,
          "located at %.15g (exact %.15g) and %.15g (exact 2)", lim.lock_time[1], t_hit, lim.lock_time[2]);
    CHECK(st.accepted <= 120 && st.rejected <= 6, "%ld steps, %ld rejected", st.accepted, st.rejected);

    /* in communication steps of 10 ms: held at the limit within 1e-11, the same two events */
    Limited chunked = {{0, 0}, 0, {0.0}};
    const Dopri5Events ev_chunked = {limited_crossed, limited_lock, &chunked};
    double xc[1] = {0.0}, hc = 0.0, largest = 0.0, highest = 0.0;
    long events = 0, accepted = 0, rejected = 0;
    for (int k = 0; k < 400; ++k) {
        rc = dopri5_events(limited_rhs, &chunked, 1, 0.01 * k, 0.01 * (k + 1), xc, 1e-10, 1e-12, &hc, &st,
                           &ev_chunked, NULL, NULL);
        CHECK(rc == DOPRI5_OK, "rc %d at chunk %d", rc, k);
        events += st.events;
        accepted += st.accepted;
        rejected += st.rejected;
        largest = fmax(largest, fabs(xc[0] - limited_exact(0.01 * (k + 1), t_hit)));
        highest = fmax(highest, xc[0]);
    }
    CHECK(events == 2 && largest < 1e-9 && highest <= 1.0 + 1e-11, "events %ld, worst error %g, highest %.17g",
          events, largest, highest);
    CHECK(accepted <= 400 + 40 && rejected <= 4, "%ld steps, %ld rejected", accepted, rejected);

    /* the same lag with its conditions evaluated as they are met (plain dopri5): it steps through the
       kinks by rejections (31 here), event location needs none of them */
    const long located_rejections = rejected;
    double xv[1] = {0.0}, hv = 0.0;
    rc = dopri5(limited_live, NULL, 1, 0.0, 4.0, xv, 1e-10, 1e-12, &hv, &st);
    CHECK(rc == DOPRI5_OK && st.rejected > located_rejections + 10, "live: rc %d, %ld steps, %ld rejected", rc,
          st.accepted, st.rejected);

    /* every accepted step observed with events: the steps tile [0, 4], each ends at a located event
       where there is one, with the rate of the branches it was taken on (Hermite error small) */
    Limited observed = {{0, 0}, 0, {0.0}};
    const Dopri5Events ev_observed = {limited_crossed, limited_lock, &observed};
    SeenLimited seen_limited = {{0, 0.0, 0.0, 0}, t_hit};
    double xo[1] = {0.0}, ho_lim = 0.0;
    rc = dopri5_events(limited_rhs, &observed, 1, 0.0, 4.0, xo, 1e-10, 1e-12, &ho_lim, &st, &ev_observed,
                       observe_limited, &seen_limited);
    CHECK(rc == DOPRI5_OK && xo[0] == xl[0] && seen_limited.seen.steps == st.accepted && !seen_limited.seen.gaps &&
          seen_limited.seen.end == 4.0 && seen_limited.seen.worst < 1e-6, "observed %ld of %ld, gaps %d, end %g, "
          "Hermite error %g", seen_limited.seen.steps, st.accepted, seen_limited.seen.gaps, seen_limited.seen.end,
          seen_limited.seen.worst);

    /* a bad events structure is refused */
    const Dopri5Events no_lock = {limited_crossed, NULL, &lim};
    rc = dopri5_events(limited_rhs, &lim, 1, 0.0, 1.0, xl, 1e-10, 1e-12, NULL, NULL, &no_lock, NULL, NULL);
    CHECK(rc == DOPRI5_BAD_ARGUMENT, "rc %d", rc);
    if (!failures) printf("ok\n");
    return failures ? 1 : 0;
}

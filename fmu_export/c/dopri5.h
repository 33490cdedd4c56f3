/* A generic explicit Runge-Kutta integrator: Dormand-Prince 5(4) with local extrapolation (the
   5th-order solution is propagated, the embedded 4th-order one estimates the error), first same as
   last (6 right-hand sides per step), a PI step-size controller and Hairer's initial step guess.
   Optional event location (dopri5_events): a right-hand side with branches (limits, switches) locked
   within each step, the first instant within an accepted step where they stop holding located on
   the step's dense output, the step ended there and the integration restarted with the branches
   that hold. libc and libm only; no global state (reentrant).

       double x[2] = {1.0, 0.0}, h = 0.0;   (h: the step size guess, 0: none yet)
       DopriStats stats;
       int rc = dopri5(f, ctx, 2, 0.0, 1.0, x, 1e-8, 1e-10, &h, &stats);
       if (rc != DOPRI5_OK) fprintf(stderr, "%s\n", dopri5_message(rc));

   The error of a step is the RMS over the components of (error estimate) / (atol + rtol *
   max(|x_i| before, |x_i| after)); a step is accepted when it is at most 1. */
#ifndef OPFMU_DOPRI5_H
#define OPFMU_DOPRI5_H

/* not exported from a shared library unless compiled with -DDOPRI5_EXPORT (an FMU's binary exports
   its FMI functions only; a program that links dopri5.c in needs nothing; on Windows only what is
   declared dllexport is exported) */
#ifndef DOPRI5_API
#if defined(__GNUC__) && !defined(_WIN32) && !defined(DOPRI5_EXPORT)
#define DOPRI5_API __attribute__((visibility("hidden")))
#else
#define DOPRI5_API
#endif
#endif

/* right-hand side: dx = f(t, x), n components; ctx is passed through */
typedef void (*Dopri5Rhs)(void *ctx, double t, const double *x, double *dx);

typedef struct {
    long accepted;    /* steps accepted */
    long rejected;    /* steps rejected (error above the tolerance, or a non-finite stage) */
    long evaluations; /* right-hand side evaluations */
    long events;      /* steps ended at a located change of the locked branches (dopri5_events) */
    double h_last;    /* the last step size tried [time units] */
} DopriStats;

enum {
    DOPRI5_OK = 0,
    DOPRI5_BAD_ARGUMENT = -1,   /* n < 1, NULL x or f, t1 < t0 or not finite, a tolerance not usable */
    DOPRI5_STEP_UNDERFLOW = -2, /* the step size fell below what the time's precision resolves */
    DOPRI5_TOO_MANY_STEPS = -3, /* more than DOPRI5_MAX_STEPS steps (accepted and rejected) */
    DOPRI5_NOT_FINITE = -4,     /* the state or its rate is not finite, and smaller steps do not help */
    DOPRI5_NO_MEMORY = -5       /* workspace for n > DOPRI5_STACK_N could not be allocated */
};

#ifndef DOPRI5_MAX_STEPS
#define DOPRI5_MAX_STEPS 100000L /* per call */
#endif
#ifndef DOPRI5_STACK_N
#define DOPRI5_STACK_N 16 /* systems up to this size need no heap */
#endif

/* Integrates x' = f(t, x) from t0 to t1 (t1 >= t0), x [n] in place: on DOPRI5_OK it holds x(t1); on
   failure it is unchanged. rtol >= 10 * DBL_EPSILON, atol > 0. *h_guess: the first step to try (<= 0
   or NULL: Hairer's initial guess from f); on success the step size to try next (carry it to the next
   call to continue where this one left off), on failure unchanged. stats may be NULL. Returns
   DOPRI5_OK or an error code. */
DOPRI5_API int dopri5(Dopri5Rhs f, void *ctx, int n, double t0, double t1, double *x, double rtol, double atol,
           double *h_guess, DopriStats *stats);

/* called after each accepted step from t0 to t1 with the states and their rates at both ends (for dense
   output between them, e.g. cubic Hermite interpolation); the arrays are valid during the call only */
typedef void (*Dopri5Observer)(void *ctx, double t0, const double *x0, const double *f0, double t1,
                               const double *x1, const double *f1);

/* dopri5 with an observer of every accepted step (observer NULL: dopri5 itself) */
DOPRI5_API int dopri5_observed(Dopri5Rhs f, void *ctx, int n, double t0, double t1, double *x, double rtol,
                               double atol, double *h_guess, DopriStats *stats, Dopri5Observer observer,
                               void *observer_ctx);

/* Event location. The right-hand side f takes branches locked by `lock` (e.g. the side of each
   limit, the truth of each condition of its equations), so f is smooth between two locks.
   crossed(ctx, t, x): nonzero where, at (t, x), the branches that hold differ from the locked ones in a
   way that changes f (a change that leaves f as it is may be ignored). lock(ctx, t, x): locks f to
   the branches that hold at (t, x). dopri5_events locks at t0, and after each accepted step whose end
   is `crossed` brackets the first such instant by bisection on the step's dense output (Hairer's
   continuous extension of order 4) to DOPRI5_EVENT_RESOLUTION * max(1, |t|), ends the step at the
   bracket's right end (where `crossed` holds), locks there and restarts from that point. A change
   that starts and ends within one step goes unseen. */
typedef struct {
    int (*crossed)(void *ctx, double t, const double *x);
    void (*lock)(void *ctx, double t, const double *x);
    void *ctx;
} Dopri5Events;

#ifndef DOPRI5_EVENT_RESOLUTION
#define DOPRI5_EVENT_RESOLUTION 1e-12 /* the width of the bracket a crossing is located to, relative to max(1, |t|) */
#endif

/* dopri5 with event location (events NULL: none) and an observer of every accepted step (which ends
   at a located event where there is one) */
DOPRI5_API int dopri5_events(Dopri5Rhs f, void *ctx, int n, double t0, double t1, double *x, double rtol,
                             double atol, double *h_guess, DopriStats *stats, const Dopri5Events *events,
                             Dopri5Observer observer, void *observer_ctx);

/* one line saying what an error code of dopri5 means */
DOPRI5_API const char *dopri5_message(int code);

#endif

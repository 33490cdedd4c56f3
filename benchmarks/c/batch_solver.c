/* Whole trajectories of a component by the FMU's Dormand-Prince 5(4), with dense output on a grid:
   the compiled-solver rows of benchmarks/inference_speed.py.

   Compiled with the component's generated equations (model_derivatives, N_STATES, N_INPUTS from the
   including unit) and fmu_export/c/dopri5.c. Inputs are the closed-form channels of
   reference_models/signals.py that have no breakpoints (FirstOrder, SecondOrder: the paper's
   families; a constant: a Piecewise without breakpoints, as they hold Pm and Efd), so the solver sees exactly the signal scipy's rows see. States between the solver's
   steps come from cubic Hermite interpolation of the states and rates at both ends of a step. */
#include <math.h>
#include <string.h>

#include "dopri5.h"

enum { FIRST_ORDER = 0, SECOND_ORDER = 1, CONSTANT = 2 };

typedef struct {
    const double *channels; /* per input: kind, then 5 parameters (see channel_value) */
    const double *grid;     /* output times [S], ascending from t0 */
    int n_grid, next;       /* grid size, the next grid index to fill */
    double *out;            /* states [S, N_STATES] */
} Trajectory;

/* y(t) of one channel: FirstOrder (y0, k, A, w, y_ref), SecondOrder (y0, dy0, zeta, wn, y_ref) or a
   constant (y0) */
static double channel_value(const double *c, double t)
{
    if ((int)c[0] == CONSTANT) return c[1];
    if ((int)c[0] == FIRST_ORDER) {
        const double y0 = c[1], k = c[2], A = c[3], w = c[4], y_ref = c[5], kw2 = k * k + w * w;
        return y_ref + (y0 - y_ref + A * w / kw2) * exp(-k * t) + A * (k * sin(w * t) - w * cos(w * t)) / kw2;
    }
    const double y0 = c[1], dy0 = c[2], zeta = c[3], wn = c[4], y_ref = c[5];
    const double wd = wn * sqrt(1.0 - zeta * zeta), c1 = y0 - y_ref, c2 = (dy0 + zeta * wn * c1) / wd;
    return y_ref + exp(-zeta * wn * t) * (c1 * cos(wd * t) + c2 * sin(wd * t));
}

static void rhs(void *ctx, double t, const double *x, double *dx)
{
    const Trajectory *tr = (const Trajectory *)ctx;
    double u[N_INPUTS];
    for (int c = 0; c < N_INPUTS; ++c) u[c] = channel_value(tr->channels + 6 * c, t);
    model_derivatives(x, u, dx);
}

/* after each accepted step [t0, t1]: the grid times in (t0, t1] by cubic Hermite interpolation */
static void fill(void *ctx, double t0, const double *x0, const double *f0, double t1, const double *x1,
                 const double *f1)
{
    Trajectory *tr = (Trajectory *)ctx;
    const double h = t1 - t0;
    while (tr->next < tr->n_grid && tr->grid[tr->next] <= t1) {
        const double s = (tr->grid[tr->next] - t0) / h, s2 = s * s, s3 = s2 * s;
        const double h00 = 2 * s3 - 3 * s2 + 1, h10 = s3 - 2 * s2 + s, h01 = -2 * s3 + 3 * s2, h11 = s3 - s2;
        double *y = tr->out + (size_t)tr->next * N_STATES;
        for (int i = 0; i < N_STATES; ++i) y[i] = h00 * x0[i] + h10 * h * f0[i] + h01 * x1[i] + h11 * h * f1[i];
        tr->next++;
    }
}

/* n trajectories: x0 [n, N_STATES], channels [n, N_INPUTS, 6], grid [S] from 0; out [n, S, N_STATES].
   Returns 0, or the dopri5 error code of the first trajectory that failed; *evaluations: right-hand
   side evaluations in all. */
OPFMU_BENCH_API int solve_batch(int n, const double *x0, const double *channels, int n_grid, const double *grid,
                                double rtol, double atol, double *out, long *evaluations)
{
    *evaluations = 0;
    for (int k = 0; k < n; ++k) {
        double x[N_STATES], h = 0.0;
        DopriStats stats;
        Trajectory tr = {channels + (size_t)k * N_INPUTS * 6, grid, n_grid, 1, out + (size_t)k * n_grid * N_STATES};
        memcpy(x, x0 + (size_t)k * N_STATES, sizeof x);
        memcpy(tr.out, x, sizeof x);
        int rc = dopri5_observed(rhs, &tr, N_STATES, grid[0], grid[n_grid - 1], x, rtol, atol, &h, &stats, fill, &tr);
        *evaluations += stats.evaluations;
        if (rc != DOPRI5_OK) return rc;
    }
    return 0;
}

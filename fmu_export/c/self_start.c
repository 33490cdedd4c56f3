/* Self-initialisation of a native FMU, reference or surrogate, from the load flow (fmu_export/self_start.py says
   which components have it and what they solve). Unknowns z = (x, s): the states and the inputs the
   start solves (SELF_START_SOLVES). Equations:
       dx/dt (x, u) = 0                        the component's right-hand side (its start equations where
                                               it has its own: OPFMU_HAS_START_EQUATIONS), a learned
                                               state's left out (SELF_START_RATE_ROWS)
       P_bus = P_lf, Q_bus = Q_lf              where SELF_START_LOAD_FLOW (system base, generator convention)
       y_k = y_k_init                          each delivered output or state (SELF_START_DELIVERS)
   with the bus voltage inputs at V_lf, theta_lf and every other input as the importer set it. The solved
   inputs take their solved values; the bus voltage inputs keep what the importer set, V_lf and theta_lf
   where it set nothing.

   Newton's method with the exact Jacobians (component_rhs_jacobian, component_output_jacobian), each
   row scaled to a largest entry of 1, by full steps that each halve the scaled residual at least. It is continued
   in lambda from the anchor (lambda = 0: a start solved at build time at the built parameters, with
   its inputs, load flow and delivered values: SELF_START_ANCHOR_*) to what the importer set
   (lambda = 1), everything blended linearly between the two, in steps of at most LARGEST_LAMBDA_STEP: a
   lambda step on which Newton fails is cut by 4, one on which it succeeds doubles the next. A state the equations hold and read nowhere
   (SELF_START_INERT: a lag with T = 0) has the equation x = its anchor value. Parameters of one structure
   (the same structural predicates: fmu_export.c_parameters) stay in it when blended, as their
   predicates are linear in them. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "linalg.h"
#include "model.h"
#ifdef OPFMU_HAS_RESET
#include "switching.h"
#endif
#include "variables.h"

#define N_X OPFMU_N_STATES
#define N_U OPFMU_N_INPUTS
#define N_S SELF_START_N_SOLVES
#define N_D SELF_START_N_DELIVERS
#define N_Z (N_X + N_S)
#define N_R SELF_START_N_RATE_ROWS /* rows of the states' own equations: N_Z less the load flow's and the delivered */
#define N_Y (OPFMU_N_OUTPUTS > 0 ? OPFMU_N_OUTPUTS : 1)
#define D_SIZE (N_D > 0 ? N_D : 1)

#define MAX_ITERATIONS 12 /* a lambda step taking more, or a damped Newton step, is cut (no jump to another branch) */
#define STEP_TOLERANCE 1e-13   /* converged: the last full Newton step below this times 1 + |z| */
#define PATH_TOLERANCE 1e-8    /* the same on the way to lambda = 1 */
#define RESIDUAL_TOLERANCE 1e-10 /* accepted: each scaled residual below this times 1 + |z| */
#define LARGEST_LAMBDA_STEP 0.125 /* at least 8 steps from the anchor: each a short way along one branch */
#define SMALLEST_LAMBDA_STEP 1e-4

/* the system at one lambda: parameters (derived ones included), inputs (the solved ones overwritten
   from z), the load flow V_lf, theta_lf, P_lf, Q_lf and the delivered values */
typedef struct {
    double p[OPFMU_P_SIZE];
    double u[N_U];
    double flow[4];
    double target[D_SIZE];
} System;

static double blend(double start, double end, double lambda) { return (1.0 - lambda) * start + lambda * end; }

static void system_at(const ModelState *m, double lambda, System *q)
{
    for (int i = 0; i < OPFMU_N_PARAMS; ++i) q->p[i] = blend(OPFMU_PARAM_START[i], m->p[i], lambda);
    model_derive(q->p);
    for (int c = 0; c < N_U; ++c) q->u[c] = blend(SELF_START_ANCHOR_U[c], m->u[c], lambda);
    for (int k = 0; k < 4; ++k) q->flow[k] = blend(SELF_START_ANCHOR_FLOW[k], m->start.flow[k], lambda);
    for (int k = 0; k < N_D; ++k) q->target[k] = blend(SELF_START_ANCHOR_DELIVERED[k], m->start.delivered[k], lambda);
#if SELF_START_LOAD_FLOW
    q->u[BUS_VOLTAGE_MAGNITUDE] = q->flow[0];
    q->u[BUS_VOLTAGE_ANGLE] = q->flow[1];
#endif
}

/* x and u at unknowns z */
static void unpack(const System *q, const double z[N_Z], double x[OPFMU_X_SIZE], double u[N_U])
{
    memset(x, 0, OPFMU_X_SIZE * sizeof *x);
    memcpy(x, z, N_X * sizeof *x);
    memcpy(u, q->u, sizeof q->u);
    for (int k = 0; k < N_S; ++k) u[SELF_START_SOLVES[k]] = z[N_X + k];
}

/* the residual r [N_Z] at z and, unless J is NULL, its Jacobian J[i * N_Z + j] = d r_i / d z_j */
static void residual(const System *q, const double z[N_Z], double r[N_Z], double *J)
{
    double x[OPFMU_X_SIZE], u[N_U], dx[OPFMU_X_SIZE], y[N_Y];
    unpack(q, z, x, u);
#ifdef OPFMU_HAS_START_EQUATIONS
    model_start_equations(x, u, q->p, dx);
#else
    model_derivatives(x, u, q->p, dx);
#endif
    model_outputs(x, u, q->p, y);
    for (int k = 0; k < N_R; ++k) {
        const int i = SELF_START_RATE_ROWS[k];
        r[k] = SELF_START_INERT[i] ? x[i] - SELF_START_ANCHOR_X[i] : dx[i];
    }
    int row = N_R;
#if SELF_START_LOAD_FLOW
    const double v_re = q->flow[0] * cos(q->flow[1]), v_im = q->flow[0] * sin(q->flow[1]);
    const int i_re = (int)(VR_BUS_CURRENT_REAL - VR_FIRST_OUTPUT), i_im = (int)(VR_BUS_CURRENT_IMAGINARY - VR_FIRST_OUTPUT);
    r[row++] = v_re * y[i_re] + v_im * y[i_im] - q->flow[2];
    r[row++] = v_im * y[i_re] - v_re * y[i_im] - q->flow[3];
#endif
    for (int k = 0; k < N_D; ++k) {
        const int at = SELF_START_DELIVERS[k];
        r[row++] = (at >= 0 ? y[at] : x[-1 - at]) - q->target[k];
    }
    if (!J) return;
    double Jf[OPFMU_X_SIZE * OPFMU_N_COLUMNS], Jy[N_Y * OPFMU_N_COLUMNS];
#ifdef OPFMU_HAS_START_EQUATIONS
    component_start_jacobian(x, u, q->p, Jf);
#else
    component_rhs_jacobian(x, u, q->p, Jf);
#endif
    component_output_jacobian(x, u, q->p, Jy);
    int column[N_Z]; /* z_j's column in the component's Jacobians (states, then inputs) */
    for (int j = 0; j < N_X; ++j) column[j] = j;
    for (int k = 0; k < N_S; ++k) column[N_X + k] = N_X + SELF_START_SOLVES[k];
    for (int j = 0; j < N_Z; ++j) {
        const int c = column[j];
        for (int k = 0; k < N_R; ++k) {
            const int i = SELF_START_RATE_ROWS[k];
            J[k * N_Z + j] = SELF_START_INERT[i] ? (double)(i == j) : Jf[i * OPFMU_N_COLUMNS + c];
        }
        row = N_R;
#if SELF_START_LOAD_FLOW
        const double di_re = Jy[i_re * OPFMU_N_COLUMNS + c], di_im = Jy[i_im * OPFMU_N_COLUMNS + c];
        J[row++ * N_Z + j] = v_re * di_re + v_im * di_im;
        J[row++ * N_Z + j] = v_im * di_re - v_re * di_im;
#endif
        for (int k = 0; k < N_D; ++k) {
            const int at = SELF_START_DELIVERS[k];
            J[row++ * N_Z + j] = at >= 0 ? Jy[at * OPFMU_N_COLUMNS + c] : (double)(j == -1 - at);
        }
    }
}

static double largest(const double *v, int n)
{
    double most = 0.0;
    for (int i = 0; i < n; ++i) most = fmax(most, fabs(v[i]));
    return most;
}

/* the largest residual, each divided by its row's scale (INFINITY where a residual is not finite) */
static double scaled_residual(const double r[N_Z], const double scale[N_Z])
{
    double most = 0.0;
    for (int i = 0; i < N_Z; ++i) {
        const double v = fabs(r[i]) / scale[i];
        if (!isfinite(v)) return INFINITY;
        most = fmax(most, v);
    }
    return most;
}

/* row i of J where the exact one is zero: a rest on the kink of a clip (HYGOV4's gate rate at its
   closing limit 0 at rest), where the branch taken gives no slope. The one-sided difference
   quotients on the side that has one (the larger row), each unknown moved by 1e-7 (1 + |z_j|). */
static void kink_row(const System *q, const double z[N_Z], const double r[N_Z], int i, double *row)
{
    double moved[N_Z], rm[N_Z], sides[2][N_Z];
    for (int side = 0; side < 2; ++side) {
        for (int j = 0; j < N_Z; ++j) {
            const double step = (side ? -1e-7 : 1e-7) * (1.0 + fabs(z[j]));
            memcpy(moved, z, sizeof moved);
            moved[j] += step;
            residual(q, moved, rm, NULL);
            sides[side][j] = (rm[i] - r[i]) / step;
        }
    }
    memcpy(row, sides[largest(sides[1], N_Z) > largest(sides[0], N_Z)], N_Z * sizeof *row);
}

/* Newton from z to a solution of the system q, within `tolerance` (relative step), by full steps that
   each reduce the scaled residual; 1 on success (z the solution), 0 otherwise (z unchanged): a step
   that does not reduce it means z lies too far from the solution to tell its branch */
static int newton(const System *q, double z[N_Z], double tolerance)
{
    double w[N_Z], r[N_Z], J[N_Z * N_Z], scale[N_Z], b[N_Z], dz[N_Z], trial[N_Z];
    int perm[N_Z];
    memcpy(w, z, sizeof w);
    for (int iteration = 0; iteration < MAX_ITERATIONS; ++iteration) {
        residual(q, w, r, J);
        for (int i = 0; i < N_Z; ++i) {
            if (largest(&J[i * N_Z], N_Z) == 0.0) kink_row(q, w, r, i, &J[i * N_Z]);
            scale[i] = largest(&J[i * N_Z], N_Z);
            if (!(scale[i] > 0.0) || !isfinite(scale[i])) return 0;
            for (int j = 0; j < N_Z; ++j) J[i * N_Z + j] /= scale[i];
            b[i] = -r[i] / scale[i];
        }
        const double now = scaled_residual(r, scale);
        if (!isfinite(now)) return 0;
        if (now <= 1e-15 * (1.0 + largest(w, N_Z))) break;
        if (!lu_factor_n(J, N_Z, perm)) return 0;
        lu_solve_n(J, N_Z, perm, b, dz);
        for (int j = 0; j < N_Z; ++j) trial[j] = w[j] + dz[j];
        residual(q, trial, r, NULL);
        const double then = scaled_residual(r, scale);
        if (!(then <= 0.5 * now || then <= 1e-14 * (1.0 + largest(trial, N_Z)))) return 0;
        memcpy(w, trial, sizeof w);
        if (largest(dz, N_Z) <= tolerance * (1.0 + largest(w, N_Z))) break;
        if (iteration == MAX_ITERATIONS - 1) return 0;
    }
    residual(q, w, r, J); /* accepted only where every scaled residual is small */
    for (int i = 0; i < N_Z; ++i) {
        if (largest(&J[i * N_Z], N_Z) == 0.0) kink_row(q, w, r, i, &J[i * N_Z]);
        scale[i] = largest(&J[i * N_Z], N_Z);
    }
    if (!(scaled_residual(r, scale) <= RESIDUAL_TOLERANCE * (1.0 + largest(w, N_Z)))) return 0;
    memcpy(z, w, sizeof w);
    return 1;
}

/* "V_lf = ... pu, ..., Efd_init = ..." of the start asked for */
static void describe_start(const ModelState *m, char *text, size_t size)
{
    size_t used = 0;
    text[0] = '\0';
#if SELF_START_LOAD_FLOW
    used += (size_t)snprintf(text, size, "V_lf = %g pu, theta_lf = %g rad, P_lf = %g pu, Q_lf = %g pu", m->start.flow[0],
                             m->start.flow[1], m->start.flow[2], m->start.flow[3]);
#endif
    for (int k = 0; k < N_D && used < size; ++k)
        used += (size_t)snprintf(text + used, size - used, "%s%s_init = %g", used ? ", " : "",
                                 SELF_START_DELIVER_NAMES[k], m->start.delivered[k]);
}

ModelStatus self_start_solve(ModelState *m, char *message, size_t size)
{
    char asked[300];
    double z[N_Z];
    memcpy(z, SELF_START_ANCHOR_X, N_X * sizeof *z);
    for (int k = 0; k < N_S; ++k) z[N_X + k] = SELF_START_ANCHOR_U[SELF_START_SOLVES[k]];
    double lambda = 0.0, step = LARGEST_LAMBDA_STEP;
    System q;
    system_at(m, 0.0, &q);
    int solved = newton(&q, z, PATH_TOLERANCE); /* the anchor, to this build's rounding */
    while (solved && lambda < 1.0) {
        const double next = fmin(1.0, lambda + step);
        double trial[N_Z];
        memcpy(trial, z, sizeof trial);
        system_at(m, next, &q);
        if (newton(&q, trial, next == 1.0 ? STEP_TOLERANCE : PATH_TOLERANCE)) {
            memcpy(z, trial, sizeof z);
            lambda = next;
            step = fmin(LARGEST_LAMBDA_STEP, 2.0 * step);
        } else if ((step *= 0.25) < SMALLEST_LAMBDA_STEP) {
            solved = 0;
        }
    }
    describe_start(m, asked, sizeof asked);
    if (!solved) {
        snprintf(message, size, "no rest at the start asked for (%s): the Newton iteration from the anchor "
                 "fails at lambda = %.4g (0: the anchor, a start solved when the FMU was built; 1: the start asked for)", asked, lambda);
        return MODEL_ERROR;
    }
    double x[OPFMU_X_SIZE], u[N_U];
    unpack(&q, z, x, u);
#ifdef OPFMU_HAS_RESET
    /* a rest with a state beyond a non-windup limit, its unlimited rate 0 there, is none (Python's
       initialisations refuse it; an integrator would place the state on the limit at once): moved a
       little back inside, the state's rate pushes it out and the reset places it on the limit */
    for (int i = 0; i < N_X; ++i) {
        for (int side = -1; side <= 1; side += 2) {
            double nudged[OPFMU_X_SIZE], placed[OPFMU_X_SIZE];
            const double step = 1e-6 * (1.0 + fabs(x[i]));
            memcpy(nudged, x, sizeof nudged);
            nudged[i] += side * step;
            model_reset(nudged, u, q.p, placed);
            if (fabs(placed[i] - nudged[i]) > 10.0 * step) {
                snprintf(message, size, "no rest at the start asked for (%s): it would hold state %d at %g, beyond "
                         "its limit %g", asked, i, x[i], placed[i]);
                return MODEL_ERROR;
            }
        }
    }
#endif
    for (int k = 0; k < N_S; ++k) {
        const int c = SELF_START_SOLVES[k];
        if (u[c] < OPFMU_INPUT_MIN[c]) {
            snprintf(message, size, "the start asked for (%s) needs %s = %g %s, below its lower bound %g %s", asked,
                     OPFMU_INPUT_NAMES[c], u[c], OPFMU_INPUT_UNITS[c], OPFMU_INPUT_MIN[c], OPFMU_INPUT_UNITS[c]);
            return MODEL_ERROR;
        }
        m->start.solved[k] = u[c];
    }
    for (int k = 0; k < N_S; ++k) m->u[SELF_START_SOLVES[k]] = u[SELF_START_SOLVES[k]];
#if SELF_START_LOAD_FLOW
    if (!m->start.bus_voltage_set) { /* the bus voltage the host never set: the load flow's */
        m->u[BUS_VOLTAGE_MAGNITUDE] = u[BUS_VOLTAGE_MAGNITUDE];
        m->u[BUS_VOLTAGE_ANGLE] = u[BUS_VOLTAGE_ANGLE];
    }
#endif
    memcpy(m->x, x, sizeof m->x);
    return MODEL_OK;
}

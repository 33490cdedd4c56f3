/* The native reference model: the component's ODE (the generated model_derivatives, traced from its
   one definition) integrated over each communication step by Dormand-Prince 5(4) (dopri5.c) to the
   parameters rtol and atol, with the inputs held over the step, or linear in time where the master
   set their first derivatives (fmi2SetRealInputDerivatives). The solver's step size carries over
   from step to step and is part of the FMU state. A step the solver cannot complete to the
   tolerance (step size underflow, too many steps, a non-finite state) is refused with the reason and
   leaves the state where it was.

   A component whose right-hand side has conditions (limits, switches: reference_models.piecewise.where)
   has OPFMU_N_SWITCHING > 0 switching functions (the generated model_switching): the solver integrates
   with each condition's branch locked (model_derivatives_locked), so the right-hand side is smooth
   within each solver step, and Dormand-Prince locates the instant a condition's truth changes in a way
   that changes the right-hand side, ends its step there and restarts with the branches that then
   hold (dopri5_events; switching.c). The branches are locked afresh from the state and inputs at the
   start of each communication step; the FMU state keeps those the last step ended on (ModelState.mode),
   which Model Exchange (model_exchange.c) integrates with between events.

   A component with a reset (OPFMU_HAS_RESET: the generated model_reset, from Component.reset: a
   state at or beyond a non-windup limit while its unlimited rate pushes outward is placed on the
   limit, ANDES' anti-windup) has it applied wherever the branches are locked: at the start of each
   communication step (at the inputs set for it) and at each located switching, before the branches
   are chosen: a state that starts beyond a limit, or that the located crossing's bracket leaves just
   beyond it, goes on exactly from the limit, and one under a limit that moves with an input follows it.

   A component without states (OPFMU_N_STATES = 0: its outputs a function of its inputs alone) has
   nothing to integrate: a step advances the time and the inputs, and the outputs follow them. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "dopri5.h"
#include "model.h"
#include "model_exchange.h"
#include "switching.h"
#include "variables.h"

#define N_X OPFMU_N_STATES
#define N_U OPFMU_N_INPUTS

void model_defaults(ModelState *m)
{
    component_defaults(m);
    m->rtol = OPFMU_RTOL;
    m->atol = OPFMU_ATOL;
}

ModelStatus model_initialize(ModelState *m, double start_time, char *message, size_t size)
{
    if (component_initial_state(m, message, size) != MODEL_OK) return MODEL_ERROR;
    m->time = start_time;
    m->h_guess = 0.0;
    return MODEL_OK;
}

#if N_X > 0
#if N_G > 0
/* Sliding on a moving limit. A state held on a limit that moves away from it while its rate keeps
   pushing on it (ESDC2A's VRMAX Vt rising after a fault is cleared) leaves the limit, is driven back
   onto it, and so on, infinitely often (Zeno): thousands of located switchings in a microsecond,
   until the step gives up. A condition that changes back within ZENO_GAP [s] of its last change
   slides: it stays locked to the slower of its two branches (slower_branch: the limiter's hold), its
   changes are not located, for ZENO_DWELL [s]; then the branches are locked afresh (the reset placing the state on the limit where it is
   pushed beyond it). The state follows the moving limit sampled every ZENO_DWELL at most (held
   below a rising ceiling by at most its rise over ZENO_DWELL, never across it), as a fixed step of
   that size does (the monolithic DAE, reference_models/grid/monolithic.py, the same). */
#define ZENO_GAP 1e-6
#define ZENO_DWELL 1e-3
#endif

/* the inputs over a step: u(t) = u0 + du (t - t0) + d2u (t - t0)^2 / 2; the parameters; the branches
   the right-hand side is locked to, and what sliding needs: the time of the last lock, the branches
   before it, the conditions that slide, and until when */
typedef struct {
    const double *u0, *du, *d2u, *p;
    double t0;
#if N_G > 0
    int mode[N_G];
    double last_lock, slide_until;
    int locks, before[N_G], sliding[N_G]; /* locks: how many so far (`before` holds branches from the second on) */
#endif
} StepInputs;

static void inputs_at(const StepInputs *in, double t, double u[N_U])
{
    const double tau = t - in->t0;
    for (int c = 0; c < N_U; ++c) u[c] = in->u0[c] + tau * (in->du[c] + 0.5 * in->d2u[c] * tau);
}

static void rhs(void *ctx, double t, const double *x, double *dx)
{
    const StepInputs *in = (const StepInputs *)ctx;
    double u[N_U];
    inputs_at(in, t, u);
#if N_G > 0
    model_derivatives_locked(x, u, in->p, in->mode, dx);
#else
    model_derivatives(x, u, in->p, dx);
#endif
}

#if N_G > 0
/* the branches that hold at (t, x) differ from the locked ones, the sliding ones aside, and give
   another dx/dt there; or a slide has ended (t at or past slide_until) */
static int crossed(void *ctx, double t, const double *x)
{
    const StepInputs *in = (const StepInputs *)ctx;
    double u[N_U], g[N_G];
    int now[N_G], probe[N_G];
    if (t >= in->slide_until) return 1;
    inputs_at(in, t, u);
    model_switching(x, u, in->p, g, now);
    for (int k = 0; k < N_G; ++k) probe[k] = in->sliding[k] ? now[k] : in->mode[k];
    return branches_changed(x, u, in->p, probe);
}

/* of condition k's two branches (the others as in `mode`), the one on which the states change least
   at (x, u) (the largest rate relative to the state, the smaller): a limiter's hold rather than its
   free rate, which would carry the state across the limit for the slide's length */
static int slower_branch(const double *x, const double u[N_U], const double *p, const int mode[N_G], int k)
{
    int probe[N_G];
    double dx[N_X], speed[2];
    memcpy(probe, mode, sizeof probe);
    for (int branch = 0; branch < 2; ++branch) {
        probe[k] = branch;
        model_derivatives_locked(x, u, p, probe, dx);
        speed[branch] = 0.0;
        for (int i = 0; i < N_X; ++i) speed[branch] = fmax(speed[branch], fabs(dx[i]) / fmax(1.0, fabs(x[i])));
    }
    return speed[1] < speed[0];
}

/* x is dopri5_events' own working state (the step's start, the located switching), from which it
   integrates on after this call: the reset places it on its limits before the branches are chosen;
   a sliding condition keeps its branch until its slide ends, and one that changes back within
   ZENO_GAP of its last change starts sliding */
static void lock(void *ctx, double t, const double *x)
{
    StepInputs *in = (StepInputs *)ctx;
    double u[N_U];
    int locked[N_G];
    memcpy(locked, in->mode, sizeof locked);
    if (t >= in->slide_until) { /* the slide ends: every branch locked afresh */
        memset(in->sliding, 0, sizeof in->sliding);
        in->slide_until = INFINITY;
    }
    inputs_at(in, t, u);
    relock((double *)x, u, in->p, in->mode);
    for (int k = 0; k < N_G; ++k) {
        if (in->sliding[k]) {
            in->mode[k] = locked[k];
        } else if (in->locks >= 2 && t - in->last_lock < ZENO_GAP && in->mode[k] != locked[k]
                   && in->mode[k] == in->before[k]) {
            in->sliding[k] = 1; /* back where it was a moment ago: it slides, on the slower of its branches */
            in->mode[k] = slower_branch(x, u, in->p, in->mode, k);
            if (!isfinite(in->slide_until)) in->slide_until = t + ZENO_DWELL;
        }
    }
    memcpy(in->before, locked, sizeof locked);
    in->last_lock = t;
    in->locks++;
}
#endif

/* integrates m->x from m->time to stop with the inputs over the step (m->u, m->du, m->d2u); MODEL_ERROR
   (message written) where Dormand-Prince cannot, m unchanged */
static ModelStatus integrate(ModelState *m, double stop, char *message, size_t size)
{
    double x[N_X], h_guess = m->h_guess;
    StepInputs inputs = {m->u, m->du, m->d2u, m->p, m->time};
#if N_G > 0
    inputs.last_lock = -INFINITY;
    inputs.slide_until = INFINITY;
    memset(inputs.sliding, 0, sizeof inputs.sliding);
#endif
    DopriStats stats;
    memcpy(x, m->x, sizeof x);
#if N_G > 0
    const Dopri5Events events = {crossed, lock, &inputs};
    const int rc = dopri5_events(rhs, &inputs, N_X, m->time, stop, x, m->rtol, m->atol, &h_guess, &stats, &events,
                                 NULL, NULL);
#else
    const int rc = dopri5(rhs, &inputs, N_X, m->time, stop, x, m->rtol, m->atol, &h_guess, &stats);
#endif
    if (rc != DOPRI5_OK) {
        snprintf(message, size, "t = %.9g s: Dormand-Prince 5(4) cannot complete the step to %.9g s within rtol = %g, "
                 "atol = %g: %s (after %ld steps and %ld rejected, last step size %g s)", m->time, stop, m->rtol,
                 m->atol, dopri5_message(rc), stats.accepted, stats.rejected, stats.h_last);
        return MODEL_ERROR;
    }
    memcpy(m->x, x, sizeof x);
    m->h_guess = h_guess;
#if N_G > 0
    memcpy(m->mode, inputs.mode, sizeof inputs.mode); /* the branches the step ended on */
#endif
    return MODEL_OK;
}
#endif

ModelStatus model_do_step(ModelState *m, double h, char *message, size_t size)
{
    const double stop = m->time + h;
    double u_end[N_U];
    for (int c = 0; c < N_U; ++c) u_end[c] = m->u[c] + h * (m->du[c] + 0.5 * m->d2u[c] * h);
    if (check_inputs_at_step_end(m, u_end, message, size) != MODEL_OK) return MODEL_ERROR;
#if N_X > 0
    if (integrate(m, stop, message, size) != MODEL_OK) return MODEL_ERROR;
#endif
    memcpy(m->u, u_end, sizeof u_end); /* the inputs at the new communication point */
    m->time = stop;
    return MODEL_OK;
}

ModelStatus model_get_extra(const ModelState *m, unsigned int vr, double *value)
{
    switch (vr) {
    case VR_RTOL: *value = m->rtol; return MODEL_OK;
    case VR_ATOL: *value = m->atol; return MODEL_OK;
    default: return exchange_get_real(m, vr, value);
    }
}

ModelStatus model_set_extra(ModelState *m, unsigned int vr, double value, char *message, size_t size)
{
    switch (vr) {
    case VR_RTOL:
        if (!(value >= OPFMU_RTOL_MIN && value < 1.0)) {
            snprintf(message, size, "rtol = %g must lie in [%g, 1) (the relative tolerance of each solver step)",
                     value, OPFMU_RTOL_MIN);
            return MODEL_ERROR;
        }
        m->rtol = value;
        return MODEL_OK;
    case VR_ATOL:
        if (!(value > 0.0)) {
            snprintf(message, size, "atol = %g must be > 0 (the absolute tolerance of each solver step)", value);
            return MODEL_ERROR;
        }
        m->atol = value;
        return MODEL_OK;
    default:
        snprintf(message, size, "value reference %u is not a settable Real variable", vr);
        return MODEL_ERROR;
    }
}

int model_boolean_exists(unsigned int vr) { (void)vr; return 0; }

int model_get_boolean(const ModelState *m, unsigned int vr) { (void)m; (void)vr; return 0; }

const char *model_no_derivative(unsigned int vr) { (void)vr; return NULL; }

ModelStatus model_check_state(const ModelState *m, char *why, size_t size)
{
    if (check_component_state(m, why, size) != MODEL_OK) return MODEL_ERROR;
    if (!(m->rtol >= OPFMU_RTOL_MIN && m->rtol < 1.0)) {
        snprintf(why, size, "rtol = %g does not lie in [%g, 1)", m->rtol, OPFMU_RTOL_MIN);
        return MODEL_ERROR;
    }
    if (!(m->atol > 0.0 && isfinite(m->atol))) {
        snprintf(why, size, "atol = %g is not positive and finite", m->atol);
        return MODEL_ERROR;
    }
    if (!(m->h_guess >= 0.0 && isfinite(m->h_guess))) {
        snprintf(why, size, "the solver's next step size %g s is not finite and >= 0 (0: none yet)", m->h_guess);
        return MODEL_ERROR;
    }
    return check_locks(m, why, size);
}

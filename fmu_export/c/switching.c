/* The branches of the native reference model's right-hand side (switching.h says what each
   function does): shared by the co-simulation step (reference_model.c) and Model Exchange
   (model_exchange.c), so both lock, reset and compare the branches the same way. */
#include <stdio.h>
#include <string.h>

#include "switching.h"

#if N_G > 0
int branches_changed(const double x[OPFMU_N_STATES], const double u[OPFMU_N_INPUTS], const double p[],
                     const int locked[N_G])
{
    double g[N_G], before[OPFMU_N_STATES], now[OPFMU_N_STATES];
    int mode[N_G];
    model_switching(x, u, p, g, mode);
    if (memcmp(mode, locked, sizeof mode) == 0) return 0;
    model_derivatives_locked(x, u, p, locked, before);
    model_derivatives_locked(x, u, p, mode, now);
    return memcmp(before, now, sizeof now) != 0;
}

int reset_moves(const double x[OPFMU_N_STATES], const double u[OPFMU_N_INPUTS], const double p[])
{
#ifdef OPFMU_HAS_RESET
    double placed[OPFMU_N_STATES];
    model_reset(x, u, p, placed);
    return memcmp(placed, x, sizeof placed) != 0;
#else
    (void)x;
    (void)u;
    (void)p;
    return 0;
#endif
}

void relock(double x[OPFMU_N_STATES], const double u[OPFMU_N_INPUTS], const double p[], int mode[N_G])
{
    double g[N_G];
#ifdef OPFMU_HAS_RESET
    double placed[OPFMU_N_STATES];
    model_reset(x, u, p, placed);
    memcpy(x, placed, sizeof placed);
#endif
    model_switching(x, u, p, g, mode);
}
#endif

void locked_derivatives(const ModelState *m, double dx[OPFMU_X_SIZE])
{
#if N_G > 0
    model_derivatives_locked(m->x, m->u, m->p, m->mode, dx);
#elif OPFMU_N_STATES > 0
    model_derivatives(m->x, m->u, m->p, dx);
#else
    (void)m;
    (void)dx;
#endif
}

void switching_functions(const ModelState *m, double g[OPFMU_G_SIZE])
{
#if N_G > 0
    int mode[N_G];
    model_switching(m->x, m->u, m->p, g, mode);
#else
    (void)m;
    (void)g;
#endif
}

void initial_lock(ModelState *m)
{
#if N_G > 0
    double g[N_G];
    model_switching(m->x, m->u, m->p, g, m->mode);
#endif
    memcpy(m->u_locked, m->u, sizeof m->u_locked);
    m->lock_due = 1;
}

ModelStatus check_locks(const ModelState *m, char *why, size_t size)
{
    for (int k = 0; k < N_G; ++k) {
        if (m->mode[k] != 0 && m->mode[k] != 1) {
            snprintf(why, size, "the locked branch of switching condition %d is %d, not 0 or 1", k, m->mode[k]);
            return MODEL_ERROR;
        }
    }
    if (m->lock_due != 0 && m->lock_due != 1) {
        snprintf(why, size, "lock_due is %d, not 0 or 1", m->lock_due);
        return MODEL_ERROR;
    }
    if (first_non_finite(m->u_locked, OPFMU_N_INPUTS) >= 0) {
        snprintf(why, size, "the inputs of the last lock are not finite");
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

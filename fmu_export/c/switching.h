/* The branches of the native reference model's right-hand side (switching.c): the generated
   switching functions, the right-hand side with their branches locked, the limit resets, and how
   both the co-simulation step (reference_model.c, at each communication point and located
   switching) and Model Exchange (model_exchange.c, at initialisation and each event) lock them.

   mode[k] is condition k's truth (0 or 1), the branch of the right-hand side's where k; it is
   locked from a state and inputs and kept until the next lock, so that the right-hand side is
   smooth in between. The FMU state keeps the last locked modes (ModelState.mode). */
#ifndef OPFMU_SWITCHING_H
#define OPFMU_SWITCHING_H

#include "model.h"

#define N_G OPFMU_N_SWITCHING

#if N_G > 0
/* g[k] = a - b and mode[k] = (a op b) of the right-hand side's condition k (equations.c) */
OPFMU_INTERNAL void model_switching(const double x[OPFMU_N_STATES], const double u[OPFMU_N_INPUTS], const double p[],
                                    double g[N_G], int mode[N_G]);
/* dx/dt with condition k's branch locked to mode[k] (equations.c) */
OPFMU_INTERNAL void model_derivatives_locked(const double x[OPFMU_N_STATES], const double u[OPFMU_N_INPUTS],
                                             const double p[], const int mode[N_G], double dx[OPFMU_N_STATES]);

/* the branches that hold at (x, u) differ from `locked` in a way that changes dx/dt there (a
   change that leaves it as it is, a condition in a branch not taken, does not count) */
OPFMU_INTERNAL int branches_changed(const double x[OPFMU_N_STATES], const double u[OPFMU_N_INPUTS], const double p[],
                                    const int locked[N_G]);
/* locks mode to the branches that hold at (x, u), after placing x on the limits it is pushed beyond
   (model_reset, where the component has one) */
OPFMU_INTERNAL void relock(double x[OPFMU_N_STATES], const double u[OPFMU_N_INPUTS], const double p[], int mode[N_G]);
/* the reset at (x, u) would move a state (one held on a limit that has moved inward since it was
   placed there, with a state or an input); 0 for a component without a reset */
OPFMU_INTERNAL int reset_moves(const double x[OPFMU_N_STATES], const double u[OPFMU_N_INPUTS], const double p[]);
#endif

#ifdef OPFMU_HAS_RESET
#if N_G == 0
#error "a component with a reset has switching functions (its non-windup limits)"
#endif
/* the states after the component's limit resets at inputs u (equations.c) */
OPFMU_INTERNAL void model_reset(const double x[OPFMU_N_STATES], const double u[OPFMU_N_INPUTS], const double p[],
                                double out[OPFMU_N_STATES]);
#endif

/* dx/dt at m's state and inputs with the branches m->mode locked [OPFMU_N_STATES] */
OPFMU_INTERNAL void locked_derivatives(const ModelState *m, double dx[OPFMU_X_SIZE]);
/* the switching functions g at m's state and inputs [OPFMU_N_SWITCHING]: the event indicators */
OPFMU_INTERNAL void switching_functions(const ModelState *m, double g[OPFMU_G_SIZE]);
/* at initialisation's end: locks m->mode to the branches that hold at m's state and inputs, the
   state left as it is, and makes the first event update a full lock (m->lock_due), as the first
   communication step starts with one */
OPFMU_INTERNAL void initial_lock(ModelState *m);
/* MODEL_ERROR (why written) unless every mode of m and its lock_due are 0 or 1 and the inputs of its
   last lock finite */
OPFMU_INTERNAL ModelStatus check_locks(const ModelState *m, char *why, size_t size);

#endif

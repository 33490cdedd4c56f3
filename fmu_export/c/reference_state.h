/* The native reference model's state (model.h includes it as OPFMU_STATE_HEADER): the component's
   ODE integrated by Dormand-Prince 5(4) over each communication step (reference_model.c), or by the
   importer's integrator under Model Exchange (model_exchange.c). */
#ifndef OPFMU_REFERENCE_STATE_H
#define OPFMU_REFERENCE_STATE_H

/* the declared size of an array of the switching functions: at least 1, as C requires */
#define OPFMU_G_SIZE (OPFMU_N_SWITCHING > 0 ? OPFMU_N_SWITCHING : 1)

typedef struct {
    double time;                    /* current communication point [s] */
    double u[OPFMU_N_INPUTS];       /* inputs at `time` */
    double du[OPFMU_N_INPUTS];      /* their first time derivatives over the next step (0: held) */
    double d2u[OPFMU_N_INPUTS];     /* their second time derivatives over it (0: linear) */
    double x_start[OPFMU_X_SIZE];   /* parameters: initial state (model.h: its first OPFMU_N_STATES) */
    double p[OPFMU_P_SIZE];         /* parameters: the component's, then derived ones (model.h) */
    double rtol, atol;              /* parameters: the solver's tolerances */
    double x[OPFMU_X_SIZE];         /* state at `time` */
    double h_guess;                 /* the solver's step size to try next [s] (0: none yet) */
#ifdef OPFMU_SELF_START
    SelfStartState start;         /* the start from the load flow (model.h) */
#endif
    int mode[OPFMU_G_SIZE];         /* the branches the right-hand side is locked to (switching.h) */
    double u_locked[OPFMU_N_INPUTS]; /* Model Exchange: the inputs at the last lock (model_exchange.c) */
    int lock_due;                   /* Model Exchange: the next event update is a full lock */
} ModelState;

#endif

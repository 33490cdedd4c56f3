/* The interface between the FMI 2.0 co-simulation plumbing (fmi2_cs.c) and one model
   (surrogate_model.c). A model's whole dynamic state is the plain struct ModelState, so the
   plumbing can copy and serialise it byte for byte. */
#ifndef OPFMU_MODEL_H
#define OPFMU_MODEL_H

#include "config.h"

#define OPFMU_Z_SIZE (OPFMU_FIRST_LAYER > 0 ? OPFMU_FIRST_LAYER : 1)
#define OPFMU_TRUNK_SLOTS (OPFMU_TRUNK_SIZE > 0 ? OPFMU_N_SENSORS : 1)
#define OPFMU_TRUNK_CACHE (OPFMU_TRUNK_SIZE > 0 ? OPFMU_N_SENSORS * OPFMU_TRUNK_SIZE : 1)
#define OPFMU_COEF_CAP (OPFMU_COEF_SIZE > 0 ? OPFMU_COEF_SIZE : 1)

typedef enum { MODEL_OK = 0, MODEL_WARNING = 1, MODEL_ERROR = 3 } ModelStatus;

/* Variable kinds the plumbing checks writes against. */
typedef enum { VAR_INPUT, VAR_PARAMETER, VAR_OUTPUT } VarKind;

typedef struct {
    double Vs, theta_vs;          /* inputs [pu, rad], held over the next step */
    double x_start[4];            /* parameters: initial state (delta, omega, Ed_p, Eq_p) */
    double rollover_horizon;      /* parameter [s]: window length, <= the trained horizon */
    double residual_limit;        /* parameter: residual above which a warning is logged; 0: no check */
    int residual_alarm;           /* the residual is above the limit (warned; re-armed below half of it) */
    double restart_jump;          /* parameter [pu, rad]: an input change larger than this starts a window */
    double rest_radius;           /* parameter: scale of the rest correction's reach (0: no correction) */
    double slow_weight;           /* parameter in [0, 1]: weight of the slow-mode correction (0: none) */
    double swing_weight;          /* parameter in [0, 1]: weight of the exact swing step for omega (0: none) */
    double time;                  /* current communication point [s] */
    double x[4];                  /* state at `time` */
    double omega_operator;        /* the operator's omega at `time`, before the exact swing step (residual) */
    double window_start;          /* start time of the current operator window [s] */
    double x_window[4];           /* state at the window start */
    int in_envelope;              /* false once an input or a window start left the envelope */
    double sensors[2 * OPFMU_N_SENSORS]; /* (Vs, theta_vs) at the window's sensor times */
    /* the sensor layer's output z, tracked incrementally (OPFMU_FIRST_LAYER > 0): z = z_base (x0 part
       and bias) + z_past (slots before `filled`, final) + the held input times the remaining slots */
    double z_base[OPFMU_Z_SIZE], z_past[OPFMU_Z_SIZE];
    int filled;                   /* slots before this index hold final values */
    double last_u[2];             /* the input written from slot `filled` on */
    /* the trunk values at each sensor time, computed when first needed (OPFMU_TRUNK_SIZE > 0): they
       depend on the window time alone, so every window after the first reuses them */
    unsigned char trunk_ready[OPFMU_TRUNK_SLOTS];
    double trunk[OPFMU_TRUNK_CACHE];
    double coef[OPFMU_COEF_CAP];  /* the operator's coefficients at the last evaluation (residual) */
    /* the rest correction of the current window (surrogate_model.c): the equilibrium x_rest of the
       input at the window start, the operator's coefficients from there under that input held, and
       the weight the correction gets (0: none) */
    double x_rest[4], rest_coef[OPFMU_COEF_CAP], rest_weight;
    /* the slow-mode correction of the current window (surrogate_model.c): the slowest mode's left and
       right eigenvectors (left . right = 1), the slow coordinate left . x at the window start and the
       integral of left . f since then; slow_on: the window has one */
    double slow_left[4], slow_right[4], slow_start, slow_integral;
    int slow_on;
    double corrected_for[2];      /* the input both corrections of the current window were computed for */
} ModelState;

void model_defaults(ModelState *m);
/* kind of a real variable, or -1 if vr names none */
int model_real_kind(unsigned int vr);
ModelStatus model_get_real(const ModelState *m, unsigned int vr, double *value);
ModelStatus model_set_real(ModelState *m, unsigned int vr, double value, char *message, size_t size);
int model_boolean_exists(unsigned int vr);
int model_get_boolean(const ModelState *m, unsigned int vr);
ModelStatus model_initialize(ModelState *m, double start_time, char *message, size_t size);
ModelStatus model_do_step(ModelState *m, double h, char *message, size_t size);

#endif

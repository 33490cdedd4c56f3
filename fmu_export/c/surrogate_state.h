/* The surrogate model's state (model.h includes it as OPFMU_STATE_HEADER). Its sizes come from the
   generated config.h: OPFMU_N_STATES states, OPFMU_N_INPUTS inputs, OPFMU_N_SENSORS sensor times
   per window, the kernel's layer sizes. */
#ifndef OPFMU_SURROGATE_STATE_H
#define OPFMU_SURROGATE_STATE_H

#define OPFMU_Z_SIZE (OPFMU_FIRST_LAYER > 0 ? OPFMU_FIRST_LAYER : 1)
#define OPFMU_TRUNK_SLOTS (OPFMU_TRUNK_SIZE > 0 ? OPFMU_N_SENSORS : 1)
#define OPFMU_TRUNK_CACHE (OPFMU_TRUNK_SIZE > 0 ? OPFMU_N_SENSORS * OPFMU_TRUNK_SIZE : 1)
#define OPFMU_COEF_CAP (OPFMU_COEF_SIZE > 0 ? OPFMU_COEF_SIZE : 1)

/* a window's frame: angle origin a [rad], shift of the angle states (a plus whole periods) [rad],
   speed c [rad/s] */
typedef struct {
    double a, shift, c;
} WindowFrame;

typedef struct {
    double u[OPFMU_N_INPUTS];     /* inputs at `time` */
    double du[OPFMU_N_INPUTS];    /* their first time derivatives over the next steps (0: held;
                                     fmi2SetRealInputDerivatives) */
    double x_start[OPFMU_N_STATES]; /* parameters: initial state */
#ifdef OPFMU_SELF_START
    SelfStartState start;         /* the start from the load flow (model.h) */
#endif
    double p[OPFMU_P_SIZE];       /* parameters: the component's, fixed at the trained values (model.h) */
    double rollover_horizon;      /* parameter [s]: window length, <= the trained horizon */
    double residual_limit;        /* parameter: residual above which a warning is logged; 0: no check */
    int residual_alarm;           /* the residual is above the limit (warned; re-armed below half of it) */
    double restart_jump;          /* parameter [input units]: an input change larger than this starts a window */
    double rest_radius;           /* parameter: scale of the rest correction's reach (0: no correction) */
    double slow_weight;           /* parameter in [0, 1]: weight of the slow-mode correction (0: none) */
    double swing_weight;          /* parameter in [0, 1]: weight of the exact step of the affine states (0: none) */
    double time;                  /* current communication point [s] */
    double x[OPFMU_N_STATES];     /* state at `time` */
    double x_operator[OPFMU_N_STATES]; /* the operator's state at `time`, before the exact step (residual) */
    double window_start;          /* start time of the current operator window [s] */
    double x_window[OPFMU_N_STATES]; /* state at the window start */
    /* the window's frame (reference_models/drift.py; zeros for a component without one): inputs at
       window time tau are seen as u - a R - c (R tau + T), states as x - (shift + c tau) A - c W, with
       R, T, A, W the frame tables of config.h */
    WindowFrame frame;
    double x_window_f[OPFMU_N_STATES]; /* the window's start state in its frame */
    int in_envelope;              /* false once an input or a window start left the envelope */
    double sensors[OPFMU_N_INPUTS * OPFMU_N_SENSORS]; /* the inputs at the window's sensor times, slot-major */
    /* the sensor layer's output z, tracked incrementally (OPFMU_FIRST_LAYER > 0): z = z_base (x0 part
       and bias) + z_past (slots before `filled`, final) + the held input times the remaining slots */
    double z_base[OPFMU_Z_SIZE], z_past[OPFMU_Z_SIZE];
    int filled;                   /* slots before this index hold final values */
    double last_u[OPFMU_N_INPUTS]; /* the input written from slot `filled` on (at window time last_start) */
    double last_du[OPFMU_N_INPUTS]; /* and its derivative: slot k holds last_u + last_du (min(s_k, last_end) - last_start) */
    double last_start;            /* window time the last step (or part of one) started at */
    double last_end;              /* window time the last step ended at (its ramps, the frame's too, stop there) */
    double input_time;            /* time the previous step started at (its input was set for it) */
    double prev_end_u[OPFMU_N_INPUTS]; /* the inputs at the end of the previous step (restart_jump compares with them) */
    double prev_du[OPFMU_N_INPUTS]; /* their derivatives over the previous step */
    /* the trunk values at each sensor time, computed when first needed (OPFMU_TRUNK_SIZE > 0): they
       depend on the window time alone, so every window after the first reuses them */
    unsigned char trunk_ready[OPFMU_TRUNK_SLOTS];
    double trunk[OPFMU_TRUNK_CACHE];
    double coef[OPFMU_COEF_CAP];  /* the operator's coefficients at the last evaluation (residual) */
    /* the rest correction of the current window (corrections.c): the equilibrium x_rest of the input
       at the window start, the operator's coefficients from there under that input held, and the
       weight the correction gets (0: none) */
    double x_rest[OPFMU_N_STATES], rest_coef[OPFMU_COEF_CAP], rest_weight;
    /* the slow-mode correction of the current window (corrections.c): the slowest mode's left and
       right eigenvectors (left . right = 1), the slow coordinate left . x at the window start and the
       integral of left . f since then; slow_on: the window has one */
    double slow_left[OPFMU_N_STATES], slow_right[OPFMU_N_STATES], slow_start, slow_integral;
    int slow_on;
    double corrected_for[OPFMU_N_INPUTS]; /* the input both corrections of the current window were computed for */
} ModelState;

#endif

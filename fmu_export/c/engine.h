/* What the surrogate model's source files share: the generated operator kernel, the sensor grid,
   and the functions frame.c, window.c and corrections.c provide (the component's equations are
   declared in model.h). They call each other one way: window.c uses corrections.c and frame.c,
   corrections.c uses frame.c, frame.c only the kernel. */
#ifndef OPFMU_ENGINE_H
#define OPFMU_ENGINE_H

#include "linalg.h"
#include "model.h"

#define N_X OPFMU_N_STATES
#define N_U OPFMU_N_INPUTS

/* the parameter array the component's equations take: a surrogate's hold its trained values as literals,
   the only values its parameters accept (model.h) */
#define TRAINED_P OPFMU_PARAM_START

static const double SENSOR_DT = OPFMU_HORIZON / (OPFMU_N_SENSORS - 1);
static const double TIME_EPS = 1e-9;

/* the operator kernel (operator_kernel.c, generated from the ONNX graph) */
void opfmu_operator(const double x0[N_X], const double u[N_U * OPFMU_N_SENSORS], double t, double x[N_X]);
/* the operator on physical values with the window frame done as the engine does it (frame.c) */
void opfmu_framed_operator(const double x0[N_X], const double u[N_U * OPFMU_N_SENSORS], double t, double x[N_X]);
#if OPFMU_FIRST_LAYER > 0
void opfmu_first_layer(const double x0[N_X], const double u[N_U * OPFMU_N_SENSORS], double z[OPFMU_FIRST_LAYER]);
void opfmu_from_first_layer(const double x0[N_X], const double z[OPFMU_FIRST_LAYER], double t, double x[N_X]);
/* suffix sums over sensor slots of the sensor layer's slope (sensor_sums.c, generated) */
OPFMU_INTERNAL extern const double OPFMU_SENSOR_SUFFIX[(OPFMU_N_SENSORS + 1) * N_U * OPFMU_FIRST_LAYER];
#define SUFFIX(k, c, h) OPFMU_SENSOR_SUFFIX[((k) * N_U + (c)) * OPFMU_FIRST_LAYER + (h)]
/* suffix sums over slots k of the slope along the frame's input ramp R times the slot's time s_k
   (sum over j >= k of s_j R . slope_j; zeros without a frame) */
OPFMU_INTERNAL extern const double OPFMU_RAMP_SUFFIX[(OPFMU_N_SENSORS + 1) * OPFMU_FIRST_LAYER];
#define RAMP_SUFFIX(k, h) OPFMU_RAMP_SUFFIX[(k) * OPFMU_FIRST_LAYER + (h)]
/* suffix sums over slots k of each input's slope times the slot's time s_k (sum over j >= k of s_j
   slope_j): how an input ramping over a step (its derivative set) reaches z */
OPFMU_INTERNAL extern const double OPFMU_TIME_SUFFIX[(OPFMU_N_SENSORS + 1) * N_U * OPFMU_FIRST_LAYER];
#define TIME_SUFFIX(k, c, h) OPFMU_TIME_SUFFIX[((k) * N_U + (c)) * OPFMU_FIRST_LAYER + (h)]
#endif
#if OPFMU_TRUNK_SIZE > 0
void opfmu_trunk(double t, double tau[OPFMU_TRUNK_SIZE]);
void opfmu_coefficients(const double x0[N_X], const double z[OPFMU_FIRST_LAYER], double c[OPFMU_COEF_SIZE]);
void opfmu_head(const double c[OPFMU_COEF_SIZE], const double tau[OPFMU_TRUNK_SIZE], double x[N_X]);
#endif

/* frame.c */
/* the input u at window time tau in the window frame */
OPFMU_INTERNAL void input_in_frame(const WindowFrame *f, const double u[N_U], double tau, double u_f[N_U]);
/* the state x (raw, at window time tau) in the window frame, and back */
OPFMU_INTERNAL void state_in_frame(const WindowFrame *f, const double x[N_X], double tau, double x_f[N_X]);
OPFMU_INTERNAL void state_from_frame(const WindowFrame *f, const double x_f[N_X], double tau, double x[N_X]);
/* the frame of a window starting at state x under input u: (a, shift, c) of drift.window_frame */
OPFMU_INTERNAL WindowFrame window_frame(const double x[N_X], const double u[N_U]);
#if OPFMU_FIRST_LAYER > 0
/* the sensor layer's output from x0 with every sensor slot at zero */
OPFMU_INTERNAL void first_layer_base(const double x0[N_X], double base[OPFMU_FIRST_LAYER]);
#endif
#if OPFMU_TRUNK_SIZE > 0
/* the operator's coefficients from x0 with every sensor slot holding u, given first_layer_base(x0) */
OPFMU_INTERNAL void held_coefficients(const double x0[N_X], const double base[OPFMU_FIRST_LAYER],
                                      const double u[N_U], double coef[OPFMU_COEF_SIZE]);
#endif

/* window.c */
/* the inputs dt after they were u0, along their derivatives m->du (u0 itself, bit for bit, where a
   derivative is 0) */
OPFMU_INTERNAL void input_after(const ModelState *m, const double u0[N_U], double dt, double u[N_U]);
/* the operator's physics residual at the current time (RMS over the states, per state scaled) */
OPFMU_INTERNAL double window_residual(const ModelState *m);

/* corrections.c */
/* the rest and slow-mode corrections of a window just started, for the current input; unless
   `always`, only if they were computed for another input */
OPFMU_INTERNAL void start_corrections(ModelState *m, int always);
#if OPFMU_TRUNK_SIZE > 0
/* subtracts the rest correction at the trunk values `basis` from x */
OPFMU_INTERNAL void rest_correct(const ModelState *m, const double *basis, double x[N_X]);
/* subtracts the rest correction's rate, its difference between trunk values lo and hi over span, from rate */
OPFMU_INTERNAL void rest_correct_rate(const ModelState *m, const double *lo, const double *hi, double span,
                                      double rate[N_X]);
#endif
/* l . f(x, u): the rate of the slow coordinate under the held input */
OPFMU_INTERNAL double slow_rate(const ModelState *m, const double x[N_X]);
/* after a step of length h that started at slow rate rate_start: the slow-mode correction of m->x */
OPFMU_INTERNAL void slow_correct(ModelState *m, double h, double rate_start);

#define N_AFFINE_CAP (OPFMU_N_AFFINE > 0 ? OPFMU_N_AFFINE : 1)
/* g and k of each affine state's rate g - k x_i at state x under input u */
OPFMU_INTERNAL void affine_drive(const double x[N_X], const double u[N_U], double g[N_AFFINE_CAP],
                                 double k[N_AFFINE_CAP]);
/* after a step of length h from x_start (g_start, k_start there, from affine_drive): moves each
   affine state of m->x swing_weight of the way to its exact solution */
OPFMU_INTERNAL void affine_step(ModelState *m, const double x_start[N_X], const double g_start[N_AFFINE_CAP],
                                const double k_start[N_AFFINE_CAP], double h);

#endif

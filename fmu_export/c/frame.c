/* The operator in its window frame (reference_models/drift.py), what both the window engine
   (window.c) and its corrections (corrections.c) evaluate it through: the frame of a window from its
   start state and input, inputs and states seen in the frame and back, the operator on physical
   values with the frame done as the engine does it, and the operator's sensor layer and
   coefficients under an input held in every sensor slot. The frame tables are zeros for a component
   without a drift symmetry. */
#include <math.h>

#include "engine.h"

void input_in_frame(const WindowFrame *f, const double u[N_U], double tau, double u_f[N_U])
{
    for (int c = 0; c < N_U; ++c)
        u_f[c] = u[c] - f->a * OPFMU_FRAME_INPUT_RATES[c]
                 - f->c * (OPFMU_FRAME_INPUT_RATES[c] * OPFMU_FRAME_SPEED_SCALE * tau + OPFMU_FRAME_INPUT_TORQUES[c]);
}

void state_in_frame(const WindowFrame *f, const double x[N_X], double tau, double x_f[N_X])
{
    for (int i = 0; i < N_X; ++i)
        x_f[i] = x[i] - (f->shift + f->c * OPFMU_FRAME_SPEED_SCALE * tau) * OPFMU_FRAME_ANGLES[i] - f->c * OPFMU_FRAME_SPEED[i];
}

void state_from_frame(const WindowFrame *f, const double x_f[N_X], double tau, double x[N_X])
{
    for (int i = 0; i < N_X; ++i)
        x[i] = x_f[i] + (f->shift + f->c * OPFMU_FRAME_SPEED_SCALE * tau) * OPFMU_FRAME_ANGLES[i] + f->c * OPFMU_FRAME_SPEED[i];
}

WindowFrame window_frame(const double x[N_X], const double u[N_U])
{
    WindowFrame f = {0.0, 0.0, 0.0};
#if OPFMU_FRAME
    f.a = u[OPFMU_FRAME_ANGLE_INPUT];
#if OPFMU_FRAME_SPEED_STATE >= 0
    f.c = x[OPFMU_FRAME_SPEED_STATE] - OPFMU_FRAME_SPEED_REST; /* the speed's offset from rest */
    if (OPFMU_FRAME_SPEED_STEP > 0.0) f.c = OPFMU_FRAME_SPEED_STEP * floor(f.c / OPFMU_FRAME_SPEED_STEP + 0.5);
#endif
#if OPFMU_FRAME_ANGLE_STATE >= 0
    f.shift = f.a + OPFMU_FRAME_PERIOD * floor((x[OPFMU_FRAME_ANGLE_STATE] - f.a) / OPFMU_FRAME_PERIOD + 0.5);
#else
    f.shift = f.a;
#endif
#else
    (void)x;
    (void)u;
#endif
    return f;
}

/* The operator on physical values, the frame done here as the engine does it: what the ONNX file's
   whole graph computes (the builder checks the two against each other). */
void opfmu_framed_operator(const double x0[N_X], const double u[N_U * OPFMU_N_SENSORS], double t, double x[N_X])
{
    const WindowFrame frame = window_frame(x0, u);
    double x0_f[N_X], x_f[N_X], u_f[N_U * OPFMU_N_SENSORS];
    state_in_frame(&frame, x0, 0.0, x0_f);
    for (int k = 0; k < OPFMU_N_SENSORS; ++k) input_in_frame(&frame, u + k * N_U, (double)k * SENSOR_DT, u_f + k * N_U);
    opfmu_operator(x0_f, u_f, t, x_f);
    state_from_frame(&frame, x_f, t, x);
}

#if OPFMU_FIRST_LAYER > 0
static const double ZERO_SENSORS[N_U * OPFMU_N_SENSORS];

void first_layer_base(const double x0[N_X], double base[OPFMU_FIRST_LAYER])
{
    opfmu_first_layer(x0, ZERO_SENSORS, base);
}
#endif

#if OPFMU_TRUNK_SIZE > 0
void held_coefficients(const double x0[N_X], const double base[OPFMU_FIRST_LAYER], const double u[N_U],
                       double coef[OPFMU_COEF_SIZE])
{
    double z[OPFMU_FIRST_LAYER];
    for (int h = 0; h < OPFMU_FIRST_LAYER; ++h) {
        double sum = base[h];
        for (int c = 0; c < N_U; ++c) sum += SUFFIX(0, c, h) * u[c];
        z[h] = sum;
    }
    opfmu_coefficients(x0, z, coef);
}
#endif

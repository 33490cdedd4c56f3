/* Model Exchange of the native reference FMU (model_exchange.c), version independent as
   cosimulation.c is for co-simulation: fmi2_me.c and fmi3_me.c map their version's calls onto these
   functions. Each takes the calling FMI function's name for its messages, refuses a call its instance
   was not instantiated for (co-simulation) or that its state does not allow (ST_EVENT: event mode,
   initialisation's end included; ST_CONTINUOUS: continuous-time mode), and an array of the wrong size
   or NULL, with STATUS_ERROR and a logged reason; nothing aborts.

   The importer integrates dx/dt = f(t, x, u) with the branches of the right-hand side locked
   (switching.h), and locates the sign changes of the event indicators, the switching functions g.
   An event update (me_update_discrete_states) locks the modes from the state and inputs, and applies
   the limit resets before, where the co-simulation step does:
   * where a communication step starts: the first event after initialisation, inputs that changed
     since the last lock, a reset an integrator step's end asked for;
   * at a located switching (an indicator's sign change) where the branches that now hold change
     dx/dt (a condition in a branch not taken changes nothing: its mode follows, no reset).
   A condition locked at its switching point (g = 0 exactly) takes the branch that holds just after.
   The FMU state holds the locked modes, the inputs they were locked at and whether a full lock is
   due, so a restored state integrates on exactly as it would have. */
#ifndef OPFMU_MODEL_EXCHANGE_H
#define OPFMU_MODEL_EXCHANGE_H

#include "cosimulation.h"

/* der(x) (VR_FIRST_DERIVATIVE: dx/dt on the locked branches) and the event indicators
   (VR_FIRST_INDICATOR: the switching functions) at m's time, state and inputs; MODEL_ERROR if vr
   names neither */
OPFMU_INTERNAL ModelStatus exchange_get_real(const ModelState *m, unsigned int vr, double *value);

/* the time [s] the states and inputs are at (finite) */
OPFMU_INTERNAL Status me_set_time(Instance *inst, const char *function, double time);
/* the continuous states x [n]: n must be OPFMU_N_STATES, every value finite (continuous-time mode) */
OPFMU_INTERNAL Status me_set_states(Instance *inst, const char *function, const double x[], size_t n);
/* the continuous states, their derivatives on the locked branches, the event indicators (the
   switching functions, n = OPFMU_N_SWITCHING) and the states' nominal values (1) into out [n] */
OPFMU_INTERNAL Status me_get_states(Instance *inst, const char *function, double out[], size_t n);
OPFMU_INTERNAL Status me_get_derivatives(Instance *inst, const char *function, double out[], size_t n);
OPFMU_INTERNAL Status me_get_indicators(Instance *inst, const char *function, double out[], size_t n);
OPFMU_INTERNAL Status me_get_nominals(Instance *inst, const char *function, double out[], size_t n);
OPFMU_INTERNAL Status me_enter_event_mode(Instance *inst, const char *function);
/* the event update (above); *values_changed nonzero where a reset moved a state. No further
   iteration and no time event is ever needed. */
OPFMU_INTERNAL Status me_update_discrete_states(Instance *inst, const char *function, int *values_changed);
OPFMU_INTERNAL Status me_enter_continuous_time_mode(Instance *inst, const char *function);
/* *enter_event_mode nonzero where the accepted step's end needs an event: the reset would move a
   state (one held on a limit that moved inward since, which the co-simulation step places on it at
   each communication point: a full lock is then due), or the branches that hold there change dx/dt
   from the locked ones (a change the importer's indicators did not see, such as an indicator that
   touched zero) */
OPFMU_INTERNAL Status me_completed_integrator_step(Instance *inst, const char *function, int *enter_event_mode);

#endif

/* The interface between the FMI plumbing (cosimulation.c, under fmi2_cs.c or fmi3_cs.c) and one model.

   Both native FMUs (the surrogate and the reference) compile the plumbing and variables.c unchanged
   against this interface, for FMI 2.0 and 3.0 alike; a model never touches an FMI call. Per FMU,
   generated at build time: config.h (sizes, defaults, component tables, OPFMU_STATE_HEADER: the
   header that defines the model's ModelState), variables.h (the value references of the model
   description, groups VR_FIRST_INPUT, VR_FIRST_STATE, VR_FIRST_OUTPUT, VR_FIRST_START, and
   VR_FIRST_BUS where the FMU has the bus port's outputs, which variables.c computes), equations.c
   (the component's right-hand side and derived outputs) and derivatives.c (their exact partial
   derivatives).

   A model's whole dynamic state is the plain struct ModelState, so the plumbing copies and
   serialises it byte for byte, and asks the model (model_check_state) whether a state it did not
   make itself is one the model can run from. Every ModelState has at least the fields
       double time;                  current communication point [s]
       double u[OPFMU_N_INPUTS];     inputs (the component's, in its order)
       double du[OPFMU_N_INPUTS];    their first time derivatives over the next steps [unit/s] (0: held)
       double x[OPFMU_X_SIZE];       state at `time`
       double x_start[OPFMU_X_SIZE]; initial-state parameters
       double p[OPFMU_P_SIZE];       the component's parameters (OPFMU_N_PARAMS, value references from
                                     VR_FIRST_PARAM), then the parameters derived from them (model_derive)
   which variables.c reads and writes for the component's own variables (the first OPFMU_N_STATES
   of x and x_start: a component without states has none, and one unused element, as C needs).

   The generated equations read the parameters from p (fmu_export/c_parameters.py): a parameter set
   by the importer is checked (model_check_parameters: its range, the structural parameters the
   equations were generated for, and for a surrogate the trained values) and the derived ones follow
   it. A surrogate's equations hold its trained values as literals; its p only holds them. */
#ifndef OPFMU_MODEL_H
#define OPFMU_MODEL_H

#include <stddef.h>

#include "config.h"

/* functions shared between the FMU's source files but not exported from its binary (on Windows
   only the FMI functions, declared dllexport by the FMI headers, are exported) */
#if defined(__GNUC__) && !defined(_WIN32)
#define OPFMU_INTERNAL __attribute__((visibility("hidden")))
#else
#define OPFMU_INTERNAL
#endif

typedef enum { MODEL_OK = 0, MODEL_WARNING = 1, MODEL_ERROR = 3 } ModelStatus;

/* Variable kinds the plumbing checks writes against (VAR_LOCAL: read only, neither an output nor
   settable: the native reference FMU's state derivatives and event indicators) */
typedef enum { VAR_INPUT, VAR_PARAMETER, VAR_OUTPUT, VAR_LOCAL } VarKind;

/* value reference vr lies in the group of n starting at first */
#define IN_GROUP(vr, first, n) ((unsigned int)((vr) - (first)) < (unsigned int)(n))

/* columns of the component's Jacobians: the states, then the inputs */
#define OPFMU_N_COLUMNS (OPFMU_N_STATES + OPFMU_N_INPUTS)

/* the declared size of an array of the states: at least 1, as C requires (n_x = 0: one unused) */
#define OPFMU_X_SIZE (OPFMU_N_STATES > 0 ? OPFMU_N_STATES : 1)

#ifdef OPFMU_SELF_START
/* the start from the load flow (self_start.c), a field `start` of either model's ModelState */
typedef struct {
    double flow[4];           /* parameters V_lf [pu], theta_lf [rad], P_lf, Q_lf [pu, system base] */
    double delivered[SELF_START_N_DELIVERS > 0 ? SELF_START_N_DELIVERS : 1]; /* parameters <y>_init */
    double solved[SELF_START_N_SOLVES > 0 ? SELF_START_N_SOLVES : 1];        /* calculated <u>_init */
    int stale;                /* 1 while the solved start may not match what is set */
    int in_x;                 /* 1 where the state x holds the solved start (not x_start) */
    int bus_voltage_set;      /* 1 once the importer set a bus voltage input: it keeps its value */
} SelfStartState;
#endif

#include OPFMU_STATE_HEADER /* the model's ModelState */

/* --- the component's equations (equations.c, derivatives.c: generated from its definition), at the
   parameters p (OPFMU_P_SIZE: the parameters, then the derived ones) --- */
OPFMU_INTERNAL void model_derivatives(const double x[OPFMU_X_SIZE], const double u[OPFMU_N_INPUTS], const double p[],
                                      double dx[OPFMU_X_SIZE]);
OPFMU_INTERNAL void model_outputs(const double x[OPFMU_X_SIZE], const double u[OPFMU_N_INPUTS], const double p[],
                                  double y[OPFMU_N_OUTPUTS]);
/* J[i * OPFMU_N_COLUMNS + j] = d (dx_i/dt) / d (x, u)_j, exact */
OPFMU_INTERNAL void component_rhs_jacobian(const double x[OPFMU_X_SIZE], const double u[OPFMU_N_INPUTS],
                                           const double p[], double J[OPFMU_X_SIZE * OPFMU_N_COLUMNS]);
/* J[i * OPFMU_N_COLUMNS + j] = d y_i / d (x, u)_j, exact */
OPFMU_INTERNAL void component_output_jacobian(const double x[OPFMU_X_SIZE], const double u[OPFMU_N_INPUTS],
                                              const double p[], double J[OPFMU_N_OUTPUTS * OPFMU_N_COLUMNS]);
/* the derived parameters p[OPFMU_N_PARAMS..] from the parameters p[0..OPFMU_N_PARAMS) */
OPFMU_INTERNAL void model_derive(double p[OPFMU_P_SIZE]);
/* MODEL_ERROR (why written) where the parameters p (derived ones computed) break a rule: with only >= 0
   the rules that read parameter `only` alone (a value being set), with only < 0 every rule (ranges,
   structural parameters, relations between parameters: at initialisation) */
OPFMU_INTERNAL ModelStatus model_check_parameters(const double p[OPFMU_P_SIZE], int only, char *why, size_t size);

/* --- variables.c (both FMUs): the component's variables by value reference --- */
/* kind of a real variable, or -1 if vr names none */
OPFMU_INTERNAL int model_real_kind(unsigned int vr);
OPFMU_INTERNAL ModelStatus model_get_real(const ModelState *m, unsigned int vr, double *value);
OPFMU_INTERNAL ModelStatus model_set_real(ModelState *m, unsigned int vr, double value, char *message, size_t size);
/* the derived outputs' Jacobian at the current state and inputs, J[i * OPFMU_N_COLUMNS + j] */
OPFMU_INTERNAL void model_output_jacobian(const ModelState *m, double J[OPFMU_N_OUTPUTS * OPFMU_N_COLUMNS]);
/* nonzero where output vr's derivatives with respect to the inputs come from that Jacobian: a derived
   output, or the bus port's P_bus, Q_bus */
OPFMU_INTERNAL int model_partials_from_jacobian(unsigned int vr);
/* d unknown / d known (an output and an input, by value reference) at m, from the outputs' Jacobian J
   there: zero for a state, which does not depend on the inputs directly */
OPFMU_INTERNAL double model_partial(const ModelState *m, const double J[], unsigned int unknown, unsigned int known);
/* why the component's output vr has no directional derivative (the bus port's Norton outputs), or NULL */
OPFMU_INTERNAL const char *component_no_derivative(unsigned int vr);
/* every field of m zero but the component's: inputs at their start values, the initial state and
   the state at the default initial state */
OPFMU_INTERNAL void component_defaults(ModelState *m);
/* where the FMU starts from the load flow (fmu_export/self_start.py) and the importer asked for it (a
   start parameter set to another value than its default and no initial-state parameter <state>0 to
   another than its own):
   solves the start from the start parameters (V_lf, theta_lf, P_lf, Q_lf, <y>_init) into the state,
   the solved inputs and their calculated parameters (self_start_solve), unless nothing was set since
   it last did; MODEL_ERROR (why written) where there is no such start. MODEL_OK otherwise. */
OPFMU_INTERNAL ModelStatus component_settle_start(ModelState *m, char *why, size_t size);
/* at the end of initialisation: the start settled (component_settle_start) and the state x at it, or
   at the initial-state parameters x_start; MODEL_ERROR (why written) where there is no such start */
OPFMU_INTERNAL ModelStatus component_initial_state(ModelState *m, char *why, size_t size);
#ifdef OPFMU_SELF_START
/* self_start.c: the start from the load flow, unconditionally */
OPFMU_INTERNAL ModelStatus self_start_solve(ModelState *m, char *why, size_t size);
#endif
#ifdef OPFMU_HAS_START_EQUATIONS
/* the component's start equations where they differ from its rates (Component.start_equations):
   their residuals r [OPFMU_N_STATES] and Jacobian J[i * OPFMU_N_COLUMNS + j] = d r_i / d (x, u)_j */
OPFMU_INTERNAL void model_start_equations(const double x[], const double u[], const double p[], double r[]);
OPFMU_INTERNAL void component_start_jacobian(const double x[], const double u[], const double p[], double J[]);
#endif
/* sets the time derivative of order `order` (1 [unit/s]; 2 [unit/s^2] where OPFMU_INPUT_ORDER is 2, in
   the model's d2u) of input c (0-based) for the next steps: over each, u + du tau + d2u tau^2 / 2 with
   tau the time into the step */
OPFMU_INTERNAL ModelStatus model_set_input_derivative(ModelState *m, unsigned int c, int order, double value,
                                                      char *message, size_t size);
/* MODEL_ERROR (why written) unless the component's fields of m (time, u, du, x, x_start, p) are finite,
   the inputs at or above their lower bounds, as the setters and steps keep them, and the parameters
   pass every rule with their derived ones as model_derive gives them */
OPFMU_INTERNAL ModelStatus check_component_state(const ModelState *m, char *why, size_t size);
/* MODEL_ERROR (message written) where an input with a nonzero derivative ends a step at u_end
   non-finite or below its lower bound beyond the tolerance (an input held over the step is u_end
   itself, already checked); an end value within the tolerance below its bound is set to the bound */
OPFMU_INTERNAL ModelStatus check_inputs_at_step_end(const ModelState *m, double u_end[OPFMU_N_INPUTS],
                                                    char *message, size_t size);
/* the index of the first of the n values at v that is not finite, or -1 */
OPFMU_INTERNAL int first_non_finite(const double *v, int n);

/* --- each model provides --- */
OPFMU_INTERNAL void model_defaults(ModelState *m);
OPFMU_INTERNAL ModelStatus model_initialize(ModelState *m, double start_time, char *message, size_t size);
/* advances m from m->time to m->time + h (inputs held, or linear where their derivatives are set) */
OPFMU_INTERNAL ModelStatus model_do_step(ModelState *m, double h, char *message, size_t size);
/* the model's own Real variables (those after the component's groups): MODEL_ERROR if vr names none */
OPFMU_INTERNAL ModelStatus model_get_extra(const ModelState *m, unsigned int vr, double *value);
OPFMU_INTERNAL ModelStatus model_set_extra(ModelState *m, unsigned int vr, double value, char *message, size_t size);
OPFMU_INTERNAL int model_boolean_exists(unsigned int vr);
OPFMU_INTERNAL int model_get_boolean(const ModelState *m, unsigned int vr);
/* why the model's own output vr has no directional derivative (a diagnostic), or NULL */
OPFMU_INTERNAL const char *model_no_derivative(unsigned int vr);
/* MODEL_ERROR (why written) unless every field of m lies in the range the model's setters and steps
   keep it in (check_component_state for the component's fields): a state from the importer's bytes
   is run only if it passes, so none can make a step hang or run with values the setters refuse */
OPFMU_INTERNAL ModelStatus model_check_state(const ModelState *m, char *why, size_t size);

#endif

/* The FMI plumbing both versions share (cosimulation.c): the instance, the FMI state machine,
   logging and status helpers, the checks of a step, of variable access and of derivative requests,
   and FMU state snapshots (get, set, free, serialize, deserialize, each validated). fmi2_cs.c and
   fmi3_cs.c hold only their version's API: its types, how its arguments map onto these functions,
   and what that version refuses on its own. Every function here takes the calling FMI function's
   name for its messages and returns a Status with the values fmi2Status and fmi3Status share. */
#ifndef OPFMU_COSIMULATION_H
#define OPFMU_COSIMULATION_H

#include <stdarg.h>
#include <stddef.h>

#include "model.h"

/* the status codes of FMI 2.0 and 3.0 (fmi2Status and fmi3Status have these values) */
typedef enum { STATUS_OK = 0, STATUS_WARNING = 1, STATUS_DISCARD = 2, STATUS_ERROR = 3 } Status;

/* ST_STEP: co-simulation's step mode; ST_EVENT, ST_CONTINUOUS: Model Exchange's event and
   continuous-time modes (model_exchange.h), after initialisation */
typedef enum {
    ST_INSTANTIATED = 1, ST_INIT = 2, ST_STEP = 4, ST_TERMINATED = 8, ST_ERROR = 16, ST_EVENT = 32, ST_CONTINUOUS = 64
} MachineState;
#define ST_RUNNING (ST_STEP | ST_EVENT | ST_CONTINUOUS)
#define ST_ANY (ST_INSTANTIATED | ST_INIT | ST_RUNNING | ST_TERMINATED | ST_ERROR)
#define ST_INITIALIZED (ST_RUNNING | ST_TERMINATED | ST_ERROR)

typedef struct Instance Instance;

/* passes one message (no '%' in it) to the importer's logger, the way the FMI version calls it */
typedef void (*EmitFunction)(const Instance *inst, Status status, const char *category, const char *message);

/* what an FMU state holds: a header (what it is, the machine state) and the model state; its bytes
   are its serialized form */
typedef struct {
    unsigned int magic; /* the FMI version's SNAPSHOT magic: a state of the other version is refused */
    unsigned int size;  /* sizeof(Snapshot) */
    char guid[48];      /* OPFMU_GUID */
    MachineState state;
    ModelState model;
} Snapshot;

struct Instance {
    EmitFunction emit;      /* the version's call of the importer's logger */
    void *environment;      /* the importer's environment pointer, passed back to its logger */
    void (*logger)(void);   /* the importer's logger, of its version's type (emit casts it back); NULL: none */
    char *name;             /* the instance name (a copy) */
    unsigned int snapshot_magic;
    int log_warnings, log_errors, log_all;
    MachineState state;
    int model_exchange;     /* instantiated for Model Exchange (model_exchange.h), not co-simulation */
    double start_time;      /* [s] */
    Snapshot **snapshots;   /* the FMU states this instance handed out and has not freed */
    size_t n_snapshots, snapshot_capacity;
    ModelState model;
};

/* formats a message into message[size] with every '%' replaced (the logger takes it as its format) */
OPFMU_INTERNAL void format_message(char *message, size_t size, const char *format, va_list args);
/* logs through the instance's logger where its logging settings let this status through */
OPFMU_INTERNAL void log_message(const Instance *inst, Status status, const char *category, const char *format, ...);
/* logs format (with one string detail) under the status's category; returns status */
OPFMU_INTERNAL Status fail(Instance *inst, Status status, const char *format, const char *detail);
/* nonzero if the call is not allowed in the instance's state (logged), or there is no instance */
OPFMU_INTERNAL int not_allowed(Instance *inst, const char *function, int allowed);
/* a model's status as an FMI status, its message logged */
OPFMU_INTERNAL Status model_status(Instance *inst, ModelStatus status, const char *message);

/* a new instance in state ST_INSTANTIATED with the model's defaults; NULL when out of memory */
OPFMU_INTERNAL Instance *instance_new(const char *name, unsigned int snapshot_magic, EmitFunction emit,
                                      void *environment, void (*logger)(void), int logging_on);
/* frees the instance and every FMU state it handed out that was not freed */
OPFMU_INTERNAL void instance_free(Instance *inst);
/* FMI 3.0 (fmi3_cs.c): a new instance for either interface, after the checks both share (a name, the
   instantiation token); NULL (logged through the importer's fmi3LogMessageCallback `logger`, named
   `function`) when refused or out of memory */
OPFMU_INTERNAL Instance *fmi3_new_instance(const char *function, const char *name, const char *token, int logging_on,
                                           void *environment, void (*logger)(void));

OPFMU_INTERNAL Status cs_set_debug_logging(Instance *inst, const char *function, int on, size_t n,
                                           const char *const categories[]);
/* the experiment's tolerance (if defined: positive and finite), start and stop time [s] */
OPFMU_INTERNAL Status cs_setup_experiment(Instance *inst, const char *function, int tolerance_defined,
                                          double tolerance, double start_time, int stop_time_defined,
                                          double stop_time);
OPFMU_INTERNAL Status cs_enter_initialization(Instance *inst, const char *function);
OPFMU_INTERNAL Status cs_exit_initialization(Instance *inst, const char *function);
OPFMU_INTERNAL Status cs_terminate(Instance *inst, const char *function);
OPFMU_INTERNAL Status cs_reset(Instance *inst, const char *function);

/* one Real variable by its model value reference */
OPFMU_INTERNAL Status cs_get_real(Instance *inst, const char *function, unsigned int vr, double *value);
OPFMU_INTERNAL Status cs_set_real(Instance *inst, const char *function, unsigned int vr, double value);
/* the first time derivative of input vr (order must be 1) */
OPFMU_INTERNAL Status cs_set_input_derivative(Instance *inst, const char *function, unsigned int vr, int order,
                                              double value);

/* a communication step from t [s] of length h [s]: refused unless h is positive and finite and t
   is the FMU's time */
OPFMU_INTERNAL Status cs_do_step(Instance *inst, const char *function, double t, double h);

/* The checks of a directional or adjoint derivative request: knowns must be inputs, unknowns
   outputs (a model's diagnostic output and the bus port's Norton outputs are refused with their
   reason), each seed (of value reference seeded[j]) finite. Where an unknown's derivatives come from
   the outputs' Jacobian (model_partials_from_jacobian), it goes into J; model_partial then gives
   d unknown / d known. Nonzero: refused (logged). */
OPFMU_INTERNAL int cs_derivatives_refused(Instance *inst, const char *function, const unsigned int unknowns[],
                                          size_t n_unknowns, const unsigned int knowns[], size_t n_knowns,
                                          const unsigned int seeded[], const double seed[], size_t n_seed,
                                          double J[]);

/* FMU states: *state NULL gets a new one; a non-NULL one must be one this instance handed out */
OPFMU_INTERNAL Status cs_get_state(Instance *inst, const char *function, void **state);
OPFMU_INTERNAL Status cs_set_state(Instance *inst, const char *function, const void *state);
OPFMU_INTERNAL Status cs_free_state(Instance *inst, const char *function, void **state);
OPFMU_INTERNAL Status cs_serialized_state_size(Instance *inst, const char *function, const void *state,
                                               size_t *size);
OPFMU_INTERNAL Status cs_serialize_state(Instance *inst, const char *function, const void *state,
                                         unsigned char *bytes, size_t size);
OPFMU_INTERNAL Status cs_deserialize_state(Instance *inst, const char *function, const unsigned char *bytes,
                                           size_t size, void **state);

#endif

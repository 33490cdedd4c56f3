/* The FMI plumbing both versions share (cosimulation.h says what each function does). Model
   behaviour lives behind model.h; every misuse returns STATUS_ERROR (or STATUS_DISCARD) with a
   reason through the importer's logger, and nothing aborts. An FMU state is checked before it is
   used: its header (magic, size, GUID, machine state) here, its model state by the model
   (model_check_state), so that no state can make a step hang or run with values the FMU's setters
   refuse; a refused state leaves the instance as it was. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cosimulation.h"
#ifdef OPFMU_MODEL_EXCHANGE
#include "switching.h"
#endif
#include "variables.h"

void format_message(char *message, size_t size, const char *format, va_list args)
{
    vsnprintf(message, size, format, args);
    for (char *c = message; *c; ++c)
        if (*c == '%') *c = '#'; /* the message reaches the logger as its format: no conversions */
}

void log_message(const Instance *inst, Status status, const char *category, const char *format, ...)
{
    char message[1024];
    va_list args;
    if (!inst || !inst->logger) return;
    if (status == STATUS_ERROR && !(inst->log_errors || inst->log_all)) return;
    if (status == STATUS_WARNING && !(inst->log_warnings || inst->log_all)) return;
    if (status == STATUS_OK && !inst->log_all) return;
    va_start(args, format);
    format_message(message, sizeof message, format, args);
    va_end(args);
    inst->emit(inst, status, category, message);
}

Status fail(Instance *inst, Status status, const char *format, const char *detail)
{
    log_message(inst, status, status == STATUS_ERROR ? "logStatusError" : "logStatusWarning", format, detail);
    return status;
}

int not_allowed(Instance *inst, const char *function, int allowed)
{
    if (!inst) return 1;
    if (inst->state & allowed) return 0;
    log_message(inst, STATUS_ERROR, "logStatusError", "%s is not allowed in the current state of the FMU", function);
    return 1;
}

Status model_status(Instance *inst, ModelStatus status, const char *message)
{
    if (status == MODEL_ERROR) return fail(inst, STATUS_ERROR, "%s", message);
    if (status == MODEL_WARNING) log_message(inst, STATUS_WARNING, "logStatusWarning", "%s", message);
    return STATUS_OK;
}

/* The instance is one allocation with its ModelState (with the surrogate's sensor buffers, most of a
   megabyte), which never lives on the importer's stack. */
Instance *instance_new(const char *name, unsigned int snapshot_magic, EmitFunction emit, void *environment,
                       void (*logger)(void), int logging_on)
{
    Instance *inst = (Instance *)calloc(1, sizeof(Instance));
    char *copy = (char *)malloc(strlen(name) + 1);
    if (!inst || !copy) {
        free(inst);
        free(copy);
        return NULL;
    }
    strcpy(copy, name);
    inst->emit = emit;
    inst->environment = environment;
    inst->logger = logger;
    inst->name = copy;
    inst->snapshot_magic = snapshot_magic;
    inst->log_errors = inst->log_warnings = 1;
    inst->log_all = logging_on;
    inst->state = ST_INSTANTIATED;
    model_defaults(&inst->model);
    return inst;
}

void instance_free(Instance *inst)
{
    if (!inst) return;
    for (size_t i = 0; i < inst->n_snapshots; ++i) free(inst->snapshots[i]);
    free(inst->snapshots);
    free(inst->name);
    free(inst);
}

Status cs_set_debug_logging(Instance *inst, const char *function, int on, size_t n, const char *const categories[])
{
    char message[512];
    if (not_allowed(inst, function, ST_ANY)) return STATUS_ERROR;
    if (n == 0) {
        inst->log_warnings = inst->log_errors = inst->log_all = on;
        return STATUS_OK;
    }
    for (size_t i = 0; i < n; ++i) {
        if (!categories || !categories[i]) {
            snprintf(message, sizeof message, "%s: category is NULL", function);
            return fail(inst, STATUS_ERROR, "%s", message);
        }
        if (!strcmp(categories[i], "logStatusWarning")) inst->log_warnings = on;
        else if (!strcmp(categories[i], "logStatusError")) inst->log_errors = on;
        else if (!strcmp(categories[i], "logAll")) inst->log_all = on;
        else {
            snprintf(message, sizeof message, "%s: unknown log category %.200s", function, categories[i]);
            return fail(inst, STATUS_ERROR, "%s", message);
        }
    }
    return STATUS_OK;
}

Status cs_setup_experiment(Instance *inst, const char *function, int tolerance_defined, double tolerance,
                           double start_time, int stop_time_defined, double stop_time)
{
    char message[512];
    if (not_allowed(inst, function, ST_INSTANTIATED)) return STATUS_ERROR;
    if (tolerance_defined && !(tolerance > 0.0 && isfinite(tolerance))) {
        snprintf(message, sizeof message, "%s: tolerance %g must be positive and finite", function, tolerance);
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    if (!isfinite(start_time) || (stop_time_defined && !(stop_time >= start_time))) {
        snprintf(message, sizeof message, "%s: start time must be finite and not after the stop time", function);
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    inst->start_time = start_time;
    return STATUS_OK;
}

Status cs_enter_initialization(Instance *inst, const char *function)
{
    if (not_allowed(inst, function, ST_INSTANTIATED)) return STATUS_ERROR;
    inst->state = ST_INIT;
    return STATUS_OK;
}

Status cs_exit_initialization(Instance *inst, const char *function)
{
    char message[512] = "";
    if (not_allowed(inst, function, ST_INIT)) return STATUS_ERROR;
    if (model_check_parameters(inst->model.p, -1, message, sizeof message) != MODEL_OK) {
        char refused[700];
        snprintf(refused, sizeof refused, "%s: %s", function, message);
        inst->state = ST_ERROR;
        return fail(inst, STATUS_ERROR, "%s", refused);
    }
    Status status = model_status(inst, model_initialize(&inst->model, inst->start_time, message, sizeof message),
                                 message);
#ifdef OPFMU_MODEL_EXCHANGE
    if (status != STATUS_ERROR) initial_lock(&inst->model); /* the branches at the initial state and inputs */
#endif
    inst->state = status == STATUS_ERROR ? ST_ERROR : inst->model_exchange ? ST_EVENT : ST_STEP;
    return status;
}

Status cs_terminate(Instance *inst, const char *function)
{
    if (not_allowed(inst, function, ST_RUNNING | ST_ERROR)) return STATUS_ERROR;
    inst->state = ST_TERMINATED;
    return STATUS_OK;
}

Status cs_reset(Instance *inst, const char *function)
{
    if (not_allowed(inst, function, ST_ANY)) return STATUS_ERROR;
    inst->state = ST_INSTANTIATED;
    inst->start_time = 0.0;
    model_defaults(&inst->model);
    return STATUS_OK;
}

Status cs_get_real(Instance *inst, const char *function, unsigned int vr, double *value)
{
    char message[512], why[400];
    if (inst->state == ST_INIT && component_settle_start(&inst->model, why, sizeof why) != MODEL_OK) {
        snprintf(message, sizeof message, "%s: %s", function, why);
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    if (model_get_real(&inst->model, vr, value) == MODEL_OK) return STATUS_OK;
    snprintf(message, sizeof message, "%s: no Real variable with value reference %u", function, vr);
    return fail(inst, STATUS_ERROR, "%s", message);
}

Status cs_set_real(Instance *inst, const char *function, unsigned int vr, double value)
{
    char message[512], reason[400];
    int kind = model_real_kind(vr);
    if (kind == VAR_OUTPUT || kind == VAR_LOCAL || kind < 0) {
        snprintf(message, sizeof message, "%s: value reference %u is not an input or parameter", function, vr);
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    if (kind == VAR_PARAMETER && (inst->state & ST_RUNNING)) {
        snprintf(message, sizeof message, "%s: parameter %u is fixed after initialization", function, vr);
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    if (model_set_real(&inst->model, vr, value, reason, sizeof reason) != MODEL_OK) {
        snprintf(message, sizeof message, "%s: %s", function, reason);
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    return STATUS_OK;
}

Status cs_set_input_derivative(Instance *inst, const char *function, unsigned int vr, int order, double value)
{
    char message[512], reason[400];
    if (inst->model_exchange) {
        snprintf(message, sizeof message, "%s: input derivatives are for co-simulation (under Model Exchange the "
                 "importer sets the inputs at each time)", function);
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    if (model_real_kind(vr) != VAR_INPUT || !IN_GROUP(vr, VR_FIRST_INPUT, OPFMU_N_INPUTS)) {
        snprintf(message, sizeof message, "%s: value reference %u is not an input", function, vr);
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    if (order < 1 || order > OPFMU_INPUT_ORDER) {
        snprintf(message, sizeof message, "%s: order %d of value reference %u: derivatives of order 1%s are supported "
                 "(inputs %s over a step)", function, order, vr, OPFMU_INPUT_ORDER > 1 ? " and 2" : " only",
                 OPFMU_INPUT_ORDER > 1 ? "quadratic at most" : "linear");
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    if (model_set_input_derivative(&inst->model, vr - VR_FIRST_INPUT, order, value, reason, sizeof reason)
        != MODEL_OK) {
        snprintf(message, sizeof message, "%s: %s", function, reason);
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    return STATUS_OK;
}

Status cs_do_step(Instance *inst, const char *function, double t, double h)
{
    char message[512] = "";
    if (not_allowed(inst, function, ST_STEP)) return STATUS_ERROR;
    if (!(h > 0.0) || !isfinite(h)) {
        snprintf(message, sizeof message, "%s: communication step size %g must be positive and finite", function, h);
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    if (!isfinite(t) || fabs(t - inst->model.time) > 1e-9 * fmax(1.0, fabs(inst->model.time))) {
        snprintf(message, sizeof message, "%s: communication point %.12g s is not the FMU's time %.12g s", function, t,
                 inst->model.time);
        return fail(inst, STATUS_ERROR, "%s", message);
    }
    Status status = model_status(inst, model_do_step(&inst->model, h, message, sizeof message), message);
    if (status == STATUS_ERROR) inst->state = ST_ERROR;
    return status;
}

int cs_derivatives_refused(Instance *inst, const char *function, const unsigned int unknowns[], size_t n_unknowns,
                           const unsigned int knowns[], size_t n_knowns, const unsigned int seeded[],
                           const double seed[], size_t n_seed, double J[])
{
    char message[512];
    for (size_t k = 0; k < n_knowns; ++k) {
        if (model_real_kind(knowns[k]) != VAR_INPUT || !IN_GROUP(knowns[k], VR_FIRST_INPUT, OPFMU_N_INPUTS)) {
            snprintf(message, sizeof message, "%s: known value reference %u is not an input (derivatives are of "
                     "outputs with respect to inputs)", function, knowns[k]);
            fail(inst, STATUS_ERROR, "%s", message);
            return 1;
        }
    }
    for (size_t j = 0; j < n_seed; ++j) {
        if (!isfinite(seed[j])) {
            snprintf(message, sizeof message, "%s: seed %g of value reference %u is not a finite number", function,
                     seed[j], seeded[j]);
            fail(inst, STATUS_ERROR, "%s", message);
            return 1;
        }
    }
    int derived = 0;
    for (size_t i = 0; i < n_unknowns; ++i) {
        const unsigned int vr = unknowns[i];
        if (model_real_kind(vr) != VAR_OUTPUT) {
            snprintf(message, sizeof message, "%s: unknown value reference %u is not an output", function, vr);
            fail(inst, STATUS_ERROR, "%s", message);
            return 1;
        }
        if (model_partials_from_jacobian(vr)) {
            derived = 1;
        } else if (!IN_GROUP(vr, VR_FIRST_STATE, OPFMU_N_STATES)) {
            const char *reason = component_no_derivative(vr);
            if (!reason) reason = model_no_derivative(vr);
            snprintf(message, sizeof message, "%s: output %u: %s", function, vr,
                     reason ? reason : "has no directional derivative");
            fail(inst, STATUS_ERROR, "%s", message);
            return 1;
        }
    }
    if (derived) model_output_jacobian(&inst->model, J);
    return 0;
}

/* --- FMU states --- */

/* the index of a state this instance handed out, or -1 */
static long snapshot_index(const Instance *inst, const void *state)
{
    for (size_t i = 0; i < inst->n_snapshots; ++i)
        if (inst->snapshots[i] == state) return (long)i;
    return -1;
}

/* a refusal naming the function, with a reason */
static Status refuse_state(Instance *inst, const char *function, const char *reason)
{
    char message[700];
    snprintf(message, sizeof message, "%s: %s", function, reason);
    return fail(inst, STATUS_ERROR, "%s", message);
}

/* nonzero (why written) unless snap is a state of this FMU and version whose every field lies in
   the ranges the FMU's setters and steps keep it in */
static int bad_snapshot(const Instance *inst, const Snapshot *snap, char *why, size_t size)
{
    const MachineState s = snap->state;
    if (snap->magic != inst->snapshot_magic || snap->size != sizeof(Snapshot)) {
        snprintf(why, size, "corrupt or foreign state (not an FMU state of this FMU and FMI version)");
        return 1;
    }
    if (strncmp(snap->guid, OPFMU_GUID, sizeof snap->guid)) {
        snprintf(why, size, "corrupt or foreign state (the state is of another FMU: its GUID is not %s)", OPFMU_GUID);
        return 1;
    }
    if (s != ST_INSTANTIATED && s != ST_INIT && s != ST_STEP && s != ST_TERMINATED && s != ST_ERROR &&
        s != ST_EVENT && s != ST_CONTINUOUS) {
        snprintf(why, size, "corrupt state: machine state %d is none of the FMU's", (int)s);
        return 1;
    }
    if (s & (inst->model_exchange ? ST_STEP : ST_EVENT | ST_CONTINUOUS)) {
        snprintf(why, size, "the state is of an instance for %s, this one is for %s",
                 inst->model_exchange ? "co-simulation" : "Model Exchange",
                 inst->model_exchange ? "Model Exchange" : "co-simulation");
        return 1;
    }
    char reason[400] = "";
    if (model_check_state(&snap->model, reason, sizeof reason) != MODEL_OK) {
        snprintf(why, size, "corrupt state: %s", reason);
        return 1;
    }
    return 0;
}

/* adds a state to those this instance handed out; 0 when out of memory */
static int keep_snapshot(Instance *inst, Snapshot *snap)
{
    if (inst->n_snapshots == inst->snapshot_capacity) {
        size_t capacity = inst->snapshot_capacity ? 2 * inst->snapshot_capacity : 4;
        Snapshot **grown = (Snapshot **)realloc(inst->snapshots, capacity * sizeof *grown);
        if (!grown) return 0;
        inst->snapshots = grown;
        inst->snapshot_capacity = capacity;
    }
    inst->snapshots[inst->n_snapshots++] = snap;
    return 1;
}

Status cs_get_state(Instance *inst, const char *function, void **state)
{
    if (not_allowed(inst, function, ST_ANY)) return STATUS_ERROR;
    if (!state) return refuse_state(inst, function, "NULL state pointer");
    if (*state && snapshot_index(inst, *state) < 0)
        return refuse_state(inst, function, "the state to overwrite is not one this instance handed out");
    Snapshot *snap = (Snapshot *)*state;
    if (!snap) {
        snap = (Snapshot *)malloc(sizeof(Snapshot));
        if (!snap || !keep_snapshot(inst, snap)) {
            free(snap);
            return refuse_state(inst, function, "out of memory");
        }
    }
    memset(snap, 0, sizeof *snap);
    snap->magic = inst->snapshot_magic;
    snap->size = sizeof(Snapshot);
    strncpy(snap->guid, OPFMU_GUID, sizeof snap->guid - 1);
    snap->state = inst->state;
    snap->model = inst->model;
    *state = snap;
    return STATUS_OK;
}

Status cs_set_state(Instance *inst, const char *function, const void *state)
{
    char why[600];
    if (not_allowed(inst, function, ST_ANY)) return STATUS_ERROR;
    if (!state || snapshot_index(inst, state) < 0)
        return refuse_state(inst, function, "not an FMU state this instance handed out (getting or "
                                            "deserializing a state gives one)");
    const Snapshot *snap = (const Snapshot *)state;
    if (bad_snapshot(inst, snap, why, sizeof why)) return refuse_state(inst, function, why);
    inst->state = snap->state;
    inst->model = snap->model;
    return STATUS_OK;
}

Status cs_free_state(Instance *inst, const char *function, void **state)
{
    if (not_allowed(inst, function, ST_ANY)) return STATUS_ERROR;
    if (!state || !*state) return STATUS_OK; /* nothing to free */
    long i = snapshot_index(inst, *state);
    if (i < 0) return refuse_state(inst, function, "not an FMU state this instance handed out: not freed");
    free(inst->snapshots[i]);
    inst->snapshots[i] = inst->snapshots[--inst->n_snapshots];
    *state = NULL;
    return STATUS_OK;
}

Status cs_serialized_state_size(Instance *inst, const char *function, const void *state, size_t *size)
{
    if (not_allowed(inst, function, ST_ANY)) return STATUS_ERROR;
    if (!state || !size) return refuse_state(inst, function, "NULL argument");
    if (snapshot_index(inst, state) < 0) return refuse_state(inst, function, "not an FMU state this instance handed out");
    *size = sizeof(Snapshot);
    return STATUS_OK;
}

Status cs_serialize_state(Instance *inst, const char *function, const void *state, unsigned char *bytes, size_t size)
{
    if (not_allowed(inst, function, ST_ANY)) return STATUS_ERROR;
    if (!state || !bytes || size < sizeof(Snapshot))
        return refuse_state(inst, function, "NULL state or buffer too small");
    if (snapshot_index(inst, state) < 0) return refuse_state(inst, function, "not an FMU state this instance handed out");
    memcpy(bytes, state, sizeof(Snapshot));
    return STATUS_OK;
}

Status cs_deserialize_state(Instance *inst, const char *function, const unsigned char *bytes, size_t size,
                            void **state)
{
    char why[600];
    if (not_allowed(inst, function, ST_ANY)) return STATUS_ERROR;
    if (!bytes || !state || size != sizeof(Snapshot))
        return refuse_state(inst, function, "NULL argument or wrong size");
    if (*state && snapshot_index(inst, *state) < 0)
        return refuse_state(inst, function, "the state to overwrite is not one this instance handed out");
    Snapshot *probe = (Snapshot *)malloc(sizeof(Snapshot)); /* on the heap, aligned: the bytes need not be */
    if (!probe) return refuse_state(inst, function, "out of memory");
    memcpy(probe, bytes, sizeof(Snapshot));
    if (bad_snapshot(inst, probe, why, sizeof why)) {
        free(probe);
        return refuse_state(inst, function, why);
    }
    if (*state) { /* into a state this instance handed out */
        memcpy(*state, probe, sizeof(Snapshot));
        free(probe);
    } else {
        if (!keep_snapshot(inst, probe)) {
            free(probe);
            return refuse_state(inst, function, "out of memory");
        }
        *state = probe;
    }
    return STATUS_OK;
}

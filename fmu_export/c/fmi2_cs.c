/* FMI 2.0 co-simulation plumbing of both native FMUs: instances, the FMI state machine, logging,
   variable access, directional derivatives of the outputs with respect to the inputs, input
   derivatives (where the model can interpolate its inputs) and FMU state (get/set/serialize). Model
   behaviour lives behind model.h. Every misuse returns fmi2Error (or fmi2Discard) with a reason
   through the importer's logger; nothing aborts. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "model.h"
#include "variables.h"

typedef enum { ST_INSTANTIATED = 1, ST_INIT = 2, ST_STEP = 4, ST_TERMINATED = 8, ST_ERROR = 16 } MachineState;
#define ST_ANY (ST_INSTANTIATED | ST_INIT | ST_STEP | ST_TERMINATED | ST_ERROR)
#define ST_INITIALIZED (ST_STEP | ST_TERMINATED | ST_ERROR)

typedef struct {
    fmi2CallbackFunctions callbacks;
    char *name;
    int log_warnings, log_errors, log_all;
    MachineState state;
    double start_time;
    ModelState model;
} Instance;

/* what an FMU state holds: the machine state and the model state */
typedef struct {
    unsigned int magic;
    unsigned int size;
    char guid[48];
    MachineState state;
    ModelState model;
} Snapshot;

#define SNAPSHOT_MAGIC 0x0F3F5A11u

static void log_message(const Instance *inst, fmi2Status status, const char *category, const char *format, ...)
{
    char message[1024];
    va_list args;
    if (!inst || !inst->callbacks.logger) return;
    if (status == fmi2Error && !(inst->log_errors || inst->log_all)) return;
    if (status == fmi2Warning && !(inst->log_warnings || inst->log_all)) return;
    if (status == fmi2OK && !inst->log_all) return;
    va_start(args, format);
    vsnprintf(message, sizeof message, format, args);
    va_end(args);
    for (char *c = message; *c; ++c)
        if (*c == '%') *c = '#'; /* the message reaches the logger as its format: no conversions */
    inst->callbacks.logger(inst->callbacks.componentEnvironment, inst->name, status, category, message);
}

static fmi2Status fail(Instance *inst, fmi2Status status, const char *format, const char *detail)
{
    log_message(inst, status, status == fmi2Error ? "logStatusError" : "logStatusWarning", format, detail);
    return status;
}

/* returns nonzero if the call is not allowed now (and logs why) */
static int not_allowed(Instance *inst, const char *function, int allowed)
{
    if (!inst) return 1;
    if (inst->state & allowed) return 0;
    log_message(inst, fmi2Error, "logStatusError", "%s is not allowed in the current state of the FMU", function);
    return 1;
}

static fmi2Status model_status(Instance *inst, ModelStatus status, const char *message)
{
    if (status == MODEL_ERROR) return fail(inst, fmi2Error, "%s", message);
    if (status == MODEL_WARNING) log_message(inst, fmi2Warning, "logStatusWarning", "%s", message);
    return fmi2OK;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories, const fmi2String categories[])
{
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2SetDebugLogging", ST_ANY)) return fmi2Error;
    if (nCategories == 0) {
        inst->log_warnings = inst->log_errors = inst->log_all = loggingOn;
        return fmi2OK;
    }
    for (size_t i = 0; i < nCategories; ++i) {
        if (!categories || !categories[i]) return fail(inst, fmi2Error, "%s", "fmi2SetDebugLogging: category is NULL");
        if (!strcmp(categories[i], "logStatusWarning")) inst->log_warnings = loggingOn;
        else if (!strcmp(categories[i], "logStatusError")) inst->log_errors = loggingOn;
        else if (!strcmp(categories[i], "logAll")) inst->log_all = loggingOn;
        else return fail(inst, fmi2Error, "fmi2SetDebugLogging: unknown log category %s", categories[i]);
    }
    return fmi2OK;
}

/* The instance is allocated first, so that refusals are logged through it: a ModelState (with the
   surrogate's sensor buffers, most of a megabyte) never lives on the importer's stack. */
fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    (void)fmuResourceLocation;
    (void)visible;
    if (!functions || !functions->logger) return NULL;
    Instance *inst = (Instance *)calloc(1, sizeof(Instance));
    if (!inst) {
        functions->logger(functions->componentEnvironment, instanceName ? instanceName : "?", fmi2Error,
                          "logStatusError", "fmi2Instantiate: out of memory");
        return NULL;
    }
    inst->callbacks = *functions;
    inst->name = (char *)(instanceName ? instanceName : "?");
    inst->log_errors = inst->log_warnings = 1;
    char refusal[256] = "";
    if (!instanceName || !*instanceName) snprintf(refusal, sizeof refusal, "missing instance name");
    else if (fmuType != fmi2CoSimulation)
        snprintf(refusal, sizeof refusal, "%s supports co-simulation only", OPFMU_MODEL_IDENTIFIER);
    else if (!fmuGUID || strcmp(fmuGUID, OPFMU_GUID))
        snprintf(refusal, sizeof refusal, "GUID %.60s does not match this binary (%s)", fmuGUID ? fmuGUID : "(null)",
                 OPFMU_GUID);
    char *name = *refusal ? NULL : (char *)malloc(strlen(instanceName) + 1);
    if (!*refusal && !name) snprintf(refusal, sizeof refusal, "out of memory");
    if (*refusal) {
        log_message(inst, fmi2Error, "logStatusError", "fmi2Instantiate: %s", refusal);
        free(inst);
        return NULL;
    }
    strcpy(name, instanceName);
    inst->name = name;
    inst->log_all = loggingOn;
    inst->state = ST_INSTANTIATED;
    model_defaults(&inst->model);
    return inst;
}

void fmi2FreeInstance(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (!inst) return;
    free(inst->name);
    free(inst);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    Instance *inst = (Instance *)c;
    (void)toleranceDefined;
    (void)tolerance;
    if (not_allowed(inst, "fmi2SetupExperiment", ST_INSTANTIATED)) return fmi2Error;
    if (!isfinite(startTime) || (stopTimeDefined && !(stopTime >= startTime)))
        return fail(inst, fmi2Error, "%s", "fmi2SetupExperiment: start time must be finite and not after the stop time");
    inst->start_time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2EnterInitializationMode", ST_INSTANTIATED)) return fmi2Error;
    inst->state = ST_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    char message[512] = "";
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2ExitInitializationMode", ST_INIT)) return fmi2Error;
    fmi2Status status = model_status(inst, model_initialize(&inst->model, inst->start_time, message, sizeof message), message);
    inst->state = status == fmi2Error ? ST_ERROR : ST_STEP;
    return status;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2Terminate", ST_STEP | ST_ERROR)) return fmi2Error;
    inst->state = ST_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2Reset", ST_ANY)) return fmi2Error;
    inst->state = ST_INSTANTIATED;
    inst->start_time = 0.0;
    model_defaults(&inst->model);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2GetReal", ST_ANY)) return fmi2Error;
    if (nvr > 0 && (!vr || !value)) return fail(inst, fmi2Error, "%s", "fmi2GetReal: NULL array");
    for (size_t i = 0; i < nvr; ++i) {
        if (model_get_real(&inst->model, vr[i], &value[i]) != MODEL_OK) {
            char detail[64];
            snprintf(detail, sizeof detail, "%u", vr[i]);
            return fail(inst, fmi2Error, "fmi2GetReal: no Real variable with value reference %s", detail);
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    char message[512];
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2SetReal", ST_INSTANTIATED | ST_INIT | ST_STEP)) return fmi2Error;
    if (nvr > 0 && (!vr || !value)) return fail(inst, fmi2Error, "%s", "fmi2SetReal: NULL array");
    for (size_t i = 0; i < nvr; ++i) {
        int kind = model_real_kind(vr[i]);
        if (kind == VAR_OUTPUT || kind < 0) {
            snprintf(message, sizeof message, "fmi2SetReal: value reference %u is not an input or parameter", vr[i]);
            return fail(inst, fmi2Error, "%s", message);
        }
        if (kind == VAR_PARAMETER && inst->state == ST_STEP) {
            snprintf(message, sizeof message, "fmi2SetReal: parameter %u is fixed after initialization", vr[i]);
            return fail(inst, fmi2Error, "%s", message);
        }
        if (model_set_real(&inst->model, vr[i], value[i], message, sizeof message) != MODEL_OK)
            return fail(inst, fmi2Error, "fmi2SetReal: %s", message);
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2GetBoolean", ST_ANY)) return fmi2Error;
    if (nvr > 0 && (!vr || !value)) return fail(inst, fmi2Error, "%s", "fmi2GetBoolean: NULL array");
    for (size_t i = 0; i < nvr; ++i) {
        if (!model_boolean_exists(vr[i])) return fail(inst, fmi2Error, "%s", "fmi2GetBoolean: unknown value reference");
        value[i] = model_get_boolean(&inst->model, vr[i]) ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

/* access to a variable type the FMU does not have: fine for an empty list, an error otherwise */
static fmi2Status none_of(fmi2Component c, size_t nvr, const char *function)
{
    if (nvr == 0) return fmi2OK;
    return fail((Instance *)c, fmi2Error, "%s: the FMU has no variable of this type to access", function);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{ (void)vr; (void)value; return none_of(c, nvr, "fmi2SetBoolean"); }
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{ (void)vr; (void)value; return none_of(c, nvr, "fmi2GetInteger"); }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{ (void)vr; (void)value; return none_of(c, nvr, "fmi2SetInteger"); }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{ (void)vr; (void)value; return none_of(c, nvr, "fmi2GetString"); }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{ (void)vr; (void)value; return none_of(c, nvr, "fmi2SetString"); }

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    char message[512] = "";
    Instance *inst = (Instance *)c;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (not_allowed(inst, "fmi2DoStep", ST_STEP)) return fmi2Error;
    if (!(communicationStepSize > 0.0) || !isfinite(communicationStepSize)) {
        snprintf(message, sizeof message, "fmi2DoStep: communication step size %g must be positive and finite",
                 communicationStepSize);
        return fail(inst, fmi2Error, "%s", message);
    }
    if (!isfinite(currentCommunicationPoint) ||
        fabs(currentCommunicationPoint - inst->model.time) > 1e-9 * fmax(1.0, fabs(inst->model.time))) {
        snprintf(message, sizeof message, "fmi2DoStep: communication point %.12g s is not the FMU's time %.12g s",
                 currentCommunicationPoint, inst->model.time);
        return fail(inst, fmi2Error, "%s", message);
    }
    fmi2Status status = model_status(inst, model_do_step(&inst->model, communicationStepSize, message, sizeof message), message);
    if (status == fmi2Error) inst->state = ST_ERROR;
    return status;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    return fail((Instance *)c, fmi2Error, "%s", "fmi2CancelStep: steps run synchronously; there is nothing to cancel");
}

static fmi2Status no_status(fmi2Component c, const char *function)
{
    return fail((Instance *)c, fmi2Discard, "%s: no asynchronous status is provided", function);
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{ (void)s; (void)value; return no_status(c, "fmi2GetStatus"); }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    Instance *inst = (Instance *)c;
    if (inst && s == fmi2LastSuccessfulTime && value) {
        *value = inst->model.time;
        return fmi2OK;
    }
    return no_status(c, "fmi2GetRealStatus");
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{ (void)s; (void)value; return no_status(c, "fmi2GetIntegerStatus"); }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{ (void)s; (void)value; return no_status(c, "fmi2GetBooleanStatus"); }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{ (void)s; (void)value; return no_status(c, "fmi2GetStringStatus"); }

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
#if OPFMU_CAN_INTERPOLATE_INPUTS
    char message[512];
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2SetRealInputDerivatives", ST_INSTANTIATED | ST_INIT | ST_STEP)) return fmi2Error;
    if (nvr > 0 && (!vr || !order || !value)) return fail(inst, fmi2Error, "%s", "fmi2SetRealInputDerivatives: NULL array");
    for (size_t i = 0; i < nvr; ++i) {
        if (model_real_kind(vr[i]) != VAR_INPUT || !IN_GROUP(vr[i], VR_FIRST_INPUT, OPFMU_N_INPUTS)) {
            snprintf(message, sizeof message, "fmi2SetRealInputDerivatives: value reference %u is not an input", vr[i]);
            return fail(inst, fmi2Error, "%s", message);
        }
        if (order[i] != 1) {
            snprintf(message, sizeof message, "fmi2SetRealInputDerivatives: order %d of value reference %u: only "
                     "first derivatives are supported (inputs linear over a step)", (int)order[i], vr[i]);
            return fail(inst, fmi2Error, "%s", message);
        }
        if (model_set_input_derivative(&inst->model, vr[i] - VR_FIRST_INPUT, value[i], message, sizeof message) !=
            MODEL_OK)
            return fail(inst, fmi2Error, "fmi2SetRealInputDerivatives: %s", message);
    }
    return fmi2OK;
#else
    (void)vr; (void)nvr; (void)order; (void)value;
    return fail((Instance *)c, fmi2Error, "%s", "fmi2SetRealInputDerivatives: not supported (inputs are held constant)");
#endif
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    return fail((Instance *)c, fmi2Error, "%s", "fmi2GetRealOutputDerivatives: not supported");
}

/* Outputs with respect to inputs at the current state and inputs: the states at the communication
   point do not depend on the inputs directly (zero); the derived outputs have the component's exact
   partial derivatives (generated from its definition). Knowns must be inputs, unknowns outputs; a
   model's diagnostic output is refused with its reason. Nothing is written unless every reference is
   valid. */
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    char message[512];
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2GetDirectionalDerivative", ST_INIT | ST_INITIALIZED)) return fmi2Error;
    if ((nUnknown > 0 && (!vUnknown_ref || !dvUnknown)) || (nKnown > 0 && (!vKnown_ref || !dvKnown)))
        return fail(inst, fmi2Error, "%s", "fmi2GetDirectionalDerivative: NULL array");
    for (size_t k = 0; k < nKnown; ++k) {
        if (model_real_kind(vKnown_ref[k]) != VAR_INPUT || !IN_GROUP(vKnown_ref[k], VR_FIRST_INPUT, OPFMU_N_INPUTS)) {
            snprintf(message, sizeof message, "fmi2GetDirectionalDerivative: known value reference %u is not an "
                     "input (derivatives are of outputs with respect to inputs)", vKnown_ref[k]);
            return fail(inst, fmi2Error, "%s", message);
        }
        if (!isfinite(dvKnown[k])) {
            snprintf(message, sizeof message, "fmi2GetDirectionalDerivative: seed %g of value reference %u is not a "
                     "finite number", dvKnown[k], vKnown_ref[k]);
            return fail(inst, fmi2Error, "%s", message);
        }
    }
    int derived = 0;
    for (size_t i = 0; i < nUnknown; ++i) {
        const fmi2ValueReference vr = vUnknown_ref[i];
        if (model_real_kind(vr) != VAR_OUTPUT) {
            snprintf(message, sizeof message, "fmi2GetDirectionalDerivative: unknown value reference %u is not an "
                     "output", vr);
            return fail(inst, fmi2Error, "%s", message);
        }
        if (IN_GROUP(vr, VR_FIRST_OUTPUT, OPFMU_N_OUTPUTS)) {
            derived = 1;
        } else if (!IN_GROUP(vr, VR_FIRST_STATE, OPFMU_N_STATES)) {
            const char *reason = model_no_derivative(vr);
            snprintf(message, sizeof message, "fmi2GetDirectionalDerivative: output %u: %s", vr,
                     reason ? reason : "has no directional derivative");
            return fail(inst, fmi2Error, "%s", message);
        }
    }
    double J[OPFMU_N_OUTPUTS > 0 ? OPFMU_N_OUTPUTS * OPFMU_N_COLUMNS : 1];
    if (derived) model_output_jacobian(&inst->model, J);
    for (size_t i = 0; i < nUnknown; ++i) {
        const fmi2ValueReference vr = vUnknown_ref[i];
        double sum = 0.0;
        if (IN_GROUP(vr, VR_FIRST_OUTPUT, OPFMU_N_OUTPUTS)) {
            const double *row = J + (vr - VR_FIRST_OUTPUT) * OPFMU_N_COLUMNS + OPFMU_N_STATES;
            for (size_t k = 0; k < nKnown; ++k) sum += row[vKnown_ref[k] - VR_FIRST_INPUT] * dvKnown[k];
        }
        dvUnknown[i] = sum; /* a state: no direct dependence on the inputs */
    }
    return fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2GetFMUstate", ST_ANY)) return fmi2Error;
    if (!FMUstate) return fail(inst, fmi2Error, "%s", "fmi2GetFMUstate: NULL state pointer");
    Snapshot *snap = (Snapshot *)(*FMUstate ? *FMUstate : malloc(sizeof(Snapshot)));
    if (!snap) return fail(inst, fmi2Error, "%s", "fmi2GetFMUstate: out of memory");
    memset(snap, 0, sizeof *snap);
    snap->magic = SNAPSHOT_MAGIC;
    snap->size = sizeof(Snapshot);
    strncpy(snap->guid, OPFMU_GUID, sizeof snap->guid - 1);
    snap->state = inst->state;
    snap->model = inst->model;
    *FMUstate = snap;
    return fmi2OK;
}

static int valid_snapshot(const Snapshot *snap)
{
    return snap->magic == SNAPSHOT_MAGIC && snap->size == sizeof(Snapshot) &&
           !strncmp(snap->guid, OPFMU_GUID, sizeof snap->guid) && (snap->state & ST_ANY);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    Instance *inst = (Instance *)c;
    const Snapshot *snap = (const Snapshot *)FMUstate;
    if (not_allowed(inst, "fmi2SetFMUstate", ST_ANY)) return fmi2Error;
    if (!snap || !valid_snapshot(snap)) return fail(inst, fmi2Error, "%s", "fmi2SetFMUstate: not an FMU state of this FMU");
    inst->state = snap->state;
    inst->model = snap->model;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    (void)c;
    if (FMUstate && *FMUstate) {
        free(*FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2SerializedFMUstateSize", ST_ANY)) return fmi2Error;
    if (!FMUstate || !size) return fail(inst, fmi2Error, "%s", "fmi2SerializedFMUstateSize: NULL argument");
    *size = sizeof(Snapshot);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2SerializeFMUstate", ST_ANY)) return fmi2Error;
    if (!FMUstate || !serializedState || size < sizeof(Snapshot))
        return fail(inst, fmi2Error, "%s", "fmi2SerializeFMUstate: NULL state or buffer too small");
    memcpy(serializedState, FMUstate, sizeof(Snapshot));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size, fmi2FMUstate *FMUstate)
{
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2DeSerializeFMUstate", ST_ANY)) return fmi2Error;
    if (!serializedState || !FMUstate || size != sizeof(Snapshot))
        return fail(inst, fmi2Error, "%s", "fmi2DeSerializeFMUstate: NULL argument or wrong size");
    Snapshot *probe = (Snapshot *)malloc(sizeof(Snapshot)); /* on the heap: a Snapshot holds a ModelState */
    if (!probe) return fail(inst, fmi2Error, "%s", "fmi2DeSerializeFMUstate: out of memory");
    memcpy(probe, serializedState, sizeof(Snapshot));
    if (!valid_snapshot(probe)) {
        free(probe);
        return fail(inst, fmi2Error, "%s", "fmi2DeSerializeFMUstate: corrupt or foreign state");
    }
    if (*FMUstate) { /* into the state the importer gave */
        memcpy(*FMUstate, probe, sizeof(Snapshot));
        free(probe);
    } else {
        *FMUstate = probe;
    }
    return fmi2OK;
}

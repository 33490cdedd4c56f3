/* FMI 3.0 co-simulation plumbing of both native FMUs, the counterpart of fmi2_cs.c over the same
   model interface (model.h): instances, the FMI state machine (no event mode: initialization goes
   straight to step mode), logging, variable access, directional and adjoint derivatives of the
   outputs with respect to the inputs, and FMU state (get/set/serialize). Model Exchange, Scheduled
   Execution, clocks, event mode and the variable types the FMU does not have are refused. FMI 3.0
   value references are unique across types: a Real keeps its model value reference (Float64),
   Boolean b of the model is FMI3_VR_FIRST_BOOLEAN + b, and FMI3_VR_TIME is the independent
   variable `time`. Every misuse returns fmi3Error with a reason through the importer's logger;
   nothing aborts. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "model.h"
#include "variables.h"

typedef enum { ST_INSTANTIATED = 1, ST_INIT = 2, ST_STEP = 4, ST_TERMINATED = 8, ST_ERROR = 16 } MachineState;
#define ST_ANY (ST_INSTANTIATED | ST_INIT | ST_STEP | ST_TERMINATED | ST_ERROR)
#define ST_INITIALIZED (ST_STEP | ST_TERMINATED | ST_ERROR)

typedef struct {
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback logger; /* NULL: the importer takes no messages */
    int log_warnings, log_errors, log_all;
    MachineState state;
    double start_time;
    ModelState model;
} Instance;

/* what an FMU state holds: a header (what it is, the machine state) and the model state. The
   model state can be large (the surrogate's window caches): no copy of it lives on the stack. */
typedef struct {
    unsigned int magic;
    unsigned int size;
    char guid[48];
    MachineState state;
} SnapshotHeader;

typedef struct {
    SnapshotHeader header;
    ModelState model;
} Snapshot;

#define SNAPSHOT_MAGIC 0x0F3F5A13u /* not fmi2_cs.c's: an FMI 2.0 state is refused */

/* formats the message and passes it to the importer's logger, with no '%' in it (as fmi2_cs.c) */
static void emit(fmi3InstanceEnvironment environment, fmi3LogMessageCallback logger, fmi3Status status,
                 const char *category, const char *format, va_list args)
{
    char message[1024];
    vsnprintf(message, sizeof message, format, args);
    for (char *c = message; *c; ++c)
        if (*c == '%') *c = '#';
    logger(environment, status, category, message);
}

static void log_message(const Instance *inst, fmi3Status status, const char *category, const char *format, ...)
{
    va_list args;
    if (!inst || !inst->logger) return;
    if (status == fmi3Error && !(inst->log_errors || inst->log_all)) return;
    if (status == fmi3Warning && !(inst->log_warnings || inst->log_all)) return;
    if (status == fmi3OK && !inst->log_all) return;
    va_start(args, format);
    emit(inst->environment, inst->logger, status, category, format, args);
    va_end(args);
}

/* a refused instantiation: logs why (where the importer gave a logger) and returns no instance */
static fmi3Instance refuse(fmi3InstanceEnvironment environment, fmi3LogMessageCallback logger, const char *format, ...)
{
    va_list args;
    if (!logger) return NULL;
    va_start(args, format);
    emit(environment, logger, fmi3Error, "logStatusError", format, args);
    va_end(args);
    return NULL;
}

static fmi3Status fail(Instance *inst, fmi3Status status, const char *format, const char *detail)
{
    log_message(inst, status, status == fmi3Error ? "logStatusError" : "logStatusWarning", format, detail);
    return status;
}

/* returns nonzero if the call is not allowed now (and logs why) */
static int not_allowed(Instance *inst, const char *function, int allowed)
{
    if (!inst) return 1;
    if (inst->state & allowed) return 0;
    log_message(inst, fmi3Error, "logStatusError", "%s is not allowed in the current state of the FMU", function);
    return 1;
}

static fmi3Status model_status(Instance *inst, ModelStatus status, const char *message)
{
    if (status == MODEL_ERROR) return fail(inst, fmi3Error, "%s", message);
    if (status == MODEL_WARNING) log_message(inst, fmi3Warning, "logStatusWarning", "%s", message);
    return fmi3OK;
}

/* a function of an interface or feature the FMU does not provide: fmi3Error with the reason */
static fmi3Status unsupported(fmi3Instance instance, const char *reason)
{
    return fail((Instance *)instance, fmi3Error, "%s", reason);
}

/* access to a variable type the FMU does not have: fine for an empty list, an error otherwise */
static fmi3Status none_of(fmi3Instance instance, size_t nvr, const char *function, const char *type)
{
    if (!instance) return fmi3Error;
    if (nvr == 0) return fmi3OK;
    log_message((Instance *)instance, fmi3Error, "logStatusError", "%s: the FMU has no %s variable to access",
                function, type);
    return fmi3Error;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    Instance *inst = (Instance *)instance;
    if (not_allowed(inst, "fmi3SetDebugLogging", ST_ANY)) return fmi3Error;
    if (nCategories == 0) {
        inst->log_warnings = inst->log_errors = inst->log_all = loggingOn;
        return fmi3OK;
    }
    for (size_t i = 0; i < nCategories; ++i) {
        if (!categories || !categories[i]) return fail(inst, fmi3Error, "%s", "fmi3SetDebugLogging: category is NULL");
        if (!strcmp(categories[i], "logStatusWarning")) inst->log_warnings = loggingOn;
        else if (!strcmp(categories[i], "logStatusError")) inst->log_errors = loggingOn;
        else if (!strcmp(categories[i], "logAll")) inst->log_all = loggingOn;
        else return fail(inst, fmi3Error, "fmi3SetDebugLogging: unknown log category %s", categories[i]);
    }
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    return refuse(instanceEnvironment, logMessage, "fmi3InstantiateModelExchange: %s supports co-simulation only",
                  OPFMU_MODEL_IDENTIFIER);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    return refuse(instanceEnvironment, logMessage, "fmi3InstantiateScheduledExecution: %s supports co-simulation "
                  "only", OPFMU_MODEL_IDENTIFIER);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    (void)resourcePath;
    (void)visible;
    (void)earlyReturnAllowed; /* steps always run to their end */
    (void)requiredIntermediateVariables;
    (void)intermediateUpdate; /* never called: there are no intermediate variables */
    if (!instanceName || !*instanceName)
        return refuse(instanceEnvironment, logMessage, "fmi3InstantiateCoSimulation: missing instance name");
    if (!instantiationToken || strcmp(instantiationToken, OPFMU_GUID))
        return refuse(instanceEnvironment, logMessage, "fmi3InstantiateCoSimulation: instantiation token %s does not "
                      "match this binary (%s)", instantiationToken ? instantiationToken : "(null)", OPFMU_GUID);
    if (eventModeUsed)
        return refuse(instanceEnvironment, logMessage, "fmi3InstantiateCoSimulation: %s has no event mode "
                      "(hasEventMode=\"false\"); instantiate it with eventModeUsed = false", OPFMU_MODEL_IDENTIFIER);
    if (nRequiredIntermediateVariables > 0)
        return refuse(instanceEnvironment, logMessage, "fmi3InstantiateCoSimulation: %s has no intermediate variables "
                      "(no intermediate update); requiredIntermediateVariables must be empty", OPFMU_MODEL_IDENTIFIER);
    Instance *inst = (Instance *)calloc(1, sizeof(Instance));
    if (!inst) return refuse(instanceEnvironment, logMessage, "fmi3InstantiateCoSimulation: out of memory");
    inst->environment = instanceEnvironment;
    inst->logger = logMessage;
    inst->log_errors = inst->log_warnings = 1;
    inst->log_all = loggingOn;
    inst->state = ST_INSTANTIATED;
    model_defaults(&inst->model);
    return inst;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    free(instance);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    Instance *inst = (Instance *)instance;
    (void)toleranceDefined;
    (void)tolerance;
    if (not_allowed(inst, "fmi3EnterInitializationMode", ST_INSTANTIATED)) return fmi3Error;
    if (!isfinite(startTime) || (stopTimeDefined && !(stopTime >= startTime)))
        return fail(inst, fmi3Error, "%s",
                    "fmi3EnterInitializationMode: start time must be finite and not after the stop time");
    inst->start_time = startTime;
    inst->state = ST_INIT;
    return fmi3OK;
}

/* initializes the model at the start time; then in step mode (there is no event mode) */
fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    char message[512] = "";
    Instance *inst = (Instance *)instance;
    if (not_allowed(inst, "fmi3ExitInitializationMode", ST_INIT)) return fmi3Error;
    fmi3Status status = model_status(inst, model_initialize(&inst->model, inst->start_time, message, sizeof message), message);
    inst->state = status == fmi3Error ? ST_ERROR : ST_STEP;
    return status;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{ return unsupported(instance, "fmi3EnterEventMode: the FMU has no event mode"); }

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    Instance *inst = (Instance *)instance;
    if (not_allowed(inst, "fmi3Terminate", ST_STEP | ST_ERROR)) return fmi3Error;
    inst->state = ST_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    Instance *inst = (Instance *)instance;
    if (not_allowed(inst, "fmi3Reset", ST_ANY)) return fmi3Error;
    inst->state = ST_INSTANTIATED;
    inst->start_time = 0.0;
    model_defaults(&inst->model);
    return fmi3OK;
}

/* all variables are scalars: one value per value reference; nonzero: refused (logged) */
static int bad_arrays(Instance *inst, const char *function, const fmi3ValueReference vr[], size_t nvr,
                      const void *values, size_t nValues)
{
    if (nValues != nvr) {
        log_message(inst, fmi3Error, "logStatusError", "%s: %lu values for %lu value references (all variables are "
                    "scalars)", function, (unsigned long)nValues, (unsigned long)nvr);
        return 1;
    }
    if (nvr > 0 && (!vr || !values)) {
        log_message(inst, fmi3Error, "logStatusError", "%s: NULL array", function);
        return 1;
    }
    return 0;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues)
{
    char detail[64];
    Instance *inst = (Instance *)instance;
    if (not_allowed(inst, "fmi3GetFloat64", ST_ANY)) return fmi3Error;
    if (bad_arrays(inst, "fmi3GetFloat64", vr, nvr, values, nValues)) return fmi3Error;
    for (size_t i = 0; i < nvr; ++i) {
        if (vr[i] == FMI3_VR_TIME) {
            values[i] = inst->model.time;
        } else if (vr[i] >= VR_REAL_COUNT || model_get_real(&inst->model, vr[i], &values[i]) != MODEL_OK) {
            snprintf(detail, sizeof detail, "%u", vr[i]);
            return fail(inst, fmi3Error, "fmi3GetFloat64: no Float64 variable with value reference %s", detail);
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues)
{
    char message[512];
    Instance *inst = (Instance *)instance;
    if (not_allowed(inst, "fmi3SetFloat64", ST_INSTANTIATED | ST_INIT | ST_STEP)) return fmi3Error;
    if (bad_arrays(inst, "fmi3SetFloat64", vr, nvr, values, nValues)) return fmi3Error;
    for (size_t i = 0; i < nvr; ++i) {
        if (vr[i] == FMI3_VR_TIME)
            return fail(inst, fmi3Error, "%s", "fmi3SetFloat64: time is the independent variable and cannot be set");
        int kind = model_real_kind(vr[i]);
        if (kind == VAR_OUTPUT || kind < 0) {
            snprintf(message, sizeof message, "fmi3SetFloat64: value reference %u is not an input or parameter", vr[i]);
            return fail(inst, fmi3Error, "%s", message);
        }
        if (kind == VAR_PARAMETER && inst->state == ST_STEP) {
            snprintf(message, sizeof message, "fmi3SetFloat64: parameter %u is fixed after initialization", vr[i]);
            return fail(inst, fmi3Error, "%s", message);
        }
        if (model_set_real(&inst->model, vr[i], values[i], message, sizeof message) != MODEL_OK)
            return fail(inst, fmi3Error, "fmi3SetFloat64: %s", message);
    }
    return fmi3OK;
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[],
                          size_t nValues)
{
    char detail[64];
    Instance *inst = (Instance *)instance;
    if (not_allowed(inst, "fmi3GetBoolean", ST_ANY)) return fmi3Error;
    if (bad_arrays(inst, "fmi3GetBoolean", vr, nvr, values, nValues)) return fmi3Error;
    for (size_t i = 0; i < nvr; ++i) {
        if (vr[i] < FMI3_VR_FIRST_BOOLEAN || !model_boolean_exists(vr[i] - FMI3_VR_FIRST_BOOLEAN)) {
            snprintf(detail, sizeof detail, "%u", vr[i]);
            return fail(inst, fmi3Error, "fmi3GetBoolean: no Boolean variable with value reference %s", detail);
        }
        values[i] = model_get_boolean(&inst->model, vr[i] - FMI3_VR_FIRST_BOOLEAN) ? fmi3True : fmi3False;
    }
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Boolean values[], size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3SetBoolean", "settable Boolean"); }

fmi3Status fmi3GetFloat32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float32 values[],
                          size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3GetFloat32", "Float32"); }
fmi3Status fmi3SetFloat32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float32 values[], size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3SetFloat32", "Float32"); }
fmi3Status fmi3GetInt8(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Int8 values[],
                       size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3GetInt8", "Int8"); }
fmi3Status fmi3SetInt8(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Int8 values[],
                       size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3SetInt8", "Int8"); }
fmi3Status fmi3GetUInt8(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3UInt8 values[],
                        size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3GetUInt8", "UInt8"); }
fmi3Status fmi3SetUInt8(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3UInt8 values[],
                        size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3SetUInt8", "UInt8"); }
fmi3Status fmi3GetInt16(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Int16 values[],
                        size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3GetInt16", "Int16"); }
fmi3Status fmi3SetInt16(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Int16 values[],
                        size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3SetInt16", "Int16"); }
fmi3Status fmi3GetUInt16(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3UInt16 values[],
                         size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3GetUInt16", "UInt16"); }
fmi3Status fmi3SetUInt16(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const fmi3UInt16 values[], size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3SetUInt16", "UInt16"); }
fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 values[],
                        size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3GetInt32", "Int32"); }
fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 values[],
                        size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3SetInt32", "Int32"); }
fmi3Status fmi3GetUInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3UInt32 values[],
                         size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3GetUInt32", "UInt32"); }
fmi3Status fmi3SetUInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const fmi3UInt32 values[], size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3SetUInt32", "UInt32"); }
fmi3Status fmi3GetInt64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Int64 values[],
                        size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3GetInt64", "Int64"); }
fmi3Status fmi3SetInt64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Int64 values[],
                        size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3SetInt64", "Int64"); }
fmi3Status fmi3GetUInt64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3UInt64 values[],
                         size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3GetUInt64", "UInt64"); }
fmi3Status fmi3SetUInt64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const fmi3UInt64 values[], size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3SetUInt64", "UInt64"); }
fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3String values[],
                         size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3GetString", "String"); }
fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const fmi3String values[], size_t nValues)
{ (void)vr; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3SetString", "String"); }
fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues)
{ (void)vr; (void)valueSizes; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3GetBinary", "Binary"); }
fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues)
{ (void)vr; (void)valueSizes; (void)values; (void)nValues; return none_of(instance, nvr, "fmi3SetBinary", "Binary"); }
fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[])
{ (void)vr; (void)values; return none_of(instance, nvr, "fmi3GetClock", "Clock"); }
fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[])
{ (void)vr; (void)values; return none_of(instance, nvr, "fmi3SetClock", "Clock"); }

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    (void)valueReference; (void)nDependencies;
    return unsupported(instance, "fmi3GetNumberOfVariableDependencies: not provided "
                       "(providesPerElementDependencies=\"false\"; the dependencies are in the model description)");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    return unsupported(instance, "fmi3GetVariableDependencies: not provided "
                       "(providesPerElementDependencies=\"false\"; the dependencies are in the model description)");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime)
{
    char message[512] = "";
    Instance *inst = (Instance *)instance;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (not_allowed(inst, "fmi3DoStep", ST_STEP)) return fmi3Error;
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime)
        return fail(inst, fmi3Error, "%s", "fmi3DoStep: NULL output argument");
    *eventHandlingNeeded = *terminateSimulation = *earlyReturn = fmi3False; /* no events, no early return */
    *lastSuccessfulTime = inst->model.time;
    if (!(communicationStepSize > 0.0) || !isfinite(communicationStepSize)) {
        snprintf(message, sizeof message, "fmi3DoStep: communication step size %g must be positive and finite",
                 communicationStepSize);
        return fail(inst, fmi3Error, "%s", message);
    }
    if (!isfinite(currentCommunicationPoint) ||
        fabs(currentCommunicationPoint - inst->model.time) > 1e-9 * fmax(1.0, fabs(inst->model.time))) {
        snprintf(message, sizeof message, "fmi3DoStep: communication point %.12g s is not the FMU's time %.12g s",
                 currentCommunicationPoint, inst->model.time);
        return fail(inst, fmi3Error, "%s", message);
    }
    fmi3Status status = model_status(inst, model_do_step(&inst->model, communicationStepSize, message, sizeof message), message);
    if (status == fmi3Error) inst->state = ST_ERROR;
    *lastSuccessfulTime = inst->model.time; /* the end of the step, or where a refused step left the model */
    return status;
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    return unsupported(instance, "fmi3EnterStepMode: "
                                 "the FMU has no event mode (it is in step mode after initialization)");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues)
{
    (void)vr; (void)nvr; (void)orders; (void)values; (void)nValues;
    return unsupported(instance, "fmi3GetOutputDerivatives: not supported (maxOutputDerivativeOrder = 0)");
}

/* The checks both derivative functions share, and the Jacobian of the derived outputs into J where
   an unknown is one. Knowns must be inputs, unknowns outputs (a model's diagnostic output is refused
   with its reason); the seed runs over the knowns (over the unknowns for the adjoint), the
   sensitivity over the other list, each as long as its list, and the seed must be finite. Nonzero:
   refused (logged), nothing written. */
static int derivatives_refused(Instance *inst, const char *function, int adjoint,
                               const fmi3ValueReference unknowns[], size_t nUnknowns,
                               const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                               size_t nSeed, const fmi3Float64 sensitivity[], size_t nSensitivity, double J[])
{
    char message[512];
    const fmi3ValueReference *seeded = adjoint ? unknowns : knowns;
    const size_t n_seeded = adjoint ? nUnknowns : nKnowns, n_sensed = adjoint ? nKnowns : nUnknowns;
    if (not_allowed(inst, function, ST_INIT | ST_INITIALIZED)) return 1;
    if (nSeed != n_seeded || nSensitivity != n_sensed) {
        snprintf(message, sizeof message, "%s: %lu seeds and %lu sensitivities for %lu unknowns and %lu knowns (the "
                 "seed needs one value per %s, the sensitivity one per %s)", function, (unsigned long)nSeed,
                 (unsigned long)nSensitivity, (unsigned long)nUnknowns, (unsigned long)nKnowns,
                 adjoint ? "unknown" : "known", adjoint ? "known" : "unknown");
        fail(inst, fmi3Error, "%s", message);
        return 1;
    }
    if ((nUnknowns > 0 && !unknowns) || (nKnowns > 0 && !knowns) || (nSeed > 0 && !seed) ||
        (nSensitivity > 0 && !sensitivity)) {
        log_message(inst, fmi3Error, "logStatusError", "%s: NULL array", function);
        return 1;
    }
    for (size_t k = 0; k < nKnowns; ++k) {
        if (model_real_kind(knowns[k]) != VAR_INPUT || !IN_GROUP(knowns[k], VR_FIRST_INPUT, OPFMU_N_INPUTS)) {
            snprintf(message, sizeof message, "%s: known value reference %u is not an input (derivatives are of "
                     "outputs with respect to inputs)", function, knowns[k]);
            fail(inst, fmi3Error, "%s", message);
            return 1;
        }
    }
    for (size_t j = 0; j < nSeed; ++j) {
        if (!isfinite(seed[j])) {
            snprintf(message, sizeof message, "%s: seed %g of value reference %u is not a finite number", function,
                     seed[j], seeded[j]);
            fail(inst, fmi3Error, "%s", message);
            return 1;
        }
    }
    int derived = 0;
    for (size_t i = 0; i < nUnknowns; ++i) {
        const fmi3ValueReference vr = unknowns[i];
        if (model_real_kind(vr) != VAR_OUTPUT) {
            snprintf(message, sizeof message, "%s: unknown value reference %u is not an output", function, vr);
            fail(inst, fmi3Error, "%s", message);
            return 1;
        }
        if (IN_GROUP(vr, VR_FIRST_OUTPUT, OPFMU_N_OUTPUTS)) {
            derived = 1;
        } else if (!IN_GROUP(vr, VR_FIRST_STATE, OPFMU_N_STATES)) {
            const char *reason = model_no_derivative(vr);
            snprintf(message, sizeof message, "%s: output %u: %s", function, vr,
                     reason ? reason : "has no directional derivative");
            fail(inst, fmi3Error, "%s", message);
            return 1;
        }
    }
    if (derived) model_output_jacobian(&inst->model, J);
    return 0;
}

/* d unknown / d known (checked by derivatives_refused): a state at the communication point does not
   depend on the inputs directly (zero); a derived output has the component's exact partial derivative */
static double partial(const double J[], fmi3ValueReference unknown, fmi3ValueReference known)
{
    if (!IN_GROUP(unknown, VR_FIRST_OUTPUT, OPFMU_N_OUTPUTS)) return 0.0;
    return J[(unknown - VR_FIRST_OUTPUT) * OPFMU_N_COLUMNS + OPFMU_N_STATES + (known - VR_FIRST_INPUT)];
}

/* sensitivity[i] = sum over k of d unknown_i / d known_k * seed[k] */
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    double J[OPFMU_N_OUTPUTS > 0 ? OPFMU_N_OUTPUTS * OPFMU_N_COLUMNS : 1];
    if (derivatives_refused((Instance *)instance, "fmi3GetDirectionalDerivative", 0, unknowns, nUnknowns, knowns,
                            nKnowns, seed, nSeed, sensitivity, nSensitivity, J))
        return fmi3Error;
    for (size_t i = 0; i < nUnknowns; ++i) {
        double sum = 0.0;
        for (size_t k = 0; k < nKnowns; ++k) sum += partial(J, unknowns[i], knowns[k]) * seed[k];
        sensitivity[i] = sum;
    }
    return fmi3OK;
}

/* sensitivity[k] = sum over i of seed[i] * d unknown_i / d known_k */
fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    double J[OPFMU_N_OUTPUTS > 0 ? OPFMU_N_OUTPUTS * OPFMU_N_COLUMNS : 1];
    if (derivatives_refused((Instance *)instance, "fmi3GetAdjointDerivative", 1, unknowns, nUnknowns, knowns,
                            nKnowns, seed, nSeed, sensitivity, nSensitivity, J))
        return fmi3Error;
    for (size_t k = 0; k < nKnowns; ++k) {
        double sum = 0.0;
        for (size_t i = 0; i < nUnknowns; ++i) sum += seed[i] * partial(J, unknowns[i], knowns[k]);
        sensitivity[k] = sum;
    }
    return fmi3OK;
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    Instance *inst = (Instance *)instance;
    if (not_allowed(inst, "fmi3GetFMUState", ST_ANY)) return fmi3Error;
    if (!FMUState) return fail(inst, fmi3Error, "%s", "fmi3GetFMUState: NULL state pointer");
    Snapshot *snap = (Snapshot *)(*FMUState ? *FMUState : malloc(sizeof(Snapshot)));
    if (!snap) return fail(inst, fmi3Error, "%s", "fmi3GetFMUState: out of memory");
    memset(snap, 0, sizeof *snap);
    snap->header.magic = SNAPSHOT_MAGIC;
    snap->header.size = sizeof(Snapshot);
    strncpy(snap->header.guid, OPFMU_GUID, sizeof snap->header.guid - 1);
    snap->header.state = inst->state;
    snap->model = inst->model;
    *FMUState = snap;
    return fmi3OK;
}

static int valid_snapshot(const SnapshotHeader *header)
{
    return header->magic == SNAPSHOT_MAGIC && header->size == sizeof(Snapshot) &&
           !strncmp(header->guid, OPFMU_GUID, sizeof header->guid) && (header->state & ST_ANY);
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    Instance *inst = (Instance *)instance;
    const Snapshot *snap = (const Snapshot *)FMUState;
    if (not_allowed(inst, "fmi3SetFMUState", ST_ANY)) return fmi3Error;
    if (!snap || !valid_snapshot(&snap->header))
        return fail(inst, fmi3Error, "%s", "fmi3SetFMUState: not an FMU state of this FMU");
    inst->state = snap->header.state;
    inst->model = snap->model;
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    if (not_allowed((Instance *)instance, "fmi3FreeFMUState", ST_ANY)) return fmi3Error;
    if (FMUState && *FMUState) {
        free(*FMUState);
        *FMUState = NULL;
    }
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    Instance *inst = (Instance *)instance;
    if (not_allowed(inst, "fmi3SerializedFMUStateSize", ST_ANY)) return fmi3Error;
    if (!FMUState || !size) return fail(inst, fmi3Error, "%s", "fmi3SerializedFMUStateSize: NULL argument");
    *size = sizeof(Snapshot);
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    Instance *inst = (Instance *)instance;
    if (not_allowed(inst, "fmi3SerializeFMUState", ST_ANY)) return fmi3Error;
    if (!FMUState || !serializedState || size < sizeof(Snapshot))
        return fail(inst, fmi3Error, "%s", "fmi3SerializeFMUState: NULL state or buffer too small");
    memcpy(serializedState, FMUState, sizeof(Snapshot));
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState)
{
    Instance *inst = (Instance *)instance;
    SnapshotHeader header;
    if (not_allowed(inst, "fmi3DeserializeFMUState", ST_ANY)) return fmi3Error;
    if (!serializedState || !FMUState || size != sizeof(Snapshot))
        return fail(inst, fmi3Error, "%s", "fmi3DeserializeFMUState: NULL argument or wrong size");
    memcpy(&header, serializedState, sizeof header); /* the bytes need not be aligned for a Snapshot */
    if (!valid_snapshot(&header))
        return fail(inst, fmi3Error, "%s", "fmi3DeserializeFMUState: corrupt or foreign state");
    Snapshot *snap = (Snapshot *)(*FMUState ? *FMUState : malloc(sizeof(Snapshot)));
    if (!snap) return fail(inst, fmi3Error, "%s", "fmi3DeserializeFMUState: out of memory");
    memcpy(snap, serializedState, sizeof(Snapshot));
    *FMUState = snap;
    return fmi3OK;
}

/* --- configuration mode, clocks and discrete states: the FMU has no structural parameters, no clocks
   and no event mode --- */
fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{ return unsupported(instance, "fmi3EnterConfigurationMode: the FMU has no structural parameters"); }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{ return unsupported(instance, "fmi3ExitConfigurationMode: the FMU has no structural parameters"); }

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
{
    (void)vr; (void)nvr; (void)intervals; (void)qualifiers;
    return unsupported(instance, "fmi3GetIntervalDecimal: the FMU has no clocks");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions; (void)qualifiers;
    return unsupported(instance, "fmi3GetIntervalFraction: the FMU has no clocks");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 shifts[])
{ (void)vr; (void)nvr; (void)shifts; return unsupported(instance, "fmi3GetShiftDecimal: the FMU has no clocks"); }
fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    return unsupported(instance, "fmi3GetShiftFraction: the FMU has no clocks");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[])
{ (void)vr; (void)nvr; (void)intervals; return unsupported(instance, "fmi3SetIntervalDecimal: the FMU has no clocks"); }
fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    return unsupported(instance, "fmi3SetIntervalFraction: the FMU has no clocks");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[])
{ (void)vr; (void)nvr; (void)shifts; return unsupported(instance, "fmi3SetShiftDecimal: the FMU has no clocks"); }
fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    return unsupported(instance, "fmi3SetShiftFraction: the FMU has no clocks");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{ return unsupported(instance, "fmi3EvaluateDiscreteStates: the FMU has no event mode"); }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    (void)discreteStatesNeedUpdate; (void)terminateSimulation; (void)nominalsOfContinuousStatesChanged;
    (void)valuesOfContinuousStatesChanged; (void)nextEventTimeDefined; (void)nextEventTime;
    return unsupported(instance, "fmi3UpdateDiscreteStates: the FMU has no event mode");
}

/* --- Model Exchange and Scheduled Execution: never instantiated, so these are refused --- */
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{ return unsupported(instance, "fmi3EnterContinuousTimeMode: the FMU supports co-simulation only"); }
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    return unsupported(instance, "fmi3CompletedIntegratorStep: the FMU supports co-simulation only");
}
fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{ (void)time; return unsupported(instance, "fmi3SetTime: the FMU supports co-simulation only"); }
fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    (void)continuousStates; (void)nContinuousStates;
    return unsupported(instance, "fmi3SetContinuousStates: the FMU supports co-simulation only");
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[], size_t nContinuousStates)
{
    (void)derivatives; (void)nContinuousStates;
    return unsupported(instance, "fmi3GetContinuousStateDerivatives: the FMU supports co-simulation only");
}
fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    (void)eventIndicators; (void)nEventIndicators;
    return unsupported(instance, "fmi3GetEventIndicators: the FMU supports co-simulation only");
}
fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    (void)continuousStates; (void)nContinuousStates;
    return unsupported(instance, "fmi3GetContinuousStates: the FMU supports co-simulation only");
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nContinuousStates)
{
    (void)nominals; (void)nContinuousStates;
    return unsupported(instance, "fmi3GetNominalsOfContinuousStates: the FMU supports co-simulation only");
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    (void)nEventIndicators;
    return unsupported(instance, "fmi3GetNumberOfEventIndicators: the FMU supports co-simulation only");
}
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    (void)nContinuousStates;
    return unsupported(instance, "fmi3GetNumberOfContinuousStates: the FMU supports co-simulation only");
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference; (void)activationTime;
    return unsupported(instance, "fmi3ActivateModelPartition: the FMU supports co-simulation only");
}

/* The FMI 3.0 API of both native FMUs over the shared plumbing (cosimulation.c), the counterpart of
   fmi2_cs.c: its types, how its arguments map onto the shared functions (value references are
   unique across types, the model's in either version: the Booleans' follow the last Real's, and
   FMI3_VR_TIME is the independent variable `time`), and what FMI
   3.0 refuses on its own: Scheduled Execution, clocks, event mode in co-simulation (initialization
   goes straight to step mode), discrete states and the variable types the FMU does not have; Model
   Exchange, except in an FMU built with OPFMU_MODEL_EXCHANGE, the native reference, whose Model
   Exchange calls (and event mode) are in fmi3_me.c. Every misuse returns fmi3Error with a reason
   through the importer's logger; nothing aborts. */
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "cosimulation.h"
#include "fmi3Functions.h"
#include "variables.h"

#define SNAPSHOT_MAGIC 0x0F3F5A13u /* not fmi2_cs.c's: an FMI 2.0 state is refused */

static void emit(const Instance *inst, Status status, const char *category, const char *message)
{
    fmi3LogMessageCallback logger = (fmi3LogMessageCallback)inst->logger;
    logger((fmi3InstanceEnvironment)inst->environment, (fmi3Status)status, category, message);
}

/* a refused instantiation: logs why (where the importer gave a logger) and returns no instance */
static fmi3Instance refuse(fmi3InstanceEnvironment environment, fmi3LogMessageCallback logger, const char *format, ...)
{
    char message[1024];
    va_list args;
    if (!logger) return NULL;
    va_start(args, format);
    format_message(message, sizeof message, format, args);
    va_end(args);
    logger(environment, fmi3Error, "logStatusError", message);
    return NULL;
}

/* a function of an interface or feature the FMU does not provide: fmi3Error with the reason */
static fmi3Status unsupported(fmi3Instance instance, const char *reason)
{
    return (fmi3Status)fail((Instance *)instance, STATUS_ERROR, "%s", reason);
}

/* access to a variable type the FMU does not have: fine for an empty list, an error otherwise */
static fmi3Status none_of(fmi3Instance instance, size_t nvr, const char *function, const char *type)
{
    if (!instance) return fmi3Error;
    if (nvr == 0) return fmi3OK;
    log_message((Instance *)instance, STATUS_ERROR, "logStatusError", "%s: the FMU has no %s variable to access",
                function, type);
    return fmi3Error;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    return (fmi3Status)cs_set_debug_logging((Instance *)instance, "fmi3SetDebugLogging", loggingOn, nCategories,
                                            categories);
}

#ifndef OPFMU_MODEL_EXCHANGE
fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    return refuse(instanceEnvironment, logMessage, "fmi3InstantiateModelExchange: %s supports co-simulation only",
                  OPFMU_MODEL_IDENTIFIER);
}
#endif

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
    if (eventModeUsed)
        return refuse(instanceEnvironment, logMessage, "fmi3InstantiateCoSimulation: %s has no event mode "
                      "(hasEventMode=\"false\"); instantiate it with eventModeUsed = false", OPFMU_MODEL_IDENTIFIER);
    if (nRequiredIntermediateVariables > 0)
        return refuse(instanceEnvironment, logMessage, "fmi3InstantiateCoSimulation: %s has no intermediate variables "
                      "(no intermediate update); requiredIntermediateVariables must be empty", OPFMU_MODEL_IDENTIFIER);
    return fmi3_new_instance("fmi3InstantiateCoSimulation", instanceName, instantiationToken, loggingOn,
                             instanceEnvironment, (void (*)(void))logMessage);
}

Instance *fmi3_new_instance(const char *function, const char *name, const char *token, int logging_on,
                            void *environment, void (*logger)(void))
{
    fmi3LogMessageCallback log = (fmi3LogMessageCallback)logger;
    if (!name || !*name) return refuse(environment, log, "%s: missing instance name", function);
    if (!token || strcmp(token, OPFMU_GUID))
        return refuse(environment, log, "%s: instantiation token %s does not match this binary (%s)", function,
                      token ? token : "(null)", OPFMU_GUID);
    Instance *inst = instance_new(name, SNAPSHOT_MAGIC, emit, environment, logger, logging_on);
    if (!inst) return refuse(environment, log, "%s: out of memory", function);
    return inst;
}

void fmi3FreeInstance(fmi3Instance instance) { instance_free((Instance *)instance); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    Instance *inst = (Instance *)instance;
    Status status = cs_setup_experiment(inst, "fmi3EnterInitializationMode", toleranceDefined, tolerance, startTime,
                                        stopTimeDefined, stopTime);
    if (status != STATUS_OK) return (fmi3Status)status;
    return (fmi3Status)cs_enter_initialization(inst, "fmi3EnterInitializationMode");
}

/* initializes the model at the start time; then in step mode (there is no event mode) */
fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{ return (fmi3Status)cs_exit_initialization((Instance *)instance, "fmi3ExitInitializationMode"); }

#ifndef OPFMU_MODEL_EXCHANGE
fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{ return unsupported(instance, "fmi3EnterEventMode: the FMU has no event mode"); }
#endif

fmi3Status fmi3Terminate(fmi3Instance instance) { return (fmi3Status)cs_terminate((Instance *)instance, "fmi3Terminate"); }

fmi3Status fmi3Reset(fmi3Instance instance) { return (fmi3Status)cs_reset((Instance *)instance, "fmi3Reset"); }

/* all variables are scalars: one value per value reference; nonzero: refused (logged) */
static int bad_arrays(Instance *inst, const char *function, const fmi3ValueReference vr[], size_t nvr,
                      const void *values, size_t nValues)
{
    if (nValues != nvr) {
        log_message(inst, STATUS_ERROR, "logStatusError", "%s: %lu values for %lu value references (all variables are "
                    "scalars)", function, (unsigned long)nValues, (unsigned long)nvr);
        return 1;
    }
    if (nvr > 0 && (!vr || !values)) {
        log_message(inst, STATUS_ERROR, "logStatusError", "%s: NULL array", function);
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
        } else if (vr[i] >= VR_REAL_COUNT) { /* a Boolean's or no variable's */
            snprintf(detail, sizeof detail, "%u", vr[i]);
            return (fmi3Status)fail(inst, STATUS_ERROR, "fmi3GetFloat64: no Float64 variable with value reference %s",
                                    detail);
        } else if (cs_get_real(inst, "fmi3GetFloat64", vr[i], &values[i]) != STATUS_OK) {
            return fmi3Error;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues)
{
    Instance *inst = (Instance *)instance;
    if (not_allowed(inst, "fmi3SetFloat64", ST_INSTANTIATED | ST_INIT | ST_RUNNING)) return fmi3Error;
    if (bad_arrays(inst, "fmi3SetFloat64", vr, nvr, values, nValues)) return fmi3Error;
    for (size_t i = 0; i < nvr; ++i) {
        if (vr[i] == FMI3_VR_TIME)
            return (fmi3Status)fail(inst, STATUS_ERROR, "%s",
                                    "fmi3SetFloat64: time is the independent variable and cannot be set");
        if (cs_set_real(inst, "fmi3SetFloat64", vr[i], values[i]) != STATUS_OK) return fmi3Error;
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
        if (!model_boolean_exists(vr[i])) {
            snprintf(detail, sizeof detail, "%u", vr[i]);
            return (fmi3Status)fail(inst, STATUS_ERROR, "fmi3GetBoolean: no Boolean variable with value reference %s", detail);
        }
        values[i] = model_get_boolean(&inst->model, vr[i]) ? fmi3True : fmi3False;
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
    Instance *inst = (Instance *)instance;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (not_allowed(inst, "fmi3DoStep", ST_STEP)) return fmi3Error;
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime)
        return (fmi3Status)fail(inst, STATUS_ERROR, "%s", "fmi3DoStep: NULL output argument");
    *eventHandlingNeeded = *terminateSimulation = *earlyReturn = fmi3False; /* no events, no early return */
    Status status = cs_do_step(inst, "fmi3DoStep", currentCommunicationPoint, communicationStepSize);
    *lastSuccessfulTime = inst->model.time; /* the end of the step, or where a refused step left the model */
    return (fmi3Status)status;
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

/* The checks of both derivative functions: FMI 3.0's list lengths (the seed runs over the knowns,
   over the unknowns for the adjoint, the sensitivity over the other list) and NULL arrays, then the
   shared ones (cs_derivatives_refused), with the Jacobian of the derived outputs into J where an
   unknown is one. Nonzero: refused (logged), nothing written. */
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
        fail(inst, STATUS_ERROR, "%s", message);
        return 1;
    }
    if ((nUnknowns > 0 && !unknowns) || (nKnowns > 0 && !knowns) || (nSeed > 0 && !seed) ||
        (nSensitivity > 0 && !sensitivity)) {
        log_message(inst, STATUS_ERROR, "logStatusError", "%s: NULL array", function);
        return 1;
    }
    return cs_derivatives_refused(inst, function, unknowns, nUnknowns, knowns, nKnowns, seeded, seed, nSeed, J);
}

/* sensitivity[i] = sum over k of d unknown_i / d known_k * seed[k] */
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    Instance *inst = (Instance *)instance;
    double J[OPFMU_N_OUTPUTS > 0 ? OPFMU_N_OUTPUTS * OPFMU_N_COLUMNS : 1];
    if (derivatives_refused(inst, "fmi3GetDirectionalDerivative", 0, unknowns, nUnknowns, knowns,
                            nKnowns, seed, nSeed, sensitivity, nSensitivity, J))
        return fmi3Error;
    for (size_t i = 0; i < nUnknowns; ++i) {
        double sum = 0.0;
        for (size_t k = 0; k < nKnowns; ++k)
            sum += model_partial(&inst->model, J, unknowns[i], knowns[k]) * seed[k];
        sensitivity[i] = sum;
    }
    return fmi3OK;
}

/* sensitivity[k] = sum over i of seed[i] * d unknown_i / d known_k */
fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    Instance *inst = (Instance *)instance;
    double J[OPFMU_N_OUTPUTS > 0 ? OPFMU_N_OUTPUTS * OPFMU_N_COLUMNS : 1];
    if (derivatives_refused(inst, "fmi3GetAdjointDerivative", 1, unknowns, nUnknowns, knowns,
                            nKnowns, seed, nSeed, sensitivity, nSensitivity, J))
        return fmi3Error;
    for (size_t k = 0; k < nKnowns; ++k) {
        double sum = 0.0;
        for (size_t i = 0; i < nUnknowns; ++i)
            sum += seed[i] * model_partial(&inst->model, J, unknowns[i], knowns[k]);
        sensitivity[k] = sum;
    }
    return fmi3OK;
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{ return (fmi3Status)cs_get_state((Instance *)instance, "fmi3GetFMUState", FMUState); }

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{ return (fmi3Status)cs_set_state((Instance *)instance, "fmi3SetFMUState", FMUState); }

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{ return (fmi3Status)cs_free_state((Instance *)instance, "fmi3FreeFMUState", FMUState); }

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{ return (fmi3Status)cs_serialized_state_size((Instance *)instance, "fmi3SerializedFMUStateSize", FMUState, size); }

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    return (fmi3Status)cs_serialize_state((Instance *)instance, "fmi3SerializeFMUState", FMUState, serializedState,
                                          size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState)
{
    return (fmi3Status)cs_deserialize_state((Instance *)instance, "fmi3DeserializeFMUState", serializedState, size,
                                            FMUState);
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
{ return unsupported(instance, "fmi3EvaluateDiscreteStates: the FMU has no discrete states"); }
#ifndef OPFMU_MODEL_EXCHANGE /* fmi3_me.c has these */
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
#endif

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference; (void)activationTime;
    return unsupported(instance, "fmi3ActivateModelPartition: the FMU supports co-simulation only");
}

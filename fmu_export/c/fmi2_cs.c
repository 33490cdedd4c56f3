/* The FMI 2.0 API of both native FMUs over the shared plumbing (cosimulation.c): its types, how
   its arguments map onto the shared functions, and what FMI 2.0 refuses on its own (asynchronous
   status, output derivatives, variable types the FMU does not have; model exchange, except in an FMU
   built with OPFMU_MODEL_EXCHANGE, the native reference, whose Model Exchange calls are in
   fmi2_me.c). Model behaviour
   lives behind model.h. Every misuse returns fmi2Error (or fmi2Discard) with a reason through the
   importer's logger; nothing aborts. */
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "cosimulation.h"
#include "fmi2Functions.h"
#include "variables.h"

#define SNAPSHOT_MAGIC 0x0F3F5A11u /* not fmi3_cs.c's: an FMI 3.0 state is refused */

static void emit(const Instance *inst, Status status, const char *category, const char *message)
{
    fmi2CallbackLogger logger = (fmi2CallbackLogger)inst->logger;
    logger((fmi2ComponentEnvironment)inst->environment, inst->name, (fmi2Status)status, category, message);
}

/* a refused instantiation: logs why through the importer's logger and returns no instance */
static fmi2Component refuse(const fmi2CallbackFunctions *functions, fmi2String instanceName, const char *format, ...)
{
    char message[1024];
    va_list args;
    va_start(args, format);
    format_message(message, sizeof message, format, args);
    va_end(args);
    functions->logger(functions->componentEnvironment, instanceName ? instanceName : "?", fmi2Error, "logStatusError",
                      message);
    return NULL;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories, const fmi2String categories[])
{
    return (fmi2Status)cs_set_debug_logging((Instance *)c, "fmi2SetDebugLogging", loggingOn, nCategories, categories);
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    (void)fmuResourceLocation;
    (void)visible;
    if (!functions || !functions->logger) return NULL;
    if (!instanceName || !*instanceName) return refuse(functions, instanceName, "fmi2Instantiate: missing instance name");
#ifdef OPFMU_MODEL_EXCHANGE
    if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange)
        return refuse(functions, instanceName, "fmi2Instantiate: fmuType %d is neither fmi2ModelExchange nor "
                      "fmi2CoSimulation", (int)fmuType);
#else
    if (fmuType != fmi2CoSimulation)
        return refuse(functions, instanceName, "fmi2Instantiate: %s supports co-simulation only", OPFMU_MODEL_IDENTIFIER);
#endif
    if (!fmuGUID || strcmp(fmuGUID, OPFMU_GUID))
        return refuse(functions, instanceName, "fmi2Instantiate: GUID %.60s does not match this binary (%s)",
                      fmuGUID ? fmuGUID : "(null)", OPFMU_GUID);
    Instance *inst = instance_new(instanceName, SNAPSHOT_MAGIC, emit, functions->componentEnvironment,
                                  (void (*)(void))functions->logger, loggingOn);
    if (!inst) return refuse(functions, instanceName, "fmi2Instantiate: out of memory");
    inst->model_exchange = fmuType == fmi2ModelExchange; /* its calls: fmi2_me.c */
    return inst;
}

void fmi2FreeInstance(fmi2Component c) { instance_free((Instance *)c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    return (fmi2Status)cs_setup_experiment((Instance *)c, "fmi2SetupExperiment", toleranceDefined, tolerance,
                                           startTime, stopTimeDefined, stopTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{ return (fmi2Status)cs_enter_initialization((Instance *)c, "fmi2EnterInitializationMode"); }

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{ return (fmi2Status)cs_exit_initialization((Instance *)c, "fmi2ExitInitializationMode"); }

fmi2Status fmi2Terminate(fmi2Component c) { return (fmi2Status)cs_terminate((Instance *)c, "fmi2Terminate"); }

fmi2Status fmi2Reset(fmi2Component c) { return (fmi2Status)cs_reset((Instance *)c, "fmi2Reset"); }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2GetReal", ST_ANY)) return fmi2Error;
    if (nvr > 0 && (!vr || !value)) return (fmi2Status)fail(inst, STATUS_ERROR, "%s", "fmi2GetReal: NULL array");
    for (size_t i = 0; i < nvr; ++i)
        if (cs_get_real(inst, "fmi2GetReal", vr[i], &value[i]) != STATUS_OK) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2SetReal", ST_INSTANTIATED | ST_INIT | ST_RUNNING)) return fmi2Error;
    if (nvr > 0 && (!vr || !value)) return (fmi2Status)fail(inst, STATUS_ERROR, "%s", "fmi2SetReal: NULL array");
    for (size_t i = 0; i < nvr; ++i)
        if (cs_set_real(inst, "fmi2SetReal", vr[i], value[i]) != STATUS_OK) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2GetBoolean", ST_ANY)) return fmi2Error;
    if (nvr > 0 && (!vr || !value)) return (fmi2Status)fail(inst, STATUS_ERROR, "%s", "fmi2GetBoolean: NULL array");
    for (size_t i = 0; i < nvr; ++i) {
        if (!model_boolean_exists(vr[i]))
            return (fmi2Status)fail(inst, STATUS_ERROR, "%s", "fmi2GetBoolean: unknown value reference");
        value[i] = model_get_boolean(&inst->model, vr[i]) ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

/* access to a variable type the FMU does not have: fine for an empty list, an error otherwise */
static fmi2Status none_of(fmi2Component c, size_t nvr, const char *function)
{
    if (nvr == 0) return fmi2OK;
    return (fmi2Status)fail((Instance *)c, STATUS_ERROR, "%s: the FMU has no variable of this type to access", function);
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
    (void)noSetFMUStatePriorToCurrentPoint;
    return (fmi2Status)cs_do_step((Instance *)c, "fmi2DoStep", currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    return (fmi2Status)fail((Instance *)c, STATUS_ERROR, "%s",
                            "fmi2CancelStep: steps run synchronously; there is nothing to cancel");
}

static fmi2Status no_status(fmi2Component c, const char *function)
{
    return (fmi2Status)fail((Instance *)c, STATUS_DISCARD, "%s: no asynchronous status is provided", function);
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
    Instance *inst = (Instance *)c;
    if (not_allowed(inst, "fmi2SetRealInputDerivatives", ST_INSTANTIATED | ST_INIT | ST_STEP)) return fmi2Error;
    if (nvr > 0 && (!vr || !order || !value))
        return (fmi2Status)fail(inst, STATUS_ERROR, "%s", "fmi2SetRealInputDerivatives: NULL array");
    for (size_t i = 0; i < nvr; ++i)
        if (cs_set_input_derivative(inst, "fmi2SetRealInputDerivatives", vr[i], (int)order[i], value[i]) != STATUS_OK)
            return fmi2Error;
    return fmi2OK;
#else
    (void)vr; (void)nvr; (void)order; (void)value;
    return (fmi2Status)fail((Instance *)c, STATUS_ERROR, "%s",
                            "fmi2SetRealInputDerivatives: not supported (inputs are held constant)");
#endif
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    return (fmi2Status)fail((Instance *)c, STATUS_ERROR, "%s", "fmi2GetRealOutputDerivatives: not supported");
}

/* dvUnknown[i] = sum over k of d unknown_i / d known_k * dvKnown[k], outputs with respect to inputs at
   the current state and inputs (model_partial); nothing is written unless every reference is valid */
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    Instance *inst = (Instance *)c;
    double J[OPFMU_N_OUTPUTS > 0 ? OPFMU_N_OUTPUTS * OPFMU_N_COLUMNS : 1];
    if (not_allowed(inst, "fmi2GetDirectionalDerivative", ST_INIT | ST_INITIALIZED)) return fmi2Error;
    if ((nUnknown > 0 && (!vUnknown_ref || !dvUnknown)) || (nKnown > 0 && (!vKnown_ref || !dvKnown)))
        return (fmi2Status)fail(inst, STATUS_ERROR, "%s", "fmi2GetDirectionalDerivative: NULL array");
    if (cs_derivatives_refused(inst, "fmi2GetDirectionalDerivative", vUnknown_ref, nUnknown, vKnown_ref, nKnown,
                               vKnown_ref, dvKnown, nKnown, J))
        return fmi2Error;
    for (size_t i = 0; i < nUnknown; ++i) {
        double sum = 0.0;
        for (size_t k = 0; k < nKnown; ++k)
            sum += model_partial(&inst->model, J, vUnknown_ref[i], vKnown_ref[k]) * dvKnown[k];
        dvUnknown[i] = sum;
    }
    return fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{ return (fmi2Status)cs_get_state((Instance *)c, "fmi2GetFMUstate", FMUstate); }

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{ return (fmi2Status)cs_set_state((Instance *)c, "fmi2SetFMUstate", FMUstate); }

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{ return (fmi2Status)cs_free_state((Instance *)c, "fmi2FreeFMUstate", FMUstate); }

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{ return (fmi2Status)cs_serialized_state_size((Instance *)c, "fmi2SerializedFMUstateSize", FMUstate, size); }

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    return (fmi2Status)cs_serialize_state((Instance *)c, "fmi2SerializeFMUstate", FMUstate,
                                          (unsigned char *)serializedState, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size, fmi2FMUstate *FMUstate)
{
    return (fmi2Status)cs_deserialize_state((Instance *)c, "fmi2DeSerializeFMUstate",
                                            (const unsigned char *)serializedState, size, FMUstate);
}

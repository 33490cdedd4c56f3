/* The FMI 3.0 Model Exchange API of the native reference FMU over model_exchange.c, the
   counterpart of fmi2_me.c: fmi3InstantiateModelExchange, event mode (which a co-simulation
   instance does not have: hasEventMode="false") and the continuous-time calls. The event update
   never asks for another iteration or a time event. Every misuse returns fmi3Error with a reason
   through the importer's logger; nothing aborts. */
#include "fmi3Functions.h"
#include "model_exchange.h"

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)resourcePath;
    (void)visible;
    Instance *inst = fmi3_new_instance("fmi3InstantiateModelExchange", instanceName, instantiationToken, loggingOn,
                                       instanceEnvironment, (void (*)(void))logMessage);
    if (inst) inst->model_exchange = 1;
    return inst;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{ return (fmi3Status)me_enter_event_mode((Instance *)instance, "fmi3EnterEventMode"); }

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    Instance *inst = (Instance *)instance;
    int changed = 0;
    if (inst && (!discreteStatesNeedUpdate || !terminateSimulation || !nominalsOfContinuousStatesChanged ||
                 !valuesOfContinuousStatesChanged || !nextEventTimeDefined || !nextEventTime))
        return (fmi3Status)fail(inst, STATUS_ERROR, "%s", "fmi3UpdateDiscreteStates: NULL output argument");
    Status status = me_update_discrete_states(inst, "fmi3UpdateDiscreteStates", &changed);
    if (status != STATUS_OK) return (fmi3Status)status;
    *discreteStatesNeedUpdate = *terminateSimulation = *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = changed ? fmi3True : fmi3False;
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    return fmi3OK;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{ return (fmi3Status)me_enter_continuous_time_mode((Instance *)instance, "fmi3EnterContinuousTimeMode"); }

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    Instance *inst = (Instance *)instance;
    int event = 0;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (inst && (!enterEventMode || !terminateSimulation))
        return (fmi3Status)fail(inst, STATUS_ERROR, "%s", "fmi3CompletedIntegratorStep: NULL output argument");
    Status status = me_completed_integrator_step(inst, "fmi3CompletedIntegratorStep", &event);
    if (status != STATUS_OK) return (fmi3Status)status;
    *enterEventMode = event ? fmi3True : fmi3False;
    *terminateSimulation = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{ return (fmi3Status)me_set_time((Instance *)instance, "fmi3SetTime", time); }

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[], size_t nContinuousStates)
{ return (fmi3Status)me_set_states((Instance *)instance, "fmi3SetContinuousStates", continuousStates, nContinuousStates); }

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[], size_t nContinuousStates)
{
    return (fmi3Status)me_get_derivatives((Instance *)instance, "fmi3GetContinuousStateDerivatives", derivatives,
                                          nContinuousStates);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    return (fmi3Status)me_get_indicators((Instance *)instance, "fmi3GetEventIndicators", eventIndicators,
                                         nEventIndicators);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates)
{ return (fmi3Status)me_get_states((Instance *)instance, "fmi3GetContinuousStates", continuousStates, nContinuousStates); }

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nContinuousStates)
{
    return (fmi3Status)me_get_nominals((Instance *)instance, "fmi3GetNominalsOfContinuousStates", nominals,
                                       nContinuousStates);
}

/* the sizes of the arrays above; in any state, for either interface */
static fmi3Status count(fmi3Instance instance, const char *function, size_t *n, size_t value)
{
    Instance *inst = (Instance *)instance;
    if (not_allowed(inst, function, ST_ANY)) return fmi3Error;
    if (!n) return (fmi3Status)fail(inst, STATUS_ERROR, "%s: NULL argument", function);
    *n = value;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{ return count(instance, "fmi3GetNumberOfEventIndicators", nEventIndicators, OPFMU_N_SWITCHING); }

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{ return count(instance, "fmi3GetNumberOfContinuousStates", nContinuousStates, OPFMU_N_STATES); }

/* The FMI 2.0 Model Exchange API of the native reference FMU over model_exchange.c (an instance
   of fmuType fmi2ModelExchange, fmi2_cs.c's fmi2Instantiate): its types and how its arguments map
   onto the shared functions. The event update never asks for another iteration or a time event.
   Every misuse returns fmi2Error with a reason through the importer's logger; nothing aborts. */
#include "fmi2Functions.h"
#include "model_exchange.h"

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{ return (fmi2Status)me_set_time((Instance *)c, "fmi2SetTime", time); }

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{ return (fmi2Status)me_set_states((Instance *)c, "fmi2SetContinuousStates", x, nx); }

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{ return (fmi2Status)me_get_states((Instance *)c, "fmi2GetContinuousStates", x, nx); }

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{ return (fmi2Status)me_get_derivatives((Instance *)c, "fmi2GetDerivatives", derivatives, nx); }

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{ return (fmi2Status)me_get_indicators((Instance *)c, "fmi2GetEventIndicators", eventIndicators, ni); }

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{ return (fmi2Status)me_get_nominals((Instance *)c, "fmi2GetNominalsOfContinuousStates", x_nominal, nx); }

fmi2Status fmi2EnterEventMode(fmi2Component c)
{ return (fmi2Status)me_enter_event_mode((Instance *)c, "fmi2EnterEventMode"); }

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo)
{
    Instance *inst = (Instance *)c;
    int changed = 0;
    if (inst && !eventInfo) return (fmi2Status)fail(inst, STATUS_ERROR, "%s", "fmi2NewDiscreteStates: NULL eventInfo");
    Status status = me_update_discrete_states(inst, "fmi2NewDiscreteStates", &changed);
    if (status != STATUS_OK) return (fmi2Status)status;
    eventInfo->newDiscreteStatesNeeded = fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = changed ? fmi2True : fmi2False;
    eventInfo->nextEventTimeDefined = fmi2False;
    eventInfo->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{ return (fmi2Status)me_enter_continuous_time_mode((Instance *)c, "fmi2EnterContinuousTimeMode"); }

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    Instance *inst = (Instance *)c;
    int event = 0;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (inst && (!enterEventMode || !terminateSimulation))
        return (fmi2Status)fail(inst, STATUS_ERROR, "%s", "fmi2CompletedIntegratorStep: NULL output argument");
    Status status = me_completed_integrator_step(inst, "fmi2CompletedIntegratorStep", &event);
    if (status != STATUS_OK) return (fmi2Status)status;
    *enterEventMode = event ? fmi2True : fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

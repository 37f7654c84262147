/* kronlag FMU: the FMI 2.0 functions, Model Exchange and Co-Simulation in one library, over the
 * instance of fmu_core.c (appended after it by kronlag.views.fmu, with the FMI 2.0 headers).
 * Memory comes from calloc (canNotUseMemoryManagementFunctions="true"). */

#include "fmi2Functions.h"

static void kl_log2(const kl_fmu *fmu, const char *message)
{
    const fmi2CallbackFunctions *functions = fmu->logger;
    if (functions && functions->logger)
        functions->logger(functions->componentEnvironment, fmu->name, fmi2Error, "logStatusError", "%s", message);
}

static fmi2Status kl_status2(int failed)
{
    return failed ? fmi2Error : fmi2OK;
}

typedef struct {
    kl_fmu *fmu;
    fmi2CallbackFunctions functions;  /* kept: the importer's struct need not outlive fmi2Instantiate */
} kl_fmu2;

#define KL_FMU(c) (((kl_fmu2 *)(c))->fmu)

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    (void)c, (void)loggingOn, (void)nCategories, (void)categories;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    (void)fmuResourceLocation, (void)visible, (void)loggingOn;
    kl_fmu2 *component = calloc(1, sizeof(kl_fmu2));
    if (!component) return NULL;
    if (functions) component->functions = *functions;
    kl_fmu probe;
    memset(&probe, 0, sizeof probe);
    probe.log = kl_log2, probe.logger = &component->functions;
    snprintf(probe.name, sizeof probe.name, "%s", instanceName ? instanceName : "");
    if (!fmuGUID || strcmp(fmuGUID, KL_FMU_GUID) != 0) {
        kl_error(&probe, "the GUID %s is not this FMU's (%s)", fmuGUID ? fmuGUID : "(none)", KL_FMU_GUID);
        free(component);
        return NULL;
    }
    component->fmu = kl_new(instanceName, fmuType == fmi2CoSimulation, kl_log2, &component->functions, NULL);
    if (!component->fmu) {
        free(component);
        return NULL;
    }
    return component;
}

void fmi2FreeInstance(fmi2Component c)
{
    if (!c) return;
    kl_delete(KL_FMU(c));
    free(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    (void)stopTimeDefined, (void)stopTime;
    kl_setup(KL_FMU(c), toleranceDefined, tolerance, startTime);
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    KL_FMU(c)->mode = KL_MODE_INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) { return kl_status2(kl_exit_initialization(KL_FMU(c))); }

fmi2Status fmi2Terminate(fmi2Component c)
{
    KL_FMU(c)->mode = KL_MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    kl_reset(KL_FMU(c));
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    for (size_t k = 0; k < nvr; ++k)
        if (kl_get(KL_FMU(c), vr[k], value + k)) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    for (size_t k = 0; k < nvr; ++k)
        if (kl_set(KL_FMU(c), vr[k], value[k])) return fmi2Error;
    return fmi2OK;
}

/* No Integer, Boolean or String variables; no FMU state, directional derivatives, input
 * interpolation, output derivatives or asynchronous steps (modelDescription.xml says so). */
static fmi2Status kl_none2(fmi2Component c, size_t n, const char *what)
{
    return n ? kl_status2(kl_error(KL_FMU(c), "this FMU has no %s variables", what)) : fmi2OK;
}

static fmi2Status kl_unsupported2(fmi2Component c, const char *function)
{
    return kl_status2(kl_error(KL_FMU(c), "%s is not supported by this FMU", function));
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    (void)vr, (void)value;
    return kl_none2(c, nvr, "Integer");
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    (void)vr, (void)value;
    return kl_none2(c, nvr, "Boolean");
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    (void)vr, (void)value;
    return kl_none2(c, nvr, "String");
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    (void)vr, (void)value;
    return kl_none2(c, nvr, "Integer");
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    (void)vr, (void)value;
    return kl_none2(c, nvr, "Boolean");
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    (void)vr, (void)value;
    return kl_none2(c, nvr, "String");
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    (void)state;
    return kl_unsupported2(c, "fmi2GetFMUstate");
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    (void)state;
    return kl_unsupported2(c, "fmi2SetFMUstate");
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    (void)state;
    return kl_unsupported2(c, "fmi2FreeFMUstate");
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    (void)state, (void)size;
    return kl_unsupported2(c, "fmi2SerializedFMUstateSize");
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    (void)state, (void)bytes, (void)size;
    return kl_unsupported2(c, "fmi2SerializeFMUstate");
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state)
{
    (void)bytes, (void)size, (void)state;
    return kl_unsupported2(c, "fmi2DeSerializeFMUstate");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference unknowns[], size_t nUnknown,
                                        const fmi2ValueReference knowns[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)unknowns, (void)nUnknown, (void)knowns, (void)nKnown, (void)dvKnown, (void)dvUnknown;
    return kl_unsupported2(c, "fmi2GetDirectionalDerivative");
}

/* ---- Model Exchange -------------------------------------------------------------------------- */

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    (void)c;
    return fmi2OK;
}

/* The event step: the states projected when they drifted off the constraints. */
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info)
{
    int changed = 0;
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    fmi2Status status = kl_status2(kl_event_update(KL_FMU(c), &changed));
    info->valuesOfContinuousStatesChanged = changed ? fmi2True : fmi2False;
    return status;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    (void)c;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    *enterEventMode = kl_step_event(KL_FMU(c)) ? fmi2True : fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    kl_set_time(KL_FMU(c), time);
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    return kl_status2(kl_set_states(KL_FMU(c), x, nx));
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    return kl_status2(kl_get_derivatives(KL_FMU(c), derivatives, nx));
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{
    (void)eventIndicators;
    return ni ? kl_status2(kl_error(KL_FMU(c), "this FMU has no event indicators")) : fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    return kl_status2(kl_get_states(KL_FMU(c), x, nx));
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    (void)c;
    for (size_t i = 0; i < nx; ++i) x_nominal[i] = 1.0;
    return fmi2OK;
}

/* ---- Co-Simulation --------------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    return kl_unsupported2(c, "fmi2SetRealInputDerivatives (canInterpolateInputs is false)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    return kl_unsupported2(c, "fmi2GetRealOutputDerivatives (maxOutputDerivativeOrder is 0)");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    return kl_status2(kl_do_step(KL_FMU(c), currentCommunicationPoint, communicationStepSize));
}

fmi2Status fmi2CancelStep(fmi2Component c) { return kl_unsupported2(c, "fmi2CancelStep (the steps are synchronous)"); }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s, (void)value;
    return kl_unsupported2(c, "fmi2GetStatus (the steps are synchronous)");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    if (s != fmi2LastSuccessfulTime) return kl_unsupported2(c, "fmi2GetRealStatus other than fmi2LastSuccessfulTime");
    *value = KL_FMU(c)->t;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)s, (void)value;
    return kl_unsupported2(c, "fmi2GetIntegerStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    (void)s, (void)value;
    return kl_unsupported2(c, "fmi2GetBooleanStatus");
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)s, (void)value;
    return kl_unsupported2(c, "fmi2GetStringStatus");
}

/* kronlag FMU: the FMI 3.0 functions, Model Exchange and Co-Simulation in one library, over the
 * instance of fmu_core.c (appended after it by kronlag.views.fmu, with the FMI 3.0 headers).
 * Only Float64 variables; no clocks, scheduled execution, FMU state, derivatives of the outputs,
 * directional or adjoint derivatives, event mode in co-simulation (modelDescription.xml says so). */

#include "fmi3Functions.h"

static void kl_log3(const kl_fmu *fmu, const char *message)
{
    fmi3LogMessageCallback log = (fmi3LogMessageCallback)fmu->logger;
    if (log) log(fmu->environment, fmi3Error, "logStatusError", message);
}

static fmi3Status kl_status3(int failed)
{
    return failed ? fmi3Error : fmi3OK;
}

static fmi3Status kl_unsupported3(fmi3Instance instance, const char *function)
{
    return kl_status3(kl_error(instance, "%s is not supported by this FMU", function));
}

static fmi3Instance kl_instantiate3(fmi3String instanceName, fmi3String instantiationToken, int cosimulation,
                                    fmi3InstanceEnvironment environment, fmi3LogMessageCallback log)
{
    kl_fmu probe;
    memset(&probe, 0, sizeof probe);
    probe.log = kl_log3, probe.logger = (const void *)log, probe.environment = environment;
    snprintf(probe.name, sizeof probe.name, "%s", instanceName ? instanceName : "");
    if (!instantiationToken || strcmp(instantiationToken, KL_FMU_GUID) != 0) {
        kl_error(&probe, "the instantiation token %s is not this FMU's (%s)",
                 instantiationToken ? instantiationToken : "(none)", KL_FMU_GUID);
        return NULL;
    }
    return kl_new(instanceName, cosimulation, kl_log3, (const void *)log, environment);
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    (void)instance, (void)loggingOn, (void)nCategories, (void)categories;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage)
{
    (void)resourcePath, (void)visible, (void)loggingOn;
    return kl_instantiate3(instanceName, instantiationToken, 0, instanceEnvironment, logMessage);
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
    (void)resourcePath, (void)visible, (void)loggingOn, (void)eventModeUsed, (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables, (void)nRequiredIntermediateVariables, (void)intermediateUpdate;
    return kl_instantiate3(instanceName, instantiationToken, 1, instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    (void)instanceEnvironment, (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                               "this FMU does not support scheduled execution");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) { kl_delete(instance); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    (void)stopTimeDefined, (void)stopTime;
    kl_setup(instance, toleranceDefined, tolerance, startTime);
    ((kl_fmu *)instance)->mode = KL_MODE_INITIALIZATION;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) { return kl_status3(kl_exit_initialization(instance)); }

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    (void)instance;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    ((kl_fmu *)instance)->mode = KL_MODE_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    kl_reset(instance);
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Float64 values[], size_t nValues)
{
    if (nValues != nValueReferences) return kl_status3(kl_error(instance, "fmi3GetFloat64: scalars only"));
    for (size_t k = 0; k < nValueReferences; ++k)
        if (kl_get(instance, valueReferences[k], values + k)) return fmi3Error;
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Float64 values[], size_t nValues)
{
    if (nValues != nValueReferences) return kl_status3(kl_error(instance, "fmi3SetFloat64: scalars only"));
    for (size_t k = 0; k < nValueReferences; ++k)
        if (kl_set(instance, valueReferences[k], values[k])) return fmi3Error;
    return fmi3OK;
}

/* The other types: this FMU has no variables of them. */
#define KL_NO_VARIABLES(TYPE, VALUES)                                                                        \
    fmi3Status fmi3Get##TYPE(fmi3Instance instance, const fmi3ValueReference valueReferences[],              \
                             size_t nValueReferences, VALUES values[], size_t nValues)                        \
    {                                                                                                         \
        (void)valueReferences, (void)values, (void)nValues;                                                  \
        return nValueReferences ? kl_status3(kl_error(instance, "this FMU has no " #TYPE " variables")) : fmi3OK; \
    }                                                                                                         \
    fmi3Status fmi3Set##TYPE(fmi3Instance instance, const fmi3ValueReference valueReferences[],              \
                             size_t nValueReferences, const VALUES values[], size_t nValues)                  \
    {                                                                                                         \
        (void)valueReferences, (void)values, (void)nValues;                                                  \
        return nValueReferences ? kl_status3(kl_error(instance, "this FMU has no " #TYPE " variables")) : fmi3OK; \
    }

KL_NO_VARIABLES(Float32, fmi3Float32)
KL_NO_VARIABLES(Int8, fmi3Int8)
KL_NO_VARIABLES(UInt8, fmi3UInt8)
KL_NO_VARIABLES(Int16, fmi3Int16)
KL_NO_VARIABLES(UInt16, fmi3UInt16)
KL_NO_VARIABLES(Int32, fmi3Int32)
KL_NO_VARIABLES(UInt32, fmi3UInt32)
KL_NO_VARIABLES(Int64, fmi3Int64)
KL_NO_VARIABLES(UInt64, fmi3UInt64)
KL_NO_VARIABLES(Boolean, fmi3Boolean)
KL_NO_VARIABLES(String, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    (void)valueReferences, (void)valueSizes, (void)values, (void)nValues;
    return nValueReferences ? kl_status3(kl_error(instance, "this FMU has no Binary variables")) : fmi3OK;
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues)
{
    (void)valueReferences, (void)valueSizes, (void)values, (void)nValues;
    return nValueReferences ? kl_status3(kl_error(instance, "this FMU has no Binary variables")) : fmi3OK;
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Clock values[])
{
    (void)valueReferences, (void)values;
    return nValueReferences ? kl_status3(kl_error(instance, "this FMU has no clocks")) : fmi3OK;
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Clock values[])
{
    (void)valueReferences, (void)values;
    return nValueReferences ? kl_status3(kl_error(instance, "this FMU has no clocks")) : fmi3OK;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    (void)valueReference, (void)nDependencies;
    return kl_unsupported3(instance, "fmi3GetNumberOfVariableDependencies");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    (void)dependent, (void)elementIndicesOfDependent, (void)independents, (void)elementIndicesOfIndependents;
    (void)dependencyKinds, (void)nDependencies;
    return kl_unsupported3(instance, "fmi3GetVariableDependencies");
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    (void)FMUState;
    return kl_unsupported3(instance, "fmi3GetFMUState");
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    (void)FMUState;
    return kl_unsupported3(instance, "fmi3SetFMUState");
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    (void)FMUState;
    return kl_unsupported3(instance, "fmi3FreeFMUState");
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    (void)FMUState, (void)size;
    return kl_unsupported3(instance, "fmi3SerializedFMUStateSize");
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    (void)FMUState, (void)serializedState, (void)size;
    return kl_unsupported3(instance, "fmi3SerializeFMUState");
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState)
{
    (void)serializedState, (void)size, (void)FMUState;
    return kl_unsupported3(instance, "fmi3DeserializeFMUState");
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed, (void)sensitivity;
    (void)nSensitivity;
    return kl_unsupported3(instance, "fmi3GetDirectionalDerivative");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed, (void)sensitivity;
    (void)nSensitivity;
    return kl_unsupported3(instance, "fmi3GetAdjointDerivative");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    return kl_unsupported3(instance, "fmi3EnterConfigurationMode (no structural parameters)");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    return kl_unsupported3(instance, "fmi3ExitConfigurationMode (no structural parameters)");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences, (void)nValueReferences, (void)intervals, (void)qualifiers;
    return kl_unsupported3(instance, "fmi3GetIntervalDecimal (no clocks)");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions, (void)qualifiers;
    return kl_unsupported3(instance, "fmi3GetIntervalFraction (no clocks)");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[])
{
    (void)valueReferences, (void)nValueReferences, (void)shifts;
    return kl_unsupported3(instance, "fmi3GetShiftDecimal (no clocks)");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return kl_unsupported3(instance, "fmi3GetShiftFraction (no clocks)");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[])
{
    (void)valueReferences, (void)nValueReferences, (void)intervals;
    return kl_unsupported3(instance, "fmi3SetIntervalDecimal (no clocks)");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[])
{
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return kl_unsupported3(instance, "fmi3SetIntervalFraction (no clocks)");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[])
{
    (void)valueReferences, (void)nValueReferences, (void)shifts;
    return kl_unsupported3(instance, "fmi3SetShiftDecimal (no clocks)");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return kl_unsupported3(instance, "fmi3SetShiftFraction (no clocks)");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{
    (void)instance;
    return fmi3OK;
}

/* The event update: the states projected when they drifted off the constraints. */
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    int changed = 0;
    fmi3Status status = kl_status3(kl_event_update(instance, &changed));
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = changed ? fmi3True : fmi3False;
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    return status;
}

/* ---- Model Exchange -------------------------------------------------------------------------- */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{
    (void)instance;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    *enterEventMode = kl_step_event(instance) ? fmi3True : fmi3False;
    *terminateSimulation = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    kl_set_time(instance, time);
    return fmi3OK;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    return kl_status3(kl_set_states(instance, continuousStates, nContinuousStates));
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates)
{
    return kl_status3(kl_get_derivatives(instance, derivatives, nContinuousStates));
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    (void)eventIndicators;
    return nEventIndicators ? kl_status3(kl_error(instance, "this FMU has no event indicators")) : fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    return kl_status3(kl_get_states(instance, continuousStates, nContinuousStates));
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nContinuousStates)
{
    (void)instance;
    for (size_t i = 0; i < nContinuousStates; ++i) nominals[i] = 1.0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    (void)instance;
    *nEventIndicators = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    (void)instance;
    *nContinuousStates = KL_N;
    return fmi3OK;
}

/* ---- Co-Simulation --------------------------------------------------------------------------- */

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    (void)instance;
    return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues)
{
    (void)valueReferences, (void)nValueReferences, (void)orders, (void)values, (void)nValues;
    return kl_unsupported3(instance, "fmi3GetOutputDerivatives (maxOutputDerivativeOrder is 0)");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    int failed = kl_do_step(instance, currentCommunicationPoint, communicationStepSize);
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = ((kl_fmu *)instance)->t;
    return kl_status3(failed);
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference, (void)activationTime;
    return kl_unsupported3(instance, "fmi3ActivateModelPartition (no scheduled execution)");
}

/* FMI 3.0 co-simulation interface of a hevsim native cell/module FMU (generated sources:
 * model_data.h; version-independent part: hevsim_fmi.h; model: hevsim_model.h; kernel:
 * hevsim_kernel.h). Build, for example:
 *   cc -std=c99 -O2 -shared -fPIC -I<FMI 3.0 headers> fmi3_model.c -lm -o <modelIdentifier>.so
 * Supported: Float64 and Boolean variables, fixed or variable communication steps, FMU state
 * get/set/serialize. Not supported (refused with fmi3Error): model exchange, scheduled
 * execution, event mode, clocks, other variable types, derivatives, early return.
 */
#include <string.h>
#include "fmi3Functions.h"

#define HV_STATUS fmi3Status
#define HV_OK fmi3OK
#define HV_ERROR fmi3Error
#define HV_VR fmi3ValueReference
#define HV_SERIAL_MAGIC "hevsim-fmu3-state-1"
typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} hv_callbacks;
#include "hevsim_fmi.h"

static void hv_emit(const hv_instance *m, fmi3Status status, const char *category, const char *text)
{
    if (m->cb.log != NULL) m->cb.log(m->cb.env, status, category, text);
}

static fmi3Status hv_unsupported(fmi3Instance instance, const char *fn)
{
    return hv_error((hv_instance *)instance, fn, "not supported by this FMU (co-simulation without event mode)");
}

FMI3_Export const char *fmi3GetVersion(void) { return fmi3Version; }

FMI3_Export fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                                           const fmi3String categories[])
{
    (void)nCategories;
    (void)categories;
    if (instance == NULL) return fmi3Error;
    ((hv_instance *)instance)->logging = loggingOn;
    return fmi3OK;
}

FMI3_Export fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                                      fmi3String resourcePath, fmi3Boolean visible,
                                                      fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                                      fmi3LogMessageCallback logMessage)
{
    (void)instanceName;
    (void)instantiationToken;
    (void)resourcePath;
    (void)visible;
    (void)loggingOn;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", "this FMU supports co-simulation only");
    return NULL;
}

FMI3_Export fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                                     fmi3String resourcePath, fmi3Boolean visible,
                                                     fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
                                                     fmi3Boolean earlyReturnAllowed,
                                                     const fmi3ValueReference requiredIntermediateVariables[],
                                                     size_t nRequiredIntermediateVariables,
                                                     fmi3InstanceEnvironment instanceEnvironment,
                                                     fmi3LogMessageCallback logMessage,
                                                     fmi3IntermediateUpdateCallback intermediateUpdate)
{
    hv_instance *m;
    hv_callbacks cb;
    (void)resourcePath;
    (void)visible;
    (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables;
    (void)intermediateUpdate;
    cb.env = instanceEnvironment;
    cb.log = logMessage;
    m = hv_new(instanceName, cb, loggingOn);
    if (m == NULL) return NULL;
    if (instantiationToken == NULL || strcmp(instantiationToken, MODEL_GUID) != 0) {
        hv_log(m, fmi3Error, "logStatusError", "fmi3InstantiateCoSimulation: instantiationToken '%s' does not match '%s'",
               instantiationToken ? instantiationToken : "(null)", MODEL_GUID);
        hv_free(m);
        return NULL;
    }
    if (eventModeUsed) {
        hv_log(m, fmi3Error, "logStatusError", "fmi3InstantiateCoSimulation: event mode is not supported (hasEventMode=false)");
        hv_free(m);
        return NULL;
    }
    hv_reset(m);
    return m;
}

FMI3_Export fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                                           fmi3String resourcePath, fmi3Boolean visible,
                                                           fmi3Boolean loggingOn,
                                                           fmi3InstanceEnvironment instanceEnvironment,
                                                           fmi3LogMessageCallback logMessage,
                                                           fmi3ClockUpdateCallback clockUpdate,
                                                           fmi3LockPreemptionCallback lockPreemption,
                                                           fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName;
    (void)instantiationToken;
    (void)resourcePath;
    (void)visible;
    (void)loggingOn;
    (void)clockUpdate;
    (void)lockPreemption;
    (void)unlockPreemption;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", "this FMU supports co-simulation only");
    return NULL;
}

FMI3_Export void fmi3FreeInstance(fmi3Instance instance) { hv_free((hv_instance *)instance); }

FMI3_Export fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                                   fmi3Float64 tolerance, fmi3Float64 startTime,
                                                   fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    hv_instance *m = (hv_instance *)instance;
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    if (m == NULL) return fmi3Error;
    m->d.time = startTime;
    m->d.r[VR_TIME] = startTime;
    m->phase = PH_INITIALIZATION;
    return fmi3OK;
}

FMI3_Export fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    hv_instance *m = (hv_instance *)instance;
    double t;
    if (m == NULL) return fmi3Error;
    t = m->d.time;
    hv_init(&m->d);
    m->d.time = t;
    m->d.r[VR_TIME] = t;
    m->phase = PH_STEPPING;
    return fmi3OK;
}

FMI3_Export fmi3Status fmi3EnterEventMode(fmi3Instance instance) { return hv_unsupported(instance, "fmi3EnterEventMode"); }

FMI3_Export fmi3Status fmi3Terminate(fmi3Instance instance)
{
    if (instance == NULL) return fmi3Error;
    ((hv_instance *)instance)->phase = PH_TERMINATED;
    return fmi3OK;
}

FMI3_Export fmi3Status fmi3Reset(fmi3Instance instance)
{
    if (instance == NULL) return fmi3Error;
    hv_reset((hv_instance *)instance);
    return fmi3OK;
}

FMI3_Export fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                      size_t nValueReferences, fmi3Float64 values[], size_t nValues)
{
    hv_instance *m = (hv_instance *)instance;
    if (m == NULL) return fmi3Error;
    if (nValues != nValueReferences) return hv_error(m, "fmi3GetFloat64", "nValues differs from nValueReferences (no arrays)");
    return hv_get_reals(m, "fmi3GetFloat64", valueReferences, nValueReferences, values, "Float64");
}

FMI3_Export fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                      size_t nValueReferences, const fmi3Float64 values[], size_t nValues)
{
    hv_instance *m = (hv_instance *)instance;
    if (m == NULL) return fmi3Error;
    if (nValues != nValueReferences) return hv_error(m, "fmi3SetFloat64", "nValues differs from nValueReferences (no arrays)");
    return hv_set_reals(m, "fmi3SetFloat64", valueReferences, nValueReferences, values, "Float64");
}

FMI3_Export fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                      size_t nValueReferences, fmi3Boolean values[], size_t nValues)
{
    hv_instance *m = (hv_instance *)instance;
    size_t k;
    (void)nValues;
    if (m == NULL) return fmi3Error;
    if (hv_check_booleans(m, "fmi3GetBoolean", valueReferences, nValueReferences) != fmi3OK) return fmi3Error;
    for (k = 0; k < nValueReferences; k++) values[k] = m->d.r[valueReferences[k]] != 0.0;
    return fmi3OK;
}

FMI3_Export fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                      size_t nValueReferences, const fmi3Boolean values[], size_t nValues)
{
    hv_instance *m = (hv_instance *)instance;
    size_t k;
    (void)nValues;
    if (m == NULL) return fmi3Error;
    if (hv_check_booleans(m, "fmi3SetBoolean", valueReferences, nValueReferences) != fmi3OK) return fmi3Error;
    for (k = 0; k < nValueReferences; k++) m->d.r[valueReferences[k]] = values[k] ? 1.0 : 0.0;
    return fmi3OK;
}

/* variable types this FMU has none of: any value reference is an error */
#define HV_NO_TYPE(fn, type, ctype, cnst)                                                                      \
    FMI3_Export fmi3Status fn(fmi3Instance instance, const fmi3ValueReference valueReferences[],             \
                              size_t nValueReferences, cnst ctype values[], size_t nValues)                  \
    {                                                                                                          \
        (void)values;                                                                                          \
        (void)nValues;                                                                                         \
        return hv_no_vars((hv_instance *)instance, #fn, valueReferences, nValueReferences, type);             \
    }
#define HV_EMPTY
HV_NO_TYPE(fmi3GetFloat32, "Float32", fmi3Float32, HV_EMPTY)
HV_NO_TYPE(fmi3GetInt8, "Int8", fmi3Int8, HV_EMPTY)
HV_NO_TYPE(fmi3GetUInt8, "UInt8", fmi3UInt8, HV_EMPTY)
HV_NO_TYPE(fmi3GetInt16, "Int16", fmi3Int16, HV_EMPTY)
HV_NO_TYPE(fmi3GetUInt16, "UInt16", fmi3UInt16, HV_EMPTY)
HV_NO_TYPE(fmi3GetInt32, "Int32", fmi3Int32, HV_EMPTY)
HV_NO_TYPE(fmi3GetUInt32, "UInt32", fmi3UInt32, HV_EMPTY)
HV_NO_TYPE(fmi3GetInt64, "Int64", fmi3Int64, HV_EMPTY)
HV_NO_TYPE(fmi3GetUInt64, "UInt64", fmi3UInt64, HV_EMPTY)
HV_NO_TYPE(fmi3GetString, "String", fmi3String, HV_EMPTY)
HV_NO_TYPE(fmi3SetFloat32, "Float32", fmi3Float32, const)
HV_NO_TYPE(fmi3SetInt8, "Int8", fmi3Int8, const)
HV_NO_TYPE(fmi3SetUInt8, "UInt8", fmi3UInt8, const)
HV_NO_TYPE(fmi3SetInt16, "Int16", fmi3Int16, const)
HV_NO_TYPE(fmi3SetUInt16, "UInt16", fmi3UInt16, const)
HV_NO_TYPE(fmi3SetInt32, "Int32", fmi3Int32, const)
HV_NO_TYPE(fmi3SetUInt32, "UInt32", fmi3UInt32, const)
HV_NO_TYPE(fmi3SetInt64, "Int64", fmi3Int64, const)
HV_NO_TYPE(fmi3SetUInt64, "UInt64", fmi3UInt64, const)
HV_NO_TYPE(fmi3SetString, "String", fmi3String, const)

FMI3_Export fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                     size_t nValueReferences, size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    (void)valueSizes;
    (void)values;
    (void)nValues;
    return hv_no_vars((hv_instance *)instance, "fmi3GetBinary", valueReferences, nValueReferences, "Binary");
}

FMI3_Export fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                     size_t nValueReferences, const size_t valueSizes[], const fmi3Binary values[],
                                     size_t nValues)
{
    (void)valueSizes;
    (void)values;
    (void)nValues;
    return hv_no_vars((hv_instance *)instance, "fmi3SetBinary", valueReferences, nValueReferences, "Binary");
}

FMI3_Export fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, fmi3Clock values[])
{
    (void)valueReferences;
    (void)nValueReferences;
    (void)values;
    return hv_unsupported(instance, "fmi3GetClock");
}

FMI3_Export fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Clock values[])
{
    (void)valueReferences;
    (void)nValueReferences;
    (void)values;
    return hv_unsupported(instance, "fmi3SetClock");
}

FMI3_Export fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                                           size_t *nDependencies)
{
    (void)valueReference;
    (void)nDependencies;
    return hv_unsupported(instance, "fmi3GetNumberOfVariableDependencies");
}

FMI3_Export fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                                   size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                                   size_t elementIndicesOfIndependents[],
                                                   fmi3DependencyKind dependencyKinds[], size_t nDependencies)
{
    (void)dependent;
    (void)elementIndicesOfDependent;
    (void)independents;
    (void)elementIndicesOfIndependents;
    (void)dependencyKinds;
    (void)nDependencies;
    return hv_unsupported(instance, "fmi3GetVariableDependencies");
}

FMI3_Export fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    return hv_get_state((hv_instance *)instance, "fmi3GetFMUState", FMUState);
}

FMI3_Export fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    return hv_set_state((hv_instance *)instance, "fmi3SetFMUState", FMUState);
}

FMI3_Export fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    (void)instance;
    hv_free_state(FMUState);
    return fmi3OK;
}

FMI3_Export fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    (void)FMUState;
    if (instance == NULL) return fmi3Error;
    *size = HV_SERIAL_SIZE;
    return fmi3OK;
}

FMI3_Export fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                             size_t size)
{
    return hv_serialize((hv_instance *)instance, "fmi3SerializeFMUState", FMUState, serializedState, size);
}

FMI3_Export fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                               fmi3FMUState *FMUState)
{
    return hv_deserialize((hv_instance *)instance, "fmi3DeserializeFMUState", serializedState, size, FMUState);
}

#define HV_DERIVATIVE(fn)                                                                                      \
    FMI3_Export fmi3Status fn(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,  \
                              const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],   \
                              size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)                  \
    {                                                                                                          \
        (void)unknowns;                                                                                        \
        (void)nUnknowns;                                                                                       \
        (void)knowns;                                                                                          \
        (void)nKnowns;                                                                                         \
        (void)seed;                                                                                            \
        (void)nSeed;                                                                                           \
        (void)sensitivity;                                                                                     \
        (void)nSensitivity;                                                                                    \
        return hv_unsupported(instance, #fn);                                                                  \
    }
HV_DERIVATIVE(fmi3GetDirectionalDerivative)
HV_DERIVATIVE(fmi3GetAdjointDerivative)

FMI3_Export fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    return hv_unsupported(instance, "fmi3EnterConfigurationMode");
}
FMI3_Export fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    return hv_unsupported(instance, "fmi3ExitConfigurationMode");
}

#define HV_CLOCK_FN(fn, args, voids)                                                                           \
    FMI3_Export fmi3Status fn args                                                                             \
    {                                                                                                          \
        voids;                                                                                                 \
        return hv_unsupported(instance, #fn);                                                                  \
    }
HV_CLOCK_FN(fmi3GetIntervalDecimal,
            (fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
             fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]),
            (void)valueReferences; (void)nValueReferences; (void)intervals; (void)qualifiers)
HV_CLOCK_FN(fmi3GetIntervalFraction,
            (fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
             fmi3UInt64 counters[], fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]),
            (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions; (void)qualifiers)
HV_CLOCK_FN(fmi3GetShiftDecimal,
            (fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
             fmi3Float64 shifts[]),
            (void)valueReferences; (void)nValueReferences; (void)shifts)
HV_CLOCK_FN(fmi3GetShiftFraction,
            (fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
             fmi3UInt64 counters[], fmi3UInt64 resolutions[]),
            (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions)
HV_CLOCK_FN(fmi3SetIntervalDecimal,
            (fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
             const fmi3Float64 intervals[]),
            (void)valueReferences; (void)nValueReferences; (void)intervals)
HV_CLOCK_FN(fmi3SetIntervalFraction,
            (fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
             const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]),
            (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions)
HV_CLOCK_FN(fmi3SetShiftDecimal,
            (fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
             const fmi3Float64 shifts[]),
            (void)valueReferences; (void)nValueReferences; (void)shifts)
HV_CLOCK_FN(fmi3SetShiftFraction,
            (fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
             const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]),
            (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions)
HV_CLOCK_FN(fmi3EvaluateDiscreteStates, (fmi3Instance instance), (void)0)
HV_CLOCK_FN(fmi3UpdateDiscreteStates,
            (fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate, fmi3Boolean *terminateSimulation,
             fmi3Boolean *nominalsOfContinuousStatesChanged, fmi3Boolean *valuesOfContinuousStatesChanged,
             fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime),
            (void)discreteStatesNeedUpdate; (void)terminateSimulation; (void)nominalsOfContinuousStatesChanged;
            (void)valuesOfContinuousStatesChanged; (void)nextEventTimeDefined; (void)nextEventTime)
/* model exchange */
HV_CLOCK_FN(fmi3EnterContinuousTimeMode, (fmi3Instance instance), (void)0)
HV_CLOCK_FN(fmi3CompletedIntegratorStep,
            (fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *enterEventMode,
             fmi3Boolean *terminateSimulation),
            (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation)
HV_CLOCK_FN(fmi3SetTime, (fmi3Instance instance, fmi3Float64 time), (void)time)
HV_CLOCK_FN(fmi3SetContinuousStates, (fmi3Instance instance, const fmi3Float64 continuousStates[], size_t n),
            (void)continuousStates; (void)n)
HV_CLOCK_FN(fmi3GetContinuousStateDerivatives, (fmi3Instance instance, fmi3Float64 derivatives[], size_t n),
            (void)derivatives; (void)n)
HV_CLOCK_FN(fmi3GetEventIndicators, (fmi3Instance instance, fmi3Float64 eventIndicators[], size_t n),
            (void)eventIndicators; (void)n)
HV_CLOCK_FN(fmi3GetContinuousStates, (fmi3Instance instance, fmi3Float64 continuousStates[], size_t n),
            (void)continuousStates; (void)n)
HV_CLOCK_FN(fmi3GetNominalsOfContinuousStates, (fmi3Instance instance, fmi3Float64 nominals[], size_t n),
            (void)nominals; (void)n)
HV_CLOCK_FN(fmi3GetNumberOfEventIndicators, (fmi3Instance instance, size_t *n), (void)n)
HV_CLOCK_FN(fmi3GetNumberOfContinuousStates, (fmi3Instance instance, size_t *n), (void)n)
HV_CLOCK_FN(fmi3GetOutputDerivatives,
            (fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
             const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues),
            (void)valueReferences; (void)nValueReferences; (void)orders; (void)values; (void)nValues)
/* scheduled execution */
HV_CLOCK_FN(fmi3ActivateModelPartition,
            (fmi3Instance instance, fmi3ValueReference clockReference, fmi3Float64 activationTime),
            (void)clockReference; (void)activationTime)

FMI3_Export fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    hv_instance *m = (hv_instance *)instance;
    if (m == NULL) return fmi3Error;
    m->phase = PH_STEPPING;
    return fmi3OK;
}

FMI3_Export fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                                  fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                  fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                                  fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    hv_instance *m = (hv_instance *)instance;
    fmi3Status status;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (m == NULL) return fmi3Error;
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    status = hv_step(m, "fmi3DoStep", currentCommunicationPoint, communicationStepSize);
    if (lastSuccessfulTime && m->phase == PH_STEPPING) *lastSuccessfulTime = m->d.time;
    return status;
}

/* FMI 2.0 co-simulation interface of a hevsim native cell/module FMU (generated sources:
 * model_data.h; version-independent part: hevsim_fmi.h; model: hevsim_model.h; kernel:
 * hevsim_kernel.h). Build, for example:
 *   cc -std=c99 -O2 -shared -fPIC -I<FMI 2.0 headers> fmi2_model.c -lm -o <modelIdentifier>.so
 */
#include <string.h>
#include "fmi2Functions.h"

#define HV_STATUS fmi2Status
#define HV_OK fmi2OK
#define HV_ERROR fmi2Error
#define HV_VR fmi2ValueReference
#define HV_SERIAL_MAGIC "hevsim-fmu-state-1"
typedef fmi2CallbackFunctions hv_callbacks;
#include "hevsim_fmi.h"

static void hv_emit(const hv_instance *m, fmi2Status status, const char *category, const char *text)
{
    char buf[2048];
    size_t i, k = 0;
    if (m->cb.logger == NULL) return;
    /* the message is the logger's format string: a literal percent sign is doubled */
    for (i = 0; text[i] != '\0' && k + 2 < sizeof(buf); i++) {
        if (text[i] == '%') buf[k++] = '%';
        buf[k++] = text[i];
    }
    buf[k] = '\0';
    m->cb.logger(m->cb.componentEnvironment, m->name, status, category, buf);
}

FMI2_Export const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
FMI2_Export const char *fmi2GetVersion(void) { return fmi2Version; }

FMI2_Export fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                                           const fmi2String categories[])
{
    (void)nCategories;
    (void)categories;
    if (c == NULL) return fmi2Error;
    ((hv_instance *)c)->logging = loggingOn;
    return fmi2OK;
}

FMI2_Export fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                          fmi2String fmuResourceLocation,
                                          const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                                          fmi2Boolean loggingOn)
{
    hv_instance *m;
    (void)fmuResourceLocation;
    (void)visible;
    if (functions == NULL) return NULL;
    m = hv_new(instanceName, *functions, loggingOn);
    if (m == NULL) return NULL;
    if (fmuType != fmi2CoSimulation) {
        hv_error(m, "fmi2Instantiate", "this FMU supports co-simulation only (fmuType fmi2CoSimulation)");
        hv_free(m);
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, MODEL_GUID) != 0) {
        hv_log(m, fmi2Error, "logStatusError", "fmi2Instantiate: GUID '%s' does not match this FMU's '%s'",
               fmuGUID ? fmuGUID : "(null)", MODEL_GUID);
        hv_free(m);
        return NULL;
    }
    hv_reset(m);
    return m;
}

FMI2_Export void fmi2FreeInstance(fmi2Component c) { hv_free((hv_instance *)c); }

FMI2_Export fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                                           fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    hv_instance *m = (hv_instance *)c;
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    if (m == NULL) return fmi2Error;
    m->d.time = startTime;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    if (c == NULL) return fmi2Error;
    ((hv_instance *)c)->phase = PH_INITIALIZATION;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    hv_instance *m = (hv_instance *)c;
    if (m == NULL) return fmi2Error;
    hv_init(&m->d);
    m->phase = PH_STEPPING;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2Terminate(fmi2Component c)
{
    if (c == NULL) return fmi2Error;
    ((hv_instance *)c)->phase = PH_TERMINATED;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2Reset(fmi2Component c)
{
    if (c == NULL) return fmi2Error;
    hv_reset((hv_instance *)c);
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    return hv_get_reals((hv_instance *)c, "fmi2GetReal", vr, nvr, value, "Real");
}

FMI2_Export fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      fmi2Integer value[])
{
    (void)value;
    return hv_no_vars((hv_instance *)c, "fmi2GetInteger", vr, nvr, "Integer");
}

FMI2_Export fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      fmi2Boolean value[])
{
    hv_instance *m = (hv_instance *)c;
    size_t k;
    if (m == NULL) return fmi2Error;
    if (hv_check_booleans(m, "fmi2GetBoolean", vr, nvr) != fmi2OK) return fmi2Error;
    for (k = 0; k < nvr; k++) value[k] = m->d.r[vr[k]] != 0.0 ? fmi2True : fmi2False;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                     fmi2String value[])
{
    (void)value;
    return hv_no_vars((hv_instance *)c, "fmi2GetString", vr, nvr, "String");
}

FMI2_Export fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                   const fmi2Real value[])
{
    return hv_set_reals((hv_instance *)c, "fmi2SetReal", vr, nvr, value, "Real");
}

FMI2_Export fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      const fmi2Integer value[])
{
    (void)value;
    return hv_no_vars((hv_instance *)c, "fmi2SetInteger", vr, nvr, "Integer");
}

FMI2_Export fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      const fmi2Boolean value[])
{
    hv_instance *m = (hv_instance *)c;
    size_t k;
    if (m == NULL) return fmi2Error;
    if (hv_check_booleans(m, "fmi2SetBoolean", vr, nvr) != fmi2OK) return fmi2Error;
    for (k = 0; k < nvr; k++) m->d.r[vr[k]] = value[k] ? 1.0 : 0.0;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                     const fmi2String value[])
{
    (void)value;
    return hv_no_vars((hv_instance *)c, "fmi2SetString", vr, nvr, "String");
}

FMI2_Export fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    return hv_get_state((hv_instance *)c, "fmi2GetFMUstate", FMUstate);
}

FMI2_Export fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    return hv_set_state((hv_instance *)c, "fmi2SetFMUstate", FMUstate);
}

FMI2_Export fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    (void)c;
    hv_free_state(FMUstate);
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    (void)FMUstate;
    if (c == NULL) return fmi2Error;
    *size = HV_SERIAL_SIZE;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[],
                                             size_t size)
{
    return hv_serialize((hv_instance *)c, "fmi2SerializeFMUstate", FMUstate, serializedState, size);
}

FMI2_Export fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                               fmi2FMUstate *FMUstate)
{
    return hv_deserialize((hv_instance *)c, "fmi2DeSerializeFMUstate", serializedState, size, FMUstate);
}

FMI2_Export fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                                    size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                                    size_t nKnown, const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown_ref;
    (void)nUnknown;
    (void)vKnown_ref;
    (void)nKnown;
    (void)dvKnown;
    (void)dvUnknown;
    return hv_error((hv_instance *)c, "fmi2GetDirectionalDerivative", "not supported (providesDirectionalDerivative=false)");
}

FMI2_Export fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                                   const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return hv_error((hv_instance *)c, "fmi2SetRealInputDerivatives", "not supported (canInterpolateInputs=false)");
}

FMI2_Export fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                                    const fmi2Integer order[], fmi2Real value[])
{
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return hv_error((hv_instance *)c, "fmi2GetRealOutputDerivatives", "not supported (maxOutputDerivativeOrder=0)");
}

FMI2_Export fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                                  fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    if (c == NULL) return fmi2Error;
    return hv_step((hv_instance *)c, "fmi2DoStep", currentCommunicationPoint, communicationStepSize);
}

FMI2_Export fmi2Status fmi2CancelStep(fmi2Component c)
{
    return hv_error((hv_instance *)c, "fmi2CancelStep", "the FMU steps synchronously; there is no step to cancel");
}

FMI2_Export fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s;
    if (c == NULL) return fmi2Error;
    *value = fmi2OK;
    return fmi2Discard;
}

FMI2_Export fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    hv_instance *m = (hv_instance *)c;
    if (m == NULL) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *value = m->d.time;
        return fmi2OK;
    }
    return fmi2Discard;
}

FMI2_Export fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)c;
    (void)s;
    (void)value;
    return fmi2Discard;
}

FMI2_Export fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    (void)c;
    (void)s;
    (void)value;
    return fmi2Discard;
}

FMI2_Export fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)c;
    (void)s;
    (void)value;
    return fmi2Discard;
}

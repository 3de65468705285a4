/* FMI 2.0 co-simulation interface of a hevsim native cell/module FMU (generated sources:
 * model_data.h; model: hevsim_model.h; kernel: hevsim_kernel.h). Build, for example:
 *   cc -std=c99 -O2 -shared -fPIC -I<FMI 2.0 headers> fmi2_model.c -lm -o <modelIdentifier>.so
 */
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"
#include "hevsim_model.h"

typedef enum { PH_INSTANTIATED, PH_INITIALIZATION, PH_STEPPING, PH_TERMINATED } hv_phase;

typedef struct {
    hv_data d;
    hv_phase phase;
    char *name;
    fmi2CallbackFunctions cb;
    fmi2Boolean logging;
} hv_instance;

#define HV_SERIAL_MAGIC "hevsim-fmu-state-1"

static void hv_log(hv_instance *m, fmi2Status status, const char *category, const char *fmt, ...)
{
    char text[1024], buf[2048];
    size_t i, k = 0;
    va_list ap;
    if (m == NULL || m->cb.logger == NULL) return;
    if (status == fmi2OK && !m->logging) return;
    va_start(ap, fmt);
    vsnprintf(text, sizeof(text), fmt, ap);
    va_end(ap);
    /* the message is the logger's format string: a literal percent sign is doubled */
    for (i = 0; text[i] != '\0' && k + 2 < sizeof(buf); i++) {
        if (text[i] == '%') buf[k++] = '%';
        buf[k++] = text[i];
    }
    buf[k] = '\0';
    m->cb.logger(m->cb.componentEnvironment, m->name, status, category, buf);
}

static fmi2Status hv_error(hv_instance *m, const char *fn, const char *msg)
{
    hv_log(m, fmi2Error, "logStatusError", "%s: %s", fn, msg);
    return fmi2Error;
}

static fmi2Status hv_bad_vr(hv_instance *m, const char *fn, fmi2ValueReference vr, const char *type)
{
    char msg[256];
    if (vr < N_VR)
        snprintf(msg, sizeof(msg), "value reference %u is '%s', not a %s variable", (unsigned)vr, VAR_NAME[vr], type);
    else
        snprintf(msg, sizeof(msg), "value reference %u is not a variable of this FMU (0..%d)", (unsigned)vr, N_VR - 1);
    return hv_error(m, fn, msg);
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
    m = (hv_instance *)calloc(1, sizeof(hv_instance));
    if (m == NULL) return NULL;
    m->cb = *functions;
    m->logging = loggingOn;
    m->name = (char *)malloc(strlen(instanceName ? instanceName : "") + 1);
    if (m->name == NULL) {
        free(m);
        return NULL;
    }
    strcpy(m->name, instanceName ? instanceName : "");
    if (fmuType != fmi2CoSimulation) {
        hv_error(m, "fmi2Instantiate", "this FMU supports co-simulation only (fmuType fmi2CoSimulation)");
        free(m->name);
        free(m);
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, MODEL_GUID) != 0) {
        hv_log(m, fmi2Error, "logStatusError", "fmi2Instantiate: GUID '%s' does not match this FMU's '%s'",
               fmuGUID ? fmuGUID : "(null)", MODEL_GUID);
        free(m->name);
        free(m);
        return NULL;
    }
    hv_start(&m->d);
    hv_init(&m->d);
    m->phase = PH_INSTANTIATED;
    return m;
}

FMI2_Export void fmi2FreeInstance(fmi2Component c)
{
    hv_instance *m = (hv_instance *)c;
    if (m == NULL) return;
    free(m->name);
    free(m);
}

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
    hv_instance *m = (hv_instance *)c;
    if (m == NULL) return fmi2Error;
    hv_start(&m->d);
    hv_init(&m->d);
    m->phase = PH_INSTANTIATED;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    hv_instance *m = (hv_instance *)c;
    size_t k;
    if (m == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= N_VR || VAR_KIND[vr[k]] == K_BOOLEAN) return hv_bad_vr(m, "fmi2GetReal", vr[k], "Real");
        value[k] = m->d.r[vr[k]];
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      fmi2Integer value[])
{
    (void)value;
    if (c == NULL) return fmi2Error;
    return nvr == 0 ? fmi2OK : hv_bad_vr((hv_instance *)c, "fmi2GetInteger", vr[0], "Integer");
}

FMI2_Export fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      fmi2Boolean value[])
{
    hv_instance *m = (hv_instance *)c;
    size_t k;
    if (m == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= N_VR || VAR_KIND[vr[k]] != K_BOOLEAN) return hv_bad_vr(m, "fmi2GetBoolean", vr[k], "Boolean");
        value[k] = m->d.r[vr[k]] != 0.0 ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                     fmi2String value[])
{
    (void)value;
    if (c == NULL) return fmi2Error;
    return nvr == 0 ? fmi2OK : hv_bad_vr((hv_instance *)c, "fmi2GetString", vr[0], "String");
}

FMI2_Export fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                   const fmi2Real value[])
{
    hv_instance *m = (hv_instance *)c;
    char msg[512];
    size_t k;
    if (m == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= N_VR || VAR_KIND[vr[k]] == K_BOOLEAN) return hv_bad_vr(m, "fmi2SetReal", vr[k], "Real");
        if (hv_check_set((int)vr[k], value[k], msg, sizeof(msg))) return hv_error(m, "fmi2SetReal", msg);
    }
    for (k = 0; k < nvr; k++) m->d.r[vr[k]] = value[k];
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      const fmi2Integer value[])
{
    (void)value;
    if (c == NULL) return fmi2Error;
    return nvr == 0 ? fmi2OK : hv_bad_vr((hv_instance *)c, "fmi2SetInteger", vr[0], "Integer");
}

FMI2_Export fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      const fmi2Boolean value[])
{
    hv_instance *m = (hv_instance *)c;
    size_t k;
    if (m == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++)
        if (vr[k] >= N_VR || VAR_KIND[vr[k]] != K_BOOLEAN) return hv_bad_vr(m, "fmi2SetBoolean", vr[k], "Boolean");
    for (k = 0; k < nvr; k++) m->d.r[vr[k]] = value[k] ? 1.0 : 0.0;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                     const fmi2String value[])
{
    (void)value;
    if (c == NULL) return fmi2Error;
    return nvr == 0 ? fmi2OK : hv_bad_vr((hv_instance *)c, "fmi2SetString", vr[0], "String");
}

/* FMU state: a copy of hv_data (and the phase) */
typedef struct {
    hv_data d;
    double phase; /* a hv_phase; a double so that the struct has no padding bytes */
} hv_saved;

FMI2_Export fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    hv_instance *m = (hv_instance *)c;
    hv_saved *s;
    if (m == NULL || FMUstate == NULL) return fmi2Error;
    s = (hv_saved *)*FMUstate;
    if (s == NULL) {
        s = (hv_saved *)malloc(sizeof(hv_saved));
        if (s == NULL) return hv_error(m, "fmi2GetFMUstate", "out of memory");
        *FMUstate = s;
    }
    s->d = m->d;
    s->phase = (double)m->phase;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    hv_instance *m = (hv_instance *)c;
    if (m == NULL) return fmi2Error;
    if (FMUstate == NULL) return hv_error(m, "fmi2SetFMUstate", "the FMU state is NULL");
    m->d = ((hv_saved *)FMUstate)->d;
    m->phase = (hv_phase)((hv_saved *)FMUstate)->phase;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    (void)c;
    if (FMUstate != NULL) {
        free(*FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

#define HV_SERIAL_SIZE (sizeof(HV_SERIAL_MAGIC) + sizeof(MODEL_GUID) + sizeof(hv_saved))

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
    hv_instance *m = (hv_instance *)c;
    if (m == NULL) return fmi2Error;
    if (FMUstate == NULL || size < HV_SERIAL_SIZE)
        return hv_error(m, "fmi2SerializeFMUstate", "no FMU state, or the buffer is too small");
    memcpy(serializedState, HV_SERIAL_MAGIC, sizeof(HV_SERIAL_MAGIC));
    memcpy(serializedState + sizeof(HV_SERIAL_MAGIC), MODEL_GUID, sizeof(MODEL_GUID));
    memcpy(serializedState + sizeof(HV_SERIAL_MAGIC) + sizeof(MODEL_GUID), FMUstate, sizeof(hv_saved));
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                               fmi2FMUstate *FMUstate)
{
    hv_instance *m = (hv_instance *)c;
    hv_saved *s;
    if (m == NULL || FMUstate == NULL) return fmi2Error;
    if (size != HV_SERIAL_SIZE || memcmp(serializedState, HV_SERIAL_MAGIC, sizeof(HV_SERIAL_MAGIC)) != 0 ||
        memcmp(serializedState + sizeof(HV_SERIAL_MAGIC), MODEL_GUID, sizeof(MODEL_GUID)) != 0)
        return hv_error(m, "fmi2DeSerializeFMUstate", "the serialized state was not made by this FMU");
    s = (hv_saved *)*FMUstate;
    if (s == NULL) {
        s = (hv_saved *)malloc(sizeof(hv_saved));
        if (s == NULL) return hv_error(m, "fmi2DeSerializeFMUstate", "out of memory");
        *FMUstate = s;
    }
    memcpy(s, serializedState + sizeof(HV_SERIAL_MAGIC) + sizeof(MODEL_GUID), sizeof(hv_saved));
    return fmi2OK;
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
    hv_instance *m = (hv_instance *)c;
    char msg[1024];
    (void)noSetFMUStatePriorToCurrentPoint;
    if (m == NULL) return fmi2Error;
    if (m->phase != PH_STEPPING) return hv_error(m, "fmi2DoStep", "called outside step mode (exit initialization mode first)");
    if (hv_do_step(&m->d, currentCommunicationPoint, communicationStepSize, msg, sizeof(msg)))
        return hv_error(m, "fmi2DoStep", msg);
    return fmi2OK;
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

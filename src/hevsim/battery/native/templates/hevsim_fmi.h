/* The part of hevsim's native FMI 2.0 and FMI 3.0 wrappers that does not depend on the FMI
 * version: the instance (model data, phase, name, logging), the logger messages, the value
 * reference checks of the get/set functions, the communication step and the FMU state (copy,
 * serialisation). The including wrapper defines first:
 *   HV_STATUS, HV_OK, HV_ERROR  its status type and the values for success and error,
 *   HV_VR                       its value reference type,
 *   HV_SERIAL_MAGIC             the string that starts a serialized FMU state,
 *   hv_callbacks                the type of its logger callback(s),
 * and after including it defines hv_emit (hand one message to the logger callback).
 */
#ifndef HEVSIM_FMI_H
#define HEVSIM_FMI_H

#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include "model_data.h"
#ifdef HV_THERMAL_ROM
#include "hevsim_rom.h" /* the module thermal ROM */
#else
#include "hevsim_model.h" /* the cell or module */
#endif

typedef enum { PH_INSTANTIATED, PH_INITIALIZATION, PH_STEPPING, PH_TERMINATED } hv_phase;

typedef struct {
    hv_data d;
    hv_cache cache; /* data the model derives from d (not part of the FMU state) */
    hv_phase phase;
    char *name;
    hv_callbacks cb;
    int logging;
} hv_instance;

/* FMU state: a copy of hv_data (and the phase) */
typedef struct {
    hv_data d;
    double phase; /* a hv_phase; a double so that the struct has no padding bytes */
} hv_saved;

#define HV_SERIAL_SIZE (sizeof(HV_SERIAL_MAGIC) + sizeof(MODEL_GUID) + sizeof(hv_saved))
#define HV_SERIAL_DATA (sizeof(HV_SERIAL_MAGIC) + sizeof(MODEL_GUID)) /* offset of the hv_saved bytes */

/* hand the message `text` to the instance's logger (defined by the wrapper) */
static void hv_emit(const hv_instance *m, HV_STATUS status, const char *category, const char *text);

static void hv_log(hv_instance *m, HV_STATUS status, const char *category, const char *fmt, ...)
{
    char text[1024];
    va_list ap;
    if (m == NULL) return;
    if (status == HV_OK && !m->logging) return;
    va_start(ap, fmt);
    vsnprintf(text, sizeof(text), fmt, ap);
    va_end(ap);
    hv_emit(m, status, category, text);
}

static HV_STATUS hv_error(hv_instance *m, const char *fn, const char *msg)
{
    hv_log(m, HV_ERROR, "logStatusError", "%s: %s", fn, msg);
    return HV_ERROR;
}

static HV_STATUS hv_bad_vr(hv_instance *m, const char *fn, HV_VR vr, const char *type)
{
    char msg[256];
    if (vr < N_VR)
        snprintf(msg, sizeof(msg), "value reference %u is '%s', not a %s variable", (unsigned)vr, VAR_NAME[vr], type);
    else
        snprintf(msg, sizeof(msg), "value reference %u is not a variable of this FMU (0..%d)", (unsigned)vr, N_VR - 1);
    return hv_error(m, fn, msg);
}

/* start values and the initial state: a new or reset instance */
static void hv_reset(hv_instance *m)
{
    hv_start(&m->d);
    hv_init(&m->d);
    m->phase = PH_INSTANTIATED;
}

/* a new instance named `name` (NULL: out of memory); the wrapper checks its arguments next */
static hv_instance *hv_new(const char *name, hv_callbacks cb, int logging)
{
    hv_instance *m = (hv_instance *)calloc(1, sizeof(hv_instance));
    if (m == NULL) return NULL;
    m->cb = cb;
    m->logging = logging;
    m->name = (char *)malloc(strlen(name ? name : "") + 1);
    if (m->name == NULL) {
        free(m);
        return NULL;
    }
    strcpy(m->name, name ? name : "");
    return m;
}

static void hv_free(hv_instance *m)
{
    if (m == NULL) return;
    free(m->name);
    free(m);
}

/* HV_OK if every vr[k] is a Boolean variable */
static HV_STATUS hv_check_booleans(hv_instance *m, const char *fn, const HV_VR vr[], size_t nvr)
{
    size_t k;
    for (k = 0; k < nvr; k++)
        if (vr[k] >= N_VR || VAR_KIND[vr[k]] != K_BOOLEAN) return hv_bad_vr(m, fn, vr[k], "Boolean");
    return HV_OK;
}

static HV_STATUS hv_get_reals(hv_instance *m, const char *fn, const HV_VR vr[], size_t nvr, double value[],
                              const char *type)
{
    size_t k;
    if (m == NULL) return HV_ERROR;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= N_VR || VAR_KIND[vr[k]] == K_BOOLEAN) return hv_bad_vr(m, fn, vr[k], type);
        value[k] = m->d.r[vr[k]];
    }
    return HV_OK;
}

/* 0 if `value` may be given to variable vr (not an output, constant or the independent variable;
 * finite; a parameter or input inside its range), else 1 with a message */
static int hv_check_set(int vr, double value, char *msg, size_t n)
{
    int kind = VAR_KIND[vr];
    if (kind == K_OUTPUT || kind == K_CONSTANT || kind == K_INDEPENDENT) {
        snprintf(msg, n, "variable '%s' (value reference %d) is %s and cannot be set (value %.17g refused)",
                 VAR_NAME[vr], vr,
                 kind == K_OUTPUT ? "an output" : kind == K_CONSTANT ? "a constant" : "the independent variable",
                 value);
        return 1;
    }
    if (!isfinite(value)) {
        snprintf(msg, n, "%s = %g is not a finite number", VAR_NAME[vr], value);
        return 1;
    }
    if ((kind == K_PARAMETER || kind == K_INPUT) &&
        (value < VAR_MIN[vr] || value > VAR_MAX[vr] || (VAR_MIN_OPEN[vr] && value <= VAR_MIN[vr]))) {
        snprintf(msg, n, "%s = %.17g is outside its range %s", VAR_NAME[vr], value, VAR_RANGE[vr]);
        return 1;
    }
    return 0;
}

/* all values are checked (hv_check_set) before any is set */
static HV_STATUS hv_set_reals(hv_instance *m, const char *fn, const HV_VR vr[], size_t nvr, const double value[],
                              const char *type)
{
    char msg[512];
    size_t k;
    if (m == NULL) return HV_ERROR;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= N_VR || VAR_KIND[vr[k]] == K_BOOLEAN) return hv_bad_vr(m, fn, vr[k], type);
        if (hv_check_set((int)vr[k], value[k], msg, sizeof(msg))) return hv_error(m, fn, msg);
    }
    for (k = 0; k < nvr; k++) m->d.r[vr[k]] = value[k];
    return HV_OK;
}

/* get/set of a variable type this FMU has none of: any value reference is an error */
static HV_STATUS hv_no_vars(hv_instance *m, const char *fn, const HV_VR vr[], size_t nvr, const char *type)
{
    if (m == NULL) return HV_ERROR;
    return nvr == 0 ? HV_OK : hv_bad_vr(m, fn, vr[0], type);
}

/* one communication step (step mode only) */
static HV_STATUS hv_step(hv_instance *m, const char *fn, double t, double dt)
{
    char msg[1024];
    if (m->phase != PH_STEPPING) return hv_error(m, fn, "called outside step mode (exit initialization mode first)");
    if (hv_do_step(&m->d, &m->cache, t, dt, msg, sizeof(msg))) return hv_error(m, fn, msg);
    return HV_OK;
}

/* the FMU state *state (allocated if NULL) := the instance's */
static HV_STATUS hv_get_state(hv_instance *m, const char *fn, void **state)
{
    hv_saved *s;
    if (m == NULL || state == NULL) return HV_ERROR;
    s = (hv_saved *)*state;
    if (s == NULL) {
        s = (hv_saved *)malloc(sizeof(hv_saved));
        if (s == NULL) return hv_error(m, fn, "out of memory");
        *state = s;
    }
    s->d = m->d;
    s->phase = (double)m->phase;
    return HV_OK;
}

static HV_STATUS hv_set_state(hv_instance *m, const char *fn, const void *state)
{
    if (m == NULL) return HV_ERROR;
    if (state == NULL) return hv_error(m, fn, "the FMU state is NULL");
    m->d = ((const hv_saved *)state)->d;
    m->phase = (hv_phase)((const hv_saved *)state)->phase;
    return HV_OK;
}

static void hv_free_state(void **state)
{
    if (state != NULL) {
        free(*state);
        *state = NULL;
    }
}

/* serialized state: HV_SERIAL_MAGIC, MODEL_GUID (both with their NUL), the hv_saved bytes */
static HV_STATUS hv_serialize(hv_instance *m, const char *fn, const void *state, void *buf, size_t size)
{
    unsigned char *b = (unsigned char *)buf;
    if (m == NULL) return HV_ERROR;
    if (state == NULL || size < HV_SERIAL_SIZE) return hv_error(m, fn, "no FMU state, or the buffer is too small");
    memcpy(b, HV_SERIAL_MAGIC, sizeof(HV_SERIAL_MAGIC));
    memcpy(b + sizeof(HV_SERIAL_MAGIC), MODEL_GUID, sizeof(MODEL_GUID));
    memcpy(b + HV_SERIAL_DATA, state, sizeof(hv_saved));
    return HV_OK;
}

static HV_STATUS hv_deserialize(hv_instance *m, const char *fn, const void *buf, size_t size, void **state)
{
    const unsigned char *b = (const unsigned char *)buf;
    hv_saved *s;
    if (m == NULL || state == NULL) return HV_ERROR;
    if (size != HV_SERIAL_SIZE || memcmp(b, HV_SERIAL_MAGIC, sizeof(HV_SERIAL_MAGIC)) != 0 ||
        memcmp(b + sizeof(HV_SERIAL_MAGIC), MODEL_GUID, sizeof(MODEL_GUID)) != 0)
        return hv_error(m, fn, "the serialized state was not made by this FMU");
    s = (hv_saved *)*state;
    if (s == NULL) {
        s = (hv_saved *)malloc(sizeof(hv_saved));
        if (s == NULL) return hv_error(m, fn, "out of memory");
        *state = s;
    }
    memcpy(s, b + HV_SERIAL_DATA, sizeof(hv_saved));
    return HV_OK;
}

#endif

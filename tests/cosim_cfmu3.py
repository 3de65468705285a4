# ruff: noqa: E501 (C source and XML)
"""A small FMI 3.0 co-simulation FMU written in C and compiled in the test with the system
compiler against FMPy's headers (``fmpy/c-code/fmi3Functions.h``): a feedthrough of every
FMI 3.0 scalar type, which pythonfmu3 cannot produce (it writes Float64, Int32, Boolean and
String only).

For each type ``T`` of :data:`TYPES` (index ``i`` from 1) the FMU has a parameter ``p_T``
(value reference ``10 i + 1``), an input ``u_T`` (``10 i + 2``) and an output ``y_T``
(``10 i + 3``, direct feedthrough of ``u_T``):

* numbers (Float32 .. UInt64, Enumeration): ``y = u + p`` in the type's own C arithmetic
  (Float32: single-precision sum; integers: in range for the values the tests use, no
  wrap-around relied upon);
* Boolean: ``y = u != p`` (exclusive or);
* String: ``y = u`` followed by ``p`` (255 bytes at most);
* Binary: ``y = u`` followed by ``p`` (64 bytes at most each).

Plus the Float32 array input ``ua`` [201] and output ``ya`` [202] (``<Dimension start="3"/>``):
``ya[k] = ua[k] + k * p_Float32`` (k = 1, 2, 3; single precision), and ``steps`` [203], a UInt64 output counting the steps taken
(starts at ``p_UInt64``, so it can start above 2**53).

Calls the model does not support (model exchange, scheduled execution, clocks, FMU state,
derivatives, configuration mode) are exported and return ``fmi3Error`` (``NULL`` for the
other instantiate functions): FMPy's ``FMU3Slave`` loads every ``fmi3`` symbol.
``canGetAndSetFMUState="false"``.
"""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

TYPES = (
    "Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64",
    "Boolean", "String", "Enumeration", "Binary",
)  # fmt: skip
"""The variable types of the feedthrough, in value-reference order (index 1 ..)."""

NUMERIC = TYPES[:10]

C_SOURCE = r"""
#include <stdlib.h>
#include <string.h>
#include <stdio.h>
#include "fmi3Functions.h"

typedef struct {
    fmi3Float32 Float32_[3]; fmi3Float64 Float64_[3];
    fmi3Int8 Int8_[3]; fmi3UInt8 UInt8_[3]; fmi3Int16 Int16_[3]; fmi3UInt16 UInt16_[3];
    fmi3Int32 Int32_[3]; fmi3UInt32 UInt32_[3];
    fmi3Int64 Int64_[6];  /* Int64 0..2, Enumeration 3..5 */
    fmi3UInt64 UInt64_[4];  /* UInt64 0..2, steps 3 */
    fmi3Boolean Boolean_[3];
    char String_[3][520];
    fmi3Byte Binary_[3][130]; size_t blen[3];
    fmi3Float32 ua[3], ya[3];
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    char name[64];
} M;

static void update(M *m) {
    m->Float32_[2] = m->Float32_[1] + m->Float32_[0];
    m->Float64_[2] = m->Float64_[1] + m->Float64_[0];
    m->Int8_[2] = (fmi3Int8)(m->Int8_[1] + m->Int8_[0]);
    m->UInt8_[2] = (fmi3UInt8)(m->UInt8_[1] + m->UInt8_[0]);
    m->Int16_[2] = (fmi3Int16)(m->Int16_[1] + m->Int16_[0]);
    m->UInt16_[2] = (fmi3UInt16)(m->UInt16_[1] + m->UInt16_[0]);
    m->Int32_[2] = m->Int32_[1] + m->Int32_[0];
    m->UInt32_[2] = m->UInt32_[1] + m->UInt32_[0];
    m->Int64_[2] = m->Int64_[1] + m->Int64_[0];
    m->Int64_[5] = m->Int64_[4] + m->Int64_[3];
    m->UInt64_[2] = m->UInt64_[1] + m->UInt64_[0];
    m->Boolean_[2] = m->Boolean_[1] != m->Boolean_[0];
    snprintf(m->String_[2], sizeof m->String_[2], "%.255s%.255s", m->String_[1], m->String_[0]);
    memcpy(m->Binary_[2], m->Binary_[1], m->blen[1]);
    memcpy(m->Binary_[2] + m->blen[1], m->Binary_[0], m->blen[0]);
    m->blen[2] = m->blen[1] + m->blen[0];
    for (int k = 0; k < 3; k++) m->ya[k] = m->ua[k] + (fmi3Float32)(k + 1) * m->Float32_[0];
}

static fmi3Status bad(M *m, const char *call, fmi3ValueReference vr) {
    if (m->log) m->log(m->env, fmi3Error, "error", call);
    (void)vr;
    return fmi3Error;
}

/* slot of value reference vr in the type with index idx (1-based): 0 parameter, 1 input,
   2 output; -1 another type; writable: parameters and inputs only */
static int slot(fmi3ValueReference vr, int idx, int set) {
    if ((int)(vr / 10) != idx) return -1;
    int k = (int)(vr % 10) - 1;
    if (k < 0 || k > (set ? 1 : 2)) return -1;
    return k;
}

#define ACCESS(T, IDX)                                                                                    \
fmi3Status fmi3Get##T(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3##T v[], size_t nv) { \
    M *m = c; update(m); if (nv != nvr) return bad(m, "fmi3Get" #T ": nValues", 0);                       \
    for (size_t k = 0; k < nvr; k++) {                                                                    \
        int s = slot(vr[k], IDX, 0); if (s < 0) return bad(m, "fmi3Get" #T ": value reference", vr[k]);    \
        v[k] = m->T##_[s]; }                                                                              \
    return fmi3OK; }                                                                                      \
fmi3Status fmi3Set##T(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3##T v[], size_t nv) { \
    M *m = c; if (nv != nvr) return bad(m, "fmi3Set" #T ": nValues", 0);                                  \
    for (size_t k = 0; k < nvr; k++) {                                                                    \
        int s = slot(vr[k], IDX, 1); if (s < 0) return bad(m, "fmi3Set" #T ": value reference", vr[k]);    \
        m->T##_[s] = v[k]; }                                                                              \
    return fmi3OK; }

ACCESS(Float64, 2)
ACCESS(Int8, 3)
ACCESS(UInt8, 4)
ACCESS(Int16, 5)
ACCESS(UInt16, 6)
ACCESS(Int32, 7)
ACCESS(UInt32, 8)
ACCESS(Boolean, 11)

fmi3Status fmi3GetFloat32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float32 v[], size_t nv) {
    M *m = c; update(m); size_t j = 0;
    for (size_t k = 0; k < nvr; k++) {
        int s = slot(vr[k], 1, 0);
        if (s >= 0 && j < nv) v[j++] = m->Float32_[s];
        else if ((vr[k] == 201 || vr[k] == 202) && j + 3 <= nv) {
            for (int i = 0; i < 3; i++) v[j++] = vr[k] == 201 ? m->ua[i] : m->ya[i]; }
        else return bad(m, "fmi3GetFloat32: value reference", vr[k]);
    }
    return j == nv ? fmi3OK : bad(m, "fmi3GetFloat32: nValues", 0); }
fmi3Status fmi3SetFloat32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float32 v[], size_t nv) {
    M *m = c; size_t j = 0;
    for (size_t k = 0; k < nvr; k++) {
        int s = slot(vr[k], 1, 1);
        if (s >= 0 && j < nv) m->Float32_[s] = v[j++];
        else if (vr[k] == 201 && j + 3 <= nv) { for (int i = 0; i < 3; i++) m->ua[i] = v[j++]; }
        else return bad(m, "fmi3SetFloat32: value reference", vr[k]);
    }
    return j == nv ? fmi3OK : bad(m, "fmi3SetFloat32: nValues", 0); }

/* Int64 (index 9) and Enumeration (index 13) */
fmi3Status fmi3GetInt64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Int64 v[], size_t nv) {
    M *m = c; update(m); if (nv != nvr) return bad(m, "fmi3GetInt64: nValues", 0);
    for (size_t k = 0; k < nvr; k++) {
        int s = slot(vr[k], 9, 0), e = slot(vr[k], 13, 0);
        if (s >= 0) v[k] = m->Int64_[s]; else if (e >= 0) v[k] = m->Int64_[3 + e];
        else return bad(m, "fmi3GetInt64: value reference", vr[k]); }
    return fmi3OK; }
fmi3Status fmi3SetInt64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Int64 v[], size_t nv) {
    M *m = c; if (nv != nvr) return bad(m, "fmi3SetInt64: nValues", 0);
    for (size_t k = 0; k < nvr; k++) {
        int s = slot(vr[k], 9, 1), e = slot(vr[k], 13, 1);
        if (s >= 0) m->Int64_[s] = v[k]; else if (e >= 0) m->Int64_[3 + e] = v[k];
        else return bad(m, "fmi3SetInt64: value reference", vr[k]); }
    return fmi3OK; }
/* UInt64 (index 10) and steps [203] */
fmi3Status fmi3GetUInt64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3UInt64 v[], size_t nv) {
    M *m = c; update(m); if (nv != nvr) return bad(m, "fmi3GetUInt64: nValues", 0);
    for (size_t k = 0; k < nvr; k++) {
        int s = vr[k] == 203 ? 3 : slot(vr[k], 10, 0);
        if (s < 0) return bad(m, "fmi3GetUInt64: value reference", vr[k]);
        v[k] = m->UInt64_[s]; }
    return fmi3OK; }
fmi3Status fmi3SetUInt64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3UInt64 v[], size_t nv) {
    M *m = c; if (nv != nvr) return bad(m, "fmi3SetUInt64: nValues", 0);
    for (size_t k = 0; k < nvr; k++) {
        int s = slot(vr[k], 10, 1);
        if (s < 0) return bad(m, "fmi3SetUInt64: value reference", vr[k]);
        m->UInt64_[s] = v[k]; }
    return fmi3OK; }

fmi3Status fmi3GetString(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3String v[], size_t nv) {
    M *m = c; update(m); if (nv != nvr) return bad(m, "fmi3GetString: nValues", 0);
    for (size_t k = 0; k < nvr; k++) {
        int s = slot(vr[k], 12, 0); if (s < 0) return bad(m, "fmi3GetString: value reference", vr[k]);
        v[k] = m->String_[s]; }
    return fmi3OK; }
fmi3Status fmi3SetString(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3String v[], size_t nv) {
    M *m = c; if (nv != nvr) return bad(m, "fmi3SetString: nValues", 0);
    for (size_t k = 0; k < nvr; k++) {
        int s = slot(vr[k], 12, 1); if (s < 0) return bad(m, "fmi3SetString: value reference", vr[k]);
        snprintf(m->String_[s], 256, "%s", v[k] ? v[k] : ""); }
    return fmi3OK; }
fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, size_t sizes[], fmi3Binary v[], size_t nv) {
    M *m = c; update(m); if (nv != nvr) return bad(m, "fmi3GetBinary: nValues", 0);
    for (size_t k = 0; k < nvr; k++) {
        int s = slot(vr[k], 14, 0); if (s < 0) return bad(m, "fmi3GetBinary: value reference", vr[k]);
        v[k] = m->Binary_[s]; sizes[k] = m->blen[s]; }
    return fmi3OK; }
fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const size_t sizes[], const fmi3Binary v[], size_t nv) {
    M *m = c; if (nv != nvr) return bad(m, "fmi3SetBinary: nValues", 0);
    for (size_t k = 0; k < nvr; k++) {
        int s = slot(vr[k], 14, 1); if (s < 0) return bad(m, "fmi3SetBinary: value reference", vr[k]);
        if (sizes[k] > 64) return bad(m, "fmi3SetBinary: more than 64 bytes", vr[k]);
        memcpy(m->Binary_[s], v[k], sizes[k]); m->blen[s] = sizes[k]; }
    return fmi3OK; }

const char* fmi3GetVersion(void) { return fmi3Version; }
fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n, const fmi3String cat[]) { return fmi3OK; }

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String res,
    fmi3Boolean vis, fmi3Boolean logging, fmi3Boolean eventMode, fmi3Boolean early,
    const fmi3ValueReference req[], size_t nreq, fmi3InstanceEnvironment env,
    fmi3LogMessageCallback log, fmi3IntermediateUpdateCallback upd) {
    M *m = (M*)calloc(1, sizeof(M));
    m->env = env; m->log = log;
    snprintf(m->name, sizeof m->name, "%s", name);
    m->Int64_[3] = 1; m->Int64_[4] = 1;  /* Enumeration p, u start at 1 */
    update(m);
    return m;
}
void fmi3FreeInstance(fmi3Instance c) { free(c); }
fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tolDef, fmi3Float64 tol,
    fmi3Float64 t0, fmi3Boolean stopDef, fmi3Float64 t1) { return fmi3OK; }
fmi3Status fmi3ExitInitializationMode(fmi3Instance c) { M *m = c; m->UInt64_[3] = m->UInt64_[0]; update(m); return fmi3OK; }
fmi3Status fmi3EnterStepMode(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noset,
    fmi3Boolean *event, fmi3Boolean *terminate, fmi3Boolean *early, fmi3Float64 *last) {
    M *m = c;
    m->UInt64_[3] += 1;
    update(m);
    *event = fmi3False; *terminate = fmi3False; *early = fmi3False; *last = t + h;
    return fmi3OK;
}
"""

STUBS = r"""
/* Exported fmi3 calls this model does not support: fmi3Error (3), or NULL for the
   instantiate functions. No header: the arguments are not used. */
#define ERR(name) int name(void) { return 3; }
#define NUL(name) void *name(void) { return 0; }
NUL(fmi3InstantiateModelExchange)
NUL(fmi3InstantiateScheduledExecution)
ERR(fmi3EnterEventMode) ERR(fmi3Reset) ERR(fmi3GetClock) ERR(fmi3SetClock)
ERR(fmi3GetNumberOfVariableDependencies) ERR(fmi3GetVariableDependencies)
ERR(fmi3GetFMUState) ERR(fmi3SetFMUState) ERR(fmi3FreeFMUState) ERR(fmi3SerializedFMUStateSize)
ERR(fmi3SerializeFMUState) ERR(fmi3DeserializeFMUState)
ERR(fmi3GetDirectionalDerivative) ERR(fmi3GetAdjointDerivative)
ERR(fmi3EnterConfigurationMode) ERR(fmi3ExitConfigurationMode)
ERR(fmi3GetIntervalDecimal) ERR(fmi3GetIntervalFraction) ERR(fmi3GetShiftDecimal) ERR(fmi3GetShiftFraction)
ERR(fmi3SetIntervalDecimal) ERR(fmi3SetIntervalFraction) ERR(fmi3SetShiftDecimal) ERR(fmi3SetShiftFraction)
ERR(fmi3EvaluateDiscreteStates) ERR(fmi3UpdateDiscreteStates)
ERR(fmi3EnterContinuousTimeMode) ERR(fmi3CompletedIntegratorStep) ERR(fmi3SetTime)
ERR(fmi3SetContinuousStates) ERR(fmi3GetContinuousStateDerivatives) ERR(fmi3GetEventIndicators)
ERR(fmi3GetContinuousStates) ERR(fmi3GetNominalsOfContinuousStates)
ERR(fmi3GetNumberOfEventIndicators) ERR(fmi3GetNumberOfContinuousStates)
ERR(fmi3GetOutputDerivatives) ERR(fmi3ActivateModelPartition)
"""


def _variable(t: str, i: int, kind: str) -> str:
    vr = 10 * i + {"p": 1, "u": 2, "y": 3}[kind]
    name = f"{kind}_{t}"
    tag = t
    attrs = f'name="{name}" valueReference="{vr}"'
    if t == "Enumeration":
        attrs += ' declaredType="Level"'
    float_t = t in ("Float32", "Float64")
    if kind == "p":
        attrs += ' causality="parameter" variability="fixed"'
    elif kind == "u":
        attrs += f' causality="input" variability="{"continuous" if float_t else "discrete"}"'
    else:
        attrs += f' causality="output" variability="{"continuous" if float_t else "discrete"}"'
    if kind == "y":
        return f"    <{tag} {attrs}/>\n"
    if t == "String":
        return f'    <{tag} {attrs}><Start value=""/></{tag}>\n'
    if t == "Binary":
        return f'    <{tag} {attrs}><Start value=""/></{tag}>\n'
    start = {"Boolean": "false", "Enumeration": "1"}.get(t, "0")
    return f'    <{tag} {attrs} start="{start}"/>\n'


def model_description(ident: str) -> str:
    """The FMI 3.0 ``modelDescription.xml`` of the C model, with model identifier ``ident``."""
    vars_ = '    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>\n'
    outputs = []
    for i, t in enumerate(TYPES, start=1):
        for kind in "puy":
            vars_ += _variable(t, i, kind)
        outputs.append(f'<Output valueReference="{10 * i + 3}" dependencies="{10 * i + 2}"/>')
    vars_ += (
        '    <Float32 name="ua" valueReference="201" causality="input" variability="continuous" start="0 0 0">'
        '<Dimension start="3"/></Float32>\n'
        '    <Float32 name="ya" valueReference="202" causality="output" variability="continuous">'
        '<Dimension start="3"/></Float32>\n'
        '    <UInt64 name="steps" valueReference="203" causality="output" variability="discrete"/>\n'
    )
    outputs += ['<Output valueReference="202" dependencies="201"/>', '<Output valueReference="203"/>']
    outputs += [o.replace("<Output", "<InitialUnknown") for o in outputs]
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="{ident}" instantiationToken="{{5a1f3c2e-7b0d-4e8a-9c61-2f30a7e4b001}}"
    variableNamingConvention="structured">
  <CoSimulation modelIdentifier="{ident}" canHandleVariableCommunicationStepSize="true"
      canGetAndSetFMUState="false" canSerializeFMUState="false" providesIntermediateUpdate="false"/>
  <TypeDefinitions>
    <EnumerationType name="Level"><Item name="one" value="1"/><Item name="two" value="2"/><Item name="three" value="3"/><Item name="four" value="4"/><Item name="five" value="5"/><Item name="six" value="6"/></EnumerationType>
  </TypeDefinitions>
  <DefaultExperiment startTime="0" stopTime="1" stepSize="0.1"/>
  <ModelVariables>
{vars_}  </ModelVariables>
  <ModelStructure>
    {"".join(outputs)}
  </ModelStructure>
</fmiModelDescription>
"""


def build_c_fmu3(out_fmu: Path, ident: str = "CTypes3") -> Path:
    """Compile the C model and its stubs against FMPy's FMI 3.0 headers and package them with
    :func:`model_description` as ``out_fmu`` (Linux x86-64 binary)."""
    import fmpy

    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc, "no C compiler"
    include = Path(fmpy.__file__).parent / "c-code"
    work = out_fmu.parent / f"{ident}_build"
    work.mkdir(parents=True, exist_ok=True)
    (work / "model.c").write_text(C_SOURCE)
    (work / "stubs.c").write_text(STUBS)
    so = work / f"{ident}.so"
    proc = subprocess.run(
        [cc, "-shared", "-fPIC", "-O1", "-Wall", "-Werror", "-Wno-unused-parameter", f"-I{include}",
         "-o", str(so), str(work / "model.c"), str(work / "stubs.c"), "-lm"],
        capture_output=True, text=True,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    with zipfile.ZipFile(out_fmu, "w") as z:
        z.writestr("modelDescription.xml", model_description(ident))
        z.write(so, f"binaries/x86_64-linux/{ident}.so")
    return out_fmu

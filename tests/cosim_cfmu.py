# ruff: noqa: E501 (C source and XML)
"""A small FMI 2.0 co-simulation FMU written in C and compiled in the test with the system
compiler against FMPy's headers (``fmpy/c-code``): what pythonfmu cannot produce.

Variables (value references in brackets):

* ``u`` [0] Real input, ``y`` [1] Real output: ``y(t+h) = y(t) + k*u*h`` (``y`` starts at ``y0``);
* ``k`` [2], ``y0`` [3], ``terminate_at`` [4], ``fail_at`` [5] Real parameters: a step
  crossing ``terminate_at`` integrates up to it, then returns ``fmi2Discard`` with
  ``fmi2Terminated = true`` and ``fmi2LastSuccessfulTime = terminate_at``; a step crossing
  ``fail_at`` logs an error through the logger callback and returns ``fmi2Error``;
* ``x`` [6] Real input, ``z`` [7] Real output: direct feedthrough ``z = x + c`` with ``c`` [8]
  a Real parameter;
* ``n`` [0] Integer output (steps taken), ``m`` [1] Integer input, ``mi`` [2] Integer output
  (``2*m``), ``e`` [3] Enumeration output (1 + n mod 3);
* ``b`` [0] Boolean output (``y > 0.5``), ``bi`` [1] Boolean input, ``bo`` [2] Boolean output
  (``not bi``);
* ``s`` [0] String input, ``so`` [1] String output (``s``), ``slen`` [9] Real output
  (length of ``s``).

``canGetAndSetFMUstate="false"``: the FMU has no state support.
"""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from collections.abc import Callable
from pathlib import Path

FMI2_NO_STATE_STUBS = r"""
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { return fmi2Error; }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) { return fmi2Error; }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) { return fmi2Error; }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference a[], size_t na,
    const fmi2ValueReference b[], size_t nb, const fmi2Real dv[], fmi2Real d[]) { return fmi2Error; }
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
    const fmi2Integer o[], const fmi2Real v[]) { return fmi2Error; }
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
    const fmi2Integer o[], fmi2Real v[]) { return fmi2Error; }
"""
"""C definitions of the FMU-state and derivative functions of an FMI 2.0 FMU without them (each
returns fmi2Error), shared by the test FMUs."""

C_SOURCE = (
    r"""
#include <stdlib.h>
#include <string.h>
#include <stdio.h>
#include "fmi2Functions.h"

typedef struct {
    fmi2Real r[10];
    fmi2Integer i[4];
    fmi2Boolean b[3];
    char s[256];
    fmi2Real time, last;
    int terminated;
    const fmi2CallbackFunctions *cb;
    fmi2String name;
} M;

static void update(M *m) {
    m->r[7] = m->r[6] + m->r[8];
    m->i[2] = 2 * m->i[1];
    m->i[3] = 1 + m->i[0] % 3;
    m->b[0] = m->r[1] > 0.5;
    m->b[2] = !m->b[1];
    m->r[9] = (fmi2Real)strlen(m->s);
}

const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char* fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) { return fmi2OK; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type t, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    M *m = (M*)calloc(1, sizeof(M));
    m->cb = cb; m->name = name;
    m->r[2] = 1.0; m->r[4] = 1e300; m->r[5] = 1e300;
    return m;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol, fmi2Real tv, fmi2Real t0, fmi2Boolean st, fmi2Real t1) {
    ((M*)c)->time = t0; ((M*)c)->last = t0; return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { M *m = c; m->r[1] = m->r[3]; update(m); return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { return fmi2Error; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    M *m = c; update(m); for (size_t k = 0; k < n; k++) { if (vr[k] > 9) return fmi2Error; v[k] = m->r[vr[k]]; } return fmi2OK; }
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    M *m = c; update(m); for (size_t k = 0; k < n; k++) { if (vr[k] > 3) return fmi2Error; v[k] = m->i[vr[k]]; } return fmi2OK; }
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    M *m = c; update(m); for (size_t k = 0; k < n; k++) { if (vr[k] > 2) return fmi2Error; v[k] = m->b[vr[k]]; } return fmi2OK; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    M *m = c; for (size_t k = 0; k < n; k++) { if (vr[k] > 1) return fmi2Error; v[k] = m->s; } return fmi2OK; }
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    M *m = c; for (size_t k = 0; k < n; k++) { if (vr[k] > 9) return fmi2Error; m->r[vr[k]] = v[k]; } return fmi2OK; }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    M *m = c;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] != 1) {
            m->cb->logger(m->cb->componentEnvironment, m->name, fmi2Error, "error",
                          "Integer variable %u is not an input", (unsigned)vr[k]);
            return fmi2Error;
        }
        m->i[1] = v[k];
    }
    return fmi2OK; }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    M *m = c; for (size_t k = 0; k < n; k++) { if (vr[k] != 1) return fmi2Error; m->b[1] = v[k]; } return fmi2OK; }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    M *m = c; for (size_t k = 0; k < n; k++) { if (vr[k] != 0) return fmi2Error; strncpy(m->s, v[k], 255); } return fmi2OK; }

"""
    + FMI2_NO_STATE_STUBS
    + r"""
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noset) {
    M *m = c;
    if (m->terminated) return fmi2Error;
    fmi2Real end = t + h;
    if (end > m->r[5]) {
        m->cb->logger(m->cb->componentEnvironment, m->name, fmi2Error, "error",
                      "integrator blew up: step from t = %g crosses fail_at = %g", t, m->r[5]);
        return fmi2Error;
    }
    if (end > m->r[4]) {
        m->r[1] += m->r[2] * m->r[0] * (m->r[4] - t);
        m->i[0] += 1;
        m->time = m->last = m->r[4];
        m->terminated = 1;
        return fmi2Discard;
    }
    m->r[1] += m->r[2] * m->r[0] * h;
    m->i[0] += 1;
    m->time = m->last = end;
    return fmi2OK;
}
fmi2Status fmi2CancelStep(fmi2Component c) { return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) { return fmi2Error; }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    if (s != fmi2LastSuccessfulTime) return fmi2Error; *v = ((M*)c)->last; return fmi2OK; }
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) { return fmi2Error; }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    if (s != fmi2Terminated) return fmi2Error; *v = ((M*)c)->terminated; return fmi2OK; }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) { return fmi2Error; }
"""
)

_VARS = """
    <ScalarVariable name="u" valueReference="0" causality="input" variability="continuous"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="y" valueReference="1" causality="output" variability="continuous" initial="exact"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="k" valueReference="2" causality="parameter" variability="tunable"><Real start="1"/></ScalarVariable>
    <ScalarVariable name="y0" valueReference="3" causality="parameter" variability="fixed"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="terminate_at" valueReference="4" causality="parameter" variability="fixed"><Real start="1e300"/></ScalarVariable>
    <ScalarVariable name="fail_at" valueReference="5" causality="parameter" variability="fixed"><Real start="1e300"/></ScalarVariable>
    <ScalarVariable name="x" valueReference="6" causality="input" variability="continuous"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="z" valueReference="7" causality="output" variability="continuous" initial="calculated"><Real/></ScalarVariable>
    <ScalarVariable name="c" valueReference="8" causality="parameter" variability="fixed"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="slen" valueReference="9" causality="output" variability="discrete" initial="calculated"><Real/></ScalarVariable>
    <ScalarVariable name="n" valueReference="0" causality="output" variability="discrete" initial="exact"><Integer start="0"/></ScalarVariable>
    <ScalarVariable name="m" valueReference="1" causality="input" variability="discrete"><Integer start="0"/></ScalarVariable>
    <ScalarVariable name="mi" valueReference="2" causality="output" variability="discrete" initial="calculated"><Integer/></ScalarVariable>
    <ScalarVariable name="e" valueReference="3" causality="output" variability="discrete" initial="calculated"><Enumeration declaredType="Phase"/></ScalarVariable>
    <ScalarVariable name="b" valueReference="0" causality="output" variability="discrete" initial="calculated"><Boolean/></ScalarVariable>
    <ScalarVariable name="bi" valueReference="1" causality="input" variability="discrete"><Boolean start="false"/></ScalarVariable>
    <ScalarVariable name="bo" valueReference="2" causality="output" variability="discrete" initial="calculated"><Boolean/></ScalarVariable>
    <ScalarVariable name="s" valueReference="0" causality="input" variability="discrete"><String start=""/></ScalarVariable>
    <ScalarVariable name="so" valueReference="1" causality="output" variability="discrete" initial="calculated"><String/></ScalarVariable>
"""
# 1-based indices (in ModelVariables order) of the outputs, and what each depends on
_OUTPUTS = {2: "", 8: "7", 10: "18", 11: "", 13: "12", 14: "", 15: "", 17: "16", 19: "18"}

_CALCULATED = (8, 10, 13, 14, 15, 17, 19)


def model_description(ident: str) -> str:
    outs = "".join(
        f'<Unknown index="{i}"' + (f' dependencies="{d}"' if d else ' dependencies=""') + "/>"
        for i, d in _OUTPUTS.items()
    )
    init = "".join(
        f'<Unknown index="{i}"' + (f' dependencies="{d}"' if d else "") + "/>"
        for i, d in _OUTPUTS.items()
        if i in _CALCULATED
    )
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{ident}" guid="{{8c4e810f-3df3-4a00-8276-176fa3c9f000}}"
    variableNamingConvention="flat" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{ident}" canHandleVariableCommunicationStepSize="true"
      canGetAndSetFMUstate="false" canSerializeFMUstate="false"/>
  <TypeDefinitions>
    <SimpleType name="Phase"><Enumeration><Item name="a" value="1"/><Item name="b" value="2"/><Item name="c" value="3"/></Enumeration></SimpleType>
  </TypeDefinitions>
  <DefaultExperiment startTime="0" stopTime="1" stepSize="0.1"/>
  <ModelVariables>{_VARS}  </ModelVariables>
  <ModelStructure><Outputs>{outs}</Outputs><InitialUnknowns>{init}</InitialUnknowns></ModelStructure>
</fmiModelDescription>
"""


def build_c_fmu(
    out_fmu: Path,
    ident: str = "CTestModel",
    source: str = C_SOURCE,
    description: Callable[[str], str] = model_description,
) -> Path:
    """Compile the C model (``source``, this module's by default) and package it with
    ``description(ident)`` as ``out_fmu`` (Linux x86-64 binary)."""
    import fmpy

    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc, "no C compiler"
    include = Path(fmpy.__file__).parent / "c-code"
    work = out_fmu.parent / f"{ident}_build"
    work.mkdir(parents=True, exist_ok=True)
    (work / f"{ident}.c").write_text(source)
    so = work / f"{ident}.so"
    subprocess.run(
        [cc, "-shared", "-fPIC", "-O1", f"-I{include}", "-o", str(so), str(work / f"{ident}.c"), "-lm"],
        check=True,
        capture_output=True,
    )
    with zipfile.ZipFile(out_fmu, "w") as z:
        z.writestr("modelDescription.xml", description(ident))
        z.write(so, f"binaries/linux64/{ident}.so")
    return out_fmu

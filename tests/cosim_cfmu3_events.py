# ruff: noqa: E501 (C source and XML)
"""An FMI 3.0 co-simulation FMU with event mode (``hasEventMode="true"``), written in C: the
Integer ``counter`` [1] starts at 1 and goes up by one at every whole second (a time event
inside the FMU), ``x`` [2] (Float64 output) integrates ``u`` [3] (Float64 input). Instantiated
with ``eventModeUsed`` and ``earlyReturnAllowed``, a step crossing a whole second returns early
there with ``eventHandlingNeeded``: the importer enters event mode, where
``fmi3UpdateDiscreteStates`` increments the counter, and steps on. Without event mode the FMU
handles its events inside ``fmi3DoStep``."""

from __future__ import annotations

import re
import shutil
import subprocess
import zipfile
from pathlib import Path

SOURCE = r"""
#include <stdlib.h>
#include <math.h>
#include "fmi3Functions.h"

typedef struct { fmi3Int32 counter; fmi3Float64 x, u, time, next; int event_mode; } M;

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String res,
    fmi3Boolean vis, fmi3Boolean logging, fmi3Boolean eventMode, fmi3Boolean early,
    const fmi3ValueReference req[], size_t nreq, fmi3InstanceEnvironment env,
    fmi3LogMessageCallback log, fmi3IntermediateUpdateCallback upd) {
    M *m = (M*)calloc(1, sizeof(M)); m->counter = 1; m->next = 1; m->event_mode = eventMode && early; return m; }
void fmi3FreeInstance(fmi3Instance c) { free(c); }
const char* fmi3GetVersion(void) { return fmi3Version; }
fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n, const fmi3String cat[]) { return fmi3OK; }
fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tolDef, fmi3Float64 tol,
    fmi3Float64 t0, fmi3Boolean stopDef, fmi3Float64 t1) { ((M*)c)->time = t0; return fmi3OK; }
fmi3Status fmi3ExitInitializationMode(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3EnterEventMode(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3EnterStepMode(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *need, fmi3Boolean *term, fmi3Boolean *nom,
    fmi3Boolean *vals, fmi3Boolean *defined, fmi3Float64 *next) {
    M *m = c;
    if (m->time >= m->next - 1e-10) { m->counter += 1; m->next += 1; }
    *need = fmi3False; *term = fmi3False; *nom = fmi3False; *vals = fmi3False;
    *defined = fmi3True; *next = m->next;
    return fmi3OK; }
fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noset,
    fmi3Boolean *event, fmi3Boolean *terminate, fmi3Boolean *early, fmi3Float64 *last) {
    M *m = c;
    fmi3Float64 end = t + h;
    *event = fmi3False; *terminate = fmi3False; *early = fmi3False;
    if (m->event_mode && end > m->next + 1e-10) {  /* stop at the event */
        m->x += m->u * (m->next - t); m->time = m->next;
        *event = fmi3True; *early = fmi3True; *last = m->next;
        return fmi3OK;
    }
    m->x += m->u * h; m->time = end; *last = end;
    if (m->event_mode && fabs(end - m->next) <= 1e-10) *event = fmi3True;  /* the event at the step's end */
    while (!m->event_mode && end >= m->next - 1e-10) { m->counter += 1; m->next += 1; }
    return fmi3OK; }
fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 v[], size_t nv) {
    M *m = c; for (size_t k = 0; k < nvr; k++) { if (vr[k] == 2) v[k] = m->x; else if (vr[k] == 3) v[k] = m->u;
    else if (vr[k] == 0) v[k] = m->time; else return fmi3Error; } return fmi3OK; }
fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 v[], size_t nv) {
    M *m = c; for (size_t k = 0; k < nvr; k++) { if (vr[k] == 3) m->u = v[k]; else return fmi3Error; } return fmi3OK; }
fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 v[], size_t nv) {
    M *m = c; for (size_t k = 0; k < nvr; k++) { if (vr[k] != 1) return fmi3Error; v[k] = m->counter; } return fmi3OK; }
"""

ALL_FMI3 = (
    "ActivateModelPartition CompletedIntegratorStep DeserializeFMUState DoStep EnterConfigurationMode "
    "EnterContinuousTimeMode EnterEventMode EnterInitializationMode EnterStepMode EvaluateDiscreteStates "
    "ExitConfigurationMode ExitInitializationMode FreeFMUState FreeInstance GetAdjointDerivative GetBinary "
    "GetBoolean GetClock GetContinuousStateDerivatives GetContinuousStates GetDirectionalDerivative "
    "GetEventIndicators GetFMUState GetFloat32 GetFloat64 GetInt16 GetInt32 GetInt64 GetInt8 "
    "GetIntervalDecimal GetIntervalFraction GetNominalsOfContinuousStates GetNumberOfContinuousStates "
    "GetNumberOfEventIndicators GetNumberOfVariableDependencies GetOutputDerivatives GetShiftDecimal "
    "GetShiftFraction GetString GetUInt16 GetUInt32 GetUInt64 GetUInt8 GetVariableDependencies GetVersion "
    "InstantiateCoSimulation InstantiateModelExchange InstantiateScheduledExecution Reset SerializeFMUState "
    "SerializedFMUStateSize SetBinary SetBoolean SetClock SetContinuousStates SetDebugLogging SetFMUState "
    "SetFloat32 SetFloat64 SetInt16 SetInt32 SetInt64 SetInt8 SetIntervalDecimal SetIntervalFraction "
    "SetShiftDecimal SetShiftFraction SetString SetTime SetUInt16 SetUInt32 SetUInt64 SetUInt8 Terminate "
    "UpdateDiscreteStates"
).split()
"""Every FMI 3.0 function (the ones a source does not define are exported as stubs)."""


def stubs(source: str) -> str:
    """C stubs returning fmi3Error (NULL for instantiate) for the FMI 3.0 functions ``source``
    does not define. No header: the arguments are not used."""
    defined = set(re.findall(r"\bfmi3(\w+)\(", source))
    lines = [
        f"void *fmi3{f}(void) {{ return 0; }}"
        if f.startswith("Instantiate")
        else f"int fmi3{f}(void) {{ return 3; }}"
        for f in ALL_FMI3
        if f not in defined
    ]
    return "\n".join(lines) + "\n"


MODEL_DESCRIPTION = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="EventCounter" instantiationToken="{{3c2a3b4d-0000-4000-8000-000000000001}}">
  <CoSimulation modelIdentifier="{ident}" hasEventMode="true" canHandleVariableCommunicationStepSize="true"/>
  <DefaultExperiment startTime="0" stopTime="3" stepSize="0.3"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Int32 name="counter" valueReference="1" causality="output" variability="discrete" initial="exact" start="1"/>
    <Float64 name="x" valueReference="2" causality="output" variability="continuous" initial="exact" start="0"/>
    <Float64 name="u" valueReference="3" causality="input" variability="continuous" start="0"/>
  </ModelVariables>
  <ModelStructure><Output valueReference="1"/><Output valueReference="2"/></ModelStructure>
</fmiModelDescription>
"""


def build_event_fmu3(out_dir: Path, ident: str = "EventCounter3") -> Path:
    """Compile the FMU to ``out_dir/<ident>.fmu`` (Linux x86-64 binary)."""
    import fmpy

    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc, "no C compiler"
    include = Path(fmpy.__file__).parent / "c-code"
    work = out_dir / f"{ident}_build"
    work.mkdir(parents=True, exist_ok=True)
    (work / "model.c").write_text(SOURCE)
    (work / "stubs.c").write_text(stubs(SOURCE))
    so = work / f"{ident}.so"
    proc = subprocess.run(
        [cc, "-shared", "-fPIC", "-O1", f"-I{include}", "-o", str(so), str(work / "model.c"), str(work / "stubs.c"), "-lm"],
        capture_output=True, text=True,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    out = out_dir / f"{ident}.fmu"
    with zipfile.ZipFile(out, "w") as z:
        z.writestr("modelDescription.xml", MODEL_DESCRIPTION.format(ident=ident))
        z.write(so, f"binaries/x86_64-linux/{ident}.so")
    return out

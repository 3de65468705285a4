# ruff: noqa: E501 (C source and XML)
"""The Model Exchange models of tests/cosim_cme.py as FMI 3.0 FMUs: the same C model functions
(``init``, ``start``, ``deriv``, ``indic``, ``update``) behind the FMI 3.0 Model Exchange
interface (Float64 variables, the Stair counter an Int32; event indicators declared as
``EventIndicator`` elements of local variables)."""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

from tests.cosim_cme import MODELS

_FRAME = r"""
#include <stdlib.h>
#include <string.h>
#include <float.h>
#include <math.h>
#include "fmi3Functions.h"

/* the FMI 2.0 names the model functions use */
typedef fmi3Float64 fmi2Real;
typedef fmi3Int32 fmi2Integer;
#define fmi2True 1
#define fmi2False 0
typedef struct {
    int newDiscreteStatesNeeded, terminateSimulation, nominalsOfContinuousStatesChanged,
        valuesOfContinuousStatesChanged, nextEventTimeDefined;
    double nextEventTime;
} fmi2EventInfo;

typedef struct {
    fmi2Real r[16];
    fmi2Integer i[4];
    fmi2Real time, next;
    void *cb;
} M;

#define NX %(nx)d
#define NZ %(nz)d

%(model)s

const char* fmi3GetVersion(void) { return fmi3Version; }
fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n, const fmi3String cat[]) { return fmi3OK; }
fmi3Instance fmi3InstantiateModelExchange(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean vis,
    fmi3Boolean logging, fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    M *m = (M*)calloc(1, sizeof(M)); init(m); return m; }
void fmi3FreeInstance(fmi3Instance c) { free(c); }
fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tolDef, fmi3Float64 tol,
    fmi3Float64 t0, fmi3Boolean stopDef, fmi3Float64 t1) { ((M*)c)->time = t0; return fmi3OK; }
fmi3Status fmi3ExitInitializationMode(fmi3Instance c) { start((M*)c); return fmi3OK; }
fmi3Status fmi3EnterEventMode(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 v[], size_t nv) {
    M *m = c; deriv(m);
    for (size_t k = 0; k < nvr; k++) {
        if (vr[k] == 100) v[k] = m->time;
        else if (vr[k] == 10) { fmi3Float64 z[1] = {0}; if (NZ) indic(m, z, 1); v[k] = z[0]; }
        else if (vr[k] > 15) return fmi3Error;
        else v[k] = m->r[vr[k]];
    }
    return fmi3OK; }
fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 v[], size_t nv) {
    M *m = c; for (size_t k = 0; k < nvr; k++) { if (vr[k] > 15) return fmi3Error; m->r[vr[k]] = v[k]; } return fmi3OK; }
fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 v[], size_t nv) {
    M *m = c; for (size_t k = 0; k < nvr; k++) { if (vr[k] > 3) return fmi3Error; v[k] = m->i[vr[k]]; } return fmi3OK; }
fmi3Status fmi3SetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 v[], size_t nv) {
    M *m = c; for (size_t k = 0; k < nvr; k++) { if (vr[k] > 3) return fmi3Error; m->i[vr[k]] = v[k]; } return fmi3OK; }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *need, fmi3Boolean *term, fmi3Boolean *nom,
    fmi3Boolean *vals, fmi3Boolean *defined, fmi3Float64 *next) {
    fmi2EventInfo e = {0, 0, 0, 0, 0, 0.0};
    update((M*)c, &e);
    *need = e.newDiscreteStatesNeeded; *term = e.terminateSimulation; *nom = e.nominalsOfContinuousStatesChanged;
    *vals = e.valuesOfContinuousStatesChanged; *defined = e.nextEventTimeDefined; *next = e.nextEventTime;
    return fmi3OK; }
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean noset, fmi3Boolean *ev, fmi3Boolean *term) {
    *ev = fmi3False; *term = fmi3False; return fmi3OK; }
fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 t) { ((M*)c)->time = t; return fmi3OK; }
fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 x[], size_t nx) {
    M *m = c; for (size_t k = 0; k < nx; k++) m->r[k] = x[k]; return fmi3OK; }
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 dx[], size_t nx) {
    M *m = c; deriv(m); for (size_t k = 0; k < nx; k++) dx[k] = m->r[nx + k]; return fmi3OK; }
fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 z[], size_t nz) { indic((M*)c, z, nz); return fmi3OK; }
fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t nx) {
    M *m = c; for (size_t k = 0; k < nx; k++) x[k] = m->r[k]; return fmi3OK; }
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t nx) {
    for (size_t k = 0; k < nx; k++) x[k] = 1.0; return fmi3OK; }
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *n) { *n = NZ; return fmi3OK; }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *n) { *n = NX; return fmi3OK; }
"""

STUBS = r"""
/* Exported fmi3 calls these models do not support: fmi3Error (3), or NULL for the
   instantiate functions. No header: the arguments are not used. */
#define ERR(name) int name(void) { return 3; }
#define NUL(name) void *name(void) { return 0; }
NUL(fmi3InstantiateCoSimulation) NUL(fmi3InstantiateScheduledExecution)
ERR(fmi3Reset) ERR(fmi3GetClock) ERR(fmi3SetClock) ERR(fmi3EnterStepMode) ERR(fmi3DoStep)
ERR(fmi3GetFloat32) ERR(fmi3SetFloat32) ERR(fmi3GetInt8) ERR(fmi3SetInt8) ERR(fmi3GetUInt8) ERR(fmi3SetUInt8)
ERR(fmi3GetInt16) ERR(fmi3SetInt16) ERR(fmi3GetUInt16) ERR(fmi3SetUInt16) ERR(fmi3GetUInt32) ERR(fmi3SetUInt32)
ERR(fmi3GetInt64) ERR(fmi3SetInt64) ERR(fmi3GetUInt64) ERR(fmi3SetUInt64) ERR(fmi3GetBoolean) ERR(fmi3SetBoolean)
ERR(fmi3GetString) ERR(fmi3SetString) ERR(fmi3GetBinary) ERR(fmi3SetBinary)
ERR(fmi3GetNumberOfVariableDependencies) ERR(fmi3GetVariableDependencies)
ERR(fmi3GetFMUState) ERR(fmi3SetFMUState) ERR(fmi3FreeFMUState) ERR(fmi3SerializedFMUStateSize)
ERR(fmi3SerializeFMUState) ERR(fmi3DeserializeFMUState)
ERR(fmi3GetDirectionalDerivative) ERR(fmi3GetAdjointDerivative)
ERR(fmi3EnterConfigurationMode) ERR(fmi3ExitConfigurationMode)
ERR(fmi3GetIntervalDecimal) ERR(fmi3GetIntervalFraction) ERR(fmi3GetShiftDecimal) ERR(fmi3GetShiftFraction)
ERR(fmi3SetIntervalDecimal) ERR(fmi3SetIntervalFraction) ERR(fmi3SetShiftDecimal) ERR(fmi3SetShiftFraction)
ERR(fmi3EvaluateDiscreteStates) ERR(fmi3GetOutputDerivatives) ERR(fmi3ActivateModelPartition)
ERR(fmi3SetInputDerivatives)
"""


def _model_description(name: str, ident: str) -> str:
    spec = MODELS[name]
    vars_ = spec["vars"]
    assert isinstance(vars_, list)
    typ = "Int32" if name == "Stair" else "Float64"
    rows = [
        '    <Float64 name="time" valueReference="100" causality="independent" variability="continuous"/>'
    ]
    vr_of = {v[0]: v[1] for v in vars_}
    for vname, vr, caus, var, start in vars_:
        attrs = f'name="{vname}" valueReference="{vr}" causality="{caus}" variability="{var}"'
        if vname.startswith("der("):
            attrs += f' derivative="{vr_of[vname[4:-1]]}"'
        elif start is not None:
            attrs += (' initial="exact"' if caus == "output" else "") + f' start="{start}"'
        rows.append(f"    <{typ} {attrs}/>")
    structure = [f'<Output valueReference="{v[1]}"/>' for v in vars_ if v[2] == "output"]
    structure += [
        f'<ContinuousStateDerivative valueReference="{v[1]}"/>' for v in vars_ if v[0].startswith("der(")
    ]
    structure += [f'<InitialUnknown valueReference="{v[1]}"/>' for v in vars_ if v[0].startswith("der(")]
    if spec["nz"]:
        rows.append('    <Float64 name="z" valueReference="10" causality="local" variability="continuous"/>')
        structure.append('<EventIndicator valueReference="10"/>')
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="{name}" instantiationToken="{{2c2a3b4d-0000-4000-8000-00000000{len(name):04d}}}">
  <ModelExchange modelIdentifier="{ident}"/>
  <DefaultExperiment startTime="0" stopTime="{spec["stop"]}" stepSize="0.01"/>
  <ModelVariables>
{chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure>{"".join(structure)}</ModelStructure>
</fmiModelDescription>
"""


def build_me_fmu3(name: str, out_dir: Path) -> Path:
    """Compile model ``name`` of :data:`tests.cosim_cme.MODELS` to ``out_dir/<name>3.fmu``
    (FMI 3.0 Model Exchange, Linux x86-64 binary)."""
    import fmpy

    spec = MODELS[name]
    ident = f"ME3{name}"
    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc, "no C compiler"
    include = Path(fmpy.__file__).parent / "c-code"
    work = out_dir / f"{ident}_build"
    work.mkdir(parents=True, exist_ok=True)
    (work / "model.c").write_text(_FRAME % {"model": spec["c"], "nx": spec["nx"], "nz": spec["nz"]})
    (work / "stubs.c").write_text(STUBS)
    so = work / f"{ident}.so"
    proc = subprocess.run(
        [cc, "-shared", "-fPIC", "-O1", f"-I{include}", "-o", str(so), str(work / "model.c"), str(work / "stubs.c"), "-lm"],
        capture_output=True, text=True,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    out = out_dir / f"{name}3.fmu"
    with zipfile.ZipFile(out, "w") as z:
        z.writestr("modelDescription.xml", _model_description(name, ident))
        z.write(so, f"binaries/x86_64-linux/{ident}.so")
    return out

# ruff: noqa: E501 (C source and XML)
"""FMI 2.0 Model Exchange FMUs written in C and compiled in the tests (the models of the Modelica
Reference FMUs, written again here: the Reference FMUs are not built on this machine):

* ``BouncingBall``: ``h' = v``, ``v' = g`` (h0 = 1 m, g = -9.81 m/s², e = 0.7); event indicator
  ``h``; at ``h <= 0`` with ``v < 0`` the ball bounces, ``v = -e v`` (at rest below 0.1 m/s:
  ``v = 0``, ``g = 0``) — state events;
* ``Dahlquist``: ``x' = -k x`` (x0 = 1, k = 1);
* ``VanDerPol``: ``x0' = x1``, ``x1' = mu (1 - x0²) x1 - x0`` (x0 = 2, x1 = 0, mu = 1);
* ``Stair``: no continuous state; the Integer ``counter`` starts at 1 and is incremented by a
  time event every second; at 10 the FMU requests termination (time events, termination);
* ``Integrator``: ``x' = u`` with a Real input ``u`` (x0 = 0): for mixing with co-simulation
  participants.

Each model is the generic C below plus a few model functions: ``init`` (start values),
``start`` (after initialisation), ``deriv`` (derivatives), ``indic`` (event indicators),
``update`` (the event update, filling ``fmi2EventInfo``).
"""

from __future__ import annotations

from pathlib import Path

from tests.cosim_cfmu import FMI2_NO_STATE_STUBS, build_c_fmu

_FRAME = r"""
#include <stdlib.h>
#include <string.h>
#include <float.h>
#include <math.h>
#include "fmi2Functions.h"

typedef struct {
    fmi2Real r[16];
    fmi2Integer i[4];
    fmi2Real time, next;
    const fmi2CallbackFunctions *cb;
} M;

%(model)s

const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char* fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) { return fmi2OK; }
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type t, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    M *m = (M*)calloc(1, sizeof(M)); m->cb = cb; init(m); return m; }
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol, fmi2Real tv, fmi2Real t0, fmi2Boolean st, fmi2Real t1) {
    ((M*)c)->time = t0; return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { start((M*)c); return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { return fmi2Error; }
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    M *m = c; deriv(m); for (size_t k = 0; k < n; k++) { if (vr[k] > 15) return fmi2Error; v[k] = m->r[vr[k]]; } return fmi2OK; }
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    M *m = c; for (size_t k = 0; k < n; k++) { if (vr[k] > 3) return fmi2Error; v[k] = m->i[vr[k]]; } return fmi2OK; }
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    M *m = c; for (size_t k = 0; k < n; k++) { if (vr[k] > 15) return fmi2Error; m->r[vr[k]] = v[k]; } return fmi2OK; }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    M *m = c; for (size_t k = 0; k < n; k++) { if (vr[k] > 3) return fmi2Error; m->i[vr[k]] = v[k]; } return fmi2OK; }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) { return n ? fmi2Error : fmi2OK; }
%(stubs)s
fmi2Status fmi2EnterEventMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *e) {
    e->newDiscreteStatesNeeded = fmi2False; e->terminateSimulation = fmi2False;
    e->nominalsOfContinuousStatesChanged = fmi2False; e->valuesOfContinuousStatesChanged = fmi2False;
    e->nextEventTimeDefined = fmi2False; e->nextEventTime = 0;
    update((M*)c, e); return fmi2OK; }
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noset, fmi2Boolean *ev, fmi2Boolean *term) {
    *ev = fmi2False; *term = fmi2False; return fmi2OK; }
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { ((M*)c)->time = t; return fmi2OK; }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    M *m = c; for (size_t k = 0; k < nx; k++) m->r[k] = x[k]; return fmi2OK; }
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx) {
    M *m = c; deriv(m); for (size_t k = 0; k < nx; k++) dx[k] = m->r[nx + k]; return fmi2OK; }
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t nz) { indic((M*)c, z, nz); return fmi2OK; }
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    M *m = c; for (size_t k = 0; k < nx; k++) x[k] = m->r[k]; return fmi2OK; }
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    for (size_t k = 0; k < nx; k++) x[k] = 1.0; return fmi2OK; }
/* co-simulation functions a model exchange FMU does not have: FMPy does not load them */
"""

NO_EVENTS = r"""
static void indic(M *m, fmi2Real z[], size_t nz) {}
static void update(M *m, fmi2EventInfo *e) {}
"""

MODELS: dict[str, dict[str, object]] = {
    "BouncingBall": {
        # r: 0 h, 1 v, 2 der(h), 3 der(v), 4 g, 5 e
        "c": r"""
static void init(M *m) { m->r[0] = 1; m->r[1] = 0; m->r[4] = -9.81; m->r[5] = 0.7; }
static void start(M *m) {}
static void deriv(M *m) { m->r[2] = m->r[1]; m->r[3] = m->r[4]; }
static void indic(M *m, fmi2Real z[], size_t nz) { z[0] = m->r[0]; }
static void update(M *m, fmi2EventInfo *e) {
    if (m->r[0] <= 0 && m->r[1] < 0) {
        m->r[0] = DBL_MIN; m->r[1] = -m->r[5] * m->r[1];
        if (m->r[1] < 0.1) { m->r[1] = 0; m->r[4] = 0; }
        e->valuesOfContinuousStatesChanged = fmi2True;
    }
}
""",
        "nx": 2,
        "nz": 1,
        "vars": [("h", 0, "output", "continuous", "1"), ("v", 1, "output", "continuous", "0"),
                 ("der(h)", 2, "local", "continuous", None), ("der(v)", 3, "local", "continuous", None),
                 ("g", 4, "parameter", "fixed", "-9.81"), ("e", 5, "parameter", "tunable", "0.7")],
        "stop": 3.0,
    },
    "Dahlquist": {
        "c": r"""
static void init(M *m) { m->r[0] = 1; m->r[2] = 1; }
static void start(M *m) {}
static void deriv(M *m) { m->r[1] = -m->r[2] * m->r[0]; }
""" + NO_EVENTS,
        "nx": 1,
        "nz": 0,
        "vars": [("x", 0, "output", "continuous", "1"), ("der(x)", 1, "local", "continuous", None),
                 ("k", 2, "parameter", "fixed", "1")],
        "stop": 10.0,
    },
    "VanDerPol": {
        "c": r"""
static void init(M *m) { m->r[0] = 2; m->r[1] = 0; m->r[4] = 1; }
static void start(M *m) {}
static void deriv(M *m) { m->r[2] = m->r[1]; m->r[3] = m->r[4] * (1 - m->r[0] * m->r[0]) * m->r[1] - m->r[0]; }
""" + NO_EVENTS,
        "nx": 2,
        "nz": 0,
        "vars": [("x0", 0, "output", "continuous", "2"), ("x1", 1, "output", "continuous", "0"),
                 ("der(x0)", 2, "local", "continuous", None), ("der(x1)", 3, "local", "continuous", None),
                 ("mu", 4, "parameter", "fixed", "1")],
        "stop": 20.0,
    },
    "Stair": {
        # i: 0 counter; time events every second, termination at counter 10
        "c": r"""
static void init(M *m) { m->i[0] = 1; m->next = 1; }
static void start(M *m) {}
static void deriv(M *m) {}
static void indic(M *m, fmi2Real z[], size_t nz) {}
static void update(M *m, fmi2EventInfo *e) {
    if (m->time >= m->next - 1e-10) { m->i[0] += 1; m->next += 1; }
    e->nextEventTimeDefined = fmi2True; e->nextEventTime = m->next;
    if (m->i[0] >= 10) e->terminateSimulation = fmi2True;
}
""",
        "nx": 0,
        "nz": 0,
        "vars": [("counter", 0, "output", "discrete", "1")],
        "stop": 10.0,
    },
    "Integrator": {
        # r: 0 x, 1 der(x), 2 u (input)
        "c": r"""
static void init(M *m) { m->r[0] = 0; m->r[2] = 0; }
static void start(M *m) {}
static void deriv(M *m) { m->r[1] = m->r[2]; }
""" + NO_EVENTS,
        "nx": 1,
        "nz": 0,
        "vars": [("x", 0, "output", "continuous", "0"), ("der(x)", 1, "local", "continuous", None),
                 ("u", 2, "input", "continuous", "0")],
        "stop": 1.0,
    },
}  # fmt: skip
"""Each model: C functions, number of states and event indicators, variables (name, value
reference, causality, variability, start), the stop time the comparisons use."""


def _model_description(name: str, ident: str) -> str:
    spec = MODELS[name]
    vars_ = spec["vars"]
    assert isinstance(vars_, list)
    rows, index = [], {}
    for k, (vname, vr, caus, var, start) in enumerate(vars_, start=1):
        index[vname] = k
        typ = "Integer" if name == "Stair" else "Real"
        attrs = f' start="{start}"' if start is not None and caus != "local" else ""
        deriv = ""
        if vname.startswith("der("):
            deriv = f' derivative="{index[vname[4:-1]]}"'
        init = ' initial="exact"' if caus == "output" and start is not None else ""
        if caus == "local" and vname.startswith("der("):
            init = ""
        var_attr = "fixed" if var == "fixed" else var
        rows.append(
            f'    <ScalarVariable name="{vname}" valueReference="{vr}" causality="{caus}" '
            f'variability="{var_attr}"{init}><{typ}{attrs}{deriv}/></ScalarVariable>'
        )
    outs = "".join(f'<Unknown index="{index[v[0]]}"/>' for v in vars_ if v[2] == "output")
    ders = "".join(f'<Unknown index="{index[v[0]]}"/>' for v in vars_ if v[0].startswith("der("))
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{{1c2a3b4d-0000-4000-8000-00000000{len(name):04d}}}"
    variableNamingConvention="structured" numberOfEventIndicators="{spec["nz"]}">
  <ModelExchange modelIdentifier="{ident}"/>
  <DefaultExperiment startTime="0" stopTime="{spec["stop"]}" stepSize="0.01"/>
  <ModelVariables>
{chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure><Outputs>{outs}</Outputs>{f"<Derivatives>{ders}</Derivatives>" if ders else ""}</ModelStructure>
</fmiModelDescription>
"""


def build_me_fmu(name: str, out_dir: Path) -> Path:
    """Compile model ``name`` of :data:`MODELS` to ``out_dir/<name>.fmu`` (FMI 2.0 ME)."""
    ident = f"ME{name}"
    source = _FRAME % {"model": MODELS[name]["c"], "stubs": FMI2_NO_STATE_STUBS}
    out_dir.mkdir(parents=True, exist_ok=True)
    return build_c_fmu(out_dir / f"{name}.fmu", ident=ident, source=source,
                       description=lambda i: _model_description(name, i))  # fmt: skip

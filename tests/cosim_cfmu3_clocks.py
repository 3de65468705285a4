# ruff: noqa: E501 (C source and XML)
"""FMI 3.0 co-simulation FMUs with clocks (``hasEventMode="true"``), written in C, one source
compiled twice:

* ``ClockedCounter`` (``-DCOUNTER``): the periodic input clock ``tick`` [10]
  (``intervalVariability="constant"``, ``intervalDecimal="0.3"``, ``shiftDecimal="0.1"``:
  ticks at 0.1, 0.4, 0.7, ..) and the Int32 output ``count`` [11] clocked by it (+1 per
  tick); the triggered input clock ``trig`` [20] with the clocked Int32 input ``k_in`` [21]
  and the clocked outputs ``trig_count`` [22] (+1 per tick) and ``last_k`` [23] (``k_in`` at
  the last tick). Setting ``k_in`` while ``trig`` is not active is an error (fmi3Error), so a
  master that sets it outside its ticks fails. ``fmi3GetIntervalDecimal(tick)`` gives 0.3.
* ``TickSource`` (``-DSOURCE``): the triggered output clock ``out`` [30] ticks at every
  multiple of 0.7 s (a time event: early return there with ``eventHandlingNeeded``), its
  clocked Int32 output ``n_out`` [31] is 10 x the number of ticks so far.

Clocks are deactivated by the FMU in ``fmi3UpdateDiscreteStates``."""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

from tests.cosim_cfmu3_events import stubs

SOURCE = r"""
#include <stdlib.h>
#include <math.h>
#include "fmi3Functions.h"

#define EPS 1e-10
#define OUT_PERIOD 0.7

typedef struct {
    fmi3Float64 time; int event_mode;
    fmi3Int32 count, trig_count, last_k, k_in; int tick_on, trig_on;
    fmi3Int32 n_out, n_ticks; int out_on;
} M;

static fmi3Float64 next_out(M *m) { return OUT_PERIOD * (m->n_ticks + 1); }

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String res,
    fmi3Boolean vis, fmi3Boolean logging, fmi3Boolean eventMode, fmi3Boolean early,
    const fmi3ValueReference req[], size_t nreq, fmi3InstanceEnvironment env,
    fmi3LogMessageCallback log, fmi3IntermediateUpdateCallback upd) {
    M *m = (M*)calloc(1, sizeof(M)); m->event_mode = eventMode && early; return m; }
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
    if (m->tick_on) m->count += 1;
    if (m->trig_on) { m->trig_count += 1; m->last_k = m->k_in; }
    if (m->out_on) m->n_ticks += 1;
    m->tick_on = m->trig_on = m->out_on = 0;  /* clocks deactivated */
    *need = fmi3False; *term = fmi3False; *nom = fmi3False; *vals = fmi3False;
#ifdef SOURCE
    *defined = fmi3True; *next = next_out(m);
#else
    *defined = fmi3False; *next = 0;
#endif
    return fmi3OK; }
fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noset,
    fmi3Boolean *event, fmi3Boolean *terminate, fmi3Boolean *early, fmi3Float64 *last) {
    M *m = c;
    fmi3Float64 end = t + h;
    *event = fmi3False; *terminate = fmi3False; *early = fmi3False; *last = end;
    if (m->tick_on || m->trig_on || m->out_on) return fmi3Error;  /* a clock left active */
#ifdef SOURCE
    fmi3Float64 te = next_out(m);
    if (!m->event_mode) return fmi3Error;  /* this FMU needs event mode */
    if (end >= te - EPS) {  /* the output clock ticks at te: return there */
        m->time = te; m->out_on = 1; m->n_out = 10 * (m->n_ticks + 1);
        *event = fmi3True; *early = end > te + EPS; *last = te;
        return fmi3OK;
    }
#endif
    m->time = end;
    return fmi3OK; }
fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]) {
    M *m = c; for (size_t k = 0; k < n; k++) {
#ifdef COUNTER
        if (vr[k] == 10) m->tick_on = v[k]; else if (vr[k] == 20) m->trig_on = v[k]; else return fmi3Error;
#else
        return fmi3Error;
#endif
    } return fmi3OK; }
fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]) {
    M *m = c; for (size_t k = 0; k < n; k++) {
        if (vr[k] == 30) v[k] = m->out_on; else if (vr[k] == 10) v[k] = m->tick_on;
        else if (vr[k] == 20) v[k] = m->trig_on; else return fmi3Error; } return fmi3OK; }
fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
    fmi3Float64 iv[], fmi3IntervalQualifier q[]) {
    for (size_t k = 0; k < n; k++) { if (vr[k] != 10) return fmi3Error; iv[k] = 0.3; q[k] = fmi3IntervalChanged; }
    return fmi3OK; }
fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 v[], size_t nv) {
    M *m = c; for (size_t k = 0; k < nvr; k++) { if (vr[k] == 0) v[k] = m->time; else return fmi3Error; } return fmi3OK; }
fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 v[], size_t nv) {
    M *m = c; for (size_t k = 0; k < nvr; k++) {
        switch (vr[k]) { case 11: v[k] = m->count; break; case 21: v[k] = m->k_in; break;
            case 22: v[k] = m->trig_count; break; case 23: v[k] = m->last_k; break;
            case 31: v[k] = m->n_out; break; default: return fmi3Error; } } return fmi3OK; }
fmi3Status fmi3SetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 v[], size_t nv) {
    M *m = c; for (size_t k = 0; k < nvr; k++) {
        if (vr[k] != 21 || !m->trig_on) return fmi3Error;  /* clocked: only while trig ticks */
        m->k_in = v[k]; } return fmi3OK; }
"""

COUNTER_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="ClockedCounter" instantiationToken="{{3c2a3b4d-0000-4000-8000-0000000000c1}}">
  <CoSimulation modelIdentifier="{ident}" hasEventMode="true" canHandleVariableCommunicationStepSize="true"/>
  <DefaultExperiment startTime="0" stopTime="2" stepSize="0.25"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Clock name="tick" valueReference="10" causality="input" intervalVariability="{interval_variability}"{interval}/>
    <Int32 name="count" valueReference="11" causality="output" variability="discrete" clocks="10" initial="exact" start="0"/>
    <Clock name="trig" valueReference="20" causality="input" intervalVariability="triggered"/>
    <Int32 name="k_in" valueReference="21" causality="input" variability="discrete" clocks="20" start="0"/>
    <Int32 name="trig_count" valueReference="22" causality="output" variability="discrete" clocks="20" initial="exact" start="0"/>
    <Int32 name="last_k" valueReference="23" causality="output" variability="discrete" clocks="20" initial="exact" start="0"/>
  </ModelVariables>
  <ModelStructure><Output valueReference="11"/><Output valueReference="22"/><Output valueReference="23"/></ModelStructure>
</fmiModelDescription>
"""

SOURCE_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="TickSource" instantiationToken="{{3c2a3b4d-0000-4000-8000-0000000000c2}}">
  <CoSimulation modelIdentifier="{ident}" hasEventMode="true" canHandleVariableCommunicationStepSize="true"/>
  <DefaultExperiment startTime="0" stopTime="2" stepSize="0.25"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Clock name="out" valueReference="30" causality="output" intervalVariability="triggered"/>
    <Int32 name="n_out" valueReference="31" causality="output" variability="discrete" clocks="30" initial="exact" start="0"/>
  </ModelVariables>
  <ModelStructure><Output valueReference="30"/><Output valueReference="31"/></ModelStructure>
</fmiModelDescription>
"""


def _build(out_dir: Path, ident: str, define: str, md: str) -> Path:
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
        [cc, "-shared", "-fPIC", "-O1", f"-D{define}", f"-I{include}", "-o", str(so), str(work / "model.c"), str(work / "stubs.c"), "-lm"],
        capture_output=True, text=True,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    out = out_dir / f"{ident}.fmu"
    with zipfile.ZipFile(out, "w") as z:
        z.writestr("modelDescription.xml", md)
        z.write(so, f"binaries/x86_64-linux/{ident}.so")
    return out


def build_counter_fmu3(
    out_dir: Path, ident: str = "ClockedCounter", interval_variability: str = "constant", in_md: bool = True
) -> Path:
    """The ClockedCounter FMU; ``in_md=False`` leaves intervalDecimal / shiftDecimal out of the
    model description (the interval then comes from fmi3GetIntervalDecimal, no shift)."""
    interval = ' intervalDecimal="0.3" shiftDecimal="0.1"' if in_md else ""
    md = COUNTER_MD.format(ident=ident, interval_variability=interval_variability, interval=interval)
    return _build(out_dir, ident, "COUNTER", md)


def build_source_fmu3(out_dir: Path, ident: str = "TickSource") -> Path:
    """The TickSource FMU."""
    return _build(out_dir, ident, "SOURCE", SOURCE_MD.format(ident=ident))

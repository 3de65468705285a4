# ruff: noqa: E501 (C source and XML)
"""An FMI 3.0 Model Exchange FMU with clocks, written in C and compiled in the tests (the frame
of tests/cosim_cme3.py):

* ``x' = -x`` (x0 = 1), output ``x``;
* a periodic input clock ``tick`` (``intervalVariability="constant"``, interval 0.3 s, shift
  0.1 s): at each tick (in event mode) the clocked output ``count`` grows by 1 and ``x`` jumps
  by +1 (a discrete change of the continuous state);
* an output clock ``third`` ticking with every third tick (read with ``fmi3GetClock``, which
  resets it).

Closed form: ticks at t_k = 0.1 + 0.3 k; count(t) = number of ticks <= t;
x(t) = exp(-t) + sum over t_k <= t of exp(-(t - t_k)).
"""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

from tests.cosim_cme3 import _FRAME, STUBS

MODEL = r"""
/* r: 0 x, 1 der(x), 2 count; i: 1 tick active, 2 third (output clock) */
static void init(M *m) { m->r[0] = 1; m->r[2] = 0; }
static void start(M *m) {}
static void deriv(M *m) { m->r[1] = -m->r[0]; }
static void indic(M *m, fmi2Real z[], size_t nz) {}
static void update(M *m, fmi2EventInfo *e) {
    if (m->i[1]) {
        m->r[2] += 1; m->r[0] += 1; e->valuesOfContinuousStatesChanged = fmi2True;
        if (((int)m->r[2]) % 3 == 0) m->i[2] = 1;
        m->i[1] = 0;
    }
}
fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]) {
    M *m = c; for (size_t k = 0; k < n; k++) { if (vr[k] != 20) return fmi3Error; m->i[1] = v[k]; } return fmi3OK; }
fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]) {
    M *m = c; for (size_t k = 0; k < n; k++) { if (vr[k] != 21) return fmi3Error; v[k] = m->i[2]; m->i[2] = 0; } return fmi3OK; }
"""

XML = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="MEClocks" instantiationToken="{2c2a3b4d-0000-4000-8000-00000000c10c}">
  <ModelExchange modelIdentifier="MEClocks"/>
  <DefaultExperiment startTime="0" stopTime="2" stepSize="0.05"/>
  <ModelVariables>
    <Float64 name="time" valueReference="100" causality="independent" variability="continuous"/>
    <Float64 name="x" valueReference="0" causality="output" variability="continuous" initial="exact" start="1"/>
    <Float64 name="der(x)" valueReference="1" causality="local" variability="continuous" derivative="0"/>
    <Float64 name="count" valueReference="2" causality="output" variability="discrete" clocks="20" initial="exact" start="0"/>
    <Clock name="tick" valueReference="20" causality="input" intervalVariability="constant" intervalDecimal="0.3" shiftDecimal="0.1"/>
    <Clock name="third" valueReference="21" causality="output" intervalVariability="triggered" clocks="20"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="0"/><Output valueReference="2"/><Output valueReference="21"/>
    <ContinuousStateDerivative valueReference="1"/><InitialUnknown valueReference="1"/>
  </ModelStructure>
</fmiModelDescription>
"""


def build_me_clocks_fmu(out_dir: Path) -> Path:
    """Compile the model to ``out_dir/MEClocks.fmu`` (FMI 3.0 Model Exchange, Linux x86-64)."""
    import fmpy

    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc, "no C compiler"
    include = Path(fmpy.__file__).parent / "c-code"
    work = out_dir / "MEClocks_build"
    work.mkdir(parents=True, exist_ok=True)
    (work / "model.c").write_text(_FRAME % {"model": MODEL, "nx": 1, "nz": 0})
    (work / "stubs.c").write_text(STUBS.replace("ERR(fmi3GetClock) ERR(fmi3SetClock) ", ""))
    so = work / "MEClocks.so"
    proc = subprocess.run(
        [cc, "-shared", "-fPIC", "-O1", f"-I{include}", "-o", str(so), str(work / "model.c"), str(work / "stubs.c"), "-lm"],
        capture_output=True, text=True,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    out = out_dir / "MEClocks.fmu"
    with zipfile.ZipFile(out, "w") as z:
        z.writestr("modelDescription.xml", XML)
        z.write(so, "binaries/x86_64-linux/MEClocks.so")
    return out

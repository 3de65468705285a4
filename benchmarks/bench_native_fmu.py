"""Native FMU benchmark (issue 16): per-step time of the native C cell and module FMUs against
the pythonfmu FMUs of the same models, measured in the same run, and the export times.

Per step = set the inputs + ``doStep`` + get the outputs:

* through FMPy's C-level calls (``fmi2SetReal``/``fmi2DoStep``/``fmi2GetReal`` by ctypes with
  prebuilt arrays), for the native and the pythonfmu FMU (this includes the Python loop and
  ctypes overhead, about 1-2 us);
* in a host's own loop: a small C program that loads the native binary and times the same
  calls (no Python in the process).

Targets: native cell <= 2 us per step, native 12-cell module <= 10 us, export <= 5 s.

The module thermal ROM FMU (issue 16 item 3; the ROM of ``examples/module_thermal.toml`` on its
default mesh, built first unless ``--rom FILE`` is given): per step = set its 43 inputs (heat
per cell, fluid per segment, ambient) + ``doStep`` + get the 24 cell temperatures (mean, hot
spot), through FMPy's C-level calls, against one step of the Python ROM
(:class:`hevsim.thermal.rom.RomStepper`, one module, plus its cell mean and hot-spot outputs)
measured in the same run; its export time; and its agreement with RomStepper (largest relative
difference per output over every step of the 1-hour US06-like heat of ``bench_rom.py``).

Run: ``.venv/bin/python benchmarks/bench_native_fmu.py [--steps 20000] [--rom module.rom.npz]``
"""

from __future__ import annotations

import argparse
import ctypes
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import OtherLoad  # noqa: E402

TARGET_CELL_US = 2.0
TARGET_MODULE_US = 10.0
TARGET_EXPORT_S = 5.0

HOST_C = r"""
#define _POSIX_C_SOURCE 199309L
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "fmi2Functions.h"
static void logger(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c, fmi2String m, ...)
{ (void)e; (void)n; (void)s; (void)c; fprintf(stderr, "%s\n", m); }
int main(int argc, char **argv)
{
    void *h = dlopen(argv[1], RTLD_NOW);
    fmi2CallbackFunctions cb = {logger, NULL, NULL, NULL, NULL};
    fmi2ValueReference in[2] = {0, 2}, out[5] = {12, 13, 14, 15, 16};
    fmi2Real u[2], y[5], t = 0.0;
    long k, n = atol(argv[3]);
    struct timespec a, b;
    fmi2Component c;
    fmi2InstantiateTYPE *inst = (fmi2InstantiateTYPE *)dlsym(h, "fmi2Instantiate");
    fmi2SetupExperimentTYPE *setup = (fmi2SetupExperimentTYPE *)dlsym(h, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE *enter =
        (fmi2EnterInitializationModeTYPE *)dlsym(h, "fmi2EnterInitializationMode");
    fmi2ExitInitializationModeTYPE *exit_ =
        (fmi2ExitInitializationModeTYPE *)dlsym(h, "fmi2ExitInitializationMode");
    fmi2SetRealTYPE *set = (fmi2SetRealTYPE *)dlsym(h, "fmi2SetReal");
    fmi2GetRealTYPE *get = (fmi2GetRealTYPE *)dlsym(h, "fmi2GetReal");
    fmi2DoStepTYPE *step = (fmi2DoStepTYPE *)dlsym(h, "fmi2DoStep");
    c = inst("bench", fmi2CoSimulation, argv[2], "", &cb, fmi2False, fmi2False);
    setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    enter(c);
    exit_(c);
    clock_gettime(CLOCK_MONOTONIC, &a);
    for (k = 0; k < n; k++, t += 1.0) {
        u[0] = atof(argv[4]) * (k % 200 < 150 ? 1.0 : -0.5);
        u[1] = 298.15;
        set(c, in, 2, u);
        if (step(c, t, 1.0, fmi2True) != fmi2OK) return 5;
        get(c, out, 5, y);
    }
    clock_gettime(CLOCK_MONOTONIC, &b);
    printf("%.6f %.17g\n", ((b.tv_sec - a.tv_sec) * 1e9 + (b.tv_nsec - a.tv_nsec)) / 1e3 / n, y[0]);
    return 0;
}
"""


def fmpy_step_us(fmu: Path, steps: int, current_a: float) -> float:
    """Per-step time [us] of set inputs + doStep + get outputs through FMPy's C-level calls."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    slave = FMU2Slave(
        guid=md.guid,
        unzipDirectory=extract(str(fmu)),
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName="bench",
    )
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    vin = (ctypes.c_uint * 2)(vr["current_a"], vr["port_temp_k"])
    names = ("voltage_v", "soc", "port_heat_w", "temp_k", "soh")
    vout = (ctypes.c_uint * 5)(*[vr[n] for n in names])
    u = (ctypes.c_double * 2)(current_a, 298.15)
    y = (ctypes.c_double * 5)()
    set_real, do_step, get_real, comp = (
        slave.fmi2SetReal,
        slave.fmi2DoStep,
        slave.fmi2GetReal,
        slave.component,
    )
    t0 = time.perf_counter()
    for k in range(steps):
        u[0] = current_a if k % 200 < 150 else -0.5 * current_a
        set_real(comp, vin, 2, u)
        do_step(comp, float(k), 1.0, 1)
        get_real(comp, vout, 5, y)
    elapsed = time.perf_counter() - t0
    slave.terminate()
    slave.freeInstance()
    return elapsed / steps * 1e6


def host_loop_us(fmu: Path, steps: int, current_a: float, tmp: Path) -> float:
    """Per-step time [us] of the same calls in a C host's own loop (no Python)."""
    import fmpy
    from fmpy import read_model_description

    from hevsim.battery.native import find_compiler, native_binary

    md = read_model_description(str(fmu))
    name, data = native_binary(fmu)
    lib = tmp / Path(name).name
    lib.write_bytes(data)
    host = tmp / "bench_host"
    if not host.exists():
        (tmp / "bench_host.c").write_text(HOST_C)
        headers = Path(fmpy.__file__).parent / "c-code"
        cmd = [
            find_compiler(),
            "-std=c99",
            "-O2",
            f"-I{headers}",
            str(tmp / "bench_host.c"),
            "-o",
            str(host),
            "-ldl",
        ]
        subprocess.run(cmd, check=True)
    out = subprocess.run(
        [str(host), str(lib), md.guid, str(steps), str(current_a)], capture_output=True, text=True
    )
    if out.returncode != 0:
        raise RuntimeError(f"host loop failed ({out.returncode}): {out.stderr}")
    return float(out.stdout.split()[0])


def rom_fmu_step_us(fmu: Path, steps: int) -> float:
    """Per-step time [us] of the ROM FMU: set all inputs + doStep + get the cell temperatures."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(fmu))
    ins = [v.valueReference for v in md.modelVariables if v.causality == "input"]
    outs = [v.valueReference for v in md.modelVariables if v.name.endswith(("_mean_temp_k", "_max_temp_k"))]
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu)),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench")  # fmt: skip
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    n_cells = sum(1 for v in md.modelVariables if v.name.endswith("_heat_w") and v.causality == "input")
    vin, vout = (ctypes.c_uint * len(ins))(*ins), (ctypes.c_uint * len(outs))(*outs)
    start = [float(v.start) for v in md.modelVariables if v.causality == "input"]
    u, y = (ctypes.c_double * len(ins))(*start), (ctypes.c_double * len(outs))()
    set_real, do_step, get_real, comp = (
        slave.fmi2SetReal,
        slave.fmi2DoStep,
        slave.fmi2GetReal,
        slave.component,
    )
    t0 = time.perf_counter()
    for k in range(steps):
        heat = 2.0 if k % 10 < 5 else 0.8
        for c in range(n_cells):
            u[c] = heat
        set_real(comp, vin, len(ins), u)
        do_step(comp, float(k), 1.0, 1)
        get_real(comp, vout, len(outs), y)
    elapsed = time.perf_counter() - t0
    slave.terminate()
    slave.freeInstance()
    return elapsed / steps * 1e6


def python_rom_step_us(rom: Any, steps: int) -> float:
    """Per-step time [us] of the Python ROM (RomStepper, one module) with its cell outputs."""
    import numpy as np

    from hevsim.thermal.rom import RomStepper

    meta = rom.metadata
    st = RomStepper(rom, float(meta["dt_s"]), rom.wall_h_range_w_m2k[1], float(meta["initial_temp_k"]))
    fluid = np.full((1, rom.n_segments), float(meta["inlet_temp_k"]))
    hot, cold = np.full((1, rom.n_cells), 2.0), np.full((1, rom.n_cells), 0.8)
    amb = float(meta["ambient_k"])
    t0 = time.perf_counter()
    for k in range(steps):
        z = st.step(hot if k % 10 < 5 else cold, fluid, amb)
        rom.cell_mean_k(z)
        rom.cell_max_k(z)
    return (time.perf_counter() - t0) / steps * 1e6


def rom_agreement(fmu: Path, rom: Any) -> float:
    """Largest relative difference FMU vs RomStepper over all cell temperatures and wall heats,
    every step of a 1-hour US06-like per-cell heat (the bench_rom.py load (c)) at the inlet."""
    import numpy as np
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    from bench_rom import us06_cell_heat_w
    from hevsim.thermal.rom import RomStepper

    heat = us06_cell_heat_w(1.0)
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    names = [f"cell{c}_{q}_temp_k" for q in ("mean", "max") for c in range(rom.n_cells)]
    names += [f"segment{s}_wall_heat_w" for s in range(rom.n_segments)]
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu)),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="agree")  # fmt: skip
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    meta = rom.metadata
    h, amb = rom.wall_h_range_w_m2k[1], float(meta["ambient_k"])
    fluid = np.full(rom.n_segments, float(meta["inlet_temp_k"]))
    st = RomStepper(rom, float(meta["dt_s"]), h, float(meta["initial_temp_k"]))
    heat_vr = [vr[f"cell{c}_heat_w"] for c in range(rom.n_cells)]
    out_vr = [vr[n] for n in names]
    got, ref = np.empty((len(heat), len(names))), np.empty((len(heat), len(names)))
    for k, q in enumerate(heat):
        slave.setReal(heat_vr, q.tolist())
        slave.doStep(k * float(meta["dt_s"]), float(meta["dt_s"]))
        got[k] = slave.getReal(out_vr)
        z = st.step(q[None, :], fluid[None, :], amb)[0]
        ref[k] = np.concatenate([rom.cell_mean_k(z), rom.cell_max_k(z), rom.wall_heat_w(z, fluid, h)])
    slave.terminate()
    slave.freeInstance()
    return float((np.abs(got - ref) / np.maximum(1.0, np.abs(ref).max(axis=0))).max())


def rom_case(rom_file: str | None, steps: int, tmp: Path) -> None:
    """Export the ROM FMU and compare its step with the Python ROM's (same run)."""
    from hevsim.battery.native.rom import export_rom_fmu
    from hevsim.thermal.rom import build_rom_from_config, load_rom

    if rom_file:
        rom = load_rom(rom_file)
    else:
        rom, _ = build_rom_from_config(ROOT / "examples" / "module_thermal.toml")
    fmu, t_export = timed(export_rom_fmu, rom, tmp / "rom.fmu")
    fmu_us = rom_fmu_step_us(fmu, steps)
    py_us = python_rom_step_us(rom, steps)
    print(
        f"\nthermal ROM (order {rom.order}, {rom.n_cells} cells, {rom.n_segments} segments): "
        f"export {t_export:.2f} s"
    )
    print(f"{'per step':<13}{'native FMPy us':>16}{'Python ROM us':>15}{'ratio':>8}")
    print(f"{'ROM':<13}{fmu_us:>16.2f}{py_us:>15.2f}{py_us / fmu_us:>7.1f}x")
    agree = rom_agreement(fmu, rom)
    print(f"agreement over a 1 h US06-like heat: max relative difference {agree:.2e} (bound 1e-12)")


def timed(fn: Any, *args: Any, **kw: Any) -> tuple[Any, float]:
    t0 = time.perf_counter()
    r = fn(*args, **kw)
    return r, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--steps", type=int, default=20000, help="steps of the native runs (pythonfmu: steps / 10)"
    )
    ap.add_argument("--rom", help="thermal ROM file (default: build the example module's ROM first)")
    a = ap.parse_args()
    from hevsim.battery.fmu import export_fmu
    from hevsim.battery.native import export_native_fmu

    module_kw = {
        "n_series": 2,
        "n_parallel": 6,
        "capacity_spread": 0.03,
        "resistance_spread": 0.05,
        "seed": 42,
    }
    with tempfile.TemporaryDirectory() as tmp_name, OtherLoad() as load:
        tmp = Path(tmp_name)
        cases: dict[str, tuple[Path, Path, float, float, float]] = {}
        for label, kw, params, soc, current in (
            ("cell", {}, "thesis_table_4_1", 1.0, 2.0),
            ("module 2s6p", module_kw, "saft_li_ion_6ah", 0.8, 30.0),
        ):
            native, t_native = timed(
                export_native_fmu, params, tmp / f"n_{len(cases)}.fmu", soc, 298.15, **kw
            )
            pyfmu, t_py = timed(export_fmu, params, tmp / f"p_{len(cases)}.fmu", soc, 298.15, **kw)
            cases[label] = (native, pyfmu, current, t_native, t_py)
        print(f"{'case':<13}{'export native s':>16}{'export pythonfmu s':>20}")
        for label, (_, _, _, t_native, t_py) in cases.items():
            flag = "ok" if t_native <= TARGET_EXPORT_S else f"ABOVE {TARGET_EXPORT_S} s"
            print(f"{label:<13}{t_native:>16.2f}{t_py:>20.2f}   ({flag})")
        print(f"\nper step (set 2 inputs + doStep + get 5 outputs), {a.steps} native steps")
        print(
            f"{'case':<13}{'native C host us':>17}{'native FMPy us':>16}{'pythonfmu FMPy us':>19}{'ratio':>8}"
        )
        for label, (native, pyfmu, current, _, _) in cases.items():
            target = TARGET_CELL_US if label == "cell" else TARGET_MODULE_US
            host = host_loop_us(native, a.steps, current, tmp)
            nat = fmpy_step_us(native, a.steps, current)
            py = fmpy_step_us(pyfmu, max(200, a.steps // 10), current)
            flag = "ok" if min(host, nat) <= target else f"ABOVE {target} us"
            print(
                f"{label:<13}{host:>17.3f}{nat:>16.3f}{py:>19.2f}{py / nat:>7.0f}x"
                f"   (target {target} us: {flag})"
            )
        rom_case(a.rom, a.steps, tmp)
    print(load.text())


if __name__ == "__main__":
    main()

"""Thermal ROM of the module (issue 12 item 1): build time, step time and validation vs the FEM.

Run from the repository root::

    .venv/bin/python benchmarks/bench_rom.py [--mesh-size 0.005] [--hours 1] [--skip-long]

On the default module mesh (``examples/module_thermal.toml``) it builds the ROM
(:func:`hevsim.thermal.rom.build_rom`, after meshing and assembly, timed separately; target
<= 30 s), times one ROM step (:class:`~hevsim.thermal.rom.RomStepper`, one module and a batch of
100; target <= 20 us per module step) against one FEM step measured in the same run (the
baseline), and compares ROM and FEM (both implicit Euler, the same 1-D coolant channel) on:

(a) the co-simulation module's square load: per-cell heat 2 W / 0.8 W alternating every 5 s,
    cells spread +-20 %, coolant inlet 15 degC, 300 s;
(b) a 10 K step of the coolant inlet at 100 s under 1 W per cell, 300 s;
(c) a 1-hour US06-like per-cell heat profile: the heat of every cell of the 2s6p module of the
    thesis cell (``Module``, 3 % capacity and 5 % resistance spread, port at 30 degC) under the
    US06 road-load current (:func:`hevsim.battery.profiles.cycle_cell_current`, repeated).

and (issue 26) on the load families the ROM is not built or tuned with,
:func:`hevsim.thermal.rom.validation_loads` (per-cell heat of both signs within the 5 W design
amplitude, moving the hot spot inside the cells): a random multi-sine per cell, a checkerboard
swapping every 20 s, random steps held 15 s, a travelling wave, and random heats under a
+-10 K inlet sine.

It prints the largest per-cell mean and hot-spot error of each load (bound: 0.2 K for (a)-(c);
the ROM's stated tolerance ``tol_k``, 0.05 K, for the validation families). The script
only reports: it always exits 0.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import OtherLoad

ROOT = Path(__file__).resolve().parents[1]
TARGET_BUILD_S = 30.0
TARGET_STEP_US = 20.0
BOUND_K = 0.2


def us06_cell_heat_w(hours: float) -> np.ndarray:
    """(steps, 12) per-cell heat [W] of the thesis 2s6p module under the US06 road-load current."""
    from hevsim.battery.module import Module
    from hevsim.battery.profiles import cycle_cell_current

    steps = round(3600 * hours)
    current = 6.0 * cycle_cell_current("us06", duration_s=steps, dt_s=1.0)
    mod = Module("thesis_table_4_1", 2, 6, soc_initial=0.95, temp_k=303.15, capacity_spread=0.03,
                 resistance_spread=0.05, seed=2)  # fmt: skip
    res = mod.simulate(current, 1.0, port_temperature=303.15)
    return np.asarray(res.cells[:, :, 3])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--mesh-size", type=float, default=None, help="gmsh mesh size [m] (default: the example's)"
    )
    ap.add_argument("--hours", type=float, default=1.0, help="length of load (c) [h]")
    ap.add_argument("--skip-long", action="store_true", help="skip load (c)")
    args = ap.parse_args()

    from hevsim.thermal.geometry import build_module_mesh
    from hevsim.thermal.rom import (
        RomStepper,
        build_rom,
        compare_with_fem,
        full_model,
        mesh_hash,
        validation_loads,
    )
    from hevsim.thermal.run import KELVIN, load_thermal_config

    cfg = load_thermal_config(ROOT / "examples" / "module_thermal.toml")
    if args.mesh_size:
        cfg = dataclasses.replace(cfg, geometry=dataclasses.replace(cfg.geometry, mesh_size_m=args.mesh_size))
    t0 = time.perf_counter()
    mesh = build_module_mesh(cfg.geometry)
    t_mesh = time.perf_counter() - t0
    with OtherLoad() as load:
        t0 = time.perf_counter()
        full, _, _ = full_model(cfg, mesh)
        t_asm = time.perf_counter() - t0
        t0 = time.perf_counter()
        rom = build_rom(full, mesh_hash(mesh))
        t_build = time.perf_counter() - t0
    print(f"mesh: {full.n_nodes} FEM nodes (meshing {t_mesh:.1f} s, assembly {t_asm:.1f} s)")
    print(f"ROM build: {t_build:.2f} s (target <= {TARGET_BUILD_S:g} s); {load.text()}")
    print(f"ROM order {rom.order}, error estimate {rom.metadata['error_estimate_k']:.4f} K, hot spot over "
          f"{rom.metadata['candidates_per_cell']} nodes per cell, its error estimate "
          f"{rom.hot_spot_error_k:.4f} K")  # fmt: skip

    # step time: one module, and a batch of 100 modules (per module)
    h = rom.wall_h_range_w_m2k[1]
    for n_mod, reps in ((1, 20000), (100, 500)):
        st = RomStepper(rom, 1.0, h, 303.15, n_modules=n_mod)
        q = np.ones((n_mod, rom.n_cells))
        tf = np.full((n_mod, rom.n_segments), 288.15)
        for _ in range(100):
            st.step(q, tf, 303.15)
        with OtherLoad() as load:
            t0 = time.perf_counter()
            for _ in range(reps):
                st.step(q, tf, 303.15)
            per = (time.perf_counter() - t0) / reps / n_mod
        print(f"ROM step, {n_mod:>3} module(s): {1e6 * per:8.2f} us per module step "
              f"(target <= {TARGET_STEP_US:g} us); {load.text()}")  # fmt: skip

    spread = np.linspace(0.8, 1.2, 12)

    def inlet_15c(t: float) -> float:
        return 15.0 + KELVIN

    loads: list[tuple[str, object, object, int]] = [
        ("(a) square heat 300 s", lambda t: spread * (2.0 if (t % 10.0) < 5.0 else 0.8), inlet_15c, 300),
        (
            "(b) coolant step 300 s",
            lambda t: np.ones(12),
            lambda t: KELVIN + (15.0 if t < 100 else 25.0),
            300,
        ),
    ]
    if not args.skip_long:
        heat = us06_cell_heat_w(args.hours)
        loads.append(
            (
                f"(c) US06-like {args.hours:g} h",
                lambda t: heat[min(round(t) - 1, len(heat) - 1)],
                inlet_15c,
                len(heat),
            )
        )
    tol = float(rom.metadata["options"]["tol_k"])
    bounds = {name: BOUND_K for name, *_ in loads}
    for name, (hf, inf, steps) in validation_loads(rom.n_cells).items():
        loads.append((f"({name}) {steps} s", hf, inf, steps))
        bounds[f"({name}) {steps} s"] = tol
    # the pack's module hot spot (issue 26 item 5): the ROM's states through the pack's slack
    # screening (examples/pack.toml's [module] hot_spot_slack_k, default 0.01 K) vs the FEM's
    # largest nodal temperature of the module
    from hevsim.battery import pack_run as R
    from hevsim.battery.pack import Pack, load_pack_config

    pack = Pack(load_pack_config(ROOT / "examples" / "pack.toml"), rom=rom)
    slack = float(pack._f[R.F_HSEPS])
    q = pack._modal["q"]
    print(f"module hot spot: screening slack {slack:g} K, error estimate (ROM + slack) "
          f"{pack.hot_spot_error()['estimate_k']:.4f} K")  # fmt: skip
    head = ("load", "mean err K", "hot-spot err K", "module hs err K", "peak FEM degC", "FEM step ms",
            "ROM step us", "ratio")  # fmt: skip
    print(f"{head[0]:<26}" + "".join(f"{h:>15}" for h in head[1:]))
    for name, hf, inf, steps in loads:
        c = compare_with_fem(cfg, mesh, rom, hf, inf, steps)
        s = pack.arrays
        hot = np.empty(1)
        module_err = 0.0
        assert c.rom_z is not None
        for k, z in enumerate(c.rom_z):
            R._module_hot_spots_within(s, np.ascontiguousarray((z @ q)[None, :]), hot)
            module_err = max(module_err, abs(hot[0] - c.fem_max_k[k].max()))
        bound = bounds[name]
        ok = "ok" if max(c.mean_error_k, c.max_error_k, module_err) <= bound else f"ABOVE {bound:g} K"
        vals = (c.mean_error_k, c.max_error_k, module_err, c.fem_max_k.max() - KELVIN, 1e3 * c.fem_step_s,
                1e6 * c.rom_step_s, c.fem_step_s / c.rom_step_s)  # fmt: skip
        print(f"{name:<26}" + "".join(f"{v:>15.4f}" for v in vals) + f"  {ok}")
    print("(hot-spot err: per cell, the maximum over every node of the reconstructed field; module hs err:")
    print(" the module's hot spot as the pack reports it, within the slack of that maximum, vs the FEM's)")
    print("(FEM/ROM step times include the 1-D channel and the observations of each side)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

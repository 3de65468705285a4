"""Benchmark: a 1-hour drive (UDDS repeated, 1 s step) of every architecture with a whole pack
(issue 24, "Pack in the vehicle" speed row), with FASTSim 3's ``run_once()`` on its bundled
2016 Prius UDDS measured in the same run as the ratio baseline.

Cases, for each architecture with a traction battery (series HEV, BEV, power split, parallel P3
and P2: examples/series_hev_pack.toml, bev_pack.toml, prius_like_power_split_pack.toml,
parallel_hev_pack.toml, high_performance_parallel_hev_pack.toml), each with its own pack file
and cell, edited to the sizes of the speed target:

* **1200 cells, module ROMs + cooling loop**: 100 modules of 2s6p (the module mesh of
  examples/module_thermal.toml: its ROM is built once into a temporary folder, or ``--rom
  FILE``), every cell simulated with its spread, plate flow and chiller as in
  bench_pack_vehicle.py (a); target <= 2 s;
* **representative cell per module**: the same 100 modules with ``cells = "representative"``
  (no spread), each cell's port at its plate's coolant + the cooling loop (bench_pack_vehicle.py
  (c)); target <= 0.2 s.

The vehicles' inverter windows are opened (``bus_min_v``/``bus_max_v``) for the 200 series
cells. The series HEV runs the compiled series kernel with the pack's compiled step inside; the
other architectures their compiled forward loop (:mod:`hevsim.sim._compiled_hev`,
:mod:`~hevsim.sim._compiled_bev`) with the same compiled pack step inside (issue 24 item 1);
``--python`` adds each case through the Python reference loop (``HEVSIM_FORWARD=python``) as
the same-run "before".

Prints the best of ``--repeat`` runs after one warm-up (wall and CPU seconds, the other
processes' load, ``uptime``), each case's ratio to FASTSim's ``run_once()`` (one UDDS, 1369 s
of driving; the hevsim cases drive 3600 s) and whether the target is met (CPU seconds).

    python benchmarks/bench_pack_architectures.py [--repeat 2] [--rom FILE] [--python] [--no-fastsim]
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_pack_vehicle import hour_cycle, timed
from hevsim.config import load_vehicle_config
from hevsim.sim.pack_vehicle import simulate_pack_vehicle

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"
ARCHITECTURES = {  # label: (vehicle example, its pack file)
    "series HEV": ("series_hev_pack.toml", "vehicle_pack.toml"),
    "BEV": ("bev_pack.toml", "bev_battery.toml"),
    "power split": ("prius_like_power_split_pack.toml", "prius_like_battery.toml"),
    "parallel P3": ("parallel_hev_pack.toml", "vehicle_pack.toml"),
    "parallel P2": ("high_performance_parallel_hev_pack.toml", "hot_lap_pack.toml"),
}
TARGET_S = {"rom": 2.0, "rep": 0.2}


def _sub(text: str, pattern: str, new: str) -> str:
    out, n = re.subn(pattern, new, text, flags=re.MULTILINE)
    assert n >= 1, pattern
    return out


def copy_case(folder: Path, vehicle: str, pack: str, kind: str, rom: Path, tag: str) -> Path:
    """Copies of a shipped pack vehicle and its pack file in ``folder``: 100 modules of 2s6p,
    ``kind`` "rom" (every cell, module ROM ``rom``) or "rep" (one representative cell per
    module, coolant ports); the vehicle's inverter window opened for the 200 series cells."""
    text = (EX / pack).read_text()
    text = text.replace(
        'thermal_config = "module_thermal.toml"', f'thermal_config = "{EX / "module_thermal.toml"}"'
    )
    text = _sub(text, r"^n_series = \d+", "n_series = 2")
    text = _sub(text, r"^n_parallel = \d+", "n_parallel = 6")
    text = _sub(text, r"^n_modules = \d+", "n_modules = 100")
    if kind == "rom":
        text = _sub(text, r'^thermal = "coolant"', f'thermal = "rom"\nrom_file = "{rom}"')
        text = _sub(text, r"^flow_l_min = [0-9.]+", "flow_l_min = 1000.0")  # 10 L/min per plate
        text = _sub(text, r"^flow_ref_l_min = [0-9.]+", "flow_ref_l_min = 1000.0")
        text = _sub(text, r"^chiller_max_w = [0-9.]+", "chiller_max_w = 20000.0")
    else:
        text = _sub(text, r"^capacity_spread = [0-9.]+", "capacity_spread = 0.0")
        text = _sub(text, r"^resistance_spread = [0-9.]+", "resistance_spread = 0.0")
        text = _sub(text, r'^thermal = "coolant"', 'thermal = "coolant"\ncells = "representative"')
        text = text.replace('# cells = "representative"', "# (representative: set above)")
    (folder / f"{tag}_{pack}").write_text(text)
    veh = (EX / vehicle).read_text()
    veh = _sub(veh, rf'^pack = "{re.escape(pack)}"', f'pack = "{tag}_{pack}"')
    veh = _sub(veh, r"^bus_min_v = [0-9.]+", "bus_min_v = 1.0")
    veh = _sub(veh, r"^bus_max_v = [0-9.]+", "bus_max_v = 5000.0")
    path = folder / f"{tag}_{vehicle}"
    path.write_text(veh)
    return path


def fastsim_run_once(repeats: int) -> float | None:
    """Median wall time [s] of FASTSim 3's ``run_once()`` on its bundled 2016 Prius over its
    bundled UDDS (a fresh ``SimDrive`` per repetition, construction untimed), or None."""
    try:
        from bench_simulate import bench_fastsim
    except ImportError:
        return None
    f = bench_fastsim(repeats)
    return None if f is None else float(statistics.median(f["run_once"]))


def uptime() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, check=False).stdout.strip()
    except OSError:
        return "uptime: n/a"


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--rom", help="module ROM of examples/module_thermal.toml (built when omitted)")
    ap.add_argument("--python", action="store_true", help="also time the Python reference loop")
    ap.add_argument("--no-fastsim", action="store_true")
    ap.add_argument("--only", nargs="*", help="architecture labels to run (default: all)")
    args = ap.parse_args()
    cyc = hour_cycle()
    print(f"uptime at start: {uptime()}")
    fs = None if args.no_fastsim else fastsim_run_once(20)
    print(f"FASTSim run_once() on its 2016 Prius, UDDS: {'n/a' if fs is None else f'{1e3 * fs:.2f} ms'}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        rom = Path(args.rom).resolve() if args.rom else folder / "module.rom.npz"
        if not args.rom:
            from hevsim.thermal.rom import build_rom_from_config

            t0 = time.perf_counter()
            built, _ = build_rom_from_config(EX / "module_thermal.toml")
            built.save(rom)
            print(f"ROM built in {time.perf_counter() - t0:.1f} s (order {built.order}; not in the timings)")
        print(
            f"1-hour drive ({cyc.name}, {len(cyc.time_s) - 1} steps of 1 s), "
            f"best of {args.repeat} after a warm-up:"
        )
        rows = []
        for label, (vehicle, pack) in ARCHITECTURES.items():
            if args.only and label not in args.only:
                continue
            for kind, what in (("rom", "1200 cells, ROMs + loop"), ("rep", "representative/module, loop")):
                tag = f"{kind}_{label.replace(' ', '_')}"
                cfg = load_vehicle_config(copy_case(folder, vehicle, pack, kind, rom, tag))
                loops = [("", None)] + (
                    [(" (py)", "python")] if args.python and label != "series HEV" else []
                )
                for suffix, env in loops:
                    if env:
                        os.environ["HEVSIM_FORWARD"] = env
                    try:
                        run = lambda c=cfg: simulate_pack_vehicle(c, cyc, 1.0)  # noqa: E731
                        t = timed(f"{label}, {what}{suffix}", run, args.repeat)
                    finally:
                        os.environ.pop("HEVSIM_FORWARD", None)
                    rows.append((label, kind, what + suffix, t, env is None))
        print(f"uptime at end: {uptime()}")
        print("CPU seconds, target, ratio to FASTSim run_once() (same run):")
        for label, kind, what, t, judged in rows:
            ratio = f"{t / fs:8.1f}x" if fs else "     n/a"
            met = ("met" if t <= TARGET_S[kind] else "NOT met") if judged else "(reference)"
            print(f"  {label:<12} {what:<36} {t:7.3f} s  <= {TARGET_S[kind]:g} s {met:<11} {ratio}")


if __name__ == "__main__":
    main()

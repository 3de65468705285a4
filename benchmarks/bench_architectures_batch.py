"""Variant-cycles per second of ``simulate_batch`` for the non-series architectures (issue 11).

Run from the repository root (or anywhere; paths are resolved from this file)::

    .venv/bin/python benchmarks/bench_architectures_batch.py [--variants 1000] [--baseline 20]

For the conventional sedan, the parallel HEV (P3), the power split and the BEV with their
rule-based controllers, ``hevsim.sim.simulator.simulate_batch(cfg, {"body.mass_kg": ...},
"udds")`` over ``--variants`` masses (after a warm-up batch of 4), reported as variant-cycles
per second of wall time (validation of every variant included) and of the batch's CPU time,
and the ratio to the same batch run variant by variant through the Python loop
(``compiled=False``, ``--baseline`` variants) measured in the same run. The issue's target
is >= 1000 variant-cycles/s on UDDS for the conventional and parallel vehicles on an idle
2-core machine. Whether an architecture has a compiled batch is shown (``compiled``: it has a
compiled loop, :func:`hevsim.sim.forward.compiled_loop`). The script only reports: it always
exits 0.

When FASTSim 3 is installed (the ``bench`` extra), its ``run_once()`` on its 2016 Prius UDDS
is timed just before each row (median of 10, a fresh ``SimDrive`` each, so both see the same
load) and the row shows ``x FASTSim``: the batch's variant-cycles per wall second times that
time, i.e. the batch's throughput over FASTSim's sequential throughput; ``x per CPU`` is the
same per CPU second of each (load-independent, but without the batch's parallelism).
Issue 24's goal is >= 40 for every architecture; the series HEV (its kernel batch, variants
of ``mass_kg``) is a row too.

``--processes N`` (N >= 2) adds the spread over fresh processes: each architecture's batch is
timed in N new interpreters in turn (warm numba cache; each pinned to one core, so the
figure is per CPU second of a single thread: other load changes it little), and the table
shows the slowest, median and fastest process and slowest / fastest. A compiled loop whose
speed depends on where its machine code lands in memory shows as a ratio well above 1 (the
BEV was 1.5-1.7 from one process to the next before its battery lookup was inlined; see
docs/simulate.md); the script flags a ratio above ``SPREAD_FLAG``. ``--only LABEL`` limits
either table to one vehicle.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from _machine import OtherLoad

REPO = Path(__file__).resolve().parents[1]
GOAL_FASTSIM = 40.0  # issue 24: batch throughput >= 40x FASTSim's sequential run_once()
SPREAD_FLAG = 1.25  # --processes: slowest / fastest process above this is flagged
VEHICLES = {
    "series": "examples/series_hev.toml",
    "conventional": "examples/conventional_sedan.toml",
    "parallel (P3)": "examples/parallel_hev.toml",
    "power split": "examples/prius_like_power_split.toml",
    "bev": "examples/bev.toml",
}


def _rate(cfg: object, n: int, compiled: bool | None) -> tuple[float, float]:
    """(variant-cycles per wall second, per CPU second of this process) of one batch."""
    from hevsim.sim.simulator import simulate_batch

    masses = np.linspace(0.85, 1.15, n) * float(cfg.body.mass_kg)  # type: ignore[attr-defined]
    series = getattr(cfg, "architecture", "series") == "series"
    key = "mass_kg" if series else "body.mass_kg"  # the series kernel's batch takes kernel names
    c0, t0 = time.process_time(), time.perf_counter()
    if series:
        simulate_batch(cfg, {key: masses}, "udds")  # type: ignore[arg-type]
    else:
        simulate_batch(cfg, {key: masses}, "udds", compiled=compiled)  # type: ignore[arg-type]
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return n / wall, n / cpu


def fastsim_timer() -> Any:
    """A function ``f(repeats)`` giving (median wall [s], median CPU [s]) of FASTSim 3's
    ``run_once()`` on its 2016 Prius UDDS (a fresh ``SimDrive`` each, construction untimed);
    None when FASTSim is not installed."""
    try:
        import fastsim as fsim
    except ImportError:
        return None
    veh = fsim.Vehicle.from_resource("2016_TOYOTA_Prius_Two.yaml")
    cyc = fsim.Cycle.from_resource("udds.csv")

    def timed(repeats: int) -> tuple[float, float]:
        wall, cpu = [], []
        for i in range(repeats + 2):
            sd = fsim.SimDrive(veh, cyc)
            c0, t0 = time.process_time(), time.perf_counter()
            (sd.run_once if hasattr(sd, "run_once") else sd.walk_once)()
            if i >= 2:
                wall.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
        return float(np.median(wall)), float(np.median(cpu))

    return timed


def _child(label: str, n: int) -> int:
    """One fresh process of ``--processes``: pinned to one core, a warm-up batch, then print
    the variant-cycles per CPU second of the best of three batches of ``n`` variants."""
    from hevsim import config as C

    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    cfg = C.load_vehicle_config(REPO / VEHICLES[label])
    _rate(cfg, 4, None)
    print(max(_rate(cfg, n, None)[1] for _ in range(3)))
    return 0


def spread(labels: list[str], processes: int, n: int) -> None:
    """Print each vehicle's batch rate per CPU second over ``processes`` fresh processes,
    run in turn (module docstring)."""
    import subprocess

    rates: dict[str, list[float]] = {label: [] for label in labels}
    for _ in range(processes):
        for label in labels:  # interleaved: a change in the machine's load hits every vehicle
            cmd = [sys.executable, __file__, "--child", label, "--variants", str(n)]
            out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
            rates[label].append(float(out.split()[-1]))
    print(f"\nspread over {processes} fresh processes (one core each, {n} variants, best of 3 batches; "
          "variant-cycles per CPU s)")  # fmt: skip
    print("{:<16}{:>10}{:>10}{:>10}{:>14}".format("vehicle", "slowest", "median", "fastest", "fast/slow"))
    for label, r in rates.items():
        ratio = max(r) / min(r)
        flag = f"  > {SPREAD_FLAG:g}: depends on the process" if ratio > SPREAD_FLAG else ""
        print(f"{label:<16}{min(r):>10.0f}{float(np.median(r)):>10.0f}{max(r):>10.0f}{ratio:>14.2f}{flag}")
        print(f"{'':<16}each process, in order: {' '.join(f'{x:.0f}' for x in r)}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", type=int, default=1000)
    ap.add_argument("--baseline", type=int, default=20, help="variants of the Python-loop baseline")
    ap.add_argument("--processes", type=int, default=0, help="spread over this many fresh processes (>= 2)")
    ap.add_argument("--only", choices=list(VEHICLES), help="one vehicle")
    ap.add_argument("--child", choices=list(VEHICLES), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        return _child(a.child, a.variants)
    labels = [a.only] if a.only else list(VEHICLES)
    from hevsim import config as C
    from hevsim.sim.forward import compiled_loop

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"cores available: {cores}")
    head = ("vehicle", "compiled", "variants", "per wall s", "per CPU s", "python loop/s", "ratio",
            "x FASTSim", "x per CPU")  # fmt: skip
    print("{:<16}{:>9}{:>9}{:>12}{:>11}{:>15}{:>8}{:>10}{:>10}".format(*head))
    worst = float("inf")
    fs_times = []
    with OtherLoad() as load:
        fs = fastsim_timer()
        for label in labels:
            cfg = C.load_vehicle_config(REPO / VEHICLES[label])
            series = cfg.architecture == "series"
            compiled = series or hasattr(compiled_loop(cfg.architecture), "simulate_batch_compiled")
            _rate(cfg, 4, None)  # warm-up (compilation)
            fs_wall, fs_cpu = fs(10) if fs is not None else (float("nan"), float("nan"))
            wall, cpu = _rate(cfg, a.variants, None)  # FASTSim timed just before: the same load
            base = float("nan") if series else _rate(cfg, a.baseline, False)[0]
            fs_times.append(fs_wall)
            x_fs, x_cpu = wall * fs_wall, cpu * fs_cpu
            worst = min(worst, x_fs)
            row = (label, str(compiled), a.variants, wall, cpu, base, wall / base, x_fs, x_cpu)
            print("{:<16}{:>9}{:>9}{:>12.0f}{:>11.0f}{:>15.1f}{:>8.1f}{:>10.1f}{:>10.1f}".format(*row))
    if fs is None:
        print("FASTSim not installed (pip install -e '.[bench]'): no x FASTSim columns")
    else:
        ok = "MET" if worst >= GOAL_FASTSIM else "NOT met"
        print(
            f"FASTSim run_once() {min(fs_times) * 1e3:.2f}-{max(fs_times) * 1e3:.2f} ms (median of 10 before "
            "each row); x FASTSim = per wall s x its wall time, x per CPU = per CPU s x its CPU time"
        )
        print(
            f"issue 24 goal: every architecture >= {GOAL_FASTSIM:g}x FASTSim throughput: {ok} "
            f"(worst {worst:.1f}x)"
        )
    print(load.text())
    if a.processes >= 2:
        spread(labels, a.processes, min(a.variants, 300))
    print(f"load average now: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    raise SystemExit(main())

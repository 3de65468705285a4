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
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from _machine import OtherLoad

REPO = Path(__file__).resolve().parents[1]
VEHICLES = {
    "conventional": "examples/conventional_sedan.toml",
    "parallel (P3)": "examples/parallel_hev.toml",
    "power split": "examples/prius_like_power_split.toml",
    "bev": "examples/bev.toml",
}


def _rate(cfg: object, n: int, compiled: bool | None) -> tuple[float, float]:
    """(variant-cycles per wall second, per CPU second of this process) of one batch."""
    from hevsim.sim.simulator import simulate_batch

    masses = np.linspace(0.85, 1.15, n) * float(cfg.body.mass_kg)  # type: ignore[attr-defined]
    c0, t0 = time.process_time(), time.perf_counter()
    simulate_batch(cfg, {"body.mass_kg": masses}, "udds", compiled=compiled)  # type: ignore[arg-type]
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return n / wall, n / cpu


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", type=int, default=1000)
    ap.add_argument("--baseline", type=int, default=20, help="variants of the Python-loop baseline")
    a = ap.parse_args()
    from hevsim import config as C
    from hevsim.sim.forward import compiled_loop

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"cores available: {cores}")
    head = ("vehicle", "compiled", "variants", "per wall s", "per CPU s", "python loop/s", "ratio")
    print("{:<16}{:>9}{:>9}{:>12}{:>11}{:>15}{:>8}".format(*head))
    with OtherLoad() as load:
        for label, path in VEHICLES.items():
            cfg = C.load_vehicle_config(REPO / path)
            compiled = hasattr(compiled_loop(cfg.architecture), "simulate_batch_compiled")
            _rate(cfg, 4, None)  # warm-up (compilation)
            wall, cpu = _rate(cfg, a.variants, None)
            base, _ = _rate(cfg, a.baseline, False)
            row = (label, str(compiled), a.variants, wall, cpu, base, wall / base)
            print("{:<16}{:>9}{:>9}{:>12.0f}{:>11.0f}{:>15.1f}{:>8.1f}".format(*row))
    print(load.text())
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    raise SystemExit(main())

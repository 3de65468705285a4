"""Benchmark: a 1-hour drive (UDDS repeated, 1 s step) of every architecture with a whole pack
(issue 24, "Pack in the vehicle" speed row), against the series HEV measured in the same run.

Cases (every cell simulated with its spread, each cell's port at its plate's coolant + the
cooling loop, ``thermal = "coolant"``):

* BEV, 1200 cells: examples/bev_pack.toml with 50 modules of 2s12p (the shipped pack is 2s8p,
  800 cells) — through the Python forward loop (hevsim.sim.forward) as every forward architecture;
* BEV, the shipped 800-cell pack, and with ``cells = "representative"`` (50 simulated cells);
* power split (examples/prius_like_power_split_pack.toml, 80 cells) and parallel P3
  (examples/parallel_hev_pack.toml, 600 cells);
* peer: the series HEV (examples/series_hev_pack.toml, compiled kernel with the pack's compiled
  step inside) with 100 thesis 2s6p modules = 1200 cells, coolant ports, the same hour.

Prints the best of ``--repeat`` runs after one warm-up (wall and CPU seconds, the other
processes' load) and each case's ratio to the series HEV.

    python benchmarks/bench_pack_architectures.py [--repeat 2]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_pack_vehicle import hour_cycle, timed
from hevsim.config import load_vehicle_config
from hevsim.sim.pack_vehicle import simulate_pack_vehicle

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"


def copy_case(folder: Path, vehicle: str, pack: str, edits: dict[str, str], tag: str) -> Path:
    """Copies of a shipped pack vehicle and its pack file (with text edits) in ``folder``."""
    text = (EX / pack).read_text()
    text = text.replace(
        'thermal_config = "module_thermal.toml"', f'thermal_config = "{EX / "module_thermal.toml"}"'
    )
    for old, new in edits.items():
        assert old in text, old
        text = text.replace(old, new)
    (folder / f"{tag}_{pack}").write_text(text)
    veh = (EX / vehicle).read_text().replace(f'pack = "{pack}"', f'pack = "{tag}_{pack}"')
    veh = veh.replace("bus_max_v = 450.0", "bus_max_v = 1000.0")  # the series peer: 200 cells in series
    path = folder / f"{tag}_{vehicle}"
    path.write_text(veh)
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    cyc = hour_cycle()
    rep = {"capacity_spread = 0.02": "capacity_spread = 0.0",
           "resistance_spread = 0.05": "resistance_spread = 0.0",
           '# cells = "representative"': 'cells = "representative"'}  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        cases = {
            "series HEV, 1200 cells (compiled kernel; peer)": copy_case(
                folder,
                "series_hev_pack.toml",
                "vehicle_pack.toml",
                {"n_modules = 50": "n_modules = 100"},
                "s1200",
            ),
            "BEV, 1200 cells (50 x 2s12p)": copy_case(
                folder, "bev_pack.toml", "bev_battery.toml", {"n_parallel = 8 ": "n_parallel = 12 "}, "b1200"
            ),
            "BEV, 800 cells (shipped, 50 x 2s8p)": copy_case(
                folder, "bev_pack.toml", "bev_battery.toml", {}, "b800"
            ),
            "BEV, representative cell per module (50 cells)": copy_case(
                folder, "bev_pack.toml", "bev_battery.toml", rep, "brep"
            ),
            "power split, 80 cells": copy_case(
                folder, "prius_like_power_split_pack.toml", "prius_like_battery.toml", {}, "ps"
            ),
            "parallel P3, 600 cells": copy_case(
                folder, "parallel_hev_pack.toml", "vehicle_pack.toml", {}, "p3"
            ),
        }
        print(
            f"1-hour drive ({cyc.name}, {len(cyc.time_s) - 1} steps of 1 s), "
            f"best of {args.repeat} after a warm-up:"
        )
        times = {}
        for label, path in cases.items():
            cfg = load_vehicle_config(path)
            times[label] = timed(label, lambda cfg=cfg: simulate_pack_vehicle(cfg, cyc, 1.0), args.repeat)
        peer = next(iter(times.values()))
        print("CPU time / the series HEV's (same run):")
        for label, t in times.items():
            print(f"  {label:<58} {t / peer:7.2f}x")


if __name__ == "__main__":
    main()

"""Fuel economy of the series HEV (``examples/series_hev.toml``) under each of its controllers.

Run from the repository root (or anywhere; paths are resolved from this file)::

    .venv/bin/python benchmarks/series_controllers.py [--cycles udds hwfet wltc3b]

For every cycle: the rule-based thermostat (the compiled series kernel, its proportional
driver), ECMS with the equivalence factor of the DP's costate (``ecms_from_dp``: median of
``-costate x LHV / (Q OCV)``), adaptive ECMS (the configured ``s0``, no knowledge of the
cycle) and the DP optimum itself (charge sustaining, default grids 201 SOC x 101 genset
powers), which ECMS and A-ECMS score over the same 101 genset powers in the forward loop of
``hevsim.sim.forward``. Prints MPG, SOC-corrected MPGGE, final SOC, the SOC-corrected fuel as
a ratio of the DP's and each run's wall time. Reports and never asserts: always exits 0.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from hevsim.config import load_vehicle_config
from hevsim.control.parallel import ecms_from_dp
from hevsim.optimal import optimize
from hevsim.sim.model import build_series_hev
from hevsim.sim.simulator import simulate

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", nargs="+", default=["udds", "hwfet", "wltc3b"])
    args = ap.parse_args()
    hev = build_series_hev(load_vehicle_config(ROOT / "examples" / "series_hev.toml"))
    load0 = os.getloadavg()[0]
    print(
        f"{'cycle':<8}{'controller':<34}{'MPG':>7}{'MPGGE':>8}{'SOC end':>9}{'fuel_eq/DP':>11}{'wall s':>8}"
    )
    for cycle in args.cycles:
        t = time.perf_counter()
        dp = optimize(hev, cycle, progress=False)
        t_dp = time.perf_counter() - t
        s = ecms_from_dp(dp)
        runs = []
        ecms = f"ECMS (s = {s['equivalence_factor']:.3f} from DP)"
        controllers = (("rule-based (thermostat)", {}), (ecms, {"controller": "ecms", **s}),
                       ("A-ECMS", {"controller": "aecms"}))  # fmt: skip
        for label, kw in controllers:
            t = time.perf_counter()
            r = simulate(hev, cycle, **kw)
            runs.append((label, r.metrics, time.perf_counter() - t))
        runs.append(("DP (charge sustaining)", dp.metrics, t_dp))
        ref = float(dp.metrics["fuel_equivalent_kg"]["value"])
        for label, m, wall in runs:
            print(f"{cycle:<8}{label:<34}{m['mpg']['value']:>7.1f}{m['mpgge']['value']:>8.1f}"
                  f"{m['soc_final']['value']:>9.3f}{m['fuel_equivalent_kg']['value'] / ref:>11.4f}"
                  f"{wall:>8.2f}", flush=True)  # fmt: skip
    print(f"load average {load0:.1f} -> {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores "
          f"(numpy {np.__version__})")  # fmt: skip


if __name__ == "__main__":
    main()

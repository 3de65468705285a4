"""Speed of the laminar channel-flow solve (issue 19, "laminar flow solve on the default plate <= 60 s").

Run from the repository root::

    .venv/bin/python benchmarks/bench_flow.py [--flow-l-min 0.3] [--cells-across-width 4]

Solves steady Navier-Stokes (P2/P1, Newton with Re continuation) in the default plate's
3-pass serpentine channel at a laminar flow rate (the shipped 10 L/min is turbulent and
refused) and reports the wall time of the solve (mesh, assembly, all linear solves), the
pressure drop, pump power and mass balance. The baseline measured in the same run is one
Stokes solve on the same mesh (one assembly + one sparse LU), so the ratio shows the cost of
the nonlinear iterations. The script only reports: it always exits 0.
"""

from __future__ import annotations

import argparse
import dataclasses
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import OtherLoad

TARGET_SOLVE_S = 60.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--flow-l-min", type=float, default=0.3, help="inlet flow rate [L/min] (Re ~ 104)")
    ap.add_argument("--cells-across-width", type=int, default=4)
    ap.add_argument("--cells-across-height", type=int, default=2)
    ap.add_argument("--cell-length", type=float, default=0.002, help="element length along the channel [m]")
    args = ap.parse_args()

    from hevsim.thermal.coolant import Coolant
    from hevsim.thermal.flow import L_MIN_TO_M3_S, FlowSection, format_flow, plate_channel, solve_flow
    from hevsim.thermal.geometry import ModuleGeometry

    sec = FlowSection(
        cells_across_width=args.cells_across_width,
        cells_across_height=args.cells_across_height,
        cell_length_m=args.cell_length,
    )
    ch = plate_channel(ModuleGeometry())
    with OtherLoad() as load:
        t0 = time.perf_counter()
        # baseline: Stokes (density ~0 -> Re ~0: one linear solve after the Stokes start)
        stokes = Coolant(density_kg_m3=1e-12)
        solve_flow(
            ch, stokes, args.flow_l_min * L_MIN_TO_M3_S, section=dataclasses.replace(sec, picard_iterations=0)
        )
        t_base = time.perf_counter() - t0
        t0 = time.perf_counter()
        res = solve_flow(ch, Coolant(), args.flow_l_min * L_MIN_TO_M3_S, section=sec)
        t_solve = time.perf_counter() - t0
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(format_flow(res))
    print(f"Newton updates: {', '.join(f'{h:.1e}' for h in res.history)}")
    print(f"baseline (Stokes, 2 linear solves): {t_base:.2f} s")
    print(
        f"laminar solve: {t_solve:.2f} s (target <= {TARGET_SOLVE_S:g} s: "
        f"{'met' if t_solve <= TARGET_SOLVE_S else 'NOT met'}); ratio to baseline {t_solve / t_base:.1f}"
    )
    print(f"peak resident memory {peak_gb:.2f} GB")
    print(load.text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Mesh study of the local Nusselt number of the 3-D laminar coolant (issue 19): a straight
8 x 4 mm duct, developed inflow at Re 1 (Pe 65), wall at 300 K, inlet at 290 K, on meshes
refined together across and along the duct. Prints per mesh the local Nusselt number at a few
stations, the thermally developed value against Shah & London's Nu_T = 3.391 (aspect 1/2,
R. K. Shah and A. L. London, *Laminar Flow Forced Convection in Ducts*, 1978, Table 45), the
observed order of convergence, the energy balance and the CPU time of each level.

Run from the repository root::

    .venv/bin/python benchmarks/bench_cht_nusselt_mesh.py [--levels 4]

Only reports (always exits 0); the machine's load is printed with the figures.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import OtherLoad

WIDTH_M, HEIGHT_M, LENGTH_M = 0.008, 0.004, 0.06
DH_M = 2 * WIDTH_M * HEIGHT_M / (WIDTH_M + HEIGHT_M)
#: Shah & London (1978), Table 45: Nu_T of a rectangular duct of aspect ratio 1/2.
NU_T = 3.391
#: Meshes: cells across the width, across the height, cell length along the duct [m].
MESHES = ((4, 2, 0.003), (6, 3, 0.002), (8, 4, 0.0015), (12, 6, 0.001))
#: Wall segments: 6 mm each, a whole number of cells on every mesh [-].
SEGMENTS = 10
#: Stations [m] where the local Nusselt number is printed, and the developed window [m].
STATIONS_M = (0.003, 0.009, 0.021, 0.045)
DEVELOPED_M = (0.036, 0.048)


def level(cells: tuple[int, int, float]) -> dict[str, Any]:
    """Nusselt figures of one mesh."""
    from hevsim.thermal.cht import CoolantThermal
    from hevsim.thermal.coolant import Coolant
    from hevsim.thermal.flow import FlowSection, duct_channel, solve_flow

    c0 = time.process_time()
    c = Coolant()
    ch = duct_channel(LENGTH_M, WIDTH_M, HEIGHT_M)
    q = 1.0 * c.viscosity_pa_s / (c.density_kg_m3 * DH_M) * WIDTH_M * HEIGHT_M  # Re 1
    sec = FlowSection(
        channel="duct", cells_across_width=cells[0], cells_across_height=cells[1], cell_length_m=cells[2]
    )
    flow = solve_flow(ch, c, q, section=sec)
    path = np.array([[0.0, WIDTH_M / 2, HEIGHT_M / 2], [LENGTH_M, WIDTH_M / 2, HEIGHT_M / 2]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = CoolantThermal(flow, ch, c, path, SEGMENTS)
    tw, t_in = np.full(SEGMENTS, 300.0), 290.0
    t, heat = model.solve(tw, t_in)
    local = model.local_film(tw, t_in, heat)
    tb = local["bulk_temp_k"]
    seg_m = LENGTH_M / SEGMENTS
    i0, i1 = round(DEVELOPED_M[0] / seg_m), round(DEVELOPED_M[1] / seg_m)
    h = (
        model.capacity_rate_w_k
        / model.wall_area_m2[i0:i1].sum()
        * math.log((300.0 - tb[i0]) / (300.0 - tb[i1]))
    )
    rise = model.capacity_rate_w_k * (model.outlet_temp_k(t) - t_in)
    return {
        "dofs": float(model.basis.N),
        "local": np.array([local["nusselt"][int(x / seg_m)] for x in STATIONS_M]),
        "developed": h * DH_M / c.conductivity_w_mk,
        "imbalance": abs(heat.sum() / rise - 1.0),
        "cpu_s": time.process_time() - c0,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--levels", type=int, default=len(MESHES), help="number of meshes (coarsest first)")
    args = ap.parse_args()
    rows = []
    with OtherLoad() as load:
        for cells in MESHES[: args.levels]:
            rows.append((cells, level(cells)))
    head = " ".join(f"Nu@{x * 1e3:.1f}mm" for x in STATIONS_M)
    print(f"{'mesh (w x h, dx)':>20s} {'T dofs':>7s} {head}  Nu_dev  err(S&L)  imbalance  CPU")
    for cells, r in rows:
        loc = " ".join(f"{v:10.3f}" for v in r["local"])
        dev = r["developed"]
        print(
            f"{cells[0]:>6d} x {cells[1]:<2d} {cells[2] * 1e3:4.1f} mm {r['dofs']:7.0f} {loc}  {dev:6.3f} "
            f"{(dev / NU_T - 1) * 100:+7.2f} %  {r['imbalance']:9.1e} {r['cpu_s']:5.1f} s"
        )
    for (c1, r1), (c2, r2) in itertools.pairwise(rows):
        e1, e2 = abs(r1["developed"] / NU_T - 1), abs(r2["developed"] / NU_T - 1)
        p = math.log(e1 / e2) / math.log(c2[1] / c1[1]) if e1 > 0 and e2 > 0 else float("nan")
        change = " ".join(f"{v:+.3f}" for v in r2["local"] - r1["local"])
        print(
            f"{c1[1]} -> {c2[1]} cells across: local Nu changes by {change}; observed order of the "
            f"developed Nu error {p:.2f} (meaningful once the error falls monotonically)"
        )
    print(f"Shah & London Nu_T (aspect 1/2) = {NU_T}")
    print(load.text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

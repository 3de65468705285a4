"""Speed and memory of the module heat model (issue 5, item 7).

Run from the repository root::

    .venv/bin/python benchmarks/bench_thermal.py [--mesh-size 0.0025] [--steps 300]

A ~25 000-node module mesh (the size of the thesis's Standard.inp), 300 s at 1 s steps with
the 1-D coolant channel coupled every step. Meshing, assembly + factorisation and the time
loop are timed separately (``time.perf_counter``); the target is the time loop <= 10 s and
peak resident memory <= 2 GB. The baseline measured in the same run is 300 bare
back-substitutions with the same factors, so the ratio shows the coupling/observation
overhead. The script only reports: it always exits 0.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import OtherLoad

TARGET_SOLVE_S = 10.0
TARGET_PEAK_GB = 2.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh-size", type=float, default=0.0028, help="gmsh mesh size [m]")
    ap.add_argument("--steps", type=int, default=300, help="1 s steps")
    args = ap.parse_args()

    from hevsim.thermal.coolant import ChannelModel, segments_along_path
    from hevsim.thermal.geometry import ModuleGeometry, build_module_mesh
    from hevsim.thermal.materials import DEFAULT_PART_MATERIALS, TABLE_4_3
    from hevsim.thermal.mesh import CHANNEL_WALL
    from hevsim.thermal.solver import HeatModel, discretise

    geom = ModuleGeometry(mesh_size_m=args.mesh_size)
    t0 = time.perf_counter()
    mesh = build_module_mesh(geom)
    t_mesh = time.perf_counter() - t0
    with OtherLoad() as load:
        t0 = time.perf_counter()
        wall = mesh.facet_groups[CHANNEL_WALL]
        assert mesh.channel_path_m is not None
        seg = segments_along_path(mesh.points_m[wall].mean(axis=1), mesh.channel_path_m, 30)
        seg = np.searchsorted(np.unique(seg), seg)
        mats = {p: TABLE_4_3[DEFAULT_PART_MATERIALS[p]] for p in mesh.part_names}
        disc = discretise(mesh, mats, ambient_k=303.15, wall_segment_of_facet=seg)
        ch = ChannelModel(
            int(seg.max()) + 1,
            inlet_temp_k=288.15,
            flow_m3_s=10 / 60000,
            width_m=geom.channel_width_m,
            height_m=geom.channel_height_m,
        )
        model = HeatModel(disc, dt_s=1.0, initial_temp_k=303.15, coolant=ch)
        t_setup = time.perf_counter() - t0
        rng = np.random.default_rng(0)
        t0 = time.perf_counter()
        for _ in range(args.steps):
            model.set_cell_heat_w(1.0 + 0.5 * rng.random(mesh.n_cells))  # updated from outside each step
            model.step()
        t_solve = time.perf_counter() - t0
        b = model.temp_k.copy()
        t0 = time.perf_counter()
        for _ in range(args.steps):
            b = model._lu.solve(b)
        t_base = time.perf_counter() - t0
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    print(
        f"mesh: {mesh.points_m.shape[0]} nodes ({disc.points_m.shape[0]} after splitting at contacts), "
        f"{mesh.tets.shape[0]} tetrahedra, size {args.mesh_size} m"
    )
    print(f"meshing (gmsh, 1 thread)           {t_mesh:8.2f} s (excluded from the target)")
    print(f"assembly + factorisation           {t_setup:8.2f} s")
    print(
        f"time loop, {args.steps} steps, coolant coupled {t_solve:8.2f} s  "
        f"({1e3 * t_solve / args.steps:.1f} ms/step)"
        f"  target <= {TARGET_SOLVE_S:.0f} s: {'PASS' if t_solve <= TARGET_SOLVE_S else 'FAIL'}"
    )
    print(
        f"baseline: {args.steps} bare splu solves        {t_base:8.2f} s  "
        f"ratio loop/baseline {t_solve / t_base:.2f}"
    )
    print(
        f"peak resident memory               {peak_gb:8.3f} GB  target <= {TARGET_PEAK_GB:.0f} GB: "
        f"{'PASS' if peak_gb <= TARGET_PEAK_GB else 'FAIL'}"
    )
    print(
        f"coolant outlet {ch.outlet_temp_k - 273.15:.3f} °C, heat to coolant {ch.heat_w:.2f} W, "
        f"max temperature {model.temp_k.max() - 273.15:.2f} °C"
    )
    print(load.text())
    return 0


if __name__ == "__main__":
    sys.exit(main())

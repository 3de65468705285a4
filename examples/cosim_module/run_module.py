"""The thesis's battery-module co-simulation (sections 4.1.4, 4.3), open-source edition.

2s6p module of the thesis cell (hevsim's electro-thermal module, in process; the same model
exported as an FMU runs in its place through ``export_fmu``) under a high-frequency
high-load square power cycle, coupled Gauss-Seidel with the FEM module and its coolant
channel cell by cell: each cell's port heat into its FEM cell, each FEM cell's mean
temperature back to that cell's thermal port. Module initially at 30 degC, coolant inlet at
15 degC, 300 s.

Run:  .venv/bin/python examples/cosim_module/run_module.py [OUT_DIR] [--duration 300]
(or, once wired, ``hevsim cosim examples/cosim_module/module.ssd --out OUT_DIR``)
Writes OUT_DIR/system.ssd, results.csv, summary.json and pictures/*.png (see docs/cosim.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hevsim.cosim import Connection
from hevsim.cosim.config import PY_TYPE, Component, SystemDescription, run_cosim, write_ssd

HERE = Path(__file__).resolve().parent
N_CELLS = 12  # 2s6p, the FEM module's 2 x 6 cells


def module_system(
    duration_s: float = 300.0, step_s: float = 1.0, mesh_size_m: float | None = None
) -> SystemDescription:
    """The coupled system as an SSP description."""
    fem_params: dict[str, object] = {"config": "../module_thermal.toml"}  # relative to the SSD
    if mesh_size_m is not None:
        fem_params["mesh_size_m"] = mesh_size_m
    comps = [
        Component("load", PY_TYPE, "hevsim.cosim.library:power_cycle",
                  parameters={"discharge_w": 250.0, "charge_w": 150.0, "period_s": 10.0}),
        Component("battery", PY_TYPE, "hevsim.cosim.participant:ModuleCellsParticipant",
                  parameters={"params": "thesis_table_4_1", "soc_initial": 0.9, "temp_initial_k": 303.15,
                              "n_series": 2, "n_parallel": 6, "power_input": True}),
        Component("fem", PY_TYPE, "hevsim.cosim.fem:FemModuleParticipant", parameters=fem_params),
    ]  # fmt: skip
    # cell c of the module (series group c // 6, branch c % 6) is FEM cell c (row c // 6,
    # column c % 6): its port heat goes into that cell, that cell's mean temperature comes back
    conns = [Connection("load", "power_w", "battery", "power_w")]
    for c in range(N_CELLS):
        conns.append(Connection("battery", f"cell{c}_port_heat_w", "fem", f"cell{c}_heat_w"))
        conns.append(Connection("fem", f"cell{c}_temp_k", "battery", f"cell{c}_port_temp_k"))
    master = {"algorithm": "gauss-seidel", "step_s": step_s, "order": ["load", "battery", "fem"]}
    return SystemDescription("cosim_module", comps, conns, 0.0, duration_s, master, base_dir=HERE)


def write_shipped() -> Path:
    """(Re)write ``module.ssd`` next to this script."""
    return write_ssd(module_system(), HERE / "module.ssd")


def main() -> None:
    ap = argparse.ArgumentParser(description="thesis battery-module co-simulation")
    ap.add_argument("out", nargs="?", default="results/cosim_module")
    ap.add_argument("--duration", type=float, default=300.0)
    a = ap.parse_args()
    out = Path(a.out)
    # the shipped description for the thesis case, else the same system built in Python
    res = run_cosim(HERE / "module.ssd" if a.duration == 300.0 else module_system(a.duration), out)
    for k in ("fem.cell_max_temp_k", "fem.outlet_temp_k", "fem.cooling_power_w", "battery.voltage_v"):
        print(f"{k:24s} final {res[k][-1]:10.3f}  max {res[k].max():10.3f}")
    final = [res[f"fem.cell{c}_temp_k"][-1] for c in range(N_CELLS)]
    peak = [res[f"fem.cell{c}_temp_k"].max() for c in range(N_CELLS)]
    hot = max(range(N_CELLS), key=lambda c: final[c])
    print(
        f"hottest cell at the end: {hot} ({final[hot] - 273.15:.3f} degC); cell means "
        f"{min(final) - 273.15:.3f} .. {max(final) - 273.15:.3f} degC, peak {max(peak) - 273.15:.3f} degC"
    )
    print(f"wall time {res.stats['wall_s']:.1f} s, {res.stats['steps']} communication steps")


if __name__ == "__main__":
    main()

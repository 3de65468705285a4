"""The thesis's battery-module co-simulation (sections 4.1.4, 4.3), open-source edition.

Four participants, as in the thesis (Dymola FMU, Abaqus/Standard, Abaqus/CFD, one load):

* ``load``: a high-frequency high-load square power cycle (250 W discharge / 150 W charge);
* ``battery``: the 2s6p module of the thesis cell as an FMI 2.0 co-simulation FMU exported by
  ``hevsim export-fmu`` (``module_2s6p.fmu``, run in a worker process through FMPy) with one
  thermal port per cell (``per_cell_ports``);
* ``fem``: the 3D finite-element module (cells, holder, cooling plate, ...): each cell's port
  heat into its FEM cell, each FEM cell's mean temperature back to that cell's port;
* ``coolant``: the 1-D coolant channel: the plate's wall temperature per channel segment in,
  heat flux and film coefficient (the thesis's lumped heat capacitance) out.

Gauss-Seidel in the order load, battery, fem, coolant; 1 s exchange; module initially at
30 degC, coolant inlet at 15 degC, 300 s.

Run:  hevsim cosim examples/cosim_module/module.ssd --out OUT_DIR
  or  .venv/bin/python examples/cosim_module/run_module.py [OUT_DIR] [--duration 300]
Rebuild the shipped files (module.ssd and module_2s6p.fmu) after changing the model:
      .venv/bin/python examples/cosim_module/run_module.py --write-shipped
Writes OUT_DIR/system.ssd, results.csv, summary.json, fields/ and pictures/*.png
(see docs/cosim.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hevsim.cosim import Connection
from hevsim.cosim.ssd import FMU_TYPE, PY_TYPE, Component, SystemDescription
from hevsim.cosim.ssp_write import write_ssd
from hevsim.cosim.system import run_cosim

HERE = Path(__file__).resolve().parent
N_CELLS = 12  # 2s6p, the FEM module's 2 x 6 cells
FMU = "module_2s6p.fmu"
#: the module's cell parameters and initial state (FMU defaults and parameters)
BATTERY = {"params": "thesis_table_4_1", "soc_initial": 0.9, "temp_initial_k": 303.15, "n_series": 2,
           "n_parallel": 6}  # fmt: skip


def module_system(
    duration_s: float = 300.0,
    step_s: float = 1.0,
    mesh_size_m: float | None = None,
    battery: str = "fmu",
) -> SystemDescription:
    """The coupled system as an SSP description; ``battery="inprocess"`` puts hevsim's module
    in process (:class:`hevsim.cosim.participant.ModuleCellsParticipant`) instead of the FMU."""
    from hevsim.thermal.run import load_thermal_config

    config = "../module_thermal.toml"  # relative to the SSD
    segments = load_thermal_config(HERE / config).coolant.segments
    fem_params: dict[str, object] = {"config": config, "coolant": "external"}
    if mesh_size_m is not None:
        fem_params["mesh_size_m"] = mesh_size_m
    if battery == "fmu":
        bat = Component("battery", FMU_TYPE, FMU, parameters={
            "power_input": True, "per_cell_ports": True,
            "soc_initial": BATTERY["soc_initial"], "temp_initial_k": BATTERY["temp_initial_k"]})  # fmt: skip
    else:
        bat = Component("battery", PY_TYPE, "hevsim.cosim.participant:ModuleCellsParticipant",
                        parameters={**BATTERY, "power_input": True})  # fmt: skip
    comps = [
        Component("load", PY_TYPE, "hevsim.cosim.library:power_cycle",
                  parameters={"discharge_w": 250.0, "charge_w": 150.0, "period_s": 10.0}),
        bat,
        Component("fem", PY_TYPE, "hevsim.cosim.fem:FemModuleParticipant", parameters=fem_params),
        Component("coolant", PY_TYPE, "hevsim.cosim.coolant:CoolantChannelParticipant",
                  parameters={"config": config}),
    ]  # fmt: skip
    # cell c of the module (series group c // 6, branch c % 6) is FEM cell c (row c // 6,
    # column c % 6): its port heat goes into that cell, that cell's mean temperature comes back
    conns = [Connection("load", "power_w", "battery", "power_w")]
    for c in range(N_CELLS):
        conns.append(Connection("battery", f"cell{c}_port_heat_w", "fem", f"cell{c}_heat_w"))
        conns.append(Connection("fem", f"cell{c}_temp_k", "battery", f"cell{c}_port_temp_k"))
    for j in range(segments):
        conns.append(Connection("fem", f"wall{j}_temp_k", "coolant", f"wall{j}_temp_k"))
        conns.append(Connection("fem", f"wall{j}_area_m2", "coolant", f"wall{j}_area_m2"))
        conns.append(Connection("coolant", f"wall{j}_heat_flux_w_m2", "fem", f"wall{j}_heat_flux_w_m2"))
        conns.append(Connection("coolant", f"wall{j}_film_w_m2k", "fem", f"wall{j}_film_w_m2k"))
    master = {"algorithm": "gauss-seidel", "step_s": step_s, "order": ["load", "battery", "fem", "coolant"]}
    return SystemDescription("cosim_module", comps, conns, 0.0, duration_s, master, base_dir=HERE)


def export_module_fmu(out: Path | None = None) -> Path:
    """Export the module FMU the example runs (``module_2s6p.fmu`` next to this script)."""
    from hevsim.battery.fmu import export_fmu

    b = BATTERY
    return export_fmu(b["params"], out or HERE / FMU, soc_initial=b["soc_initial"],
                      temp_initial_k=b["temp_initial_k"], n_series=b["n_series"], n_parallel=b["n_parallel"],
                      model_name="HevsimModule2s6p")  # fmt: skip


def write_shipped() -> Path:
    """(Re)write ``module.ssd`` and ``module_2s6p.fmu`` next to this script."""
    export_module_fmu()
    return write_ssd(module_system(), HERE / "module.ssd")


def main() -> None:
    ap = argparse.ArgumentParser(description="thesis battery-module co-simulation")
    ap.add_argument("out", nargs="?", default="results/cosim_module")
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--write-shipped", action="store_true", help="rewrite module.ssd and the FMU, then exit")
    a = ap.parse_args()
    if a.write_shipped:
        print(f"wrote {write_shipped()} and {HERE / FMU}")
        return
    out = Path(a.out)
    # the shipped description for the thesis case, else the same system built in Python
    res = run_cosim(HERE / "module.ssd" if a.duration == 300.0 else module_system(a.duration), out)
    for k in (
        "fem.cell_max_temp_k",
        "fem.plate_max_temp_k",
        "coolant.outlet_temp_k",
        "coolant.cooling_power_w",
        "battery.voltage_v",
    ):
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

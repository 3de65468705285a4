"""The thesis's battery-module co-simulation (sections 4.1.4, 4.3), open-source edition.

Four participants, as in the thesis (Dymola FMU, Abaqus/Standard, Abaqus/CFD, one load):

* ``load``: a high-frequency high-load square power cycle (250 W discharge / 150 W charge);
* ``battery``: the 2s6p module of the thesis cell as a native (compiled C99) FMI 2.0
  co-simulation FMU exported by ``hevsim export-fmu --native`` (``module_2s6p.fmu``, run in a
  worker process through FMPy) with one thermal port per cell (``per_cell_ports``);
* ``fem``: the 3D finite-element module (cells, holder, cooling plate, ...): each cell's port
  heat into its FEM cell, each FEM cell's mean temperature back to that cell's port;
* ``coolant``: the 1-D coolant channel: the plate's wall temperature per channel segment in,
  heat flux and film coefficient (the thesis's lumped heat capacitance) out.

Gauss-Seidel in the order load, battery, fem, coolant; 1 s exchange; module initially at
30 degC, coolant inlet at 15 degC, 300 s.

The FMU is not in git: it is built from today's code and data for this machine, at first use
by this script (and again whenever it is stale, i.e. its GUID, a hash of its generated sources,
differs from a fresh export's) or by ``make examples`` (= ``run_module.py --build-fmu``).

Run:  .venv/bin/python examples/cosim_module/run_module.py [OUT_DIR] [--duration 300]
  or  make examples && hevsim cosim examples/cosim_module/module.ssd --out OUT_DIR
Rewrite the shipped module.ssd after changing the system (and rebuild the FMU):
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
    base_dir: Path = HERE,
) -> SystemDescription:
    """The coupled system as an SSP description; ``battery="inprocess"`` puts hevsim's module
    in process (:class:`hevsim.cosim.participant.ModuleCellsParticipant`) instead of the FMU.
    ``base_dir``: the folder the SSD's relative paths (the FMU, ``../module_thermal.toml``)
    start from (a copy of ``examples/cosim_module``)."""
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
    return SystemDescription("cosim_module", comps, conns, 0.0, duration_s, master, base_dir=base_dir)


def export_module_fmu(out: Path) -> Path:
    """Export the native module FMU the example runs to ``out`` (atomically)."""
    from hevsim.battery.native import export_native_fmu

    b = BATTERY
    return export_native_fmu(b["params"], out, soc_initial=b["soc_initial"],
                             temp_initial_k=b["temp_initial_k"], n_series=b["n_series"],
                             n_parallel=b["n_parallel"], model_name="HevsimModule2s6p")  # fmt: skip


def fmu_guid(path: Path) -> str | None:
    """The ``guid`` of the FMU at ``path`` (None: no file, or not a readable FMU)."""
    from fmpy import read_model_description

    if not path.is_file():
        return None
    try:
        return str(read_model_description(str(path)).guid)
    except Exception:  # unreadable: stale, rebuild
        return None


def build_fmu(folder: Path = HERE) -> tuple[Path, bool]:
    """Build ``folder/module_2s6p.fmu`` if it is missing or stale: export a fresh FMU to a
    temporary file and keep the existing one only if its GUID (a hash of the generated model
    data and C sources) is the same. Returns the FMU path and whether it was (re)written."""
    import tempfile

    from hevsim.io import copy_file_atomic

    out = folder / FMU
    with tempfile.TemporaryDirectory() as tmp:
        fresh = export_module_fmu(Path(tmp) / FMU)
        if fmu_guid(out) == fmu_guid(fresh):
            return out, False
        copy_file_atomic(fresh, out)
    return out, True


def write_shipped() -> Path:
    """(Re)write ``module.ssd`` next to this script (and build the FMU if needed)."""
    build_fmu()
    return write_ssd(module_system(), HERE / "module.ssd")


def main() -> None:
    ap = argparse.ArgumentParser(description="thesis battery-module co-simulation")
    ap.add_argument("out", nargs="?", default="results/cosim_module")
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument(
        "--write-shipped", action="store_true", help="rewrite module.ssd (and build the FMU), then exit"
    )
    ap.add_argument(
        "--build-fmu", action="store_true", help="build the module FMU if missing or stale, then exit"
    )
    a = ap.parse_args()
    if a.write_shipped:
        print(f"wrote {write_shipped()}")
        return
    fmu, built = build_fmu()
    print(f"{'built' if built else 'up to date:'} {fmu}")
    if a.build_fmu:
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

"""The thesis's battery-module co-simulation (sections 4.1.4, 4.3), open-source edition.

2s6p module of the thesis cell (hevsim's electro-thermal module, in process; the same model
exported as an FMU runs in its place through ``export_fmu``) under a high-frequency
high-load square power cycle, coupled Gauss-Seidel with the FEM module and its coolant
channel cell by cell: each cell's port heat into its FEM cell, each FEM cell's mean
temperature back to that cell's thermal port. Module initially at 30 degC, coolant inlet at
15 degC, 300 s.

Run:  .venv/bin/python examples/cosim_module/run_module.py [OUT_DIR] [--duration 300]
(or, once wired, ``hevsim cosim examples/cosim_module/module.ssd --out OUT_DIR``)
Writes OUT_DIR/system.ssd, results.csv, summary.json (see docs/cosim.md) and
OUT_DIR/pictures/*.png.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hevsim.cosim import Connection, CosimResult
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


def plot_results(res: CosimResult, out_dir: str | Path) -> list[Path]:
    """PNG pictures: module current and voltage (thesis figs 4.33-4.34), coolant outlet
    temperature (fig 4.31), cooling power, and the cells' final mean temperatures seen from
    above with the hottest cell marked (fig 4.32's hot spots, per cell)."""
    from matplotlib.figure import Figure

    from hevsim.thermal.run import load_thermal_config

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t = res.time_s
    made = []
    series = [
        ("module_current_voltage.png",
         [("battery.current_a", "current [A]"), ("battery.voltage_v", "voltage [V]")]),
        ("coolant_outlet.png", [("fem.outlet_temp_k", "outlet temperature [degC]")]),
        ("cooling_power.png", [("fem.cooling_power_w", "cooling power [W]")]),
        ("cell_temperature.png", [("fem.cell_max_temp_k", "hottest cell node [degC]"),
                                  ("fem.cell_mean_temp_k", "mean cell [degC]")]),
    ]  # fmt: skip
    for name, cols in series:
        fig = Figure(figsize=(7, 2.4 * len(cols)), dpi=100)
        for i, (col, label) in enumerate(cols):
            ax = fig.add_subplot(len(cols), 1, i + 1)
            y = res[col] - (273.15 if col.endswith("_k") else 0.0)
            ax.plot(t, y)
            ax.set_ylabel(label)
            ax.grid(True)
        ax.set_xlabel("time [s]")
        fig.tight_layout()
        fig.savefig(out / name)
        made.append(out / name)
    g = load_thermal_config(HERE.parent / "module_thermal.toml").geometry
    temps = [res[f"fem.cell{i}_temp_k"][-1] - 273.15 for i in range(g.rows * g.columns)]
    fig = Figure(figsize=(8, 3.5), dpi=100)
    ax = fig.add_subplot()
    hot = int(max(range(len(temps)), key=lambda i: temps[i]))
    for i, temp in enumerate(temps):
        x, y = g.cell_centre_xy_m(i // g.columns, i % g.columns)
        edge = "cyan" if i == hot else "none"
        lo, hi = min(temps), max(temps) + 1e-9
        ax.scatter([x * 1e3], [y * 1e3], s=900, c=[temp], cmap="inferno", vmin=lo, vmax=hi, edgecolors=edge)
        ax.annotate(f"{temp:.3f}", (x * 1e3, y * 1e3), ha="center", va="center", fontsize=7, color="grey")
    pitch_mm = g.cell_pitch_m * 1e3
    xs = [g.cell_centre_xy_m(0, c)[0] * 1e3 for c in (0, g.columns - 1)]
    ys = [g.cell_centre_xy_m(r, 0)[1] * 1e3 for r in (0, g.rows - 1)]
    ax.set_xlim(xs[0] - pitch_mm, xs[1] + pitch_mm)
    ax.set_ylim(ys[0] - pitch_mm, ys[1] + pitch_mm)
    ax.set_aspect("equal")
    ax.set_title(f"final cell mean temperature [degC], hottest cell {hot} outlined")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    fig.savefig(out / "cell_temperatures_top.png")
    made.append(out / "cell_temperatures_top.png")
    return made


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
    plot_results(res, out / "pictures")
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

"""Pictures of a co-simulation result (thesis figs 4.30-4.34 for the module case).

Whatever the system, :func:`plot_cosim` draws the recognised signals it finds: module
current and voltage, coolant outlet temperature, cooling power, cell temperatures, and — for
an FEM module participant — the cells' final mean temperatures seen from above with the
hottest cell outlined.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from hevsim.units import KELVIN_OFFSET

FEM_SOURCE = "hevsim.cosim.fem:FemModuleParticipant"

# (file name, [(variable suffix, axis label)]) per picture; drawn for every component that has them
SERIES = (
    ("current_voltage", (("current_a", "current [A]"), ("voltage_v", "voltage [V]"))),
    ("coolant_outlet", (("outlet_temp_k", "outlet temperature [°C]"),)),
    ("cooling_power", (("cooling_power_w", "cooling power [W]"),)),
    (
        "cell_temperature",
        (("cell_max_temp_k", "hottest cell node [°C]"), ("cell_mean_temp_k", "mean cell [°C]")),
    ),
)


def _series_figure(res: Any, component: str, cols: tuple[tuple[str, str], ...], path: Path) -> Path:
    from hevsim.report.plots import _figure, _grid, _save

    fig, axes = _figure(len(cols), 1, figsize=(9.0, 2.6 * len(cols)), sharex=True, squeeze=False)
    for ax, (var, label) in zip(axes[:, 0], cols, strict=True):
        y = np.asarray(res[f"{component}.{var}"], float)
        ax.plot(res.time_s, y - (KELVIN_OFFSET if var.endswith("_k") else 0.0))
        ax.set_ylabel(label)
        _grid(ax)
    axes[0, 0].set_title(f"{component}")
    axes[-1, 0].set_xlabel("time [s]")
    return _save(fig, path)


def _top_view(res: Any, component: str, geometry: Any, path: Path) -> Path:
    from hevsim.report.plots import _figure, _save

    n = geometry.rows * geometry.columns
    temps = np.array([res[f"{component}.cell{i}_temp_k"][-1] for i in range(n)]) - KELVIN_OFFSET
    hot = int(np.argmax(temps))
    fig, ax = _figure(figsize=(9.0, 4.0))
    xy = np.array([geometry.cell_centre_xy_m(i // geometry.columns, i % geometry.columns) for i in range(n)])
    sc = ax.scatter(xy[:, 0] * 1e3, xy[:, 1] * 1e3, s=900, c=temps, cmap="inferno",
                    edgecolors=["cyan" if i == hot else "none" for i in range(n)], linewidths=2)  # fmt: skip
    for i, t in enumerate(temps):
        ax.annotate(
            f"{t:.3f}", (xy[i, 0] * 1e3, xy[i, 1] * 1e3), ha="center", va="center", fontsize=7, color="grey"
        )
    fig.colorbar(sc, ax=ax).set_label("°C")
    pad = geometry.cell_pitch_m * 1e3
    ax.set_xlim(xy[:, 0].min() * 1e3 - pad, xy[:, 0].max() * 1e3 + pad)
    ax.set_ylim(xy[:, 1].min() * 1e3 - pad, xy[:, 1].max() * 1e3 + pad)
    ax.set_aspect("equal")
    ax.set_title(f"{component}: final cell mean temperature [°C], hottest cell {hot} outlined")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    return _save(fig, path)


def plot_cosim(res: Any, desc: Any, out_dir: str | Path) -> list[Path]:
    """Write the pictures that apply to ``res`` (a :class:`CosimResult`) of system ``desc``."""
    out = Path(out_dir)
    made: list[Path] = []
    columns = set(res.columns)
    for comp in desc.components:
        for name, cols in SERIES:
            present = tuple(c for c in cols if f"{comp.name}.{c[0]}" in columns)
            if present:
                made.append(_series_figure(res, comp.name, present, out / f"{comp.name}_{name}.png"))
        if comp.source == FEM_SOURCE and "config" in comp.parameters:
            from hevsim.thermal.run import load_thermal_config

            cfg = load_thermal_config(Path(desc.base_dir) / str(comp.parameters["config"]))
            if f"{comp.name}.cell0_temp_k" in columns:
                made.append(_top_view(res, comp.name, cfg.geometry, out / f"{comp.name}_cells_top.png"))
    return made

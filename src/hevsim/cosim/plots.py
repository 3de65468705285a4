"""Pictures of a co-simulation result (thesis figs 4.30-4.34 for the module case).

Whatever the system, :func:`plot_cosim` draws the recognised signals it finds: module
current and voltage, coolant outlet temperature, cooling power, cell and plate temperatures.
Temperature fields (plate, cells, section) are drawn by the participants that hold them
(:meth:`hevsim.cosim.fem.FemModuleParticipant.write_fields`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from hevsim.units import KELVIN_OFFSET

# (file name, [(variable suffix, axis label)]) per picture; drawn for every component that has them
SERIES = (
    (
        "current_voltage",
        (("current_a", "current [A]"), ("terminal_current_a", "current [A]"), ("voltage_v", "voltage [V]")),
    ),
    ("coolant_outlet", (("outlet_temp_k", "outlet temperature [°C]"),)),
    ("cooling_power", (("cooling_power_w", "cooling power [W]"),)),
    (
        "cell_temperature",
        (("cell_max_temp_k", "hottest cell node [°C]"), ("cell_mean_temp_k", "mean cell [°C]")),
    ),
    (
        "plate_and_wall_heat",
        (("plate_max_temp_k", "hottest plate node [°C]"), ("wall_heat_w", "heat to coolant [W]")),
    ),
)


def _series_figure(res: Any, component: str, cols: tuple[tuple[str, str], ...], path: Path) -> Path:
    from hevsim.figures import figure, grid, save

    fig, axes = figure(len(cols), 1, figsize=(9.0, 2.6 * len(cols)), sharex=True, squeeze=False)
    for ax, (var, label) in zip(axes[:, 0], cols, strict=True):
        y = np.asarray(res[f"{component}.{var}"], float)
        ax.plot(res.time_s, y - (KELVIN_OFFSET if var.endswith("_k") else 0.0))
        ax.set_ylabel(label)
        grid(ax)
    axes[0, 0].set_title(f"{component}")
    axes[-1, 0].set_xlabel("time [s]")
    return save(fig, path)


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
    return made

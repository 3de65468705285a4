"""Plots and Markdown reports of simulation results.

``plot_all(result, out_dir)`` writes one PNG per applicable figure and returns their paths;
``write_report(result, out_dir, plots)`` writes ``report.md`` linking them;
``build_report(result, out_dir)`` does both. matplotlib is imported only when a plot is drawn.

Importing this package registers its plotters with :mod:`hevsim.figures`: ``"simulation"``
(:func:`plot_simulation`, for ``SimulationResult.save(plots=True)``) and ``"optimum"``
(:func:`~hevsim.report.dp_plots.plot_optimum`, for ``OptimizationResult.save(plots=True)``).
The results in ``sim/`` and ``optimal/`` look them up there: the layers below report import
nothing from it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hevsim.figures import register_plotter
from hevsim.report.dp_plots import plot_optimum
from hevsim.report.markdown import REPORT_FILE, build_report, render_report, write_report
from hevsim.report.plots import (
    PLOT_FILES,
    plot_all,
    plot_currents,
    plot_energy_audit,
    plot_engine,
    plot_engine_operating_points,
    plot_power_modes,
    plot_soc,
    plot_speed_tracking,
)


def plot_simulation(result: Any, out_dir: Path) -> list[Path]:
    """Every plot that applies to a simulation result and ``report.md`` linking them, in
    ``out_dir``; returns the files written (the plots, then the report)."""
    files = plot_all(result, out_dir)
    return [*files, write_report(result, out_dir, files)]


register_plotter("simulation", plot_simulation)
register_plotter("optimum", plot_optimum)

__all__ = [
    "PLOT_FILES",
    "REPORT_FILE",
    "build_report",
    "plot_all",
    "plot_currents",
    "plot_energy_audit",
    "plot_engine",
    "plot_engine_operating_points",
    "plot_optimum",
    "plot_power_modes",
    "plot_simulation",
    "plot_soc",
    "plot_speed_tracking",
    "render_report",
    "write_report",
]

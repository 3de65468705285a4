"""Plots and Markdown reports of simulation results.

``plot_all(result, out_dir)`` writes one PNG per applicable figure and returns their paths;
``write_report(result, out_dir, plots)`` writes ``report.md`` linking them;
``build_report(result, out_dir)`` does both. matplotlib is imported only when a plot is drawn.
"""

from __future__ import annotations

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

__all__ = [
    "PLOT_FILES",
    "REPORT_FILE",
    "build_report",
    "plot_all",
    "plot_currents",
    "plot_energy_audit",
    "plot_engine",
    "plot_engine_operating_points",
    "plot_power_modes",
    "plot_soc",
    "plot_speed_tracking",
    "render_report",
    "write_report",
]

"""Plots of a DP optimum: every applicable figure is written as a valid PNG."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd

from hevsim.report.dp_plots import plot_optimum

PNG = b"\x89PNG\r\n\x1a\n"


def _result(with_gear: bool, with_ctg: bool) -> SimpleNamespace:
    t = np.arange(0.0, 120.0)
    p_req = 1e4 * np.sin(t / 9.0)
    ts = pd.DataFrame({
        "time_s": t,
        "soc": 0.75 + 0.03 * np.sin(t / 10.0),
        "speed_mps": 10 + 5 * np.sin(t / 7.0),
        "power_required_w": p_req,
        "power_engine_w": np.maximum(p_req, 0.0),
        "power_battery_w": np.minimum(p_req, 0.0),
        "friction_brake_power_w": np.zeros(t.size),
    })  # fmt: skip
    if with_gear:
        ts["gear"] = (t // 25) % 5 + 1
    ns = SimpleNamespace(timeseries=ts, soc_window=(0.4, 0.8), soc_target=(0.7, 0.8), engine=None)
    if with_ctg:
        ns.cost_to_go = np.linspace(1, 0, t.size)[:, None] * np.ones((1, 30))
        ns.cost_to_go[:, :3] = np.inf  # unreachable nodes are left blank
        ns.soc_grid = np.linspace(0.4, 0.8, 30)
        ns.cost_to_go_time_s = t
    return ns


def test_all_plots_written(tmp_path: Path) -> None:
    files = plot_optimum(_result(True, True), tmp_path)
    names = {f.name for f in files}
    assert names == {"soc_trajectory.png", "power_split.png", "gear.png", "cost_to_go.png"}
    for f in files:
        assert f.read_bytes()[:8] == PNG


def test_optional_plots_skipped(tmp_path: Path) -> None:
    names = {f.name for f in plot_optimum(_result(False, False), tmp_path)}
    assert names == {"soc_trajectory.png", "power_split.png"}

"""Plots of a dynamic-programming optimum (thesis chapter 3, figs 3.1 and 3.2).

Each function takes the optimal trajectory (a time-series DataFrame with unit-suffixed
columns) and writes one PNG; :func:`plot_optimum` writes the ones that apply.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.figures import figure, grid, save
from hevsim.report.plots import (
    W_PER_KW,
    _bsfc_levels,
    _col,
    _time,
    bsfc_grid,
    fuel_rate_kgps,
    plot_engine_operating_points,
)
from hevsim.units import RADPS_PER_RPM


def plot_soc_trajectory(
    ts: pd.DataFrame,
    path: str | Path,
    soc_window: Sequence[float] | None = None,
    soc_target: Sequence[float] | None = None,
) -> Path:
    """Optimal SOC vs time (fig 3.1) with the allowed window and the final target."""
    fig, ax = figure(figsize=(10.0, 4.5))
    t = _time(ts)
    soc = _col(ts, "soc") * 100.0
    if soc_window is not None:
        ax.axhspan(
            soc_window[0] * 100,
            soc_window[1] * 100,
            color="tab:green",
            alpha=0.08,
            label="allowed SOC window",
        )
    if soc_target is not None:
        ax.plot(
            [t[-1], t[-1]],
            [soc_target[0] * 100, soc_target[1] * 100],
            color="tab:red",
            lw=6,
            alpha=0.6,
            solid_capstyle="butt",
            label="final SOC target",
        )
    ax.plot(t, soc, color="tab:blue", lw=1.6, label="optimal SOC")
    ax.set_title(f"Optimal SOC trajectory: {soc[0]:.1f} % -> {soc[-1]:.1f} %")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("SOC [%]")
    ax.legend(loc="best", fontsize="small")
    grid(ax)
    return save(fig, path)


def plot_power_split(ts: pd.DataFrame, path: str | Path) -> Path:
    """Power required at the wheels vs supplied by the engine and the battery (fig 3.2) [kW]."""
    fig, (ax, ax2) = figure(2, 1, figsize=(11.0, 6.5), sharex=True, height_ratios=[3, 1])
    t = _time(ts)
    req = _col(ts, "power_required_w") / W_PER_KW
    ax.fill_between(t, 0.0, req, step="post", color="0.75", label="required at wheels")
    if "power_engine_w" in ts.columns:
        ax.step(
            t, _col(ts, "power_engine_w") / W_PER_KW, where="post", color="tab:red", lw=1.0, label="engine"
        )
    if "power_battery_w" in ts.columns:
        ax.step(
            t,
            _col(ts, "power_battery_w") / W_PER_KW,
            where="post",
            color="tab:blue",
            lw=1.0,
            label="battery (> 0 supplied, < 0 recovered)",
        )
    if "friction_brake_power_w" in ts.columns:
        ax.step(
            t,
            -_col(ts, "friction_brake_power_w") / W_PER_KW,
            where="post",
            color="tab:brown",
            lw=0.8,
            label="friction brakes",
        )
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_ylabel("power [kW]")
    ax.set_title("Power required vs supplied and recovered along the optimum")
    ax.legend(loc="upper right", fontsize="small", ncols=2)
    grid(ax)
    if "speed_mps" in ts.columns:
        ax2.plot(t, _col(ts, "speed_mps") * 3.6, color="k", lw=1.0)
        ax2.set_ylabel("speed [km/h]")
    grid(ax2)
    ax2.set_xlabel("time [s]")
    return save(fig, path)


def plot_gear(ts: pd.DataFrame, path: str | Path) -> Path:
    """Optimal gear vs time, with the share of time in each gear."""
    fig, (ax, ax2) = figure(1, 2, figsize=(12.0, 4.0), width_ratios=[4, 1])
    t = _time(ts)
    gear = _col(ts, "gear")
    ax.step(t, gear, where="post", color="tab:purple", lw=1.0)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("gear")
    ax.set_title("Optimal gear")
    grid(ax)
    moving = _col(ts, "speed_mps") > 0 if "speed_mps" in ts.columns else np.ones(t.size, bool)
    gears = np.unique(gear[moving & (gear > 0)]).astype(int)
    share = [100.0 * float(np.mean(gear[moving] == g)) for g in gears]
    ax2.barh([str(g) for g in gears], share, color="tab:purple")
    ax2.set_xlabel("% of moving time")
    grid(ax2)
    return save(fig, path)


def plot_operating_points_by_gear(ts: pd.DataFrame, engine: Any, path: str | Path) -> Path:
    """Engine operating points on the BSFC map [g/kWh], coloured by the optimal gear."""
    fig, ax = figure(figsize=(9.5, 6.5))
    w, trq, bsfc = bsfc_grid(engine)
    rpm = w / RADPS_PER_RPM
    if np.isfinite(bsfc).any():
        levels = _bsfc_levels(bsfc)
        cs = ax.contour(rpm, trq, bsfc, levels=levels, colors="0.45", linewidths=0.6)
        ax.clabel(cs, levels=cs.levels[::2], fmt="%.0f", fontsize="x-small", inline=True)
    from hevsim.components.engine import scaled_max_torque

    tmax_w = scaled_max_torque(engine.max_torque, engine.torque_scale, w)
    ax.plot(rpm, tmax_w, color="k", lw=2.0, label="max torque")
    fuel = fuel_rate_kgps(ts)
    fired = (fuel > 0) if fuel is not None else np.zeros(len(ts), bool)
    gear = _col(ts, "gear")
    pts_rpm = _col(ts, "engine_speed_radps") / RADPS_PER_RPM
    pts_t = _col(ts, "engine_torque_nm")
    for g in np.unique(gear[fired]).astype(int):
        sel = fired & (gear == g)
        ax.scatter(pts_rpm[sel], pts_t[sel], s=14, alpha=0.8, label=f"gear {g} ({int(sel.sum())} steps)")
    ax.set_xlim(float(rpm[0]), float(rpm[-1]))
    ax.set_xlabel("engine speed [rpm]")
    ax.set_ylabel("engine torque [N·m]")
    ax.set_title(f"Optimal engine operating points by gear on the BSFC map (g/kWh)\n{engine.name}")
    ax.legend(loc="lower right", fontsize="small")
    grid(ax)
    return save(fig, path)


def plot_cost_to_go(
    cost_to_go: np.ndarray,
    soc_grid: np.ndarray,
    time_s: np.ndarray,
    path: str | Path,
    soc_path: np.ndarray | None = None,
    unit: str = "g",
) -> Path:
    """Cost-to-go as a heat map over time and SOC, with the optimal SOC path on top.

    ``cost_to_go`` [kg] has shape (len(time_s), len(soc_grid)); infeasible nodes (inf) are
    left blank.
    """
    fig, ax = figure(figsize=(11.0, 5.5))
    scale = 1000.0 if unit == "g" else 1.0
    c = np.where(np.isfinite(cost_to_go), cost_to_go * scale, np.nan)
    mesh = ax.pcolormesh(time_s, soc_grid * 100.0, c.T, shading="auto", cmap="magma_r")
    cbar = fig.colorbar(mesh, ax=ax)
    cbar.set_label(f"fuel to the end of the cycle [{unit}]")
    if soc_path is not None:
        ax.plot(
            time_s[: soc_path.size],
            soc_path[: time_s.size] * 100.0,
            color="cyan",
            lw=1.4,
            label="optimal SOC",
        )
        ax.legend(loc="upper right", fontsize="small")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("SOC [%]")
    ax.set_title("Cost-to-go (blank: the target cannot be reached from there)")
    return save(fig, path)


def plot_optimum(result: Any, out_dir: str | Path) -> list[Path]:
    """Write every plot that applies to an optimization result; returns the files.

    Uses ``result.timeseries`` and, when present, ``result.engine``, ``result.soc_window``,
    ``result.soc_target``, ``result.cost_to_go``, ``result.soc_grid`` and
    ``result.cost_to_go_time_s``.
    """
    out = Path(out_dir)
    ts: pd.DataFrame = result.timeseries
    files = [
        plot_soc_trajectory(
            ts,
            out / "soc_trajectory.png",
            getattr(result, "soc_window", None),
            getattr(result, "soc_target", None),
        ),
    ]
    if "power_required_w" in ts.columns:
        files.append(plot_power_split(ts, out / "power_split.png"))
    if "gear" in ts.columns:
        files.append(plot_gear(ts, out / "gear.png"))
        if getattr(result, "engine", None) is not None:
            files.append(
                plot_operating_points_by_gear(ts, result.engine, out / "operating_points_by_gear.png")
            )
    op = plot_engine_operating_points(
        ts, getattr(result, "engine", None), out / "engine_operating_points.png"
    )
    if op is not None:
        files.append(op)
    ctg = getattr(result, "cost_to_go", None)
    if ctg is not None:
        files.append(
            plot_cost_to_go(
                np.asarray(ctg),
                np.asarray(result.soc_grid),
                np.asarray(result.cost_to_go_time_s),
                out / "cost_to_go.png",
                _col(ts, "soc"),
            )
        )
    return files

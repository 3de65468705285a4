"""Plots of a forward-simulation result, one PNG per figure.

Every function takes SI data (the result's time series, the engine object, the energy audit)
and a target path, converts to display units only here (mph, rpm, kW, kWh, g/kWh), writes
one PNG and returns its path. Figures are built with the object-oriented matplotlib API on
the Agg canvas (``matplotlib.figure.Figure`` + ``FigureCanvasAgg``): nothing touches pyplot's
global backend or figure registry, so the functions are safe on headless machines and inside
interactive sessions alike, and every figure is released when the function returns. Files
appear atomically (written to a temporary name in the same folder, then renamed).

matplotlib is imported inside the functions: importing :mod:`hevsim.report` stays cheap.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import numpy.typing as npt
import pandas as pd

from hevsim.figures import DPI as DPI  # re-exported: the resolution lives with the helpers
from hevsim.figures import figure, grid, save
from hevsim.units import J_PER_WH, MPS_PER_MPH, RADPS_PER_RPM

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from hevsim.tables import Table1D, Table2D

FloatArray = npt.NDArray[np.float64]

J_PER_KWH = 1000.0 * J_PER_WH
"""Joules in one kilowatt-hour [J]."""
W_PER_KW = 1000.0
"""Watts in one kilowatt [W]."""
G_PER_KG = 1000.0
"""Grams in one kilogram [g]."""
S_PER_H = 3600.0
"""Seconds in one hour [s]."""
BSFC_MIN_LOAD_FRACTION = 0.04
"""Map points below this fraction of the peak torque or peak power are left out of the BSFC
contours: there BSFC tends to infinity and would swamp the colour scale [-]."""

OP_BIN_RPM = 25.0
"""Engine-speed bin for grouping operating points [rpm]."""
OP_BIN_NM = 2.0
"""Engine-torque bin for grouping operating points [N·m]."""
OP_LABEL_SHARE = 0.05
"""Operating-point bins holding at least this share of the fuelled time are labelled [-]."""

POWER_MODE_NAMES: tuple[str, ...] = ("pure_ev", "pure_ice", "combined", "ice_charging", "charging")
"""Default names of the supervisory power modes, indexed by ``power_mode`` code."""
GENSET_STATE_NAMES: tuple[str, ...] = ("off", "starting", "running")
"""Names of the genset states, indexed by ``genset_state`` code."""
ENERGY_SOURCES: tuple[str, ...] = ("fuel", "genset_source", "battery_chemical")
"""Energy-audit terms that are sources; every other term except the residual is a sink."""
ENERGY_SINKS: tuple[str, ...] = (
    "aero",
    "rolling",
    "grade",
    "kinetic_vehicle",
    "kinetic_genset",
    "friction_brakes",
    "engine_loss",
    "generator_loss",
    "motor_loss",
    "gear_loss",
    "battery_loss",
    "aux",
)
"""Known energy-audit sinks, in display order (unknown sink terms follow them)."""
RESIDUAL_KEY = "residual"
"""Energy-audit key of the closing error [J]."""

PLOT_FILES: dict[str, str] = {
    "speed_tracking": "speed_tracking.png",
    "soc": "soc.png",
    "currents": "currents.png",
    "engine": "engine.png",
    "engine_operating_points": "engine_operating_points.png",
    "power_modes": "power_modes.png",
    "energy_audit": "energy_audit.png",
}
"""Plot name -> file name written by :func:`plot_all`."""

_MARGINS_IN = (0.85, 0.6, 0.25, 0.45)
"""Fixed margins (left, bottom, right, top) [in] of the time-series figures."""
_MODE_COLORS = ("tab:green", "tab:red", "tab:purple", "tab:orange", "tab:blue")
_CURRENT_COLUMNS: Sequence[str] = ("battery_current_a", "motor_current_a", "generator_current_a")


class EngineLike(Protocol):
    """What the plots need from an engine (see :class:`hevsim.components.engine.Engine`)."""

    @property
    def name(self) -> str: ...
    @property
    def fuel_map(self) -> Table2D | None: ...
    @property
    def max_torque(self) -> Table1D: ...
    @property
    def torque_scale(self) -> float: ...


# --------------------------------------------------------------------------- helpers

# The figure helpers live in the ground layer (hevsim.figures: any layer draws with them);
# their former private names stay here for callers of hevsim.report.plots.
_figure, _grid, _save = figure, grid, save

MAX_LINE_POINTS = 4000
"""Longest line drawn as is [points]; longer lines keep the min and max of each of
``MAX_LINE_POINTS // 2`` bins, so peaks survive while the picture stays the same at PNG
resolution (a 10 in figure at 120 dpi is 1200 pixels wide)."""


def thin_line(
    x: FloatArray, y: FloatArray, max_points: int = MAX_LINE_POINTS
) -> tuple[FloatArray, FloatArray]:
    """``(x, y)`` reduced to at most ``max_points`` points by keeping the minimum and the
    maximum of ``y`` in each of ``max_points // 2`` equal-count bins, in their original order.

    Lines of ``max_points`` points or fewer come back unchanged. NaN samples never win a
    bin (a bin of only NaN keeps NaN). ``x`` must be sorted (time).
    """
    n = int(y.size)
    if n <= max_points or max_points < 2:
        return x, y
    n_bins = max_points // 2
    edges = np.linspace(0, n, n_bins + 1).astype(np.int64)
    starts = edges[:-1]
    finite = np.where(np.isnan(y), np.inf, y)
    i_min = np.minimum.reduceat(finite, starts)
    finite = np.where(np.isnan(y), -np.inf, y)
    i_max = np.maximum.reduceat(finite, starts)
    # positions of the extreme values inside each bin (first occurrence)
    bin_of = np.repeat(np.arange(n_bins), np.diff(edges))
    pos = np.arange(n)
    is_min = np.where(np.isnan(y), np.isinf(i_min[bin_of]), y == i_min[bin_of])
    is_max = np.where(np.isnan(y), np.isinf(i_max[bin_of]), y == i_max[bin_of])
    first_min = np.full(n_bins, n, dtype=np.int64)
    first_max = np.full(n_bins, n, dtype=np.int64)
    np.minimum.at(first_min, bin_of[is_min], pos[is_min])
    np.minimum.at(first_max, bin_of[is_max], pos[is_max])
    keep = np.unique(np.concatenate([first_min, first_max]))
    keep = keep[keep < n]
    return x[keep], y[keep]


def _col(ts: pd.DataFrame, name: str) -> FloatArray:
    """Column ``name`` as a float array."""
    return np.asarray(ts[name].to_numpy(dtype=np.float64), dtype=np.float64)


def _has(ts: pd.DataFrame, *names: str) -> bool:
    return all(n in ts.columns for n in names)


def _time(ts: pd.DataFrame) -> FloatArray:
    if "time_s" in ts.columns:
        return _col(ts, "time_s")
    return np.arange(len(ts), dtype=np.float64)


def step_durations(t: FloatArray) -> FloatArray:
    """Duration [s] each sample holds: t[i+1] - t[i], the last one repeating the median step."""
    if t.size == 0:
        return np.zeros(0)
    if t.size == 1:
        return np.ones(1)
    d = np.diff(t)
    return np.append(d, float(np.median(d)))


def _runs(mask: npt.NDArray[np.bool_], t: FloatArray) -> list[tuple[float, float]]:
    """(start [s], width [s]) of each run of True in ``mask`` (sample-and-hold)."""
    if t.size == 0:
        return []
    edges = np.diff(mask.astype(np.int8), prepend=np.int8(0), append=np.int8(0))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1)
    t_ext = np.append(t, t[-1] + step_durations(t)[-1])
    return [(float(t_ext[s]), float(t_ext[e] - t_ext[s])) for s, e in zip(starts, ends, strict=True)]


def fuel_rate_kgps(ts: pd.DataFrame) -> FloatArray | None:
    """Fuel rate [kg/s] from ``fuel_rate_kgps``, ``fuel_rate_gps`` [g/s] or the cumulative
    ``fuel_kg`` [kg]; None if the time series has none of them."""
    if "fuel_rate_kgps" in ts.columns:
        return _col(ts, "fuel_rate_kgps")
    if "fuel_rate_gps" in ts.columns:
        return _col(ts, "fuel_rate_gps") / G_PER_KG
    if "fuel_kg" in ts.columns and len(ts) > 1:
        rate = np.diff(_col(ts, "fuel_kg")) / np.diff(_time(ts))
        return np.append(rate, 0.0)
    return None


def _speed_mph(ts: pd.DataFrame, which: str) -> FloatArray | None:
    """Speed column ``which`` ('speed' or 'speed_desired') in [mph], or None if absent."""
    if f"{which}_mps" in ts.columns:
        return _col(ts, f"{which}_mps") / MPS_PER_MPH
    if f"{which}_mph" in ts.columns:
        return _col(ts, f"{which}_mph")
    return None


def power_mode_names(ts: pd.DataFrame) -> dict[int, str]:
    """Power-mode code -> name, from ``power_mode_name`` when present, else the defaults."""
    names = dict(enumerate(POWER_MODE_NAMES))
    if _has(ts, "power_mode", "power_mode_name"):
        pairs = ts[["power_mode", "power_mode_name"]].drop_duplicates()
        for code, name in zip(pairs["power_mode"], pairs["power_mode_name"], strict=True):
            names[int(code)] = str(name)
    return names


def split_energy_audit(
    energy_audit: Mapping[str, float],
) -> tuple[list[tuple[str, float]], list[tuple[str, float]], float | None]:
    """Split an energy audit [J] into (sources, sinks, residual) in display order."""
    known = set(ENERGY_SOURCES) | set(ENERGY_SINKS) | {RESIDUAL_KEY}
    sources = [(k, float(energy_audit[k])) for k in ENERGY_SOURCES if k in energy_audit]
    sinks = [(k, float(energy_audit[k])) for k in ENERGY_SINKS if k in energy_audit]
    sinks += [(k, float(v)) for k, v in energy_audit.items() if k not in known]
    residual = energy_audit.get(RESIDUAL_KEY)
    return sources, sinks, None if residual is None else float(residual)


# --------------------------------------------------------------------------- plots


def plot_speed_tracking(ts: pd.DataFrame, path: str | Path) -> Path:
    """Desired vs actual vehicle speed [mph] over time [s], with the tracking error below."""
    t = _time(ts)
    v = _speed_mph(ts, "speed")
    v_des = _speed_mph(ts, "speed_desired")
    fig, (ax, ax_err) = figure(
        2, 1, sharex=True, figsize=(10.0, 6.0), gridspec_kw={"height_ratios": [3, 1]},
        margins_in=_MARGINS_IN, hspace=0.3,
    )  # fmt: skip
    if v_des is not None:
        ax.plot(*thin_line(t, v_des), color="0.35", lw=2.2, ls="--", label="desired (cycle)")
    if v is not None:
        ax.plot(*thin_line(t, v), color="tab:blue", lw=1.2, label="actual")
    ax.set_ylabel("speed [mph]")
    ax.set_title("Drive-cycle speed tracking")
    ax.legend(loc="upper right")
    grid(ax)
    if v is not None and v_des is not None:
        err = v - v_des
        rms = float(np.sqrt(np.mean(err**2))) if err.size else 0.0
        ax_err.plot(*thin_line(t, err), color="tab:red", lw=1.0)
        ax_err.axhline(0.0, color="0.3", lw=0.8)
        ax_err.set_title(
            f"error (actual - desired): RMS {rms:.3f} mph, max |error| "
            f"{float(np.max(np.abs(err))) if err.size else 0.0:.3f} mph",
            fontsize="small",
        )
    ax_err.set_ylabel("error [mph]")
    ax_err.set_xlabel("time [s]")
    grid(ax_err)
    return save(fig, path)


def plot_soc(ts: pd.DataFrame, path: str | Path) -> Path:
    """Battery state of charge [%] over time [s], genset starting/running spans shaded."""
    t = _time(ts)
    fig, ax = figure(figsize=(10.0, 4.8), margins_in=_MARGINS_IN)
    if "genset_state" in ts.columns:
        state = _col(ts, "genset_state")
        for code, color, label in ((2, "tab:orange", "genset running"), (1, "gold", "starting")):
            spans = _runs(state == code, t)
            if spans:
                ax.broken_barh(
                    spans,
                    (0.0, 1.0),
                    transform=ax.get_xaxis_transform(),
                    color=color,
                    alpha=0.25 if code == 2 else 0.6,
                    lw=0,
                    label=label,
                )
    soc = 100.0 * _col(ts, "soc")
    ax.plot(*thin_line(t, soc), color="tab:blue", lw=1.5, label="SOC")
    if soc.size:
        ax.set_title(
            f"Battery state of charge: {soc[0]:.1f} % -> {soc[-1]:.1f} % "
            f"(min {np.min(soc):.1f} %, max {np.max(soc):.1f} %)"
        )
        pad = max(1.0, 0.15 * float(np.ptp(soc)))
        ax.set_ylim(float(np.min(soc)) - pad, float(np.max(soc)) + pad)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("SOC [%]")
    ax.legend(loc="best")
    grid(ax)
    return save(fig, path)


def plot_currents(ts: pd.DataFrame, path: str | Path) -> Path:
    """Battery, motor and generator currents [A] over time [s]."""
    t = _time(ts)
    fig, ax = figure(figsize=(10.0, 4.8), margins_in=_MARGINS_IN)
    series = (
        ("generator_current_a", "generator", "tab:orange", 1.0),
        ("motor_current_a", "motor", "tab:green", 1.0),
        ("battery_current_a", "battery (discharge > 0)", "tab:blue", 1.4),
    )
    for col, label, color, lw in series:
        if col in ts.columns:
            ax.plot(*thin_line(t, _col(ts, col)), color=color, lw=lw, label=label)
    ax.axhline(0.0, color="0.3", lw=0.8)
    ax.set_title("Electrical currents")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("current [A]")
    ax.legend(loc="best")
    grid(ax)
    return save(fig, path)


def plot_engine(ts: pd.DataFrame, path: str | Path) -> Path:
    """Engine speed [rpm], torque [N·m] and throttle [%] over time [s] (three panels)."""
    t = _time(ts)
    fig, (ax_w, ax_t, ax_th) = figure(
        3, 1, sharex=True, figsize=(10.0, 7.0), gridspec_kw={"height_ratios": [2, 2, 1]},
        margins_in=_MARGINS_IN, hspace=0.12,
    )  # fmt: skip
    if "engine_speed_radps" in ts.columns:
        rpm = _col(ts, "engine_speed_radps") / RADPS_PER_RPM
    elif "engine_speed_rpm" in ts.columns:
        rpm = _col(ts, "engine_speed_rpm")
    else:
        rpm = np.full(t.shape, np.nan)
    ax_w.plot(*thin_line(t, rpm), color="tab:blue", lw=1.2, label="engine speed")
    ax_w.set_ylabel("speed [rpm]")
    ax_w.set_title("Engine speed, torque and throttle")
    grid(ax_w)
    fuel = fuel_rate_kgps(ts)
    spans = _runs(fuel > 0.0, t) if fuel is not None else []
    if spans:
        for a in (ax_w, ax_t, ax_th):  # one collection per panel, however many spans
            a.broken_barh(
                spans,
                (0.0, 1.0),
                transform=a.get_xaxis_transform(),
                color="tab:orange",
                alpha=0.12,
                lw=0,
                label="fuelled" if a is ax_w else None,
            )
    ax_w.legend(loc="upper right")
    if "engine_torque_nm" in ts.columns:
        ax_t.plot(*thin_line(t, _col(ts, "engine_torque_nm")), color="tab:red", lw=1.2)
    ax_t.axhline(0.0, color="0.3", lw=0.8)
    ax_t.set_ylabel("torque [N·m]")
    grid(ax_t)
    if "engine_throttle" in ts.columns:
        ax_th.plot(*thin_line(t, 100.0 * _col(ts, "engine_throttle")), color="tab:green", lw=1.0)
    ax_th.set_ylabel("throttle [%]")
    ax_th.set_ylim(-5.0, 105.0)
    ax_th.set_xlabel("time [s]")
    grid(ax_th)
    return save(fig, path)


def bsfc_grid(
    engine: EngineLike, n_speed: int = 120, n_torque: int = 120
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """BSFC [g/kWh] of the (scaled) engine on a regular grid, NaN where undefined.

    Returns (speed [rad/s] 1-D, torque [N·m] 1-D, bsfc [g/kWh] shape (n_torque, n_speed)).
    BSFC = fuel_rate [kg/s] * 3.6e9 / (torque [N·m] * speed [rad/s]); points above the
    max-torque curve or below :data:`BSFC_MIN_LOAD_FRACTION` of peak torque/power are masked.
    """
    fuel_map = engine.fuel_map
    scale = float(engine.torque_scale)
    tmax = engine.max_torque
    if fuel_map is None:
        w = np.linspace(float(tmax.x[0]), float(tmax.x[-1]), n_speed)
    else:
        w = np.linspace(float(fuel_map.x[0]), float(fuel_map.x[-1]), n_speed)
    from hevsim.components.engine import scaled_fuel_map_rate, scaled_max_torque  # the engine's kernels

    tmax_w = scaled_max_torque(tmax, scale, w)
    trq = np.linspace(0.0, float(np.max(tmax_w)), n_torque)
    ww, tt = np.meshgrid(w, trq)
    if fuel_map is None:
        return w, trq, np.full(ww.shape, np.nan)

    fuel_kgps = scaled_fuel_map_rate(fuel_map, scale, tt, ww)
    power_w = tt * ww
    peak_power = float(np.max(tmax_w * w))
    with np.errstate(divide="ignore", invalid="ignore"):
        bsfc = fuel_kgps * G_PER_KG * S_PER_H * W_PER_KW / power_w
    bad = (
        (tt > scaled_max_torque(tmax, scale, ww) * (1.0 + 1e-9))
        | (tt < BSFC_MIN_LOAD_FRACTION * float(np.max(tmax_w)))
        | (power_w < BSFC_MIN_LOAD_FRACTION * peak_power)
        | ~np.isfinite(bsfc)
        | (bsfc <= 0.0)
    )
    return w, trq, np.where(bad, np.nan, bsfc)


def _bsfc_levels(bsfc: FloatArray) -> FloatArray:
    """Contour levels [g/kWh]: fine near the best point, coarser towards light load."""
    from matplotlib.ticker import MaxNLocator

    finite = bsfc[np.isfinite(bsfc)]
    lo = float(np.min(finite))
    hi = min(float(np.percentile(finite, 95)), 2.5 * lo)
    if hi <= lo:
        hi = lo * 1.1 + 1.0
    locator = MaxNLocator(nbins=14, steps=[1, 2, 2.5, 5, 10])
    levels = np.asarray(locator.tick_values(lo, hi), dtype=np.float64)
    return levels[levels >= lo * 0.999]


def _time_weighted_scatter(ax: Axes, pts_rpm: FloatArray, pts_t: FloatArray, dt: FloatArray) -> None:
    """Operating points binned on a fine grid, marker area proportional to time spent.

    A controller that holds a few fixed operating points shows as a few large markers (the
    busiest labelled with their share of fuelled time), a free trajectory as many small ones.
    """
    keys = np.stack([np.round(pts_rpm / OP_BIN_RPM), np.round(pts_t / OP_BIN_NM)], axis=1).astype(np.int64)
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    time_s = np.bincount(inverse, weights=dt)
    x = np.bincount(inverse, weights=dt * pts_rpm) / time_s
    y = np.bincount(inverse, weights=dt * pts_t) / time_s
    share = time_s / float(time_s.sum())
    ax.scatter(
        x,
        y,
        s=10.0 + 600.0 * share,
        c="tab:red",
        edgecolors="white",
        linewidths=0.5,
        alpha=0.7,
        zorder=3,
        label=f"operating points, area ∝ time ({float(dt.sum()):.0f} s fuelled)",
    )
    for i in np.flatnonzero(share >= OP_LABEL_SHARE):
        ax.annotate(
            f"{100.0 * share[i]:.0f} %",
            (x[i], y[i]),
            xytext=(8, 8),
            textcoords="offset points",
            fontsize="small",
            color="darkred",
            zorder=4,
        )


def plot_engine_operating_points(
    ts: pd.DataFrame | None, engine: EngineLike | None, path: str | Path
) -> Path | None:
    """Engine BSFC map [g/kWh] with the max-torque curve and the fuelled operating points.

    Axes in rpm and N·m. Returns None (and writes nothing) when there is no engine; with an
    engine the map is drawn even if the engine never fired.
    """
    if engine is None:
        return None
    fig, ax = figure(figsize=(9.0, 6.5), margins_in=(0.85, 0.6, 0.2, 0.75))
    w, trq, bsfc = bsfc_grid(engine)
    rpm = w / RADPS_PER_RPM
    has_map = bool(np.isfinite(bsfc).any())
    if has_map:
        levels = _bsfc_levels(bsfc)
        cf = ax.contourf(rpm, trq, bsfc, levels=levels, cmap="viridis_r", alpha=0.85, extend="both")
        cs = ax.contour(rpm, trq, bsfc, levels=levels, colors="k", linewidths=0.5, alpha=0.6)
        ax.clabel(cs, levels=cs.levels[::2], fmt="%.0f", fontsize="x-small", inline=True)
        cbar = fig.colorbar(cf, ax=ax)
        cbar.set_label("BSFC [g/kWh]")
        i_best = np.unravel_index(np.nanargmin(bsfc), bsfc.shape)
        ax.plot(
            rpm[i_best[1]],
            trq[i_best[0]],
            marker="*",
            ms=16,
            color="white",
            mec="k",
            ls="none",
            label=f"best BSFC {bsfc[i_best]:.0f} g/kWh",
        )
    from hevsim.components.engine import scaled_max_torque

    tmax_w = scaled_max_torque(engine.max_torque, engine.torque_scale, w)
    ax.plot(rpm, tmax_w, color="k", lw=2.2, label="max torque")

    summary = ""
    fuel = fuel_rate_kgps(ts) if ts is not None else None
    if (
        ts is not None
        and fuel is not None
        and "engine_torque_nm" in ts.columns
        and (_has(ts, "engine_speed_radps") or _has(ts, "engine_speed_rpm"))
    ):
        fired = fuel > 0.0
        if fired.any():
            pts_rpm = (
                _col(ts, "engine_speed_radps") / RADPS_PER_RPM
                if "engine_speed_radps" in ts.columns
                else _col(ts, "engine_speed_rpm")
            )[fired]
            pts_t = _col(ts, "engine_torque_nm")[fired]
            dt = step_durations(_time(ts))[fired]
            _time_weighted_scatter(ax, pts_rpm, pts_t, dt)
            energy_j = float(np.sum(np.maximum(pts_t * pts_rpm * RADPS_PER_RPM, 0.0) * dt))
            fuel_kg = float(np.sum(fuel[fired] * dt))
            if energy_j > 0.0:
                avg = fuel_kg * G_PER_KG / (energy_j / J_PER_KWH)
                summary = f" — cycle-average BSFC {avg:.0f} g/kWh"
    if not has_map:
        summary += " (no fuel map: ideal engine)"
    ax.set_xlim(float(rpm[0]), float(rpm[-1]))
    ax.set_ylim(min(0.0, ax.get_ylim()[0]), float(np.max(tmax_w)) * 1.08)
    ax.set_title(f"Engine operating points on the BSFC map\n{engine.name}{summary}")
    ax.set_xlabel("engine speed [rpm]")
    ax.set_ylabel("engine torque [N·m]")
    ax.legend(loc="lower right", fontsize="small", framealpha=0.9)
    grid(ax)
    return save(fig, path)


def plot_power_modes(ts: pd.DataFrame, path: str | Path) -> Path:
    """Supervisory power mode over time [s] and the share of time [%] spent in each mode."""
    t = _time(ts)
    codes = _col(ts, "power_mode").astype(np.int64)
    names = power_mode_names(ts)
    all_codes = sorted(set(names) | {int(c) for c in np.unique(codes)})
    dt = step_durations(t)
    total = float(dt.sum()) or 1.0
    fig, (ax, ax_bar) = figure(
        1, 2, sharey=True, figsize=(11.0, 4.5), gridspec_kw={"width_ratios": [3, 1]},
        margins_in=(1.15, 0.6, 0.25, 0.45), wspace=0.05,
    )  # fmt: skip
    for code in all_codes:
        color = _MODE_COLORS[code % len(_MODE_COLORS)]
        spans = _runs(codes == code, t)
        if spans:
            ax.broken_barh(spans, (code - 0.35, 0.7), color=color, alpha=0.8, lw=0)
    labels = [names.get(c, f"mode {c}") for c in all_codes]
    ax.set_yticks(all_codes, labels)
    ax.set_ylim(min(all_codes) - 0.6, max(all_codes) + 0.6)
    ax.set_xlabel("time [s]")
    ax.set_title("Power mode over time")
    ax.grid(True, axis="x", alpha=0.4)
    shares = [100.0 * float(dt[codes == c].sum()) / total for c in all_codes]
    colors = [_MODE_COLORS[c % len(_MODE_COLORS)] for c in all_codes]
    bars = ax_bar.barh(all_codes, shares, height=0.7, color=colors, alpha=0.8)
    ax_bar.bar_label(bars, labels=[f"{s:.1f} %" for s in shares], padding=3, fontsize="small")
    ax_bar.set_xlim(0.0, max(100.0, max(shares, default=0.0) * 1.25))
    ax_bar.set_xlabel("share of time [%]")
    ax_bar.set_title("Time in mode")
    ax_bar.grid(True, axis="x", alpha=0.4)
    return save(fig, path)


def plot_energy_audit(energy_audit: Mapping[str, float], path: str | Path) -> Path:
    """Horizontal bars of the energy sources and sinks [kWh] and the closing residual."""
    from matplotlib.patches import Patch

    sources, sinks, residual = split_energy_audit(energy_audit)
    rows: list[tuple[str, float, str]] = [(k, v, "tab:green") for k, v in sources]
    rows += [(k, v, "tab:orange") for k, v in sinks]
    if residual is not None:
        rows.append((RESIDUAL_KEY, residual, "tab:red"))
    fig, ax = figure(figsize=(9.0, 0.9 + 0.42 * max(len(rows), 3)), margins_in=(1.45, 0.55, 0.25, 0.4))
    y = np.arange(len(rows))[::-1]
    kwh = np.array([v / J_PER_KWH for _, v, _ in rows])
    bars = ax.barh(y, kwh, color=[c for *_, c in rows], height=0.7)
    ax.bar_label(bars, labels=[f"{v:.3g}" for v in kwh], padding=3, fontsize="small")
    ax.set_yticks(y, [k.replace("_", " ") for k, _, _ in rows])
    ax.axvline(0.0, color="0.3", lw=0.8)
    lo, hi = (float(np.min(kwh)), float(np.max(kwh))) if kwh.size else (0.0, 1.0)
    span = max(max(hi, 0.0) - min(lo, 0.0), 1e-9)
    left = min(lo, 0.0) - (0.16 * span if lo < 0.0 else 0.0)  # room for negative labels
    ax.set_xlim(left, max(hi, 0.0) + 0.16 * span)
    for boundary in (len(sources), len(sources) + len(sinks)):
        if 0 < boundary < len(rows):
            ax.axhline(len(rows) - boundary - 0.5, color="0.5", lw=0.8, ls=":")
    total = sum(v for _, v in sources)
    title = "Energy audit"
    if residual is not None and total:
        title += f": residual {100.0 * residual / total:.3f} % of sources"
    ax.set_title(title)
    ax.set_xlabel("energy [kWh]")
    ax.legend(
        handles=[
            Patch(color="tab:green", label="source"),
            Patch(color="tab:orange", label="sink"),
            Patch(color="tab:red", label="residual (sources - sinks)"),
        ],
        loc="lower right",
        fontsize="small",
    )
    ax.grid(True, axis="x", alpha=0.4)
    return save(fig, path)


def plot_all(result: Any, out_dir: str | Path) -> list[Path]:
    """Write every plot that applies to ``result`` into ``out_dir``; return the paths written.

    ``result`` needs ``timeseries`` (DataFrame) and may carry ``engine`` (None for
    engine-less configurations) and ``energy_audit`` (dict term -> [J]).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ts: pd.DataFrame = result.timeseries
    engine: EngineLike | None = getattr(result, "engine", None)
    audit: Mapping[str, float] | None = getattr(result, "energy_audit", None)
    written: list[Path | None] = []
    if _speed_mph(ts, "speed") is not None or _speed_mph(ts, "speed_desired") is not None:
        written.append(plot_speed_tracking(ts, out / PLOT_FILES["speed_tracking"]))
    if "soc" in ts.columns:
        written.append(plot_soc(ts, out / PLOT_FILES["soc"]))
    if any(c in ts.columns for c in _CURRENT_COLUMNS):
        written.append(plot_currents(ts, out / PLOT_FILES["currents"]))
    if engine is not None:
        written.append(plot_engine(ts, out / PLOT_FILES["engine"]))
        written.append(plot_engine_operating_points(ts, engine, out / PLOT_FILES["engine_operating_points"]))
    if "power_mode" in ts.columns:
        written.append(plot_power_modes(ts, out / PLOT_FILES["power_modes"]))
    if audit:
        written.append(plot_energy_audit(audit, out / PLOT_FILES["energy_audit"]))
    return [p for p in written if p is not None]

"""The series HEV's compiled run: its inputs (:func:`kernel_inputs`: the model, the cycle on
the step's grid, the supervisor's codes and a :class:`GensetSchedule`) and its result
(:func:`_assemble`: the time series and events made on first read, the metrics). Below the
entry point :func:`hevsim.sim.simulator.simulate` (which re-exports these names) and the pack
vehicle's series run (:mod:`hevsim.sim.pack_vehicle`)."""

from __future__ import annotations

import platform
import time
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

import hevsim
from hevsim.architectures import architecture
from hevsim.architectures.series import SeriesHEV
from hevsim.config import VehicleConfig
from hevsim.cycles import DriveCycle
from hevsim.errors import ConfigError
from hevsim.fuels import config_fuel
from hevsim.sim import kernel as K
from hevsim.sim._records import add_display_units
from hevsim.sim.metrics import compute_metrics, energy_audit, soc_correction_ocv
from hevsim.sim.results import SimulationResult, _Later
from hevsim.units import RADPS_PER_RPM

# The series HEV's compiled kernels (single run, batch run); which architecture runs where is
# the registry's (hevsim.architectures.ARCHITECTURES), not a table here. The driver and
# supervisory controller are chosen inside a kernel by the codes of
# hevsim.sim.kernel.DRIVER_KINDS / SUPERVISOR_KINDS; the battery model is the one loop's, as
# for every architecture (tables, a cell's CellRun or a pack's PackRun stepped by
# hevsim.sim._loop.battery_begin / battery_end).


@dataclass(frozen=True, eq=False)
class GensetSchedule:
    """Genset commands vs time for the ``schedule`` supervisor (e.g. a DP optimum).

    ``engine_speed_radps`` [rad/s] is the speed target (0 = genset off) and
    ``engine_throttle`` [-] the throttle once running; each value holds until the next time.
    ``engine_torque_nm`` [N·m] (optional): the engine torque of each point (default: the
    torque at the throttle).

    ``quasi_static`` False (the ``schedule`` supervisor): the generator cranks the engine to
    90 % of the target speed and its speed loop then holds it, with the shaft's inertia.
    True (the ``replay`` supervisor): the decisions apply exactly as the DP's quasi-static
    model takes them: the engine runs at the scheduled speed and torque from the step it is
    scheduled on, no cranking, no speed dynamics (:meth:`OptimizationResult.genset_schedule
    <hevsim.optimal.OptimizationResult.genset_schedule>`).
    """

    time_s: np.ndarray
    engine_speed_radps: np.ndarray
    engine_throttle: np.ndarray
    source: str = "schedule"
    engine_torque_nm: np.ndarray | None = None
    quasi_static: bool = False

    def __post_init__(self) -> None:
        t = np.asarray(self.time_s, float)
        w = np.asarray(self.engine_speed_radps, float)
        thr = np.asarray(self.engine_throttle, float)
        if not (t.ndim == 1 and t.shape == w.shape == thr.shape and t.size >= 1):
            raise ConfigError(
                f"{self.source}: time, engine speed and throttle must be 1-D arrays of equal "
                f"length, got shapes {t.shape}, {w.shape}, {thr.shape}."
            )
        for name, arr in (("time_s", t), ("engine_speed", w), ("engine_throttle", thr)):
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                raise ConfigError(
                    f"{self.source}: {name} row {bad[0]} is {arr[bad[0]]:g}; expected a finite number."
                )
        if np.any(np.diff(t) <= 0):
            i = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
            raise ConfigError(f"{self.source}: time_s row {i} = {t[i]:g} does not increase.")
        if np.any((thr < 0) | (thr > 1)) or np.any(w < 0):
            raise ConfigError(f"{self.source}: throttle must be within 0..1 and engine speed >= 0.")
        object.__setattr__(self, "time_s", t)
        object.__setattr__(self, "engine_speed_radps", w)
        object.__setattr__(self, "engine_throttle", thr)
        if self.engine_torque_nm is not None:
            tq = np.asarray(self.engine_torque_nm, float)
            if tq.shape != t.shape or not np.all(np.isfinite(tq)):
                raise ConfigError(
                    f"{self.source}: engine_torque_nm must be a finite 1-D array of the length of time_s "
                    f"({t.size}), got shape {tq.shape}."
                )
            object.__setattr__(self, "engine_torque_nm", tq)

    @classmethod
    def from_csv(cls, path: str | Path, quasi_static: bool = False) -> GensetSchedule:
        """Read ``time_s``, ``engine_speed_rpm`` (or ``engine_speed_radps``), ``engine_throttle``
        and, when present, ``engine_torque_nm`` (a DP result's ``timeseries.csv`` has them all)."""
        frame = pd.read_csv(path) if Path(path).is_file() else None
        if frame is None:
            raise ConfigError(f"{path}: schedule file not found; expected a CSV file.")
        if "engine_speed_radps" in frame:
            w = frame["engine_speed_radps"].to_numpy(float)
        elif "engine_speed_rpm" in frame:
            w = frame["engine_speed_rpm"].to_numpy(float) * RADPS_PER_RPM
        else:
            raise ConfigError(
                f"{path}: needs a column engine_speed_rpm or engine_speed_radps; found {list(frame.columns)}."
            )
        for col in ("time_s", "engine_throttle"):
            if col not in frame:
                raise ConfigError(f"{path}: missing column '{col}'; found {list(frame.columns)}.")
        torque = frame["engine_torque_nm"].to_numpy(float) if "engine_torque_nm" in frame else None
        return cls(frame["time_s"].to_numpy(float), w, frame["engine_throttle"].to_numpy(float), str(path),
                   torque, quasi_static)  # fmt: skip

    def on_grid(self, t_s: np.ndarray) -> np.ndarray:
        """(n, 3) array of (speed target [rad/s], throttle [-], engine torque [N·m], NaN when
        not given) held from the latest schedule time."""
        idx = np.clip(np.searchsorted(self.time_s, t_s + 1e-9, side="right") - 1, 0, None)
        torque = (
            self.engine_torque_nm[idx] if self.engine_torque_nm is not None else np.full(idx.size, np.nan)
        )
        return np.ascontiguousarray(
            np.stack([self.engine_speed_radps[idx], self.engine_throttle[idx], torque], 1)
        )


def _check_series_run(hev: SeriesHEV, kind: str, soc_lo: float, soc_hi: float) -> None:
    """ConfigError for a run the series kernel cannot make sense of: an initial SOC outside
    the battery's window, or a thermostat that could never start its genset (the pack never
    goes below ``soc_min``, and cranking ends only at ``start_speed_rpm``)."""
    c = hev.config
    b = c.battery
    if soc_lo < b.soc_min or soc_hi > b.soc_max:
        bad = soc_lo if soc_lo < b.soc_min else soc_hi
        raise ConfigError(
            f"{c.name}: soc_initial = {bad:g} lies outside [battery.soc_min, battery.soc_max] = "
            f"[{b.soc_min:g}, {b.soc_max:g}]."
        )
    if kind != "thermostat" or c.genset.kind == "none":
        return
    ctl = c.controller
    if ctl.soc_low <= b.soc_min:
        raise ConfigError(
            f"{c.name}: key 'controller.soc_low' = {ctl.soc_low:g} must be above 'battery.soc_min' = "
            f"{b.soc_min:g}: the pack never goes below its floor, so the genset would never start."
        )
    if c.genset.kind == "engine" and ctl.start_speed_rpm >= ctl.engine_speed_rpm:
        raise ConfigError(
            f"{c.name}: key 'controller.start_speed_rpm' = {ctl.start_speed_rpm:g} must be below "
            f"'controller.engine_speed_rpm' = {ctl.engine_speed_rpm:g}: the speed loop holds the genset "
            "at engine_speed_rpm, so it would crank forever."
        )


def _plugins(hev: SeriesHEV, grid: DriveCycle, schedule: GensetSchedule | None, p: np.ndarray) -> np.ndarray:
    """Set the role codes in ``p``; return the supervisor's per-step data (a schedule)."""
    cfg = hev.config
    kind = cfg.controller.kind
    if schedule is not None:
        kind = "replay" if schedule.quasi_static else "schedule"
    if kind == "schedule" and schedule is None:
        if not cfg.controller.schedule:
            raise ConfigError(
                f"{cfg.name}: controller.kind = 'schedule' needs controller.schedule (a CSV file)."
            )
        schedule = GensetSchedule.from_csv(Path(cfg.base_dir) / cfg.controller.schedule)
    _check_series_run(hev, kind, float(np.min(p[..., K.SOC0])), float(np.max(p[..., K.SOC0])))
    p[..., K.DRVKIND] = K.DRIVER_KINDS.index(cfg.driver.kind)
    p[..., K.SUPKIND] = K.SUPERVISOR_KINDS.index(kind)
    return schedule.on_grid(grid.time_s) if schedule is not None else np.zeros((1, 3))


def _prepare(
    model: SeriesHEV | VehicleConfig, cycle: DriveCycle | str | None, dt_s: float | None
) -> tuple[SeriesHEV, DriveCycle, DriveCycle, float]:
    hev = (
        model if isinstance(model, SeriesHEV) else architecture("series").build(model)
    )  # the registry's builder
    cfg = hev.config
    from hevsim.sim.forward import cycle_and_step

    cyc, dt = cycle_and_step(cycle, dt_s, cfg.simulation)
    return hev, cyc, _grid(cyc, dt), dt


_GRIDS: dict[tuple[int, float], tuple[weakref.ref[DriveCycle], DriveCycle]] = {}
"""Resampled cycles of :func:`_grid` by (cycle identity, step [s])."""


def _grid(cyc: DriveCycle, dt: float) -> DriveCycle:
    """``cyc`` resampled every ``dt`` [s], made once per cycle object and step: a
    :class:`DriveCycle` is frozen with read-only arrays, so the same object resamples to
    the same grid (kept while the cycle lives; at most 32)."""
    key = (id(cyc), dt)
    hit = _GRIDS.get(key)
    if hit is not None and hit[0]() is cyc:
        return hit[1]
    res = cyc.resampled(dt)
    grid = DriveCycle(res.name, np.array(res.time_s), np.array(res.speed_mps), np.array(res.grade))
    if len(_GRIDS) >= 32:
        _GRIDS.clear()
    _GRIDS[key] = (weakref.ref(cyc), grid)
    return grid


def _energy_keys(hev: SeriesHEV) -> tuple[float, float, float, float]:
    f = config_fuel(hev.config, hev.engine)  # the engine's fuel; no engine: the [fuel] section's
    return (
        f.density_kg_per_m3,
        f.heating_value_btu_per_us_gal,
        f.co2_kg_per_kg,
        f.lower_heating_value_j_per_kg,
    )


def kernel_inputs(
    model: SeriesHEV | VehicleConfig,
    cycle: DriveCycle | str | None = None,
    dt_s: float | None = None,
    soc_initial: float | None = None,
    schedule: GensetSchedule | None = None,
) -> tuple[SeriesHEV, DriveCycle, float, tuple[Any, ...]]:
    """Everything one kernel call needs: ``(model, cycle, dt, args)``; ``kernel(*args)`` runs.

    ``args`` ends with the output buffers ``(out, energy, summary)``; ``args[4]`` is the
    battery, ``(pack tables, the battery run the loop steps or None)``
    (:func:`hevsim.sim._compiled_series.run_compiled`; a ``"cell"`` battery's
    :class:`~hevsim.battery.cell_run.CellRun` is fresh: build the arguments again for another
    run). Used by :func:`hevsim.sim.simulator.simulate` and by benchmarks that time the compiled kernel alone.
    """
    hev, cyc, grid, dt = _prepare(model, cycle, dt_s)
    p = hev.param_vector(soc_initial)
    eng, mot, gen, ptab = hev.kernel_tables()
    battery = (ptab, hev.battery_run(dt, grid.time_s.size - 1, soc_initial))
    sched = _plugins(hev, grid, schedule, p)
    out = np.zeros((grid.time_s.size, len(K.CHANNELS)))
    energy = np.zeros(len(K.ENERGY_TERMS))
    summary = np.zeros(len(K.SUMMARY))
    cyc_arrays = (grid.time_s, grid.speed_mps, grid.grade)
    args = (p, eng, mot, gen, battery, sched, *cyc_arrays, True, out, energy, summary)
    return hev, cyc, dt, args


def _assemble(
    hev: SeriesHEV,
    cyc: DriveCycle,
    dt: float,
    p: np.ndarray,
    out: np.ndarray,
    energy: np.ndarray,
    summary: np.ndarray,
    t_kernel: float,
    t_total: float,
) -> SimulationResult:
    ts = _Later(lambda: _timeseries(out))  # made on first read (_Deferred)
    events = _Later(lambda: _events(out))
    audit = energy_audit(energy)
    socf = summary[K.S_SOCF]
    soc0 = p[K.SOC0]
    ocv_mean = soc_correction_ocv(hev.config.metrics.soc_correction_ocv_v, hev.battery, soc0, socf)
    density, heating, co2, _lhv = _energy_keys(hev)
    metrics = compute_metrics(summary, audit, soc0, hev.battery.capacity_ah, ocv_mean, density,
                              heating, co2, hev.config.metrics.conversion_efficiency)  # fmt: skip
    metadata = {
        "config": hev.name,
        "description": hev.config.description,
        "cycle": cyc.name,
        "cycle_source": cyc.source,
        "dt_s": dt,
        "fuel": config_fuel(hev.config, hev.engine).metadata(),
        "hevsim_version": hevsim.__version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "created_unix_s": time.time(),
        "kernel_time_s": t_kernel,
        "total_time_s": t_total,
    }
    return SimulationResult(ts, metrics, audit, events, metadata, hev, cyc)  # type: ignore[arg-type]  # _Later: _Deferred


INT_CHANNELS = ("genset_state", "power_mode", "mode_reason", "battery_limited")


def _timeseries(out: np.ndarray) -> pd.DataFrame:
    """The kernel's channel array as a DataFrame, with display units and state names added.

    Built from one dict of columns (one copy), in the order of :data:`K.CHANNELS` with
    ``speed_*_mph`` after the speeds and ``engine_speed_rpm`` after the engine speed.
    """
    cols: dict[str, Any] = {}
    for i, name in enumerate(K.CHANNELS):
        col = out[:, i]
        if name in INT_CHANNELS:
            cols[name] = col.astype(np.int64)
        elif name == "fuel_rate_kgps":
            cols["fuel_rate_gps"] = col * 1e3
        else:
            cols[name] = col
        add_display_units(cols, name, col)
    cols["power_mode_name"] = pd.Categorical.from_codes(cols["power_mode"], pd.Index(K.POWER_MODES))
    cols["genset_state_name"] = pd.Categorical.from_codes(cols["genset_state"], pd.Index(K.GENSET_STATES))
    return pd.DataFrame(cols)


def _events(out: np.ndarray) -> pd.DataFrame:
    """The genset-state and power-mode changes of the kernel's channel array ``out``: one
    row per change (time [s], kind, from, to, reason), by time, a genset change before a
    power-mode change at the same time."""
    times = out[:, K.C["time_s"]]
    reasons = out[:, K.C["mode_reason"]].astype(np.int64)
    parts = []
    for col, kind, names in (
        ("genset_state", "genset", K.GENSET_STATES),
        ("power_mode", "power_mode", K.POWER_MODES),
    ):
        vals = out[:, K.C[col]].astype(np.int64)
        changes = np.flatnonzero(np.diff(vals) != 0) + 1
        parts.append((changes, kind, names, vals))
    if not any(c.size for c, *_ in parts):
        return pd.DataFrame([], columns=["time_s", "kind", "from_state", "to_state", "reason"])
    rows = np.concatenate([c for c, *_ in parts])
    order = np.argsort(rows, kind="stable")  # by time; at equal times the genset rows (first) first
    label = np.array(K.REASONS, dtype=object)
    cols: dict[str, list[Any]] = {"time_s": [], "kind": [], "from_state": [], "to_state": [], "reason": []}
    for changes, kind, names, vals in parts:
        table = np.array(names, dtype=object)
        cols["kind"].extend([kind] * changes.size)
        cols["from_state"].extend(table[vals[changes - 1]].tolist())
        cols["to_state"].extend(table[vals[changes]].tolist())
        cols["reason"].extend(label[reasons[changes]].tolist())
    cols["time_s"] = times[rows].tolist()
    ev = pd.DataFrame({k: [v[i] for i in order.tolist()] for k, v in cols.items()})
    return ev

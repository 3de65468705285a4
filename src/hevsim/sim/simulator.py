"""Forward simulation API: :func:`simulate` for one run, :func:`simulate_batch` for variants."""

from __future__ import annotations

import dataclasses
import os
import platform
import time
import weakref
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

import hevsim
from hevsim.architectures import architecture
from hevsim.architectures.series import SeriesHEV
from hevsim.battery.cell import soc_outside
from hevsim.components.engine import Engine
from hevsim.config import (
    SERIES_CONTROLLER_KEYS,
    SERIES_ONLINE_CONTROLLERS,
    VehicleConfig,
    check_series_online,
)
from hevsim.cycles import DriveCycle
from hevsim.errors import ConfigError, DomainError, TrackingError
from hevsim.figures import plotter
from hevsim.fuels import config_fuel
from hevsim.io import atomic_directory, write_json
from hevsim.sim import kernel as K
from hevsim.sim._compiled_series import run_batch, run_compiled
from hevsim.sim.checks import (
    TRACKING_BOUND,
    TrackingBound,
    check_domain,
    check_metrics,
    tracking_message,
    tracking_violation,
)
from hevsim.sim.metrics import compute_metrics, energy_audit, soc_correction_ocv
from hevsim.units import MPS_PER_MPH, RADPS_PER_RPM, c_to_k

CSV_AUTO_MAX_ROWS = 50_000
"""Longest time series [rows] that :meth:`SimulationResult.save` also writes as CSV unless
asked otherwise: about 3 s and 25 MB of CSV; longer runs get Parquet only (``--csv`` forces
CSV)."""


class _Deferred:
    """A :class:`SimulationResult` field that holds its value or a function of no arguments
    that makes it: the function runs on the first read and its value replaces it. The series
    kernel's run assembles its pandas time series and events table this way, so a caller
    that reads only metrics does not pay for them (about a third of a UDDS run's time)."""

    def __init__(self, name: str) -> None:
        self.slot = f"_{name}_value"

    def __get__(self, obj: Any, owner: Any = None) -> Any:
        if obj is None:
            return self
        value = obj.__dict__[self.slot]
        if isinstance(value, _Later):
            value = obj.__dict__[self.slot] = value.make()
        return value

    def __set__(self, obj: Any, value: Any) -> None:
        obj.__dict__[self.slot] = value


@dataclass(frozen=True)
class _Later:
    """A value to make on first read (:class:`_Deferred`)."""

    make: Any


@dataclass
class SimulationResult:
    """One forward simulation: time series, scalar metrics, energy audit, events, metadata.

    ``timeseries`` and ``events`` may be handed over as ``_Later(function)``: made on their
    first read (a pickle or copy makes them first)."""

    timeseries: pd.DataFrame
    metrics: dict[str, dict[str, Any]]
    energy_audit: dict[str, float]
    events: pd.DataFrame
    metadata: dict[str, Any]
    model: SeriesHEV
    cycle: DriveCycle
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def engine(self) -> Engine | None:
        """The engine of the simulated vehicle (for operating-point plots)."""
        return self.model.engine

    def value(self, name: str) -> float:
        """Value of metric ``name`` (in its unit)."""
        return float(self.metrics[name]["value"])

    def __getstate__(self) -> dict[str, Any]:
        _ = self.timeseries, self.events  # make the deferred fields: a function may not pickle
        return self.__dict__.copy()

    def save(self, out_dir: str | Path, plots: bool = True, csv: bool | None = None) -> Path:
        """Write the results folder atomically: time series (Parquet, and CSV for short runs
        or on request), metrics.json, energy_audit.json, events.csv, config.json and, with
        ``plots``, the PNG plots and report.md (the ``"simulation"`` plotter of
        :mod:`hevsim.figures`, which :mod:`hevsim.report` registers).

        ``csv`` None writes ``timeseries.csv`` only when the run has at most
        :data:`CSV_AUTO_MAX_ROWS` rows (CSV costs about 60 µs a row, Parquet a twentieth of
        that); True or False forces it on or off. Files are written to a temporary sibling
        folder that is renamed into place, so an interrupted run leaves no partial folder.
        An existing folder is replaced.
        """
        write_csv = len(self.timeseries) <= CSV_AUTO_MAX_ROWS if csv is None else bool(csv)
        with atomic_directory(out_dir) as tmp:
            self.timeseries.to_parquet(tmp / "timeseries.parquet", index=False)
            if write_csv:
                self.timeseries.to_csv(tmp / "timeseries.csv", index=False, float_format="%.6g")
            self.events.to_csv(tmp / "events.csv", index=False)
            write_json(tmp / "metrics.json", self.metrics)
            write_json(
                tmp / "energy_audit.json",
                {k: {"value": v, "unit": "J"} for k, v in self.energy_audit.items()},
            )
            write_json(tmp / "config.json", self.model.config.to_dict())
            write_json(tmp / "metadata.json", self.metadata)
            if plots:  # the report layer's plotter: every plot that applies and report.md
                plotter("simulation")(self, tmp)
        return Path(out_dir)


SimulationResult.timeseries = _Deferred("timeseries")  # type: ignore[assignment]
SimulationResult.events = _Deferred("events")  # type: ignore[assignment]


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


def _other_architecture(model: Any) -> str | None:
    """The architecture name of a non-series configuration or model, else None."""
    cfg = getattr(model, "config", model)
    name = getattr(cfg, "architecture", "series")
    return None if name == "series" or isinstance(model, SeriesHEV) else str(name)


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


def _simulate_pack_options(
    model: Any,
    cycle: Any,
    dt_s: float | None,
    soc_initial: float | None,
    schedule: Any,
    controller: Any,
    controller_params: dict[str, Any],
    **pack_options: Any,
) -> SimulationResult:
    """:func:`simulate` with a pack's ambient, soak, cooling or age options (ConfigError
    naming the option and the battery model when the vehicle has no pack)."""
    cfg: Any = getattr(model, "config", model)
    given = [k for k, v in pack_options.items() if v is not None and v is not False]
    battery = getattr(cfg, "battery", None)
    if battery is not None and battery.model == "cell":
        return _simulate_cell_options(model, cycle, dt_s, soc_initial, schedule, controller,
                                      controller_params, given, **pack_options)  # fmt: skip
    if battery is None or battery.model != "pack":
        got = "no [battery]" if battery is None else f"key 'battery.model' = {battery.model!r}"
        raise ConfigError(
            f"{cfg.name}: simulate({', '.join(given)}=...) sets the pack's ambient, cooling or age; it "
            f"needs [battery] model = 'pack' (got {got})."
        )
    if controller_params:
        cfg = cfg.replace(**{f"controller.{k}": v for k, v in controller_params.items()})
        model = cfg
    from hevsim.sim.pack_vehicle import simulate_pack_vehicle

    return simulate_pack_vehicle(model, cycle, dt_s, soc_initial, controller=controller, schedule=schedule,
                                 ambient_temp_c=pack_options["ambient_c"], soak=pack_options["soak"],
                                 cooling_off=pack_options["cooling_off"],
                                 age_state=pack_options["age_state"])  # fmt: skip


def _simulate_cell_options(
    model: Any,
    cycle: Any,
    dt_s: float | None,
    soc_initial: float | None,
    schedule: Any,
    controller: Any,
    controller_params: dict[str, Any],
    given: list[str],
    **options: Any,
) -> SimulationResult:
    """:func:`simulate` of a ``[battery] model = "cell"`` vehicle at another ambient: the
    cells' heat port at ``ambient_c`` [degC]; with ``soak`` the cells start at it too (the
    configuration's ``battery.temperature_c``). The series HEV's kernel supervisors run the
    cells (:meth:`~hevsim.architectures.series.SeriesHEV.battery_run`) with that port; the other
    architectures :func:`hevsim.sim.forward.simulate_cell_architecture`.
    ConfigError for the pack's cooling and age options (a cell battery has neither)."""
    cfg: Any = getattr(model, "config", model)
    bad = [k for k in ("cooling_off", "age_state") if k in given]
    if bad:
        raise ConfigError(
            f"{cfg.name}: simulate({', '.join(bad)}=...) sets a pack's cooling loop or cell ages; "
            "key 'battery.model' = 'cell' has neither (expected [battery] model = 'pack'); 'cell' takes "
            "ambient_c and soak."
        )
    ambient, soak = options["ambient_c"], options["soak"]
    if soak and ambient is None:
        raise ConfigError(f"{cfg.name}: soak starts the cells at the ambient; give ambient_c with it.")
    from hevsim.sim.cell_vehicle import soaked

    if soak:  # the cells start at the ambient
        cfg = model = soaked(cfg, ambient)
    other = _other_architecture(model)
    kind = cfg.controller.kind if controller is None else controller
    online = not isinstance(kind, str) or kind not in SERIES_CONTROLLER_KEYS  # the series HEV's ECMS, replay
    if other is not None or online:
        from hevsim.sim.forward import simulate_cell_architecture

        if controller_params:
            model = cfg.replace(**{f"controller.{k}": v for k, v in controller_params.items()})
        if other is None and schedule is not None:
            raise ConfigError(
                f"simulate: a genset schedule replaces the series HEV's supervisor; got {kind!r}."
            )
        return simulate_cell_architecture(other or "series", model, cycle, dt_s, soc_initial, controller,
                                          ambient_temp_c=ambient)  # fmt: skip
    hev = model if isinstance(model, SeriesHEV) else architecture("series").build(model)
    if ambient is not None:  # ... and their heat port is at it
        hev = dataclasses.replace(hev, cell_port_temp_k=c_to_k(float(ambient)))
    return simulate(hev, cycle, dt_s, soc_initial, schedule, controller=controller, **controller_params)


def simulate(
    model: SeriesHEV | VehicleConfig | str | Path,
    cycle: DriveCycle | str | None = None,
    dt_s: float | None = None,
    soc_initial: float | None = None,
    schedule: GensetSchedule | None = None,
    tracking: TrackingBound | None = TRACKING_BOUND,
    controller: Any = None,
    *,
    ambient_c: float | None = None,
    soak: bool = False,
    cooling_off: bool = False,
    age_state: Any = None,
    **controller_params: Any,
) -> SimulationResult:
    """Simulate ``model`` (a vehicle file path, configuration or built model of any
    architecture) forward over ``cycle`` with a fixed step ``dt_s`` [s].

    ``ambient_c`` [degC], ``soak``, ``cooling_off`` and ``age_state`` (a
    :class:`hevsim.battery.life.PackAgeState`, advanced in place) are for a vehicle with
    ``[battery] model = "pack"`` (any architecture but the conventional car): the pack's
    ambient, cells and coolant starting at it, the cooling loop stopped, the cells' age
    (:func:`hevsim.sim.pack_vehicle.simulate_pack_vehicle`). ``ambient_c`` and ``soak`` also
    serve ``[battery] model = "cell"``: the cells' heat port at the ambient, with ``soak`` their
    start too (:func:`hevsim.sim.forward.simulate_cell_architecture`). ``hevsim.simulate`` is this
    function.

    ``cycle`` is a :class:`DriveCycle`, a registered name or a CSV path (default: the
    configuration's). ``schedule`` replaces the configured supervisory controller by a genset
    schedule (for example a DP optimum). Returns a :class:`SimulationResult`.

    ``controller``: a ``[controller] kind`` name or a controller object of
    :mod:`hevsim.control` (default: the configuration's kind), ``controller_params`` override
    ``[controller]`` values (``equivalence_factor=2.6``). The series HEV's kernel supervisors
    (``thermostat``, ``schedule``) run in its compiled kernel; its online controllers
    (``ecms``, ``aecms``: :data:`hevsim.config.SERIES_ONLINE_CONTROLLERS`) run on its
    quasi-static power flow (:func:`hevsim.architectures.series.power_flow`, the DP's stage
    model) in the loop every other architecture uses,
    :func:`hevsim.sim.forward.simulate_architecture` (driver: the trace follower of that loop).

    Any other architecture (parallel, conventional, BEV, power split: a configuration or a
    built model) runs in :func:`hevsim.sim.forward.simulate_architecture`.

    Raises :class:`~hevsim.errors.DomainError` when a recorded channel becomes NaN or
    infinite or the SOC leaves [0, 1], and :class:`~hevsim.errors.TrackingError` (holding the
    completed result as ``.result``) when the speed error stays beyond ``tracking``
    (default :data:`~hevsim.sim.checks.TRACKING_BOUND`; None skips that check).
    """
    if isinstance(model, str | Path):  # a vehicle file of any architecture
        from hevsim.config import load_vehicle_config

        model = load_vehicle_config(model)
    if ambient_c is not None or soak or cooling_off or age_state is not None:
        pack = {"ambient_c": ambient_c, "soak": soak, "cooling_off": cooling_off, "age_state": age_state}
        return _simulate_pack_options(model, cycle, dt_s, soc_initial, schedule, controller,
                                      controller_params, **pack)  # fmt: skip
    other = _other_architecture(model)
    if other is not None:  # parallel, conventional, BEV, power split: hevsim.sim.forward
        if schedule is not None:
            raise ConfigError(
                f"simulate: a genset schedule is for the series HEV; this is a {other} vehicle (pass a "
                "controller to hevsim.sim.forward.simulate_architecture instead)."
            )
        from hevsim.sim.forward import simulate_architecture

        return simulate_architecture(other, model, cycle, dt_s, soc_initial, controller, **controller_params)
    cfg_any: Any = getattr(model, "config", model)
    kind = cfg_any.controller.kind
    if isinstance(controller, str):
        if controller in SERIES_CONTROLLER_KEYS and controller != kind:
            raise ConfigError(
                f"simulate: controller {controller!r} is a series-kernel supervisor; set key "
                f"'controller.kind' = {controller!r} in the configuration (it holds {kind!r})."
            )
        kind = controller
    if (controller is not None and not isinstance(controller, str)) or kind not in SERIES_CONTROLLER_KEYS:
        if schedule is not None:
            raise ConfigError(
                f"simulate: a genset schedule replaces the series HEV's supervisor; got controller {kind!r} "
                "too."
            )
        from hevsim.sim.forward import simulate_architecture

        check_series_online(cfg_any, cfg_any.name, getattr(controller, "name", kind))
        return simulate_architecture(
            "series", model, cycle, dt_s, soc_initial, controller, **controller_params
        )
    if controller_params:
        raise ConfigError(
            f"simulate: controller parameters ({', '.join(controller_params)}) are for the online "
            f"controllers ({', '.join(SERIES_ONLINE_CONTROLLERS)}); the series kernel's {kind!r} reads "
            "its [controller] section."
        )
    if getattr(getattr(getattr(model, "config", model), "battery", None), "model", "") == "pack":
        from hevsim.sim.pack_vehicle import simulate_pack_vehicle

        return simulate_pack_vehicle(model, cycle, dt_s, soc_initial, schedule=schedule)
    t_start = time.perf_counter()
    assert not isinstance(model, str | Path)  # a path was loaded above
    hev, cyc, dt, args = kernel_inputs(model, cycle, dt_s, soc_initial, schedule)
    t_kernel = time.perf_counter()
    run_compiled(*args)
    t_done = time.perf_counter()
    p, out, energy, summary = args[0], args[-3], args[-2], args[-1]
    label = f"{hev.name} on {cyc.name}"
    check_domain(label, args[6], out, energy, summary, p)
    result = _assemble(hev, cyc, dt, p, out, energy, summary, t_done - t_kernel, t_done - t_start)
    cells = args[4][1]
    if cells is not None:  # a "cell" battery: its channels, metrics and energy terms, as every architecture's
        from hevsim.sim.cell_vehicle import attach_cells

        attach_cells(result, cells, hev.config)
    if tracking is not None:
        error = out[:, K.C["speed_desired_mps"]] - out[:, K.C["speed_mps"]]
        if tracking_violation(out[:, K.C["time_s"]], error, tracking) is not None:  # (the message's test)
            message = tracking_message(label, result.timeseries, p, tracking)
            if message is not None:
                raise TrackingError(message, result)
    check_metrics(label, result.metrics)
    return result


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
    run). Used by :func:`simulate` and by benchmarks that time the compiled kernel alone.
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
        if name in ("speed_desired_mps", "speed_mps"):
            cols[name.replace("_mps", "_mph")] = col / MPS_PER_MPH
        elif name == "engine_speed_radps":
            cols["engine_speed_rpm"] = col / RADPS_PER_RPM
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


@dataclass
class BatchResult:
    """Scalar results of a batch of variants: one row per variant."""

    table: pd.DataFrame
    elapsed_s: float

    @property
    def rate_per_s(self) -> float:
        """Variant-cycles simulated per second of wall time."""
        return len(self.table) / self.elapsed_s if self.elapsed_s > 0 else float("inf")


def simulate_batch(
    model: SeriesHEV | VehicleConfig,
    variants: dict[str, Any],
    cycle: DriveCycle | str | None = None,
    dt_s: float | None = None,
    compiled: bool | None = None,
) -> BatchResult:
    """Run many parameter variants of one vehicle in one parallel call.

    ``variants`` maps kernel parameter names (:data:`hevsim.sim.kernel.PARAMS`, e.g.
    ``"mass_kg"``, ``"driver_gain_per_mps"``, ``"soc_initial"``) to arrays of equal length
    (scalars broadcast). Returns fuel economy and summaries per variant. For the other
    architectures, and a series HEV whose ``[controller] kind`` is an online controller
    (``ecms``, ``aecms``: it runs in :mod:`hevsim.sim.forward`), the variants are dotted
    configuration keys (``"body.mass_kg"``), run by the architecture's compiled batch where it
    has one, else one after the other (:func:`hevsim.sim.forward.simulate_batch_architecture`;
    ``compiled=False`` forces the latter).
    """
    other = _other_architecture(model)
    cfg_any: Any = getattr(model, "config", model)
    if other is not None or cfg_any.controller.kind in SERIES_ONLINE_CONTROLLERS:
        from hevsim.sim.forward import simulate_batch_architecture

        return simulate_batch_architecture(model, variants, cycle, dt_s, compiled=compiled)
    hev, _cyc, grid, _dt = _prepare(model, cycle, dt_s)
    unknown = [k for k in variants if k not in K.P]
    if unknown:
        raise ConfigError(
            f"batch variants: parameter(s) {unknown} are not known; valid names are: {', '.join(K.PARAMS)}."
        )
    arrays = {k: np.atleast_1d(np.asarray(v, dtype=np.float64)) for k, v in variants.items()}
    try:
        n = np.broadcast_shapes(*(a.shape for a in arrays.values()))[0] if arrays else 1
    except ValueError as exc:
        shapes = {k: a.shape for k, a in arrays.items()}
        raise ConfigError(f"batch variants: arrays must have equal lengths, got {shapes}.") from exc
    base = hev.param_vector()
    pmat = np.repeat(base[None, :], n, axis=0)
    for k, a in arrays.items():
        pmat[:, K.P[k]] = np.broadcast_to(a, (n,))
    if hev.cell is not None or hev.config.battery.model == "pack":
        raise ConfigError(
            f"{hev.name}: batch runs with battery.model = {hev.config.battery.model!r} are not supported "
            "(the cells' dynamic state would be shared by the variants); use simulate() per variant."
        )
    eng, mot, gen, bat = hev.kernel_tables()
    energy = np.zeros((n, len(K.ENERGY_TERMS)))
    summary = np.zeros((n, len(K.SUMMARY)))
    t0 = time.perf_counter()
    sched = _plugins(hev, grid, None, pmat)
    run_batch(pmat, eng, mot, gen, bat, sched, grid.time_s, grid.speed_mps, grid.grade, energy, summary)
    elapsed = time.perf_counter() - t0
    density, heating, co2, _ = _energy_keys(hev)
    rows = []
    for i in range(n):
        audit = energy_audit(energy[i])
        soc0 = pmat[i, K.SOC0]
        ocv_mean = soc_correction_ocv(
            hev.config.metrics.soc_correction_ocv_v, hev.battery, soc0, summary[i, K.S_SOCF]
        )
        m = compute_metrics(summary[i], audit, soc0, hev.battery.capacity_ah, ocv_mean, density,
                            heating, co2, hev.config.metrics.conversion_efficiency)  # fmt: skip
        row = {k: float(pmat[i, K.P[k]]) for k in arrays}
        row.update({name: v["value"] for name, v in m.items()})
        rows.append(row)
    if not np.all(np.isfinite(summary)):
        i = int(np.flatnonzero(~np.isfinite(summary).all(axis=1))[0])
        values = ", ".join(f"{k} = {float(pmat[i, K.P[k]]):g}" for k in arrays)
        raise DomainError(
            f"batch: variant {i} ({values}) produced non-finite results; expected parameters "
            "within their physical ranges."
        )
    socf = summary[:, K.S_SOCF]
    out_of_range = soc_outside(socf)  # the battery layer's SOC domain (SOC_TOLERANCE)
    if out_of_range is not None:  # a batch records no time series: only the final SOC is checked
        i = out_of_range[0]
        values = ", ".join(f"{k} = {float(pmat[i, K.P[k]]):g}" for k in arrays)
        raise DomainError(
            f"batch: variant {i} ({values}) ended with SOC {socf[i]:.4g}; expected a state of "
            "charge in [0, 1] (the battery ran dry or was overcharged)."
        )
    return BatchResult(pd.DataFrame(rows), elapsed)


def default_workers() -> int:
    """CPU cores available to this process."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1

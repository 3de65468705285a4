"""Forward simulation API: :func:`simulate` for one run, :func:`simulate_batch` for variants."""

from __future__ import annotations

import dataclasses
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.architectures import architecture
from hevsim.architectures.series import SeriesHEV
from hevsim.battery.cell import soc_outside
from hevsim.config import (
    SERIES_CONTROLLER_KEYS,
    SERIES_ONLINE_CONTROLLERS,
    VehicleConfig,
    check_series_online,
)
from hevsim.cycles import DriveCycle
from hevsim.errors import ConfigError, DomainError, TrackingError
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
from hevsim.sim.results import CSV_AUTO_MAX_ROWS, BatchResult, SimulationResult, _Deferred, _Later  # noqa: F401 (re-exported)
from hevsim.sim.series_run import GensetSchedule, _assemble, _energy_keys, _plugins, _prepare, kernel_inputs
from hevsim.units import c_to_k


def _other_architecture(model: Any) -> str | None:
    """The architecture name of a non-series configuration or model, else None."""
    cfg = getattr(model, "config", model)
    name = getattr(cfg, "architecture", "series")
    return None if name == "series" or isinstance(model, SeriesHEV) else str(name)


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

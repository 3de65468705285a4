"""Forward simulation of the quasi-static architectures (parallel HEV, conventional, BEV):
driver -> supervisory controller -> the architecture's power flow -> vehicle.

Each step ``k`` (``t_k`` to ``t_k + dt``):

1. **Driver** (trace follower with the powertrain's capability as its limit, as FASTSim's):
   it asks for the wheel force that brings the car from its speed ``v`` to the cycle's
   next speed ``v*`` in one step, ``F = road_load(v_mid, (v* - v)/dt, grade)`` at the
   mid-step speed (eq 32).
2. **Supervisory controller** (:mod:`hevsim.control`): picks the control (parallel: gear and
   throttle; conventional: gear; BEV: none) from the candidates, scoring them with the
   architecture's vectorised power flow (``step.evaluate``). If no control can deliver the
   force, the end speed is lowered by bisection until one can (the car falls behind the
   trace; ``traction_limited`` is set). A full-throttle launch is this limit.
3. **Power flow** (``power_flow`` of the architecture's module in
   :mod:`hevsim.architectures`): the chosen control's operating points, fuel, battery
   current and SOC change, and ``loss_powers`` for the energy audit.
4. **Vehicle**: the speed becomes the end speed that force gives; every power is taken at
   the mid-step speed, so ``F v_mid dt = Δ(m v²/2) + road losses`` exactly and the audit
   closes to round-off.

The driver and the power flow are exactly the DP's quasi-static stage model when the car
follows the trace, so replaying a DP optimum reproduces its fuel.

An architecture module used here provides ``power_flow(model, wheel_speed_radps,
wheel_torque_nm, *controls, soc, dt_s, regen_ok, battery_state, detail=False)`` (a
:class:`~hevsim.components.flow.Stage` with ``details``), ``loss_powers(model, stage,
wheel_speed_radps, wheel_torque_nm)`` (W per audit term, with ``fuel`` and ``wheel``),
``MODES`` and ``power_mode(details, wheel_force_n, v_mid_mps)``; optionally
``extra_metrics(model, metrics)`` (adds its own figures to a run's metrics).

**Compiled runs (optional hooks).** The Python loop above is the reference. A compiled loop
of this package (``hevsim.sim._compiled_*``, found by :func:`compiled_loop` from the
architectures it declares in ``ARCHITECTURES``; the architecture modules never import it)
defines

``simulate_compiled(model, grid, controller, *, soc_initial, soc_min, soc_max)``
    one run on ``grid`` (the cycle resampled to the time step: ``time_s`` [s],
    ``speed_mps`` [m/s], ``grade`` [-], ``n + 1`` points) with the controller object
    ``controller`` (from :func:`hevsim.control.make_controller`), starting at
    ``soc_initial`` [-] in the window ``soc_min..soc_max`` [-]. It returns a
    :class:`ForwardRecord` equal (to round-off) to what the Python loop records, or None
    when this controller or option has no compiled form (the Python loop then runs). It
    leaves the controller as the loop would (``reset`` then its per-step state, e.g. the
    final equivalence factor ``s`` of an adaptive ECMS).

``simulate_batch_compiled(model, variants, grid, controller, *, soc_initial, soc_min, soc_max)``
    the same for ``n`` parameter variants at once: ``variants`` maps dotted configuration
    keys (``"body.mass_kg"``) to float arrays of length ``n`` (already validated).
    Returns a :class:`BatchRecord`, or None when a key, the controller or an option has no
    compiled form (the variants then run one by one through :func:`simulate_architecture`).

:func:`simulate_architecture` turns either record into the same result (channels, audit,
metrics, events) as the Python loop; ``compiled=False`` (or the environment variable
``HEVSIM_FORWARD=python``) forces the Python loop.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import os
import platform
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

import hevsim
from hevsim.components.flow import LIMIT_RTOL
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.errors import ConfigError, DomainError, InputError
from hevsim.fuels import config_fuel
from hevsim.sim import kernel as K
from hevsim.sim._loop import AUDIT_ROAD, add_road_audit, track_step, write_summary
from hevsim.sim._records import (  # re-exported: the records every forward loop fills
    BISECTION_STEPS,
    REGEN_CURRENT_RTOL,
    ForwardRecord,
    add_display_units,
)
from hevsim.sim.checks import stuck_error
from hevsim.sim.metrics import compute_metrics, soc_correction_ocv

SOURCES = ("fuel", "genset_source", "battery_chemical")
"""Energy sources of the audit; every other term is a sink."""
INT_COLUMNS = ("gear", "power_mode", "traction_limited")
BOOL_COLUMNS = ("engine_on", "clutch_closed", "clutch_slipping", "fuel_cut")


LOG = logging.getLogger("hevsim")

FORWARD_ENV = "HEVSIM_FORWARD"
"""Environment variable: ``python`` makes :func:`simulate_architecture` default to the Python
loop even where the architecture has a compiled run (tests compare the two)."""


@dataclass
class Step:
    """What a controller sees at one step: demand, state and the power flow of candidates.

    Attributes: k, time_s [s], dt_s [s], v_mid_mps [m/s], wheel_speed_radps [rad/s],
    wheel_torque_nm [N·m], soc [-], energy_per_soc_j (Q x OCV, 1 without a battery) [J].
    """

    model: Any
    flow: Any
    k: int
    time_s: float
    dt_s: float
    v_mid_mps: float
    wheel_speed_radps: float
    wheel_torque_nm: float
    soc: float
    energy_per_soc_j: float
    battery_state: Any
    soc_min: float
    soc_max: float = 1.0

    @property
    def hev(self) -> Any:
        """The vehicle model (former name)."""
        return self.model

    def evaluate(self, *controls: Any, detail: bool = False) -> tuple[Any, np.ndarray]:
        """(Stage of the power flow, feasible) for candidate controls (arrays, broadcast)."""
        st = self.flow(
            self.model, self.wheel_speed_radps, self.wheel_torque_nm, *controls, self.soc, self.dt_s,
            self.v_mid_mps > 0.0, self.battery_state, detail=detail,
        )  # fmt: skip
        feasible = ~np.asarray(st.infeasible)
        flow = getattr(st, "flow", None)
        if flow is not None:
            flags = st.flags
            if "battery_charge_current" in flags:  # see REGEN_CURRENT_RTOL
                others = np.zeros(np.shape(feasible), dtype=bool)
                for name, flag in flags.items():
                    if name != "battery_charge_current":
                        others = others | np.asarray(flag)
                limit = self.model.battery.max_charge_current_a
                near = np.asarray(flow.current_a) >= -limit * (1.0 + REGEN_CURRENT_RTOL)
                feasible = feasible | (~others & near & (np.asarray(flow.torque_nm) < 0.0))
            if self.soc <= self.soc_min:  # empty: no discharge for traction (the auxiliaries on the
                # bus are still supplied: at a standstill nothing else could feed them)
                aux_w = float(getattr(self.model, "aux_power_w", 0.0))
                feasible = feasible & (np.asarray(flow.battery_power_w) <= aux_w * (1.0 + 1e-6))
            if self.soc >= self.soc_max:  # full: no charging from any source (the engine through a
                # generator too), up to the regeneration limiter's round-off (REGEN_CURRENT_RTOL)
                tol = REGEN_CURRENT_RTOL * np.abs(np.asarray(flow.power_elec_w))
                feasible = feasible & (np.asarray(flow.battery_power_w) >= -tol)
        return st, np.broadcast_to(feasible, np.shape(st.d_soc))


def _battery_state(model: Any, soc: float, soc_max: float) -> Any:
    from hevsim.components.flow import BatteryState

    bs = BatteryState.at(model.battery, np.asarray(soc))
    if soc >= soc_max:  # full: no charging (regeneration goes to the friction brakes)
        bs = dataclasses.replace(bs, p_charge_max_w=np.zeros_like(bs.p_charge_max_w))
    return bs


def cycle_and_step(
    cycle: DriveCycle | str | None, dt_s: float | None, simulation: Any
) -> tuple[DriveCycle, float]:
    """(drive cycle, time step [s]) of a run: ``cycle`` (a :class:`DriveCycle`, registered
    name or CSV path) and ``dt_s``, by default the ``[simulation]`` section's; checks the step
    (0.001 to 10 s) and that the cycle moves."""
    cyc = cycle if isinstance(cycle, DriveCycle) else load_cycle(cycle or simulation.cycle)
    dt = float(dt_s if dt_s is not None else simulation.dt_s)
    if not 1e-3 <= dt <= 10.0:
        raise ConfigError(f"time step dt_s = {dt:g} is out of range; expected 0.001 to 10 s.")
    if cyc.distance_m <= 0.0:
        raise InputError(
            f"drive cycle '{cyc.name}'"
            + (f" ({cyc.source})" if cyc.source else "")
            + ": the vehicle stands still for the whole cycle (distance 0 m); expected a cycle "
            "with some speed > 0 (fuel economy and per-distance figures are undefined otherwise)."
        )
    return cyc, dt


def simulate_architecture(
    name: str,
    model: Any,
    cycle: DriveCycle | str | None = None,
    dt_s: float | None = None,
    soc_initial: float | None = None,
    controller: Any = None,
    compiled: bool | None = None,
    pack_run: Any = None,
    **controller_params: Any,
) -> Any:
    """Simulate a vehicle of architecture ``name`` (file path, configuration or built model)
    forward over ``cycle``.

    ``controller``: a controller object (:mod:`hevsim.control`, e.g. a
    :class:`~hevsim.control.parallel.ControlSchedule`), a ``[controller] kind`` name, or
    None for the configuration's; ``controller_params`` override ``[controller]`` values
    (``equivalence_factor=2.6``). ``dt_s`` [s] defaults to the configuration's; the cycle is
    resampled to it. ``compiled``: use the architecture's compiled run where it has one for
    this controller (default: yes, unless ``HEVSIM_FORWARD=python``); False forces the
    Python loop. ``pack_run``: the :class:`~hevsim.battery.bms.PackRun` of a ``[battery]
    model = "pack"`` vehicle, whose compiled step runs inside the compiled loop (or is called
    step by step from the Python loop); without one such a vehicle goes to
    :func:`hevsim.sim.pack_vehicle.simulate_pack_vehicle`, which makes it), or the
    :class:`~hevsim.battery.cell_run.CellRun` of a ``[battery] model = "cell"`` vehicle (the
    same protocol; without one: :func:`simulate_cell_architecture`). Returns a
    :class:`~hevsim.sim.simulator.SimulationResult`.
    """
    from hevsim.architectures import architecture
    from hevsim.config import load_vehicle_config
    from hevsim.control import make_controller
    from hevsim.sim.results import SimulationResult

    t_start = time.perf_counter()
    arch = architecture(name)
    mod = arch.power_module()
    if isinstance(model, str | Path):
        model = load_vehicle_config(model)
    if isinstance(model, arch.config_type):
        model = arch.build(model)
    cfg = getattr(model, "config", None)
    if cfg is None or cfg.architecture != name:
        got = getattr(cfg, "architecture", type(model).__name__)
        raise ConfigError(f"simulate: key 'powertrain.architecture' = {got!r}; expected {name!r} here.")
    if hasattr(mod, "quasi_static_model"):  # series: the motor's rotor inertia in the effective mass
        model = mod.quasi_static_model(model)
    ctl = controller if controller is not None and not isinstance(controller, str) else None
    if ctl is None:
        ctl = make_controller(model, controller, **controller_params)
    elif controller_params:
        raise ConfigError("simulate: controller parameters need a controller kind, not a controller object.")
    cyc, dt = cycle_and_step(cycle, dt_s, cfg.simulation)
    grid = cyc.resampled(dt)
    b = getattr(cfg, "battery", None)
    soc0 = float(cfg.simulation.soc_initial if soc_initial is None else soc_initial)
    if b is not None and not b.soc_min <= soc0 <= b.soc_max:
        raise ConfigError(
            f"soc_initial = {soc0:g} lies outside [battery.soc_min, battery.soc_max] = "
            f"[{b.soc_min:g}, {b.soc_max:g}]."
        )
    if b is not None and b.model == "cell" and pack_run is None:  # hevsim.sim.cell_vehicle
        return simulate_cell_architecture(name, model, cyc, dt, soc0, ctl, compiled)
    if b is not None and b.model == "pack" and pack_run is None:  # a fresh run of its pack
        from threadpoolctl import threadpool_limits

        from hevsim.sim.pack_setup import _attach, make_pack_run

        run = make_pack_run(cfg, dt, soc0)
        with threadpool_limits(1, user_api="blas"):  # as hevsim.sim.pack_vehicle.simulate_pack_vehicle
            res = simulate_architecture(name, model, cyc, dt, soc0, ctl, pack_run=run)
        _attach(res, run, cfg)
        return res
    t_k0 = time.perf_counter()
    window = (b.soc_min, b.soc_max) if b is not None else (0.0, 1.0)
    hook = getattr(compiled_loop(name), "simulate_compiled", None) if use_compiled(compiled) else None
    rec = None
    if hook is not None:  # a pack steps inside the compiled loop (its compiled step, issue 24)
        extra = {"pack": pack_run} if pack_run is not None else {}
        rec = hook(model, grid, ctl, soc_initial=soc0, soc_min=window[0], soc_max=window[1], **extra)
    ran_compiled = rec is not None
    if rec is None:
        rec = _run(mod, model, ctl, grid, soc0, window[0], window[1], pack=pack_run)
    ts, audit, summary, events = finish_record(rec, grid, mod.MODES)
    t_done = time.perf_counter()
    traction = float(np.sum(np.clip(ts["wheel_power_w"].to_numpy()[:-1], 0.0, None)) * dt)
    metrics = run_metrics(model, summary, audit, traction, soc0)
    if hasattr(mod, "extra_metrics"):  # an architecture's own figures (the FCEV's hydrogen and MPGe)
        mod.extra_metrics(model, metrics)
    f = config_fuel(cfg, getattr(model, "engine", None))
    bad = [k for k, m in metrics.items() if np.isnan(float(m["value"]))]
    if bad or not all(np.isfinite(c).all() for c in rec.columns.values()):
        raise DomainError(
            f"{model.name} on {cyc.name}: non-finite results ({', '.join(bad) or 'time series'})."
        )
    if "soc" in ts:  # a state outside its physical domain stops the run (no silently wrong number)
        soc = ts["soc"].to_numpy()
        out = np.flatnonzero((soc < 0.0) | (soc > 1.0))
        if out.size:
            k = int(out[0])
            raise DomainError(
                f"{model.name} on {cyc.name}: battery SOC = {soc[k]:.6g} at t = {ts['time_s'].iloc[k]:g} s "
                "leaves [0, 1]; check battery.soc_min/soc_max and the controller's charge limits."
            )
    metadata = {
        "architecture": name, "config": model.name, "description": cfg.description, "cycle": cyc.name,
        "cycle_source": cyc.source, "dt_s": dt, "controller": getattr(ctl, "name", type(ctl).__name__),
        "fuel": f.metadata(), "hevsim_version": hevsim.__version__, "python": platform.python_version(),
        "numpy": np.__version__, "created_unix_s": time.time(), "kernel_time_s": t_done - t_k0,
        "total_time_s": time.perf_counter() - t_start, "compiled": ran_compiled,
    }  # fmt: skip
    if hasattr(ctl, "s"):
        metadata["equivalence_factor_final"] = float(ctl.s)
    if getattr(ctl, "_shed", True) is not None and hasattr(ctl, "ramp_down_overrides"):  # a fuel cell
        metadata["ramp_down_overrides"] = int(ctl.ramp_down_overrides)
    if hasattr(ctl, "deviated_steps"):  # a schedule replay: steps it could not follow (hevsim.control)
        metadata.update(ctl.report(metrics))
        if ctl.deviated_steps:
            LOG.warning(
                "%s on %s: the schedule's control was infeasible at %d step(s) from t = %g s (e.g. "
                "the BMS limits the battery below what the schedule needs); the closest feasible "
                "control was applied (metadata schedule_*).",
                model.name,
                cyc.name,
                ctl.deviated_steps,
                ctl.deviated_first_s,
            )
    return SimulationResult(ts, metrics, audit, events, metadata, model, cyc)


def simulate_cell_architecture(
    name: str,
    model: Any,
    cycle: DriveCycle | str | None = None,
    dt_s: float | None = None,
    soc_initial: float | None = None,
    controller: Any = None,
    compiled: bool | None = None,
    ambient_temp_c: float | None = None,
) -> Any:
    """:func:`simulate_architecture` of a ``[battery] model = "cell"`` vehicle of architecture
    ``name`` (the series HEV's online controllers too; its kernel supervisors step the cells in
    its kernel, :func:`hevsim.sim.simulator.simulate`): a fresh
    :class:`~hevsim.battery.cell_run.CellRun` of its ``[battery]`` (the cells' heat port at
    ``ambient_temp_c`` [degC], default ``battery.temperature_c``; for a soaked start pass a
    configuration from :func:`hevsim.sim.cell_vehicle.soaked`) stepped in the loop, then its
    channels, metrics and energy terms added to the result
    (:func:`hevsim.sim.cell_vehicle.attach_cells`)."""
    from hevsim.architectures import architecture
    from hevsim.config import load_vehicle_config
    from hevsim.sim.cell_vehicle import attach_cells, make_cell_run

    if isinstance(model, str | Path):
        model = load_vehicle_config(model)
    cfg = getattr(model, "config", model)
    if getattr(getattr(cfg, "battery", None), "model", "") != "cell":
        raise ConfigError(
            f"{cfg.name}: a cell run needs [battery] model = 'cell'; got "
            f"{getattr(getattr(cfg, 'battery', None), 'model', None)!r}."
        )
    if not hasattr(model, "config"):
        model = architecture(name, cfg.name).build(cfg)
    cyc, dt = cycle_and_step(cycle, dt_s, cfg.simulation)
    soc0 = float(cfg.simulation.soc_initial if soc_initial is None else soc_initial)
    run = make_cell_run(cfg, dt, soc0, len(cyc.resampled(dt).time_s) - 1, ambient_temp_c=ambient_temp_c)
    res = simulate_architecture(name, model, cyc, dt, soc0, controller, compiled, pack_run=run)
    attach_cells(res, run, cfg)
    return res


# One entry point per architecture: simulate_architecture with the name fixed.
simulate_parallel = functools.partial(simulate_architecture, "parallel")
"""Simulate a parallel HEV forward (see :func:`simulate_architecture`)."""
simulate_conventional = functools.partial(simulate_architecture, "conventional")
"""Simulate a conventional vehicle forward (see :func:`simulate_architecture`)."""
simulate_bev = functools.partial(simulate_architecture, "bev")
"""Simulate a battery-electric vehicle forward (see :func:`simulate_architecture`)."""
simulate_power_split = functools.partial(simulate_architecture, "power_split")
"""Simulate a power-split HEV forward (see :func:`simulate_architecture`)."""
simulate_fcev = functools.partial(simulate_architecture, "fcev")
"""Simulate a fuel-cell vehicle forward (see :func:`simulate_architecture`)."""


COMPILED_PLUGINS = ("_compiled_hev", "_compiled_bev", "_compiled_fcev", "_compiled_conventional")
"""Modules of :mod:`hevsim.sim` holding architectures' plug-ins of the one compiled loop
(:func:`hevsim.sim._loop.run_loop`) and their hooks; each declares the architectures it runs in
``ARCHITECTURES``."""


def compiled_loop(architecture: str) -> Any:
    """The module of ``architecture``'s plug-in of the one compiled forward loop (its
    ``simulate_compiled`` and ``simulate_batch_compiled``), None where it has none. The plug-ins
    live here in sim/, so an architecture module never imports them; they are imported one by
    one (a run loads only its own)."""
    import importlib

    for name in COMPILED_PLUGINS:
        mod = importlib.import_module(f"hevsim.sim.{name}")
        if architecture in mod.ARCHITECTURES:
            return mod
    return None


def use_compiled(compiled: bool | None) -> bool:
    """Whether a run uses an architecture's compiled hooks: ``compiled`` if given, else
    unless the environment variable :data:`FORWARD_ENV` is ``python``."""
    if compiled is not None:
        return bool(compiled)
    return os.environ.get(FORWARD_ENV, "").strip().lower() != "python"


def run_metrics(
    model: Any,
    summary: np.ndarray,
    audit: dict[str, float],
    traction_j: float,
    soc0: float,
    cfg: Any = None,
) -> dict[str, dict[str, Any]]:
    """Metrics of one run from its summary, closed audit [J] and positive wheel energy
    ``traction_j`` [J], starting at SOC ``soc0`` [-] (single runs and batches alike);
    ``cfg``: the variant's configuration (default the model's)."""
    cfg = model.config if cfg is None else cfg
    battery = getattr(model, "battery", None)
    f = config_fuel(cfg, getattr(model, "engine", None))
    socf = summary[K.S_SOCF]
    capacity = battery.capacity_ah if battery is not None else 0.0
    ocv_override = cfg.metrics.soc_correction_ocv_v
    ocv_mean = soc_correction_ocv(ocv_override, battery, soc0, socf) if battery is not None else 0.0
    metrics = compute_metrics(summary, audit, soc0, capacity, ocv_mean, f.density_kg_per_m3,
                              f.heating_value_btu_per_us_gal, f.co2_kg_per_kg,
                              cfg.metrics.conversion_efficiency)  # fmt: skip
    metrics["engine_starts"]["description"] = "engine starts (off -> fired)"
    metrics["traction_energy_j"] = {"value": traction_j, "unit": "J", "description": "positive wheel energy"}
    metrics["energy_audit_residual_traction_pct"] = {
        "value": 100.0 * abs(audit["residual"]) / traction_j if traction_j > 0 else 0.0, "unit": "%",
        "description": "energy audit residual / positive traction energy at the wheels",
    }  # fmt: skip
    metrics["traction_limited_s"] = {
        "value": float(summary[K.S_BLIM]), "unit": "s",
        "description": "time the powertrain could not follow the trace",
    }  # fmt: skip
    return metrics


def close_audit(audit: dict[str, float]) -> dict[str, float]:
    """``audit`` [J] with its ``residual``: sources (:data:`SOURCES`) minus every sink."""
    out = dict(audit)
    out.pop("residual", None)
    out["residual"] = sum(out.get(s, 0.0) for s in SOURCES) - sum(
        val for key, val in out.items() if key not in SOURCES and key != "residual"
    )
    return out


def finish_record(rec: ForwardRecord, grid: Any, modes: tuple[str, ...]) -> tuple[Any, ...]:
    """(time series, closed audit, summary, events) of a :class:`ForwardRecord`: the last row
    repeats the last step's operating point at the end speed, SOC and fuel."""
    t = np.asarray(grid.time_s, dtype=np.float64)
    n = t.size - 1
    cols = rec.columns
    for key in cols:
        cols[key][n] = cols[key][n - 1] if n > 0 else 0.0
    cols["speed_desired_mps"][n] = float(grid.speed_mps[n])
    cols["speed_mps"][n] = rec.speed_final_mps
    cols["soc"][n] = rec.summary[K.S_SOCF]
    cols["fuel_kg"][n] = rec.summary[K.S_FUEL]
    ts = _frame(t, cols, modes)
    return ts, close_audit(rec.audit), rec.summary, _events(t, cols, modes)


def simulate_batch_architecture(
    model: Any,
    variants: dict[str, Any],
    cycle: DriveCycle | str | None = None,
    dt_s: float | None = None,
    compiled: bool | None = None,
) -> Any:
    """Run parameter variants of a parallel, conventional, BEV or power-split vehicle.

    ``variants`` maps dotted configuration keys (``"body.mass_kg"``, ``"controller.equivalence_factor"``)
    to arrays of equal length (scalars broadcast); each variant is validated like a file
    (:meth:`~hevsim.config._VehicleConfig.replace`). The architecture's compiled batch
    (``simulate_batch_compiled``, see the module docstring) runs them all at once where it
    covers the keys and the controller (``compiled`` as in :func:`simulate_architecture`);
    otherwise (and always for a ``[battery] model = "pack"`` vehicle, whose pack the threaded
    compiled batch does not take) they are simulated in turn, each a compiled run where the
    architecture has one (a pack vehicle's pack steps inside it). Returns a
    :class:`~hevsim.sim.simulator.BatchResult` (one row per variant: the variant's values and
    every metric).
    """
    from hevsim.architectures import architecture
    from hevsim.config import load_vehicle_config
    from hevsim.control import make_controller
    from hevsim.sim.results import BatchResult

    cfg = load_vehicle_config(model) if isinstance(model, str | Path) else getattr(model, "config", model)
    arrays = {k: np.atleast_1d(np.asarray(v)) for k, v in variants.items()}
    try:
        n = np.broadcast_shapes(*(a.shape for a in arrays.values()))[0] if arrays else 1
    except ValueError as exc:
        shapes = {k: a.shape for k, a in arrays.items()}
        raise ConfigError(f"batch variants: arrays must have equal lengths, got {shapes}.") from exc
    cyc = cycle if isinstance(cycle, DriveCycle) else load_cycle(cycle or cfg.simulation.cycle)
    t0 = time.perf_counter()
    values = [{k: np.broadcast_to(a, (n,))[i].item() for k, a in arrays.items()} for i in range(n)]
    arch = architecture(cfg.architecture, cfg.name)
    sections: dict[str, dict[str, Any]] = {}
    cfgs = [variant_config(cfg, v, arch.spec, sections) for v in values]
    # a pack or a cell battery (their cells' state) runs variant by variant
    pack = getattr(getattr(cfg, "battery", None), "model", "") in ("pack", "cell")
    loop = compiled_loop(arch.name) if use_compiled(compiled) and not pack else None
    hook = getattr(loop, "simulate_batch_compiled", None)
    rec = None
    if hook is not None and all(np.issubdtype(a.dtype, np.number) for a in arrays.values()):
        base = model if getattr(model, "config", None) is cfg else arch.build(cfg)
        b = getattr(cfg, "battery", None)
        cyc_run, dt = cycle_and_step(cyc, dt_s, cfg.simulation)
        grid = cyc_run.resampled(dt)
        flat = {k: np.ascontiguousarray(np.broadcast_to(a, (n,)), np.float64) for k, a in arrays.items()}
        soc0 = np.array([c.simulation.soc_initial for c in cfgs], dtype=np.float64)
        window = (b.soc_min, b.soc_max) if b is not None else (0.0, 1.0)
        rec = hook(base, flat, grid, make_controller(base), soc_initial=soc0, soc_min=window[0],
                   soc_max=window[1])  # fmt: skip
    rows = []
    if rec is None:
        for v, c in zip(values, cfgs, strict=True):
            res = simulate_architecture(cfg.architecture, c, cyc, dt_s, compiled=compiled)
            rows.append({**v, **{name: m["value"] for name, m in res.metrics.items()}})
    else:
        for i, (v, c) in enumerate(zip(values, cfgs, strict=True)):
            audit = close_audit(rec.audits[i])
            soc_i = c.simulation.soc_initial
            m = run_metrics(base, rec.summary[i], audit, float(rec.traction_j[i]), soc_i, cfg=c)
            rows.append({**v, **{name: x["value"] for name, x in m.items()}})
            if np.any(np.isnan([float(x["value"]) for x in m.values()])):  # as a single run (BEV: mpg inf)
                raise DomainError(f"batch: variant {i} ({v}) produced non-finite results.")
    return BatchResult(pd.DataFrame(rows), time.perf_counter() - t0)


def variant_config(cfg: Any, changes: dict[str, Any], spec: Any, sections: dict[str, dict[str, Any]]) -> Any:
    """``cfg.replace(**changes)`` validated as a file would be, faster for a batch: only the
    changed keys are checked again (with a file's per-key checks; the others are ``cfg``'s,
    already checked), then the architecture's cross-key checks (``spec.check``) run on the
    result. ``sections`` caches the sections' values as plain dicts across the variants of a
    batch (for a key a section does not know, refused by the whole section's check)."""
    from hevsim import schema

    by_section: dict[str, dict[str, Any]] = {}
    for key, value in changes.items():
        section, _, name = key.partition(".")
        current = getattr(cfg, section, None)
        if not name or not dataclasses.is_dataclass(current):
            return cfg.replace(**changes) if changes else cfg  # a top-level key: the full path
        by_section.setdefault(section, {})[name] = value
    if not by_section:
        return cfg
    source = f"{cfg.name} (modified)"
    new = {}
    for section, vals in by_section.items():
        current = getattr(cfg, section)
        cls = type(current)
        fields = {f.name: f for f in dataclasses.fields(cls)}
        if all(k in fields for k in vals):  # the changed keys checked; the others are cfg's, checked
            hints = schema.type_hints(cls)
            checked = {
                k: schema.check_value(v, hints[k], source, f"{section}.{k}", {}, {}, fields[k].metadata)
                for k, v in vals.items()
            }
            new[section] = dataclasses.replace(current, **checked)
            continue
        if section not in sections:  # an unknown key: the whole section's check names it
            sections[section] = schema.to_dict(current)
        data = {**sections[section], **vals}
        new[section] = schema.build_section(cls, data, source, section, {}, {})
    out = dataclasses.replace(cfg, **new)
    spec.check(out, source)
    return out


def _run(
    mod: Any, model: Any, ctl: Any, grid: Any, soc0: float, soc_min: float, soc_max: float, pack: Any = None
) -> ForwardRecord:
    """The Python loop (the reference of every compiled run)."""
    body, r = model.body, model.tire.radius_m
    t, v_des, gr = (np.asarray(a, dtype=np.float64) for a in (grid.time_s, grid.speed_mps, grid.grade))
    n = t.size - 1
    dt = float(t[1] - t[0])
    battery = getattr(model, "battery", None)
    q_as = battery.capacity_ah * 3600.0 if battery is not None else 0.0
    m_eff = body.mass_kg * body.mass_factor
    cols: dict[str, np.ndarray] = {}
    audit: dict[str, float] = dict.fromkeys(
        ("fuel", "genset_source", "battery_chemical", "aero", "rolling", "grade", "kinetic_vehicle"), 0.0
    )
    ctl.reset(soc0)
    road = np.zeros(3 + len(AUDIT_ROAD))
    v, soc, fuel = float(v_des[0]), soc0, 0.0
    err_sq = err_max = dist = eon = starts = lim_s = 0.0
    was_on = False

    def demand(v0: float, v1: float, k: int) -> tuple[float, float, float, float]:
        v_mid = 0.5 * (v0 + v1)
        a = (v1 - v0) / dt
        g = 0.5 * (gr[k] + gr[k + 1])
        f = float(body.road_load_force(v_mid, a, g)) if v_mid > 0.0 else 0.0
        return v_mid, a, g, f

    model_k = model
    for k in range(n):
        if pack is not None:  # the pack's BMS limits, (E, Z) and cooling load for this step
            model_k, bs = pack.vehicle_step(model, soc, soc_max, LIMIT_RTOL, REGEN_CURRENT_RTOL)
        else:
            bs = _battery_state(model, soc, soc_max) if battery is not None else None
        ocv = float(np.asarray(bs.ocv_v)) if bs is not None else 0.0
        e_soc = q_as * ocv if bs is not None else 1.0

        def step_at(v1: float, k: int = k, v0: float = v, soc: float = soc, bs: Any = bs,
                    e_soc: float = e_soc, mk: Any = model_k, coast: bool = False,
                    ) -> tuple[Step, float, float, float]:  # fmt: skip
            v_mid, a, g, f = demand(v0, v1, k)
            if coast:  # no wheel force: the road load alone brings the car to rest within the step
                f = 0.0
            st = Step(mk, mod.power_flow, k, float(t[k]), dt, v_mid, v_mid / r, f * r, soc, e_soc, bs,
                      soc_min, soc_max)  # fmt: skip
            return st, a, g, f

        v1 = float(v_des[k + 1])
        step, a, g, f = step_at(v1)
        control = ctl.choose(step)
        limited = 0.0
        if control is None:  # beyond the powertrain: lower the end speed until a control exists
            limited = 1.0
            lo, hi, best = 0.0, v1, None
            for _ in range(BISECTION_STEPS):
                mid = 0.5 * (lo + hi)
                trial = step_at(mid)
                c = ctl.choose(trial[0])
                if c is None:
                    hi = mid
                else:
                    lo, best = mid, (trial, c)
            if best is None:
                trial = step_at(0.0)
                c = ctl.choose(trial[0])
                if c is None and trial[3] > 0.0 and pack is not None:
                    # stopping needs a push (the road load decelerates the crawling car more than
                    # the step asks, so it coasts to rest within the step): no wheel force then,
                    # e.g. a BEV whose pack reached its SOC floor (the audit's aero term takes
                    # the difference, at most the crawl's kinetic energy). Only with a pack: the
                    # compiled loops (no pack) still end such a run with the DomainError below,
                    # and the Python loop without a pack stays equal to them.
                    trial = step_at(0.0, coast=True)
                    c = ctl.choose(trial[0])
                best = (trial, c)
            (step, a, g, f), control = best
            v1 = step.v_mid_mps * 2.0 - v
            if control is None:
                raise stuck_error(model, float(t[k]), soc, soc_min)
        st, _ = step.evaluate(*(np.array([c]) for c in control), detail=True)
        ctl.update(step, st)
        det = {key: float(np.ravel(val)[0]) for key, val in st.details.items()}
        loss = {
            key: float(np.ravel(val)[0])
            for key, val in mod.loss_powers(model_k, st, step.wheel_speed_radps, step.wheel_torque_nm).items()
        }
        if pack is not None and "aux" not in loss:  # the cooling load on the bus
            loss["aux"] = model_k.aux_power_w
        d_soc = float(np.ravel(st.d_soc)[0])
        v_mid = step.v_mid_mps
        # ---- energy audit [J] (all powers at the mid-step speed)
        for term, p_w in loss.items():
            if term == "fuel":
                audit["fuel"] += p_w * dt
            elif term != "wheel":
                audit[term] = audit.get(term, 0.0) + p_w * dt
        if battery is not None:
            e_chem = -d_soc * q_as * ocv
            audit["battery_chemical"] += e_chem
            audit["battery_loss"] = audit.get("battery_loss", 0.0) + e_chem - det["battery_power_w"] * dt
        road[:] = 0.0  # aero (the rest of the road load, eq 32), rolling, grade, kinetic
        add_road_audit(
            road,
            v,
            v1,
            v_mid,
            a,
            g,
            f,
            body.mass_kg,
            m_eff,
            body.rolling_resistance,
            body.rolling_resistance_speed_s_per_m,
            dt,
        )
        for j, term in enumerate(AUDIT_ROAD, start=3):
            audit[term] += float(road[j])
        # ---- mode and bookkeeping
        on = det.get("engine_on", 0.0) > 0.0
        if on and not was_on:
            starts += 1.0
        was_on = on
        fuel += float(np.ravel(st.cost_kg)[0])
        eon += dt if on else 0.0
        err_sq, err_max, dist, lim_s = track_step(
            v_des[k] - v, v_mid, dt, limited, err_sq, err_max, dist, lim_s
        )
        row = {
            "speed_desired_mps": v_des[k], "speed_mps": v, "accel_mps2": a, "wheel_force_n": f,
            "wheel_power_w": loss["wheel"], "road_load_force_n": f - m_eff * a, "fuel_kg": fuel, "soc": soc,
            **det, "power_mode": mod.power_mode(det, f, v_mid), "traction_limited": limited,
        }  # fmt: skip
        if getattr(mod, "HAS_CLUTCH", False) and "clutch_closed" not in det:  # parallel: closed iff engine on
            row["clutch_closed"] = det["engine_on"]
        if battery is not None:
            i_bat = det["battery_current_a"]
            row["battery_ocv_v"] = ocv
            row["battery_voltage_v"] = det["battery_power_w"] / i_bat if i_bat != 0.0 else ocv
        for key, val in row.items():
            cols.setdefault(key, np.zeros(n + 1))[k] = val
        v, soc = v1, soc + d_soc
        if pack is not None:  # the pack steps at the bus's terminal power: its own SOC
            soc = pack.finish_power(det["battery_power_w"])
    summary = np.zeros(len(K.SUMMARY))
    write_summary(summary, float(v_des[n] - v), err_sq, err_max, n, dist, fuel, soc, eon, starts, lim_s,
                  float(t[n] - t[0]))  # fmt: skip
    return ForwardRecord(cols, audit, summary, v)


def _frame(t: np.ndarray, cols: dict[str, np.ndarray], modes: tuple[str, ...]) -> pd.DataFrame:
    out: dict[str, Any] = {"time_s": t}
    for name, col in cols.items():
        if name in INT_COLUMNS:
            out[name] = col.astype(np.int64)
        elif name in BOOL_COLUMNS:
            out[name] = col > 0.0
        else:
            out[name] = col
        add_display_units(out, name, col)
    out["power_mode_name"] = pd.Categorical.from_codes(out["power_mode"], pd.Index(modes))
    return pd.DataFrame(out)


def _events(t: np.ndarray, ts: dict[str, np.ndarray], modes: tuple[str, ...]) -> pd.DataFrame:
    """Event log of a run's channels ``ts`` at times ``t`` [s]: power-mode, gear and
    traction-limit changes."""
    parts: list[tuple[np.ndarray, str, list[str], list[str]]] = []
    for col, kind, names in (("power_mode", "power_mode", modes), ("gear", "gear", None),
                             ("traction_limited", "traction_limit", ("off", "on"))):  # fmt: skip
        if col not in ts:
            continue
        vals = np.asarray(ts[col])
        idx = np.flatnonzero(np.diff(vals) != 0) + 1
        a, b = vals[idx - 1].astype(np.int64).tolist(), vals[idx].astype(np.int64).tolist()
        old, new = (
            ([names[i] for i in a], [names[i] for i in b])
            if names
            else (list(map(str, a)), list(map(str, b)))
        )
        parts.append((t[idx], kind, old, new))
    times = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0)
    kinds = [p[1] for p in parts for _ in range(p[0].size)]
    olds = [x for p in parts for x in p[2]]
    news = [x for p in parts for x in p[3]]
    columns = ["time_s", "kind", "from_state", "to_state", "reason"]
    if times.size == 0:
        return pd.DataFrame([], columns=columns)
    order = sorted(range(times.size), key=lambda i: (times[i], kinds[i]))  # stable, as before
    ev = pd.DataFrame(
        {
            "time_s": times[order].astype(float),
            "kind": [kinds[i] for i in order],
            "from_state": [olds[i] for i in order],
            "to_state": [news[i] for i in order],
            "reason": [f"controller chose {kinds[i]} {news[i]}" for i in order],
        },
        columns=columns,
    )
    return ev

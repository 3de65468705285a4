"""Series hybrid-electric vehicle (thesis Fig. 2.3): engine-generator genset on a DC bus with
the battery, the traction motor through the final drive to the wheels.

Its model is :class:`SeriesHEV` (built by :func:`build_series_hev`); its forward step is a
plug-in of the one compiled loop :func:`hevsim.sim._loop.run_loop`
(:mod:`hevsim.sim._compiled_series`) that brings its own driver and vehicle dynamics, one
named point kernel per stage of :mod:`hevsim.architectures.series_kernel`
(:func:`~hevsim.architectures.series_kernel.driver_step` -> genset supervisor ->
:func:`~hevsim.architectures.series_kernel.bus_limits` ->
:func:`~hevsim.architectures.series_kernel.genset_step` ->
:func:`~hevsim.architectures.series_kernel.traction_step` ->
:func:`~hevsim.architectures.series_kernel.vehicle_step` ->
:func:`~hevsim.architectures.series_kernel.bus_step`, on the bus balance of
:mod:`hevsim.components.bus`),
and its DP formulation :class:`hevsim.optimal._series_dp.SeriesFormulation` calls the same
bus balance (:func:`hevsim.optimal._hev_common.electric_flow`) over the grid. Controls:
genset state and engine throttle (forward), genset electrical power on the engine's optimal
line (DP). Controllers: ``"thermostat"`` (rule-based) and ``"schedule"`` (a genset schedule
with cranking and speed loop); a :class:`~hevsim.sim.simulator.GensetSchedule` with
``quasi_static=True`` selects the kernel's ``"replay"`` supervisor, which applies a DP
optimum's decisions exactly.

**Quasi-static power flow** (:func:`power_flow`; the performance tests of
:mod:`hevsim.sim.performance` drive it through the generic loop of :mod:`hevsim.sim.forward`).
Control ``genset_power_w``: the electrical power the genset delivers to the bus [W], as in the
DP. An engine genset sits at the fuel-optimal point of that power on the DP's optimal
operating line (:func:`hevsim.components.genset.genset_operating_points`; no cranking, no
shaft dynamics: a genset already running); a current-source genset is on for any request > 0
and then delivers ``OCV x current_a`` (as the kernel's); without a genset only 0 is
admissible. The traction motor gives the wheel torque through the final drive and
regenerates above ``brakes.regen_min_speed_mps`` (the friction brakes take the rest); the
battery closes the bus through :func:`hevsim.optimal._hev_common.electric_flow` (the DP's bus
balance, on the same :mod:`hevsim.components.bus` kernels as the forward kernel).
:func:`quasi_static_model` puts the traction motor's rotor inertia into the effective mass as
the kernel does (``m_eff = m delta + J (ratio / r)^2``). Limits flagged: those of the bus
balance (motor torque, battery power, discharge and charge current), ``motor_speed`` (beyond
the motor map's last speed) and ``genset_power`` (the genset at its largest power while the
bus is short: the battery at its power or discharge-current limit; or a request the genset
cannot deliver).
"""

from __future__ import annotations

import dataclasses
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.architectures import series_kernel as SK
from hevsim.architectures._build import build_battery, build_engine, build_machine
from hevsim.architectures._common import battery_details, machine_details, max_machine_speed_radps
from hevsim.components.battery import BatteryPack
from hevsim.components.body import VehicleBody
from hevsim.components.driveline import Gear, Tire
from hevsim.components.electric_machine import ElectricMachine
from hevsim.components.engine import Engine, EngineTables
from hevsim.config import SeriesHEVConfig
from hevsim.fuels import with_config_fuel
from hevsim.tables import FloatArray
from hevsim.units import MPS_PER_MPH, rpm_to_radps

ARCHITECTURE = "series"
CONTROLS: tuple[str, ...] = ("genset_state", "engine_throttle")
"""Controls of the forward kernel's supervisors (the quasi-static :func:`power_flow` takes the
genset's electrical power instead, as the DP)."""
DP_INPUTS: tuple[str, ...] = ("genset_power_w",)
"""The DP formulation's inputs, which :func:`power_flow` takes as they are (a DP optimum replays
them: :class:`hevsim.control.parallel.InputSchedule`)."""
MODES: tuple[str, ...] = SK.POWER_MODES
"""Power modes (thesis Table 2.1), as the kernel's."""
LOSSES: tuple[str, ...] = (
    "fuel", "genset_source", "engine_loss", "generator_loss", "motor_loss", "friction_brakes",
    "final_drive_loss", "aux", "wheel",
)  # fmt: skip
"""Energy-audit terms of :func:`loss_powers` [W] (``fuel`` and ``genset_source`` are sources)."""
CAPABILITY_POINTS = 11
"""Genset powers, from its largest down to 0, among the performance tests' candidates [-]."""
GENSET_MAX_RTOL = 1e-9
"""The candidates' top genset power lies this fraction below the largest (as the DP's grid:
the largest is the edge of the optimal-line search) [-]."""
GENSET_AT_MAX_RTOL = 1e-6
"""A genset request within this fraction of the largest power is "at its maximum" [-]."""

__all__ = [
    "ARCHITECTURE", "CONTROLS", "DP_INPUTS", "LOSSES", "MODES", "SeriesHEV", "build_series_hev",
    "candidate_controls",
    "capability_controls",
    "genset_max_power_w", "loss_powers", "power_flow", "power_mode", "quasi_static_model",
]  # fmt: skip


@dataclass(frozen=True, eq=False)
class SeriesHEV:
    """A series hybrid vehicle ready to simulate (components + control settings)."""

    config: SeriesHEVConfig
    body: VehicleBody
    tire: Tire
    gear: Gear
    traction_motor: ElectricMachine
    generator: ElectricMachine
    engine: Engine | None
    battery: BatteryPack
    cell: Any = None
    """Cell parameters (:class:`hevsim.battery.CellParameters`) of a ``"cell"`` battery."""
    aux_power_w: float | None = None
    """Electrical auxiliary load on the bus [W] of the quasi-static power flow (None: ``[controller]
    aux_power_w``; a pack's cooling power is added by :meth:`hevsim.battery.bms.PackRun.vehicle_step`)."""
    cell_port_temp_k: float | None = None
    """The heat-port (ambient) temperature [K] of a ``"cell"`` battery's cells (None: their
    initial temperature, ``[battery] temperature_c``)."""

    @property
    def name(self) -> str:
        """Configuration name."""
        return self.config.name

    def param_vector(self, soc_initial: float | None = None) -> FloatArray:
        """Scalar parameters in the kernel's layout (:data:`hevsim.architectures.series_kernel.PARAMS`)."""
        c = self.config
        ctl = c.controller
        p = np.zeros(len(SK.PARAMS))
        b = self.body
        eng = self.engine
        values: dict[str, float] = {
            "mass_kg": b.mass_kg,
            "mass_factor": b.mass_factor,
            "cd": b.drag_coefficient,
            "area_m2": b.frontal_area_m2,
            "rho_kgpm3": b.air_density_kgpm3,
            "headwind_mps": b.headwind_mps,
            "crr": b.rolling_resistance,
            "crr_v": b.rolling_resistance_speed_s_per_m,
            "tire_radius_m": self.tire.radius_m,
            "gear_ratio": self.gear.ratio,
            "gear_efficiency": self.gear.efficiency,
            "max_brake_force_n": c.brakes.max_decel_mps2 * b.mass_kg,
            "driver_gain_per_mps": c.driver.gain_per_mph / MPS_PER_MPH,
            "driver_feedforward": c.driver.feedforward,
            "motor_kind": self.traction_motor.kind_code,
            "motor_eff": self.traction_motor.efficiency,
            "motor_scale": self.traction_motor.torque_scale,
            "motor_inertia": self.traction_motor.inertia_kgm2,
            "gen_kind": self.generator.kind_code,
            "gen_eff": self.generator.efficiency,
            "gen_scale": self.generator.torque_scale,
            "gen_inertia": self.generator.inertia_kgm2,
            "engine_present": float(eng is not None),
            "engine_use_tmap": float(eng is not None and eng.torque_map is not None),
            "engine_use_fuel_map": float(eng is not None and eng.fuel_map is not None),
            "engine_stall_radps": eng.stall_speed_radps if eng else 0.0,
            "engine_redline_radps": eng.redline_radps if eng else 0.0,
            "engine_scale": eng.torque_scale if eng else 1.0,
            "engine_inertia": eng.inertia_kgm2 if eng else 0.0,
            "engine_lhv_jpkg": eng.fuel_lhv_jpkg if eng else 42.937e6,
            "bat_ns": self.battery.n_series,
            "bat_np": self.battery.n_parallel,
            "bat_r_extra": self.battery.r_extra_ohm,
            "bat_capacity_ah": self.battery.capacity_cell_ah,
            "bat_coulombic_eff": self.battery.coulombic_efficiency,
            "bat_max_dis_a": self.battery.max_discharge_current_a,
            "bat_max_chg_a": self.battery.max_charge_current_a,
            "bat_temp_k": self.battery.temperature_k,
            "soc_initial": c.simulation.soc_initial if soc_initial is None else soc_initial,
            "soc_min": self.config.battery.soc_min,
            "soc_max": self.config.battery.soc_max,
            "genset_kind": {
                "none": SK.GENSET_NONE,
                "current_source": SK.GENSET_CURRENT_SOURCE,
                "engine": SK.GENSET_ENGINE,
            }[c.genset.kind],
            "soc_low": ctl.soc_low,
            "soc_high": ctl.soc_high,
            "soc_boost": ctl.soc_boost,
            "genset_speed_radps": rpm_to_radps(ctl.engine_speed_rpm),
            "genset_start_speed_radps": rpm_to_radps(ctl.start_speed_rpm),
            "throttle_run": ctl.throttle,
            "throttle_boost": ctl.throttle_boost,
            "genset_gain_per_radps": ctl.speed_gain_per_rpm / rpm_to_radps(1.0),
            "genset_current_a": c.genset.current_a,
            "regen_min_speed_mps": c.brakes.regen_min_speed_mps,
            "aux_power_w": ctl.aux_power_w,
            "pure_ice_band_w": ctl.pure_ice_band_w,
        }
        if self.cell is not None:
            from hevsim.battery.vehicle import vehicle_parameter_values

            values.update(
                vehicle_parameter_values(
                    self.cell, self.battery.n_series, self.battery.n_parallel, self.battery.temperature_k
                )
            )
        missing = set(SK.PARAMS) - set(values) - {"driver_kind", "supervisor_kind"}
        unknown = set(values) - set(SK.PARAMS)
        if missing or unknown:  # a kernel parameter added or renamed on one side only
            raise KeyError(f"kernel parameters missing: {sorted(missing)}; unknown: {sorted(unknown)}")
        for name, value in values.items():
            p[SK.P[name]] = value
        return p

    def kernel_tables(self) -> tuple[tuple[FloatArray, ...], ...]:
        """(engine, motor, generator, battery) table tuples for the kernel: the battery's is its
        :class:`~hevsim.components.battery.PackTables` (a ``"cell"`` or ``"pack"`` battery's
        own step is the one loop's, :meth:`battery_run`)."""
        if self.engine is not None:
            eng = self.engine.kernel_tables()
        else:
            z1, z2 = np.zeros(1), np.zeros((1, 1))
            eng = EngineTables(z1, z1, z1, z1, z1, z1, z2, z1, z1, z2)  # no engine: all dummies
        return (
            eng,
            self.traction_motor.kernel_tables(),
            self.generator.kernel_tables(),
            self.battery.kernel_tables(),
        )

    def battery_run(self, dt_s: float, steps: int, soc_initial: float | None = None) -> Any:
        """The battery the one loop steps in a run of ``steps`` steps of ``dt_s`` [s] from
        ``soc_initial`` [-] (default the configuration's): None for a table battery; a fresh
        :class:`~hevsim.battery.cell_run.CellRun` for a ``"cell"`` battery (its cells at
        ``[battery] temperature_c``, their heat port at :attr:`cell_port_temp_k`), the same
        cell battery every other architecture runs. (A ``"pack"`` battery's
        :class:`~hevsim.battery.bms.PackRun` is made by :mod:`hevsim.sim.pack_vehicle`.)"""
        if self.cell is None:
            return None
        from hevsim.battery.cell_run import CellRun

        soc0 = self.config.simulation.soc_initial if soc_initial is None else soc_initial
        b = self.battery
        return CellRun(self.cell, b.n_series, b.n_parallel, soc0, b.temperature_k, dt_s, steps,
                       port_temp_k=self.cell_port_temp_k, r_extra_ohm=b.r_extra_ohm)  # fmt: skip


def build_series_hev(cfg: SeriesHEVConfig) -> SeriesHEV:
    """Build the component objects of a series HEV from its configuration."""
    base = Path(cfg.base_dir)
    body = VehicleBody.from_section(cfg.body)
    engine = build_engine(cfg.engine, base) if cfg.genset.kind == "engine" else None
    battery, cell = build_battery(cfg.battery, base)
    return SeriesHEV(
        config=cfg,
        body=body,
        tire=Tire(radius_m=cfg.tire.radius_m),
        gear=Gear(ratio=cfg.final_drive.ratio, efficiency=cfg.final_drive.efficiency),
        traction_motor=build_machine(cfg.motor, "motor", base),
        generator=build_machine(cfg.generator, "generator", base),
        engine=None if engine is None else with_config_fuel(engine, cfg),  # [fuel] section
        battery=battery,
        cell=cell,
    )


_GENSET: weakref.WeakKeyDictionary[SeriesHEV, dict[str, Any]] = weakref.WeakKeyDictionary()
"""Per model: its engine genset's largest power and the optimal-line points found so far (by
power), so that a forward run searches the engine map once per power, not once per step."""


def _genset_cache(hev: SeriesHEV) -> dict[str, Any]:
    cache = _GENSET.get(hev)
    if cache is None:
        cache = {}
        _GENSET[hev] = cache
    return cache


def genset_max_power_w(hev: SeriesHEV, ocv_v: Any = 0.0) -> Any:
    """Largest electrical power [W] the genset delivers to the bus: an engine genset's
    (:func:`hevsim.components.genset.genset_max_power_w`), a current source's
    ``OCV x current_a`` at the battery OCV ``ocv_v`` [V], 0 without a genset."""
    kind = hev.config.genset.kind
    if kind == "current_source":
        return np.asarray(ocv_v, np.float64) * hev.config.genset.current_a
    if kind != "engine" or hev.engine is None:
        return 0.0
    cache = _genset_cache(hev)
    if "p_max_w" not in cache:
        from hevsim.components.genset import genset_max_power_w as engine_generator_max_w

        cache["p_max_w"] = engine_generator_max_w(hev.engine, hev.generator)
    return cache["p_max_w"]


def _engine_points(hev: SeriesHEV, power_w: np.ndarray) -> tuple[np.ndarray, ...]:
    """(delivered power [W], engine speed [rad/s], torque [N·m], fuel rate [kg/s], feasible
    as 0/1) of the engine genset's optimal-line points at ``power_w`` [W], each power
    searched once (:func:`hevsim.components.genset.genset_operating_points`)."""
    from hevsim.components.genset import genset_operating_points

    assert hev.engine is not None
    cache = _genset_cache(hev)
    keys, rows = cache.get("keys", np.zeros(0)), cache.get("rows", np.zeros((5, 0)))
    flat = np.ravel(power_w)
    idx = np.minimum(np.searchsorted(keys, flat), max(keys.size - 1, 0))
    if keys.size == 0 or not np.array_equal(keys[idx], flat):
        new = np.unique(flat if keys.size == 0 else flat[keys[idx] != flat])
        pts = genset_operating_points(hev.engine, hev.generator, new)
        got = np.array([pts.power_w, pts.speed_radps, pts.torque_nm, pts.fuel_kgps, pts.feasible], np.float64)
        keys, order = np.unique(np.concatenate([keys, new]), return_index=True)
        rows = np.concatenate([rows, got], axis=1)[:, order]
        cache["keys"], cache["rows"] = keys, rows
        idx = np.searchsorted(keys, flat)
    return tuple(rows[j, idx].reshape(np.shape(power_w)) for j in range(5))


def aux_power_w(hev: SeriesHEV) -> float:
    """The electrical auxiliary load on the bus [W]: the model's (a pack adds its cooling
    power), else ``[controller] aux_power_w``."""
    return float(hev.config.controller.aux_power_w if hev.aux_power_w is None else hev.aux_power_w)


def quasi_static_model(hev: SeriesHEV) -> SeriesHEV:
    """The model the quasi-static loop drives: the traction motor's rotor inertia ``J``
    [kg·m²] moved into the body's rotating-mass factor, ``delta + J (ratio / r)^2 / m``, so
    that the effective mass is the compiled kernel's ``m_eff`` (the motor of the returned
    model has no inertia left, so a second call changes nothing)."""
    b, ratio, r = hev.body, hev.gear.ratio, hev.tire.radius_m
    extra = hev.traction_motor.inertia_kgm2 * (ratio / r) ** 2 / b.mass_kg
    if hev.aux_power_w is None:  # the loop's model states its auxiliary load (a pack adds cooling to it)
        hev = dataclasses.replace(hev, aux_power_w=aux_power_w(hev))
    if extra == 0.0:
        return hev
    return dataclasses.replace(
        hev,
        body=dataclasses.replace(b, mass_factor=b.mass_factor + extra),
        traction_motor=dataclasses.replace(hev.traction_motor, inertia_kgm2=0.0),
    )


def candidate_controls(hev: SeriesHEV, control_points: int) -> tuple[np.ndarray]:
    """The candidates an online controller (ECMS, A-ECMS of :mod:`hevsim.control`) scores each
    step: ``control_points`` genset electrical powers [W] from 0 (engine off) to the largest,
    evenly spaced as the DP's input grid (:class:`hevsim.optimal._series_dp.SeriesFormulation`:
    the top one :data:`GENSET_MAX_RTOL` below the largest)."""
    p_max = float(genset_max_power_w(hev)) * (1.0 - GENSET_MAX_RTOL)
    return (np.linspace(0.0, p_max, int(control_points)),)


def power_flow(
    hev: SeriesHEV,
    wheel_speed_radps: Any,
    wheel_torque_nm: Any,
    genset_power_w: Any,
    soc: Any,
    dt_s: Any,
    regen_ok: Any,
    battery_state: Any = None,
    *,
    detail: bool = False,
) -> Any:
    """(wheel speed [rad/s] and torque [N·m], genset electrical power request [W], SOC [-])
    -> genset, motor and battery operating points, fuel, SOC change over ``dt_s`` [s] and the
    limits: a :class:`~hevsim.optimal._hev_common.Stage` (module docstring). ``regen_ok``:
    the car moves (regeneration also needs ``brakes.regen_min_speed_mps``);
    ``battery_state``: the pack at ``soc`` when known."""
    from hevsim.components.flow import BatteryState, Stage, electric_flow

    cfg = hev.config
    bs = battery_state if battery_state is not None else BatteryState.at(hev.battery, soc)
    w_wh, t_wh, moving, p_req = (  # own copies: numba reads no broadcast views
        np.array(a)
        for a in np.broadcast_arrays(
            *(
                np.asarray(a, np.float64)
                for a in (wheel_speed_radps, wheel_torque_nm, regen_ok, genset_power_w)
            )
        )
    )
    w_m = w_wh * hev.gear.ratio
    t_fd = np.asarray(hev.gear.input_torque(t_wh), np.float64)
    ok = (moving > 0.0) & (w_wh * hev.tire.radius_m > cfg.brakes.regen_min_speed_mps)
    zero = np.zeros(np.shape(p_req))
    p_gen, speed, torque, fuel, source = zero, zero, zero, zero, zero
    kind = cfg.genset.kind
    if kind == "engine" and hev.engine is not None:
        p_gen, speed, torque, fuel, feasible = _engine_points(hev, p_req)
        gs_ok = (feasible > 0.0) | (p_req <= 0.0)
        at_max = p_req >= genset_max_power_w(hev) * (1.0 - GENSET_AT_MAX_RTOL)
    elif kind == "current_source":
        source = np.where(p_req > 0.0, genset_max_power_w(hev, bs.ocv_v), 0.0)
        gs_ok, at_max = p_req >= 0.0, p_req > 0.0
    else:
        gs_ok, at_max = p_req <= 0.0, p_req > 0.0
    flow = electric_flow(
        hev.traction_motor, hev.battery, t_fd, w_m, aux_power_w(hev) - p_gen - source, soc, dt_s,
        ok, bs,
    )  # fmt: skip
    shape = np.shape(flow.torque_nm)
    over_speed = np.broadcast_to(w_m > max_machine_speed_radps(hev.traction_motor), shape)
    short = flow.flags["battery_power"] | flow.flags["battery_discharge_current"]
    gs_bad = np.broadcast_to(~gs_ok, shape)
    flags = {
        **flow.flags,
        "motor_speed": over_speed,
        "genset_power": (np.broadcast_to(at_max, shape) & short) | gs_bad,
    }
    fuel = np.where(gs_ok, fuel, 0.0)
    st = Stage(
        d_soc=flow.d_soc,
        cost_kg=np.broadcast_to(fuel * dt_s, shape),
        infeasible=flow.infeasible | over_speed | gs_bad,
        flags=flags,
    )
    st.flow = flow
    st.mech = {"w_m": w_m, "t_fd": t_fd, "p_gen": p_gen, "source": source, "speed": speed,
               "torque": torque, "fuel": fuel}  # fmt: skip
    if detail:
        eng = hev.engine
        on = (p_gen > 0.0) & gs_ok
        t_cap = eng.max_torque_nm(np.where(on, speed, eng.stall_speed_radps)) if eng is not None else 1.0
        supply = p_gen + source
        st.details = {
            "engine_on": np.broadcast_to(on.astype(np.float64), shape),
            "engine_speed_radps": np.broadcast_to(speed, shape),
            "engine_torque_nm": np.broadcast_to(torque, shape),
            "engine_throttle": np.broadcast_to(np.where(on, torque / t_cap, 0.0), shape),
            "engine_power_w": np.broadcast_to(torque * speed, shape),
            "fuel_rate_gps": np.broadcast_to(fuel * 1e3, shape),
            "genset_power_w": np.broadcast_to(supply, shape),
            **machine_details(flow, w_m, shape),
            **battery_details(flow),
            "friction_brake_power_w": loss_powers(hev, st, w_wh, t_wh)["friction_brakes"],
        }
    return st


def loss_powers(hev: SeriesHEV, stage: Any, wheel_speed_radps: Any, wheel_torque_nm: Any) -> dict[str, Any]:
    """Power [W] of every energy-audit term (:data:`LOSSES`) of a :func:`power_flow` result:
    the fuel's chemical power and a current source's power (the sources), the engine's and
    the generator's losses, and the motor, friction-brake, final-drive, auxiliary and wheel
    terms of the same single-reduction drive as the BEV's
    (:func:`hevsim.architectures.bev.point_losses`)."""
    from hevsim.architectures.bev import LOSSES as DRIVE_LOSSES
    from hevsim.architectures.bev import _losses_many

    m, flow = stage.mech, stage.flow
    shape = np.shape(flow.torque_nm)
    w, wm, tfd, tm, pel = (
        np.ascontiguousarray(np.broadcast_to(np.asarray(a, np.float64), shape).ravel())
        for a in (wheel_speed_radps, m["w_m"], m["t_fd"], flow.torque_nm, flow.power_elec_w)
    )
    rows = np.empty((len(DRIVE_LOSSES), w.size))
    g, aux = hev.gear, aux_power_w(hev)
    _losses_many(w, wm, tfd, tm, pel, float(g.ratio), float(g.efficiency), aux, rows)
    out = {name: row.reshape(shape) for name, row in zip(DRIVE_LOSSES, rows, strict=True)}
    lhv = hev.engine.fuel_lhv_jpkg if hev.engine is not None else 0.0
    p_fuel = m["fuel"] * lhv
    p_engine = m["torque"] * m["speed"]
    out["fuel"] = np.broadcast_to(p_fuel, shape)
    out["engine_loss"] = np.broadcast_to(p_fuel - p_engine, shape)
    out["generator_loss"] = np.broadcast_to(p_engine - m["p_gen"], shape)
    out["genset_source"] = np.broadcast_to(m["source"], shape)
    return {name: out[name] for name in LOSSES}


def power_mode(details: dict[str, float], wheel_force_n: float, v_mid_mps: float) -> int:
    """Index in :data:`MODES` of one operating point (``details`` of :func:`power_flow`, wheel
    force [N], mid-step speed [m/s]) by the kernel's :func:`~hevsim.architectures.series_kernel.mode_step`
    (thesis Table 2.1; the pure-ICE band is not part of ``details``: 0 here)."""
    p = np.zeros(len(SK.PARAMS))
    braking = -1.0 if wheel_force_n < 0.0 else 1.0
    mode, _ = SK.mode_step(p, -1, 0, -1, braking, v_mid_mps, details["motor_power_elec_w"],
                          -details["genset_power_w"], 0.0)  # fmt: skip
    return int(mode)


def capability_controls(hev: SeriesHEV) -> tuple[np.ndarray, ...]:
    """Candidate genset powers [W] spanning the powertrain's capability (performance tests),
    largest first: an engine genset's from its largest power down to 0
    (:data:`CAPABILITY_POINTS`), a current source on then off, no genset 0."""
    kind = hev.config.genset.kind
    if kind == "engine" and hev.engine is not None:
        p_max = float(genset_max_power_w(hev)) * (1.0 - GENSET_MAX_RTOL)
        return (np.linspace(p_max, 0.0, CAPABILITY_POINTS),)
    if kind == "current_source":
        return (np.array([1.0, 0.0]),)
    return (np.zeros(1),)

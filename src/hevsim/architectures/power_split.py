"""Power-split hybrid (Toyota THS / THS-II style): one planetary gear set with the engine on
the carrier, the generator MG1 on the sun, and the motor MG2 (through ``motor_coupling``)
and the final drive on the ring.

Controls (:data:`CONTROLS`): engine speed [rad/s] and engine throttle [-]; throttle 0 is
engine off (the carrier stands still).

:func:`mechanical` / :func:`electrical` are the architecture's one power flow, used by the
forward simulator, by ECMS and by the DP (:class:`hevsim.optimal._power_split_dp.PowerSplitFormulation`):

* **Willis equation** (kinematics of the set, tooth numbers ``Z_s``, ``Z_r``):
  ``(Z_s + Z_r) w_carrier = Z_s w_sun + Z_r w_ring``; the ring turns with the final-drive
  input, ``w_ring = w_wheel i_fd``; the carrier with the engine; so MG1 turns at
  ``w_sun = ((Z_s + Z_r) w_e - Z_r w_ring) / Z_s``.
* **Torques** (quasi-static, lossless set): the engine torque ``T_e`` splits into
  ``T_e Z_r / (Z_s + Z_r)`` on the ring and ``T_e Z_s / (Z_s + Z_r)`` on the sun, which MG1
  holds: ``T_MG1 = -T_e Z_s / (Z_s + Z_r)``. MG2 gives the rest of the ring torque the wheels
  need: ``T_MG2 = coupling.input_torque(T_ring - T_e Z_r / (Z_s + Z_r))``.
* **Electric path**: MG1's electrical power is the rest of the bus for MG2's bus balance
  (:func:`hevsim.optimal._hev_common.electric_flow`): battery power = P_el(MG1) + P_el(MG2);
  the battery current and SOC change follow. Regeneration is MG2's (within its generating
  limit and the battery's charge limit); the friction brakes take the rest.
* **Limits**: engine speed within idle (``stall_speed_rpm``)..redline when fired; MG1 torque
  within its limit at ``|w_sun|`` and ``|w_sun|`` within its map; MG2 speed within its map;
  MG2 torque and the battery as in the bus balance.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from hevsim.architectures._build import build_battery, build_engine, build_machine
from hevsim.architectures._common import (
    NO_REFCOUNT,
    NamedModel,
    broadcast_loop,
    chassis,
    fixed_gear,
)
from hevsim.architectures._common import max_machine_speed_radps as _max_speed
from hevsim.components.battery import BatteryPack
from hevsim.components.body import VehicleBody
from hevsim.components.driveline import Gear, Tire, gear_input_torque, gear_output_torque
from hevsim.components.electric_machine import ElectricMachine, limits_from_curves, power_from_map
from hevsim.components.engine import Engine, fired_fuel_from_maps, torque_from_maps
from hevsim.config import PowerSplitConfig
from hevsim.fuels import with_config_fuel

ARCHITECTURE = "power_split"
CONTROLS: tuple[str, ...] = ("engine_speed_radps", "throttle")
MODES: tuple[str, ...] = ("standstill", "ev", "hybrid", "hybrid_charging", "regen")
"""Power modes: standstill; EV (engine off); hybrid (engine on, battery discharging);
hybrid charging (engine on, battery charging); braking with regeneration."""
TORQUE_RTOL = 1e-12
"""Relative tolerance on MG1's torque limit [-]."""


@dataclass(frozen=True, eq=False)
class PowerSplitHEV(NamedModel):
    """A power-split HEV: configuration and component objects."""

    config: PowerSplitConfig
    body: VehicleBody
    tire: Tire
    final_drive: Gear
    engine: Engine
    generator: ElectricMachine
    motor: ElectricMachine
    motor_coupling: Gear
    battery: BatteryPack
    sun_teeth: int
    ring_teeth: int
    aux_power_w: float

    def sun_speed_radps(self, engine_speed_radps: Any, ring_speed_radps: Any) -> Any:
        """MG1 (sun) speed [rad/s] from the Willis equation (:func:`sun_speed`, broadcast)."""
        b = np.broadcast_arrays(
            np.asarray(engine_speed_radps, np.float64), np.asarray(ring_speed_radps, np.float64)
        )
        w_e, w_r = (np.array(x.ravel()) for x in b)
        return _sun_speed_many(w_e, w_r, float(self.sun_teeth), float(self.ring_teeth)).reshape(b[0].shape)


def build_power_split(cfg: PowerSplitConfig) -> PowerSplitHEV:
    """Build the component objects of a power-split HEV from its configuration."""
    base = Path(cfg.base_dir)
    return PowerSplitHEV(
        **chassis(cfg),
        engine=with_config_fuel(build_engine(cfg.engine, base), cfg),
        generator=build_machine(cfg.generator, "generator", base),
        motor=build_machine(cfg.motor, "motor", base),
        motor_coupling=fixed_gear(cfg.motor_coupling),
        battery=build_battery(cfg.battery, base)[0],
        sun_teeth=cfg.planetary.sun_teeth,
        ring_teeth=cfg.planetary.ring_teeth,
        aux_power_w=cfg.controller.aux_power_w,
    )


class PowerSplitTables(NamedTuple):
    """The power split's constants for compiled code, by name: final drive and MG2 coupling
    ratio and efficiency [-], sun and ring tooth numbers [-], the engine's running window
    [rad/s], ``torque_scale`` [-], torque-map / fuel-map switches and fuel LHV [J/kg], MG1's
    model (kind code, constant efficiency, torque scale) and the highest speeds of MG1 and
    MG2 [rad/s] (inf without a map)."""

    final_drive_ratio: float
    final_drive_efficiency: float
    coupling_ratio: float
    coupling_efficiency: float
    sun_teeth: float
    ring_teeth: float
    stall_radps: float
    redline_radps: float
    engine_torque_scale: float
    use_torque_map: bool
    use_fuel_map: bool
    lhv_jpkg: float
    generator_kind: int
    generator_efficiency: float
    generator_torque_scale: float
    generator_max_speed_radps: float
    motor_max_speed_radps: float


def kernel_tables(hev: PowerSplitHEV) -> PowerSplitTables:
    """The :class:`PowerSplitTables` of a model (the engine's and machines' tables are their
    own ``kernel_tables()``)."""
    eng, fd, cpl, mg1 = hev.engine, hev.final_drive, hev.motor_coupling, hev.generator
    return PowerSplitTables(
        final_drive_ratio=float(fd.ratio), final_drive_efficiency=float(fd.efficiency),
        coupling_ratio=float(cpl.ratio), coupling_efficiency=float(cpl.efficiency),
        sun_teeth=float(hev.sun_teeth), ring_teeth=float(hev.ring_teeth),
        stall_radps=float(eng.stall_speed_radps), redline_radps=float(eng.redline_radps),
        engine_torque_scale=float(eng.torque_scale), use_torque_map=eng.torque_map is not None,
        use_fuel_map=eng.fuel_map is not None, lhv_jpkg=float(eng.fuel_lhv_jpkg),
        generator_kind=int(mg1.kind_code), generator_efficiency=float(mg1.efficiency),
        generator_torque_scale=float(mg1.torque_scale), generator_max_speed_radps=_max_speed(mg1),
        motor_max_speed_radps=_max_speed(hev.motor),
    )  # fmt: skip


@njit(cache=True, inline="always")
def sun_speed(engine_speed_radps, ring_speed_radps, sun_teeth, ring_teeth):
    """MG1 (sun) speed [rad/s] from the Willis equation (scalar kernel)."""
    return ((sun_teeth + ring_teeth) * engine_speed_radps - ring_teeth * ring_speed_radps) / sun_teeth


@njit(cache=True)
def _sun_speed_many(w_e, w_r, sun_teeth, ring_teeth):
    out = np.empty(w_e.shape[0])
    for i in range(w_e.shape[0]):
        out[i] = sun_speed(w_e[i], w_r[i], sun_teeth, ring_teeth)
    return out


@njit(cache=True, inline="always")
def engine_point(engine_speed_radps, throttle, d, etab):
    """The engine half of :func:`mechanical_point` (scalar kernel): the operating point of
    one control, which does not depend on the wheels (compiled loops compute it once per
    candidate and run). ``d``: :class:`PowerSplitTables`; ``etab``: the engine's tables.
    Returns (fired, on, engine speed out of its window, engine speed [rad/s], torque [N·m],
    fuel rate [kg/s])."""
    fired = throttle > 0.0
    w_e = engine_speed_radps if fired else 0.0
    can_run = w_e >= d.stall_radps and w_e <= d.redline_radps
    on = fired and can_run
    t_e = fuel = 0.0
    if on:
        t_e = torque_from_maps(
            throttle, w_e, d.use_torque_map, d.stall_radps, d.redline_radps, d.engine_torque_scale,
            etab.tmax_x, etab.tmax_y, etab.tct_x, etab.tct_y, etab.tmap_x, etab.tmap_y, etab.tmap_z,
        )  # fmt: skip
        fuel = fired_fuel_from_maps(
            t_e, w_e, d.use_fuel_map, d.lhv_jpkg, d.stall_radps, d.redline_radps, d.engine_torque_scale,
            etab.tmax_x, etab.tmax_y, etab.fuel_x, etab.fuel_y, etab.fuel_z,
        )  # fmt: skip
    return fired, on, fired and not can_run, w_e, t_e, fuel


@njit(cache=True, inline="always")
def drive_point(wheel_speed_radps, wheel_torque_nm, engine_speed_radps, w_cmd_min, grid_duplicates, eng, d,
                gtab):  # fmt: skip
    """The wheel half of :func:`mechanical_point` (scalar kernel): planetary set, MG1 and the
    torque MG2 must give, from :func:`engine_point`'s result ``eng`` for the commanded engine
    speed ``engine_speed_radps`` [rad/s]; other arguments and the result as
    :func:`mechanical_point`."""
    fired, on, engine_speed, w_e, t_e, fuel = eng
    zs, zr = d.sun_teeth, d.ring_teeth
    w_r = wheel_speed_radps * d.final_drive_ratio
    t_ring = gear_input_torque(wheel_torque_nm, d.final_drive_ratio, d.final_drive_efficiency)
    w_s = sun_speed(w_e, w_r, zs, zr)
    t_g = -t_e * zs / (zs + zr)
    t_e_ring = t_e * zr / (zs + zr)
    g_max = limits_from_curves(abs(w_s), d.generator_torque_scale, gtab.lim_x, gtab.lim_mot, gtab.lim_gen)[0]
    gen_torque = abs(t_g) > g_max * (1.0 + TORQUE_RTOL)
    gen_speed = abs(w_s) > d.generator_max_speed_radps
    p_g = power_from_map(t_g, w_s, d.generator_kind, d.generator_efficiency, d.generator_torque_scale,
                         gtab.eff_x, gtab.eff_y, gtab.eff_z)  # fmt: skip
    w_em = w_r * d.coupling_ratio
    motor_speed = abs(w_em) > d.motor_max_speed_radps
    bad = engine_speed or not np.isfinite(fuel) or gen_torque or gen_speed or motor_speed
    if grid_duplicates:
        bad = bad or (not fired and engine_speed_radps > w_cmd_min)
    t_em_req = gear_input_torque(t_ring - t_e_ring, d.coupling_ratio, d.coupling_efficiency)
    return (on, engine_speed, gen_torque, gen_speed, motor_speed, bad,
            w_r, t_ring, w_e, t_e, fuel, w_s, t_g, p_g, t_e_ring, w_em, t_em_req)  # fmt: skip


@njit(cache=True, inline="always")
def mechanical_point(
    wheel_speed_radps,
    wheel_torque_nm,
    engine_speed_radps,
    throttle,
    w_cmd_min,
    grid_duplicates,
    d,
    etab,
    gtab,
):
    """The state-independent half at one point (THE scalar kernel; see :func:`mechanical`):
    :func:`drive_point` of :func:`engine_point`.

    ``w_cmd_min`` [rad/s]: the smallest commanded engine speed of the grid (with
    ``grid_duplicates``); ``d``: :class:`PowerSplitTables`; ``etab``, ``gtab``: the engine's
    and MG1's tables. Returns (on, engine_speed, generator_torque, generator_speed,
    motor_speed, bad, w_ring, t_ring, w_e, t_e, fuel, w_sun, t_gen, p_gen, t_e_ring, w_em,
    t_em_req).
    """
    eng = engine_point(engine_speed_radps, throttle, d, etab)
    w, t, w_cmd = wheel_speed_radps, wheel_torque_nm, engine_speed_radps
    return drive_point(w, t, w_cmd, w_cmd_min, grid_duplicates, eng, d, gtab)


MECH_FLAGS: tuple[str, ...] = (
    "on",
    "engine_speed",
    "generator_torque",
    "generator_speed",
    "motor_speed",
    "bad",
)
"""Boolean outputs of :func:`mechanical_point`, in order (keys of :func:`mechanical`)."""
MECH_FLOATS: tuple[str, ...] = ("w_ring", "t_ring", "w_e", "t_e", "fuel", "w_sun", "t_gen", "p_gen",
                                "t_e_ring", "w_em", "t_em_req")  # fmt: skip
"""Float outputs of :func:`mechanical_point`, in order."""


@njit(cache=True, **NO_REFCOUNT)
def _mechanical_many(
    w_wheel, t_wheel, w_cmd, throttle, w_cmd_min, grid_duplicates, d, etab, gtab, flags, floats
):
    """:func:`mechanical_point` over flat arrays; fills ``flags`` (6, n) and ``floats`` (11, n)."""
    for i in range(w_wheel.shape[0]):
        r = mechanical_point(
            w_wheel[i], t_wheel[i], w_cmd[i], throttle[i], w_cmd_min, grid_duplicates, d, etab, gtab
        )
        flags[0, i], flags[1, i], flags[2, i], flags[3, i], flags[4, i], flags[5, i] = r[:6]
        for j in range(11):  # the float outputs (a homogeneous slice of the tuple)
            floats[j, i] = r[6:][j]


def mechanical(
    hev: PowerSplitHEV,
    wheel_speed_radps: Any,
    wheel_torque_nm: Any,
    engine_speed_radps: Any,
    throttle: Any,
    *,
    grid_duplicates: bool = False,
) -> dict[str, Any]:
    """The state-independent half: engine, planetary set, MG1 (power and limits), the
    torque MG2 must give, broadcast over every argument (each point is
    :func:`mechanical_point`, one compiled loop). ``grid_duplicates`` marks every engine
    speed but the first with the engine off as infeasible (duplicates on a DP grid)."""
    b = np.broadcast_arrays(*(np.asarray(a, np.float64) for a in (wheel_speed_radps, wheel_torque_nm,
                                                                  engine_speed_radps, throttle)))  # fmt: skip
    shape = b[0].shape
    w, t, w_cmd, thr = (np.array(a.ravel()) for a in b)
    flags = np.empty((len(MECH_FLAGS), w.size), np.bool_)
    floats = np.empty((len(MECH_FLOATS), w.size))
    w_min = float(np.min(w_cmd)) if w_cmd.size else 0.0
    _mechanical_many(w, t, w_cmd, thr, w_min, bool(grid_duplicates), kernel_tables(hev),
                     hev.engine.kernel_tables(), hev.generator.kernel_tables(), flags, floats)  # fmt: skip
    out: dict[str, Any] = {"thr": thr.reshape(shape)}
    out.update({k: flags[j].reshape(shape) for j, k in enumerate(MECH_FLAGS)})
    out.update({k: floats[j].reshape(shape) for j, k in enumerate(MECH_FLOATS)})
    return out


def electrical(
    hev: PowerSplitHEV,
    mech: dict[str, Any],
    soc: Any,
    dt_s: Any,
    regen_ok: Any,
    battery_state: Any = None,
    *,
    detail: bool = False,
) -> Any:
    """The SOC-dependent half: MG2 and the battery (bus balance with MG1's power on the bus),
    SOC change, fuel [kg over ``dt_s``], limits; ``details`` with ``detail``."""
    from hevsim.components.flow import Stage, electric_flow

    m = mech
    flow = electric_flow(hev.motor, hev.battery, m["t_em_req"], m["w_em"], m["p_gen"] + hev.aux_power_w, soc,
                         dt_s, regen_ok, battery_state)  # fmt: skip
    names = ("engine_speed", "generator_torque", "generator_speed", "motor_speed")
    flags = {**{n: m[n] for n in names}, **flow.flags}
    st = Stage(d_soc=flow.d_soc, cost_kg=m["fuel"] * dt_s, infeasible=flow.infeasible | m["bad"], flags=flags,
               flow=flow, mech=m)  # fmt: skip
    if detail:
        brakes = _losses(hev, m, flow, 0.0)["friction_brakes"]
        args = [
            m["on"],
            *(m[n] for n in ("w_e", "t_e", "thr", "fuel", "w_sun", "t_gen", "p_gen", "w_em")),
            flow.torque_nm,
            flow.power_elec_w,
            m["w_ring"],
            flow.current_a,
            flow.battery_power_w,
            brakes,
        ]
        st.details = broadcast_loop(_details_many, DETAILS, args)
    return st


def power_flow(
    hev: PowerSplitHEV,
    wheel_speed_radps: Any,
    wheel_torque_nm: Any,
    engine_speed_radps: Any,
    throttle: Any,
    soc: Any,
    dt_s: Any,
    regen_ok: Any,
    battery_state: Any = None,
    *,
    detail: bool = False,
) -> Any:
    """(wheel demand, engine speed and throttle, SOC) -> operating points, fuel, battery
    power, SOC change: :func:`electrical` of :func:`mechanical`, broadcast."""
    mech = mechanical(hev, wheel_speed_radps, wheel_torque_nm, engine_speed_radps, throttle)
    return electrical(hev, mech, soc, dt_s, regen_ok, battery_state, detail=detail)


LOSS_TERMS: tuple[str, ...] = ("fuel", "engine_loss", "generator_loss", "motor_loss", "coupling_loss",
                                "friction_brakes", "final_drive_loss", "aux", "wheel")  # fmt: skip
"""Energy-audit terms of :func:`loss_powers` / :func:`losses_point`, in order."""


@njit(cache=True, inline="always")
def losses_point(wheel_speed_radps, w_ring, t_ring, w_e, t_e, fuel, w_sun, t_gen, p_gen, t_e_ring, w_em, t_m2,
                 p_m2, aux_power_w, d):  # fmt: skip
    """Power [W] of every audit term at one point (scalar kernel of :func:`loss_powers`, in
    the order of :data:`LOSS_TERMS`) from :func:`mechanical_point`'s operating point, MG2's
    torque [N·m] and electrical power [W] of the bus balance, the auxiliary load [W] and
    ``d`` (:class:`PowerSplitTables`). The planetary set is lossless; the friction brakes
    take, at the ring, the braking torque the engine and MG2 leave."""
    t_m2_ring = gear_output_torque(t_m2, d.coupling_ratio, d.coupling_efficiency)
    fric = min(t_ring - t_e_ring - t_m2_ring, 0.0)
    t_total = t_e_ring + t_m2_ring + fric
    p_wheel = gear_output_torque(t_total, d.final_drive_ratio, d.final_drive_efficiency) * wheel_speed_radps
    p_fuel = fuel * d.lhv_jpkg
    p_m2_mech = t_m2 * w_em
    return (p_fuel, p_fuel - t_e * w_e, p_gen - t_gen * w_sun, p_m2 - p_m2_mech,
            p_m2_mech - t_m2_ring * w_ring, -fric * w_ring, t_total * w_ring - p_wheel, aux_power_w,
            p_wheel)  # fmt: skip


@njit(cache=True, **NO_REFCOUNT)
def _losses_many(w_wheel, w_ring, t_ring, w_e, t_e, fuel, w_sun, t_gen, p_gen, t_e_ring, w_em, t_m2, p_m2,
                 aux_power_w, d, out):  # fmt: skip
    """:func:`losses_point` over flat arrays; fills ``out`` (9, n)."""
    for i in range(w_wheel.shape[0]):
        r = losses_point(
            w_wheel[i],
            w_ring[i],
            t_ring[i],
            w_e[i],
            t_e[i],
            fuel[i],
            w_sun[i],
            t_gen[i],
            p_gen[i],
            t_e_ring[i],
            w_em[i],
            t_m2[i],
            p_m2[i],
            aux_power_w,
            d,
        )
        for j in range(len(r)):
            out[j, i] = r[j]


def _losses(hev: PowerSplitHEV, m: dict[str, Any], flow: Any, wheel_speed_radps: Any) -> dict[str, Any]:
    """:func:`losses_point` broadcast over a :func:`mechanical` result and its bus balance."""
    args = [np.asarray(wheel_speed_radps, np.float64), *(m[n] for n in MECH_FLOATS[:10]), flow.torque_nm,
            flow.power_elec_w]  # fmt: skip
    return broadcast_loop(_losses_many, LOSS_TERMS, args, float(hev.aux_power_w), kernel_tables(hev))


DETAILS: tuple[str, ...] = (
    "engine_on",
    "engine_speed_radps",
    "engine_torque_nm",
    "engine_throttle",
    "engine_power_w",
    "fuel_rate_gps",
    "generator_speed_radps",
    "generator_torque_nm",
    "generator_power_elec_w",
    "motor_speed_radps",
    "motor_torque_nm",
    "motor_power_elec_w",
    "ring_speed_radps",
    "battery_current_a",
    "battery_power_w",
    "friction_brake_power_w",
)
"""Operating-point channels of :func:`electrical` (``details``) / :func:`details_point`, in order."""


@njit(cache=True, inline="always")
def details_point(
    on,
    w_e,
    t_e,
    throttle,
    fuel,
    w_sun,
    t_gen,
    p_gen,
    w_em,
    t_m2,
    p_m2,
    w_ring,
    current_a,
    p_bat,
    brakes_w,
    out,
):
    """Fill ``out`` with the :data:`DETAILS` of one point (scalar kernel): engine on, speed
    [rad/s], torque [N·m], throttle [-], power [W], fuel rate [g/s]; MG1 speed [rad/s],
    torque [N·m], electrical power [W]; MG2 the same; ring speed [rad/s]; battery current [A]
    and power [W]; friction brake power [W]."""
    out[0] = 1.0 if on else 0.0
    out[1], out[2] = w_e, t_e
    out[3] = throttle if on else 0.0
    out[4] = t_e * w_e
    out[5] = fuel * 1e3
    out[6], out[7], out[8], out[9], out[10], out[11] = w_sun, t_gen, p_gen, w_em, t_m2, p_m2
    out[12], out[13], out[14], out[15] = w_ring, current_a, p_bat, brakes_w


@njit(cache=True, **NO_REFCOUNT)
def _details_many(
    on, w_e, t_e, thr, fuel, w_sun, t_gen, p_gen, w_em, t_m2, p_m2, w_ring, current_a, p_bat, brakes_w, out
):
    """:func:`details_point` over flat arrays; fills ``out`` (16, n)."""
    for i in range(on.shape[0]):
        details_point(on[i], w_e[i], t_e[i], thr[i], fuel[i], w_sun[i], t_gen[i], p_gen[i], w_em[i], t_m2[i],
                      p_m2[i], w_ring[i], current_a[i], p_bat[i], brakes_w[i], out[:, i])  # fmt: skip


def loss_powers(
    hev: PowerSplitHEV, stage: Any, wheel_speed_radps: Any, wheel_torque_nm: Any
) -> dict[str, Any]:
    """Power [W] of every audit term: ``fuel``, ``engine_loss``, ``generator_loss`` (MG1
    electrical - mechanical), ``motor_loss`` (MG2), ``coupling_loss``, ``friction_brakes``,
    ``final_drive_loss``, ``aux``, ``wheel``. The planetary set is lossless, so engine shaft
    power = MG1 shaft power + ring power from the engine (:func:`losses_point`)."""
    return _losses(hev, stage.mech, stage.flow, wheel_speed_radps)


def candidate_controls(
    hev: PowerSplitHEV, throttle_points: int, speed_points: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Engine off once (speed 0, throttle 0) and ``speed_points`` engine speeds from idle to
    redline x ``throttle_points - 1`` throttles in (0, 1]. Returns (engine speed, throttle)."""
    n_w = int(speed_points if speed_points is not None else hev.config.controller.engine_speed_points)
    eng = hev.engine
    w = np.linspace(eng.stall_speed_radps, eng.redline_radps, n_w)
    thr = np.linspace(0.0, 1.0, int(throttle_points))[1:]
    return np.concatenate([[0.0], np.repeat(w, thr.size)]), np.concatenate([[0.0], np.tile(thr, n_w)])


CAPABILITY_THROTTLE_POINTS = 11
"""Throttles per engine speed of the performance envelope's candidates [-]."""


def capability_controls(hev: PowerSplitHEV) -> tuple[np.ndarray, ...]:
    """Candidate controls that span the powertrain's capability (performance tests)."""
    return candidate_controls(hev, CAPABILITY_THROTTLE_POINTS, 2 * hev.config.controller.engine_speed_points)


def power_mode(details: dict[str, float], wheel_force_n: float, v_mid_mps: float) -> int:
    """Index in :data:`MODES` of one step's operating point."""
    return int(power_mode_point(details["engine_on"], details["battery_power_w"], wheel_force_n, v_mid_mps))


@njit(cache=True)
def power_mode_point(engine_on, battery_power_w, wheel_force_n, v_mid_mps):
    """Index in :data:`MODES` (scalar kernel) from engine on (> 0), the battery power [W],
    the wheel force [N] and the mid-step speed [m/s]."""
    if v_mid_mps <= 0.0:
        return 0
    if engine_on <= 0.0:
        return 4 if wheel_force_n < 0.0 else 1
    return 3 if battery_power_w < 0.0 else 2

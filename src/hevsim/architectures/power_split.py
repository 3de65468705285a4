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
from typing import Any

import numpy as np

from hevsim.architectures._common import NamedModel, battery_details, chassis, fixed_gear, machine_details
from hevsim.architectures._common import max_machine_speed_radps as _max_speed
from hevsim.components.battery import BatteryPack
from hevsim.components.body import VehicleBody
from hevsim.components.driveline import Gear, Tire
from hevsim.components.electric_machine import ElectricMachine
from hevsim.components.engine import Engine
from hevsim.config import PowerSplitConfig
from hevsim.fuels import with_config_fuel
from hevsim.sim.model import build_battery, build_engine, build_machine

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
        """MG1 (sun) speed [rad/s] from the Willis equation."""
        zs, zr = self.sun_teeth, self.ring_teeth
        return ((zs + zr) * np.asarray(engine_speed_radps) - zr * np.asarray(ring_speed_radps)) / zs


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
    torque MG2 must give. ``grid_duplicates`` marks every engine speed but the first with the
    engine off as infeasible (duplicates on a DP grid)."""
    eng, mg1 = hev.engine, hev.generator
    zs, zr = hev.sun_teeth, hev.ring_teeth
    w_r = np.asarray(wheel_speed_radps, dtype=np.float64) * hev.final_drive.ratio
    t_ring = np.asarray(
        hev.final_drive.input_torque(np.asarray(wheel_torque_nm, np.float64)), dtype=np.float64
    )
    w_r, t_ring, w_cmd, thr = (
        np.array(a) for a in np.broadcast_arrays(w_r, t_ring, np.asarray(engine_speed_radps, np.float64),
                                                 np.asarray(throttle, np.float64))
    )  # fmt: skip
    fired = thr > 0.0
    w_e = np.where(fired, w_cmd, 0.0)
    can_run = (w_e >= eng.stall_speed_radps) & (w_e <= eng.redline_radps)
    on = fired & can_run
    t_e = np.zeros(w_e.shape)
    fuel = np.zeros(w_e.shape)
    if on.any():
        t_e[on] = eng.torque(thr[on], w_e[on])
        fuel[on] = eng.fuel_rate(t_e[on], w_e[on])
    w_s = hev.sun_speed_radps(w_e, w_r)
    t_g = -t_e * zs / (zs + zr)
    t_e_ring = t_e * zr / (zs + zr)
    g_max = np.asarray(mg1.limits(np.abs(w_s))[0], dtype=np.float64)
    gen_torque = np.abs(t_g) > g_max * (1.0 + TORQUE_RTOL)
    gen_speed = np.abs(w_s) > _max_speed(mg1)
    p_g = np.asarray(mg1.electrical_power(t_g, w_s), dtype=np.float64)
    w_em = w_r * hev.motor_coupling.ratio
    motor_speed = np.abs(w_em) > _max_speed(hev.motor)
    bad = (fired & ~can_run) | ~np.isfinite(fuel) | gen_torque | gen_speed | motor_speed
    if grid_duplicates:
        bad = bad | (~fired & (w_cmd > np.min(w_cmd)))
    return {
        "on": on, "thr": thr, "w_ring": w_r, "t_ring": t_ring, "w_e": w_e, "t_e": t_e, "fuel": fuel,
        "w_sun": w_s, "t_gen": t_g, "p_gen": p_g, "t_e_ring": t_e_ring, "bad": bad,
        "engine_speed": fired & ~can_run, "generator_torque": gen_torque, "generator_speed": gen_speed,
        "motor_speed": motor_speed, "w_em": w_em,
        "t_em_req": np.asarray(hev.motor_coupling.input_torque(t_ring - t_e_ring), dtype=np.float64),
    }  # fmt: skip


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
    from hevsim.optimal._hev_common import Stage, electric_flow

    m = mech
    flow = electric_flow(hev.motor, hev.battery, m["t_em_req"], m["w_em"], m["p_gen"] + hev.aux_power_w, soc,
                         dt_s, regen_ok, battery_state)  # fmt: skip
    names = ("engine_speed", "generator_torque", "generator_speed", "motor_speed")
    flags = {**{n: m[n] for n in names}, **flow.flags}
    st = Stage(d_soc=flow.d_soc, cost_kg=m["fuel"] * dt_s, infeasible=flow.infeasible | m["bad"], flags=flags,
               flow=flow, mech=m)  # fmt: skip
    if detail:
        shape = np.shape(flow.torque_nm)
        fric = np.minimum(m["t_ring"] - m["t_e_ring"] - hev.motor_coupling.output_torque(flow.torque_nm), 0.0)
        st.details = {
            "engine_on": m["on"].astype(np.float64),
            "engine_speed_radps": m["w_e"],
            "engine_torque_nm": m["t_e"],
            "engine_throttle": np.where(m["on"], m["thr"], 0.0),
            "engine_power_w": m["t_e"] * m["w_e"],
            "fuel_rate_gps": m["fuel"] * 1e3,
            "generator_speed_radps": np.broadcast_to(m["w_sun"], shape),
            "generator_torque_nm": np.broadcast_to(m["t_gen"], shape),
            "generator_power_elec_w": np.broadcast_to(m["p_gen"], shape),
            **machine_details(flow, m["w_em"], shape),
            "ring_speed_radps": np.broadcast_to(m["w_ring"], shape),
            **battery_details(flow),
            "friction_brake_power_w": -fric * m["w_ring"],
        }
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


def loss_powers(
    hev: PowerSplitHEV, stage: Any, wheel_speed_radps: Any, wheel_torque_nm: Any
) -> dict[str, Any]:
    """Power [W] of every audit term: ``fuel``, ``engine_loss``, ``generator_loss`` (MG1
    electrical - mechanical), ``motor_loss`` (MG2), ``coupling_loss``, ``friction_brakes``,
    ``final_drive_loss``, ``aux``, ``wheel``. The planetary set is lossless, so engine shaft
    power = MG1 shaft power + ring power from the engine."""
    flow, m = stage.flow, stage.mech
    lhv = hev.engine.fuel_lhv_jpkg
    p_eng = m["t_e"] * m["w_e"]
    t_m2 = flow.torque_nm
    t_m2_ring = np.asarray(hev.motor_coupling.output_torque(t_m2))
    fric = np.minimum(m["t_ring"] - m["t_e_ring"] - t_m2_ring, 0.0)
    t_total = m["t_e_ring"] + t_m2_ring + fric
    p_wheel = np.asarray(hev.final_drive.output_torque(t_total)) * np.asarray(wheel_speed_radps)
    return {
        "fuel": m["fuel"] * lhv,
        "engine_loss": m["fuel"] * lhv - p_eng,
        "generator_loss": m["p_gen"] - m["t_gen"] * m["w_sun"],
        "motor_loss": flow.power_elec_w - t_m2 * m["w_em"],
        "coupling_loss": t_m2 * m["w_em"] - t_m2_ring * m["w_ring"],
        "friction_brakes": -fric * m["w_ring"],
        "final_drive_loss": t_total * m["w_ring"] - p_wheel,
        "aux": np.full(np.shape(p_wheel), hev.aux_power_w),
        "wheel": p_wheel,
    }


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
    if v_mid_mps <= 0.0:
        return 0
    if details["engine_on"] <= 0.0:
        return 4 if wheel_force_n < 0.0 else 1
    return 3 if details["battery_power_w"] < 0.0 else 2

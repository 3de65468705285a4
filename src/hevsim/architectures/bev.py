"""Battery-electric vehicle: one electric machine on a single reduction (the final drive),
the battery on its DC bus, friction brakes blended with regeneration.

No supervisory control input (:data:`CONTROLS` is empty): the machine gives the torque the
driver asks for. The architecture's power flow is one scalar compiled kernel,
:func:`wheel_point` (wheel demand -> machine request, regeneration allowed, speed limit),
followed by the shared bus balance (:func:`hevsim.components.bus.machine_request`,
:func:`~hevsim.components.bus.bus_balance`), and :func:`point_losses` (the energy audit's
terms). :func:`power_flow` and :func:`loss_powers` broadcast them (the bus balance through
:func:`hevsim.optimal._hev_common.electric_flow`); the compiled forward run
(:mod:`hevsim.sim._compiled_bev`) calls them once per step.

The machine cannot turn above the last speed of its map (``motor_speed`` limit).
Braking: the machine takes at most ``[brakes] regen_fraction`` of the braking torque (brake
blending), within its generating limit, above ``regen_min_speed_mps`` and within the
battery's charge limit; the friction brakes take the rest. ``[controller] aux_power_w`` is a
constant load on the bus.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from hevsim.architectures._build import build_battery, build_machine
from hevsim.architectures._common import (
    NamedModel,
    battery_details,
    chassis,
    machine_details,
    max_machine_speed_radps,
)
from hevsim.components.battery import BatteryPack
from hevsim.components.body import VehicleBody
from hevsim.components.driveline import Gear, Tire, gear_input_torque, gear_output_torque
from hevsim.components.electric_machine import ElectricMachine
from hevsim.config import BEVConfig

ARCHITECTURE = "bev"
CONTROLS: tuple[str, ...] = ()
MODES: tuple[str, ...] = ("standstill", "traction", "regen", "friction_braking")
LOSSES: tuple[str, ...] = ("fuel", "motor_loss", "friction_brakes", "final_drive_loss", "aux", "wheel")
"""Energy-audit terms of :func:`point_losses`, in its order [W]."""


@dataclass(frozen=True, eq=False)
class BEV(NamedModel):
    """A battery-electric vehicle: configuration and component objects."""

    config: BEVConfig
    body: VehicleBody
    tire: Tire
    final_drive: Gear
    motor: ElectricMachine
    battery: BatteryPack
    regen_fraction: float
    regen_min_speed_mps: float
    aux_power_w: float


def build_bev(cfg: BEVConfig) -> BEV:
    """Build the component objects of a BEV from its configuration."""
    base = Path(cfg.base_dir)
    return BEV(
        **chassis(cfg),
        motor=build_machine(cfg.motor, "motor", base),
        battery=build_battery(cfg.battery, base)[0],
        regen_fraction=cfg.brakes.regen_fraction,
        regen_min_speed_mps=cfg.brakes.regen_min_speed_mps,
        aux_power_w=cfg.controller.aux_power_w,
    )


@njit(cache=True, inline="always")
def wheel_point(
    w_wheel, t_wheel, regen_ok, fd_ratio, fd_eff, regen_fraction, regen_min_speed_mps, radius_m, w_max
):
    """The wheel side of the power flow at one point (scalar kernel).

    Wheel speed [rad/s] and torque [N·m], regeneration allowed by the driver (moving);
    final drive ratio and efficiency [-], brake-blending fraction [-], lowest regeneration
    speed [m/s], tire radius [m], machine speed limit [rad/s]. Returns (machine speed
    [rad/s], final-drive input torque [N·m], machine torque request [N·m]: the traction
    torque, or ``regen_fraction`` of the braking torque, regeneration allowed, over the
    speed limit).
    """
    w_m = w_wheel * fd_ratio
    t_fd = gear_input_torque(t_wheel, fd_ratio, fd_eff)
    t_req = t_fd * regen_fraction if t_fd < 0.0 else t_fd
    ok = regen_ok and w_wheel * radius_m > regen_min_speed_mps
    return w_m, t_fd, t_req, ok, w_m > w_max


@njit(cache=True, inline="always")
def point_losses(w_wheel, w_m, t_fd, t_m, p_el, fd_ratio, fd_eff, aux_w):
    """Power [W] of every energy-audit term (:data:`LOSSES`, in that order) at one point:
    wheel and machine speed [rad/s], final-drive input torque and machine torque [N·m],
    machine electrical power [W], final drive ratio and efficiency [-], auxiliary load [W].
    The friction brakes take the braking torque the machine does not."""
    fric = min(t_fd - t_m, 0.0)
    t_total = t_m + fric
    p_wheel = gear_output_torque(t_total, fd_ratio, fd_eff) * w_wheel
    return 0.0, p_el - t_m * w_m, -fric * w_m, t_total * w_m - p_wheel, aux_w, p_wheel


@njit(cache=True)
def power_mode_code(motor_torque_nm, wheel_force_n, v_mid_mps):
    """Index in :data:`MODES` of an operating point: machine torque [N·m], wheel force [N],
    mid-step speed [m/s]."""
    if v_mid_mps <= 0.0:
        return 0
    if wheel_force_n >= 0.0:
        return 1
    return 2 if motor_torque_nm < 0.0 else 3


@njit(cache=True)
def _wheel_many(w_wheel, t_wheel, regen_ok, fd_ratio, fd_eff, fraction, v_min, radius, w_max, out):
    """:func:`wheel_point` over flat arrays -> rows of ``out`` (booleans as 0/1)."""
    for i in range(w_wheel.shape[0]):
        w_m, t_fd, t_req, ok, over = wheel_point(
            w_wheel[i], t_wheel[i], regen_ok[i] > 0.0, fd_ratio, fd_eff, fraction, v_min, radius, w_max
        )
        out[0, i], out[1, i], out[2, i], out[3, i], out[4, i] = w_m, t_fd, t_req, ok, over


@njit(cache=True)
def _losses_many(w_wheel, w_m, t_fd, t_m, p_el, fd_ratio, fd_eff, aux_w, out):
    """:func:`point_losses` over flat arrays -> rows of ``out`` (:data:`LOSSES`)."""
    for i in range(w_wheel.shape[0]):
        q = point_losses(w_wheel[i], w_m[i], t_fd[i], t_m[i], p_el[i], fd_ratio, fd_eff, aux_w)
        out[0, i], out[1, i], out[2, i], out[3, i], out[4, i], out[5, i] = q


def _losses(bev: Any, w_wheel: Any, w_m: Any, t_fd: Any, flow: Any) -> dict[str, np.ndarray]:
    """:func:`point_losses` of a BEV or a fuel-cell vehicle (its ``final_drive`` and ``aux_power_w``)."""
    shape = np.shape(flow.torque_nm)
    w, wm, tfd, tm, pel = (np.ascontiguousarray(np.broadcast_to(np.asarray(a, np.float64), shape).ravel())
                           for a in (w_wheel, w_m, t_fd, flow.torque_nm, flow.power_elec_w))  # fmt: skip
    out = np.empty((len(LOSSES), w.size))
    fd = bev.final_drive
    _losses_many(w, wm, tfd, tm, pel, float(fd.ratio), float(fd.efficiency), float(bev.aux_power_w), out)
    return {name: row.reshape(shape) for name, row in zip(LOSSES, out, strict=True)}


def power_flow(
    bev: BEV,
    wheel_speed_radps: Any,
    wheel_torque_nm: Any,
    soc: Any,
    dt_s: Any,
    regen_ok: Any,
    battery_state: Any = None,
    *,
    detail: bool = False,
) -> Any:
    """(wheel demand, SOC) -> machine and battery operating points, SOC change, limits
    (broadcast :func:`wheel_point` and the shared bus balance)."""
    from hevsim.components.flow import Stage, electric_flow

    arrays = np.broadcast_arrays(
        *(np.asarray(a, np.float64) for a in (wheel_speed_radps, wheel_torque_nm, regen_ok))
    )
    shape0 = arrays[0].shape
    w_wh, t_wh, ok_in = (np.ascontiguousarray(a.ravel()) for a in arrays)
    rows = np.empty((5, w_wh.size))
    fd = bev.final_drive
    _wheel_many(
        w_wh, t_wh, ok_in, float(fd.ratio), float(fd.efficiency), float(bev.regen_fraction),
        float(bev.regen_min_speed_mps), float(bev.tire.radius_m), max_machine_speed_radps(bev.motor), rows,
    )  # fmt: skip
    w_m, t_fd, t_req, ok, over = (r.reshape(shape0) for r in rows)
    flow = electric_flow(
        bev.motor, bev.battery, t_req, w_m, bev.aux_power_w, soc, dt_s, ok > 0.0, battery_state
    )
    shape = np.shape(flow.torque_nm)
    over_speed = np.broadcast_to(over > 0.0, shape)
    flags = {**flow.flags, "motor_speed": over_speed}
    st = Stage(
        d_soc=flow.d_soc, cost_kg=np.zeros(shape), infeasible=flow.infeasible | over_speed, flags=flags
    )
    st.flow = flow
    st.mech = {"w_fd": np.broadcast_to(w_m, shape), "t_fd": np.broadcast_to(t_fd, shape)}
    if detail:
        st.details = {
            **machine_details(flow, w_m, shape),
            **battery_details(flow),
            "friction_brake_power_w": _losses(bev, w_wh.reshape(shape0), w_m, t_fd, flow)["friction_brakes"],
        }
    return st


def loss_powers(bev: BEV, stage: Any, wheel_speed_radps: Any, wheel_torque_nm: Any) -> dict[str, Any]:
    """Power [W] of every energy-audit term (:data:`LOSSES`: ``motor_loss``,
    ``friction_brakes``, ``final_drive_loss``, ``aux`` and ``wheel``; no fuel) of a
    :func:`power_flow` result (broadcast :func:`point_losses`)."""
    m = stage.mech
    return _losses(bev, wheel_speed_radps, m["w_fd"], m["t_fd"], stage.flow)


def power_mode(details: dict[str, float], wheel_force_n: float, v_mid_mps: float) -> int:
    """Index in :data:`MODES` of one step's operating point (:func:`power_mode_code`)."""
    return int(power_mode_code(details["motor_torque_nm"], wheel_force_n, v_mid_mps))


def capability_controls(bev: BEV) -> tuple[np.ndarray, ...]:
    """No control input."""
    return ()

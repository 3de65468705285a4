"""Battery-electric vehicle: one electric machine on a single reduction (the final drive),
the battery on its DC bus, friction brakes blended with regeneration.

No supervisory control input (:data:`CONTROLS` is empty): the machine gives the torque the
driver asks for. :func:`power_flow` is the architecture's one power flow (the shared bus
balance :func:`hevsim.optimal._hev_common.electric_flow` does the machine, regeneration and
battery); :func:`loss_powers` the energy audit's terms.

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

from hevsim.architectures._common import (
    NamedModel,
    battery_details,
    chassis,
    machine_details,
    max_machine_speed_radps,
)
from hevsim.components.battery import BatteryPack
from hevsim.components.body import VehicleBody
from hevsim.components.driveline import Gear, Tire
from hevsim.components.electric_machine import ElectricMachine
from hevsim.config import BEVConfig
from hevsim.sim.model import build_battery, build_machine

ARCHITECTURE = "bev"
CONTROLS: tuple[str, ...] = ()
MODES: tuple[str, ...] = ("standstill", "traction", "regen", "friction_braking")


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
    """(wheel demand, SOC) -> machine and battery operating points, SOC change, limits."""
    from hevsim.optimal._hev_common import Stage, electric_flow

    w_wh = np.asarray(wheel_speed_radps, dtype=np.float64)
    w_m = w_wh * bev.final_drive.ratio
    t_fd = np.asarray(bev.final_drive.input_torque(np.asarray(wheel_torque_nm, np.float64)), dtype=np.float64)
    t_req = np.where(t_fd < 0.0, t_fd * bev.regen_fraction, t_fd)
    ok = np.asarray(regen_ok) & (w_wh * bev.tire.radius_m > bev.regen_min_speed_mps)
    flow = electric_flow(bev.motor, bev.battery, t_req, w_m, bev.aux_power_w, soc, dt_s, ok, battery_state)
    shape = np.shape(flow.torque_nm)
    over_speed = np.broadcast_to(w_m > max_machine_speed_radps(bev.motor), shape)
    flags = {**flow.flags, "motor_speed": over_speed}
    st = Stage(
        d_soc=flow.d_soc, cost_kg=np.zeros(shape), infeasible=flow.infeasible | over_speed, flags=flags
    )
    st.flow = flow
    st.mech = {"w_fd": np.broadcast_to(w_m, shape), "t_fd": np.broadcast_to(t_fd, shape)}
    if detail:
        fric = np.minimum(t_fd - flow.torque_nm, 0.0)
        st.details = {
            **machine_details(flow, w_m, shape),
            **battery_details(flow),
            "friction_brake_power_w": -fric * w_m,
        }
    return st


def loss_powers(bev: BEV, stage: Any, wheel_speed_radps: Any, wheel_torque_nm: Any) -> dict[str, Any]:
    """Power [W] of every energy-audit term: ``motor_loss``, ``friction_brakes``,
    ``final_drive_loss``, ``aux`` and ``wheel`` (no fuel)."""
    flow, m = stage.flow, stage.mech
    fric = np.minimum(m["t_fd"] - flow.torque_nm, 0.0)
    t_total = flow.torque_nm + fric
    p_wheel = np.asarray(bev.final_drive.output_torque(t_total)) * np.asarray(wheel_speed_radps)
    return {
        "fuel": np.zeros(np.shape(p_wheel)),
        "motor_loss": flow.power_elec_w - flow.torque_nm * m["w_fd"],
        "friction_brakes": -fric * m["w_fd"],
        "final_drive_loss": t_total * m["w_fd"] - p_wheel,
        "aux": np.full(np.shape(p_wheel), bev.aux_power_w),
        "wheel": p_wheel,
    }


def power_mode(details: dict[str, float], wheel_force_n: float, v_mid_mps: float) -> int:
    """Index in :data:`MODES` of one step's operating point."""
    if v_mid_mps <= 0.0:
        return 0
    if wheel_force_n >= 0.0:
        return 1
    return 2 if details["motor_torque_nm"] < 0.0 else 3


def capability_controls(bev: BEV) -> tuple[np.ndarray, ...]:
    """No control input."""
    return ()

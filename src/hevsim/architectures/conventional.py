"""Conventional vehicle: engine, launch clutch, automatic gearbox, final drive, friction brakes.

Control (:data:`CONTROLS`): the gear (1..G), chosen by a shift schedule
(:class:`hevsim.control.simple.ShiftSchedule`). The engine follows the driver's demand: its
torque is what the gearbox input needs, so the throttle is an output.

:func:`power_flow` is the architecture's one power flow: (wheel demand, gear) -> engine,
clutch and gearbox operating points, fuel, limit flags; :func:`loss_powers` gives the energy
audit's terms from the same numbers.

* **Traction** (wheel torque > 0): the gearbox input turns at ``w_in = w_wheel i_fd i_g`` and
  needs ``T_in = gear.input_torque(final_drive.input_torque(T_wheel))``. Above the idle speed
  (``[engine] stall_speed_rpm``) the clutch is closed and the engine turns at ``w_in``; below
  it the launch clutch slips, the engine holds its idle speed and the clutch passes its torque
  (slip loss ``T_in (w_idle - w_in)``). Infeasible when ``T_in`` exceeds the engine's max
  torque at its speed or the speed exceeds the redline (the driver then gets less).
* **No traction** (braking, coasting, standstill): the clutch opens, the engine idles at idle
  speed with zero torque burning the map's idle fuel, or stops with ``[controller] stop_start
  = "on"``; the friction brakes take the braking torque.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.architectures._common import GearboxModel, chassis
from hevsim.components.body import VehicleBody
from hevsim.components.driveline import Gear, Tire
from hevsim.components.engine import Engine
from hevsim.config import ConventionalConfig
from hevsim.fuels import with_config_fuel
from hevsim.sim.model import build_engine

ARCHITECTURE = "conventional"
CONTROLS: tuple[str, ...] = ("gear",)
MODES: tuple[str, ...] = ("standstill", "traction", "launch", "braking", "engine_off")
"""Power modes: standstill (idling); traction (clutch closed); launch (clutch slipping);
braking/coasting (clutch open, idling); engine off (stop-start)."""


@dataclass(frozen=True, eq=False)
class ConventionalVehicle(GearboxModel):
    """A conventional vehicle: configuration and component objects."""

    config: ConventionalConfig
    body: VehicleBody
    tire: Tire
    final_drive: Gear
    gears: tuple[Gear, ...]
    engine: Engine
    stop_start: bool

    @property
    def idle_speed_radps(self) -> float:
        """Idle speed [rad/s] = the engine's lowest running speed."""
        return float(self.engine.stall_speed_radps)


def build_conventional(cfg: ConventionalConfig) -> ConventionalVehicle:
    """Build the component objects of a conventional vehicle from its configuration."""
    engine = build_engine(cfg.engine, Path(cfg.base_dir))
    g = cfg.gearbox
    return ConventionalVehicle(
        **chassis(cfg),
        gears=tuple(Gear(ratio=r, efficiency=g.efficiency) for r in g.ratios),
        engine=with_config_fuel(engine, cfg),
        stop_start=cfg.controller.stop_start == "on",
    )


def power_flow(
    veh: ConventionalVehicle,
    wheel_speed_radps: Any,
    wheel_torque_nm: Any,
    gear: Any,
    soc: Any = 0.0,
    dt_s: Any = 1.0,
    regen_ok: Any = True,
    battery_state: Any = None,
    *,
    detail: bool = False,
) -> Any:
    """(wheel demand, gear) -> operating points, fuel [kg over ``dt_s``], limits (broadcast).

    ``soc``, ``regen_ok`` and ``battery_state`` are accepted for the common signature (no
    battery: the SOC change is 0). Returns a :class:`~hevsim.optimal._hev_common.Stage` with
    ``mech`` (the arrays below) and, with ``detail``, ``details``.
    """
    from hevsim.optimal._hev_common import Stage

    eng = veh.engine
    w_fd = np.asarray(wheel_speed_radps, dtype=np.float64) * veh.final_drive.ratio
    t_fd = np.asarray(veh.final_drive.input_torque(np.asarray(wheel_torque_nm, np.float64)), dtype=np.float64)
    gi = np.rint(np.asarray(gear, dtype=np.float64)).astype(np.int64) - 1
    w_fd, t_fd, gi, dt = (
        np.array(a) for a in np.broadcast_arrays(w_fd, t_fd, gi, np.asarray(dt_s, np.float64))
    )
    bad = (gi < 0) | (gi >= len(veh.gears))
    gi = np.clip(gi, 0, len(veh.gears) - 1)
    w_in = w_fd * veh.gear_ratios[gi]
    traction = t_fd > 0.0
    t_in = np.zeros(gi.shape)
    for g, gearbox in enumerate(veh.gears):
        sel = traction & (gi == g)
        if sel.any():
            t_in[sel] = gearbox.input_torque(t_fd[sel])
    idle = veh.idle_speed_radps
    slipping = traction & (w_in < idle)
    w_e = np.where(traction, np.maximum(w_in, idle), idle)
    t_e = t_in
    on = traction | (not veh.stop_start)
    over_speed = traction & (w_e > eng.redline_radps)
    t_max = np.asarray(eng.max_torque_nm(w_e), dtype=np.float64)
    over_torque = traction & (t_e > t_max * (1.0 + 1e-12))
    fuel = np.zeros(gi.shape)
    if on.any():
        fuel[on] = eng.fuel_rate(t_e[on], w_e[on])
    bad = bad | over_speed | over_torque | ~np.isfinite(fuel)
    fuel = np.where(np.isfinite(fuel), fuel, 0.0)
    t_fd_eng = np.zeros(gi.shape)
    for g, gearbox in enumerate(veh.gears):
        sel = traction & (gi == g)
        if sel.any():
            t_fd_eng[sel] = gearbox.output_torque(t_in[sel])
    mech = {
        "gi": gi, "w_fd": w_fd, "t_fd": t_fd, "w_in": w_in, "t_in": t_in, "w_e": w_e, "t_e": t_e,
        "on": on, "slipping": slipping, "traction": traction, "fuel": fuel, "t_fd_eng": t_fd_eng,
    }  # fmt: skip
    st = Stage(
        d_soc=np.zeros(gi.shape), cost_kg=fuel * dt, infeasible=bad,
        flags={"engine_speed": over_speed, "engine_torque": over_torque},
    )  # fmt: skip
    st.mech = mech
    if detail:
        w_on = np.where(on, w_e, 0.0)
        st.details = {
            "gear": (gi + 1).astype(np.float64),
            "engine_on": on.astype(np.float64),
            "clutch_closed": (traction & ~slipping).astype(np.float64),
            "clutch_slipping": slipping.astype(np.float64),
            "engine_speed_radps": w_on,
            "engine_torque_nm": t_e,
            "engine_throttle": np.where(
                t_max > 0, np.clip(t_e / np.where(t_max > 0, t_max, 1.0), 0.0, 1.0), 0.0
            ),
            "engine_power_w": t_e * w_on,
            "fuel_rate_gps": fuel * 1e3,
            "gearbox_input_speed_radps": w_in,
            "friction_brake_power_w": np.maximum(t_fd_eng - t_fd, 0.0) * w_fd,
        }
    return st


def loss_powers(
    veh: ConventionalVehicle, stage: Any, wheel_speed_radps: Any, wheel_torque_nm: Any
) -> dict[str, Any]:
    """Power [W] of every energy-audit term of a :func:`power_flow` result: ``fuel`` (source),
    ``engine_loss``, ``clutch_loss`` (launch slip), ``gearbox_loss``, ``friction_brakes``,
    ``final_drive_loss`` and ``wheel`` (delivered to the wheels)."""
    m = stage.mech
    lhv = veh.engine.fuel_lhv_jpkg
    p_eng = m["t_e"] * np.where(m["on"], m["w_e"], 0.0)
    p_in = m["t_in"] * m["w_in"]
    fric = np.minimum(m["t_fd"] - m["t_fd_eng"], 0.0)
    t_total = m["t_fd_eng"] + fric
    p_wheel = np.asarray(veh.final_drive.output_torque(t_total)) * np.asarray(wheel_speed_radps)
    return {
        "fuel": m["fuel"] * lhv,
        "engine_loss": m["fuel"] * lhv - p_eng,
        "clutch_loss": p_eng - p_in,
        "gearbox_loss": p_in - m["t_fd_eng"] * m["w_fd"],
        "friction_brakes": -fric * m["w_fd"],
        "final_drive_loss": t_total * m["w_fd"] - p_wheel,
        "wheel": p_wheel,
    }


def power_mode(details: dict[str, float], wheel_force_n: float, v_mid_mps: float) -> int:
    """Index in :data:`MODES` of one step's operating point."""
    if details["engine_on"] <= 0.0:
        return 4
    if v_mid_mps <= 0.0:
        return 0
    if details["clutch_slipping"] > 0.0:
        return 2
    if details["clutch_closed"] > 0.0:
        return 1
    return 3


def capability_controls(veh: ConventionalVehicle) -> tuple[np.ndarray, ...]:
    """Candidate controls that span the powertrain's capability: every gear."""
    return (np.arange(1, len(veh.gears) + 1, dtype=np.float64),)

"""Fuel-cell vehicle (FCEV): the battery-electric drive (one machine on a single reduction,
battery on the DC bus, blended friction brakes) with a fuel-cell system feeding the bus in
place of the series HEV's genset.

Control input (:data:`CONTROLS`): the fuel-cell system's net power ``fuel_cell_power_w`` [W], 0
(off, no hydrogen) or idle ``min_power_w`` .. ``max_power_w``. The power flow is the BEV's
(:func:`hevsim.architectures.bev.wheel_point`, the shared bus balance
:func:`hevsim.components.flow.electric_flow`) with the fuel cell as a source on the bus (the
bus's other load is ``aux_power_w - P_fc``), and its hydrogen (:mod:`hevsim.components.fuel_cell`)
as the stage's fuel. Energy-audit terms (:data:`LOSSES`): ``fuel`` is the hydrogen's chemical
power (LHV basis), ``fuel_cell_loss`` what the system does not turn into net DC power.

Controllers: ``load_follower`` (:class:`hevsim.control.simple.LoadFollower`), and the generic
ECMS / A-ECMS of :mod:`hevsim.control` over :func:`candidate_controls` (0 and the DP's power
grid), each step's candidates moved into what the ramp limits reach from the previous power
(:func:`reachable_controls`, :meth:`~hevsim.components.fuel_cell.FuelCellSystem.project`),
preferring those that leave room below ``battery.soc_max`` for the fuel cell's ramp down to off
(:func:`committed_energy_j`).
DP formulation: :class:`hevsim.optimal._fcev_dp.FCEVFormulation` (state SOC, input the net
power on the same grid). The ramp limits make the previous power a second state the SOC-only
DP does not carry: the DP, and the replay of its optimum, are quasi-static (no ramp limits, as
the series DP has no cranking); the online controllers honour them at every step, but shed
power faster than the ramp-down limit where no power of the ramp window is feasible
(:func:`shed_controls`, counted).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.architectures import bev as B
from hevsim.architectures._build import build_battery, build_machine, resolve_component
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
from hevsim.components.fuel_cell import FuelCellSystem
from hevsim.config import FCEVConfig
from hevsim.units import KWH_PER_GALLON_EQUIVALENT, M_PER_MILE

ARCHITECTURE = "fcev"
CONTROLS: tuple[str, ...] = ("fuel_cell_power_w",)
DP_INPUTS: tuple[str, ...] = ("fuel_cell_power_w",)
"""The DP formulation's inputs, which :func:`power_flow` takes as they are (a DP optimum replays
them: :class:`hevsim.control.parallel.InputSchedule`)."""
MODES: tuple[str, ...] = ("standstill", "traction", "regen", "friction_braking")
LOSSES: tuple[str, ...] = (
    "fuel", "fuel_cell_loss", "motor_loss", "friction_brakes", "final_drive_loss", "aux", "wheel",
)  # fmt: skip
"""Energy-audit terms of :func:`loss_powers` [W]."""


@dataclass(frozen=True, eq=False)
class FCEV(NamedModel):
    """A fuel-cell vehicle: configuration and component objects."""

    config: FCEVConfig
    body: VehicleBody
    tire: Tire
    final_drive: Gear
    motor: ElectricMachine
    fuel_cell: FuelCellSystem
    battery: BatteryPack
    regen_fraction: float
    regen_min_speed_mps: float
    aux_power_w: float


def build_fcev(cfg: FCEVConfig) -> FCEV:
    """Build the component objects of a fuel-cell vehicle from its configuration."""
    from hevsim.fuels import config_fuel

    base = Path(cfg.base_dir)
    fc = cfg.fuel_cell
    folder = resolve_component(fc.data, "fuel_cell", base, "fuel_cell.data")
    fuel = config_fuel(cfg, None)
    lhv = fuel.lower_heating_value_j_per_kg
    system = FuelCellSystem.from_directory(
        folder, max_power_w=fc.max_power_w, min_power_w=fc.min_power_w, ramp_up_w_per_s=fc.ramp_up_w_per_s,
        ramp_down_w_per_s=fc.ramp_down_w_per_s, lhv_j_per_kg=lhv, fuel_name=fuel.name,
        fuel_density_kgpm3=fuel.density_kg_per_m3,
        heating_value_btu_per_gal=fuel.heating_value_btu_per_us_gal, co2_kg_per_kg=fuel.co2_kg_per_kg,
        idle_fuel_power_w=fc.idle_fuel_power_w,
    )  # fmt: skip
    return FCEV(
        **chassis(cfg),
        motor=build_machine(cfg.motor, "motor", base),
        fuel_cell=system,
        battery=build_battery(cfg.battery, base)[0],
        regen_fraction=cfg.brakes.regen_fraction,
        regen_min_speed_mps=cfg.brakes.regen_min_speed_mps,
        aux_power_w=cfg.controller.aux_power_w,
    )


def power_flow(
    fcev: FCEV,
    wheel_speed_radps: Any,
    wheel_torque_nm: Any,
    fuel_cell_power_w: Any,
    soc: Any,
    dt_s: Any,
    regen_ok: Any,
    battery_state: Any = None,
    *,
    detail: bool = False,
) -> Any:
    """(wheel demand, fuel-cell net power [W]: 0 = off, else idle..rating; SOC) -> machine, fuel
    cell and battery operating points, hydrogen [kg] (``cost_kg``), SOC change, limits
    (broadcast; ``fuel_cell_power`` flags a power between 0 and idle or above the rating)."""
    from hevsim.components.flow import Stage, electric_flow

    arrays = np.broadcast_arrays(
        *(np.asarray(a, np.float64) for a in (wheel_speed_radps, wheel_torque_nm, regen_ok))
    )
    shape0 = arrays[0].shape
    w_wh, t_wh, ok_in = (np.ascontiguousarray(a.ravel()) for a in arrays)
    rows = np.empty((5, w_wh.size))
    fd = fcev.final_drive
    B._wheel_many(
        w_wh, t_wh, ok_in, float(fd.ratio), float(fd.efficiency), float(fcev.regen_fraction),
        float(fcev.regen_min_speed_mps), float(fcev.tire.radius_m), max_machine_speed_radps(fcev.motor), rows,
    )  # fmt: skip
    w_m, t_fd, t_req, ok, over = (r.reshape(shape0) for r in rows)
    p_fc = np.asarray(fuel_cell_power_w, np.float64)
    flow = electric_flow(
        fcev.motor, fcev.battery, t_req, w_m, fcev.aux_power_w - p_fc, soc, dt_s, ok > 0.0, battery_state
    )
    shape = np.shape(flow.torque_nm)
    p_fc_b = np.broadcast_to(p_fc, shape)
    fc = fcev.fuel_cell
    out_of_range = ((p_fc_b < fc.min_power_w * (1.0 - 1e-12)) & (p_fc_b != 0.0)) | (
        p_fc_b > fc.max_power_w * (1.0 + 1e-12)
    )  # 0 = off
    over_speed = np.broadcast_to(over > 0.0, shape)
    flags = {**flow.flags, "motor_speed": over_speed, "fuel_cell_power": out_of_range}
    h2_kg = fc.hydrogen_rate_kgps(p_fc_b) * np.asarray(dt_s, np.float64)
    st = Stage(
        d_soc=flow.d_soc, cost_kg=h2_kg, infeasible=flow.infeasible | over_speed | out_of_range, flags=flags
    )
    st.flow = flow
    st.mech = {"w_fd": np.broadcast_to(w_m, shape), "t_fd": np.broadcast_to(t_fd, shape), "p_fc": p_fc_b}
    if detail:
        losses = B._losses(fcev, w_wh.reshape(shape0), w_m, t_fd, flow)
        st.details = {
            "fuel_cell_power_w": p_fc_b,
            "fuel_cell_efficiency": fc.efficiency(p_fc_b),
            "hydrogen_rate_kgps": fc.hydrogen_rate_kgps(p_fc_b),
            **machine_details(flow, w_m, shape),
            **battery_details(flow),
            "friction_brake_power_w": losses["friction_brakes"],
        }
    return st


def loss_powers(fcev: FCEV, stage: Any, wheel_speed_radps: Any, wheel_torque_nm: Any) -> dict[str, Any]:
    """Power [W] of every energy-audit term (:data:`LOSSES`) of a :func:`power_flow` result:
    the BEV's terms, the hydrogen's chemical power (``fuel``) and the fuel-cell system's loss."""
    m = stage.mech
    out = B._losses(fcev, wheel_speed_radps, m["w_fd"], m["t_fd"], stage.flow)
    h2_w = fcev.fuel_cell.hydrogen_power_w(m["p_fc"])
    out["fuel"] = h2_w
    out["fuel_cell_loss"] = h2_w - m["p_fc"]
    return {name: out[name] for name in LOSSES}


def power_mode(details: dict[str, float], wheel_force_n: float, v_mid_mps: float) -> int:
    """Index in :data:`MODES` of one step's operating point (the BEV's)."""
    return int(B.power_mode_code(details["motor_torque_nm"], wheel_force_n, v_mid_mps))


def candidate_controls(fcev: FCEV, n: int) -> tuple[np.ndarray]:
    """``n`` fuel-cell net powers [W] evenly spaced from 0 (off) to the rating, as the DP's input
    grid (:class:`hevsim.optimal._fcev_dp.FCEVFormulation`): what ECMS and A-ECMS score (a
    power between 0 and idle is infeasible)."""
    return (np.linspace(0.0, fcev.fuel_cell.max_power_w, max(int(n), 2)),)


def control_state(fcev: FCEV, stage: Any = None) -> float:
    """The fuel cell's net power [W] the next step's ramp limits start from: after ``stage``
    (a :func:`power_flow` result of the control applied), or before a run its
    ``fuel_cell.initial_power_w`` (0 stays off; else clipped to idle..rating)."""
    if stage is not None:
        return float(np.ravel(stage.mech["p_fc"])[0])
    fc, p0 = fcev.fuel_cell, float(fcev.config.fuel_cell.initial_power_w)
    return 0.0 if p0 <= 0.0 else min(max(p0, fc.min_power_w), fc.max_power_w)


def reachable_controls(
    fcev: FCEV, state: float, dt_s: float, controls: tuple[np.ndarray, ...]
) -> tuple[np.ndarray]:
    """``controls`` (fuel-cell net powers [W]) moved into what the ramp limits reach in ``dt_s``
    [s] from the net power ``state`` [W] (:meth:`~hevsim.components.fuel_cell.FuelCellSystem.project`):
    the candidates an online controller scores at a step."""
    (p,) = controls
    return (fcev.fuel_cell.project(state, dt_s, p),)


def committed_energy_j(fcev: FCEV, controls: tuple[np.ndarray, ...], dt_s: float) -> np.ndarray:
    """Energy [J] each candidate (fuel-cell net powers [W] applied over a step) commits the
    battery to take after the step if the bus load falls to the auxiliaries at once (the car
    coasts or brakes, regeneration to the friction brakes): the fuel cell's fastest ramp down to
    off (:meth:`~hevsim.components.fuel_cell.FuelCellSystem.shutdown_energy_j`). ECMS and A-ECMS
    keep that much room below ``battery.soc_max`` (:class:`hevsim.control.parallel._GridController`)."""
    (p,) = controls
    return np.asarray(fcev.fuel_cell.shutdown_energy_j(p, dt_s, fcev.aux_power_w))


SHED_POINTS = 65
"""Running powers from idle to the ramp window's lowest that :func:`shed_controls` offers."""


def shed_controls(fcev: FCEV, state: float, dt_s: float) -> tuple[np.ndarray]:
    """The fallback candidates [W] of a step where no power within the ramp window is feasible
    (the battery's charge limit, a derated pack's, cannot take what the fuel cell still gives
    after the bus load fell faster than its ramp-down limit): off and :data:`SHED_POINTS` powers
    from idle up to the window's lowest, ascending. The fuel cell then sheds power faster than
    its ``ramp_down_w_per_s``; the controllers take the highest feasible one (the least shed)
    and count the step (``ramp_down_overrides``)."""
    fc = fcev.fuel_cell
    lo, _, _ = fc.reachable_window(state, dt_s)
    return (np.concatenate(([0.0], np.linspace(fc.min_power_w, max(lo, fc.min_power_w), SHED_POINTS))),)


CAPABILITY_POINTS = 41
"""Fuel-cell powers the performance envelope tries, idle to rating (the battery must take or give
the rest, so the rating alone is infeasible at light load)."""


def capability_controls(fcev: FCEV) -> tuple[np.ndarray, ...]:
    """:data:`CAPABILITY_POINTS` fuel-cell powers from idle to the rating (the performance
    envelope's candidates; the envelope ignores the ramp limits: a sustained capability)."""
    fc = fcev.fuel_cell
    return (np.linspace(fc.min_power_w, fc.max_power_w, CAPABILITY_POINTS),)


def extra_metrics(fcev: FCEV, metrics: dict[str, dict[str, Any]]) -> None:
    """Add ``hydrogen_kg`` [kg] and ``mpge`` [mi/gal-equivalent] to a run's ``metrics``: miles per
    (kg of hydrogen + the battery's net energy at 33.705 kWh per gallon equivalent); the EPA counts
    1 kg of hydrogen as one gallon of gasoline equivalent (hydrogen's LHV, 120 MJ/kg = 33.3 kWh/kg,
    is 1.1 % below that gallon)."""
    kg = float(metrics["fuel_kg"]["value"])
    gallons = kg + float(metrics["battery_energy_wh"]["value"]) / 1000.0 / KWH_PER_GALLON_EQUIVALENT
    miles = float(metrics["distance_m"]["value"]) / M_PER_MILE
    metrics["hydrogen_kg"] = {"value": kg, "unit": "kg", "description": "hydrogen consumed"}
    metrics["mpge"] = {
        "value": miles / gallons if gallons > 0 else float("inf"), "unit": "mi/gal-equivalent",
        "description": "mi per (kg of hydrogen + battery net energy / 33.705 kWh): EPA MPGe, 1 kg H2 = 1 gge",
    }  # fmt: skip

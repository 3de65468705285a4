"""Energy management of the chapter-2 series HEV as a DP problem.

State: SOC. Input: the genset's electrical power ``P_g`` on a grid from 0 (engine off) to
the most the engine-generator pair can deliver. For every ``P_g > 0`` the engine runs at the
fuel-optimal point that the generator can absorb (the *optimal operating line*, computed
once by :func:`genset_operating_points`: minimum of ``Engine.fuel_rate`` over the engine
speed in stall..redline, with the torque that makes the generator deliver ``P_g`` within
its generating limit and the engine's max torque). The traction motor gives the wheels the
road load of eq (32) through the final drive (its rotor inertia included), regenerates
when braking above the configured cut-in speed (the friction brakes take the rest), and the
battery closes the bus: ``P_batt = P_motor,el + P_aux - P_g``. Genset speed dynamics and
start-up energy are not modelled (quasi-static). Cost: fuel mass [kg].
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hevsim.components.genset import (  # re-exported: the genset's optimal operating line
    SERIES_POWER_POINTS,
    GensetPoints,
    genset_max_power_w,
    genset_operating_points,
)
from hevsim.cycles import DriveCycle
from hevsim.errors import ConfigError
from hevsim.optimal._hev_common import CycleSteps, FloatArray, HEVFormulation, Stage, electric_flow
from hevsim.optimal._problem import FinalTarget
from hevsim.sim.model import SeriesHEV


class SeriesFormulation(HEVFormulation):
    """The series HEV: input the genset electrical power (0 = engine off)."""

    architecture = "series"
    input_names = ("genset_power_w",)
    input_units = ("W",)

    def __init__(
        self,
        hev: SeriesHEV,
        cycle: DriveCycle,
        *,
        soc_grid: FloatArray,
        power_points: int,
        soc_initial: float,
        target: FinalTarget,
    ) -> None:
        if hev.engine is None or hev.config.genset.kind != "engine":
            raise ConfigError(
                f"{hev.name}: key 'genset.kind' = {hev.config.genset.kind!r}: the DP series formulation "
                "needs an engine genset; expected genset.kind = 'engine'."
            )
        steps = CycleSteps.from_cycle(cycle, hev.body, hev.tire)
        p_max = genset_max_power_w(hev.engine, hev.generator)
        grid = np.linspace(0.0, p_max * (1.0 - 1e-9), power_points)
        super().__init__(hev, steps, soc_grid, (grid,), soc_initial, target, hev.engine, hev.battery,
                         hev.config.metrics.conversion_efficiency)  # fmt: skip
        self.hev = hev
        self.points = genset_operating_points(hev.engine, hev.generator, grid)
        moving = steps.v_mid_mps > 0.0
        ratio = hev.gear.ratio
        self.w_m = steps.wheel_speed_radps * ratio
        alpha = np.where(moving, steps.accel_mps2 / hev.tire.radius_m * ratio, 0.0)
        self.t_inertia = hev.traction_motor.inertia_kgm2 * alpha
        self.t_m_req = (
            np.asarray(hev.gear.input_torque(steps.wheel_torque_nm), dtype=np.float64) + self.t_inertia
        )
        self.regen_ok = steps.v_mid_mps > hev.config.brakes.regen_min_speed_mps
        self.aux_w = hev.config.controller.aux_power_w
        bat = hev.battery
        self.limit_text = {
            "motor_torque": "traction motor torque above its motoring limit at this speed",
            "battery_power": "battery power beyond the maximum OCV^2/(4R)",
            "battery_discharge_current": f"battery discharge current above {bat.max_discharge_current_a:g} A",
            "battery_charge_current": f"battery charge current above {bat.max_charge_current_a:g} A",
        }

    @classmethod
    def default_input_points(cls, model: Any) -> int:
        return SERIES_POWER_POINTS

    @classmethod
    def from_settings(
        cls, model: Any, cycle: DriveCycle, settings: Any, soc_grid: FloatArray, target: FinalTarget
    ) -> SeriesFormulation:
        return cls(model, cycle, soc_grid=soc_grid, power_points=settings.input_points,
                   soc_initial=settings.soc_initial, target=target)  # fmt: skip

    def _genset(self, p: np.ndarray) -> GensetPoints:
        """Operating points at powers ``p`` (grid values looked up, others computed)."""
        grid = self.input_grids[0]
        idx = np.clip(np.searchsorted(grid, p), 0, grid.size - 1)
        on_grid = grid[idx] == p
        if on_grid.all():
            pts = self.points
            return GensetPoints(
                pts.power_w[idx],
                pts.speed_radps[idx],
                pts.torque_nm[idx],
                pts.fuel_kgps[idx],
                pts.feasible[idx],
            )
        flat = np.ravel(p)
        uniq, inv = np.unique(flat, return_inverse=True)
        assert self.hev.engine is not None  # checked in __init__
        pts = genset_operating_points(self.hev.engine, self.hev.generator, uniq)
        shape = np.shape(p)
        return GensetPoints(
            pts.power_w[inv].reshape(shape),
            pts.speed_radps[inv].reshape(shape),
            pts.torque_nm[inv].reshape(shape),
            pts.fuel_kgps[inv].reshape(shape),
            pts.feasible[inv].reshape(shape),
        )

    def mechanical(self, k: Any, inputs: tuple[Any, ...], *, grid_duplicates: bool = False) -> Any:
        (p_in,) = inputs
        kk, p = np.broadcast_arrays(np.asarray(k, dtype=np.int64), np.asarray(p_in, dtype=np.float64))
        return {"k": kk, "p": p, "gs": self._genset(p), "dt": self.steps.dt_s[kk]}

    def electrical(self, mech: Any, soc: Any, *, detail: bool = False) -> Stage:
        hev = self.hev
        kk, p, gs, dt = mech["k"], mech["p"], mech["gs"], mech["dt"]
        w_m = self.w_m[kk]
        flow = electric_flow(
            hev.traction_motor,
            hev.battery,
            self.t_m_req[kk],
            w_m,
            self.aux_w - gs.power_w,
            soc,
            dt,
            self.regen_ok[kk],
            self.battery_at(soc),
        )
        infeasible = flow.infeasible | ~gs.feasible
        fuel = np.where(gs.feasible, gs.fuel_kgps, 0.0)
        st = Stage(d_soc=flow.d_soc, cost_kg=fuel * dt, infeasible=infeasible, flags=dict(flow.flags))
        if detail:
            on = (p > 0.0) & gs.feasible
            eng = hev.engine
            assert eng is not None
            t_max = eng.max_torque_nm(np.where(on, gs.speed_radps, eng.stall_speed_radps))
            wheel_motor = hev.gear.output_torque(flow.torque_nm - self.t_inertia[kk])
            fric = np.minimum(self.steps.wheel_torque_nm[kk] - wheel_motor, 0.0)
            st.details = {
                "engine_on": on.astype(np.float64),
                "engine_speed_radps": gs.speed_radps,
                "engine_torque_nm": gs.torque_nm,
                "engine_throttle": np.where(on, gs.torque_nm / t_max, 0.0),
                "engine_power_w": gs.torque_nm * gs.speed_radps,
                "fuel_rate_gps": fuel * 1e3,
                "genset_power_w": np.where(on, gs.power_w, 0.0),
                "motor_speed_radps": np.broadcast_to(w_m, kk.shape),
                "motor_torque_nm": flow.torque_nm,
                "motor_power_elec_w": flow.power_elec_w,
                "battery_current_a": flow.current_a,
                "battery_power_w": flow.battery_power_w,
                "friction_brake_power_w": -fric * self.steps.wheel_speed_radps[kk],
            }
        return st

    def max_wheel_force_n(self, k: int) -> float:
        hev = self.hev
        t_max = float(np.asarray(hev.traction_motor.limits(self.w_m[k])[0]))
        return float(hev.gear.output_torque(t_max - self.t_inertia[k])) / hev.tire.radius_m

"""Energy management of the fuel-cell vehicle as a DP problem.

State: SOC. Input: the fuel-cell system's net power ``P_fc`` on a grid from 0 (off) to its
rating (a grid power between 0 and idle is infeasible). The power flow is
:func:`hevsim.architectures.fcev.power_flow` (the same function the forward simulator and ECMS
call): the machine gives the road load through the final drive and regenerates above
``brakes.regen_min_speed_mps`` (the friction brakes take the rest), the battery closes the bus,
``P_batt = P_motor,el + P_aux - P_fc``. Cost: hydrogen mass [kg], ``P_fc / (eta(P_fc) LHV) dt``.
The fuel cell's ramp limits are not modelled (they would make its previous power a second state):
the optimum is quasi-static, as the series DP's genset has no cranking.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hevsim.architectures import fcev as F
from hevsim.cycles import DriveCycle
from hevsim.optimal._hev_common import CycleSteps, FloatArray, HEVFormulation, Stage
from hevsim.optimal._problem import FinalTarget


class FCEVFormulation(HEVFormulation):
    """The fuel-cell vehicle: input the fuel cell's net power (0 = off)."""

    architecture = "fcev"
    input_names = F.DP_INPUTS  # replayed as they are (hevsim.control.parallel.InputSchedule)
    input_units = ("W",)

    @classmethod
    def default_input_points(cls, model: Any) -> int:
        """``controller.control_points``: the grid ECMS scores too."""
        return int(model.config.controller.control_points)

    @classmethod
    def from_settings(
        cls, model: Any, cycle: DriveCycle, settings: Any, soc_grid: FloatArray, target: FinalTarget
    ) -> FCEVFormulation:
        return cls(model, cycle, soc_grid=soc_grid, power_points=settings.input_points,
                   soc_initial=settings.soc_initial, target=target)  # fmt: skip

    def __init__(
        self,
        fcev: F.FCEV,
        cycle: DriveCycle,
        *,
        soc_grid: FloatArray,
        power_points: int,
        soc_initial: float,
        target: FinalTarget,
    ) -> None:
        steps = CycleSteps.from_cycle(cycle, fcev.body, fcev.tire)
        (grid,) = F.candidate_controls(fcev, power_points)
        super().__init__(fcev, steps, soc_grid, (grid,), soc_initial, target, fcev.fuel_cell, fcev.battery,
                         fcev.config.metrics.conversion_efficiency)  # fmt: skip
        self.fcev = fcev
        self.regen_ok = steps.v_mid_mps > 0.0
        fc, bat = fcev.fuel_cell, fcev.battery
        self.limit_text = {
            "fuel_cell_power": (
                f"fuel-cell net power between 0 (off) and its idle {fc.min_power_w:g} W, or above its "
                f"rating {fc.max_power_w:g} W"
            ),
            "motor_torque": "traction motor torque above its motoring limit at this speed",
            "motor_speed": "traction motor speed beyond its map",
            "battery_power": "battery power beyond the maximum OCV^2/(4R)",
            "battery_discharge_current": f"battery discharge current above {bat.max_discharge_current_a:g} A",
            "battery_charge_current": f"battery charge current above {bat.max_charge_current_a:g} A",
        }

    def mechanical(self, k: Any, inputs: tuple[Any, ...], *, grid_duplicates: bool = False) -> Any:
        (p_in,) = inputs
        kk, p = np.broadcast_arrays(np.asarray(k, dtype=np.int64), np.asarray(p_in, dtype=np.float64))
        return {"k": kk, "p": p}

    def electrical(self, mech: Any, soc: Any, *, detail: bool = False) -> Stage:
        kk, p = mech["k"], mech["p"]
        steps = self.steps
        st: Stage = F.power_flow(
            self.fcev, steps.wheel_speed_radps[kk], steps.wheel_torque_nm[kk], p, soc, steps.dt_s[kk],
            self.regen_ok[kk], self.battery_at(soc), detail=detail,
        )  # fmt: skip
        if detail:  # the DP result's fuel-converter columns: the fuel cell's (no shaft)
            d = st.details
            shape = np.shape(st.d_soc)
            p_fc = np.broadcast_to(d["fuel_cell_power_w"], shape)
            zero = np.zeros(shape)
            d.update(
                engine_on=(p_fc > 0.0).astype(np.float64), engine_power_w=p_fc,
                fuel_rate_gps=np.broadcast_to(d["hydrogen_rate_kgps"], shape) * 1e3,
                engine_speed_radps=zero, engine_torque_nm=zero, engine_throttle=zero,
            )  # fmt: skip
        return st

    def max_wheel_force_n(self, k: int) -> float:
        fcev = self.fcev
        w_m = float(self.steps.wheel_speed_radps[k] * fcev.final_drive.ratio)
        t_max = float(np.asarray(fcev.motor.limits(w_m)[0]))
        return float(fcev.final_drive.output_torque(t_max)) / fcev.tire.radius_m

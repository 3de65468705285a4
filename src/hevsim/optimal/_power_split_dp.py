"""Energy management of the power-split HEV as a DP problem.

State: SOC. Inputs: engine speed (on a grid from idle to redline) and engine throttle (on a
grid in [0, 1]; 0 = engine off: only the first speed is kept on the grid). The power flow is
:func:`hevsim.architectures.power_split.mechanical` / ``electrical`` (the same functions the
forward simulator and ECMS call). Cost: fuel mass [kg].
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hevsim.architectures import power_split as ps
from hevsim.cycles import DriveCycle
from hevsim.optimal._hev_common import CycleSteps, FloatArray, HEVFormulation, Stage
from hevsim.optimal._problem import FinalTarget
from hevsim.units import radps_to_rpm


class PowerSplitFormulation(HEVFormulation):
    """The power split: inputs engine speed and throttle."""

    architecture = "power_split"
    input_names = ("engine_speed_radps", "throttle")
    input_units = ("rad/s", "-")

    @classmethod
    def default_input_points(cls, model: Any) -> int:
        return int(model.config.controller.control_points)

    @classmethod
    def from_settings(
        cls, model: Any, cycle: DriveCycle, settings: Any, soc_grid: FloatArray, target: FinalTarget
    ) -> PowerSplitFormulation:
        return cls(model, cycle, soc_grid=soc_grid, throttle_points=settings.input_points,
                   speed_points=model.config.controller.engine_speed_points,
                   soc_initial=settings.soc_initial, target=target)  # fmt: skip

    def __init__(
        self,
        hev: ps.PowerSplitHEV,
        cycle: DriveCycle,
        *,
        soc_grid: FloatArray,
        throttle_points: int,
        speed_points: int,
        soc_initial: float,
        target: FinalTarget,
    ) -> None:
        steps = CycleSteps.from_cycle(cycle, hev.body, hev.tire)
        eng = hev.engine
        speeds = np.linspace(eng.stall_speed_radps, eng.redline_radps, int(speed_points))
        throttle = np.linspace(0.0, 1.0, int(throttle_points))
        super().__init__(hev, steps, soc_grid, (speeds, throttle), soc_initial, target, eng, hev.battery,
                         hev.config.metrics.conversion_efficiency)  # fmt: skip
        self.hev = hev
        self.regen_ok = steps.v_mid_mps > 0.0
        self.limit_text = {
            "engine_speed": (
                f"engine speed outside its running window {radps_to_rpm(eng.stall_speed_radps):.0f}-"
                f"{radps_to_rpm(eng.redline_radps):.0f} rpm"
            ),
            "generator_torque": "MG1 torque above its limit (it holds the engine's sun torque)",
            "generator_speed": "MG1 speed beyond its map (Willis equation)",
            "motor_torque": "MG2 torque above its motoring limit",
            "motor_speed": "MG2 speed beyond its map",
            "battery_power": "battery power beyond the maximum OCV^2/(4R)",
            "battery_discharge_current": (
                f"battery discharge current above {hev.battery.max_discharge_current_a:g} A"
            ),
            "battery_charge_current": f"battery charge current above {hev.battery.max_charge_current_a:g} A",
        }

    def mechanical(self, k: Any, inputs: tuple[Any, ...], *, grid_duplicates: bool = False) -> Any:
        w_e, thr = inputs
        kk = np.asarray(k, dtype=np.int64)
        steps = self.steps
        mech = ps.mechanical(self.hev, steps.wheel_speed_radps[kk], steps.wheel_torque_nm[kk], w_e, thr,
                             grid_duplicates=grid_duplicates)  # fmt: skip
        mech["k"] = np.broadcast_to(kk, mech["w_e"].shape)
        return mech

    def electrical(self, mech: Any, soc: Any, *, detail: bool = False) -> Stage:
        kk = mech["k"]
        st: Stage = ps.electrical(
            self.hev, mech, soc, self.steps.dt_s[kk], self.regen_ok[kk], self.battery_at(soc), detail=detail
        )
        return st

    def max_wheel_force_n(self, k: int) -> float:
        hev = self.hev
        w_r = float(self.steps.wheel_speed_radps[k] * hev.final_drive.ratio)
        t_m2 = float(np.asarray(hev.motor.limits(w_r * hev.motor_coupling.ratio)[0]))
        t_e = float(np.max(hev.engine.max_torque_nm(self.input_grids[0])))
        t_ring = float(hev.motor_coupling.output_torque(t_m2)) + t_e * hev.ring_teeth / (
            hev.sun_teeth + hev.ring_teeth
        )
        return float(hev.final_drive.output_torque(t_ring)) / hev.tire.radius_m

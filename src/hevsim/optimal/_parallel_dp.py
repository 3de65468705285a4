"""Energy management of the parallel HEV (thesis appendix DP script) as a DP problem.

The power flow below is :func:`hevsim.architectures.parallel.mechanical` /
:func:`~hevsim.architectures.parallel.electrical` (the same functions the forward simulator
and ECMS call), evaluated over the grid of steps x gears x throttles x SOC.

State: SOC. Inputs: the gear (discrete, 1..G) and the engine throttle ``u`` on a grid in
[0, 1] (the torque split; ``u = 0`` is engine off and declutched: only gear 1 is kept on the
grid and the gear is reported as 0). Cost: fuel mass [kg].
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hevsim.architectures import parallel as parallel_flow
from hevsim.architectures._common import max_machine_speed_radps as P_max_speed
from hevsim.architectures.parallel import ParallelHEV
from hevsim.cycles import DriveCycle
from hevsim.optimal._hev_common import CycleSteps, FloatArray, HEVFormulation, Stage
from hevsim.optimal._problem import FinalTarget
from hevsim.units import radps_to_rpm


class ParallelFormulation(HEVFormulation):
    """The parallel HEV with a multi-speed gearbox: inputs gear and engine throttle."""

    architecture = "parallel"
    input_names = ("gear", "throttle")
    input_units = ("-", "-")
    discrete_inputs = (0,)

    @classmethod
    def default_input_points(cls, model: Any) -> int:
        return int(model.config.optimization.throttle_grid_points)

    @classmethod
    def from_settings(
        cls, model: Any, cycle: DriveCycle, settings: Any, soc_grid: FloatArray, target: FinalTarget
    ) -> ParallelFormulation:
        return cls(model, cycle, soc_grid=soc_grid, throttle_points=settings.input_points,
                   soc_initial=settings.soc_initial, target=target)  # fmt: skip

    def __init__(
        self,
        hev: ParallelHEV,
        cycle: DriveCycle,
        *,
        soc_grid: FloatArray,
        throttle_points: int,
        soc_initial: float,
        target: FinalTarget,
    ) -> None:
        steps = CycleSteps.from_cycle(cycle, hev.body, hev.tire)
        gears = np.arange(1, len(hev.gears) + 1, dtype=np.float64)
        throttle = np.linspace(0.0, 1.0, throttle_points)
        super().__init__(hev, steps, soc_grid, (gears, throttle), soc_initial, target, hev.engine,
                         hev.battery, hev.config.metrics.conversion_efficiency)  # fmt: skip
        self.hev = hev
        self.ratios = hev.gear_ratios
        self.w_fd = steps.wheel_speed_radps * hev.final_drive.ratio
        self.t_fd = np.asarray(hev.final_drive.input_torque(steps.wheel_torque_nm), dtype=np.float64)
        self.w_em = self.w_fd * hev.motor_coupling.ratio
        self.regen_ok = steps.v_mid_mps > 0.0
        eng = hev.engine
        bat = hev.battery
        t_max = float(np.asarray(hev.motor.limits(0.0)[0]))
        self.limit_text = {
            "engine_speed": (
                f"engine speed outside its running window {radps_to_rpm(eng.stall_speed_radps):.0f}-"
                f"{radps_to_rpm(eng.redline_radps):.0f} rpm in the chosen gear"
            ),
            "motor_torque": (
                f"electric machine torque above its motoring limit ({t_max:.0f} N·m at low speed)"
            ),
            "motor_speed": (
                f"electric machine speed above its map's {radps_to_rpm(P_max_speed(hev.motor)):.0f} rpm "
                "(P3: it turns with the final-drive input in every gear)"
            ),
            "battery_power": "battery power beyond the maximum OCV^2/(4R)",
            "battery_discharge_current": f"battery discharge current above {bat.max_discharge_current_a:g} A",
            "battery_charge_current": f"battery charge current above {bat.max_charge_current_a:g} A",
        }

    def mechanical(self, k: Any, inputs: tuple[Any, ...], *, grid_duplicates: bool = False) -> Any:
        gear_val, thr_in = inputs
        kk = np.asarray(k, dtype=np.int64)
        steps = self.steps
        mech = parallel_flow.mechanical(
            self.hev, steps.wheel_speed_radps[kk], steps.wheel_torque_nm[kk], gear_val, thr_in,
            grid_duplicates=grid_duplicates,
        )  # fmt: skip
        mech["k"] = np.broadcast_to(kk, mech["gi"].shape)
        return mech

    def electrical(self, mech: Any, soc: Any, *, detail: bool = False) -> Stage:
        kk = mech["k"]
        return parallel_flow.electrical(
            self.hev, mech, soc, self.steps.dt_s[kk], self.regen_ok[kk], self.battery_at(soc), detail=detail
        )

    def max_wheel_force_n(self, k: int) -> float:
        hev = self.hev
        eng = hev.engine
        coupling = hev.motor_coupling
        p2 = hev.machine_position == "p2"
        t_em = float(np.asarray(hev.motor.limits(self.w_em[k])[0]))
        best = 0.0 if p2 else float(coupling.output_torque(t_em))
        for gear in hev.gears:
            w_e = self.w_fd[k] * gear.ratio
            t_e = 0.0
            if eng.stall_speed_radps <= w_e <= eng.redline_radps:
                t_e = float(np.asarray(eng.torque(1.0, w_e)))
            if p2:  # machine on the gearbox input: both through the gearbox
                t_em_g = float(np.asarray(hev.motor.limits(w_e * coupling.ratio)[0]))
                best = max(best, float(gear.output_torque(t_e + float(coupling.output_torque(t_em_g)))))
            elif t_e:
                best = max(best, float(gear.output_torque(t_e)) + float(coupling.output_torque(t_em)))
        return float(hev.final_drive.output_torque(best)) / hev.tire.radius_m

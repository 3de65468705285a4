"""Energy management of the parallel HEV (thesis appendix DP script) as a DP problem.

State: SOC. Inputs: the gear (discrete, 1..G) and the engine throttle ``u`` on a grid in
[0, 1] (the torque split). For a step with mid-step speed ``v`` the final-drive input turns
at ``w_fd = v / r_w * i_fd`` and must receive ``T_fd`` (the road load of eq 32 through the
final drive). In gear ``g`` the engine turns at ``w_e = w_fd * i_g``:

* ``u > 0``: the engine is fired and clutched in; it must turn within its running window
  (stall..redline, eq 29) and gives ``T_e = Engine.torque(u, w_e)`` (throttle x max torque
  for a map without a torque table) burning ``Engine.fuel_rate(T_e, w_e)``; the gearbox
  passes ``Gear.output_torque(T_e)`` to the final drive.
* ``u = 0``: the engine is off and declutched (no fuel, no torque, the gear is irrelevant:
  only gear 1 is kept on the DP grid and the gear is reported as 0). At a standstill or
  when the engine cannot turn at its stall speed in any gear this is the only choice and
  the machine drives alone.

The electric machine, on the final-drive input through its coupling gear, supplies the
rest: ``T_em = coupling.input_torque(T_fd - T_e,fd)`` within its motoring limit (eq 30);
when braking it regenerates down to its generating limit and the battery's charge limit,
and the friction brakes take the rest. The battery (eqs 13, 21-22, 31) gives the SOC
change. Cost: fuel mass [kg].
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hevsim.cycles import DriveCycle
from hevsim.optimal._hev_common import (
    CycleSteps,
    FloatArray,
    HEVFormulation,
    Stage,
    electric_flow,
)
from hevsim.optimal._problem import FinalTarget
from hevsim.parallel import ParallelHEV
from hevsim.units import radps_to_rpm


class ParallelFormulation(HEVFormulation):
    """The parallel HEV with a multi-speed gearbox: inputs gear and engine throttle."""

    architecture = "parallel"
    input_names = ("gear", "throttle")
    input_units = ("-", "-")
    discrete_inputs = (0,)

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
            "battery_power": "battery power beyond the maximum OCV^2/(4R)",
            "battery_discharge_current": f"battery discharge current above {bat.max_discharge_current_a:g} A",
            "battery_charge_current": f"battery charge current above {bat.max_charge_current_a:g} A",
        }

    def mechanical(self, k: Any, inputs: tuple[Any, ...], *, grid_duplicates: bool = False) -> Any:
        hev = self.hev
        eng = hev.engine
        gear_val, thr_in = inputs
        gi = np.rint(np.asarray(gear_val, dtype=np.float64)).astype(np.int64) - 1
        kk, gi, thr = np.broadcast_arrays(
            np.asarray(k, dtype=np.int64), gi, np.asarray(thr_in, dtype=np.float64)
        )
        w_fd = self.w_fd[kk]
        w_e = w_fd * self.ratios[gi]
        fired = thr > 0.0
        can_run = (w_e >= eng.stall_speed_radps) & (w_e <= eng.redline_radps)
        on = fired & can_run
        t_e = np.zeros(kk.shape)
        fuel = np.zeros(kk.shape)
        t_e_fd = np.zeros(kk.shape)
        if on.any():
            t_e[on] = eng.torque(thr[on], w_e[on])
            fuel[on] = eng.fuel_rate(t_e[on], w_e[on])
            for g, gear in enumerate(hev.gears):
                sel = on & (gi == g)
                if sel.any():
                    t_e_fd[sel] = gear.output_torque(t_e[sel])
        t_fd = self.t_fd[kk]
        bad = (fired & ~can_run) | ~np.isfinite(fuel)
        if grid_duplicates:
            bad = bad | (~fired & (gi > 0))
        return {
            "k": kk, "gi": gi, "thr": thr, "on": on, "engine_speed": fired & ~can_run, "bad": bad,
            "w_fd": w_fd, "w_e": w_e, "t_e": t_e, "t_e_fd": t_e_fd, "t_fd": t_fd, "fuel": fuel,
            "t_em_req": hev.motor_coupling.input_torque(t_fd - t_e_fd), "dt": self.steps.dt_s[kk],
        }  # fmt: skip

    def electrical(self, mech: Any, soc: Any, *, detail: bool = False) -> Stage:
        hev = self.hev
        m = mech
        kk = m["k"]
        flow = electric_flow(
            hev.motor,
            hev.battery,
            m["t_em_req"],
            self.w_em[kk],
            0.0,
            soc,
            m["dt"],
            self.regen_ok[kk],
            self.battery_at(soc),
        )
        flags = {"engine_speed": m["engine_speed"], **flow.flags}
        st = Stage(
            d_soc=flow.d_soc, cost_kg=m["fuel"] * m["dt"], infeasible=flow.infeasible | m["bad"], flags=flags
        )
        if detail:
            on, w_e, t_e = m["on"], m["w_e"], m["t_e"]
            fric = np.minimum(m["t_fd"] - m["t_e_fd"] - hev.motor_coupling.output_torque(flow.torque_nm), 0.0)
            st.details = {
                "gear": np.where(on, m["gi"] + 1, 0).astype(np.float64),
                "engine_on": on.astype(np.float64),
                "engine_speed_radps": np.where(on, w_e, 0.0),
                "engine_torque_nm": t_e,
                "engine_throttle": np.where(on, m["thr"], 0.0),
                "engine_power_w": t_e * np.where(on, w_e, 0.0),
                "fuel_rate_gps": m["fuel"] * 1e3,
                "motor_speed_radps": np.broadcast_to(self.w_em[kk], kk.shape),
                "motor_torque_nm": flow.torque_nm,
                "motor_power_elec_w": flow.power_elec_w,
                "battery_current_a": flow.current_a,
                "battery_power_w": flow.battery_power_w,
                "friction_brake_power_w": -fric * m["w_fd"],
            }
        return st

    def max_wheel_force_n(self, k: int) -> float:
        hev = self.hev
        eng = hev.engine
        t_em = float(np.asarray(hev.motor.limits(self.w_em[k])[0]))
        best = float(hev.motor_coupling.output_torque(t_em))
        for gear in hev.gears:
            w_e = self.w_fd[k] * gear.ratio
            if eng.stall_speed_radps <= w_e <= eng.redline_radps:
                t_e = float(np.asarray(eng.torque(1.0, w_e)))
                best = max(
                    best, float(gear.output_torque(t_e)) + float(hev.motor_coupling.output_torque(t_em))
                )
        return float(hev.final_drive.output_torque(best)) / hev.tire.radius_m

"""The pack's cooling loop: pump, cold plates (series or parallel), radiator, chiller, controller.

The loop is a well-mixed coolant volume (``coolant_volume_l``, temperature ``T_loop``) that the
pump circulates at ``flow_l_min`` through, in order: the radiator (heat exchanger to the
ambient air, effectiveness-NTU), the chiller, the modules' cold plates and back. Per step
``dt`` (explicit in the loop temperature, so every heat flow is booked exactly once):

* capacity rate ``C = rho c_p Q`` [W/K];
* radiator: ``Q_rad = eps C_min (T_loop - T_amb)`` with the counterflow effectiveness
  ``eps(NTU = UA / C_min, C_r = C_min / C_max)`` against the fan's air stream
  (``radiator_air_flow_kg_s``, c_p of air 1006 J/(kg K)); the fan draws ``fan_power_w`` while
  the radiator cools; with ``radiator_bypass = 1`` (default) a thermostat valve bypasses the
  radiator when the coolant is colder than the ambient (it would heat the coolant);
* chiller: removes ``Q_ch`` [W] as the controller asks, at most ``chiller_max_w`` and never
  below the supply temperature ``chiller_min_supply_c``; it draws ``Q_ch / chiller_cop``;
* supply temperature to the plates ``T_s = T_loop - (Q_rad + Q_ch) / C``; in series the plates
  see ``T_s`` plus what the plates upstream added, in parallel each plate gets ``Q / n`` at
  ``T_s``;
* pump: pressure drop ``dp = dp_loop (Q/Q_ref)^2 + plates`` (each plate ``dp_plate (q/Q_ref)^2``
  at its flow ``q``, summed in series), electrical power ``Q dp / eta``, all of which ends up
  as heat in the coolant;
* the loop's pipes and tank exchange ``loop_ua_w_k (T_amb - T_loop)`` with the ambient;
* ``M c_p dT_loop/dt = sum(Q_plates) + P_pump - Q_rad - Q_ch + Q_loop_amb``.

With ``infinite_capacity = 1`` the coolant is an ideal reservoir at ``supply_temp_c``: every
plate sees that temperature and all the heat it takes leaves the system.

Controllers (``[controller] kind``): ``"thresholds"`` switches the chiller fully on when the
hottest cell exceeds ``on_temp_c`` and off below ``off_temp_c``; ``"pi"`` asks for
``kp (T_hot - setpoint) + ki int(T_hot - setpoint) dt`` [W] (clipped to [0, chiller_max_w],
the integral frozen while clipped: anti-windup); ``"off"`` never runs the chiller.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hevsim.errors import ConfigError
from hevsim.units import c_to_k

#: specific heat of air at 300 K [J/(kg K)] (Incropera, Table A.4)
AIR_SPECIFIC_HEAT_J_KGK = 1006.0
LITRE_M3 = 1e-3
LITRE_PER_MIN_M3_S = 1.0 / 60000.0
CONTROLLER_KINDS = ("thresholds", "pi", "off")
LAYOUTS = ("series", "parallel")

_T = {"bounds": (-60.0, 150.0), "unit": "degC"}


@dataclass(frozen=True)
class CoolingSection:
    """``[cooling]``: the loop (module docstring); coolant properties come from the module's
    thermal configuration (``[coolant]`` there)."""

    layout: str = field(default="series", metadata={"choices": LAYOUTS})
    flow_l_min: float = field(default=10.0, metadata={"bounds": (0.0, 1e4), "unit": "L/min"})
    infinite_capacity: int = field(default=0, metadata={"bounds": (0, 1)})
    supply_temp_c: float = field(default=25.0, metadata=_T)
    coolant_volume_l: float = field(default=3.0, metadata={"bounds": (1e-3, 1e4), "unit": "L"})
    flow_ref_l_min: float = field(default=10.0, metadata={"bounds": (1e-6, 1e4), "unit": "L/min"})
    plate_pressure_drop_pa: float = field(default=8000.0, metadata={"bounds": (0.0, 1e7), "unit": "Pa"})
    loop_pressure_drop_pa: float = field(default=15000.0, metadata={"bounds": (0.0, 1e7), "unit": "Pa"})
    pump_efficiency: float = field(default=0.4, metadata={"bounds": (0.01, 1.0), "unit": "-"})
    radiator_ua_w_k: float = field(default=300.0, metadata={"bounds": (0.0, 1e6), "unit": "W/K"})
    radiator_air_flow_kg_s: float = field(default=0.5, metadata={"bounds": (1e-6, 1e3), "unit": "kg/s"})
    fan_power_w: float = field(default=60.0, metadata={"bounds": (0.0, 1e5), "unit": "W"})
    radiator_bypass: int = field(default=1, metadata={"bounds": (0, 1)})
    chiller: int = field(default=1, metadata={"bounds": (0, 1)})
    chiller_cop: float = field(default=2.5, metadata={"bounds": (0.1, 20.0), "unit": "-"})
    chiller_max_w: float = field(default=3000.0, metadata={"bounds": (0.0, 1e6), "unit": "W"})
    chiller_min_supply_c: float = field(default=10.0, metadata=_T)
    loop_ua_w_k: float = field(default=2.0, metadata={"bounds": (0.0, 1e5), "unit": "W/K"})


@dataclass(frozen=True)
class ControllerSection:
    """``[controller]``: chiller control on the hottest cell temperature."""

    kind: str = field(default="thresholds", metadata={"choices": CONTROLLER_KINDS})
    on_temp_c: float = field(default=35.0, metadata=_T)
    off_temp_c: float = field(default=32.0, metadata=_T)
    setpoint_c: float = field(default=32.0, metadata=_T)
    kp_w_k: float = field(default=300.0, metadata={"bounds": (0.0, 1e7), "unit": "W/K"})
    ki_w_ks: float = field(default=5.0, metadata={"bounds": (0.0, 1e7), "unit": "W/(K s)"})


def check_cooling(cool: CoolingSection, ctrl: ControllerSection, source: str) -> None:
    """Refuse loops that cannot work: a chiller without flow, inverted thresholds."""
    if cool.chiller and ctrl.kind != "off" and cool.flow_l_min == 0.0 and not cool.infinite_capacity:
        raise ConfigError(
            f"{source}: key 'cooling.flow_l_min' = 0 with the chiller on (cooling.chiller = 1, controller "
            f"'{ctrl.kind}'); expected a flow > 0 L/min (a chiller cannot remove heat from stagnant "
            "coolant) or cooling.chiller = 0."
        )
    if ctrl.kind == "thresholds" and not ctrl.off_temp_c < ctrl.on_temp_c:
        raise ConfigError(
            f"{source}: key 'controller.off_temp_c' = {ctrl.off_temp_c:g} degC; expected below "
            f"controller.on_temp_c = {ctrl.on_temp_c:g} degC."
        )


def counterflow_effectiveness(ntu: float, cr: float) -> float:
    """Effectiveness of a counterflow heat exchanger [-] (Incropera eq. 11.29a/b)."""
    if ntu <= 0.0:
        return 0.0
    if abs(1.0 - cr) < 1e-9:
        return ntu / (1.0 + ntu)
    e = math.exp(-ntu * (1.0 - cr))
    return (1.0 - e) / (1.0 - cr * e)


@dataclass
class LoopStep:
    """What the loop did in one step (SI)."""

    supply_k: float
    inlet_k: np.ndarray  # per module plate
    plate_flow_m3_s: float
    radiator_w: float
    chiller_w: float
    chiller_power_w: float
    pump_power_w: float
    fan_power_w: float
    loop_ambient_w: float  # into the loop from the ambient


class CoolingLoop:
    """State and step of the loop (module docstring). ``capacity_rate`` from the coolant's
    density [kg/m^3] and specific heat [J/(kg K)]."""

    def __init__(
        self,
        cool: CoolingSection,
        ctrl: ControllerSection,
        n_plates: int,
        density_kg_m3: float,
        specific_heat_j_kgk: float,
        source: str = "cooling",
    ) -> None:
        check_cooling(cool, ctrl, source)
        self.cool, self.ctrl, self.n = cool, ctrl, int(n_plates)
        self.rho_cp = density_kg_m3 * specific_heat_j_kgk  # [J/(m^3 K)]
        self.temp_k = c_to_k(cool.supply_temp_c)
        self.heat_capacity_j_k = self.rho_cp * cool.coolant_volume_l * LITRE_M3
        self.chiller_on = False
        self.integral_ks = 0.0
        self.flow_m3_s = cool.flow_l_min * LITRE_PER_MIN_M3_S

    @property
    def plate_flow_m3_s(self) -> float:
        return self.flow_m3_s / self.n if self.cool.layout == "parallel" else self.flow_m3_s

    def stored_j(self) -> float:
        """``M c_p T_loop`` [J] (0 with an infinite capacity: the reservoir is outside)."""
        return 0.0 if self.cool.infinite_capacity else self.heat_capacity_j_k * self.temp_k

    def _chiller_demand_w(self, hottest_k: float, dt_s: float) -> float:
        c, k = self.cool, self.ctrl
        if not c.chiller or k.kind == "off":
            return 0.0
        t = hottest_k - c_to_k(0.0)
        if k.kind == "thresholds":
            if t > k.on_temp_c:
                self.chiller_on = True
            elif t < k.off_temp_c:
                self.chiller_on = False
            return c.chiller_max_w if self.chiller_on else 0.0
        err = t - k.setpoint_c
        cmd = k.kp_w_k * err + k.ki_w_ks * (self.integral_ks + err * dt_s)
        if 0.0 < cmd < c.chiller_max_w:  # anti-windup: integrate only when not clipped
            self.integral_ks += err * dt_s
        return min(max(cmd, 0.0), c.chiller_max_w)

    def begin_step(self, hottest_k: float, ambient_k: float, dt_s: float) -> LoopStep:
        """Supply temperature and plate inlets [K] for this step, from the loop state."""
        c = self.cool
        q = self.flow_m3_s
        cap = self.rho_cp * q
        if c.infinite_capacity:
            t = c_to_k(c.supply_temp_c)
            return LoopStep(t, np.full(self.n, t), self.plate_flow_m3_s, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        rad = ch = 0.0
        if cap > 0.0:
            c_air = c.radiator_air_flow_kg_s * AIR_SPECIFIC_HEAT_J_KGK
            c_min, c_max = min(cap, c_air), max(cap, c_air)
            eps = counterflow_effectiveness(c.radiator_ua_w_k / c_min, c_min / c_max)
            rad = eps * c_min * (self.temp_k - ambient_k)
            if c.radiator_bypass and rad < 0.0:  # the thermostat valve bypasses a radiator that would heat
                rad = 0.0
            after = self.temp_k - rad / cap
            ch = self._chiller_demand_w(hottest_k, dt_s)
            ch = min(ch, max(0.0, cap * (after - c_to_k(c.chiller_min_supply_c))))
            supply = after - ch / cap
        else:
            supply = self.temp_k
        q_ref = c.flow_ref_l_min * LITRE_PER_MIN_M3_S
        qp = self.plate_flow_m3_s
        plates = self.n * c.plate_pressure_drop_pa * (qp / q_ref) ** 2
        if c.layout == "parallel":
            plates = c.plate_pressure_drop_pa * (qp / q_ref) ** 2
        dp = c.loop_pressure_drop_pa * (q / q_ref) ** 2 + plates
        pump = q * dp / c.pump_efficiency
        fan = c.fan_power_w if q > 0.0 and rad > 0.0 else 0.0
        loop_amb = c.loop_ua_w_k * (ambient_k - self.temp_k)
        return LoopStep(supply, np.full(self.n, supply), qp, rad, ch, ch / c.chiller_cop, pump, fan, loop_amb)

    def series_inlets(self, step: LoopStep, plate_heat_w: np.ndarray) -> np.ndarray:
        """Plate inlet temperatures [K] in series: the supply plus the heat of the plates upstream
        (``plate_heat_w`` of the previous step) over the capacity rate."""
        if self.cool.layout != "series" or self.cool.infinite_capacity or self.flow_m3_s == 0.0:
            return step.inlet_k
        cap = self.rho_cp * self.flow_m3_s
        return step.supply_k + np.concatenate([[0.0], np.cumsum(plate_heat_w)[:-1]]) / cap

    def end_step(self, step: LoopStep, plate_heat_w: float, dt_s: float) -> None:
        """Advance the loop temperature with this step's heat flows [W]."""
        if self.cool.infinite_capacity:
            return
        net = plate_heat_w + step.pump_power_w - step.radiator_w - step.chiller_w + step.loop_ambient_w
        self.temp_k += dt_s * net / self.heat_capacity_j_k


__all__ = [
    "CONTROLLER_KINDS",
    "ControllerSection",
    "CoolingLoop",
    "CoolingSection",
    "LoopStep",
    "check_cooling",
    "counterflow_effectiveness",
]

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
from numba import njit

from hevsim.errors import ConfigError
from hevsim.units import c_to_k

#: specific heat of air at 300 K [J/(kg K)] (Incropera, Table A.4)
AIR_SPECIFIC_HEAT_J_KGK = 1006.0
LITRE_M3 = 1e-3
LITRE_PER_MIN_M3_S = 1.0 / 60000.0
CONTROLLER_KINDS = ("thresholds", "pi", "off")
LAYOUTS = ("series", "parallel")

#: cooling loop parameters ``CoolingLoop.lp`` (:class:`CoolingLoop`)
LP_NAMES = (
    "infinite", "supply_k", "flow_m3_s", "plate_flow_m3_s", "rho_cp", "heat_capacity_j_k", "c_air_w_k",
    "radiator_ua_w_k", "bypass", "chiller", "controller", "chiller_max_w", "min_supply_k", "cop",
    "on_c", "off_c", "setpoint_c", "kp", "ki", "pump_w", "fan_power_w", "loop_ua_w_k", "series",
    "zero_c_k",
)  # fmt: skip
(LP_INF, LP_SUPPLY, LP_FLOW, LP_PFLOW, LP_RHOCP, LP_HCAP, LP_CAIR, LP_UA, LP_BYPASS, LP_CHILLER, LP_CTRL,
 LP_CHMAX, LP_MINSUP, LP_COP, LP_ON, LP_OFF, LP_SET, LP_KP, LP_KI, LP_PUMP, LP_FAN, LP_LOOPUA, LP_SERIES,
 LP_ZEROC) = range(len(LP_NAMES))  # fmt: skip
#: cooling loop state ``CoolingLoop.ls``: loop temperature [K], chiller on (0/1), PI integral [K s]
LS_TEMP, LS_ON, LS_INT = range(3)
#: controller codes (``LP_CTRL``) of :data:`hevsim.battery.cooling.CONTROLLER_KINDS`
CTRL_THRESHOLDS, CTRL_PI, CTRL_OFF = range(3)

#: one loop step (:class:`LoopStep` without the inlets) as :func:`loop_begin` writes it
LOOP_STEP = (
    "supply_k", "plate_flow_m3_s", "radiator_w", "chiller_w", "chiller_power_w", "pump_power_w",
    "fan_power_w", "loop_ambient_w",
)  # fmt: skip
LS_SUPPLY, LS_PFLOW, LS_RAD, LS_CH, LS_CHP, LS_PUMP, LS_FAN, LS_LAMB = range(len(LOOP_STEP))


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
    """Effectiveness of a counterflow heat exchanger [-] (Incropera eq. 11.29a/b), for
    ``ntu`` [-] and capacity-rate ratio ``cr`` [-] (the compiled kernel, called from Python)."""
    return float(_effectiveness(float(ntu), float(cr)))


@njit(cache=True)
def _effectiveness(ntu, cr):
    """:func:`counterflow_effectiveness`'s kernel."""
    if ntu <= 0.0:
        return 0.0
    if abs(1.0 - cr) < 1e-9:
        return ntu / (1.0 + ntu)
    e = math.exp(-ntu * (1.0 - cr))
    return (1.0 - e) / (1.0 - cr * e)


@njit(cache=True)
def _chiller_demand(lp, ls, hottest_k, dt):
    """The controller's chiller demand [W] (:class:`CoolingLoop`)."""
    kind = int(lp[LP_CTRL])
    if lp[LP_CHILLER] == 0.0 or kind == CTRL_OFF:
        return 0.0
    t = hottest_k - lp[LP_ZEROC]
    if kind == CTRL_THRESHOLDS:
        if t > lp[LP_ON]:
            ls[LS_ON] = 1.0
        elif t < lp[LP_OFF]:
            ls[LS_ON] = 0.0
        return lp[LP_CHMAX] if ls[LS_ON] > 0.0 else 0.0
    err = t - lp[LP_SET]
    cmd = lp[LP_KP] * err + lp[LP_KI] * (ls[LS_INT] + err * dt)
    if 0.0 < cmd < lp[LP_CHMAX]:  # anti-windup: integrate only when not clipped
        ls[LS_INT] += err * dt
    return min(max(cmd, 0.0), lp[LP_CHMAX])


@njit(cache=True)
def loop_begin(lp, ls, hottest_k, ambient_k, dt, plate_heat_w, inlet_k, st):
    """The loop's step (:meth:`hevsim.battery.cooling.CoolingLoop.begin_step` then
    ``series_inlets`` with the plates' heat of the previous step): the step ``st``
    (:data:`LOOP_STEP`) and the plates' inlet temperatures ``inlet_k`` [K]."""
    n = inlet_k.shape[0]
    q = lp[LP_FLOW]
    if lp[LP_INF] > 0.0:
        st[LS_SUPPLY] = lp[LP_SUPPLY]
        inlet_k[:] = lp[LP_SUPPLY]
        st[LS_PFLOW] = lp[LP_PFLOW]
        st[LS_RAD:] = 0.0
        return
    cap = lp[LP_RHOCP] * q
    temp = ls[LS_TEMP]
    rad = 0.0
    ch = 0.0
    if cap > 0.0:
        c_min, c_max = min(cap, lp[LP_CAIR]), max(cap, lp[LP_CAIR])
        eps = _effectiveness(lp[LP_UA] / c_min, c_min / c_max)
        rad = eps * c_min * (temp - ambient_k)
        if lp[LP_BYPASS] > 0.0 and rad < 0.0:  # the thermostat valve bypasses a radiator that would heat
            rad = 0.0
        after = temp - rad / cap
        ch = _chiller_demand(lp, ls, hottest_k, dt)
        ch = min(ch, max(0.0, cap * (after - lp[LP_MINSUP])))
        supply = after - ch / cap
    else:
        supply = temp
    st[LS_SUPPLY] = supply
    st[LS_PFLOW] = lp[LP_PFLOW]
    st[LS_RAD] = rad
    st[LS_CH] = ch
    st[LS_CHP] = ch / lp[LP_COP]
    st[LS_PUMP] = lp[LP_PUMP]
    st[LS_FAN] = lp[LP_FAN] if q > 0.0 and rad > 0.0 else 0.0
    st[LS_LAMB] = lp[LP_LOOPUA] * (ambient_k - temp)
    if lp[LP_SERIES] > 0.0 and q != 0.0:  # the plates upstream heat the coolant
        upstream = 0.0
        for m in range(n):
            inlet_k[m] = supply + upstream / cap
            upstream += plate_heat_w[m]
    else:
        inlet_k[:] = supply


@njit(cache=True)
def loop_end(lp, ls, st, plate_w, dt):
    """Advance the loop temperature with the step's heat flows [W]
    (:meth:`hevsim.battery.cooling.CoolingLoop.end_step`)."""
    if lp[LP_INF] > 0.0:
        return
    net = plate_w + st[LS_PUMP] - st[LS_RAD] - st[LS_CH] + st[LS_LAMB]
    ls[LS_TEMP] += dt * net / lp[LP_HCAP]


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
    density [kg/m^3] and specific heat [J/(kg K)]. The parameters are the vector :attr:`lp`
    (:data:`LP_NAMES`) and the state the vector :attr:`ls` (loop temperature [K], chiller on,
    PI integral [K s]) that the compiled :func:`loop_begin` / :func:`loop_end` step."""

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
        self.heat_capacity_j_k = self.rho_cp * cool.coolant_volume_l * LITRE_M3
        self.flow_m3_s = cool.flow_l_min * LITRE_PER_MIN_M3_S
        c, q = cool, self.flow_m3_s
        q_ref = c.flow_ref_l_min * LITRE_PER_MIN_M3_S
        qp = self.plate_flow_m3_s
        plates = self.n * c.plate_pressure_drop_pa * (qp / q_ref) ** 2
        if c.layout == "parallel":
            plates = c.plate_pressure_drop_pa * (qp / q_ref) ** 2
        dp = c.loop_pressure_drop_pa * (q / q_ref) ** 2 + plates
        values = {
            "infinite": c.infinite_capacity, "supply_k": c_to_k(c.supply_temp_c), "flow_m3_s": q,
            "plate_flow_m3_s": qp, "rho_cp": self.rho_cp, "heat_capacity_j_k": self.heat_capacity_j_k,
            "c_air_w_k": c.radiator_air_flow_kg_s * AIR_SPECIFIC_HEAT_J_KGK,
            "radiator_ua_w_k": c.radiator_ua_w_k, "bypass": c.radiator_bypass, "chiller": c.chiller,
            "controller": CONTROLLER_KINDS.index(ctrl.kind),
            "chiller_max_w": c.chiller_max_w, "min_supply_k": c_to_k(c.chiller_min_supply_c),
            "cop": c.chiller_cop, "on_c": ctrl.on_temp_c, "off_c": ctrl.off_temp_c,
            "setpoint_c": ctrl.setpoint_c, "kp": ctrl.kp_w_k, "ki": ctrl.ki_w_ks,
            "pump_w": q * dp / c.pump_efficiency, "fan_power_w": c.fan_power_w, "loop_ua_w_k": c.loop_ua_w_k,
            "series": float(c.layout == "series"), "zero_c_k": c_to_k(0.0),
        }  # fmt: skip
        self.lp = np.array([float(values[k]) for k in LP_NAMES])
        self.ls = np.array([c_to_k(cool.supply_temp_c), 0.0, 0.0])

    @property
    def temp_k(self) -> float:
        """Loop temperature [K]."""
        return float(self.ls[LS_TEMP])

    @property
    def chiller_on(self) -> bool:
        return bool(self.ls[LS_ON])

    @property
    def integral_ks(self) -> float:
        return float(self.ls[LS_INT])

    @property
    def plate_flow_m3_s(self) -> float:
        return self.flow_m3_s / self.n if self.cool.layout == "parallel" else self.flow_m3_s

    def stored_j(self) -> float:
        """``M c_p T_loop`` [J] (0 with an infinite capacity: the reservoir is outside)."""
        return 0.0 if self.cool.infinite_capacity else self.heat_capacity_j_k * self.temp_k

    def begin_step(self, hottest_k: float, ambient_k: float, dt_s: float) -> LoopStep:
        """Supply temperature and plate inlets [K] for this step, from the loop state
        (:func:`loop_begin`; the inlets all at the supply: :meth:`series_inlets` adds the
        plates upstream)."""
        st = np.empty(len(LOOP_STEP))
        inlet = np.empty(self.n)
        heat = np.zeros(self.n)
        loop_begin(self.lp, self.ls, float(hottest_k), float(ambient_k), float(dt_s), heat, inlet, st)
        return LoopStep(float(st[0]), inlet, *(float(v) for v in st[1:]))

    def series_inlets(self, step: LoopStep, plate_heat_w: np.ndarray) -> np.ndarray:
        """Plate inlet temperatures [K] in series: the supply plus the heat of the plates upstream
        (``plate_heat_w`` of the previous step) over the capacity rate."""
        if self.cool.layout != "series" or self.cool.infinite_capacity or self.flow_m3_s == 0.0:
            return step.inlet_k
        cap = self.rho_cp * self.flow_m3_s
        return step.supply_k + np.concatenate([[0.0], np.cumsum(plate_heat_w)[:-1]]) / cap

    def end_step(self, step: LoopStep, plate_heat_w: float, dt_s: float) -> None:
        """Advance the loop temperature with this step's heat flows [W] (:func:`loop_end`)."""
        st = np.array([getattr(step, name) for name in LOOP_STEP])
        loop_end(self.lp, self.ls, st, float(plate_heat_w), float(dt_s))


__all__ = [
    "CONTROLLER_KINDS",
    "LOOP_STEP",
    "LP_NAMES",
    "ControllerSection",
    "CoolingLoop",
    "CoolingSection",
    "LoopStep",
    "check_cooling",
    "counterflow_effectiveness",
    "loop_begin",
    "loop_end",
]

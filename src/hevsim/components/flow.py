"""Point kernels over grids shared by every architecture: the drive cycle as quasi-static
steps, the pack evaluated at a SOC array, the machine + bus + battery balance of a block of
operating points, and the stage output an architecture returns.

The forward simulators, the performance envelope, the BMS of the pack in the vehicle and the
DP formulations (:mod:`hevsim.optimal`) all evaluate operating points through these, so they
live in the physics layer, below every caller. Everything is quasi-static (backward-facing)
and vectorised: the drive cycle fixes the speed and acceleration of every step, the road load
of eq (32) gives the wheel torque. Step ``k`` runs from ``time_s[k]`` to ``time_s[k+1]``;
speeds are evaluated at the mid-step speed and the acceleration is the finite difference, so
``F v_mid dt`` closes the kinetic-energy balance exactly. (Moved from
``hevsim.optimal._hev_common``, which re-exports them, issue 24.)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from hevsim.components.battery import BatteryPack
from hevsim.components.body import VehicleBody
from hevsim.components.bus import battery_power_limits_many, bus_balance_many, machine_request_many
from hevsim.components.driveline import Tire
from hevsim.components.electric_machine import ElectricMachine
from hevsim.cycles import DriveCycle

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

LIMIT_RTOL = 1e-6
"""Relative tolerance on the battery current limits (absorbs the rounding of the regen
scaling)."""
LIMITS: tuple[str, ...] = (
    "engine_speed",
    "motor_torque",
    "battery_power",
    "battery_discharge_current",
    "battery_charge_current",
)
"""Names of the component limits (eqs 29-31) checked for every (state, input) pair."""


@dataclass(frozen=True, eq=False)
class CycleSteps:
    """The drive cycle as DP steps: speed, acceleration and road load of each step.

    Attributes:
        cycle: the drive cycle (samples are the step boundaries).
        time_s, speed_mps: sample times [s] and speeds [m/s], shape (N+1,).
        dt_s, v_mid_mps, accel_mps2, grade: step length [s], mid-step speed [m/s],
            acceleration [m/s^2] and mean grade [-], shape (N,).
        force_n: tractive force at the wheels, eq (32) [N]; zero at a standstill (the
            brakes hold the car).
        wheel_speed_radps [rad/s], wheel_torque_nm [N·m]: at the wheels, shape (N,).
    """

    cycle: DriveCycle
    time_s: FloatArray
    speed_mps: FloatArray
    dt_s: FloatArray
    v_mid_mps: FloatArray
    accel_mps2: FloatArray
    grade: FloatArray
    force_n: FloatArray
    wheel_speed_radps: FloatArray
    wheel_torque_nm: FloatArray

    @classmethod
    def from_cycle(cls, cycle: DriveCycle, body: VehicleBody, tire: Tire) -> CycleSteps:
        """Steps of ``cycle`` for a vehicle with ``body`` and ``tire``."""
        t = np.asarray(cycle.time_s, dtype=np.float64)
        v = np.asarray(cycle.speed_mps, dtype=np.float64)
        gr = np.asarray(cycle.grade, dtype=np.float64)
        dt = np.diff(t)
        v_mid = 0.5 * (v[1:] + v[:-1])
        accel = np.diff(v) / dt
        grade = 0.5 * (gr[1:] + gr[:-1])
        moving = v_mid > 0.0
        force = np.where(moving, body.road_load_force(v_mid, accel, grade), 0.0)
        return cls(
            cycle=cycle,
            time_s=t,
            speed_mps=v,
            dt_s=dt,
            v_mid_mps=v_mid,
            accel_mps2=accel,
            grade=grade,
            force_n=force,
            wheel_speed_radps=np.asarray(tire.wheel_speed_radps(v_mid), dtype=np.float64),
            wheel_torque_nm=force * tire.radius_m,
        )

    @property
    def n_steps(self) -> int:
        """Number of steps N [-]."""
        return int(self.dt_s.size)

    @property
    def distance_m(self) -> float:
        """Distance driven [m]."""
        return float(np.sum(self.v_mid_mps * self.dt_s))

    @property
    def power_required_w(self) -> FloatArray:
        """Tractive power at the wheels, ``F v_mid`` [W] (negative when braking)."""
        return self.force_n * self.v_mid_mps

    def describe(self, k: int) -> str:
        """Human description of step ``k`` (times, speeds, acceleration, grade, load)."""
        return (
            f"step {k} (t = {self.time_s[k]:.6g} to {self.time_s[k + 1]:.6g} s, speed "
            f"{self.speed_mps[k]:.3g} -> {self.speed_mps[k + 1]:.3g} m/s, acceleration "
            f"{self.accel_mps2[k]:.3g} m/s^2, grade {self.grade[k]:.3g}; required wheel force "
            f"{self.force_n[k]:.0f} N, wheel power {self.power_required_w[k] / 1e3:.1f} kW)"
        )


def soc_invariant(battery: BatteryPack, soc: FloatArray) -> bool:
    """True when the pack's OCV and resistances do not vary over ``soc`` [-].

    Then the battery's response to a bus power is the same at every SOC node and the whole
    stage model can be evaluated once per step for all states (the solver's fast path).
    """
    soc = np.asarray(soc, dtype=np.float64)
    ones = np.ones_like(soc)
    arrays = (battery.ocv(soc), battery.resistance(soc, ones), battery.resistance(soc, -ones))
    return all(bool(np.all(a == a.flat[0])) for a in arrays)


@dataclass(frozen=True, eq=False)
class BatteryState:
    """Pack quantities at a SOC array (from the pack's own methods), reused across steps.

    Attributes: soc [-]; ocv_v [V]; r_discharge_ohm, r_charge_ohm [ohm] (eq 22);
    p_charge_max_w: largest charging power at the charge-current limit,
    ``(OCV + R I_max) I_max`` [W] (inf without a limit).
    """

    soc: Any
    ocv_v: FloatArray
    r_discharge_ohm: FloatArray
    r_charge_ohm: FloatArray
    p_charge_max_w: FloatArray

    @classmethod
    def at(cls, battery: BatteryPack, soc: Any) -> BatteryState:
        """Evaluate ``battery`` at ``soc`` (any shape)."""
        ocv = np.asarray(battery.ocv(soc), dtype=np.float64)
        ones = np.ones_like(ocv)
        r_dis = np.asarray(battery.resistance(soc, ones), dtype=np.float64)
        r_chg = np.asarray(battery.resistance(soc, -ones), dtype=np.float64)
        _, (o, rd, rc) = _flat(ocv, r_dis, r_chg)
        i_dis, i_chg = float(battery.max_discharge_current_a), float(battery.max_charge_current_a)
        _, p_chg_flat = battery_power_limits_many(o, rd, rc, i_dis, i_chg)
        p_chg = p_chg_flat.reshape(ocv.shape)
        return cls(soc, ocv, r_dis, r_chg, np.asarray(p_chg, dtype=np.float64))


class BatteryCache:
    """Remembers the :class:`BatteryState` of the last SOC array (the solver passes the same
    grid array at every backward step)."""

    SLOTS = 4

    def __init__(self, battery: BatteryPack) -> None:
        self.battery = battery
        self._states: list[BatteryState] = []

    def __call__(self, soc: Any) -> BatteryState:
        for st in self._states:
            if st.soc is soc or (np.shape(st.soc) == np.shape(soc) and np.array_equal(st.soc, soc)):
                return st
        state = BatteryState.at(self.battery, soc)
        self._states = [state, *self._states[: self.SLOTS - 1]]
        return state


@dataclass
class ElectricFlow:
    """Operating point of an electric machine and the battery for one block of pairs.

    Attributes:
        torque_nm: machine torque after the regeneration limits [N·m].
        power_elec_w: machine electrical power (> 0 drawn from the bus) [W].
        battery_power_w: battery terminal power (> 0 discharging) [W].
        current_a: battery current (> 0 discharging) [A]. d_soc: SOC change over the step [-].
        flags: one boolean array per violated limit name of :data:`LIMITS`.
        infeasible: any limit violated.
    """

    torque_nm: FloatArray
    power_elec_w: FloatArray
    battery_power_w: FloatArray
    current_a: FloatArray
    d_soc: FloatArray
    flags: dict[str, BoolArray]
    infeasible: BoolArray


def _flat(*arrays: Any) -> tuple[tuple[int, ...], list[FloatArray]]:
    """Broadcast arrays; return the shape and contiguous flat float64 copies."""
    arrs = [np.asarray(a, np.float64) for a in arrays]
    shape = np.broadcast_shapes(*(a.shape for a in arrs))
    out = []
    for a in arrs:  # writeable contiguous copies only where needed (numba, no broadcast views)
        x = (a if a.shape == shape else np.broadcast_to(a, shape)).ravel()
        out.append(x if x.flags.writeable and x.flags.c_contiguous else np.array(x))
    return shape, out


def electric_flow(
    machine: ElectricMachine,
    battery: BatteryPack,
    torque_req_nm: Any,
    omega_radps: Any,
    p_other_w: Any,
    soc: Any,
    dt_s: Any,
    regen_ok: Any,
    state: BatteryState | None = None,
) -> ElectricFlow:
    """Machine torque, bus and battery for a required machine torque (vectorised).

    The machine must deliver ``torque_req_nm`` [N·m] at ``omega_radps`` [rad/s] when motoring
    (above its motoring limit the pair is infeasible: ``motor_torque``). When braking it
    regenerates up to its generating limit where ``regen_ok``, and the friction brakes take
    the rest; regeneration is further reduced so that the battery's charge power stays
    within its current limit. ``p_other_w`` [W] is the rest of the bus load (a generator
    feeding the bus is negative). The battery (eqs 13, 21-22) then gives the current at
    ``soc`` [-] and the SOC change over ``dt_s`` [s]; its power and current limits are
    flagged (``battery_power``: beyond ``OCV^2 / 4R``; discharge and charge current).
    ``state``: the pack evaluated at ``soc`` (:class:`BatteryState`), when already known.
    """
    bs = state if state is not None else BatteryState.at(battery, soc)
    tab = machine.kernel_tables()
    kind, eff, scale = machine.kind_code, machine.efficiency, machine.torque_scale
    # the machine request does not depend on the state: once per input
    shape0, (t_req, w0, ok) = _flat(torque_req_nm, omega_radps, regen_ok)
    t0, p0 = np.empty(t_req.size), np.empty(t_req.size)
    over_t0 = np.empty(t_req.size, np.bool_)
    machine_request_many(t_req, w0, ok > 0.0, kind, eff, scale, tab, t0, p0, over_t0)
    shape, (t1, p1, w1, p_oth, ocv, r_dis, r_chg, p_chg) = _flat(
        t0.reshape(shape0), p0.reshape(shape0), w0.reshape(shape0), p_other_w, bs.ocv_v,
        bs.r_discharge_ohm, bs.r_charge_ohm, bs.p_charge_max_w,
    )  # fmt: skip
    out = [np.empty(t1.size) for _ in range(4)]
    over_p = np.empty(t1.size, np.bool_)
    bus_balance_many(
        t1, p1, w1, p_oth, ocv, r_dis, r_chg, p_chg, kind, eff, scale, tab, out[0], out[1], out[2],
        out[3], over_p,
    )  # fmt: skip
    torque, p_el, p_bat, current = (a.reshape(shape) for a in out)
    over_power = over_p.reshape(shape)
    over_torque = np.broadcast_to(over_t0.reshape(shape0), shape)
    flags = {
        "motor_torque": over_torque,
        "battery_power": over_power,
        "battery_discharge_current": current > battery.max_discharge_current_a * (1.0 + LIMIT_RTOL),
        "battery_charge_current": current < -battery.max_charge_current_a * (1.0 + LIMIT_RTOL),
    }
    infeasible = flags["motor_torque"] | flags["battery_power"]
    infeasible = infeasible | flags["battery_discharge_current"] | flags["battery_charge_current"]
    d_soc = np.asarray(battery.soc_rate(current), dtype=np.float64) * dt_s
    return ElectricFlow(torque, p_el, p_bat, current, d_soc, flags, infeasible)


@dataclass
class Stage:
    """Stage model output for a block: SOC change, fuel cost, infeasibility (+ details).

    ``details`` (on request) holds per-pair operating points keyed by time-series column
    name (see :data:`DETAIL_COLUMNS`).
    """

    d_soc: FloatArray
    cost_kg: FloatArray
    infeasible: BoolArray
    flags: dict[str, BoolArray]
    details: dict[str, FloatArray] = field(default_factory=dict)
    flow: Any = None
    """The bus balance (:class:`ElectricFlow`) behind it, where an architecture keeps it."""
    mech: Any = None
    """The architecture's state-independent operating points, where it keeps them."""


DETAIL_COLUMNS: tuple[str, ...] = (
    "engine_on",
    "engine_speed_radps",
    "engine_torque_nm",
    "engine_throttle",
    "engine_power_w",
    "fuel_rate_gps",
    "motor_speed_radps",
    "motor_torque_nm",
    "motor_power_elec_w",
    "battery_current_a",
    "battery_power_w",
    "friction_brake_power_w",
)
"""Operating-point columns every formulation reports along the optimal trajectory."""

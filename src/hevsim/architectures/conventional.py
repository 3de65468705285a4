"""Conventional vehicle: engine, launch clutch, automatic gearbox, final drive, friction brakes.

Control (:data:`CONTROLS`): the gear (1..G), chosen by a shift schedule
(:class:`hevsim.control.simple.ShiftSchedule`). The engine follows the driver's demand: its
torque is what the gearbox input needs, so the throttle is an output.

:func:`operating_point` is the architecture's one power flow, a scalar compiled kernel:
(wheel demand, gear) -> engine, clutch and gearbox operating points, fuel, limit flags;
:func:`point_details` and :func:`point_losses` give the time-series channels and the energy
audit's terms from the same numbers. :func:`power_flow` and :func:`loss_powers` (the DP,
the controllers, the Python forward loop) are broadcast loops over them, and the compiled
forward run (:mod:`hevsim.sim._compiled_conventional`) calls them once per step.

* **Traction** (wheel torque > 0): the gearbox input turns at ``w_in = w_wheel i_fd i_g`` and
  needs ``T_in = gear.input_torque(final_drive.input_torque(T_wheel))``. Above the idle speed
  (``[engine] stall_speed_rpm``) the clutch is closed and the engine turns at ``w_in``; below
  it the launch clutch slips, the engine holds its idle speed and the clutch passes its torque
  (slip loss ``T_in (w_idle - w_in)``). Infeasible when ``T_in`` exceeds the engine's max
  torque at its speed or the speed exceeds the redline (the driver then gets less).
* **Fuel cut** (braking with the gearbox input between ``[controller] fuel_cut_speed_rpm``
  (and idle) and the redline, the braking demand at least the engine's drag): the clutch
  stays closed, no fuel flows and the engine drags with its closed-throttle torque (the
  engine map's ``closed_throttle_torque.csv``, times ``torque_scale``), carried to the wheels
  through the gearbox; the friction brakes take the rest.
* **No traction** otherwise (braking below the fuel-cut speed, coasting with less demand than
  the drag, standstill): the clutch opens, the engine idles at idle speed with zero torque
  burning the map's idle fuel, or stops with ``[controller] stop_start = "on"``; the friction
  brakes take the braking torque.
* **Auxiliaries** (``[controller] aux_power_w``, electrical [W]): while the engine turns, an
  alternator of efficiency ``[alternator] efficiency`` on the crankshaft supplies them, so
  the engine gives ``P_aux / (eta_alt w_e)`` more torque (and burns the fuel for it; in a
  fuel cut the drag carries it). With the engine stopped (stop-start) the starter battery
  supplies them: the audit counts that energy as ``battery_chemical`` (its recharge is not
  modelled).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from hevsim.architectures._build import build_engine
from hevsim.architectures._common import GearboxModel, chassis
from hevsim.components.body import VehicleBody
from hevsim.components.driveline import Gear, Tire, gear_input_torque, gear_output_torque
from hevsim.components.engine import (
    Engine,
    fired_fuel_from_maps,
    max_torque_from_curve,
    torque_from_maps,
)
from hevsim.config import ConventionalConfig
from hevsim.fuels import with_config_fuel
from hevsim.units import rpm_to_radps

ARCHITECTURE = "conventional"
CONTROLS: tuple[str, ...] = ("gear",)
MODES: tuple[str, ...] = ("standstill", "traction", "launch", "braking", "engine_off", "fuel_cut")
"""Power modes: standstill (idling); traction (clutch closed); launch (clutch slipping);
braking/coasting (clutch open, idling); engine off (stop-start); fuel cut (braking, clutch
closed, engine dragging unfired)."""

MECH: tuple[str, ...] = (
    "gi", "w_fd", "t_fd", "w_in", "t_in", "w_e", "t_e", "on", "slipping", "traction", "cut",
    "fuel", "t_fd_eng", "over_speed", "over_torque", "bad", "t_max", "t_alt",
)  # fmt: skip
"""Fields of :func:`operating_point`, in its order: gear index (0-based), final-drive input
speed [rad/s] and torque [N·m], gearbox input speed [rad/s] and torque [N·m], engine speed
[rad/s] and torque [N·m], engine turning, launch clutch slipping, traction, fuel cut, fuel
rate [kg/s], torque the engine side gives the final-drive input [N·m], over the redline,
over the max torque, infeasible, max engine torque at its speed [N·m], the alternator's
torque on the crankshaft [N·m] (included in the engine torque)."""
DETAILS: tuple[str, ...] = (
    "gear", "engine_on", "clutch_closed", "clutch_slipping", "fuel_cut", "engine_speed_radps",
    "engine_torque_nm", "engine_throttle", "engine_power_w", "fuel_rate_gps",
    "gearbox_input_speed_radps", "friction_brake_power_w",
)  # fmt: skip
"""Time-series channels of :func:`point_details`, in its order."""
LOSSES: tuple[str, ...] = (
    "fuel", "engine_loss", "clutch_loss", "gearbox_loss", "friction_brakes", "final_drive_loss",
    "alternator_loss", "aux", "battery_chemical", "wheel",
)  # fmt: skip
"""Energy-audit terms of :func:`point_losses`, in its order [W] (sources: ``fuel`` and
``battery_chemical``, the starter battery supplying the auxiliaries with the engine stopped)."""


class DrivelineData(NamedTuple):
    """A conventional vehicle's driveline and engine scalars for compiled code, by name.

    ``fd_ratio`` [-], ``fd_efficiency`` [-]; ``idle_radps`` idle (= stall) speed,
    ``fuel_cut_radps``, ``redline_radps`` [rad/s]; ``stop_start`` (bool); ``use_fuel_map``
    (bool), ``lhv_jpkg`` [J/kg], ``torque_scale`` [-] of the engine; ``aux_power_w`` [W]
    electrical auxiliary load, ``alternator_efficiency`` [-]. The gear ratios and
    efficiencies and the engine's :class:`~hevsim.components.engine.EngineTables` travel
    beside it as arrays.
    """

    fd_ratio: float
    fd_efficiency: float
    idle_radps: float
    fuel_cut_radps: float
    redline_radps: float
    stop_start: bool
    use_fuel_map: bool
    lhv_jpkg: float
    torque_scale: float
    aux_power_w: float
    alternator_efficiency: float


@dataclass(frozen=True, eq=False)
class ConventionalVehicle(GearboxModel):
    """A conventional vehicle: configuration and component objects.

    ``fuel_cut_radps`` [rad/s]: the deceleration fuel cut's lowest gearbox input speed;
    ``aux_power_w`` [W]: electrical auxiliary load, supplied by an alternator of efficiency
    ``alternator_efficiency`` [-] while the engine turns.
    """

    config: ConventionalConfig
    body: VehicleBody
    tire: Tire
    final_drive: Gear
    gears: tuple[Gear, ...]
    engine: Engine
    stop_start: bool
    fuel_cut_radps: float = float("inf")
    aux_power_w: float = 0.0
    alternator_efficiency: float = 1.0

    @property
    def idle_speed_radps(self) -> float:
        """Idle speed [rad/s] = the engine's lowest running speed."""
        return float(self.engine.stall_speed_radps)

    @property
    def gear_efficiencies(self) -> np.ndarray:
        """Gearbox efficiencies [-], first gear first."""
        return np.array([g.efficiency for g in self.gears])

    def driveline_data(self) -> DrivelineData:
        """The scalars of the compiled kernels (:class:`DrivelineData`)."""
        eng = self.engine
        return DrivelineData(
            fd_ratio=float(self.final_drive.ratio), fd_efficiency=float(self.final_drive.efficiency),
            idle_radps=self.idle_speed_radps, fuel_cut_radps=float(self.fuel_cut_radps),
            redline_radps=float(eng.redline_radps), stop_start=bool(self.stop_start),
            use_fuel_map=eng.fuel_map is not None, lhv_jpkg=float(eng.fuel_lhv_jpkg),
            torque_scale=float(eng.torque_scale), aux_power_w=float(self.aux_power_w),
            alternator_efficiency=float(self.alternator_efficiency),
        )  # fmt: skip


def build_conventional(cfg: ConventionalConfig) -> ConventionalVehicle:
    """Build the component objects of a conventional vehicle from its configuration."""
    engine = build_engine(cfg.engine, Path(cfg.base_dir))
    g = cfg.gearbox
    return ConventionalVehicle(
        **chassis(cfg),
        gears=tuple(Gear(ratio=r, efficiency=g.efficiency) for r in g.ratios),
        engine=with_config_fuel(engine, cfg),
        stop_start=cfg.controller.stop_start == "on",
        fuel_cut_radps=rpm_to_radps(cfg.controller.fuel_cut_speed_rpm),
        aux_power_w=cfg.controller.aux_power_w,
        alternator_efficiency=cfg.alternator.efficiency,
    )


@njit(cache=True, inline="always")
def operating_point(
    w_wheel, t_wheel, gear, ratios, effs, fd_ratio, fd_eff, idle, w_cut, redline, stop_start,
    use_fuel_map, lhv, scale, p_aux, alt_eff, tmax_x, tmax_y, tct_x, tct_y, tmap_x, tmap_y, tmap_z,
    fuel_x, fuel_y, fuel_z,
):  # fmt: skip
    """The power flow at one point (scalar kernel): fields of :data:`MECH`, in that order.

    Wheel speed [rad/s] and torque [N·m], gear (1..G, a float rounded to the nearest);
    gearbox ``ratios`` and ``effs`` [-]; the scalars of :class:`DrivelineData` (final drive
    ratio and efficiency, idle, fuel-cut and redline speeds [rad/s], stop-start, fuel map,
    LHV [J/kg], torque scale, auxiliary load [W], alternator efficiency) and the engine's
    tables as in :class:`~hevsim.components.engine.EngineTables`.
    """
    n_gears = ratios.shape[0]
    gi = int(np.rint(gear)) - 1
    bad = gi < 0 or gi >= n_gears
    gi = min(max(gi, 0), n_gears - 1)
    w_fd = w_wheel * fd_ratio
    t_fd = gear_input_torque(t_wheel, fd_ratio, fd_eff)
    w_in = w_fd * ratios[gi]
    traction = t_fd > 0.0
    t_in = gear_input_torque(t_fd, ratios[gi], effs[gi]) if traction else 0.0
    slipping = traction and w_in < idle
    w_e = max(w_in, idle) if traction else idle
    cut = False
    t_fd_eng = gear_output_torque(t_in, ratios[gi], effs[gi]) if traction else 0.0
    if t_fd < 0.0 and w_in >= w_cut and w_in >= idle and w_in <= redline:
        drag = torque_from_maps(
            0.0, w_in, False, idle, redline, scale, tmax_x, tmax_y, tct_x, tct_y, tmap_x, tmap_y, tmap_z
        )
        drag_in = drag - p_aux / (alt_eff * w_in)  # the alternator brakes too
        drag_fd = gear_output_torque(drag_in, ratios[gi], effs[gi])
        if drag < 0.0 and t_fd <= drag_fd:  # the demand brakes at least as hard as the engine
            cut, w_e, t_in, t_fd_eng = True, w_in, drag_in, drag_fd
    on = traction or cut or not stop_start
    t_alt = p_aux / (alt_eff * w_e) if on and w_e > 0.0 else 0.0
    t_e = t_in + t_alt
    over_speed = traction and w_e > redline
    t_max = max_torque_from_curve(w_e, scale, tmax_x, tmax_y)
    over_torque = on and not cut and t_e > t_max * (1.0 + 1e-12)
    fuel = 0.0
    if on and not cut:
        fuel = fired_fuel_from_maps(
            t_e, w_e, use_fuel_map, lhv, idle, redline, scale, tmax_x, tmax_y, fuel_x, fuel_y, fuel_z
        )
    if not np.isfinite(fuel):
        bad, fuel = True, 0.0
    bad = bad or over_speed or over_torque
    return (
        gi, w_fd, t_fd, w_in, t_in, w_e, t_e, on, slipping, traction, cut, fuel, t_fd_eng, over_speed,
        over_torque, bad, t_max, t_alt,
    )  # fmt: skip


@njit(cache=True, inline="always")
def point_details(gi, w_fd, t_fd, w_in, t_e, w_e, on, slipping, traction, cut, fuel, t_fd_eng, t_max):
    """The time-series channels (:data:`DETAILS`, in that order) of an operating point
    (fields of :data:`MECH`; units as there, fuel rate in g/s)."""
    w_on = w_e if on else 0.0
    throttle = min(max(t_e / t_max, 0.0), 1.0) if t_max > 0.0 else 0.0
    closed = (traction and not slipping) or cut
    return (
        gi + 1.0, 1.0 if on else 0.0, 1.0 if closed else 0.0, 1.0 if slipping else 0.0, 1.0 if cut else 0.0,
        w_on, t_e, throttle, t_e * w_on, fuel * 1e3, w_in, max(t_fd_eng - t_fd, 0.0) * w_fd,
    )  # fmt: skip


@njit(cache=True, inline="always")
def point_losses(
    w_wheel, w_fd, t_fd, w_in, t_in, w_e, t_e, on, fuel, t_fd_eng, t_alt, fd_ratio, fd_eff, lhv, p_aux
):  # fmt: skip
    """Power [W] of every energy-audit term (:data:`LOSSES`, in that order) of an operating
    point (fields of :data:`MECH`), at wheel speed [rad/s] with the auxiliary load ``p_aux``
    [W]: ``fuel`` (source), ``engine_loss``, ``clutch_loss`` (launch slip),
    ``gearbox_loss``, ``friction_brakes``, ``final_drive_loss``, ``alternator_loss``,
    ``aux`` (the auxiliaries), ``battery_chemical`` (source: the starter battery with the
    engine stopped) and ``wheel`` (delivered to the wheels)."""
    p_fuel = fuel * lhv
    w_on = w_e if on else 0.0
    p_eng = t_e * w_on
    p_alt = t_alt * w_on
    p_in = t_in * w_in
    fric = min(t_fd - t_fd_eng, 0.0)
    t_total = t_fd_eng + fric
    p_wheel = gear_output_torque(t_total, fd_ratio, fd_eff) * w_wheel
    p_alt_out = p_aux if on else 0.0
    return (
        p_fuel, p_fuel - p_eng, p_eng - p_alt - p_in, p_in - t_fd_eng * w_fd, -fric * w_fd,
        t_total * w_fd - p_wheel, p_alt - p_alt_out, p_aux, p_aux - p_alt_out, p_wheel,
    )  # fmt: skip


@njit(cache=True)
def power_mode_code(engine_on, clutch_slipping, clutch_closed, fuel_cut, v_mid_mps):
    """Index in :data:`MODES` of an operating point (flags as 0/1 floats, mid-step speed [m/s])."""
    if engine_on <= 0.0:
        return 4
    if v_mid_mps <= 0.0:
        return 0
    if fuel_cut > 0.0:
        return 5
    if clutch_slipping > 0.0:
        return 2
    if clutch_closed > 0.0:
        return 1
    return 3


@njit(cache=True)
def _points_many(w_wheel, t_wheel, gear, ratios, effs, d, tab, mech, details, want_details):
    """:func:`operating_point` (and :func:`point_details` with ``want_details``) over flat
    arrays; fills the rows of ``mech`` (:data:`MECH`) and ``details`` (:data:`DETAILS`)."""
    tmax_x, tmax_y, tct_x, tct_y = tab.tmax_x, tab.tmax_y, tab.tct_x, tab.tct_y
    tmap_x, tmap_y, tmap_z = tab.tmap_x, tab.tmap_y, tab.tmap_z
    fuel_x, fuel_y, fuel_z = tab.fuel_x, tab.fuel_y, tab.fuel_z
    for i in range(w_wheel.shape[0]):
        p = operating_point(
            w_wheel[i], t_wheel[i], gear[i], ratios, effs, d.fd_ratio, d.fd_efficiency, d.idle_radps,
            d.fuel_cut_radps, d.redline_radps, d.stop_start, d.use_fuel_map, d.lhv_jpkg, d.torque_scale,
            d.aux_power_w, d.alternator_efficiency, tmax_x, tmax_y, tct_x, tct_y, tmap_x, tmap_y, tmap_z,
            fuel_x, fuel_y, fuel_z,
        )  # fmt: skip
        (mech[0, i], mech[1, i], mech[2, i], mech[3, i], mech[4, i], mech[5, i], mech[6, i], mech[7, i],
         mech[8, i], mech[9, i], mech[10, i], mech[11, i], mech[12, i], mech[13, i], mech[14, i],
         mech[15, i], mech[16, i], mech[17, i]) = p  # fmt: skip
        if want_details:
            (details[0, i], details[1, i], details[2, i], details[3, i], details[4, i], details[5, i],
             details[6, i], details[7, i], details[8, i], details[9, i], details[10, i],
             details[11, i]) = point_details(
                p[0], p[1], p[2], p[3], p[6], p[5], p[7], p[8], p[9], p[10], p[11], p[12], p[16]
            )  # fmt: skip


@njit(cache=True)
def _losses_many(w_wheel, mech, fd_ratio, fd_eff, lhv, p_aux, out):
    """:func:`point_losses` over the columns of ``mech`` (:data:`MECH` rows) -> ``out`` rows."""
    for i in range(w_wheel.shape[0]):
        q = point_losses(
            w_wheel[i], mech[1, i], mech[2, i], mech[3, i], mech[4, i], mech[5, i], mech[6, i],
            mech[7, i] > 0.0, mech[11, i], mech[12, i], mech[17, i], fd_ratio, fd_eff, lhv, p_aux,
        )  # fmt: skip
        for j in range(len(q)):
            out[j, i] = q[j]


_INT_MECH = ("gi",)
_BOOL_MECH = ("on", "slipping", "traction", "cut", "over_speed", "over_torque", "bad")


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
    """(wheel demand, gear) -> operating points, fuel [kg over ``dt_s``], limits (broadcast
    :func:`operating_point`).

    ``soc``, ``regen_ok`` and ``battery_state`` are accepted for the common signature (no
    battery: the SOC change is 0). Returns a :class:`~hevsim.optimal._hev_common.Stage` with
    ``mech`` (:data:`MECH` arrays, plus ``w_wheel``) and, with ``detail``, ``details``
    (:data:`DETAILS`).
    """
    from hevsim.components.flow import Stage

    arrays = np.broadcast_arrays(
        *(np.asarray(a, np.float64) for a in (wheel_speed_radps, wheel_torque_nm, gear, dt_s))
    )
    shape = arrays[0].shape
    w, t, g, dt = (np.ascontiguousarray(a.ravel()) for a in arrays)
    mech_rows = np.empty((len(MECH), w.size))
    det_rows = np.empty((len(DETAILS), w.size if detail else 0))
    _points_many(
        w, t, g, veh.gear_ratios, veh.gear_efficiencies, veh.driveline_data(), veh.engine.kernel_tables(),
        mech_rows, det_rows, detail,
    )  # fmt: skip
    mech: dict[str, np.ndarray] = {}
    for name, row in zip(MECH, mech_rows, strict=True):
        a = row.reshape(shape)
        mech[name] = a.astype(np.int64) if name in _INT_MECH else (a > 0.0) if name in _BOOL_MECH else a
    mech["w_wheel"] = w.reshape(shape)
    st = Stage(
        d_soc=np.zeros(shape), cost_kg=mech["fuel"] * dt.reshape(shape), infeasible=mech["bad"],
        flags={"engine_speed": mech["over_speed"], "engine_torque": mech["over_torque"]},
    )  # fmt: skip
    st.mech = mech
    if detail:
        st.details = {name: row.reshape(shape) for name, row in zip(DETAILS, det_rows, strict=True)}
    return st


def loss_powers(
    veh: ConventionalVehicle, stage: Any, wheel_speed_radps: Any, wheel_torque_nm: Any
) -> dict[str, Any]:
    """Power [W] of every energy-audit term (:data:`LOSSES`) of a :func:`power_flow` result
    (broadcast :func:`point_losses`)."""
    m = stage.mech
    shape = np.shape(m["fuel"])
    rows = np.vstack([np.asarray(m[name], np.float64).ravel() for name in MECH])
    w = np.ascontiguousarray(np.broadcast_to(np.asarray(wheel_speed_radps, np.float64), shape).ravel())
    out = np.empty((len(LOSSES), w.size))
    d = veh.driveline_data()
    _losses_many(w, rows, d.fd_ratio, d.fd_efficiency, d.lhv_jpkg, d.aux_power_w, out)
    return {name: row.reshape(shape) for name, row in zip(LOSSES, out, strict=True)}


def power_mode(details: dict[str, float], wheel_force_n: float, v_mid_mps: float) -> int:
    """Index in :data:`MODES` of one step's operating point (:func:`power_mode_code`)."""
    return int(
        power_mode_code(
            details["engine_on"],
            details["clutch_slipping"],
            details["clutch_closed"],
            details.get("fuel_cut", 0.0),
            v_mid_mps,
        )
    )


def capability_controls(veh: ConventionalVehicle) -> tuple[np.ndarray, ...]:
    """Candidate controls that span the powertrain's capability: every gear."""
    return (np.arange(1, len(veh.gears) + 1, dtype=np.float64),)

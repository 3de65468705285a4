"""Compiled forward runs of the parallel (P2/P3) and power-split HEVs (issue 11).

One numba loop reproduces the Python reference loop of :mod:`hevsim.sim.forward` (driver with
the bisection on the end speed when the powertrain cannot follow, supervisory controller,
power flow, energy audit) step for step, for the controllers ``electric_assist`` (parallel),
``power_follower`` (power split), ``ecms`` and ``aecms`` (both). Nothing physical is written
here: every operating point is the architecture's scalar kernel
(:func:`hevsim.architectures.parallel.mechanical_point`,
:func:`hevsim.architectures.power_split.mechanical_point`, their ``losses_point``,
``details_point`` and ``power_mode_point``), the shared bus balance
(:func:`hevsim.components.bus.machine_request`, :func:`~hevsim.components.bus.bus_balance`),
the pack's kernels and the road load of :mod:`hevsim.components.body`. The controllers'
rules are those of :mod:`hevsim.control.parallel`, whose objects hand over their parameters
and candidate grids (:func:`controller_code`).

The compiled loops allocate nothing and run without numba's reference counting (``_nrt=False``):
passing the component tables (tuples of arrays) into the per-point kernels otherwise costs
about 100 ns of reference-count traffic per candidate, more than the physics.

Data cross the numba boundary as named tuples (:class:`HEVConstants`,
:class:`ControllerConstants`, the architectures' ``kernel_tables`` and the components'
tables), unpacked by name.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from hevsim.architectures import parallel as P
from hevsim.architectures import power_split as PS
from hevsim.architectures._common import NO_REFCOUNT
from hevsim.battery.vehicle import vehicle_bus_begin, vehicle_bus_finish_power
from hevsim.components.battery import pack_ocv_r, soc_rate
from hevsim.components.body import road_load_force
from hevsim.components.bus import battery_power_limits, bus_balance, machine_request
from hevsim.components.driveline import gear_input_torque
from hevsim.components.flow import LIMIT_RTOL
from hevsim.control.parallel import HOLD_EQUIVALENCE_FACTOR, PowerFollower, specific_fuel
from hevsim.control.simple import shift_gear
from hevsim.sim import kernel as K
from hevsim.sim._compiled_common import add_road_audit, track_step, write_summary
from hevsim.sim._records import BISECTION_STEPS, REGEN_CURRENT_RTOL, BatchRecord, ForwardRecord

ELECTRIC_ASSIST, ECMS, AECMS, POWER_FOLLOWER = 0, 1, 2, 3
"""Controller codes of the compiled loop (:func:`controller_code`)."""
BASE_COLUMNS = (
    "speed_desired_mps",
    "speed_mps",
    "accel_mps2",
    "wheel_force_n",
    "wheel_power_w",
    "road_load_force_n",
    "fuel_kg",
    "soc",
)
"""First channels of a :class:`~hevsim.sim.forward.ForwardRecord`, in order."""
TAIL_COLUMNS = ("power_mode", "traction_limited", "clutch_closed", "battery_ocv_v", "battery_voltage_v")
"""Last channels, after the architecture's details."""
AUDIT_BASE = ("fuel", "genset_source", "battery_chemical", "aero", "rolling", "grade", "kinetic_vehicle")
"""Audit terms the reference loop starts with (then the loss terms, then ``battery_loss``)."""
PS_POWER_BAND, PS_POWER_BAND_MIN_W = PowerFollower.POWER_BAND, PowerFollower.POWER_BAND_MIN_W
"""The power follower's band around its target engine power [-], [W]."""
AUX_RTOL = 1e-6
"""Relative round-off [-] of the battery power accepted as "the auxiliaries only" at the SOC
floor (the bus balance returns the auxiliary load to a few ulps)."""
P_AUX = P.LOSS_TERMS.index("aux")
"""The parallel HEV's audit term of the bus's other load (its losses take it from the tables)."""
ERR_NONE, ERR_STUCK = 0, 1
"""Status codes of the compiled loop: fine; no feasible control even when stopping."""

ARCHITECTURES = ("parallel", "power_split")
"""The architectures this compiled loop runs (:func:`hevsim.sim.forward.compiled_loop`)."""


class HEVConstants(NamedTuple):
    """Body, wheel, traction machine, pack and run constants of a compiled run (SI): the
    machine's kind code, constant efficiency and torque scale; the pack's cells in series and
    parallel, wiring resistance [ohm], temperature [K], current limits [A], coulombic
    efficiency, capacity [A·s]; the SOC window; the other bus load [W]; the body's mass [kg],
    rotating-mass factor, drag coefficient, frontal area [m²], air density [kg/m³], headwind
    [m/s], rolling coefficient; the tire radius [m]; the fuel's LHV [J/kg]."""

    motor_kind: int
    motor_efficiency: float
    motor_torque_scale: float
    n_series: float
    n_parallel: float
    r_extra_ohm: float
    temperature_k: float
    i_discharge_max_a: float
    i_charge_max_a: float
    coulombic_efficiency: float
    capacity_as: float
    soc_min: float
    soc_max: float
    aux_power_w: float
    mass_kg: float
    mass_factor: float
    drag_coefficient: float
    frontal_area_m2: float
    air_density_kgpm3: float
    headwind_mps: float
    rolling_resistance: float
    rolling_resistance_speed_s_per_m: float
    radius_m: float
    lhv_jpkg: float


class ControllerConstants(NamedTuple):
    """A controller's parameters (unused ones 0): code, equivalence factor and the A-ECMS PI
    gains and kinetic-energy term, the rule-based SOC band, EV speed [m/s] and power [W],
    charging power [W], shift speeds [rad/s], the plug-in hybrid's charge-depleting SOC [-],
    EV power [W] and equivalence factor [-] (``cd_soc`` inf: never depleting), and whether the
    electric assist's engine torque rises with its throttle grid
    (:func:`~hevsim.architectures.parallel.torque_rises_with_throttle`;
    :func:`_assist_throttle` then bisects)."""

    code: int
    s0: float
    kp: float
    ki: float
    kin: float
    soc_low: float
    soc_high: float
    ev_speed_mps: float
    ev_power_w: float
    charge_power_w: float
    engine_min_power_w: float
    engine_on_speed_mps: float
    w_up_radps: float
    w_down_radps: float
    thr_monotone: bool
    cd_soc: float
    cd_ev_power_w: float
    cd_s: float


def controller_code(ctl: Any) -> ControllerConstants | None:
    """The :class:`ControllerConstants` of a controller object of :mod:`hevsim.control.parallel`,
    or None when it has no compiled form (e.g. a control schedule)."""
    from hevsim.control import parallel as C

    code = {
        C.ElectricAssist: ELECTRIC_ASSIST,
        C.ECMS: ECMS,
        C.AdaptiveECMS: AECMS,
        C.PowerFollower: POWER_FOLLOWER,
    }.get(type(ctl))
    if code is None:
        return None
    g = lambda name: float(getattr(ctl, name, 0.0))  # noqa: E731
    return ControllerConstants(
        code=code,
        s0=g("s0") if code == AECMS else g("s"),
        kp=g("kp"),
        ki=g("ki"),
        kin=g("kin"),
        soc_low=g("soc_low"),
        soc_high=g("soc_high"),
        ev_speed_mps=g("ev_speed"),
        ev_power_w=g("ev_power"),
        charge_power_w=g("charge_power"),
        engine_min_power_w=g("engine_min_power"),
        engine_on_speed_mps=float(getattr(ctl, "engine_on_speed", 1000.0)),
        w_up_radps=g("w_up"),
        w_down_radps=g("w_down"),
        thr_monotone=code == ELECTRIC_ASSIST and P.torque_rises_with_throttle(ctl.hev, ctl.thr_grid),
        cd_soc=float(ctl.cd_soc),
        cd_ev_power_w=float(ctl.cd_ev_power),
        cd_s=float(ctl.cd_s),
    )


def constants(model: Any, soc_min: float, soc_max: float) -> HEVConstants:
    """The :class:`HEVConstants` of a parallel or power-split model."""
    m, b, body = model.motor, model.battery, model.body
    return HEVConstants(
        motor_kind=int(m.kind_code),
        motor_efficiency=float(m.efficiency),
        motor_torque_scale=float(m.torque_scale),
        n_series=float(b.n_series),
        n_parallel=float(b.n_parallel),
        r_extra_ohm=float(b.r_extra_ohm),
        temperature_k=float(b.temperature_k),
        i_discharge_max_a=float(b.max_discharge_current_a),
        i_charge_max_a=float(b.max_charge_current_a),
        coulombic_efficiency=float(b.coulombic_efficiency),
        capacity_as=3600.0 * b.capacity_ah,
        soc_min=float(soc_min),
        soc_max=float(soc_max),
        aux_power_w=float(getattr(model, "aux_power_w", 0.0)),
        mass_kg=float(body.mass_kg),
        mass_factor=float(body.mass_factor),
        drag_coefficient=float(body.drag_coefficient),
        frontal_area_m2=float(body.frontal_area_m2),
        air_density_kgpm3=float(body.air_density_kgpm3),
        headwind_mps=float(body.headwind_mps),
        rolling_resistance=float(body.rolling_resistance),
        rolling_resistance_speed_s_per_m=float(body.rolling_resistance_speed_s_per_m),
        radius_m=float(model.tire.radius_m),
        lhv_jpkg=float(model.engine.fuel_lhv_jpkg),
    )


# ------------------------------------------------------------------------- one point
@njit(cache=True, inline="always", error_model="numpy")
def _electric(t_req, w_em, p_other, regen_ok, soc, dt, ocv, r_dis, r_chg, p_chg, h, mtab):
    """The bus balance of one point and the forward driver's feasibility (as
    :meth:`hevsim.sim.forward.Step.evaluate`). Returns (infeasible by a bus limit other than
    the charge current, infeasible, machine torque [N·m], electrical power [W], battery power
    [W], current [A], SOC change [-])."""
    kind, eff, scale = h.motor_kind, h.motor_efficiency, h.motor_torque_scale
    t0, p0, over_t = machine_request(
        t_req,
        w_em,
        regen_ok,
        kind,
        eff,
        scale,
        mtab.lim_x,
        mtab.lim_mot,
        mtab.lim_gen,
        mtab.eff_x,
        mtab.eff_y,
        mtab.eff_z,
    )
    t, p_el, p_bat, cur, over_p = bus_balance(
        t0, p0, w_em, p_other, ocv, r_dis, r_chg, p_chg, kind, eff, scale, mtab
    )
    dis = cur > h.i_discharge_max_a * (1.0 + LIMIT_RTOL)
    chg = cur < -h.i_charge_max_a * (1.0 + LIMIT_RTOL)
    d_soc = soc_rate(cur, h.coulombic_efficiency, h.capacity_as) * dt
    return over_t or over_p or dis, over_t or over_p or dis or chg, t, p_el, p_bat, cur, d_soc


@njit(cache=True, inline="always", error_model="numpy")
def _feasible(infeasible, others, cur, t_em, p_bat, p_el, soc, h):
    """The forward driver's feasibility of a point (as :meth:`hevsim.sim.forward.Step.evaluate`;
    see :data:`hevsim.sim.forward.REGEN_CURRENT_RTOL`)."""
    ok = not infeasible
    if not others and cur >= -h.i_charge_max_a * (1.0 + REGEN_CURRENT_RTOL) and t_em < 0.0:
        ok = True
    if soc <= h.soc_min:  # empty: no discharge for traction (the auxiliaries are still supplied)
        ok = ok and p_bat <= h.aux_power_w * (1.0 + AUX_RTOL)
    if soc >= h.soc_max:  # full: no charging, up to the regeneration limiter's round-off
        ok = ok and p_bat >= -REGEN_CURRENT_RTOL * abs(p_el)
    return ok


@njit(cache=True, inline="always", error_model="numpy")
def _point_body(dpar, dps, c0, c1, eng, w_wheel, t_wheel, regen_ok, soc, dt, bat, md, want, det, loss):
    """The power flow of one candidate control (``c0``, ``c1``) at one step: (feasible, fuel
    [kg] over the step, SOC change [-], engine power [W]). ``dpar``, ``dps``: the parallel
    or the power-split tables, the other None (the architecture: numba compiles the one
    given, see :func:`run_hev`); ``eng``: the power split's
    :func:`~hevsim.architectures.power_split.engine_point` of the control (:func:`_engine`;
    unused by the parallel HEV); ``bat``: :func:`_battery` at ``soc``; ``md``:
    (:class:`HEVConstants`, engine, motor and generator tables). With ``want``, fills the
    architecture's details (``det``) and audit terms (``loss``, [W]); without, a control
    infeasible by its engine or machine speeds (or MG1's torque) is not taken to the bus
    (SOC change 0: callers read only its infeasibility)."""
    ocv, r_dis, r_chg, p_chg = bat
    h, etab, mtab, gtab = md
    if dpar is not None:
        gi, on, es, ms, bad, w_fd, w_e, t_e, t_e_fd, t_fd, fuel, w_em, t_req = P.mechanical_point(
            w_wheel, t_wheel, c0, c1, False, dpar, etab
        )
        if not want and (es or ms):  # infeasible whatever the bus gives (see _feasible)
            return False, fuel * dt, 0.0, t_e * (w_e if on else 0.0)
        oth, inf, t, p_el, p_bat, cur, d_soc = _electric(
            t_req, w_em, h.aux_power_w, regen_ok, soc, dt, ocv, r_dis, r_chg, p_chg, h, mtab
        )
        ok = _feasible(inf or bad, oth or es or ms, cur, t, p_bat, p_el, soc, h)
        if want:
            lo = P.losses_point(w_wheel, gi, on, w_fd, w_e, t_e, t_e_fd, t_fd, fuel, w_em, t, p_el, dpar)
            for j in range(len(lo)):
                loss[j] = lo[j]
            P.details_point(gi, on, w_e, t_e, c1, fuel, w_em, t, p_el, cur, p_bat, lo[5], dpar.p2, det)
        return ok, fuel * dt, d_soc, t_e * (w_e if on else 0.0)
    if dps is not None:
        on, es, gt, gs, ms, bad, w_r, t_r, w_e, t_e, fuel, w_s, t_g, p_g, t_er, w_em, t_req = PS.drive_point(
            w_wheel, t_wheel, c0, 0.0, False, eng, dps, gtab
        )
        if not want and (es or gt or gs or ms):  # infeasible whatever the bus gives (see _feasible)
            return False, fuel * dt, 0.0, t_e * w_e
        oth, inf, t, p_el, p_bat, cur, d_soc = _electric(
            t_req, w_em, p_g + h.aux_power_w, regen_ok, soc, dt, ocv, r_dis, r_chg, p_chg, h, mtab
        )
        ok = _feasible(inf or bad, oth or es or gt or gs or ms, cur, t, p_bat, p_el, soc, h)
        if want:
            lo = PS.losses_point(
                w_wheel, w_r, t_r, w_e, t_e, fuel, w_s, t_g, p_g, t_er, w_em, t, p_el, h.aux_power_w, dps
            )
            for j in range(len(lo)):
                loss[j] = lo[j]
            PS.details_point(
                on, w_e, t_e, c1, fuel, w_s, t_g, p_g, w_em, t, p_el, w_r, cur, p_bat, lo[5], det
            )
        return ok, fuel * dt, d_soc, t_e * w_e
    return False, 0.0, 0.0, 0.0  # no architecture's tables (run_hev always gives one)


@njit(cache=True, error_model="numpy", **NO_REFCOUNT)
def _point(dpar, dps, c0, c1, eng, w_wheel, t_wheel, regen_ok, soc, dt, bat, md, want, det, loss):
    """:func:`_point_body` compiled once, for one point with its details (``want``); the
    loops over candidates inline it once (:func:`_scan`): a call per candidate, with every
    table passed, costs more than the point."""
    return _point_body(dpar, dps, c0, c1, eng, w_wheel, t_wheel, regen_ok, soc, dt, bat, md, want, det, loss)


NO_ENGINE = (False, False, False, 0.0, 0.0, 0.0)
"""The ``eng`` argument of :func:`_point` for the parallel HEV (unused)."""


@njit(cache=True, inline="always")
def _engine(eng_flags, eng_floats, i):
    """Candidate ``i``'s :func:`~hevsim.architectures.power_split.engine_point`, as
    :func:`engine_cache` stored it."""
    return (eng_flags[0, i], eng_flags[1, i], eng_flags[2, i], eng_floats[0, i], eng_floats[1, i],
            eng_floats[2, i])  # fmt: skip


@njit(cache=True)
def engine_cache(cand0, cand1, dps, etab, eng_flags, eng_floats):
    """Store every candidate's :func:`~hevsim.architectures.power_split.engine_point` in
    ``eng_flags`` (3, n) and ``eng_floats`` (3, n) (it does not depend on the step: computed
    once per run instead of once per step and candidate)."""
    for i in range(cand0.shape[0]):
        r = PS.engine_point(cand0[i], cand1[i], dps, etab)
        eng_flags[0, i], eng_flags[1, i], eng_flags[2, i] = r[0], r[1], r[2]
        eng_floats[0, i], eng_floats[1, i], eng_floats[2, i] = r[3], r[4], r[5]


# ------------------------------------------------------------------------- controllers
@njit(cache=True, inline="always", error_model="numpy")
def _argmin(cost, feasible, n):
    """:func:`hevsim.control.parallel._argmin_feasible` (-1 for None): the first minimum of the
    cost with the infeasible ones at inf (NaN wins, as numpy's argmin)."""
    any_ok = False
    for i in range(n):
        any_ok = any_ok or feasible[i]
    if not any_ok:
        return -1
    best, bv = 0, cost[0] if feasible[0] else np.inf
    for i in range(1, n):
        if np.isnan(bv):
            break
        c = cost[i] if feasible[i] else np.inf
        if np.isnan(c) or c < bv:
            best, bv = i, c
    return best


SCAN_ALL, SCAN_EV, SCAN_NEAR = 0, 1, 2
"""Modes of :func:`_scan`, passed as ``np.int64(mode)``: numba compiles a function once per
literal constant argument, a run-time integer once for all."""


@njit(cache=True, error_model="numpy", **NO_REFCOUNT)
def _scan(dpar, dps, mode, target, band, cands, w_wheel, t_wheel, regen_ok, soc, dt, bat, md, buf):
    """:func:`_point_body` (no details) of the candidates ``cands`` at one step, the power
    split's engine points from ``buf[8:10]`` (:func:`engine_cache`). ``SCAN_ALL``: every
    candidate's feasibility, fuel [kg], engine power [W] and SOC change [-] into
    ``buf[3]``, ``buf[1]``, ``buf[2]``, ``buf[0]``; returns -1. ``SCAN_EV``: the first
    feasible candidate with the engine off (second control 0); ``SCAN_NEAR``: in the order
    ``buf[5]``, the first feasible one with the engine on whose engine power ``buf[4]`` [W]
    lies within ``band`` of ``target`` [W]; their index, -1 for none."""
    cand0, cand1, _ = cands
    d_soc, fuel, p_eng, feas, p_cand, order, det, loss, e_flags, e_floats = buf
    n = cand0.shape[0]
    for k in range(n):
        i = order[k] if mode == SCAN_NEAR else k
        if mode == SCAN_EV and cand1[i] != 0.0:
            continue
        if mode == SCAN_NEAR and (cand1[i] == 0.0 or abs(p_cand[i] - target) > band):
            continue
        eng = _engine(e_flags, e_floats, i)
        c0, c1 = cand0[i], cand1[i]
        r = _point_body(
            dpar, dps, c0, c1, eng, w_wheel, t_wheel, regen_ok, soc, dt, bat, md, False, det, loss
        )
        if mode == SCAN_ALL:
            feas[i], fuel[i], d_soc[i], p_eng[i] = r
        elif r[0]:
            return i
    return -1


@njit(cache=True, error_model="numpy", **NO_REFCOUNT)
def _assist_point(w_wheel, gear, throttle, dpar, etab):
    """(``bad``, engine torque [N·m]) of :func:`~hevsim.architectures.parallel.mechanical_point`
    at no wheel torque (compiled once, called by :func:`_assist_throttle`)."""
    r = P.mechanical_point(w_wheel, 0.0, gear, throttle, False, dpar, etab)
    return r[4], r[7]


@njit(cache=True, inline="always", error_model="numpy")
def _assist_throttle(w_wheel, g, t_req, thr_grid, monotone, dpar, etab):
    """The electric assist's throttle in gear ``g`` (as
    :meth:`hevsim.control.parallel.ElectricAssist.choose`): of the engine points not
    ``bad``, the first of ``thr_grid`` whose torque reaches ``t_req`` [N·m], else the one of
    the largest torque; 0 when every point is ``bad``. ``monotone``
    (:attr:`ControllerConstants.thr_monotone`): the engine torque does not fall as the
    throttle rises along the grid, so a bisection on the torque alone skips the throttles
    below the answer, and the last throttle is the answer when none reaches ``t_req`` and
    its torque is strictly the largest; an engine speed outside the running window makes
    every throttle ``bad``. The scan of every throttle decides the other cases."""
    n = thr_grid.shape[0]
    gf = float(g)
    if monotone and n >= 2:
        w_fd = P.final_drive_point(w_wheel, 0.0, dpar)[0]
        w_e = w_fd * dpar.gear_ratio[g - 1]  # as P.driveline_point
        if thr_grid[0] > 0.0 and not P.engine_torque_point(w_e, thr_grid[0], dpar, etab)[1]:
            return 0.0  # every throttle fires the engine outside its running window: all bad
        lo, hi = 0, n
        while lo < hi:  # the first throttle whose torque reaches t_req
            mid = (lo + hi) // 2
            if P.engine_torque_point(w_e, thr_grid[mid], dpar, etab)[3] >= t_req:
                hi = mid
            else:
                lo = mid + 1
        for i in range(lo, n):  # from there, the first point not bad
            if not _assist_point(w_wheel, gf, thr_grid[i], dpar, etab)[0]:
                return thr_grid[i]
        if lo == n:  # none reaches t_req: the last throttle, if not bad and strictly the largest
            bad, t_last = _assist_point(w_wheel, gf, thr_grid[n - 1], dpar, etab)
            if not bad and t_last > P.engine_torque_point(w_e, thr_grid[n - 2], dpar, etab)[3]:
                return thr_grid[n - 1]
    first_above, i_max, t_max, any_ok = -1, -1, -np.inf, False
    for i in range(n):
        bad, te = _assist_point(w_wheel, gf, thr_grid[i], dpar, etab)
        te = te if not bad else -np.inf
        any_ok = any_ok or not bad
        if te >= t_req:  # the first throttle that gives the torque (the rest cannot change it)
            first_above = i
            break
        if i_max < 0 or te > t_max:
            i_max, t_max = i, te
    if any_ok:
        return thr_grid[first_above if first_above >= 0 else i_max]
    return 0.0


@njit(cache=True, error_model="numpy", **NO_REFCOUNT)
def _choose(dpar, dps, cc, state, cands, w_wheel, t_wheel, v_mid, soc, dt, e_soc, bat, md, buf):
    """The controller's choice at one step (:mod:`hevsim.control.parallel`): (found, c0, c1,
    filled, fuel [kg], SOC change [-]); ``filled``: the choice's details, audit terms
    (``buf[6]``, ``buf[7]``), fuel and SOC change are those of :func:`_point` with ``want``
    (else not computed). ``dpar``, ``dps``: as :func:`_point`. ``state``: [gear of the
    shift schedule, equivalence factor s, SOC integral, SOC reference] (updated as the
    controller objects update themselves); ``cands``: (first and second control of every
    candidate, the electric assist's throttle grid); ``buf``: work arrays."""
    cand0, cand1, thr_grid = cands
    h, etab, _, _ = md
    cost, fuel, p_eng, feas = buf[:4]
    det, loss = buf[6], buf[7]
    regen_ok = v_mid > 0.0
    n = cand0.shape[0]
    p_dem = t_wheel * w_wheel
    depl = soc > cc.cd_soc  # a plug-in hybrid's charge depleting (_GridController.depleting)
    if depl:
        low_load = p_dem < cc.cd_ev_power_w
        frac = 0.0
    else:
        low_load = v_mid < cc.ev_speed_mps and p_dem < cc.ev_power_w
        frac = min(max((cc.soc_high - soc) / (cc.soc_high - cc.soc_low), 0.0), 1.0)  # charge_fraction
    p_charge = frac * cc.charge_power_w + (h.aux_power_w if soc < cc.soc_low else 0.0)  # charging_power
    s = 0.0
    if cc.code == ELECTRIC_ASSIST:
        if dpar is not None:
            w_fd = w_wheel * dpar.final_drive_ratio
            g = shift_gear(int(state[0]), w_fd, dpar.gear_ratio, cc.w_up_radps, cc.w_down_radps)
            state[0] = g
            forced = v_mid > cc.engine_on_speed_mps
            if depl:
                ev = not forced and (p_dem <= 0.0 or low_load)
            else:
                ev = not forced and (p_dem <= 0.0 or soc > cc.soc_high or (soc > cc.soc_low and low_load))
            c0, c1 = float(g), 0.0
            if not ev:
                w_e = w_fd * dpar.gear_ratio[g - 1]
                t_fd = gear_input_torque(t_wheel, dpar.final_drive_ratio, dpar.final_drive_efficiency)
                t_req = gear_input_torque(t_fd, dpar.gear_ratio[g - 1], dpar.gear_efficiency[g - 1]) + (
                    p_charge / w_e if w_e > 0 else 0.0
                )
                if soc < cc.soc_high and w_e > 0:
                    t_req = max(t_req, cc.engine_min_power_w / w_e)
                c1 = _assist_throttle(w_wheel, g, t_req, thr_grid, cc.thr_monotone, dpar, etab)
            if soc < cc.soc_low and h.aux_power_w > 0.0:  # ElectricAssist.holds: charge-hold
                s = HOLD_EQUIVALENCE_FACTOR
            else:
                ok, fuel_kg, d_soc, _ = _point(dpar, dps, c0, c1, NO_ENGINE, w_wheel, t_wheel, regen_ok, soc,
                                               dt, bat, md, True, det, loss)  # fmt: skip
                if ok:
                    return True, c0, c1, True, fuel_kg, d_soc
    elif cc.code == AECMS:
        if depl:
            s = cc.cd_s
        else:
            err = state[3] - cc.kin * v_mid**2 / e_soc - soc
            s = max(0.0, cc.s0 + cc.kp * err + cc.ki * state[2])
        state[1] = s
    elif cc.code == ECMS:
        s = cc.cd_s if depl else cc.s0
    elif (
        p_dem <= 0.0
        or (depl and low_load)
        or (not depl and soc > cc.soc_low and low_load)
        or (not depl and soc > cc.soc_high and p_dem < cc.engine_min_power_w)
    ):  # power follower (PowerFollower.electric): the first feasible EV candidate
        i = _scan(
            dpar, dps, np.int64(SCAN_EV), 0.0, 0.0, cands, w_wheel, t_wheel, regen_ok, soc, dt, bat, md, buf
        )
        if i >= 0:
            return True, cand0[i], cand1[i], False, 0.0, 0.0
    if cc.code == POWER_FOLLOWER:
        # The least fuel per unit of engine work of the feasible candidates whose engine power
        # (known per run: p_cand) is near the target: candidates in the order of their specific
        # fuel (``order``, ties by index; per run, as it depends on the engine alone), the first
        # near and feasible one is it (the argmin over all, as the Python controller takes it).
        # The rest only when none is feasible.
        target = max(p_dem, 0.0) + p_charge
        if soc < cc.soc_high and not depl:  # PowerFollower.target_power
            target = max(target, cc.engine_min_power_w)
        band = max(PS_POWER_BAND * target, PS_POWER_BAND_MIN_W)
        i = _scan(
            dpar,
            dps,
            np.int64(SCAN_NEAR),
            target,
            band,
            cands,
            w_wheel,
            t_wheel,
            regen_ok,
            soc,
            dt,
            bat,
            md,
            buf,
        )
        if i >= 0:
            return True, cand0[i], cand1[i], False, 0.0, 0.0
        _scan(
            dpar, dps, np.int64(SCAN_ALL), 0.0, 0.0, cands, w_wheel, t_wheel, regen_ok, soc, dt, bat, md, buf
        )
        for i in range(n):
            cost[i] = abs(p_eng[i] - target)
        i = _argmin(cost, feas, n)
    else:
        _scan(
            dpar, dps, np.int64(SCAN_ALL), 0.0, 0.0, cands, w_wheel, t_wheel, regen_ok, soc, dt, bat, md, buf
        )
        for i in range(n):  # every candidate: ECMS score from its fuel and SOC change (in cost)
            cost[i] = fuel[i] / dt * h.lhv_jpkg + s * (-cost[i] / dt * e_soc)
        i = _argmin(cost, feas, n)
    if i < 0:
        return False, 0.0, 0.0, False, 0.0, 0.0
    return True, cand0[i], cand1[i], False, 0.0, 0.0


@njit(cache=True, inline="always", error_model="numpy")
def _battery(soc, h, ptab):
    """(OCV [V], discharge and charge resistance [ohm], largest charge power [W]) at ``soc``
    (the forward loop's battery state: no charging when full)."""
    ocv, r_dis = pack_ocv_r(soc, h.temperature_k, 1.0, h.n_series, h.n_parallel, h.r_extra_ohm, ptab)
    _, r_chg = pack_ocv_r(soc, h.temperature_k, -1.0, h.n_series, h.n_parallel, h.r_extra_ohm, ptab)
    p_chg = battery_power_limits(ocv, r_dis, ocv, r_chg, h.i_discharge_max_a, h.i_charge_max_a)[1]
    if soc >= h.soc_max:  # full: no charging (regeneration goes to the friction brakes)
        p_chg = 0.0
    return ocv, r_dis, r_chg, p_chg


@njit(cache=True, inline="always")
def _step_constants(h, i_dis, i_chg, aux_w):
    """``h`` with the battery's current limits [A] and the bus's other load [W] of one step
    (a pack's BMS limits and cooling load, :func:`battery_begin`)."""
    return HEVConstants(
        h.motor_kind, h.motor_efficiency, h.motor_torque_scale, h.n_series, h.n_parallel, h.r_extra_ohm,
        h.temperature_k, i_dis, i_chg, h.coulombic_efficiency, h.capacity_as, h.soc_min, h.soc_max, aux_w,
        h.mass_kg, h.mass_factor, h.drag_coefficient, h.frontal_area_m2, h.air_density_kgpm3, h.headwind_mps,
        h.rolling_resistance, h.rolling_resistance_speed_s_per_m, h.radius_m, h.lhv_jpkg,
    )  # fmt: skip


@njit(cache=True, inline="always", error_model="numpy")
def battery_begin(soc, h, ptab, pk):
    """The battery model's start of a step in every compiled forward loop: (the bus's battery
    state ``(OCV [V], discharge and charge resistance [ohm], largest charge power [W])``,
    the run constants for the step). ``pk`` None: the pack tables ``ptab`` at the vehicle's
    ``soc`` [-] (:func:`_battery`) and ``h`` as it is. ``pk`` a pack's
    :class:`~hevsim.battery.pack_run.PackArrays` (``[battery] model = "pack"``): the pack's
    compiled step begins (:func:`~hevsim.battery.pack_run.pack_begin`: BMS limits, Thevenin
    pairs, cooling decision) and :func:`~hevsim.battery.pack_run.pack_bus_state` gives the
    state, the current limits and the cooling load on the bus (in ``h``), as the Python loop's
    :meth:`hevsim.battery.bms.PackRun.vehicle_step`. ``pk`` a ``[battery] model = "cell"``
    battery's :data:`~hevsim.battery.vehicle.CellBusTables`: the pack's step pairs of its
    representative cell (:func:`~hevsim.battery.vehicle.cell_bus_state`), the limits and load of
    ``h``, as :meth:`hevsim.battery.cell_run.CellRun.vehicle_step`. Both through
    :func:`~hevsim.battery.vehicle.vehicle_bus_begin`."""
    if pk is None:
        return _battery(soc, h, ptab), h
    ocv, r_dis, r_chg, p_chg, i_dis, i_chg, aux_w = vehicle_bus_begin(
        pk, soc, h.soc_max, h.i_discharge_max_a, h.i_charge_max_a, h.aux_power_w, LIMIT_RTOL,
        REGEN_CURRENT_RTOL,
    )  # fmt: skip
    return (ocv, r_dis, r_chg, p_chg), _step_constants(h, i_dis, i_chg, aux_w)


@njit(cache=True, inline="always", error_model="numpy")
def battery_end(soc, d_soc, p_bat, pk):
    """The battery model's end of a step: the SOC [-] after it. ``pk`` None: ``soc + d_soc``;
    a pack: its step at the bus's terminal power ``p_bat`` [W]
    (:func:`~hevsim.battery.pack_run.pack_finish_power`: cells, module thermal model, cooling
    loop, ageing stress, records), its mean cell SOC; a cell battery: its cell's step
    (:func:`~hevsim.battery.vehicle.cell_finish_power`), its SOC."""
    if pk is None:
        return soc + d_soc
    return vehicle_bus_finish_power(pk, p_bat)


@njit(cache=True, inline="always", error_model="numpy")
def _demand(v0, v1, k, dt, gr, h):
    """(mid-step speed [m/s], acceleration [m/s²], grade [-], wheel force [N]) of a step."""
    v_mid = 0.5 * (v0 + v1)
    a = (v1 - v0) / dt
    g = 0.5 * (gr[k] + gr[k + 1])
    f = 0.0
    if v_mid > 0.0:
        f = road_load_force(
            v_mid,
            a,
            g,
            h.mass_kg,
            h.mass_factor,
            h.drag_coefficient,
            h.frontal_area_m2,
            h.air_density_kgpm3,
            h.headwind_mps,
            h.rolling_resistance,
            h.rolling_resistance_speed_s_per_m,
        )
    return v_mid, a, g, f


# ------------------------------------------------------------------------- the run
@njit(cache=True, nogil=True, error_model="numpy", **NO_REFCOUNT)
def run_hev(
    dpar,
    dps,
    cc,
    soc0,
    t,
    v_des,
    gr,
    cand0,
    cand1,
    thr_grid,
    h,
    etab,
    mtab,
    gtab,
    ptab,
    cols,
    audit,
    summary,
    state,
    buf,
    pk,
):
    """One forward run (the compiled :func:`hevsim.sim.forward._run`) of the parallel HEV
    (tables ``dpar``, ``dps`` None) or the power split (``dps``, ``dpar`` None): numba
    compiles one architecture's code per type signature (its branches on the other's None
    are pruned before typing). Fills ``cols``
    (channels x ``n + 1``: :data:`BASE_COLUMNS`, the details, :data:`TAIL_COLUMNS`),
    ``audit`` (:data:`AUDIT_BASE`, the loss terms but ``fuel`` and ``wheel``, battery loss;
    [J]) and ``summary`` (:data:`hevsim.sim.kernel.SUMMARY`). Returns (status, step index,
    final speed [m/s]). ``pk``: None, or the pack of a ``[battery] model = "pack"`` vehicle
    (:func:`battery_begin`, :func:`battery_end`)."""
    n = t.shape[0] - 1
    dt = t[1] - t[0]
    cands = (cand0, cand1, thr_grid)
    det, loss = buf[6], buf[7]
    nd = det.shape[0]
    nl = loss.shape[0]
    m_eff = h.mass_kg * h.mass_factor
    r = h.radius_m
    q_as = h.capacity_as
    state[0] = 1.0
    state[1] = cc.s0
    state[2] = 0.0
    state[3] = min(soc0, cc.cd_soc)
    v, soc, fuel = v_des[0], soc0, 0.0
    err_sq = err_max = dist = eon = starts = lim_s = 0.0
    was_on = False
    for k in range(n):
        bat, hk = battery_begin(soc, h, ptab, pk)
        md = (hk, etab, mtab, gtab)
        ocv = bat[0]
        e_soc = q_as * ocv
        v1 = v_des[k + 1]
        v_mid, a, g, f = _demand(v, v1, k, dt, gr, h)
        found, c0, c1, filled, fuel_kg, d_soc = _choose(
            dpar, dps, cc, state, cands, v_mid / r, f * r, v_mid, soc, dt, e_soc, bat, md, buf
        )
        limited = 0.0
        if not found:  # beyond the powertrain: lower the end speed until a control exists
            limited = 1.0
            lo, hi, have = 0.0, v1, False
            bv = ba = bg = bf = bc0 = bc1 = 0.0
            for _ in range(BISECTION_STEPS):
                mid = 0.5 * (lo + hi)
                tv, ta, tg, tf = _demand(v, mid, k, dt, gr, h)
                ok, x0, x1, _, _, _ = _choose(
                    dpar, dps, cc, state, cands, tv / r, tf * r, tv, soc, dt, e_soc, bat, md, buf
                )
                if not ok:
                    hi = mid
                else:
                    lo, have = mid, True
                    bv, ba, bg, bf, bc0, bc1 = tv, ta, tg, tf, x0, x1
            if not have:
                bv, ba, bg, bf = _demand(v, 0.0, k, dt, gr, h)
                ok, bc0, bc1, _, _, _ = _choose(
                    dpar, dps, cc, state, cands, bv / r, bf * r, bv, soc, dt, e_soc, bat, md, buf
                )
                if not ok and bf > 0.0 and pk is not None:  # coast to rest (forward._run, with a pack)
                    bf = 0.0
                    ok, bc0, bc1, _, _, _ = _choose(
                        dpar, dps, cc, state, cands, bv / r, bf * r, bv, soc, dt, e_soc, bat, md, buf
                    )
                if not ok:
                    return ERR_STUCK, k, v
            v_mid, a, g, f, c0, c1 = bv, ba, bg, bf, bc0, bc1
            v1 = v_mid * 2.0 - v
            filled = False
        if not filled:  # the chosen control's details and audit terms
            eng = NO_ENGINE
            if dps is not None:
                eng = PS.engine_point(c0, c1, dps, etab)
            _, fuel_kg, d_soc, _ = _point(
                dpar, dps, c0, c1, eng, v_mid / r, f * r, v_mid > 0.0, soc, dt, bat, md, True, det, loss
            )
        if pk is not None and dpar is not None:  # the bus's other load of the step (the cooling too)
            loss[P_AUX] = hk.aux_power_w
        if cc.code == AECMS and not soc > cc.cd_soc:  # update: integrate the SOC error of the step taken
            state[2] += (state[3] - cc.kin * v_mid**2 / e_soc - soc) * dt
        # ---- energy audit [J]
        audit[0] += loss[0] * dt
        for j in range(1, nl - 1):
            audit[len(AUDIT_BASE) + j - 1] += loss[j] * dt
        e_chem = -d_soc * q_as * ocv
        p_bat = det[nd - 2]
        audit[2] += e_chem
        audit[len(AUDIT_BASE) + nl - 2] += e_chem - p_bat * dt
        crr, crr_v = h.rolling_resistance, h.rolling_resistance_speed_s_per_m
        add_road_audit(audit, v, v1, v_mid, a, g, f, h.mass_kg, m_eff, crr, crr_v, dt)
        # ---- mode and bookkeeping
        i_on, mode = 0, 0.0
        if dpar is not None:
            i_on, mode = 1, P.power_mode_point(det[1], det[9], f, v_mid)
        if dps is not None:
            mode = PS.power_mode_point(det[0], det[14], f, v_mid)
        on = det[i_on] > 0.0
        if on and not was_on:
            starts += 1.0
        was_on = on
        fuel += fuel_kg
        eon += dt if on else 0.0
        err_sq, err_max, dist, lim_s = track_step(
            v_des[k] - v, v_mid, dt, limited, err_sq, err_max, dist, lim_s
        )
        row = (v_des[k], v, a, f, loss[nl - 1], f - m_eff * a, fuel, soc)
        for j in range(len(row)):
            cols[j, k] = row[j]
        for j in range(nd):
            cols[len(BASE_COLUMNS) + j, k] = det[j]
        b = len(BASE_COLUMNS) + nd
        cols[b, k] = mode
        cols[b + 1, k] = limited
        cols[b + 2, k] = det[i_on]
        cols[b + 3, k] = ocv
        i_bat = det[nd - 3]
        cols[b + 4, k] = p_bat / i_bat if i_bat != 0.0 else ocv
        v, soc = v1, battery_end(soc, d_soc, p_bat, pk)
    write_summary(summary, v_des[n] - v, err_sq, err_max, n, dist, fuel, soc, eon, starts, lim_s, t[n] - t[0])
    return ERR_NONE, n, v


# ------------------------------------------------------------------------- Python side
def writable(tab: Any) -> Any:
    """``tab`` (a named tuple of arrays and scalars) with its read-only arrays copied: a
    read-only array is another numba type, so a machine whose map arrays are read-only would
    compile :func:`run_hev` a second time (about 20 s) for the same architecture."""
    if all(a.flags.writeable for a in tab if isinstance(a, np.ndarray)):
        return tab
    return type(tab)(*(a.copy() if isinstance(a, np.ndarray) and not a.flags.writeable else a for a in tab))


def _run_one(
    model: Any, grid: Any, ctl: Any, soc0: float, soc_min: float, soc_max: float, pack: Any = None
) -> tuple[Any, ...]:
    """One compiled run: (channel names, channels (names x n + 1), audit names, audit [J],
    summary, final speed [m/s]); the controller left as the Python loop leaves it. ``pack``:
    the :class:`~hevsim.battery.bms.PackRun` of a ``[battery] model = "pack"`` vehicle
    (:func:`pack_arrays`)."""
    from hevsim.sim.checks import stuck_error

    cc = controller_code(ctl)
    assert cc is not None
    parallel = isinstance(model, P.ParallelHEV)
    mod = P if parallel else PS
    dpar, dps = None, None  # the other architecture's: None (run_hev)
    if parallel:
        dpar = writable(P.kernel_tables(model))
        gtab = writable(model.motor.kernel_tables())
    else:
        dps = writable(PS.kernel_tables(model))
        gtab = writable(model.generator.kernel_tables())
    ctl.reset(float(soc0))
    t, v_des, gr = (np.require(a, np.float64, ("C", "W")) for a in (grid.time_s, grid.speed_mps, grid.grade))
    names = (*BASE_COLUMNS, *mod.DETAILS, *TAIL_COLUMNS)
    cols = np.zeros((len(names), t.size))
    audit_names = (*AUDIT_BASE, *mod.LOSS_TERMS[1:-1], "battery_loss")
    audit = np.zeros(len(audit_names))
    summary = np.zeros(len(K.SUMMARY))
    state = np.zeros(4)
    cand0, cand1 = (np.require(c, np.float64, ("C", "W")) for c in (ctl.controls[0], ctl.controls[-1]))
    thr = np.require(getattr(ctl, "thr_grid", np.zeros(0)), np.float64, ("C", "W"))
    h = constants(model, soc_min, soc_max)
    etab, mtab, ptab = (writable(c.kernel_tables()) for c in (model.engine, model.motor, model.battery))
    nc = cand0.size
    e_flags, e_floats = np.zeros((3, nc), np.bool_), np.zeros((3, nc))
    p_cand, order = np.zeros(nc), np.arange(nc)
    if not parallel:  # each candidate's engine operating point, engine power [W], specific-fuel order
        engine_cache(cand0, cand1, dps, etab, e_flags, e_floats)
        p_cand = e_floats[1] * e_floats[0]
        fuel_kg = e_floats[2] * (t[1] - t[0])  # as _point gives it
        spec = specific_fuel(fuel_kg, p_cand)  # as the Python controller ranks them
        order = np.argsort(np.where(np.isnan(spec), -np.inf, spec), kind="stable")  # NaN first
    buf = (np.empty(nc), np.empty(nc), np.empty(nc), np.empty(nc, np.bool_), p_cand, order,
           np.zeros(len(mod.DETAILS)), np.zeros(len(mod.LOSS_TERMS)), e_flags, e_floats)  # fmt: skip
    status, k, v_end = run_hev(dpar, dps, cc, float(soc0), t, v_des, gr, cand0, cand1, thr, h, etab, mtab,
                               gtab, ptab, cols, audit, summary, state, buf,
                               pack_arrays(pack, model, t.size - 1))  # fmt: skip
    if status == ERR_STUCK:
        soc_last = cols[names.index("soc"), k - 1] if k > 0 else soc0
        raise stuck_error(model, float(t[k]), float(soc_last), soc_min)
    if cc.code == ELECTRIC_ASSIST:
        ctl.gear = int(state[0])
    elif cc.code == AECMS:
        ctl.s, ctl.integral = float(state[1]), float(state[2])
    return names, cols, audit_names, audit, summary, float(v_end)


def pack_arrays(pack: Any, model: Any, steps: int) -> Any:
    """The ``pk`` argument of the compiled loops: None without a pack; for a
    :class:`~hevsim.battery.bms.PackRun`, its pack's
    :class:`~hevsim.battery.pack_run.PackArrays` with room for ``steps`` record rows and the
    model's own auxiliary load [W] as the base the cooling adds to (as
    :meth:`~hevsim.battery.bms.PackRun.vehicle_step`)."""
    if pack is None:
        return None
    if hasattr(pack, "loop_arrays"):  # a "cell" battery (hevsim.battery.cell_run.CellRun)
        return pack.loop_arrays(float(getattr(model, "aux_power_w", 0.0)), steps)
    from hevsim.battery.pack_run import F_BASEAUX

    if pack.base_aux_w is None:
        pack.base_aux_w = float(getattr(model, "aux_power_w", 0.0))
    pack.pack.reserve(steps)
    s = pack.pack.arrays
    s.f[F_BASEAUX] = pack.base_aux_w
    return s


def simulate(
    model: Any, grid: Any, ctl: Any, *, soc_initial: float, soc_min: float, soc_max: float, pack: Any = None
) -> ForwardRecord | None:
    """The compiled forward run of a parallel or power-split ``model`` (the
    ``simulate_compiled`` hook of :mod:`hevsim.sim.forward`, same arguments and
    :class:`~hevsim.sim.forward.ForwardRecord`); None for a controller without a compiled
    form. Leaves the controller as the Python loop does (shift-schedule gear, A-ECMS factor
    and integral). ``pack``: the :class:`~hevsim.battery.bms.PackRun` of a ``[battery] model =
    "pack"`` vehicle, stepped inside the loop (:func:`battery_begin`, :func:`battery_end`)."""
    if controller_code(ctl) is None:
        return None
    names, cols, audit_names, audit, summary, v_end = _run_one(
        model, grid, ctl, soc_initial, soc_min, soc_max, pack
    )
    columns = {name: cols[j] for j, name in enumerate(names)}
    if not isinstance(model, P.ParallelHEV):  # clutch_closed is the parallel HEV's; the power split has none
        del columns["clutch_closed"]
    return ForwardRecord(columns, dict(zip(audit_names, audit.tolist(), strict=True)), summary, v_end)


MODEL_KEYS = ("body.mass_kg", "body.mass_factor", "body.drag_coefficient", "body.frontal_area_m2",
              "body.rolling_resistance", "tire.radius_m", "engine.torque_scale")  # fmt: skip
"""Configuration keys a compiled batch varies on the built model (others: the Python path)."""


def _variant(model: Any, kind: str, values: dict[str, float]) -> tuple[Any, Any] | None:
    """(model, controller) of one variant: the built ``model`` with the :data:`MODEL_KEYS` of
    ``values`` replaced and the controller ``kind`` made for it with the ``controller.*``
    values it reads; None when a key cannot be varied this way."""
    import dataclasses

    from hevsim.components.driveline import Tire
    from hevsim.control import CONTROLLERS, make_controller

    reads = CONTROLLERS[kind].parameters
    params: dict[str, float] = {}
    for key, val in values.items():
        section, _, name = key.partition(".")
        if section == "controller" and name in reads:
            params[name] = val
        elif section == "controller" and name != "kind" and not hasattr(model, name):
            continue  # a parameter this controller does not read: the Python path ignores it too
        elif key not in MODEL_KEYS and key != "simulation.soc_initial":
            return None
    changes: dict[str, Any] = {}
    body = {k.split(".")[1]: v for k, v in values.items() if k.startswith("body.")}
    if body:
        changes["body"] = dataclasses.replace(model.body, **body)
    if "tire.radius_m" in values:
        changes["tire"] = Tire(radius_m=values["tire.radius_m"])
    if "engine.torque_scale" in values:
        changes["engine"] = dataclasses.replace(model.engine, torque_scale=values["engine.torque_scale"])
    vm = dataclasses.replace(model, **changes) if changes else model
    return vm, make_controller(vm, kind, **params)


def simulate_batch(
    model: Any,
    variants: dict[str, np.ndarray],
    grid: Any,
    controller: Any,
    *,
    soc_initial: np.ndarray,
    soc_min: float,
    soc_max: float,
) -> BatchRecord | None:
    """The compiled batch (the ``simulate_batch_compiled`` hook of :mod:`hevsim.sim.forward`):
    :func:`threaded_batch` of :func:`_run_one`; None for a controller without a compiled form
    or a key outside :data:`MODEL_KEYS`, ``simulation.soc_initial`` and the ``controller.*``
    keys the controller reads."""
    if controller_code(controller) is None:
        return None

    def run(vm: Any, ctl: Any, soc0: float) -> tuple[Any, ...]:
        return _run_one(vm, grid, ctl, soc0, soc_min, soc_max)[:5]

    return threaded_batch(model, variants, grid, controller, soc_initial, run)


def threaded_batch(
    model: Any, variants: dict[str, np.ndarray], grid: Any, controller: Any, soc_initial: np.ndarray, run: Any
) -> BatchRecord | None:
    """Every variant (:func:`_variant`) a compiled run on its own thread of a pool (the
    compiled loops release the GIL): ``run(variant model, its controller, initial SOC)``
    returns (channel names, channels (names x n + 1), audit names, audit [J], summary) of one
    run. None when a variant's keys cannot be varied on the built model (the keys decide it:
    the first variant tells; the threads build the others, overlapping one variant's Python
    set-up with another's compiled run)."""
    import os
    from concurrent.futures import ThreadPoolExecutor

    n = int(np.size(soc_initial))

    def pair(i: int) -> tuple[Any, Any] | None:
        return _variant(model, controller.name, {k: float(v[i]) for k, v in variants.items()})

    first = pair(0) if n else None
    if first is None:
        return None
    dt = float(grid.time_s[1] - grid.time_s[0])

    def one(i: int) -> tuple[Any, ...]:
        built = first if i == 0 else pair(i)
        assert built is not None  # the keys of variant 0
        vm, ctl = built
        names, cols, audit_names, audit, summary = run(vm, ctl, float(soc_initial[i]))
        wheel = cols[names.index("wheel_power_w")][:-1]
        return (
            dict(zip(audit_names, audit.tolist(), strict=True)),
            summary,
            float(np.sum(np.clip(wheel, 0.0, None)) * dt),
        )

    with ThreadPoolExecutor(max_workers=min(n, os.cpu_count() or 1) or 1) as pool:
        out = list(pool.map(one, range(n)))
    return BatchRecord([o[0] for o in out], np.array([o[1] for o in out]).reshape(n, len(K.SUMMARY)),
                       np.array([o[2] for o in out]))  # fmt: skip


simulate_compiled = simulate
"""The compiled forward run (:func:`hevsim.sim.forward.compiled_loop`'s ``simulate_compiled``)."""
simulate_batch_compiled = simulate_batch
"""The compiled batch (:func:`hevsim.sim.forward.compiled_loop`'s ``simulate_batch_compiled``)."""

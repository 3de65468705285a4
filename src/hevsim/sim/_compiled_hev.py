"""The parallel (P2/P3) and power-split HEVs' plug-in of the one compiled forward loop
(:func:`hevsim.sim._loop.run_loop`, issue 24; issue 11 compiled them first).

The loop reproduces the Python reference loop of :mod:`hevsim.sim.forward` step for step;
this module gives it the supervisory controllers ``electric_assist`` (parallel),
``power_follower`` (power split), ``ecms`` and ``aecms`` (both) over the architectures' point
kernels (:class:`ParallelPlug`: :func:`parallel_choose`, :func:`parallel_point`,
:func:`parallel_commit`; :class:`PowerSplitPlug`: ``power_split_*``). Nothing physical is
written here: every operating point is the architecture's scalar kernel
(:func:`hevsim.architectures.parallel.mechanical_point`,
:func:`hevsim.architectures.power_split.mechanical_point`, their ``losses_point``,
``details_point`` and ``power_mode_point``), the shared bus balance
(:func:`hevsim.components.bus.machine_request`, :func:`~hevsim.components.bus.bus_balance`)
and the pack's kernels. The controllers' rules are those of :mod:`hevsim.control.parallel`,
whose objects hand over their parameters and candidate grids (:func:`controller_code`).

The kernels allocate nothing and run without numba's reference counting (``_nrt=False``):
passing the component tables (tuples of arrays) into the per-point kernels otherwise costs
about 100 ns of reference-count traffic per candidate, more than the physics.

Data cross the numba boundary as named tuples (:class:`~hevsim.sim._loop.RunConstants`,
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
from hevsim.components.battery import soc_rate
from hevsim.components.bus import bus_balance, machine_request
from hevsim.components.driveline import gear_input_torque
from hevsim.components.flow import LIMIT_RTOL
from hevsim.control.parallel import HOLD_EQUIVALENCE_FACTOR, PowerFollower, specific_fuel
from hevsim.control.simple import shift_gear
from hevsim.sim import kernel as K
from hevsim.sim._loop import (
    AUDIT_BASE,
    BASE_COLUMNS,
    ERR_STUCK,
    RunConstants,
    audit_slots,
    constants,
    grid_arrays,
    pack_arrays,
    register,
    run_loop,
    threaded_batch,
    writable,
)
from hevsim.sim._records import REGEN_CURRENT_RTOL, BatchRecord, ForwardRecord

ELECTRIC_ASSIST, ECMS, AECMS, POWER_FOLLOWER = 0, 1, 2, 3
"""Controller codes of the compiled loop (:func:`controller_code`)."""
TAIL_COLUMNS = ("power_mode", "traction_limited", "clutch_closed", "battery_ocv_v", "battery_voltage_v")
"""Last channels, after the architecture's details."""
PS_POWER_BAND, PS_POWER_BAND_MIN_W = PowerFollower.POWER_BAND, PowerFollower.POWER_BAND_MIN_W
"""The power follower's band around its target engine power [-], [W]."""
AUX_RTOL = 1e-6
"""Relative round-off [-] of the battery power accepted as "the auxiliaries only" at the SOC
floor (the bus balance returns the auxiliary load to a few ulps)."""
P_AUX = P.LOSS_TERMS.index("aux")
"""The parallel HEV's audit term of the bus's other load (its losses take it from the tables)."""

ARCHITECTURES = ("parallel", "power_split")
"""The architectures this compiled loop runs (:func:`hevsim.sim.forward.compiled_loop`)."""


HEVConstants = RunConstants
"""The loop's run constants (:class:`hevsim.sim._loop.RunConstants`; former name)."""


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
    ocv, r_dis, r_chg, p_chg, _ = bat
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


@njit(cache=True, **NO_REFCOUNT)
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


@njit(cache=True, error_model="numpy", **NO_REFCOUNT)
def _scan(dpar, dps, cands, w_wheel, t_wheel, regen_ok, soc, dt, bat, md, buf):
    """:func:`_point_body` (no details) of every candidate of ``cands`` at one step (the power
    split's engine points from ``buf[8:10]``, :func:`engine_cache`): feasibility, fuel [kg],
    engine power [W] and SOC change [-] into ``buf[3]``, ``buf[1]``, ``buf[2]``, ``buf[0]``."""
    cand0, cand1, _ = cands
    d_soc, fuel, p_eng, feas, _, _, det, loss, e_flags, e_floats = buf
    for i in range(cand0.shape[0]):
        eng = _engine(e_flags, e_floats, i)
        r = _point_body(
            dpar, dps, cand0[i], cand1[i], eng, w_wheel, t_wheel, regen_ok, soc, dt, bat, md, False, det, loss
        )
        feas[i], fuel[i], d_soc[i], p_eng[i] = r


@njit(cache=True, inline="always", error_model="numpy")
def _load_terms(cc, h, v_mid, soc, p_dem):
    """(charge depleting, low load, charging power [W]) of the rule-based controllers at the
    SOC ``soc`` [-], mid-step speed [m/s] and wheel power demand ``p_dem`` [W]
    (:mod:`hevsim.control.parallel`: ``_GridController.depleting``, ``charge_fraction``,
    ``charging_power``)."""
    depl = soc > cc.cd_soc  # a plug-in hybrid's charge depleting (_GridController.depleting)
    if depl:
        low_load = p_dem < cc.cd_ev_power_w
        frac = 0.0
    else:
        low_load = v_mid < cc.ev_speed_mps and p_dem < cc.ev_power_w
        frac = min(max((cc.soc_high - soc) / (cc.soc_high - cc.soc_low), 0.0), 1.0)  # charge_fraction
    p_charge = frac * cc.charge_power_w + (h.aux_power_w if soc < cc.soc_low else 0.0)  # charging_power
    return depl, low_load, p_charge


PF_EV, PF_NEAR, PF_ALL, PF_FILL = 0, 1, 2, 3
"""Phases of :func:`_pf_choose`: the EV candidates in order; the engine-on candidates near
the target power in the order of their specific fuel; every candidate; the details of the
one chosen among all."""


@njit(cache=True, error_model="numpy", **NO_REFCOUNT)
def _pf_choose(dpar, dps, cc, cands, w_wheel, t_wheel, v_mid, soc, dt, bat, md, buf):
    """The power follower's choice at one step (:class:`hevsim.control.parallel.PowerFollower`),
    as :func:`_choose` returns it, with the chosen control's details, audit terms, fuel and SOC
    change filled (``filled`` True) whenever a control is found. ``dpar`` None, ``dps`` the
    power split's tables (as :func:`_point`).

    When the car may drive electrically, the first feasible EV candidate; else (or when none
    is feasible) the least fuel per unit of engine work of the feasible candidates whose
    engine power (known per run: ``buf[4]``) is near the target: candidates in the order of
    their specific fuel (``buf[5]``, ties by index; per run, as it depends on the engine
    alone), the first near and feasible one is it (the argmin over all, as the Python
    controller takes it); only when none is, every candidate, the feasible one nearest the
    target. One call per step evaluates every candidate it needs with one inlined
    :func:`_point_body` (a call per scan and one more for the details would pass every table
    each time: more than the points cost)."""
    cand0, cand1, _ = cands
    h = md[0]
    cost, fuel, p_eng, feas, p_cand, order, det, loss, e_flags, e_floats = buf
    regen_ok = v_mid > 0.0
    n = cand0.shape[0]
    p_dem = t_wheel * w_wheel
    depl, low_load, p_charge = _load_terms(cc, h, v_mid, soc, p_dem)
    ev = (
        p_dem <= 0.0
        or (depl and low_load)
        or (not depl and soc > cc.soc_low and low_load)
        or (not depl and soc > cc.soc_high and p_dem < cc.engine_min_power_w)
    )  # PowerFollower.electric
    target = max(p_dem, 0.0) + p_charge
    if soc < cc.soc_high and not depl:  # PowerFollower.target_power
        target = max(target, cc.engine_min_power_w)
    band = max(PS_POWER_BAND * target, PS_POWER_BAND_MIN_W)
    phase = PF_EV if ev else PF_NEAR
    k, pick = 0, -1
    while True:
        if phase == PF_EV:
            if k >= n:
                phase, k = PF_NEAR, 0
                continue
            i, k = k, k + 1
            if cand1[i] != 0.0:
                continue
        elif phase == PF_NEAR:
            if k >= n:
                phase, k = PF_ALL, 0
                continue
            i, k = order[k], k + 1
            if cand1[i] == 0.0 or abs(p_cand[i] - target) > band:
                continue
        elif phase == PF_ALL:
            if k >= n:
                for j in range(n):
                    cost[j] = abs(p_eng[j] - target)
                pick = _argmin(cost, feas, n)
                if pick < 0:
                    return False, 0.0, 0.0, False, 0.0, 0.0
                phase = PF_FILL
                continue
            i, k = k, k + 1
        else:
            i = pick
        eng = _engine(e_flags, e_floats, i)
        # details for every candidate that is taken if feasible (it is, nearly always, the first)
        want = phase != PF_ALL
        r = _point_body(
            dpar, dps, cand0[i], cand1[i], eng, w_wheel, t_wheel, regen_ok, soc, dt, bat, md, want, det, loss
        )
        if phase == PF_ALL:
            feas[i], fuel[i], cost[i], p_eng[i] = r
        elif r[0] or phase == PF_FILL:
            return True, cand0[i], cand1[i], True, r[1], r[2]


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
    """The controller's choice at one step (:mod:`hevsim.control.parallel`: electric assist,
    ECMS, A-ECMS; the power follower's is :func:`_pf_choose`): (found, c0, c1,
    filled, fuel [kg], SOC change [-]); ``filled``: the choice's details, audit terms
    (``buf[6]``, ``buf[7]``), fuel and SOC change are those of :func:`_point` with ``want``
    (else not computed). ``dpar``, ``dps``: as :func:`_point`. ``state``: [gear of the
    shift schedule, equivalence factor s, SOC integral, SOC reference] (updated as the
    controller objects update themselves); ``cands``: (first and second control of every
    candidate, the electric assist's throttle grid); ``buf``: work arrays."""
    cand0, cand1, thr_grid = cands
    h, etab, _, _ = md
    cost, fuel, _, feas = buf[:4]
    det, loss = buf[6], buf[7]
    regen_ok = v_mid > 0.0
    n = cand0.shape[0]
    p_dem = t_wheel * w_wheel
    depl, low_load, p_charge = _load_terms(cc, h, v_mid, soc, p_dem)
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
                ok, fuel_kg, d_soc, _ = _point_body(dpar, dps, c0, c1, NO_ENGINE, w_wheel, t_wheel, regen_ok,
                                                    soc, dt, bat, md, True, det, loss)  # fmt: skip
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
    _scan(dpar, dps, cands, w_wheel, t_wheel, regen_ok, soc, dt, bat, md, buf)
    for i in range(n):  # every candidate: ECMS score from its fuel and SOC change (in cost)
        cost[i] = fuel[i] / dt * h.lhv_jpkg + s * (-cost[i] / dt * e_soc)
    i = _argmin(cost, feas, n)
    if i < 0:
        return False, 0.0, 0.0, False, 0.0, 0.0
    return True, cand0[i], cand1[i], False, 0.0, 0.0


# ------------------------------------------------------------------------- the plug-in
class ParallelPlug(NamedTuple):
    """The parallel HEV's plug-in of :func:`hevsim.sim._loop.run_loop`: its tables
    (``dpar``; ``dps`` None), the controller (:class:`ControllerConstants`), the candidates'
    first and second controls and the electric assist's throttle grid, the engine, motor and
    generator (unused) tables."""

    dpar: Any
    dps: None
    cc: ControllerConstants
    cand0: np.ndarray
    cand1: np.ndarray
    thr_grid: np.ndarray
    etab: Any
    mtab: Any
    gtab: Any


class PowerSplitPlug(NamedTuple):
    """The power split's plug-in (as :class:`ParallelPlug`: ``dps`` its tables, ``dpar``
    None; ``gtab`` MG1's tables). Two types, so numba compiles one loop per architecture and
    prunes the other's branches (its tables None) before typing."""

    dpar: None
    dps: Any
    cc: ControllerConstants
    cand0: np.ndarray
    cand1: np.ndarray
    thr_grid: np.ndarray
    etab: Any
    mtab: Any
    gtab: Any


@njit(cache=True, inline="always", error_model="numpy")
def _step_data(plug, hk):
    """The ``md`` and ``cands`` arguments of :func:`_choose` and :func:`_point` at a step."""
    return (hk, plug.etab, plug.mtab, plug.gtab), (plug.cand0, plug.cand1, plug.thr_grid)


@njit(cache=True, inline="always", error_model="numpy")
def _aecms_update(cc, state, v_mid, soc, dt, e_soc):
    """The A-ECMS update of the step taken: integrate its SOC error (as
    :meth:`hevsim.control.parallel.AdaptiveECMS.update`)."""
    if cc.code == AECMS and not soc > cc.cd_soc:
        state[2] += (state[3] - cc.kin * v_mid**2 / e_soc - soc) * dt


# The plug-ins' functions (hevsim.sim._loop): one set per architecture, each passing the other
# architecture's tables as a literal None, so that numba prunes their branches in the shared
# kernels (_choose, _point) before typing; inlined into the loop (no call with every table).
@njit(cache=True, inline="always", error_model="numpy")
def parallel_choose(plug, state, work, v_mid, w_wheel, t_wheel, soc, dt, e_soc, bat, hk):
    """The parallel HEV's ``choose``: :func:`_choose` (``work``: (its ``buf``, the extra
    channels))."""
    md, cands = _step_data(plug, hk)
    return _choose(plug.dpar, None, plug.cc, state, cands, w_wheel, t_wheel, v_mid, soc, dt, e_soc, bat, md,
                   work[0])  # fmt: skip


@njit(cache=True, inline="always", error_model="numpy")
def parallel_point(plug, state, work, c0, c1, v_mid, w_wheel, t_wheel, soc, dt, bat, hk):
    """The parallel HEV's ``point``: :func:`_point` with its details and audit terms; (fuel [kg],
    SOC change [-])."""
    md, _ = _step_data(plug, hk)
    buf = work[0]
    r = _point(plug.dpar, None, c0, c1, NO_ENGINE, w_wheel, t_wheel, v_mid > 0.0, soc, dt, bat, md, True,
               buf[6], buf[7])  # fmt: skip
    return r[1], r[2]


@njit(cache=True, inline="always", error_model="numpy")
def parallel_commit(plug, state, work, v_mid, f, soc, dt, e_soc, hk, has_pack):
    """The parallel HEV's ``commit``: the bus's other load with a pack (the cooling too), the
    A-ECMS update, the clutch (``ext[0]``: closed iff the engine is on); (engine on, power mode,
    battery power [W], current [A], wheel power [W])."""
    buf, ext = work
    det, loss = buf[6], buf[7]
    nd, nl = det.shape[0], loss.shape[0]
    if has_pack:  # the bus's other load of the step (the cooling too)
        loss[P_AUX] = hk.aux_power_w
    _aecms_update(plug.cc, state, v_mid, soc, dt, e_soc)
    ext[0] = det[1]
    return det[1] > 0.0, P.power_mode_point(det[1], det[9], f, v_mid), det[nd - 2], det[nd - 3], loss[nl - 1]


@njit(cache=True, inline="always", error_model="numpy")
def power_split_choose(plug, state, work, v_mid, w_wheel, t_wheel, soc, dt, e_soc, bat, hk):
    """The power split's ``choose``: :func:`_pf_choose` for the power follower, else
    :func:`_choose`."""
    md, cands = _step_data(plug, hk)
    if plug.cc.code == POWER_FOLLOWER:
        return _pf_choose(None, plug.dps, plug.cc, cands, w_wheel, t_wheel, v_mid, soc, dt, bat, md, work[0])
    return _choose(None, plug.dps, plug.cc, state, cands, w_wheel, t_wheel, v_mid, soc, dt, e_soc, bat, md,
                   work[0])  # fmt: skip


@njit(cache=True, inline="always", error_model="numpy")
def power_split_point(plug, state, work, c0, c1, v_mid, w_wheel, t_wheel, soc, dt, bat, hk):
    """The power split's ``point``: its engine point, then :func:`_point` with its details and
    audit terms; (fuel [kg], SOC change [-])."""
    md, _ = _step_data(plug, hk)
    buf = work[0]
    eng = PS.engine_point(c0, c1, plug.dps, plug.etab)
    r = _point(None, plug.dps, c0, c1, eng, w_wheel, t_wheel, v_mid > 0.0, soc, dt, bat, md, True, buf[6],
               buf[7])  # fmt: skip
    return r[1], r[2]


@njit(cache=True, inline="always", error_model="numpy")
def power_split_commit(plug, state, work, v_mid, f, soc, dt, e_soc, hk, has_pack):
    """The power split's ``commit``: the A-ECMS update; (engine on, power mode, battery power
    [W], current [A], wheel power [W]); ``ext[0]`` the engine flag (the record drops it)."""
    buf, ext = work
    det, loss = buf[6], buf[7]
    nd, nl = det.shape[0], loss.shape[0]
    _aecms_update(plug.cc, state, v_mid, soc, dt, e_soc)
    ext[0] = det[0]
    return (
        det[0] > 0.0,
        PS.power_mode_point(det[0], det[14], f, v_mid),
        det[nd - 2],
        det[nd - 3],
        loss[nl - 1],
    )


register(ParallelPlug, parallel_choose, parallel_point, parallel_commit)
register(PowerSplitPlug, power_split_choose, power_split_point, power_split_commit)


# ------------------------------------------------------------------------- Python side
def engine_points(
    model: Any, dps: Any, etab: Any, cand0: np.ndarray, cand1: np.ndarray, dt: float, memo: dict | None = None
) -> tuple[np.ndarray, ...]:
    """The power split's per-run candidate data: (engine flags (3, n), engine floats (3, n),
    as :func:`engine_cache` fills them; engine power [W]; the order of their specific fuel over
    a step ``dt`` [s], NaN first, ties by index). They depend on the engine (``model.engine``,
    its tables ``etab``), the power split's tables ``dps``, the candidates and the step only:
    ``memo`` (a dict a batch's runs share; None: none) keeps them by these, so variants of
    the body, the tire or the controller's SOC band compute them once, a variant of the
    engine again. The arrays are read only by the loop."""
    key = None
    if memo is not None:  # an immutable engine: its identity (kept alive in the value) is its tables
        key = (id(model.engine), dps, cand0.tobytes(), cand1.tobytes(), float(dt))
        hit = memo.get(key)
        if hit is not None:
            return hit[1]
    nc = cand0.size
    e_flags, e_floats = np.zeros((3, nc), np.bool_), np.zeros((3, nc))
    engine_cache(cand0, cand1, dps, etab, e_flags, e_floats)
    p_cand = e_floats[1] * e_floats[0]
    fuel_kg = e_floats[2] * dt  # as _point gives it
    spec = specific_fuel(fuel_kg, p_cand)  # as the Python controller ranks them
    order = np.argsort(np.where(np.isnan(spec), -np.inf, spec), kind="stable")  # NaN first
    out = (e_flags, e_floats, p_cand, order)
    if memo is not None:
        memo[key] = (model.engine, out)
    return out


def _run_one(
    model: Any,
    grid: Any,
    ctl: Any,
    soc0: float,
    soc_min: float,
    soc_max: float,
    pack: Any = None,
    memo: dict | None = None,
) -> tuple[Any, ...]:
    """One compiled run: (channel names, channels (names x n + 1), audit names, audit [J],
    summary, final speed [m/s]); the controller left as the Python loop leaves it. ``pack``:
    the :class:`~hevsim.battery.bms.PackRun` of a ``[battery] model = "pack"`` vehicle
    (:func:`~hevsim.sim._loop.pack_arrays`); ``memo``: the per-run data a batch's runs share
    (:func:`engine_points`)."""
    from hevsim.sim.checks import stuck_error

    cc = controller_code(ctl)
    assert cc is not None
    parallel = isinstance(model, P.ParallelHEV)
    mod = P if parallel else PS
    ctl.reset(float(soc0))
    t, v_des, gr = grid_arrays(grid)
    names = (*BASE_COLUMNS, *mod.DETAILS, *TAIL_COLUMNS)
    cols = np.zeros((len(names), t.size))
    audit_names = (*AUDIT_BASE, *mod.LOSS_TERMS[1:-1], "battery_loss")
    audit = np.zeros(len(audit_names))
    summary = np.zeros(len(K.SUMMARY))
    state = np.array([1.0, cc.s0, 0.0, min(float(soc0), cc.cd_soc)])  # gear, s, SOC integral, SOC reference
    cand0, cand1 = (np.require(c, np.float64, ("C", "W")) for c in (ctl.controls[0], ctl.controls[-1]))
    thr = np.require(getattr(ctl, "thr_grid", np.zeros(0)), np.float64, ("C", "W"))
    h = constants(model, soc_min, soc_max)
    etab, mtab, ptab = (writable(c.kernel_tables()) for c in (model.engine, model.motor, model.battery))
    if parallel:
        plug: Any = ParallelPlug(writable(P.kernel_tables(model)), None, cc, cand0, cand1, thr, etab, mtab,
                                 writable(model.motor.kernel_tables()))  # fmt: skip
    else:
        plug = PowerSplitPlug(None, writable(PS.kernel_tables(model)), cc, cand0, cand1, thr, etab, mtab,
                              writable(model.generator.kernel_tables()))  # fmt: skip
    nc = cand0.size
    if parallel:
        e_flags, e_floats = np.zeros((3, nc), np.bool_), np.zeros((3, nc))
        p_cand, order = np.zeros(nc), np.arange(nc)
    else:  # each candidate's engine operating point, engine power [W], specific-fuel order
        dt = t[1] - t[0]
        e_flags, e_floats, p_cand, order = engine_points(model, plug.dps, etab, cand0, cand1, dt, memo)
    det, loss, ext = np.zeros(len(mod.DETAILS)), np.zeros(len(mod.LOSS_TERMS)), np.zeros(1)
    buf = (np.empty(nc), np.empty(nc), np.empty(nc), np.empty(nc, np.bool_), p_cand, order, det, loss,
           e_flags, e_floats)  # fmt: skip
    slots = audit_slots(mod.LOSS_TERMS, audit_names)
    status, k, v_end, _ = run_loop(plug, float(soc0), t, v_des, gr, h, ptab, state, (buf, ext), det, loss,
                                   ext, slots, cols, audit, summary,
                                   pack_arrays(pack, model, t.size - 1))  # fmt: skip
    if status == ERR_STUCK:
        soc_last = cols[names.index("soc"), k - 1] if k > 0 else soc0
        raise stuck_error(model, float(t[k]), float(soc_last), soc_min)
    if cc.code == ELECTRIC_ASSIST:
        ctl.gear = int(state[0])
    elif cc.code == AECMS:
        ctl.s, ctl.integral = float(state[1]), float(state[2])
    return names, cols, audit_names, audit, summary, float(v_end)


def simulate(
    model: Any, grid: Any, ctl: Any, *, soc_initial: float, soc_min: float, soc_max: float, pack: Any = None
) -> ForwardRecord | None:
    """The compiled forward run of a parallel or power-split ``model`` (the
    ``simulate_compiled`` hook of :mod:`hevsim.sim.forward`, same arguments and
    :class:`~hevsim.sim.forward.ForwardRecord`); None for a controller without a compiled
    form. Leaves the controller as the Python loop does (shift-schedule gear, A-ECMS factor
    and integral). ``pack``: the :class:`~hevsim.battery.bms.PackRun` of a ``[battery] model =
    "pack"`` vehicle, stepped inside the loop (:func:`~hevsim.sim._loop.battery_begin`,
    :func:`~hevsim.sim._loop.battery_end`)."""
    if controller_code(ctl) is None:
        return None
    names, cols, audit_names, audit, summary, v_end = _run_one(
        model, grid, ctl, soc_initial, soc_min, soc_max, pack
    )
    columns = {name: cols[j] for j, name in enumerate(names)}
    if not isinstance(model, P.ParallelHEV):  # clutch_closed is the parallel HEV's; the power split has none
        del columns["clutch_closed"]
    return ForwardRecord(columns, dict(zip(audit_names, audit.tolist(), strict=True)), summary, v_end)


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

    memo: dict = {}  # per-run data shared by variants (engine_points)

    def run(vm: Any, ctl: Any, soc0: float) -> tuple[Any, ...]:
        return _run_one(vm, grid, ctl, soc0, soc_min, soc_max, memo=memo)[:5]

    return threaded_batch(model, variants, grid, controller, soc_initial, run)


simulate_compiled = simulate
"""The compiled forward run (:func:`hevsim.sim.forward.compiled_loop`'s ``simulate_compiled``)."""
simulate_batch_compiled = simulate_batch
"""The compiled batch (:func:`hevsim.sim.forward.compiled_loop`'s ``simulate_batch_compiled``)."""

"""The series HEV's plug-in of the one compiled forward loop (:func:`hevsim.sim._loop.run_loop`,
issue 24 item 2): the thesis's vehicle (chapter 2) with its refinement levels.

The series HEV keeps the thesis's forward model, which differs from the loop's own driver
(in :func:`hevsim.sim._loop.run_loop`: the wheel force that reaches the cycle's next speed, a
bisection where the powertrain cannot): its driver is the tutorial's proportional speed loop,
the car's speed follows from the forces at the step's start (explicit Euler), the genset has a
shaft with inertia and a speed loop (or sits at a DP optimum's point, quasi-statically) and
the ``tables`` and ``cell`` batteries keep their start-of-step current limit. The plug-in
therefore brings its own ``drive`` (the loop's driver hook): :func:`series_drive`, one step of
the point kernels of :mod:`hevsim.architectures.series_kernel` (driver -> supervisor ->
battery limits -> genset -> traction -> vehicle dynamics -> bus -> power mode), with the road
and battery sides of the audit; the loop keeps the run, the trace-following bookkeeping
(error, distance, time limited), the fuel, the engine starts and running time (``commit``'s
engine state: 1 fired, 0.5 a genset turning unfired, cranking or a current source on: a start,
no engine time) and the summary.

The battery is the loop's, as for every architecture: ``ptab`` the pack tables and ``pk``
None (``[battery] model = "table"``), a :data:`~hevsim.battery.vehicle.CellBusTables`
(``"cell"``: :class:`~hevsim.battery.cell_run.CellRun`) or a pack's
:class:`~hevsim.battery.pack_run.PackArrays` (``"pack"``: cells, module thermal model,
cooling loop, BMS, ageing stress). The loop begins each step (:func:`hevsim.sim._loop.battery_begin`)
and hands :func:`series_drive` the battery's state ``bat`` (OCV, resistances, charge OCV) and
the step's current limits and bus load in ``hk``; the plug-in solves its bus with them and
``commit`` returns the step's battery power, with which the loop ends the battery's step
(:func:`hevsim.sim._loop.battery_end`: a table battery's SOC is the plug-in's charge count, a
cell's or a pack's its own). The plug-in registers ``limit_rtol = (0, 0)``: it holds a BMS's
limits exactly itself (:func:`~hevsim.architectures.series_kernel.traction_limit_step`), so
they are handed to it as they are. Its channels go to the plug-in's ``out``
(:data:`~hevsim.architectures.series_kernel.CHANNELS`, one row a step), its energy terms to
:data:`~hevsim.architectures.series_kernel.ENERGY_TERMS` (the loop's audit array: the first
seven are :data:`hevsim.sim._loop.AUDIT_BASE`; the battery's chemical energy and loss are the
plug-in's, the loop adds none).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit, prange

from hevsim.architectures import series_kernel as S
from hevsim.sim._loop import RunConstants, pack_arrays, register, run_loop, writable

W_GS, GS_STATE, MODE, REASON, FUEL, ENGINE, P_WHEEL, P_BAT, I_BAT = range(9)
"""Indices of the plug-in's ``state``: genset shaft speed [rad/s], genset state
(:data:`~hevsim.architectures.series_kernel.GENSET_STATES`), power mode and the reason of its
latest change (codes), fuel so far [kg], engine state of the step (``commit``), wheel power [W],
battery terminal power [W] and current [A] of the step."""
STATE_SIZE = 9


class SeriesPlug(NamedTuple):
    """The series HEV's plug-in of :func:`hevsim.sim._loop.run_loop`: its parameter vector
    ``p`` (:data:`~hevsim.architectures.series_kernel.PARAMS`), the component tables (engine,
    traction motor, generator; the battery is the loop's), the supervisor's per-step data
    ``sched`` (n x 3) and the channel array ``out`` (rows of
    :data:`~hevsim.architectures.series_kernel.CHANNELS`; one row: no time series)."""

    p: Any
    eng: Any
    mot: Any
    gen: Any
    sched: Any
    out: Any


@njit(cache=True, inline="always")  # in run_loop: no call passing the plug-in's ~30 arrays every step
def series_drive(plug, state, work, k, v, soc, t, v_des, gr, dt, h, bat, hk, e_soc, bms, audit):
    """The plug-in's ``drive`` (the loop's driver hook, :mod:`hevsim.sim._loop`): step ``k``
    from the speed ``v`` [m/s] and SOC ``soc`` [-] with the battery state ``bat`` (OCV [V],
    discharge and charge resistance [ohm], largest charge power [W], charge OCV [V]) and the
    step's current limits [A] and auxiliary load [W] in ``hk`` (the loop's
    :func:`~hevsim.sim._loop.battery_begin`): :func:`~hevsim.architectures.series_kernel.driver_step`
    -> supervisor -> :func:`~hevsim.architectures.series_kernel.bus_limits` ->
    :func:`~hevsim.architectures.series_kernel.genset_step` ->
    :func:`~hevsim.architectures.series_kernel.traction_step` ->
    :func:`~hevsim.architectures.series_kernel.vehicle_step` (with a BMS, ``bms``, the limits
    again at the mid-step speed) -> :func:`~hevsim.architectures.series_kernel.bus_step` ->
    :func:`~hevsim.architectures.series_kernel.mode_step`; adds the step's energy terms to
    ``audit`` (:data:`~hevsim.architectures.series_kernel.ENERGY_TERMS` [J]), writes row ``k``
    of ``plug.out`` and keeps the battery's power and current for ``commit`` (the loop ends the
    battery's step with them). Returns (True, end speed, mid-step speed [m/s], acceleration
    [m/s²], grade [-], wheel force [N], limited 0/1, fuel [kg], SOC change [-])."""
    p, eng, mot, gen, sched, out = plug.p, plug.eng, plug.mot, plug.gen, plug.sched, plug.out
    energy = audit
    record = out.shape[0] > 1
    m_eff = p[S.MASS] * p[S.MFACT] + p[S.MINERT] * (p[S.RATIO] / p[S.RTIRE]) ** 2
    j_shaft = p[S.EINERT] + p[S.GINERT]
    cap_as = p[S.BCAP] * p[S.BNP] * 3600.0
    drv_kind = int(p[S.DRVKIND])
    sup_kind = int(p[S.SUPKIND])
    quasi_static = sup_kind == S.SUPERVISOR_REPLAY
    exact = bms
    w_gs = state[W_GS]
    gs_state = int(state[GS_STATE])
    mode = int(state[MODE])
    reason = int(state[REASON])
    grade_k = gr[k]

    u, w_m0, m_max, m_min = S.driver_step(p, mot, drv_kind, v, v_des[k + 1], v_des[k], grade_k, dt, m_eff)
    gs_state, thr_cmd, w_target, new_reason = S.supervise(sup_kind, p, sched, k, soc, w_gs, gs_state)
    # the battery's discharge and charge states and power limits at the start of the step
    ocv, r_b, r_c, _, ocv_c = bat
    p_aux = hk.aux_power_w
    p_dis_max, p_chg_max, at_floor = S.bus_limits(
        p, soc, ocv, r_b, ocv_c, r_c, dt, cap_as, hk.i_discharge_max_a, hk.i_charge_max_a
    )
    t_target = sched[k, 2] if quasi_static else 0.0
    fuel_rate, w1, p_gen_el, source_on, fired, t_eng, t_gen, thr, w_gs_k, w_pow = S.genset_step(
        p, eng, gen, gs_state, thr_cmd, w_target, t_target, quasi_static, w_gs, dt, j_shaft,
        p_dis_max - p_aux,
    )  # fmt: skip
    t_m, f_motor, f_fric, limited, p_other, f_brake_req = S.traction_step(
        p, mot, u, v, w_m0, m_max, m_min, p_gen_el, source_on, ocv, p_dis_max, p_chg_max, p_aux
    )
    if at_floor and t_m > 0.0:
        t_m, f_motor, a, v1, f_aero, f_roll, f_grade, f_fric, floor_limited = S.floor_traction_step(
            p, mot, t_m, v, v, p_other, p_dis_max, grade_k, m_eff, dt
        )
        if floor_limited:
            limited = 1.0
    else:
        a, v1, f_aero, f_roll, f_grade, f_fric = S.vehicle_step(p, v, f_motor, f_fric, grade_k, m_eff, dt)
    if exact:  # the battery's limits at the mid-step speed the powers are taken at: the
        # motor first, then a generating genset's output clipped to what the battery can take
        t_m, f_motor, f_fric, a, v1, f_aero, f_roll, f_grade, mid_limited, p_m_el = S.traction_limit_step(
            p, mot, t_m, u, f_brake_req, v, v1, a, f_aero, f_roll, f_grade, f_fric, p_other, p_dis_max,
            p_chg_max, grade_k, m_eff, dt,
        )  # fmt: skip
        if mid_limited:
            limited = 1.0
        p_gen_min = -p_chg_max - (p_m_el + p_other - p_gen_el)
        if p_gen_el < p_gen_min and t_gen < 0.0:
            fuel_rate, w1, p_gen_el, t_eng, t_gen, thr, w_pow = S.genset_limit(
                p, eng, gen, t_eng, t_gen, thr, fired, w_gs_k, w1, w_pow, quasi_static, dt, j_shaft,
                p_gen_min,
            )  # fmt: skip
            limited = 1.0
    S.genset_account(p, fuel_rate, t_eng, t_gen, thr, w_gs_k, w1, w_pow, p_gen_el, quasi_static, dt, j_shaft,
                     energy, record, out, k)  # fmt: skip
    v_mid = 0.5 * (v + v1)
    p_m_mech, p_m_el, p_src, soc1, i_bat, p_bat, over_power = S.bus_step(
        p, mot, t_m, v_mid, p_gen_el, source_on, ocv, r_b, ocv_c, r_c, p_dis_max, p_chg_max, p_aux,
        at_floor, exact, soc, dt, cap_as, energy, record, out, k,
    )  # fmt: skip
    if over_power:
        limited = 1.0  # beyond the deliverable power (the bus sags) or auxiliaries shed
    # traction energy audit [J]
    energy[S.E_GEAR] += (p_m_mech - f_motor * v_mid) * dt
    energy[S.E_AERO] += f_aero * v_mid * dt
    energy[S.E_ROLL] += f_roll * v_mid * dt
    energy[S.E_GRADE] += f_grade * v_mid * dt
    energy[S.E_BRAKE] += f_fric * v_mid * dt
    energy[S.E_KINV] += 0.5 * m_eff * (v1 * v1 - v * v)
    mode, reason = S.mode_step(p, mode, reason, new_reason, u, v, p_m_el, p_gen_el, p_src)
    fuel_kg = state[FUEL] + fuel_rate * dt
    if record:
        o = out[k]
        o[S.CH_TIME_S] = t[k]
        o[S.CH_SPEED_DESIRED_MPS] = v_des[k]
        o[S.CH_SPEED_MPS] = v
        o[S.CH_ACCEL_MPS2] = a
        o[S.CH_DRIVER_REQUEST] = u
        o[S.CH_FUEL_KG] = fuel_kg
        o[S.CH_SOC] = soc
        o[S.CH_FRICTION_BRAKE_FORCE_N] = f_fric
        o[S.CH_WHEEL_FORCE_N] = f_motor
        o[S.CH_ROAD_LOAD_FORCE_N] = f_aero + f_roll + f_grade
        o[S.CH_GENSET_STATE] = gs_state
        o[S.CH_POWER_MODE] = mode
        o[S.CH_MODE_REASON] = reason
        o[S.CH_BATTERY_LIMITED] = limited
    state[W_GS] = w1
    state[GS_STATE] = gs_state
    state[MODE] = mode
    state[REASON] = reason
    state[FUEL] = fuel_kg
    state[ENGINE] = 1.0 if fired else (0.5 if gs_state != S.GS_OFF else 0.0)
    state[P_WHEEL] = (f_motor - f_fric) * v_mid
    state[P_BAT] = p_bat
    state[I_BAT] = i_bat
    # the SOC change: soc + (soc1 - soc) is soc1 exactly (Sterbenz: a step changes the SOC by
    # far less than half)
    return True, v1, v_mid, a, grade_k, f_motor - f_fric, limited, fuel_rate * dt, soc1 - soc


@njit(cache=True, inline="always")
def series_commit(plug, state, work, v_mid, f, soc, dt, e_soc, hk, has_pack):
    """The plug-in's ``commit``: (engine state: 1 fired, 0.5 the genset turning unfired, 0 off;
    power mode; the battery's terminal power [W] (the loop ends the battery's step with it)
    and current [A]; wheel power [W])."""
    return state[ENGINE], state[MODE], state[P_BAT], state[I_BAT], state[P_WHEEL]


register(SeriesPlug, None, None, series_commit, drive=series_drive, limit_rtol=(0.0, 0.0))


@njit(cache=True)
def series_constants(p):
    """The loop's :class:`~hevsim.sim._loop.RunConstants` of a series run with the parameter
    vector ``p`` (compiled: each variant of a batch its own; the battery's constants are the
    table battery's step, :func:`hevsim.sim._loop.battery_begin`)."""
    return RunConstants(
        int(p[S.MKIND]), p[S.MEFF], p[S.MSCALE], p[S.BNS], p[S.BNP], p[S.BREXT], p[S.BTEMP], p[S.BIDIS],
        p[S.BICHG], p[S.BCEFF], p[S.BCAP] * p[S.BNP] * 3600.0, p[S.SOCMIN], p[S.SOCMAX], p[S.PAUX], p[S.MASS],
        p[S.MFACT], p[S.CD], p[S.AREA], p[S.RHO], p[S.WIND], p[S.CRR], p[S.CRRV], p[S.RTIRE], p[S.ELHV],
    )  # fmt: skip


_NONE_F = np.zeros(0)
_NONE_I = np.zeros(0, np.int64)
_NO_COLS = np.zeros((0, 1))


def _tables(*tabs: Any) -> tuple[Any, ...]:
    """The component table tuples with read-only arrays copied (:func:`hevsim.sim._loop.writable`:
    one numba type, one compiled run, whether a machine's map arrays are read-only or not)."""
    return tuple(writable(tab) for tab in tabs)


def _grid(*arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """The cycle's arrays as writable C-contiguous float64 (a :class:`~hevsim.cycles.DriveCycle`'s
    are read-only: another numba type than the other plug-ins' grids)."""
    return tuple(np.require(a, np.float64, ("C", "W")) for a in arrays)


def run_compiled(
    p: Any, eng: Any, mot: Any, gen: Any, battery: Any, sched: Any, t_s: Any, v_des: Any, grade: Any,
    record: bool, out: Any, energy: Any, summary: Any,
) -> None:  # fmt: skip
    """Integrate the series HEV over the (uniformly sampled) cycle ``t_s, v_des, grade``: one
    run of :func:`hevsim.sim._loop.run_loop` with :class:`SeriesPlug`.

    The driver and supervisor are chosen by ``p[DRVKIND]`` and ``p[SUPKIND]``
    (:mod:`hevsim.architectures.series_kernel`'s dispatchers). ``eng``, ``mot``, ``gen``: the
    named table tuples of the components; ``battery``: ``(ptab, run)``, the pack tables
    (:class:`~hevsim.components.battery.PackTables`) and the battery the loop steps (None: the
    tables; a ``"cell"`` battery's :class:`~hevsim.battery.cell_run.CellRun`, a pack's
    :class:`~hevsim.battery.bms.PackRun`: :func:`hevsim.sim._loop.pack_arrays`, with the
    auxiliary load ``p[PAUX]`` as the bus's base load); ``sched``: per-step data for the
    supervisor (a schedule), shape (n, m). Fills ``energy``
    (:data:`~hevsim.architectures.series_kernel.ENERGY_TERMS`, J) and ``summary``
    (:data:`~hevsim.architectures.series_kernel.SUMMARY`); when ``record`` is true, ``out[k]``
    holds the channels of step k (k = 0..n-1 steps, plus the final state at row n).
    """
    n = t_s.shape[0] - 1
    state = np.zeros(STATE_SIZE)
    energy[:] = 0.0
    rows = out if record else out[:1]
    ptab, run = battery
    if run is not None and run.base_aux_w is None:
        run.base_aux_w = float(p[S.PAUX])  # the base the cooling adds to
    pk = pack_arrays(run, None, n)
    eng, mot, gen, ptab = _tables(eng, mot, gen, ptab)
    plug = SeriesPlug(p, eng, mot, gen, sched, rows)
    t_s, v_des, grade = _grid(t_s, v_des, grade)
    h = series_constants(p)
    _, _, v, _ = run_loop(plug, float(p[S.SOC0]), t_s, v_des, grade, h, ptab, state, _NONE_F, _NONE_F,
                          _NONE_F, _NONE_F, _NONE_I, _NO_COLS, energy, summary, pk)  # fmt: skip
    if record:
        o = out[n]
        o[:] = out[n - 1] if n > 0 else 0.0
        o[S.CH_TIME_S] = t_s[n]
        o[S.CH_SPEED_DESIRED_MPS] = v_des[n]
        o[S.CH_SPEED_MPS] = v
        o[S.CH_ENGINE_SPEED_RADPS] = state[W_GS]
        o[S.CH_FUEL_KG] = summary[S.S_FUEL]
        o[S.CH_SOC] = summary[S.S_SOCF]


@njit(cache=True)
def _variant(p, eng, mot, gen, ptab, sched, t_s, v_des, grade, energy, summary, dummy):
    """One variant of :func:`_batch`: the parameter vector ``p``, no time series."""
    none_f = np.zeros(0)
    run_loop(SeriesPlug(p, eng, mot, gen, sched, dummy), p[S.SOC0], t_s, v_des, grade, series_constants(p),
             ptab, np.zeros(STATE_SIZE), none_f, none_f, none_f, none_f, np.zeros(0, np.int64),
             np.zeros((0, 1)), energy, summary, None)  # fmt: skip


@njit(cache=True, parallel=True)
def _batch(pmat, eng, mot, gen, ptab, sched_arr, t_s, v_des, grade, energy, summary):
    """Every row of ``pmat`` one run of :func:`hevsim.sim._loop.run_loop` (:func:`run_batch`;
    ``sched_arr``: named ``sched`` numba's parfor lowering would repeat it as an argument)."""
    dummy = np.zeros((1, len(S.CHANNELS)))
    for i in prange(pmat.shape[0]):
        _variant(pmat[i], eng, mot, gen, ptab, sched_arr, t_s, v_des, grade, energy[i], summary[i], dummy)


def run_batch(
    pmat: Any, eng: Any, mot: Any, gen: Any, ptab: Any, sched: Any, t_s: Any, v_des: Any, grade: Any,
    energy: Any, summary: Any,
) -> None:  # fmt: skip
    """Run every row of ``pmat`` (one parameter vector per variant) in parallel, each one run
    of the one compiled loop with the table battery ``ptab`` (a
    :class:`~hevsim.components.battery.PackTables`). Fills ``energy[i]`` and ``summary[i]`` per
    variant (zeros on entry); no time series are recorded."""
    eng, mot, gen, ptab = _tables(eng, mot, gen, ptab)
    t_s, v_des, grade = _grid(t_s, v_des, grade)
    _batch(pmat, eng, mot, gen, ptab, sched, t_s, v_des, grade, energy, summary)

"""The series HEV's point kernels (thesis chapter 2): the steps of one integration interval
of its forward run, which is a plug-in of the one compiled loop
(:func:`hevsim.sim._loop.run_loop`, through :mod:`hevsim.sim._compiled_series`).

Every step calls the same component kernels as the vectorised models
(:mod:`hevsim.components`), reads every scalar parameter from one float vector ``p``
(indices below, :mod:`hevsim.components.kernel_params`) so a batch of parameter variants is a
matrix, and writes its channels of a step into ``out`` (columns :data:`CHANNELS`) when asked.

Integration scheme: the vehicle speed is advanced by explicit Euler with forces evaluated at
the start of the step; every power is evaluated at the mid-step speed, which makes the energy
audit close to round-off (``F v_mid dt = m (v1 - v0) v_mid = Δ(m v²/2)``). The genset shaft
is advanced with the generator's proportional speed loop treated implicitly, which keeps the
stiff loop stable at any step size.

(Formerly :mod:`hevsim.sim.kernel`, which re-exports these names; issue 24 item 2.)
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

from hevsim.components.battery import charge_current
from hevsim.components.body import aero_force, grade_force, road_load_force, rolling_force
from hevsim.components.bus import (
    REGEN_ITERATIONS,
    TORQUE_RTOL,
    battery_power_limits,
    bus_current,
    limit_machine_torque,
    needs_limit,
    regen_torque,
)
from hevsim.components.driveline import gear_output_torque
from hevsim.components.electric_machine import (
    electrical_power,
    machine_efficiency,
    machine_power,
    torque_limits,
)
from hevsim.components.engine import engine_fuel_rate, engine_torque
from hevsim.components.kernel_params import PARAMS as PARAMS  # re-exported: the layout K.PARAMS
from hevsim.components.kernel_params import P as P

# --- scalar parameter vector layout (hevsim.components.kernel_params: the battery roles write it too)
# Index constants by name: a reordered PARAMS cannot mis-assign them.
MASS = P["mass_kg"]
MFACT = P["mass_factor"]
CD = P["cd"]
AREA = P["area_m2"]
RHO = P["rho_kgpm3"]
WIND = P["headwind_mps"]
CRR = P["crr"]
CRRV = P["crr_v"]
RTIRE = P["tire_radius_m"]
RATIO = P["gear_ratio"]
GEFF = P["gear_efficiency"]
FBRAKE = P["max_brake_force_n"]
KDRV = P["driver_gain_per_mps"]
KFF = P["driver_feedforward"]
MKIND = P["motor_kind"]
MEFF = P["motor_eff"]
MSCALE = P["motor_scale"]
MINERT = P["motor_inertia"]
GKIND = P["gen_kind"]
GEFFM = P["gen_eff"]
GSCALE = P["gen_scale"]
GINERT = P["gen_inertia"]
EPRES = P["engine_present"]
ETMAP = P["engine_use_tmap"]
EFMAP = P["engine_use_fuel_map"]
ESTALL = P["engine_stall_radps"]
ERED = P["engine_redline_radps"]
ESCALE = P["engine_scale"]
EINERT = P["engine_inertia"]
ELHV = P["engine_lhv_jpkg"]
BNS = P["bat_ns"]
BNP = P["bat_np"]
BREXT = P["bat_r_extra"]
BCAP = P["bat_capacity_ah"]
BCEFF = P["bat_coulombic_eff"]
BIDIS = P["bat_max_dis_a"]
BICHG = P["bat_max_chg_a"]
BTEMP = P["bat_temp_k"]
SOC0 = P["soc_initial"]
SOCMIN = P["soc_min"]
SOCMAX = P["soc_max"]
GSKIND = P["genset_kind"]
SOCLO = P["soc_low"]
SOCHI = P["soc_high"]
SOCBOOST = P["soc_boost"]
GSW = P["genset_speed_radps"]
GSWSTART = P["genset_start_speed_radps"]
THRRUN = P["throttle_run"]
THRBOOST = P["throttle_boost"]
GSKP = P["genset_gain_per_radps"]
GSCUR = P["genset_current_a"]
REGENV = P["regen_min_speed_mps"]
PAUX = P["aux_power_w"]
PICEBAND = P["pure_ice_band_w"]
DRVKIND = P["driver_kind"]
SUPKIND = P["supervisor_kind"]

# Genset kinds and states, power modes (thesis Table 2.1) and reasons for changes.
GENSET_NONE, GENSET_CURRENT_SOURCE, GENSET_ENGINE = 0, 1, 2
GS_OFF, GS_STARTING, GS_RUNNING = 0, 1, 2
GENSET_STATES = ("off", "starting", "running")
MODE_PURE_EV, MODE_PURE_ICE, MODE_COMBINED, MODE_ICE_CHARGING, MODE_CHARGING = 0, 1, 2, 3, 4
POWER_MODES = ("pure_ev", "pure_ice", "combined", "ice_charging", "charging")
REASONS = (
    "initial state",
    "SOC fell below soc_low: genset start requested",
    "engine reached start speed: genset running",
    "SOC rose above soc_high: genset stopped",
    "braking: regeneration to the battery",
    "traction demand with genset off: battery only",
    "genset output exceeds traction demand: surplus charges the battery",
    "genset output matches traction demand within pure_ice_band_w",
    "traction demand exceeds genset output: battery assists",
    "schedule: genset on",
    "schedule: genset off",
)
(R_INIT, R_SOCLOW, R_STARTED, R_SOCHIGH, R_REGEN, R_EV, R_ICECHG, R_PUREICE, R_COMBINED,
 R_SCHED_ON, R_SCHED_OFF) = range(11)  # fmt: skip

# Recorded channels (column order of ``out``); names carry units.
CHANNELS = (
    "time_s", "speed_desired_mps", "speed_mps", "accel_mps2", "driver_request",
    "motor_speed_radps", "motor_torque_nm", "motor_power_mech_w", "motor_power_elec_w",
    "motor_current_a", "generator_torque_nm", "generator_power_elec_w", "generator_current_a",
    "engine_speed_radps", "engine_torque_nm", "engine_throttle", "engine_power_w",
    "fuel_rate_kgps", "fuel_kg", "battery_current_a", "battery_voltage_v", "battery_ocv_v",
    "battery_resistance_ohm", "battery_power_w", "soc", "friction_brake_force_n",
    "wheel_force_n", "road_load_force_n", "genset_state", "power_mode", "mode_reason",
    "battery_limited",
)  # fmt: skip
C = {name: i for i, name in enumerate(CHANNELS)}
(
    CH_TIME_S, CH_SPEED_DESIRED_MPS, CH_SPEED_MPS, CH_ACCEL_MPS2, CH_DRIVER_REQUEST,
    CH_MOTOR_SPEED_RADPS, CH_MOTOR_TORQUE_NM, CH_MOTOR_POWER_MECH_W, CH_MOTOR_POWER_ELEC_W,
    CH_MOTOR_CURRENT_A, CH_GENERATOR_TORQUE_NM, CH_GENERATOR_POWER_ELEC_W, CH_GENERATOR_CURRENT_A,
    CH_ENGINE_SPEED_RADPS, CH_ENGINE_TORQUE_NM, CH_ENGINE_THROTTLE, CH_ENGINE_POWER_W,
    CH_FUEL_RATE_KGPS, CH_FUEL_KG, CH_BATTERY_CURRENT_A, CH_BATTERY_VOLTAGE_V, CH_BATTERY_OCV_V,
    CH_BATTERY_RESISTANCE_OHM, CH_BATTERY_POWER_W, CH_SOC, CH_FRICTION_BRAKE_FORCE_N,
    CH_WHEEL_FORCE_N, CH_ROAD_LOAD_FORCE_N, CH_GENSET_STATE, CH_POWER_MODE, CH_MODE_REASON,
    CH_BATTERY_LIMITED,
) = range(len(CHANNELS))  # fmt: skip

# Energy-audit accumulators [J] (index of the ``energy`` result vector).
ENERGY_TERMS = (
    "fuel", "genset_source", "battery_chemical", "aero", "rolling", "grade", "kinetic_vehicle",
    "kinetic_genset", "friction_brakes", "engine_loss", "generator_loss", "motor_loss",
    "gear_loss", "battery_loss", "aux",
)  # fmt: skip
(
    E_FUEL, E_GSRC, E_BATT, E_AERO, E_ROLL, E_GRADE, E_KINV, E_KING, E_BRAKE,
    E_ENG, E_GEN, E_MOT, E_GEAR, E_BLOSS, E_AUX,
) = range(len(ENERGY_TERMS))  # fmt: skip

# Scalar summaries returned per run.
SUMMARY = (
    "distance_m", "fuel_kg", "soc_final", "speed_error_rms_mps", "speed_error_max_mps",
    "engine_on_time_s", "engine_starts", "battery_limited_s", "duration_s",
)  # fmt: skip
S_DIST, S_FUEL, S_SOCF, S_RMS, S_MAXERR, S_EON, S_STARTS, S_BLIM, S_DUR = range(len(SUMMARY))


# --- pluggable controllers ----------------------------------------------------------------
# Each role is a numba-jitted function with a fixed signature. The kernel loop calls a role
# only through its dispatcher below (``drive``, ``supervise``), which picks the implementation
# by an integer code held in the parameter vector. A new controller is a new function plus one
# line in its dispatcher and its name in the matching ``*_KINDS`` tuple; the loop is untouched.
# (Passing the functions as first-class arguments would also work, but numba cannot cache such
# kernels on disk: every new process would pay a 2 s compile.) The battery model is not a role
# here: the one loop steps it (tables, cells or a pack, hevsim.sim._loop.battery_begin /
# battery_end) and hands the plug-in its state and limits of the step.
#
#   driver(p, v, v_target, v_target_prev, dt, f_res0, f_drive_max, m_eff) -> u in [-1, 1]
#   supervisor(p, sched, k, soc, w_gs, gs_state) -> (gs_state, throttle, w_target, reason)
#       (reason -1 when the genset state did not change)


@njit(cache=True)
def driver_proportional(p, v, v_target, v_target_prev, dt, f_res0, f_drive_max, m_eff):
    """The tutorial's proportional speed controller, ``u = K (v_target - v_end)``.

    The P loop is solved implicitly with the vehicle dynamics (linear in u before
    saturation), so it is stable at any step and converges to the continuous-time controller
    as dt -> 0. An optional feed-forward term adds ``K_ff * dv_target/dt``.
    """
    kd = p[KDRV]
    e0 = v_target - v + dt * f_res0 / m_eff
    u = kd * e0 / (1.0 + kd * dt * f_drive_max / m_eff)
    if u < 0.0:
        u = kd * e0 / (1.0 + kd * dt * p[FBRAKE] / m_eff)
    u += p[KFF] * (v_target - v_target_prev) / dt
    return min(max(u, -1.0), 1.0)


@njit(cache=True)
def supervisor_thermostat(p, sched, k, soc, w_gs, gs_state):
    """Genset thermostat of the tutorial (lectures 5-9): on below soc_low, off above soc_high.

    An engine genset is cranked by the generator until ``genset_start_speed_radps`` and then
    fired at ``throttle_run`` (``throttle_boost`` below ``soc_boost``).
    """
    reason = -1
    if p[GSKIND] != GENSET_NONE:
        if gs_state == GS_OFF and soc < p[SOCLO]:
            gs_state = GS_STARTING if p[GSKIND] == GENSET_ENGINE else GS_RUNNING
            reason = R_SOCLOW
        elif gs_state == GS_STARTING and w_gs >= p[GSWSTART]:
            gs_state = GS_RUNNING
            reason = R_STARTED
        elif gs_state != GS_OFF and soc > p[SOCHI]:
            gs_state = GS_OFF
            reason = R_SOCHIGH
    thr = 0.0
    if gs_state == GS_RUNNING:
        thr = p[THRBOOST] if soc < p[SOCBOOST] else p[THRRUN]
    return gs_state, thr, p[GSW], reason


@njit(cache=True)
def supervisor_schedule(p, sched, k, soc, w_gs, gs_state):
    """Follow a genset schedule: ``sched[k] = (engine speed target [rad/s], throttle [-])``.

    Used to replay an optimal (DP) trajectory in the forward simulator. A target speed of 0
    stops the genset; otherwise the generator cranks the engine until 90 % of the target and
    the engine then runs at the scheduled throttle.
    """
    w_target = sched[k, 0]
    reason = -1
    if w_target <= 0.0:
        if gs_state != GS_OFF:
            gs_state = GS_OFF
            reason = R_SCHED_OFF
    elif gs_state == GS_OFF:
        gs_state = GS_STARTING
        reason = R_SCHED_ON
    if gs_state == GS_STARTING and w_gs >= 0.9 * w_target:
        gs_state = GS_RUNNING
        reason = R_STARTED
    thr = sched[k, 1] if gs_state == GS_RUNNING else 0.0
    return gs_state, thr, w_target, reason


@njit(cache=True)
def supervisor_replay(p, sched, k, soc, w_gs, gs_state):
    """Replay a DP optimum quasi-statically: ``sched[k] = (engine speed [rad/s], throttle [-],
    engine torque [N·m])``, speed 0 = off.

    The genset is running or off exactly as scheduled: no cranking, no speed loop (the
    genset step puts the engine at the scheduled point at once, as the DP's model does).
    """
    reason = -1
    if sched[k, 0] > 0.0:
        if gs_state != GS_RUNNING:
            gs_state = GS_RUNNING
            reason = R_SCHED_ON
    elif gs_state != GS_OFF:
        gs_state = GS_OFF
        reason = R_SCHED_OFF
    thr = sched[k, 1] if gs_state == GS_RUNNING else 0.0
    return gs_state, thr, sched[k, 0], reason


DRIVER_KINDS = ("proportional",)
SUPERVISOR_KINDS = ("thermostat", "schedule", "replay")
SUPERVISOR_REPLAY = 2
"""Code of the quasi-static replay supervisor (its genset has no shaft dynamics)."""


@njit(cache=True)
def drive(kind, p, v, v_target, v_target_prev, dt, f_res0, f_drive_max, m_eff):
    """Driver dispatcher (codes: :data:`DRIVER_KINDS`)."""
    return driver_proportional(p, v, v_target, v_target_prev, dt, f_res0, f_drive_max, m_eff)


@njit(cache=True)
def supervise(kind, p, sched, k, soc, w_gs, gs_state):
    """Supervisory-controller dispatcher (codes: :data:`SUPERVISOR_KINDS`)."""
    if kind == 1:
        return supervisor_schedule(p, sched, k, soc, w_gs, gs_state)
    if kind == SUPERVISOR_REPLAY:
        return supervisor_replay(p, sched, k, soc, w_gs, gs_state)
    return supervisor_thermostat(p, sched, k, soc, w_gs, gs_state)


# --- the steps of one integration interval ------------------------------------------------
# The series plug-in's step (hevsim.sim._compiled_series.series_drive) calls these in order.
# They are compiled without numba's reference counting
# (``_nrt=False``: they allocate nothing and only borrow the caller's arrays), so passing
# them the named table tuples costs no per-array reference counting, which inlining them
# into the loop did (+30 % time; with _nrt=False the split loop runs 0.8x the time of the
# single-function loop it replaced). The genset and bus steps write their own channels of
# row ``k`` of ``out`` when ``record`` is true; the plug-in's step writes the rest.
STEP_JIT: dict[str, Any] = {"cache": True, "_nrt": False}
BISECTION_STEPS = 60
"""Bisection steps that make a limit exact where the fixed-point scaling of a torque to a
power limit has not converged (an efficiency map): 2^-60 of the torque."""
LIMIT_RTOL = 1e-12
"""A torque scaled to a battery power limit stops within this fraction of it (below it)."""


@njit(**STEP_JIT)
def driver_step(p, mot, drv_kind, v, v_target, v_target_prev, grade_k, dt, m_eff):
    """Driver request ``u`` in [-1, 1] for the step to ``v_target`` [m/s].

    Evaluates the traction motor's torque limits at the start speed ``v`` [m/s] and the road
    load at rest acceleration (grade ``grade_k`` [-]), then calls the driver dispatcher.
    Returns (u, motor speed [rad/s], max motoring torque [N·m], max generating torque [N·m]).
    """
    r = p[RTIRE]
    ratio = p[RATIO]
    w_m0 = v / r * ratio
    m_max, m_min = torque_limits(w_m0, p[MSCALE], mot)
    f_res0 = road_load_force(
        v, 0.0, grade_k, p[MASS], p[MFACT], p[CD], p[AREA], p[RHO], p[WIND], p[CRR], p[CRRV]
    )
    f_drive_max = m_max * ratio * p[GEFF] / r
    u = drive(drv_kind, p, v, v_target, v_target_prev, dt, f_res0, f_drive_max, m_eff)
    return u, w_m0, m_max, m_min


@njit(**STEP_JIT)
def bus_limits(p, soc, ocv, r_b, ocv_c, r_c, dt, cap_as, i_dis_max, i_chg_max):
    """The battery's largest discharge and charge powers at its terminals this step [W].

    The discharge current is bounded by the step's limit ``i_dis_max`` [A] (the battery model's,
    :func:`hevsim.sim._loop.battery_begin`) and by the current that takes the SOC to
    ``soc_min`` within the step (eq 13), so no bus load (traction, genset cranking,
    auxiliaries) draws the pack below its floor; charging is bounded by ``i_chg_max`` [A], none
    at or above ``soc_max``. Returns (discharge power [W], charge power [W], the SOC floor binds).
    """
    i_dis = i_dis_max
    i_floor = (soc - p[SOCMIN]) * cap_as / dt
    # the floor binds below the current limit and the maximum-power current OCV / 2R
    at_floor = i_floor < i_dis and i_floor < ocv / (2.0 * r_b + 1e-300)
    if at_floor:
        i_dis = max(i_floor, 0.0)
    p_dis_max, p_chg_max = battery_power_limits(ocv, r_b, ocv_c, r_c, i_dis, i_chg_max)
    if soc >= p[SOCMAX]:
        p_chg_max = 0.0
    return p_dis_max, p_chg_max, at_floor


@njit(**STEP_JIT)
def genset_step(p, eng, gen, gs_state, thr_cmd, w_target, t_target, quasi_static, w_gs, dt, j_shaft,
                p_motoring_max):  # fmt: skip
    """Advance the genset shaft (engine + generator, 1:1) over one step of ``dt`` [s].

    An engine genset: the engine gives its torque at the commanded throttle; the generator
    holds the shaft speed on ``w_target`` [rad/s] with its proportional loop, treated
    implicitly (stable at any step), within its torque limits and, while it motors the shaft
    (cranking), within ``p_motoring_max`` [W], what the battery can give it; a stopped genset
    coasts down. ``quasi_static`` (the replay of a DP optimum): the running engine sits at
    ``w_target`` [rad/s] and ``t_target`` [N·m] (NaN: the torque at the throttle) for the whole
    step and the generator takes its torque, as in the DP's model (no shaft dynamics).
    The step's energy terms and channels are added by :func:`genset_account` once the bus
    balance has settled the generator's power (:func:`genset_limit` may lower it).
    Returns (fuel rate [kg/s], end speed [rad/s], generator electrical power [W] (> 0 drawn
    from the bus), current source on, engine fired, engine torque [N·m], generator torque
    [N·m], throttle [-], shaft speed of the record and of the fuel map [rad/s], shaft speed its
    powers are taken at [rad/s]).
    """
    t_eng = 0.0
    t_gen = 0.0
    thr = 0.0
    fuel_rate = 0.0
    w1 = w_gs
    w_pow = w_gs
    p_gen_el = 0.0
    source_on = False
    fired = False
    if p[GSKIND] == GENSET_ENGINE and quasi_static:
        thr = thr_cmd
        if gs_state == GS_RUNNING:
            w_gs = w_target
            fired = w_gs >= p[ESTALL] and w_gs <= p[ERED]
            t_eng = t_target
            if np.isnan(t_eng):
                t_eng = engine_torque(thr, w_gs, p[ETMAP] > 0, p[ESTALL], p[ERED], p[ESCALE], eng)
            t_gen = -t_eng
        else:
            w_gs = 0.0
        w1 = w_gs
        w_pow = w_gs
        fuel_rate = engine_fuel_rate(t_eng, w_gs, fired, p[EFMAP] > 0, p[ELHV], p[ESCALE], eng)
        eta_g = machine_efficiency(t_gen, w_gs, p[GKIND], p[GEFFM], p[GSCALE], gen)
        p_gen_el = electrical_power(t_gen, w_gs, eta_g)
    elif p[GSKIND] == GENSET_ENGINE:
        thr = thr_cmd
        fired = thr > 0.0 and w_gs >= p[ESTALL] and w_gs <= p[ERED]
        t_eng = engine_torque(thr, w_gs, p[ETMAP] > 0, p[ESTALL], p[ERED], p[ESCALE], eng)
        g_mot, g_gen = torque_limits(w_gs, p[GSCALE], gen)
        if gs_state == GS_OFF:
            t_gen = 0.0
            w1 = w_gs + dt / j_shaft * t_eng
            if w1 < 0.0:  # coasting engine stops: friction does exactly the remaining work
                w1 = 0.0
                t_eng = -w_gs * j_shaft / dt
        else:
            kgain = p[GSKP]
            # implicit proportional loop: J (w1 - w0)/dt = T_e + K (w* - w1) T_lim
            t_lim = g_mot if w_target >= w_gs else -g_gen
            kk = kgain * t_lim
            w1 = (w_gs + dt / j_shaft * (t_eng + kk * w_target)) / (1.0 + dt * kk / j_shaft)
            ug = kgain * (w_target - w1)
            if ug > 1.0 or ug < -1.0:
                t_gen = g_mot if ug > 0 else g_gen
                w1 = w_gs + dt / j_shaft * (t_eng + t_gen)
            else:
                t_gen = ug * t_lim
            if w1 < 0.0:
                w1 = 0.0
                t_gen = -w_gs * j_shaft / dt - t_eng
            elif t_gen > 0.0:  # motoring: no more than the battery can give (its SOC floor)
                for _ in range(REGEN_ITERATIONS):
                    p_el = machine_power(t_gen, 0.5 * (w_gs + w1), p[GKIND], p[GEFFM], p[GSCALE], gen)
                    if p_el <= p_motoring_max or p_el <= 0.0:
                        break
                    t_gen *= max(p_motoring_max, 0.0) / p_el
                    w1 = w_gs + dt / j_shaft * (t_eng + t_gen)
                    if w1 < 0.0:  # the shaft stops: engine friction does exactly the remaining work
                        w1 = 0.0
                        t_eng = -w_gs * j_shaft / dt - t_gen
        w_pow = 0.5 * (w_gs + w1)
        fuel_rate = engine_fuel_rate(t_eng, w_gs, fired, p[EFMAP] > 0, p[ELHV], p[ESCALE], eng)
        eta_g = machine_efficiency(t_gen, w_pow, p[GKIND], p[GEFFM], p[GSCALE], gen)
        p_gen_el = electrical_power(t_gen, w_pow, eta_g)
    elif p[GSKIND] == GENSET_CURRENT_SOURCE and gs_state == GS_RUNNING:
        source_on = True  # its power is set once the bus voltage is known
    return fuel_rate, w1, p_gen_el, source_on, fired, t_eng, t_gen, thr, w_gs, w_pow


@njit(**STEP_JIT)
def genset_limit(
    p, eng, gen, t_eng, t_gen, thr, fired, w_gs, w1, w_pow, quasi_static, dt, j_shaft, p_gen_min
):
    """Lower a generating genset's electrical output to ``-p_gen_min`` [W] (``p_gen_min`` the
    least generator power, > 0 drawn, the bus can take: the battery's charge limit less the
    rest of the bus), the genset's power request clipped: the engine backs off its torque by
    what the generator no longer takes (the shaft keeps its path) down to zero torque, below
    which the shaft keeps the energy (it speeds up). Exact: after the fixed-point scaling a
    bisection on the generator torque keeps the feasible end.

    ``t_eng``, ``t_gen`` [N·m], throttle ``thr``, start/end speeds ``w_gs``, ``w1`` and the
    power speed ``w_pow`` [rad/s] as returned by :func:`genset_step`. Returns (fuel rate
    [kg/s], end speed [rad/s], generator electrical power [W], engine torque [N·m], generator
    torque [N·m], throttle [-], power speed [rad/s]).
    """
    t_sum = t_eng + t_gen
    t_eng_min = min(t_eng, 0.0)
    args = (t_sum, t_eng_min, quasi_static, w_gs, w1, w_pow, dt, j_shaft)
    t_e, w_e, w_p, p_el = _genset_at(p, gen, t_gen, *args)
    if p_gen_min >= 0.0:
        t_gen = 0.0
        t_e, w_e, w_p, p_el = _genset_at(p, gen, t_gen, *args)
    else:
        for _ in range(REGEN_ITERATIONS):
            if p_el >= p_gen_min or p_el >= 0.0:
                break
            t_gen *= p_gen_min / p_el
            t_e, w_e, w_p, p_el = _genset_at(p, gen, t_gen, *args)
        if p_el < p_gen_min:  # not converged (an efficiency map): bisect, keep the feasible end
            lo, hi = t_gen, 0.0
            for _ in range(BISECTION_STEPS):
                mid = 0.5 * (lo + hi)
                if _genset_at(p, gen, mid, *args)[3] >= p_gen_min:
                    hi = mid
                else:
                    lo = mid
            t_gen = hi
            t_e, w_e, w_p, p_el = _genset_at(p, gen, t_gen, *args)
    if t_e < t_eng and t_eng > 0.0:
        thr *= t_e / t_eng  # recorded throttle: the engine's share backed off
    fuel_rate = engine_fuel_rate(t_e, w_gs, fired, p[EFMAP] > 0, p[ELHV], p[ESCALE], eng)
    return fuel_rate, w_e, p_el, t_e, t_gen, thr, w_p


@njit(**STEP_JIT)
def _genset_at(p, gen, t_g, t_sum, t_eng_min, quasi_static, w_gs, w1, w_pow, dt, j_shaft):
    """:func:`genset_limit`'s genset at generator torque ``t_g`` [N·m]: (engine torque [N·m],
    end speed, power speed [rad/s], generator electrical power [W])."""
    t_e = max(t_sum - t_g, t_eng_min)
    if quasi_static:
        w_e, w_p = w1, w_pow
    else:
        w_e = max(w_gs + dt / j_shaft * (t_e + t_g), 0.0)
        w_p = 0.5 * (w_gs + w_e)
    return t_e, w_e, w_p, machine_power(t_g, w_p, p[GKIND], p[GEFFM], p[GSCALE], gen)


@njit(**STEP_JIT)
def genset_account(p, fuel_rate, t_eng, t_gen, thr, w_gs, w1, w_pow, p_gen_el, quasi_static, dt, j_shaft,
                   energy, record, out, k):  # fmt: skip
    """Add the genset's fuel, engine, generator and shaft kinetic terms of the step to
    ``energy`` [J] and write its channels of row ``k`` of ``out`` (``record``); arguments as
    returned by :func:`genset_step` / :func:`genset_limit`."""
    if p[GSKIND] == GENSET_ENGINE:
        energy[E_FUEL] += fuel_rate * p[ELHV] * dt
        energy[E_ENG] += (fuel_rate * p[ELHV] - t_eng * w_pow) * dt
        energy[E_GEN] += (p_gen_el - t_gen * w_pow) * dt
        if not quasi_static:
            energy[E_KING] += 0.5 * j_shaft * (w1 * w1 - w_gs * w_gs)
    if record:
        out[k, CH_GENERATOR_TORQUE_NM] = t_gen
        out[k, CH_GENERATOR_POWER_ELEC_W] = p_gen_el
        out[k, CH_ENGINE_SPEED_RADPS] = w_gs
        out[k, CH_ENGINE_TORQUE_NM] = t_eng
        out[k, CH_ENGINE_THROTTLE] = thr
        out[k, CH_ENGINE_POWER_W] = t_eng * w_gs
        out[k, CH_FUEL_RATE_KGPS] = fuel_rate


@njit(**STEP_JIT)
def traction_step(p, mot, u, v, w_m0, m_max, m_min, p_gen_el, source_on, ocv, p_dis_max, p_chg_max, p_aux):
    """Motor torque for the driver request ``u`` within the battery's limits (the bus balance
    of :mod:`hevsim.components.bus`), and the forces it puts on the wheels.

    ``p_dis_max``, ``p_chg_max``: the battery's power limits of :func:`bus_limits` [W];
    ``p_aux``: the bus's auxiliary load of the step [W].
    Returns (motor torque [N·m], motor force at the wheels [N], friction brake force [N],
    limited, the rest of the bus load [W] (> 0 drawn), the driver's brake force request [N]).
    """
    r = p[RTIRE]
    ratio = p[RATIO]
    f_brake_req = 0.0
    if u >= 0.0:
        t_m = u * m_max
    else:
        f_brake_req = -u * p[FBRAKE]
        t_regen_req = -f_brake_req * r / ratio * p[GEFF]  # motor torque for the full request
        t_m = regen_torque(t_regen_req, m_min, v > p[REGENV])
    # the bus balance (components.bus): battery power limits bound the motor's torque
    p_other = p_gen_el + p_aux
    if source_on:
        p_other -= ocv * p[GSCUR]
    p_m_el0 = machine_power(t_m, w_m0, p[MKIND], p[MEFF], p[MSCALE], mot)
    limited = 0.0
    if needs_limit(t_m, p_m_el0, p_other, p_dis_max, p_chg_max):
        t_m, _, _ = limit_machine_torque(
            t_m, p_m_el0, w_m0, p_other, p_dis_max, p_chg_max, p[MKIND], p[MEFF], p[MSCALE], mot
        )
        limited = 1.0
    f_motor = gear_output_torque(t_m, ratio, p[GEFF]) / r
    f_fric = max(f_brake_req + min(f_motor, 0.0), 0.0) if u < 0.0 else 0.0
    return t_m, f_motor, f_fric, limited, p_other, f_brake_req


@njit(**STEP_JIT)
def traction_limit_step(p, mot, t_m, u, f_brake_req, v, v1, a, f_aero, f_roll, f_grade, f_fric, p_other,
                        p_dis_max, p_chg_max, grade_k, m_eff, dt):  # fmt: skip
    """The battery's limits at the speed the motor's power is taken at: :func:`traction_step`
    limits the torque at the start speed ``v`` [m/s], :func:`bus_step` takes its power at the
    mid-step speed; where that power leaves the battery beyond ``p_dis_max`` or
    ``p_chg_max`` [W] with the rest of the bus ``p_other`` [W], the motoring torque (or the
    regeneration, the friction brakes taking the rest of the driver's ``f_brake_req`` [N]) is
    scaled at the mid-step speed of the step it makes (:func:`vehicle_step` again), and a
    bisection on the torque keeps the feasible end where the fixed-point scaling has not
    converged (efficiency maps). Then the motor's own torque limits are checked at the
    mid-step speed too (:func:`_torque_limit_mid`). Nothing changes where the limits hold.

    ``v1``, ``a``, ``f_aero`` .. ``f_fric``: :func:`vehicle_step`'s values for ``t_m``.
    Returns (torque [N·m], wheel force [N], friction force [N], acceleration [m/s^2], end
    speed [m/s], aero, rolling, grade forces [N], limited, the motor's electrical power [W]).
    """
    r = p[RTIRE]
    ratio = p[RATIO]
    hi = p_dis_max - p_other
    lo = -p_chg_max - p_other
    f_motor = gear_output_torque(t_m, ratio, p[GEFF]) / r
    p_el = machine_power(t_m, 0.5 * (v + v1) / r * ratio, p[MKIND], p[MEFF], p[MSCALE], mot)
    t0 = t_m
    if not needs_limit(t_m, p_el, p_other, p_dis_max, p_chg_max):
        return _torque_limit_mid(p, mot, t_m, u, f_brake_req, v, v1, a, f_aero, f_roll, f_grade, f_fric,
                                 f_motor, p_el, hi, lo, grade_k, m_eff, dt, t0)  # fmt: skip
    target = max(hi, 0.0) if t_m > 0.0 else min(lo, 0.0)
    good, bad = 0.0, t_m  # feasible and infeasible torques bracketing the limit
    feasible = False
    for _ in range(REGEN_ITERATIONS):  # fixed point t <- t target / P(t), from either side
        t_m *= target / p_el
        f_motor, f_fric, a, v1, f_aero, f_roll, f_grade, p_el = _traction_at(
            p, mot, t_m, u, f_brake_req, v, grade_k, m_eff, dt
        )
        feasible = t_m == 0.0 or (p_el <= hi if t_m > 0.0 else p_el >= lo)
        if feasible:
            good = t_m if abs(t_m) > abs(good) else good
            if t_m == 0.0 or abs(p_el - target) <= LIMIT_RTOL * abs(target):
                break
        else:
            bad = t_m if abs(t_m) < abs(bad) else bad
    if not feasible:  # not converged (an efficiency map): bisect, keep the feasible end
        for _ in range(BISECTION_STEPS):
            mid = 0.5 * (good + bad)
            p_mid = _traction_at(p, mot, mid, u, f_brake_req, v, grade_k, m_eff, dt)[7]
            if p_mid <= hi if mid > 0.0 else p_mid >= lo:
                good = mid
            else:
                bad = mid
        t_m = good
        f_motor, f_fric, a, v1, f_aero, f_roll, f_grade, p_el = _traction_at(
            p, mot, t_m, u, f_brake_req, v, grade_k, m_eff, dt
        )
    return _torque_limit_mid(p, mot, t_m, u, f_brake_req, v, v1, a, f_aero, f_roll, f_grade, f_fric, f_motor,
                             p_el, hi, lo, grade_k, m_eff, dt, t0)  # fmt: skip


@njit(**STEP_JIT)
def _within(p, mot, t_m, p_el, v, v1, hi, lo):
    """The motor's torque ``t_m`` [N·m] within its limits at the mid-step speed of ``v``,
    ``v1`` [m/s] and its electrical power ``p_el`` [W] within ``lo`` .. ``hi`` (zero torque
    always is)."""
    if t_m == 0.0:
        return True
    t_hi, t_lo = torque_limits(0.5 * (v + v1) / p[RTIRE] * p[RATIO], p[MSCALE], mot)
    if t_m > 0.0:
        return t_m <= t_hi * (1.0 + TORQUE_RTOL) and p_el <= hi
    return t_m >= t_lo * (1.0 + TORQUE_RTOL) and p_el >= lo


@njit(**STEP_JIT)
def _torque_limit_mid(p, mot, t_m, u, f_brake_req, v, v1, a, f_aero, f_roll, f_grade, f_fric, f_motor, p_el,
                      hi, lo, grade_k, m_eff, dt, t0):  # fmt: skip
    """:func:`traction_limit_step`'s last stage: the motor's own torque limits at the mid-step
    speed (:func:`driver_step` read them at the start speed; in the constant-power region the
    mid-step limit of an accelerating car is lower). A torque beyond them goes to the limit
    at the mid-step speed of the step it makes (a bisection keeps the feasible side)."""
    if _within(p, mot, t_m, p_el, v, v1, hi, lo):
        return t_m, f_motor, f_fric, a, v1, f_aero, f_roll, f_grade, t_m != t0, p_el
    t_hi, t_lo = torque_limits(0.5 * (v + v1) / p[RTIRE] * p[RATIO], p[MSCALE], mot)
    good, bad = 0.0, t_m
    trial = min(t_m, t_hi) if t_m > 0.0 else max(t_m, t_lo)  # the limit at this step's mid speed
    for _ in range(BISECTION_STEPS):
        g = _traction_at(p, mot, trial, u, f_brake_req, v, grade_k, m_eff, dt)
        if _within(p, mot, trial, g[7], v, g[3], hi, lo):
            good = trial
        else:
            bad = trial
        if abs(bad - good) <= LIMIT_RTOL * abs(t_m):
            break
        trial = 0.5 * (good + bad)
    t_m = good
    f_motor, f_fric, a, v1, f_aero, f_roll, f_grade, p_el = _traction_at(
        p, mot, t_m, u, f_brake_req, v, grade_k, m_eff, dt
    )
    return t_m, f_motor, f_fric, a, v1, f_aero, f_roll, f_grade, True, p_el


@njit(**STEP_JIT)
def _traction_at(p, mot, t_m, u, f_brake_req, v, grade_k, m_eff, dt):
    """:func:`traction_limit_step`'s step at motor torque ``t_m`` [N·m]: (wheel force,
    friction force [N], then :func:`vehicle_step`'s acceleration, end speed and forces, the
    motor's electrical power at the mid-step speed [W])."""
    r = p[RTIRE]
    ratio = p[RATIO]
    f_motor = gear_output_torque(t_m, ratio, p[GEFF]) / r
    f_fric = max(f_brake_req + min(f_motor, 0.0), 0.0) if u < 0.0 else 0.0
    a, v1, f_aero, f_roll, f_grade, f_fric = vehicle_step(p, v, f_motor, f_fric, grade_k, m_eff, dt)
    p_el = machine_power(t_m, 0.5 * (v + v1) / r * ratio, p[MKIND], p[MEFF], p[MSCALE], mot)
    return f_motor, f_fric, a, v1, f_aero, f_roll, f_grade, p_el


@njit(**STEP_JIT)
def vehicle_step(p, v, f_motor, f_fric, grade_k, m_eff, dt):
    """Longitudinal dynamics, eq (1): explicit Euler with the forces at the start speed ``v``.

    At rest, rolling resistance and the brakes hold the car; a car that would reverse within
    the step stops, the brakes then rolling resistance doing the remaining work. Returns
    (acceleration [m/s^2], end speed [m/s], aero, rolling, grade and friction forces [N]).
    """
    f_aero = aero_force(v, p[WIND], p[CD], p[AREA], p[RHO])
    f_grade = grade_force(p[MASS], grade_k)
    f_roll_mag = rolling_force(p[MASS], grade_k, p[CRR], p[CRRV], v)
    f_roll = f_roll_mag
    net = f_motor - f_aero - f_grade
    if v <= 0.0 and abs(net) <= f_roll_mag + f_fric:
        f_roll = net  # at rest: rolling resistance and brakes hold the car (no work done)
        f_fric = 0.0
        a = 0.0
    elif v <= 0.0:
        f_roll = f_roll_mag * np.sign(net)
        a = (net - f_roll - f_fric * np.sign(net)) / m_eff
    else:
        a = (net - f_fric - f_roll) / m_eff
    v1 = v + a * dt
    if v1 < 0.0:  # the car stops within the step: brakes then rolling do the remaining work
        a_new = -v / dt
        excess = (a_new - a) * m_eff  # force to give back (> 0)
        give = min(excess, f_fric)
        f_fric -= give
        excess -= give
        f_roll -= excess
        a = a_new
        v1 = 0.0
    return a, v1, f_aero, f_roll, f_grade, f_fric


@njit(**STEP_JIT)
def floor_traction_step(p, mot, t_m, v, v1, p_other, p_dis_max, grade_k, m_eff, dt):
    """At the SOC floor: the motoring torque ``t_m`` [N·m] scaled so that the motor's power at
    the mid-step speed (not only at the start speed ``v`` [m/s], where a car at rest draws
    nothing) stays within what the battery can give, ``p_dis_max - p_other`` [W].

    Returns (torque [N·m], wheel force [N], then :func:`vehicle_step`'s values, limited) for
    the torque finally applied.
    """
    r = p[RTIRE]
    ratio = p[RATIO]
    hi = p_dis_max - p_other
    f_motor = gear_output_torque(t_m, ratio, p[GEFF]) / r
    a, v1, f_aero, f_roll, f_grade, f_fric = vehicle_step(p, v, f_motor, 0.0, grade_k, m_eff, dt)
    limited = False
    for _ in range(REGEN_ITERATIONS):
        p_el = machine_power(t_m, 0.5 * (v + v1) / r * ratio, p[MKIND], p[MEFF], p[MSCALE], mot)
        if p_el <= hi or p_el <= 0.0:
            break
        t_m *= max(hi, 0.0) / p_el
        limited = True
        f_motor = gear_output_torque(t_m, ratio, p[GEFF]) / r
        a, v1, f_aero, f_roll, f_grade, f_fric = vehicle_step(p, v, f_motor, 0.0, grade_k, m_eff, dt)
    return t_m, f_motor, a, v1, f_aero, f_roll, f_grade, f_fric, limited


@njit(**STEP_JIT)
def bus_step(p, mot, t_m, v_mid, p_gen_el, source_on, ocv, r_b, ocv_c, r_c, p_dis_max, p_chg_max, p_aux,
             at_floor, exact, soc, dt, cap_as, energy, record, out, k):  # fmt: skip
    """Close the DC bus at the mid-step speed ``v_mid`` [m/s]: motor electrical power, battery
    current (eqs 21-22) and SOC (eq 13); adds the battery, source, motor and auxiliary terms to
    ``energy`` [J]. Where the SOC floor binds (``at_floor``, :func:`bus_limits`) the
    auxiliaries get only what the battery can still give within ``p_dis_max`` [W] (shed).
    ``exact`` (a pack's BMS, :func:`hevsim.battery.vehicle.vehicle_bus_has_bms`): the same wherever the
    discharge limit
    ``p_dis_max`` still binds with the motor and the genset at their limits, and a
    current-source genset gives no more than the battery can take within ``p_chg_max`` [W].

    Returns (motor mechanical and electrical power [W], current-source power [W], SOC at the
    end of the step [-] (the charge counted with ``cap_as`` [A·s]: a table battery's; a cell or
    pack battery's own step gives its SOC), battery current [A], battery terminal power [W],
    battery-limited: beyond the deliverable power or auxiliaries shed).
    """
    w_m = v_mid / p[RTIRE] * p[RATIO]
    eta_m = machine_efficiency(t_m, w_m, p[MKIND], p[MEFF], p[MSCALE], mot)
    p_m_mech = t_m * w_m
    p_m_el = electrical_power(t_m, w_m, eta_m)
    p_src = ocv * p[GSCUR] if source_on else 0.0
    p_bat = p_m_el + p_gen_el + p_aux - p_src
    shed = 0.0
    if (at_floor or exact) and p_bat > p_dis_max and p_aux > 0.0:  # at the limit: auxiliaries shed
        shed = min(p_aux, p_bat - p_dis_max)
        p_aux -= shed
        p_bat -= shed
    if exact and p_bat < -p_chg_max and p_src > 0.0:  # at the charge limit: the current source clipped
        cut = min(p_src, -p_chg_max - p_bat)
        p_src -= cut
        p_bat += cut
        shed += cut
    # the discharge and charge states were evaluated at the start of the step (bus_limits)
    i_bat, ocv_b, r_bat, over_power = bus_current(p_bat, ocv, r_b, ocv_c, r_c)
    v_bat = ocv_b - r_bat * i_bat
    i_soc = charge_current(i_bat, p[BCEFF])
    soc1 = soc - i_soc * dt / cap_as
    e_chem = ocv_b * i_soc * dt
    energy[E_BATT] += e_chem
    energy[E_BLOSS] += e_chem - v_bat * i_bat * dt
    energy[E_GSRC] += p_src * dt
    energy[E_MOT] += (p_m_el - p_m_mech) * dt
    energy[E_AUX] += p_aux * dt
    # the battery terminal energy not matched by bus loads is numerical slack (sagging bus)
    energy[E_BLOSS] += (v_bat * i_bat - p_bat) * dt
    if record:
        out[k, CH_MOTOR_SPEED_RADPS] = w_m
        out[k, CH_MOTOR_TORQUE_NM] = t_m
        out[k, CH_MOTOR_POWER_MECH_W] = p_m_mech
        out[k, CH_MOTOR_POWER_ELEC_W] = p_m_el
        out[k, CH_MOTOR_CURRENT_A] = p_m_el / v_bat if v_bat > 0 else 0.0
        out[k, CH_GENERATOR_CURRENT_A] = (p_gen_el - p_src) / v_bat if v_bat > 0 else 0.0
        out[k, CH_BATTERY_CURRENT_A] = i_bat
        out[k, CH_BATTERY_VOLTAGE_V] = v_bat
        out[k, CH_BATTERY_OCV_V] = ocv_b
        out[k, CH_BATTERY_RESISTANCE_OHM] = r_bat
        out[k, CH_BATTERY_POWER_W] = p_bat
    return p_m_mech, p_m_el, p_src, soc1, i_bat, p_bat, over_power or shed > 0.0


@njit(**STEP_JIT)
def mode_step(p, mode, reason, new_reason, u, v, p_m_el, p_gen_el, p_src):
    """Power mode of Table 2.1 and the reason of the latest change (a supervisor's state
    change ``new_reason`` >= 0 wins). Returns (mode, reason)."""
    p_supply = -p_gen_el + p_src
    new_mode = mode
    mode_reason = -1
    if p_m_el < 0.0 or (u < 0.0 and v > 0.0):
        new_mode, mode_reason = MODE_CHARGING, R_REGEN
    elif p_supply <= 0.0:
        new_mode, mode_reason = MODE_PURE_EV, R_EV
    elif abs(p_supply - p_m_el) <= p[PICEBAND]:
        new_mode, mode_reason = MODE_PURE_ICE, R_PUREICE
    elif p_supply > p_m_el:
        new_mode, mode_reason = MODE_ICE_CHARGING, R_ICECHG
    else:
        new_mode, mode_reason = MODE_COMBINED, R_COMBINED
    if new_reason >= 0:
        reason = new_reason
    elif new_mode != mode:
        reason = mode_reason
    return new_mode, reason

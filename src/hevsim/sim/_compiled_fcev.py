"""The fuel-cell vehicle's plug-in of the one compiled forward loop
(:func:`hevsim.sim._loop.run_loop`, issue 24), with its ``load_follower`` controller (ECMS,
A-ECMS and schedule replays run the Python loop: :func:`simulate_compiled` returns None).

The power flow is the BEV's (:func:`hevsim.architectures.bev.wheel_point`,
:func:`~hevsim.architectures.bev.point_losses`, the HEV plug-in's bus balance ``_electric`` and
feasibility ``_feasible``) with the fuel cell's net power on the bus (the bus's other load is
``aux - P_fc``, as :func:`hevsim.architectures.fcev.power_flow`) and its hydrogen from the
scalar kernels of :mod:`hevsim.components.fuel_cell`. The controller's rule is
:class:`hevsim.control.simple.LoadFollower`'s: the load-following target clipped to the ramp
window, else the window's feasible power nearest to it (:data:`WINDOW_POINTS` candidates),
else the highest feasible of :func:`hevsim.architectures.fcev.shed_controls` (counted in
``ramp_down_overrides``).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from hevsim.architectures import bev as B
from hevsim.architectures import fcev as F
from hevsim.architectures._common import NO_REFCOUNT, max_machine_speed_radps
from hevsim.components.fuel_cell import (
    RUNNING_ZERO_W,
    hydrogen_power_point,
    ramp_window_point,
    reachable_point,
    reachable_window_point,
)
from hevsim.control.simple import LoadFollower, forced_on
from hevsim.sim import kernel as K
from hevsim.sim._compiled_bev import WheelData
from hevsim.sim._compiled_hev import _electric, _feasible
from hevsim.sim._loop import (
    AUDIT_BASE,
    BASE_COLUMNS,
    ERR_STUCK,
    audit_slots,
    constants,
    grid_arrays,
    pack_arrays,
    register,
    run_loop,
    threaded_batch,
    writable,
)
from hevsim.sim._records import BatchRecord, ForwardRecord
from hevsim.sim.checks import stuck_error

DETAILS: tuple[str, ...] = (
    "fuel_cell_power_w", "fuel_cell_efficiency", "hydrogen_rate_kgps", "motor_speed_radps", "motor_torque_nm",
    "motor_power_elec_w", "battery_current_a", "battery_power_w", "friction_brake_power_w",
)  # fmt: skip
"""The FCEV power flow's channels, in the Python loop's order."""
COLUMNS: tuple[str, ...] = (
    *BASE_COLUMNS, *DETAILS, "power_mode", "traction_limited", "battery_ocv_v", "battery_voltage_v",
)  # fmt: skip
"""Time-series channels of a run (:class:`~hevsim.sim.forward.ForwardRecord`), in order."""
AUDIT: tuple[str, ...] = (*AUDIT_BASE, *F.LOSSES[1:-1], "battery_loss")
"""Energy-audit terms of a run [J], in the Python loop's order."""
SLOTS = audit_slots(F.LOSSES, AUDIT)
"""Audit index of each of :data:`hevsim.architectures.fcev.LOSSES`."""
WINDOW_POINTS = LoadFollower.WINDOW_POINTS
"""Candidate powers across the ramp window when the clipped target is infeasible."""
OFF_RTOL = 1e-12
"""Relative round-off [-] of idle and rating in the fuel cell's power range (as
:func:`hevsim.architectures.fcev.power_flow`)."""

ARCHITECTURES = ("fcev",)
"""The architectures this compiled loop runs (:func:`hevsim.sim.forward.compiled_loop`)."""


class FCEVPlug(NamedTuple):
    """The FCEV's plug-in of :func:`hevsim.sim._loop.run_loop`: the wheel side
    (:class:`~hevsim.sim._compiled_bev.WheelData`), the machine's tables, the fuel cell (efficiency
    curve over the net power fraction [-], rating and idle [W], ramp limits [W/s], LHV [J/kg], idle
    hydrogen power [W]) and the load follower (mid SOC and half band [-], charging power [W], the
    model's own auxiliary load [W] its target adds, forced-on speed [m/s] and minimum on-time [s])."""

    wd: WheelData
    mtab: Any
    power_fraction: np.ndarray
    efficiency_curve: np.ndarray
    max_power_w: float
    min_power_w: float
    ramp_up_w_per_s: float
    ramp_down_w_per_s: float
    lhv_jpkg: float
    soc_mid: float
    half_band: float
    charge_power_w: float
    base_aux_w: float
    idle_fuel_power_w: float
    on_speed_mps: float
    min_on_time_s: float


@njit(cache=True, inline="always", error_model="numpy")
def _fc_point(p_fc, w_wheel, t_wheel, regen_ok, soc, dt, bat, hk, plug):
    """The power flow at one fuel-cell net power ``p_fc`` [W] (as
    :func:`hevsim.architectures.fcev.power_flow` and the forward driver's feasibility): (feasible,
    machine torque [N·m], electrical power [W], battery power [W], current [A], SOC change [-],
    machine speed [rad/s], final-drive input torque [N·m])."""
    wd = plug.wd
    w_m, t_fd, t_req, ok, over = B.wheel_point(
        w_wheel, t_wheel, regen_ok, wd.fd_ratio, wd.fd_efficiency, wd.regen_fraction, wd.regen_min_speed_mps,
        hk.radius_m, wd.w_max_radps,
    )  # fmt: skip
    ocv, r_dis, r_chg, p_chg, _ = bat
    oth, inf, t, p_el, p_bat, cur, d_soc = _electric(
        t_req, w_m, hk.aux_power_w - p_fc, ok, soc, dt, ocv, r_dis, r_chg, p_chg, hk, plug.mtab
    )
    oor = (p_fc < plug.min_power_w * (1.0 - OFF_RTOL) and p_fc != 0.0) or p_fc > plug.max_power_w * (
        1.0 + OFF_RTOL
    )
    feasible = _feasible(inf or over or oor, oth or over or oor, cur, t, p_bat, p_el, soc, hk)
    return feasible, t, p_el, p_bat, cur, d_soc, w_m, t_fd


@njit(cache=True, inline="always")
def _linspace(lo, hi, n, i):
    """Point ``i`` of ``np.linspace(lo, hi, n)``, bit for bit."""
    if i == n - 1:
        return hi
    step = (hi - lo) / (n - 1)
    if step == 0.0:
        return i / (n - 1) * (hi - lo) + lo
    return i * step + lo


@njit(cache=True, error_model="numpy", **NO_REFCOUNT)
def fcev_choose(plug, state, work, v_mid, w_wheel, t_wheel, soc, dt, e_soc, bat, hk):
    """The plug-in's ``choose`` (:mod:`hevsim.sim._loop`): :meth:`LoadFollower.choose
    <hevsim.control.simple.LoadFollower.choose>` from the previous net power ``state[0]`` [W]
    and time on ``state[3]`` [s]; the second control is 1 where the fuel cell sheds power faster
    than its ramp-down limit."""
    regen_ok = v_mid > 0.0
    prev = state[0]
    p_min, p_max, ru, rd = plug.min_power_w, plug.max_power_w, plug.ramp_up_w_per_s, plug.ramp_down_w_per_s
    lo, hi = ramp_window_point(prev, dt, p_min, p_max, ru, rd)
    floor = RUNNING_ZERO_W if forced_on(v_mid, state[3], dt, plug.on_speed_mps, plug.min_on_time_s) else 0.0
    lo, hi = max(lo, floor), max(hi, floor)
    load = _fc_point(0.0, w_wheel, t_wheel, regen_ok, soc, dt, bat, hk, plug)[2] + plug.base_aux_w
    corr = 0.0
    if plug.half_band > 0:
        corr = min(max((plug.soc_mid - soc) / plug.half_band, -1.0), 1.0)
    target = min(max(load + plug.charge_power_w * corr, lo), hi)
    if _fc_point(target, w_wheel, t_wheel, regen_ok, soc, dt, bat, hk, plug)[0]:
        return True, target, 0.0, False, 0.0, 0.0
    best, best_d, best_p = -1, np.inf, 0.0
    for i in range(WINDOW_POINTS):  # the window's feasible power nearest to the target (the first)
        p = _linspace(lo, hi, WINDOW_POINTS, i)
        if _fc_point(p, w_wheel, t_wheel, regen_ok, soc, dt, bat, hk, plug)[0]:
            d = abs(p - target)
            if best < 0 or d < best_d:
                best, best_d, best_p = i, d, p
    if best >= 0:
        return True, best_p, 0.0, False, 0.0, 0.0
    low = reachable_window_point(prev, dt, p_min, p_max, ru, rd)[0]
    top = max(low, p_min)
    for i in range(F.SHED_POINTS, -1, -1):  # shed_controls: off, then idle..top; the highest feasible
        p = max(0.0 if i == 0 else _linspace(p_min, top, F.SHED_POINTS, i - 1), floor)
        if _fc_point(p, w_wheel, t_wheel, regen_ok, soc, dt, bat, hk, plug)[0]:
            shed = not reachable_point(prev, dt, p, p_min, p_max, ru, rd)
            return True, p, 1.0 if shed else 0.0, False, 0.0, 0.0
    return False, 0.0, 0.0, False, 0.0, 0.0


@njit(cache=True, inline="always", error_model="numpy")
def fcev_point(plug, state, work, c0, c1, v_mid, w_wheel, t_wheel, soc, dt, bat, hk):
    """The plug-in's ``point`` at the net power ``c0`` [W]: the details (:data:`DETAILS`) and
    audit powers (:data:`hevsim.architectures.fcev.LOSSES`) into ``work``, the shed flag ``c1``
    into ``state[2]``; (hydrogen [kg], SOC change [-])."""
    det, loss = work
    wd = plug.wd
    _, t_m, p_el, p_bat, cur, d_soc, w_m, t_fd = _fc_point(c0, w_wheel, t_wheel, v_mid > 0.0, soc, dt, bat,
                                                          hk, plug)  # fmt: skip
    q = B.point_losses(w_wheel, w_m, t_fd, t_m, p_el, wd.fd_ratio, wd.fd_efficiency, hk.aux_power_w)
    eta, h2_w = hydrogen_power_point(
        c0, plug.max_power_w, plug.power_fraction, plug.efficiency_curve, plug.idle_fuel_power_w
    )
    rate = h2_w / plug.lhv_jpkg
    loss[0], loss[1] = h2_w, h2_w - c0
    for j in range(1, len(q)):
        loss[j + 1] = q[j]
    det[0], det[1], det[2], det[3], det[4] = c0, eta, rate, w_m, t_m
    det[5], det[6], det[7], det[8] = p_el, cur, p_bat, q[2]
    state[2] = c1
    return rate * dt, d_soc


@njit(cache=True, inline="always", error_model="numpy")
def fcev_commit(plug, state, work, v_mid, f, soc, dt, e_soc, hk, has_pack):
    """The plug-in's ``commit``: the net power applied becomes the ramp limits' start, the time
    on grows by the step (0 when off), a shed step is counted (:meth:`LoadFollower.update
    <hevsim.control.simple.LoadFollower.update>`); (engine on: never, power mode, battery power
    [W], current [A], wheel power [W])."""
    det, loss = work
    state[0] = det[0]
    state[3] = state[3] + dt if det[0] > 0.0 else 0.0
    state[1] += state[2]
    return False, float(B.power_mode_code(det[4], f, v_mid)), det[7], det[6], loss[loss.shape[0] - 1]


register(FCEVPlug, fcev_choose, fcev_point, fcev_commit)


def _run(
    model: F.FCEV, grid: Any, ctl: LoadFollower, soc0: float, soc_min: float, soc_max: float, pack: Any = None
) -> tuple[Any, ...]:
    """One compiled run: (channel names, channels (:data:`COLUMNS` x n + 1), audit names,
    audit [J], summary, end speed [m/s]); the controller left as the Python loop leaves it."""
    fd, fc = model.final_drive, model.fuel_cell
    wd = WheelData(float(fd.ratio), float(fd.efficiency), float(model.regen_fraction),
                   float(model.regen_min_speed_mps), float(max_machine_speed_radps(model.motor)))  # fmt: skip
    plug = FCEVPlug(
        wd, writable(model.motor.kernel_tables()), np.require(fc.power_fraction, np.float64, ("C", "W")),
        np.require(fc.efficiency_curve, np.float64, ("C", "W")), float(fc.max_power_w), float(fc.min_power_w),
        float(fc.ramp_up_w_per_s), float(fc.ramp_down_w_per_s), float(fc.lhv_j_per_kg), float(ctl.soc_mid),
        float(ctl.half_band), float(ctl.charge_power), float(ctl.model.aux_power_w),
        float(fc.idle_fuel_power_w), float(ctl.on_speed), float(ctl.min_on_time),
    )  # fmt: skip
    ctl.reset(float(soc0))
    t, v_des, gr = grid_arrays(grid)
    cols = np.zeros((len(COLUMNS), t.size))
    audit = np.zeros(len(AUDIT))
    summary = np.zeros(len(K.SUMMARY))
    # previous net power [W], shed steps, shed flag, time on [s]
    state = np.array([ctl.previous_w, 0.0, 0.0, ctl.on_time_s])
    det, loss = np.zeros(len(DETAILS)), np.zeros(len(F.LOSSES))
    status, k, v_end, _ = run_loop(
        plug, float(soc0), t, v_des, gr, constants(model, soc_min, soc_max, lhv_jpkg=float(fc.lhv_j_per_kg)),
        writable(model.battery.kernel_tables()), state, (det, loss), det, loss, np.zeros(0), SLOTS, cols,
        audit, summary, pack_arrays(pack, model, t.size - 1),
    )  # fmt: skip
    if status == ERR_STUCK:
        soc_last = cols[COLUMNS.index("soc"), k - 1] if k > 0 else soc0
        raise stuck_error(model, float(t[k]), float(soc_last), soc_min)
    ctl.previous_w, ctl.ramp_down_overrides, ctl.on_time_s = float(state[0]), int(state[1]), float(state[3])
    return COLUMNS, cols, AUDIT, audit, summary, float(v_end)


def simulate_compiled(
    model: F.FCEV, grid: Any, controller: Any, *, soc_initial: float, soc_min: float, soc_max: float,
    pack: Any = None,
) -> ForwardRecord | None:  # fmt: skip
    """One compiled run (the ``simulate_compiled`` hook of :mod:`hevsim.sim.forward`; ``pack``:
    a ``[battery] model = "pack"`` or ``"cell"`` vehicle's battery run, stepped in the loop);
    None for a controller other than :class:`~hevsim.control.simple.LoadFollower`."""
    if type(controller) is not LoadFollower:
        return None
    _, cols, _, audit, summary, v_end = _run(model, grid, controller, soc_initial, soc_min, soc_max, pack)
    columns = {name: cols[j] for j, name in enumerate(COLUMNS)}
    return ForwardRecord(columns, dict(zip(AUDIT, audit.tolist(), strict=True)), summary, v_end)


def simulate_batch_compiled(
    model: F.FCEV,
    variants: dict[str, np.ndarray],
    grid: Any,
    controller: Any,
    *,
    soc_initial: np.ndarray,
    soc_min: float,
    soc_max: float,
) -> BatchRecord | None:
    """The compiled batch (the ``simulate_batch_compiled`` hook of :mod:`hevsim.sim.forward`):
    every variant one compiled run (:func:`hevsim.sim._loop.threaded_batch`, threads); None for
    a controller other than :class:`~hevsim.control.simple.LoadFollower` or a key outside
    :data:`hevsim.sim._loop.MODEL_KEYS` and ``simulation.soc_initial``."""
    if type(controller) is not LoadFollower:
        return None

    def run(vm: F.FCEV, ctl: Any, soc0: float) -> tuple[Any, ...]:
        return _run(vm, grid, ctl, soc0, soc_min, soc_max)[:5]

    return threaded_batch(model, variants, grid, controller, soc_initial, run)

"""The battery-electric vehicle's plug-in of the one compiled forward loop
(:func:`hevsim.sim._loop.run_loop`, issue 24), with its ``direct`` controller.

Nothing physical is written here: the wheel side is :func:`hevsim.architectures.bev.wheel_point`,
the audit terms :func:`~hevsim.architectures.bev.point_losses`, the mode
:func:`~hevsim.architectures.bev.power_mode_code`; the bus balance and the forward driver's
feasibility rule are the HEV plug-in's (:mod:`hevsim.sim._compiled_hev`: ``_electric``,
``_feasible``), which call the shared kernels of :mod:`hevsim.components.bus` and
:mod:`~hevsim.components.battery`. The driver, the bisection, the battery step, the audit and
the bookkeeping are the loop's.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from hevsim.architectures import bev as B
from hevsim.architectures._common import max_machine_speed_radps
from hevsim.control.simple import Direct
from hevsim.sim import kernel as K
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
    "motor_speed_radps", "motor_torque_nm", "motor_power_elec_w", "battery_current_a", "battery_power_w",
    "friction_brake_power_w",
)  # fmt: skip
"""The BEV power flow's channels, in the Python loop's order."""
COLUMNS: tuple[str, ...] = (
    *BASE_COLUMNS, *DETAILS, "power_mode", "traction_limited", "battery_ocv_v", "battery_voltage_v",
)  # fmt: skip
"""Time-series channels of a run (:class:`~hevsim.sim.forward.ForwardRecord`), in order."""
AUDIT: tuple[str, ...] = (*AUDIT_BASE, *B.LOSSES[1:-1], "battery_loss")
"""Energy-audit terms of a run [J], in the Python loop's order."""
SLOTS = audit_slots(B.LOSSES, AUDIT)
"""Audit index of each of :data:`hevsim.architectures.bev.LOSSES` (:func:`hevsim.sim._loop.run_loop`)."""

ARCHITECTURES = ("bev",)
"""The architectures this compiled loop runs (:func:`hevsim.sim.forward.compiled_loop`)."""


class WheelData(NamedTuple):
    """The BEV's wheel-side scalars for compiled code: final drive ratio and efficiency [-],
    brake-blending fraction [-], lowest regeneration speed [m/s], machine speed limit [rad/s]."""

    fd_ratio: float
    fd_efficiency: float
    regen_fraction: float
    regen_min_speed_mps: float
    w_max_radps: float


@njit(cache=True, inline="always")
def _point(w_wheel, t_wheel, regen_ok, soc, dt, bat, h, wd, mtab):
    """The power flow at one point: (feasible for the forward driver, machine torque [N·m],
    electrical power [W], battery power [W], current [A], SOC change [-], machine speed
    [rad/s], final-drive input torque [N·m])."""
    w_m, t_fd, t_req, ok, over = B.wheel_point(
        w_wheel, t_wheel, regen_ok, wd.fd_ratio, wd.fd_efficiency, wd.regen_fraction, wd.regen_min_speed_mps,
        h.radius_m, wd.w_max_radps,
    )  # fmt: skip
    ocv, r_dis, r_chg, p_chg, _ = bat
    oth, inf, t, p_el, p_bat, cur, d_soc = _electric(
        t_req, w_m, h.aux_power_w, ok, soc, dt, ocv, r_dis, r_chg, p_chg, h, mtab
    )
    ok = _feasible(inf or over, oth or over, cur, t, p_bat, p_el, soc, h)
    return ok, t, p_el, p_bat, cur, d_soc, w_m, t_fd


class BEVPlug(NamedTuple):
    """The BEV's plug-in of :func:`hevsim.sim._loop.run_loop`: its wheel-side scalars and the
    machine's tables."""

    wd: WheelData
    mtab: Any


@njit(cache=True, inline="always")
def bev_choose(plug, state, work, v_mid, w_wheel, t_wheel, soc, dt, e_soc, bat, hk):
    """The plug-in's ``choose`` (:mod:`hevsim.sim._loop`): the ``direct`` controller has one
    control, feasible or not."""
    ok, _, _, _, _, _, _, _ = _point(w_wheel, t_wheel, v_mid > 0.0, soc, dt, bat, hk, plug.wd, plug.mtab)
    return ok, 0.0, 0.0, False, 0.0, 0.0


@njit(cache=True, inline="always")
def bev_point(plug, state, work, c0, c1, v_mid, w_wheel, t_wheel, soc, dt, bat, hk):
    """The plug-in's ``point``: the details (:data:`DETAILS`) and audit powers
    (:data:`hevsim.architectures.bev.LOSSES`) into ``work``; (fuel 0 [kg], SOC change [-])."""
    det, loss = work
    wd = plug.wd
    _, t_m, p_el, p_bat, cur, d_soc, w_m, t_fd = _point(w_wheel, t_wheel, v_mid > 0.0, soc, dt, bat, hk, wd,
                                                       plug.mtab)  # fmt: skip
    q = B.point_losses(w_wheel, w_m, t_fd, t_m, p_el, wd.fd_ratio, wd.fd_efficiency, hk.aux_power_w)
    for j in range(len(q)):
        loss[j] = q[j]
    det[0], det[1], det[2], det[3], det[4], det[5] = w_m, t_m, p_el, cur, p_bat, q[2]
    return 0.0, d_soc


@njit(cache=True, inline="always")
def bev_commit(plug, state, work, v_mid, f, soc, dt, e_soc, hk, has_pack):
    """The plug-in's ``commit``: (engine on: never, power mode, battery power [W], current [A],
    wheel power [W])."""
    det, loss = work
    return False, float(B.power_mode_code(det[1], f, v_mid)), det[4], det[3], loss[loss.shape[0] - 1]


register(BEVPlug, bev_choose, bev_point, bev_commit)


def _run(
    model: B.BEV, grid: Any, soc0: float, soc_min: float, soc_max: float, pack: Any = None
) -> tuple[Any, ...]:
    """One compiled run: (channel names, channels (:data:`COLUMNS` x n + 1), audit names,
    audit [J], summary, end speed [m/s]); ``pack``: a ``[battery] model = "pack"`` vehicle's
    :class:`~hevsim.battery.bms.PackRun`."""
    # a BEV burns no fuel: the constants of the HEV loop with a fuel LHV of 0
    fd = model.final_drive
    wd = WheelData(float(fd.ratio), float(fd.efficiency), float(model.regen_fraction),
                   float(model.regen_min_speed_mps), float(max_machine_speed_radps(model.motor)))  # fmt: skip
    t, v_des, gr = grid_arrays(grid)
    cols = np.zeros((len(COLUMNS), t.size))
    audit = np.zeros(len(AUDIT))
    summary = np.zeros(len(K.SUMMARY))
    det, loss = np.zeros(len(DETAILS)), np.zeros(len(B.LOSSES))
    status, k, v_end, _ = run_loop(
        BEVPlug(wd, writable(model.motor.kernel_tables())), float(soc0), t, v_des, gr,
        constants(model, soc_min, soc_max, lhv_jpkg=0.0), writable(model.battery.kernel_tables()),
        np.zeros(1), (det, loss), det, loss, np.zeros(0), SLOTS, cols, audit, summary,
        pack_arrays(pack, model, t.size - 1),
    )  # fmt: skip
    if status == ERR_STUCK:
        soc_last = cols[COLUMNS.index("soc"), k - 1] if k > 0 else soc0
        raise stuck_error(model, float(t[k]), float(soc_last), soc_min)
    return COLUMNS, cols, AUDIT, audit, summary, float(v_end)


def simulate_compiled(
    model: B.BEV, grid: Any, controller: Any, *, soc_initial: float, soc_min: float, soc_max: float,
    pack: Any = None,
) -> ForwardRecord | None:  # fmt: skip
    """One compiled run (the ``simulate_compiled`` hook of :mod:`hevsim.sim.forward`; ``pack``:
    a ``[battery] model = "pack"`` vehicle's :class:`~hevsim.battery.bms.PackRun`, stepped in
    the loop); None for a controller other than :class:`~hevsim.control.simple.Direct`."""
    if type(controller) is not Direct:
        return None
    controller.reset(float(soc_initial))
    _, cols, _, audit, summary, v_end = _run(model, grid, soc_initial, soc_min, soc_max, pack)
    columns = {name: cols[j] for j, name in enumerate(COLUMNS)}
    return ForwardRecord(columns, dict(zip(AUDIT, audit.tolist(), strict=True)), summary, v_end)


def simulate_batch_compiled(
    model: B.BEV,
    variants: dict[str, np.ndarray],
    grid: Any,
    controller: Any,
    *,
    soc_initial: np.ndarray,
    soc_min: float,
    soc_max: float,
) -> BatchRecord | None:
    """The compiled batch (the ``simulate_batch_compiled`` hook of :mod:`hevsim.sim.forward`):
    every variant one compiled run (:func:`hevsim.sim._loop.threaded_batch`, threads);
    None for a controller other than :class:`~hevsim.control.simple.Direct` or a key outside
    :data:`hevsim.sim._loop.MODEL_KEYS` and ``simulation.soc_initial``."""
    if type(controller) is not Direct:
        return None

    def run(vm: B.BEV, _ctl: Any, soc0: float) -> tuple[Any, ...]:
        return _run(vm, grid, soc0, soc_min, soc_max)[:5]

    return threaded_batch(model, variants, grid, controller, soc_initial, run)

"""Compiled forward run of the battery-electric vehicle with its ``direct`` controller.

The same loop as :func:`hevsim.sim.forward._run` (driver with bisection on the end speed,
the architecture's power flow, energy audit, bookkeeping), compiled. Nothing physical is
written here: the wheel side is :func:`hevsim.architectures.bev.wheel_point`, the audit terms
:func:`~hevsim.architectures.bev.point_losses`, the mode
:func:`~hevsim.architectures.bev.power_mode_code`; the bus balance, the forward driver's
feasibility rule, the battery state at a SOC and the driver's demand are the compiled HEV
loop's (:mod:`hevsim.sim._compiled_hev`: ``_electric``, ``_feasible``, ``_battery``,
``_demand``), which call the shared kernels of :mod:`hevsim.components.bus`,
:mod:`~hevsim.components.battery` and :mod:`~hevsim.components.body`.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from hevsim.architectures import bev as B
from hevsim.architectures._common import NO_REFCOUNT, max_machine_speed_radps
from hevsim.control.simple import Direct
from hevsim.sim import kernel as K
from hevsim.sim._compiled_common import add_road_audit, track_step, write_summary
from hevsim.sim._compiled_hev import (
    AUDIT_BASE,
    BASE_COLUMNS,
    _demand,
    _electric,
    _feasible,
    battery_begin,
    battery_end,
    constants,
    pack_arrays,
    threaded_batch,
)
from hevsim.sim._records import BISECTION_STEPS, BatchRecord, ForwardRecord
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
    ocv, r_dis, r_chg, p_chg = bat
    oth, inf, t, p_el, p_bat, cur, d_soc = _electric(
        t_req, w_m, h.aux_power_w, ok, soc, dt, ocv, r_dis, r_chg, p_chg, h, mtab
    )
    ok = _feasible(inf or over, oth or over, cur, t, p_bat, p_el, soc, h)
    return ok, t, p_el, p_bat, cur, d_soc, w_m, t_fd


@njit(cache=True, nogil=True, **NO_REFCOUNT)
def run_bev(soc0, t, v_des, gr, h0, wd, mtab, ptab, cols, audit, summary, pk):
    """One run; fills ``cols`` (:data:`COLUMNS` x ``n + 1``), ``audit`` (:data:`AUDIT` [J])
    and ``summary`` (:data:`hevsim.sim.kernel.SUMMARY`). Returns (end speed [m/s], index of
    a step with no feasible demand even when stopping, or -1). ``pk``: None, or the pack of a
    ``[battery] model = "pack"`` vehicle (:func:`hevsim.sim._compiled_hev.battery_begin`)."""
    h = h0
    n = t.shape[0] - 1
    dt = t[1] - t[0]
    r, q_as, m_eff = h.radius_m, h.capacity_as, h.mass_kg * h.mass_factor
    v, soc = v_des[0], soc0
    err_sq = err_max = dist = lim_s = 0.0
    nb = len(BASE_COLUMNS)
    for k in range(n):
        bat, h = battery_begin(soc, h0, ptab, pk)
        ocv = bat[0]
        v1 = v_des[k + 1]
        v_mid, a, g, f = _demand(v, v1, k, dt, gr, h)
        limited = 0.0
        if not _point(v_mid / r, f * r, v_mid > 0.0, soc, dt, bat, h, wd, mtab)[0]:
            limited = 1.0  # beyond the powertrain: lower the end speed (forward._run)
            lo, hi, have = 0.0, v1, False
            bv = ba = bg = bf = 0.0
            for _ in range(BISECTION_STEPS):
                mid = 0.5 * (lo + hi)
                tv, ta, tg, tf = _demand(v, mid, k, dt, gr, h)
                if _point(tv / r, tf * r, tv > 0.0, soc, dt, bat, h, wd, mtab)[0]:
                    lo, have = mid, True
                    bv, ba, bg, bf = tv, ta, tg, tf
                else:
                    hi = mid
            if not have:
                bv, ba, bg, bf = _demand(v, 0.0, k, dt, gr, h)
                ok = _point(bv / r, bf * r, bv > 0.0, soc, dt, bat, h, wd, mtab)[0]
                if not ok and bf > 0.0 and pk is not None:  # coast to rest (forward._run, with a pack)
                    bf = 0.0
                    ok = _point(bv / r, bf * r, bv > 0.0, soc, dt, bat, h, wd, mtab)[0]
                if not ok:
                    return v, k
            v_mid, a, g, f = bv, ba, bg, bf
            v1 = v_mid * 2.0 - v
        w_wheel = v_mid / r
        _, t_m, p_el, p_bat, cur, d_soc, w_m, t_fd = _point(
            w_wheel, f * r, v_mid > 0.0, soc, dt, bat, h, wd, mtab
        )
        q = B.point_losses(w_wheel, w_m, t_fd, t_m, p_el, wd.fd_ratio, wd.fd_efficiency, h.aux_power_w)
        # ---- energy audit [J]: fuel, base terms, motor, friction, final drive, aux, battery
        audit[0] += q[0] * dt
        for j in range(1, 5):
            audit[len(AUDIT_BASE) + j - 1] += q[j] * dt
        e_chem = -d_soc * q_as * ocv
        audit[2] += e_chem
        audit[len(AUDIT_BASE) + 4] += e_chem - p_bat * dt
        crr, crr_v = h.rolling_resistance, h.rolling_resistance_speed_s_per_m
        add_road_audit(audit, v, v1, v_mid, a, g, f, h.mass_kg, m_eff, crr, crr_v, dt)
        err_sq, err_max, dist, lim_s = track_step(
            v_des[k] - v, v_mid, dt, limited, err_sq, err_max, dist, lim_s
        )
        row = (v_des[k], v, a, f, q[5], f - m_eff * a, 0.0, soc, w_m, t_m, p_el, cur, p_bat, q[2])
        for j in range(len(row)):
            cols[j, k] = row[j]
        cols[nb + 6, k] = B.power_mode_code(t_m, f, v_mid)
        cols[nb + 7, k] = limited
        cols[nb + 8, k] = ocv
        cols[nb + 9, k] = p_bat / cur if cur != 0.0 else ocv
        v, soc = v1, battery_end(soc, d_soc, p_bat, pk)
    write_summary(summary, v_des[n] - v, err_sq, err_max, n, dist, 0.0, soc, 0.0, 0.0, lim_s, t[n] - t[0])
    return v, -1


def _run(
    model: B.BEV, grid: Any, soc0: float, soc_min: float, soc_max: float, pack: Any = None
) -> tuple[Any, ...]:
    """One compiled run: (channel names, channels (:data:`COLUMNS` x n + 1), audit names,
    audit [J], summary, end speed [m/s]); ``pack``: a ``[battery] model = "pack"`` vehicle's
    :class:`~hevsim.battery.bms.PackRun`."""
    # a BEV burns no fuel: the constants of the HEV loop with a fuel LHV of 0
    proxy = SimpleNamespace(
        motor=model.motor, battery=model.battery, body=model.body, tire=model.tire,
        aux_power_w=model.aux_power_w, engine=SimpleNamespace(fuel_lhv_jpkg=0.0),
    )  # fmt: skip
    fd = model.final_drive
    wd = WheelData(float(fd.ratio), float(fd.efficiency), float(model.regen_fraction),
                   float(model.regen_min_speed_mps), float(max_machine_speed_radps(model.motor)))  # fmt: skip
    t, v_des, gr = (
        np.ascontiguousarray(a, dtype=np.float64) for a in (grid.time_s, grid.speed_mps, grid.grade)
    )
    cols = np.zeros((len(COLUMNS), t.size))
    audit = np.zeros(len(AUDIT))
    summary = np.zeros(len(K.SUMMARY))
    v_end, failed = run_bev(
        float(soc0), t, v_des, gr, constants(proxy, soc_min, soc_max), wd, model.motor.kernel_tables(),
        model.battery.kernel_tables(), cols, audit, summary, pack_arrays(pack, model, t.size - 1),
    )  # fmt: skip
    if failed >= 0:
        soc_last = cols[COLUMNS.index("soc"), failed - 1] if failed > 0 else soc0
        raise stuck_error(model, float(t[failed]), float(soc_last), soc_min)
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
    every variant one compiled run (:func:`hevsim.sim._compiled_hev.threaded_batch`, threads);
    None for a controller other than :class:`~hevsim.control.simple.Direct` or a key outside
    :data:`hevsim.sim._compiled_hev.MODEL_KEYS` and ``simulation.soc_initial``."""
    if type(controller) is not Direct:
        return None

    def run(vm: B.BEV, _ctl: Any, soc0: float) -> tuple[Any, ...]:
        return _run(vm, grid, soc0, soc_min, soc_max)[:5]

    return threaded_batch(model, variants, grid, controller, soc_initial, run)

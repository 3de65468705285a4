"""Compiled forward run of the conventional vehicle with its shift-schedule controller.

The same loop as :func:`hevsim.sim.forward._run` (driver with bisection on the end speed,
shift schedule with kick-down, the architecture's power flow, energy audit, bookkeeping),
compiled: one run is one call of :func:`_run_variant`, a batch of variants one parallel loop
over it (:func:`_run_batch`). The power flow is the architecture's own scalar kernel
(:func:`hevsim.architectures.conventional.operating_point`, :func:`point_details`,
:func:`point_losses`, :func:`power_mode_code`), the road load :func:`road_load_force`, the
schedule :func:`hevsim.control.simple.shift_gear` and :func:`kickdown_gear`: nothing is
restated here. Parameters cross into compiled code by name (:class:`RunScalars`,
:class:`~hevsim.architectures.conventional.DrivelineData`,
:class:`~hevsim.components.engine.EngineTables`).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit, prange

from hevsim.architectures.conventional import (
    DETAILS,
    LOSSES,
    ConventionalVehicle,
    operating_point,
    point_details,
    point_losses,
    power_mode_code,
)
from hevsim.components.body import road_load_force
from hevsim.control.simple import ShiftSchedule, kickdown_gear, shift_gear
from hevsim.errors import DomainError
from hevsim.sim import kernel as K
from hevsim.sim._loop import add_road_audit, track_step, write_summary
from hevsim.sim._records import BISECTION_STEPS, BatchRecord, ForwardRecord
from hevsim.units import RADPS_PER_RPM

COLUMNS: tuple[str, ...] = (
    "speed_desired_mps", "speed_mps", "accel_mps2", "wheel_force_n", "wheel_power_w", "road_load_force_n",
    "fuel_kg", "soc", *DETAILS, "power_mode", "traction_limited",
)  # fmt: skip
"""Time-series channels of a run, in the Python loop's order (:class:`ForwardRecord`)."""
AUDIT: tuple[str, ...] = (
    "fuel", "genset_source", "battery_chemical", "aero", "rolling", "grade", "kinetic_vehicle",
    *(term for term in LOSSES if term not in ("fuel", "wheel", "battery_chemical")),
)  # fmt: skip
"""Energy-audit terms of a run [J], in the Python loop's order."""
_LOSS_SLOT = tuple(AUDIT.index(term) if term != "wheel" else -1 for term in LOSSES)

ARCHITECTURES = ("conventional",)
"""The architectures this compiled loop runs (:func:`hevsim.sim.forward.compiled_loop`)."""


class RunScalars(NamedTuple):
    """Per-variant parameters of a run, one float64 array (one entry per variant) each.

    Body (:class:`~hevsim.components.body.VehicleBody`): ``mass_kg`` [kg], ``mass_factor``
    [-], ``drag_coefficient`` [-], ``frontal_area_m2`` [m²], ``air_density_kgpm3`` [kg/m³],
    ``headwind_mps`` [m/s], ``rolling_resistance`` [-], ``rolling_resistance_speed_s_per_m``
    [s/m]; ``radius_m`` tire [m]; ``fd_ratio``,
    ``fd_efficiency`` final drive [-]; engine ``torque_scale`` [-], ``idle_radps``,
    ``redline_radps`` [rad/s]; ``fuel_cut_radps``, ``upshift_radps``, ``downshift_radps``
    [rad/s] of the controller; ``aux_power_w`` [W] auxiliary load, ``alternator_efficiency`` [-].
    """

    mass_kg: np.ndarray
    mass_factor: np.ndarray
    drag_coefficient: np.ndarray
    frontal_area_m2: np.ndarray
    air_density_kgpm3: np.ndarray
    headwind_mps: np.ndarray
    rolling_resistance: np.ndarray
    rolling_resistance_speed_s_per_m: np.ndarray
    radius_m: np.ndarray
    fd_ratio: np.ndarray
    fd_efficiency: np.ndarray
    torque_scale: np.ndarray
    idle_radps: np.ndarray
    redline_radps: np.ndarray
    fuel_cut_radps: np.ndarray
    upshift_radps: np.ndarray
    downshift_radps: np.ndarray
    aux_power_w: np.ndarray
    alternator_efficiency: np.ndarray


VARIANT_KEYS: dict[str, tuple[str, float]] = {
    "body.mass_kg": ("mass_kg", 1.0),
    "body.mass_factor": ("mass_factor", 1.0),
    "body.drag_coefficient": ("drag_coefficient", 1.0),
    "body.frontal_area_m2": ("frontal_area_m2", 1.0),
    "body.air_density_kgpm3": ("air_density_kgpm3", 1.0),
    "body.headwind_mps": ("headwind_mps", 1.0),
    "body.rolling_resistance": ("rolling_resistance", 1.0),
    "body.rolling_resistance_speed_s_per_m": ("rolling_resistance_speed_s_per_m", 1.0),
    "tire.radius_m": ("radius_m", 1.0),
    "final_drive.ratio": ("fd_ratio", 1.0),
    "final_drive.efficiency": ("fd_efficiency", 1.0),
    "engine.torque_scale": ("torque_scale", 1.0),
    "engine.stall_speed_rpm": ("idle_radps", RADPS_PER_RPM),
    "engine.redline_rpm": ("redline_radps", RADPS_PER_RPM),
    "controller.fuel_cut_speed_rpm": ("fuel_cut_radps", RADPS_PER_RPM),
    "controller.upshift_rpm": ("upshift_radps", RADPS_PER_RPM),
    "controller.downshift_rpm": ("downshift_radps", RADPS_PER_RPM),
    "controller.aux_power_w": ("aux_power_w", 1.0),
    "alternator.efficiency": ("alternator_efficiency", 1.0),
    "simulation.soc_initial": ("", 1.0),  # no battery: no effect on the run
}
"""Dotted configuration keys a compiled batch varies -> (:class:`RunScalars` field, factor
from the file's unit to SI); other keys run variant by variant."""


def run_scalars(veh: ConventionalVehicle, ctl: ShiftSchedule, n: int = 1) -> RunScalars:
    """:class:`RunScalars` of ``n`` copies of the vehicle ``veh`` with controller ``ctl``."""
    b, d = veh.body, veh.driveline_data()
    values = {
        "mass_kg": b.mass_kg, "mass_factor": b.mass_factor, "drag_coefficient": b.drag_coefficient,
        "frontal_area_m2": b.frontal_area_m2, "air_density_kgpm3": b.air_density_kgpm3,
        "headwind_mps": b.headwind_mps, "rolling_resistance": b.rolling_resistance,
        "rolling_resistance_speed_s_per_m": b.rolling_resistance_speed_s_per_m,
        "radius_m": veh.tire.radius_m, "fd_ratio": d.fd_ratio, "fd_efficiency": d.fd_efficiency,
        "torque_scale": d.torque_scale, "idle_radps": d.idle_radps, "redline_radps": d.redline_radps,
        "fuel_cut_radps": d.fuel_cut_radps, "upshift_radps": ctl.w_up, "downshift_radps": ctl.w_down,
        "aux_power_w": d.aux_power_w, "alternator_efficiency": d.alternator_efficiency,
    }  # fmt: skip
    return RunScalars(**{k: np.full(n, float(v)) for k, v in values.items()})


@njit(cache=True)
def _try_speed(
    v0, v1, k, dt, grade, gear_prev, m, mf, cd, area, rho, wind, crr, crrv, r, ratios, effs, fd, fd_eff, idle,
    w_cut, redline, stop_start, use_map, lhv, scale, p_aux, alt_eff, w_up, w_down, tmax_x, tmax_y, tct_x,
    tct_y, tmap_x, tmap_y, tmap_z, fuel_x, fuel_y, fuel_z,
):  # fmt: skip
    """The driver's demand for end speed ``v1`` and the shift schedule's choice (0: none):
    (gear, mid-step speed, acceleration, grade, wheel force, :func:`operating_point` of the
    last gear tried: the chosen one)."""
    v_mid = 0.5 * (v0 + v1)
    a = (v1 - v0) / dt
    g = 0.5 * (grade[k] + grade[k + 1])
    f = road_load_force(v_mid, a, g, m, mf, cd, area, rho, wind, crr, crrv) if v_mid > 0.0 else 0.0
    w_wheel, t_wheel = v_mid / r, f * r
    sched = shift_gear(gear_prev, w_wheel * fd, ratios, w_up, w_down)
    for j in range(ratios.shape[0]):
        gear = kickdown_gear(j, sched)
        p = operating_point(
            w_wheel, t_wheel, float(gear), ratios, effs, fd, fd_eff, idle, w_cut, redline, stop_start,
            use_map, lhv, scale, p_aux, alt_eff, tmax_x, tmax_y, tct_x, tct_y, tmap_x, tmap_y, tmap_z, fuel_x,
            fuel_y, fuel_z,
        )  # fmt: skip
        if not p[15]:
            return gear, v_mid, a, g, f, p
    return 0, v_mid, a, g, f, p


@njit(cache=True)
def _run_variant(
    i, t, v_des, grade, soc0, s, ratios, effs, stop_start, use_map, lhv, tab, cols, audit, summary
):  # fmt: skip
    """One run of variant ``i`` of :class:`RunScalars` ``s``; fills ``cols`` (rows x
    :data:`COLUMNS`, or one row: no time series), ``audit`` (:data:`AUDIT` [J]) and
    ``summary`` (:data:`hevsim.sim.kernel.SUMMARY`). Returns (end speed [m/s], positive
    wheel energy [J], last gear, index of a step with no feasible control or -1)."""
    m, mf, cd, area = s.mass_kg[i], s.mass_factor[i], s.drag_coefficient[i], s.frontal_area_m2[i]
    rho, wind, crr, r = s.air_density_kgpm3[i], s.headwind_mps[i], s.rolling_resistance[i], s.radius_m[i]
    crrv = s.rolling_resistance_speed_s_per_m[i]
    fd, fd_eff, scale, idle = s.fd_ratio[i], s.fd_efficiency[i], s.torque_scale[i], s.idle_radps[i]
    redline, w_cut, w_up, w_down = (
        s.redline_radps[i],
        s.fuel_cut_radps[i],
        s.upshift_radps[i],
        s.downshift_radps[i],
    )
    p_aux, alt_eff = s.aux_power_w[i], s.alternator_efficiency[i]
    tmax_x, tmax_y, tct_x, tct_y = tab.tmax_x, tab.tmax_y, tab.tct_x, tab.tct_y
    tmap_x, tmap_y, tmap_z = tab.tmap_x, tab.tmap_y, tab.tmap_z
    fuel_x, fuel_y, fuel_z = tab.fuel_x, tab.fuel_y, tab.fuel_z
    record = cols.shape[0] > 1
    n = t.shape[0] - 1
    dt = t[1] - t[0]
    m_eff = m * mf
    for j in range(audit.shape[0]):
        audit[j] = 0.0
    v, fuel = v_des[0], 0.0
    err_sq = err_max = dist = eon = starts = lim_s = traction = 0.0
    was_on = False
    gear = 1
    for k in range(n):
        v1 = v_des[k + 1]
        c, v_mid, a, g, f, p = _try_speed(
            v, v1, k, dt, grade, gear, m, mf, cd, area, rho, wind, crr, crrv, r, ratios, effs, fd, fd_eff,
            idle, w_cut, redline, stop_start, use_map, lhv, scale, p_aux, alt_eff, w_up, w_down, tmax_x,
            tmax_y, tct_x, tct_y, tmap_x, tmap_y, tmap_z, fuel_x, fuel_y, fuel_z,
        )  # fmt: skip
        limited = 0.0
        if c == 0:  # beyond the powertrain: lower the end speed until a gear can (forward._run)
            limited = 1.0
            lo, hi, best_v, best_c = 0.0, v1, -1.0, 0
            for _ in range(BISECTION_STEPS):
                mid = 0.5 * (lo + hi)
                cm = _try_speed(
                    v, mid, k, dt, grade, gear, m, mf, cd, area, rho, wind, crr, crrv, r, ratios, effs, fd,
                    fd_eff, idle, w_cut, redline, stop_start, use_map, lhv, scale, p_aux, alt_eff, w_up,
                    w_down, tmax_x, tmax_y, tct_x, tct_y, tmap_x, tmap_y, tmap_z, fuel_x, fuel_y, fuel_z,
                )[0]  # fmt: skip
                if cm == 0:
                    hi = mid
                else:
                    lo, best_v, best_c = mid, mid, cm
            if best_c == 0:
                best_v = 0.0
            c, v_mid, a, g, f, p = _try_speed(
                v, best_v, k, dt, grade, gear, m, mf, cd, area, rho, wind, crr, crrv, r, ratios, effs, fd,
                fd_eff, idle, w_cut, redline, stop_start, use_map, lhv, scale, p_aux, alt_eff, w_up, w_down,
                tmax_x, tmax_y, tct_x, tct_y, tmap_x, tmap_y, tmap_z, fuel_x, fuel_y, fuel_z,
            )  # fmt: skip
            v1 = v_mid * 2.0 - v  # (at best_v the schedule chooses best_c again: same inputs)
            if c == 0:
                return v, traction * dt, gear, k
        w_wheel = v_mid / r
        gi, w_fd, t_fd, w_in, t_in, w_e, t_e, on, slip, trac, cut, rate, t_fd_eng, _, _, _, t_max, t_alt = p
        gear = gi + 1
        det = point_details(gi, w_fd, t_fd, w_in, t_e, w_e, on, slip, trac, cut, rate, t_fd_eng, t_max)
        q = point_losses(
            w_wheel, w_fd, t_fd, w_in, t_in, w_e, t_e, on, rate, t_fd_eng, t_alt, fd, fd_eff, lhv, p_aux
        )
        # ---- energy audit [J] (all powers at the mid-step speed), as forward._run
        audit[0] += q[0] * dt
        audit[7] += q[1] * dt
        audit[8] += q[2] * dt
        audit[9] += q[3] * dt
        audit[10] += q[4] * dt
        audit[11] += q[5] * dt
        audit[12] += q[6] * dt
        audit[13] += q[7] * dt
        audit[2] += q[8] * dt
        p_wheel = q[9]
        add_road_audit(audit, v, v1, v_mid, a, g, f, m, m_eff, crr, crrv, dt)
        if on and not was_on:
            starts += 1.0
        was_on = on
        fuel += rate * dt
        if record:
            row = cols[k]
            row[0], row[1], row[2], row[3], row[4], row[5], row[6], row[7] = (
                v_des[k], v, a, f, p_wheel, f - m_eff * a, fuel, soc0,
            )  # fmt: skip
            for j in range(12):
                row[8 + j] = det[j]
            row[20] = power_mode_code(det[1], det[3], det[2], det[4], v_mid)
            row[21] = limited
        eon += dt if on else 0.0
        err_sq, err_max, dist, lim_s = track_step(
            v_des[k] - v, v_mid, dt, limited, err_sq, err_max, dist, lim_s
        )
        traction += max(p_wheel, 0.0)
        v = v1
    write_summary(
        summary, v_des[n] - v, err_sq, err_max, n, dist, fuel, soc0, eon, starts, lim_s, t[n] - t[0]
    )
    return v, traction * dt, gear, -1


@njit(cache=True, parallel=True)
def _run_batch(t, v_des, grade, soc0, s, ratios, effs, stop_start, use_map, lhv, tab, audit, summary, out):
    """:func:`_run_variant` for every variant (parallel over variants; no time series).
    ``out[i]``: (positive wheel energy [J], failed step or -1)."""
    for i in prange(summary.shape[0]):
        cols = np.zeros((1, 1))
        res = _run_variant(
            i,
            t,
            v_des,
            grade,
            soc0[i],
            s,
            ratios,
            effs,
            stop_start,
            use_map,
            lhv,
            tab,
            cols,
            audit[i],
            summary[i],
        )
        out[i, 0] = res[1]
        out[i, 1] = res[3]


def _check_layout() -> None:
    if (K.S_DIST, K.S_FUEL, K.S_SOCF, K.S_RMS, K.S_MAXERR, K.S_EON, K.S_STARTS, K.S_BLIM, K.S_DUR) != tuple(
        range(9)
    ) or _LOSS_SLOT != (0, 7, 8, 9, 10, 11, 12, 13, 2, -1):
        raise RuntimeError("compiled conventional run: summary or audit layout changed; update the kernel")


def _grid(grid: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return tuple(
        np.ascontiguousarray(np.asarray(a, dtype=np.float64))
        for a in (grid.time_s, grid.speed_mps, grid.grade)
    )  # type: ignore[return-value]


def simulate_compiled(
    model: ConventionalVehicle,
    grid: Any,
    controller: Any,
    *,
    soc_initial: float,
    soc_min: float = 0.0,
    soc_max: float = 1.0,
) -> ForwardRecord | None:
    """One compiled run (the ``simulate_compiled`` hook of :mod:`hevsim.sim.forward`);
    None for a controller other than :class:`~hevsim.control.simple.ShiftSchedule`."""
    if type(controller) is not ShiftSchedule:
        return None
    _check_layout()
    t, v_des, grade = _grid(grid)
    controller.reset(soc_initial)
    cols = np.zeros((t.size, len(COLUMNS)))
    audit = np.zeros(len(AUDIT))
    summary = np.zeros(len(K.SUMMARY))
    d = model.driveline_data()
    v_end, _, gear, failed = _run_variant(
        0, t, v_des, grade, float(soc_initial), run_scalars(model, controller), model.gear_ratios,
        model.gear_efficiencies, d.stop_start, d.use_fuel_map, d.lhv_jpkg, model.engine.kernel_tables(), cols,
        audit, summary,
    )  # fmt: skip
    if failed >= 0:
        raise DomainError(f"{model.name}: no feasible control at t = {t[failed]:g} s even when stopping.")
    controller.gear = int(gear)
    columns = {name: np.ascontiguousarray(cols[:, j]) for j, name in enumerate(COLUMNS)}
    return ForwardRecord(columns, dict(zip(AUDIT, audit.tolist(), strict=True)), summary, float(v_end))


def simulate_batch_compiled(
    model: ConventionalVehicle,
    variants: dict[str, np.ndarray],
    grid: Any,
    controller: Any,
    *,
    soc_initial: np.ndarray,
    soc_min: float = 0.0,
    soc_max: float = 1.0,
) -> BatchRecord | None:
    """All variants in one parallel compiled call (the ``simulate_batch_compiled`` hook);
    None for a key outside :data:`VARIANT_KEYS` or another controller."""
    if type(controller) is not ShiftSchedule or any(k not in VARIANT_KEYS for k in variants):
        return None
    _check_layout()
    n = int(np.size(soc_initial))
    scalars = run_scalars(model, controller, n)._asdict()
    for key, values in variants.items():
        name, factor = VARIANT_KEYS[key]
        if name:
            scalars[name] = np.ascontiguousarray(np.asarray(values, dtype=np.float64) * factor)
    t, v_des, grade = _grid(grid)
    audit = np.zeros((n, len(AUDIT)))
    summary = np.zeros((n, len(K.SUMMARY)))
    out = np.zeros((n, 2))
    d = model.driveline_data()
    soc0 = np.ascontiguousarray(soc_initial, dtype=np.float64)
    _run_batch(
        t, v_des, grade, soc0, RunScalars(**scalars), model.gear_ratios, model.gear_efficiencies,
        d.stop_start, d.use_fuel_map, d.lhv_jpkg, model.engine.kernel_tables(), audit, summary, out,
    )  # fmt: skip
    failed = np.flatnonzero(out[:, 1] >= 0)
    if failed.size:
        i = int(failed[0])
        desc = ", ".join(f"{k} = {float(v[i]):g}" for k, v in variants.items())
        t_fail = t[int(out[i, 1])]
        raise DomainError(
            f"batch: variant {i} ({desc}): no feasible control at t = {t_fail:g} s even when stopping."
        )
    audits = [dict(zip(AUDIT, row.tolist(), strict=True)) for row in audit]
    return BatchRecord(audits, summary, out[:, 0].copy())

"""The conventional vehicle's plug-in of the one compiled forward loop
(:func:`hevsim.sim._loop.run_loop`, issue 24), with its shift-schedule controller.

One run is one call of the loop with :class:`ConventionalPlug`; a batch of variants one parallel
loop over it (:func:`_run_batch`, each variant's plug-in and constants made in compiled code
from :class:`RunScalars`). The controller is the shift schedule with kick-down
(:func:`hevsim.control.simple.shift_gear`, :func:`kickdown_gear`: the first gear of the
kick-down order the engine can drive); the power flow is the architecture's own scalar kernel
(:func:`hevsim.architectures.conventional.operating_point`, :func:`point_details`,
:func:`point_losses`, :func:`power_mode_code`): nothing is restated here. The driver, the
bisection, the audit and the bookkeeping are the loop's; the vehicle has no traction battery
(the loop's battery tables None).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit, prange

from hevsim.architectures.conventional import (
    DETAILS,
    LOSSES,
    ConventionalVehicle,
    DrivelineData,
    operating_point,
    point_details,
    point_losses,
    power_mode_code,
)
from hevsim.control.simple import ShiftSchedule, kickdown_gear, shift_gear
from hevsim.errors import DomainError
from hevsim.sim import kernel as K
from hevsim.sim._loop import ERR_STUCK, RunConstants, audit_slots, grid_arrays, register, run_loop, writable
from hevsim.sim._records import BatchRecord, ForwardRecord
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
SLOTS = audit_slots(LOSSES, AUDIT)
"""Audit index of each of :data:`~hevsim.architectures.conventional.LOSSES` (the loop's ``slots``)."""

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


class ConventionalPlug(NamedTuple):
    """The conventional vehicle's plug-in of :func:`hevsim.sim._loop.run_loop`: gearbox ratios
    and efficiencies [-], ``dd`` the scalars of :class:`~hevsim.architectures.conventional.DrivelineData`
    (final drive, idle, fuel-cut and redline speeds [rad/s], stop-start, fuel map, LHV [J/kg],
    torque scale, auxiliary load [W], alternator efficiency), the shift speeds [rad/s] and the
    engine's :class:`~hevsim.components.engine.EngineTables`."""

    ratios: np.ndarray
    effs: np.ndarray
    dd: DrivelineData
    upshift_radps: float
    downshift_radps: float
    tab: Any


@njit(cache=True, inline="always")
def _operating_point(plug, w_wheel, t_wheel, gear):
    """:func:`~hevsim.architectures.conventional.operating_point` in ``gear`` (1..G)."""
    tab, d = plug.tab, plug.dd
    return operating_point(
        w_wheel, t_wheel, float(gear), plug.ratios, plug.effs, d.fd_ratio, d.fd_efficiency, d.idle_radps,
        d.fuel_cut_radps, d.redline_radps, d.stop_start, d.use_fuel_map, d.lhv_jpkg, d.torque_scale,
        d.aux_power_w, d.alternator_efficiency, tab.tmax_x,
        tab.tmax_y, tab.tct_x, tab.tct_y, tab.tmap_x, tab.tmap_y, tab.tmap_z, tab.fuel_x, tab.fuel_y,
        tab.fuel_z,
    )  # fmt: skip


@njit(cache=True, inline="always")
def _fill(plug, work, w_wheel, p):
    """The details (:data:`DETAILS`) and audit powers (:data:`LOSSES`) of the operating point
    ``p`` into ``work``; its fuel rate [kg/s]."""
    det, loss = work
    gi, w_fd, t_fd, w_in, t_in, w_e, t_e, on, slip, trac, cut, rate, t_fd_eng, _, _, _, t_max, t_alt = p
    d = point_details(gi, w_fd, t_fd, w_in, t_e, w_e, on, slip, trac, cut, rate, t_fd_eng, t_max)
    for j in range(len(d)):
        det[j] = d[j]
    q = point_losses(
        w_wheel, w_fd, t_fd, w_in, t_in, w_e, t_e, on, rate, t_fd_eng, t_alt, plug.dd.fd_ratio,
        plug.dd.fd_efficiency, plug.dd.lhv_jpkg, plug.dd.aux_power_w,
    )  # fmt: skip
    for j in range(len(q)):
        loss[j] = q[j]
    return rate


@njit(cache=True)
def conventional_choose(plug, state, work, v_mid, w_wheel, t_wheel, soc, dt, e_soc, bat, hk):
    """The plug-in's ``choose`` (:mod:`hevsim.sim._loop`): the shift schedule from the last
    gear ``state[0]``, then the kick-down order's first gear the engine can drive (none: not
    found); the chosen point's details and audit powers filled."""
    sched = shift_gear(
        int(state[0]), w_wheel * plug.dd.fd_ratio, plug.ratios, plug.upshift_radps, plug.downshift_radps
    )
    for j in range(plug.ratios.shape[0]):
        gear = kickdown_gear(j, sched)
        p = _operating_point(plug, w_wheel, t_wheel, gear)
        if not p[15]:
            rate = _fill(plug, work, w_wheel, p)
            return True, float(gear), 0.0, True, rate * dt, 0.0
    return False, 0.0, 0.0, False, 0.0, 0.0


@njit(cache=True, inline="always")
def conventional_point(plug, state, work, c0, c1, v_mid, w_wheel, t_wheel, soc, dt, bat, hk):
    """The plug-in's ``point`` in gear ``c0``: (fuel [kg], SOC change 0)."""
    rate = _fill(plug, work, w_wheel, _operating_point(plug, w_wheel, t_wheel, int(c0)))
    return rate * dt, 0.0


@njit(cache=True, inline="always")
def conventional_commit(plug, state, work, v_mid, f, soc, dt, e_soc, hk, has_pack):
    """The plug-in's ``commit``: the gear taken is the schedule's next start; (engine on, power
    mode, no battery power or current, wheel power [W])."""
    det, loss = work
    state[0] = det[0]
    mode = float(power_mode_code(det[1], det[3], det[2], det[4], v_mid))
    return det[1] > 0.0, mode, 0.0, 0.0, loss[loss.shape[0] - 1]


register(ConventionalPlug, conventional_choose, conventional_point, conventional_commit)


@njit(cache=True, inline="always")
def _variant_inputs(s, i, ratios, effs, stop_start, use_map, lhv, tab):
    """(plug-in, :class:`~hevsim.sim._loop.RunConstants`) of variant ``i`` of :class:`RunScalars`
    ``s``."""
    dd = DrivelineData(
        s.fd_ratio[i], s.fd_efficiency[i], s.idle_radps[i], s.fuel_cut_radps[i], s.redline_radps[i],
        stop_start, use_map, lhv, s.torque_scale[i], s.aux_power_w[i], s.alternator_efficiency[i],
    )  # fmt: skip
    plug = ConventionalPlug(ratios, effs, dd, s.upshift_radps[i], s.downshift_radps[i], tab)
    h = RunConstants(
        0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, s.aux_power_w[i], s.mass_kg[i],
        s.mass_factor[i], s.drag_coefficient[i], s.frontal_area_m2[i], s.air_density_kgpm3[i],
        s.headwind_mps[i], s.rolling_resistance[i], s.rolling_resistance_speed_s_per_m[i], s.radius_m[i], lhv,
    )  # fmt: skip
    return plug, h


@njit(cache=True)
def _run_variant(i, t, v_des, grade, soc0, s, ratios, effs, stop_start, use_map, lhv, tab, slots, cols, audit,
                 summary):  # fmt: skip
    """One run of variant ``i`` of :class:`RunScalars` ``s`` (:func:`hevsim.sim._loop.run_loop`
    with :class:`ConventionalPlug`); fills ``cols`` (:data:`COLUMNS` x ``n + 1``, or one column:
    no time series), ``audit`` (:data:`AUDIT` [J]) and ``summary``. Returns (status, step,
    end speed [m/s], positive wheel energy [J], last gear)."""
    plug, h = _variant_inputs(s, i, ratios, effs, stop_start, use_map, lhv, tab)
    state = np.ones(1)  # the gear
    det, loss = np.zeros(len(DETAILS)), np.zeros(len(LOSSES))
    for j in range(audit.shape[0]):
        audit[j] = 0.0
    status, k, v, traction = run_loop(plug, soc0, t, v_des, grade, h, None, state, (det, loss), det, loss,
                                      np.zeros(0), slots, cols, audit, summary, None)  # fmt: skip
    return status, k, v, traction, state[0]


@njit(cache=True, parallel=True)
def _run_batch(
    t, v_des, grade, soc0, s, ratios, effs, stop_start, use_map, lhv, tab, slots, audit, summary, out
):
    """:func:`_run_variant` for every variant (parallel over variants; no time series).
    ``out[i]``: (positive wheel energy [J], failed step or -1)."""
    for i in prange(summary.shape[0]):
        cols = np.zeros((len(COLUMNS), 1))
        status, k, _, traction, _ = _run_variant(
            i, t, v_des, grade, soc0[i], s, ratios, effs, stop_start, use_map, lhv, tab, slots, cols,
            audit[i], summary[i],
        )  # fmt: skip
        out[i, 0] = traction
        out[i, 1] = k if status == ERR_STUCK else -1


def _arrays(model: ConventionalVehicle) -> tuple[np.ndarray, np.ndarray]:
    """The gearbox ratios and efficiencies [-] as writable C arrays (one numba type)."""
    return tuple(np.require(a, np.float64, ("C", "W")) for a in (model.gear_ratios, model.gear_efficiencies))  # type: ignore[return-value]


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
    t, v_des, grade = grid_arrays(grid)
    controller.reset(soc_initial)
    cols = np.zeros((len(COLUMNS), t.size))
    audit = np.zeros(len(AUDIT))
    summary = np.zeros(len(K.SUMMARY))
    d = model.driveline_data()
    status, k, v_end, _, gear = _run_variant(
        0, t, v_des, grade, float(soc_initial), run_scalars(model, controller), *_arrays(model), d.stop_start,
        d.use_fuel_map, d.lhv_jpkg, writable(model.engine.kernel_tables()), SLOTS, cols, audit, summary,
    )  # fmt: skip
    if status == ERR_STUCK:
        raise DomainError(f"{model.name}: no feasible control at t = {t[k]:g} s even when stopping.")
    controller.gear = int(gear)
    columns = {name: cols[j] for j, name in enumerate(COLUMNS)}
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
    n = int(np.size(soc_initial))
    scalars = run_scalars(model, controller, n)._asdict()
    for key, values in variants.items():
        name, factor = VARIANT_KEYS[key]
        if name:
            scalars[name] = np.ascontiguousarray(np.asarray(values, dtype=np.float64) * factor)
    t, v_des, grade = grid_arrays(grid)
    audit = np.zeros((n, len(AUDIT)))
    summary = np.zeros((n, len(K.SUMMARY)))
    out = np.zeros((n, 2))
    d = model.driveline_data()
    soc0 = np.ascontiguousarray(soc_initial, dtype=np.float64)
    _run_batch(
        t, v_des, grade, soc0, RunScalars(**scalars), *_arrays(model), d.stop_start, d.use_fuel_map,
        d.lhv_jpkg, writable(model.engine.kernel_tables()), SLOTS, audit, summary, out,
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

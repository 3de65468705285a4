"""The one compiled forward loop (issue 24 item 2) into which every architecture plugs its
scalar point kernels.

:func:`run_loop` is :func:`hevsim.sim.forward._run` compiled, for every architecture that has
a compiled run: each step the **driver** asks for the wheel force that brings the car to the
cycle's next speed (:func:`demand`, eq 32), the **battery model** begins its step
(:func:`battery_begin`: tables, a cell's or a pack's step with its BMS limits and cooling load),
the architecture's **supervisory controller** picks a control over its **point kernels**
(``choose``), and where none exists the end speed is lowered by **bisection** (the car falls
behind the trace; with a pack, a coast to rest); the chosen control's **power flow** fills the
step's details and audit powers (``point``: point kernels and the shared **bus balance**), the
controller updates its state (``commit``), then the loop keeps the **energy audit**, the
**bookkeeping** (engine starts, trace error, records) and ends the **battery step**
(:func:`battery_end`).

An architecture is a plug-in: a named tuple of its data (tables, controller constants,
candidate grids) registered with :func:`register` together with three compiled functions::

    choose(plug, state, work, v_mid, w_wheel, t_wheel, soc, dt, e_soc, bat, hk)
        -> (found, c0, c1, filled, fuel_kg, d_soc)
    point(plug, state, work, c0, c1, v_mid, w_wheel, t_wheel, soc, dt, bat, hk)
        -> (fuel_kg, d_soc)                       # fills the details and audit powers
    commit(plug, state, work, v_mid, f, soc, dt, e_soc, hk, has_pack)
        -> (engine_on, power_mode, battery_power_w, battery_current_a, wheel_power_w)

(``filled``: ``choose`` has already filled the chosen control's details and audit powers, so
``point`` is not called.) ``commit``'s engine state ``on``: true (1) the engine fired, false (0)
off, a value between (0.5: a series genset turning unfired, cranking or a current source on)
counts an engine start but no engine-on time.

``bat`` is the battery model's state of the step (:func:`battery_begin`: OCV [V], discharge and
charge resistance [ohm], largest charge power [W], charge OCV [V]), ``hk`` the run constants
with the step's current limits [A] and bus load [W]; ``commit``'s battery power [W] ends the
battery model's step (:func:`battery_end`).

The **driver** is a fourth, optional role: ``drive(plug, state, work, k, v, soc, t, v_des, gr,
dt, h, bat, hk, e_soc, bms, audit) -> (ok, v1, v_mid, a, grade, f, limited, fuel_kg, d_soc)``
advances step ``k`` from the speed ``v``: the end and mid-step speeds [m/s], the acceleration
[m/s²], the grade [-], the wheel force [N], 1.0 where the car fell behind its powertrain's
limit, fuel [kg] and SOC change [-], and adds the road side and the battery side of the energy
audit (``ok`` False: stuck; ``bms``: the battery's limits are a BMS's, to hold on every step,
:func:`~hevsim.battery.vehicle.vehicle_bus_has_bms`). By default it is the loop's own (the
demand-side driver of eq 32, the plug-in's ``choose``, the bisection, ``point``, then the road
side of the audit, :func:`add_road_audit`, and the battery side: a branch of :func:`run_loop` on
the constant :func:`plug_drives`, so the other plug-ins' code is what it was); a plug-in with a
driver and vehicle dynamics of its own registers its ``drive`` (the series HEV's proportional
driver with explicit-Euler dynamics and genset shaft, :mod:`hevsim.sim._compiled_series`) and
needs no ``choose`` or ``point``. numba compiles :func:`run_loop` once per plug-in type (the
dispatch :func:`plug_choose`, :func:`plug_point`, :func:`plug_commit` is resolved while typing,
an ``@overload`` looking the type up in :data:`PLUGINS`), so each architecture gets its own
machine code, cached on disk like any kernel: numba dispatchers passed as arguments would do the
same but are not cacheable (their type holds the object, another in every process), so each
process would compile the loop again.

The pieces every forward loop shares, the Python reference loop too, live here as well: the
road side of the energy audit (:func:`add_road_audit`), the trace-following bookkeeping
(:func:`track_step`, :func:`write_summary`), the battery step (:func:`battery_begin`,
:func:`battery_end`, :func:`pack_arrays`) and the threaded batch of compiled runs
(:func:`threaded_batch`).

The loop allocates nothing and runs without numba's reference counting (``_nrt=False``):
passing the component tables (tuples of arrays) into the per-point kernels otherwise costs
about 100 ns of reference-count traffic per candidate, more than the physics.
"""

from __future__ import annotations

import warnings
from typing import Any, NamedTuple

import numpy as np
from numba import njit, types
from numba.core.errors import NumbaIRAssumptionWarning
from numba.extending import overload

from hevsim.architectures._common import NO_REFCOUNT
from hevsim.battery.vehicle import vehicle_bus_begin, vehicle_bus_finish_power, vehicle_bus_has_bms
from hevsim.components.battery import pack_ocv_r_both
from hevsim.components.body import grade_force, road_load_force, rolling_force
from hevsim.components.bus import battery_power_limits
from hevsim.components.flow import LIMIT_RTOL
from hevsim.sim import kernel as K
from hevsim.sim._records import BISECTION_STEPS, REGEN_CURRENT_RTOL, BatchRecord

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
"""First channels of a :class:`~hevsim.sim.forward.ForwardRecord`, in order; then the
architecture's details, ``power_mode``, ``traction_limited``, the plug-in's extra channels and,
with a battery, ``battery_ocv_v``, ``battery_voltage_v``."""
BATTERY_COLUMNS = ("battery_ocv_v", "battery_voltage_v")
"""Last channels of a run with a battery."""
AUDIT_BASE = ("fuel", "genset_source", "battery_chemical", "aero", "rolling", "grade", "kinetic_vehicle")
"""Audit terms the reference loop starts with (then the architecture's loss terms, then
``battery_loss`` with a battery)."""
AUDIT_ROAD = ("aero", "rolling", "grade", "kinetic_vehicle")
"""Audit terms :func:`add_road_audit` fills, at indices 3-6 of a loop's audit array (after
``fuel``, ``genset_source``, ``battery_chemical``), as in :func:`hevsim.sim.forward._run`."""
ERR_NONE, ERR_STUCK = 0, 1
"""Status codes of :func:`run_loop`: fine; no feasible control even when stopping."""


class RunConstants(NamedTuple):
    """Body, wheel, traction machine, pack and run constants of a compiled run (SI): the
    machine's kind code, constant efficiency and torque scale; the pack's cells in series and
    parallel, wiring resistance [ohm], temperature [K], current limits [A], coulombic
    efficiency, capacity [A·s]; the SOC window; the other bus load [W]; the body's mass [kg],
    rotating-mass factor, drag coefficient, frontal area [m²], air density [kg/m³], headwind
    [m/s], rolling coefficients [-] and [s/m]; the tire radius [m]; the fuel's LHV [J/kg]. A
    vehicle without a traction machine or battery has zeros there."""

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


def constants(model: Any, soc_min: float, soc_max: float, lhv_jpkg: float | None = None) -> RunConstants:
    """The :class:`RunConstants` of a model with a traction machine (``motor``) and a battery
    pack; ``lhv_jpkg`` [J/kg]: its fuel's LHV (default its engine's)."""
    m, b, body = model.motor, model.battery, model.body
    lhv = float(model.engine.fuel_lhv_jpkg) if lhv_jpkg is None else float(lhv_jpkg)
    return RunConstants(
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
        lhv_jpkg=lhv,
    )


# ------------------------------------------------------------------------- plug-ins
class Plugin(NamedTuple):
    """An architecture's compiled functions (module docstring); ``drive`` None: the loop's
    own driver. ``limit_rtol``: (discharge, charge) relative excess over a battery current
    limit its feasibility test accepts; a pack's BMS limits are handed to it divided by ``1 +
    rtol`` (:func:`battery_begin`) so that no accepted step exceeds them."""

    choose: Any
    point: Any
    commit: Any
    drive: Any = None
    limit_rtol: tuple[float, float] = (LIMIT_RTOL, REGEN_CURRENT_RTOL)


PLUGINS: dict[type, Plugin] = {}
"""Plug-in data type (a named tuple class) -> its :class:`Plugin`."""


def register(
    data_type: type, choose: Any, point: Any, commit: Any, drive: Any = None,
    limit_rtol: tuple[float, float] = (LIMIT_RTOL, REGEN_CURRENT_RTOL),
) -> None:  # fmt: skip
    """Make ``data_type`` (a named tuple class) a plug-in of :func:`run_loop`; ``drive``: its
    own driver and vehicle dynamics (module docstring; None: the loop's own, which calls
    ``choose`` and ``point``; with a ``drive``, ``choose`` and ``point`` may be None);
    ``limit_rtol``: :attr:`Plugin.limit_rtol` ((0, 0): the plug-in holds a BMS's limits
    exactly itself)."""
    if drive is not None:
        choose = choose or _no_choose
        point = point or _no_point
    PLUGINS[data_type] = Plugin(choose, point, commit, drive, (float(limit_rtol[0]), float(limit_rtol[1])))


def _registered(plug: Any) -> Plugin | None:
    """The :class:`Plugin` of the numba type ``plug`` (None: not a plug-in)."""
    return PLUGINS.get(getattr(plug, "instance_class", None))  # type: ignore[arg-type]


def _plugin(plug: Any, role: str) -> Any:
    """The registered function ``role`` of the numba type ``plug`` (None: not a plug-in)."""
    found = _registered(plug)
    return None if found is None else getattr(found, role)


_PY_CALL = (
    "{} exists only in compiled code: numba replaces it with the registered plug-in's function "
    "(register); call the plug-in's own function from Python"
)


def plug_choose(plug, state, work, v_mid, w_wheel, t_wheel, soc, dt, e_soc, bat, hk):
    """The plug-in's ``choose`` (compiled code only: the target of :func:`_ov_choose`)."""
    raise NotImplementedError(_PY_CALL.format("plug_choose"))


def plug_point(plug, state, work, c0, c1, v_mid, w_wheel, t_wheel, soc, dt, bat, hk):
    """The plug-in's ``point`` (compiled code only: the target of :func:`_ov_point`)."""
    raise NotImplementedError(_PY_CALL.format("plug_point"))


def plug_commit(plug, state, work, v_mid, f, soc, dt, e_soc, hk, has_pack):
    """The plug-in's ``commit`` (compiled code only: the target of :func:`_ov_commit`)."""
    raise NotImplementedError(_PY_CALL.format("plug_commit"))


def plug_drive(plug, state, work, k, v, soc, t, v_des, gr, dt, h, bat, hk, e_soc, bms, audit):
    """The plug-in's ``drive`` (compiled code only: the target of :func:`_ov_drive`)."""
    raise NotImplementedError(_PY_CALL.format("plug_drive"))


@overload(plug_choose, inline="always")
def _ov_choose(plug, state, work, v_mid, w_wheel, t_wheel, soc, dt, e_soc, bat, hk):
    fn = _plugin(plug, "choose")
    if fn is None:
        return None

    def impl(plug, state, work, v_mid, w_wheel, t_wheel, soc, dt, e_soc, bat, hk):
        return fn(plug, state, work, v_mid, w_wheel, t_wheel, soc, dt, e_soc, bat, hk)

    return impl


@overload(plug_point, inline="always")
def _ov_point(plug, state, work, c0, c1, v_mid, w_wheel, t_wheel, soc, dt, bat, hk):
    fn = _plugin(plug, "point")
    if fn is None:
        return None

    def impl(plug, state, work, c0, c1, v_mid, w_wheel, t_wheel, soc, dt, bat, hk):
        return fn(plug, state, work, c0, c1, v_mid, w_wheel, t_wheel, soc, dt, bat, hk)

    return impl


@overload(plug_commit, inline="always")
def _ov_commit(plug, state, work, v_mid, f, soc, dt, e_soc, hk, has_pack):
    fn = _plugin(plug, "commit")
    if fn is None:
        return None

    def impl(plug, state, work, v_mid, f, soc, dt, e_soc, hk, has_pack):
        return fn(plug, state, work, v_mid, f, soc, dt, e_soc, hk, has_pack)

    return impl


def plug_drives(plug):
    """Whether the plug-in brings its own ``drive`` (compiled code only: the target of
    :func:`_ov_drives`, a constant of the plug-in's type)."""
    raise NotImplementedError(_PY_CALL.format("plug_drives"))


@overload(plug_drives, inline="always")
def _ov_drives(plug):
    found = _registered(plug)
    if found is None:
        return None
    own = found.drive is not None
    return lambda plug: own


def plug_limit_rtol(plug):
    """The plug-in's :attr:`Plugin.limit_rtol` (compiled code only: the target of
    :func:`_ov_limit_rtol`, constants of the plug-in's type)."""
    raise NotImplementedError(_PY_CALL.format("plug_limit_rtol"))


@overload(plug_limit_rtol, inline="always")
def _ov_limit_rtol(plug):
    found = _registered(plug)
    if found is None:
        return None
    rtol_dis, rtol_chg = found.limit_rtol
    return lambda plug: (rtol_dis, rtol_chg)


@njit(cache=True, inline="always")
def _no_drive(plug, state, work, k, v, soc, t, v_des, gr, dt, h, bat, hk, e_soc, bms, audit):
    """The ``drive`` of a plug-in without one: never run (:func:`run_loop` takes its own driver
    for it), typed only (results: :func:`plug_drive`'s)."""
    return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0


@njit(cache=True, inline="always")
def _no_choose(plug, state, work, v_mid, w_wheel, t_wheel, soc, dt, e_soc, bat, hk):
    """The ``choose`` of a plug-in with its own ``drive``: never run, typed only."""
    return False, 0.0, 0.0, False, 0.0, 0.0


@njit(cache=True, inline="always")
def _no_point(plug, state, work, c0, c1, v_mid, w_wheel, t_wheel, soc, dt, bat, hk):
    """The ``point`` of a plug-in with its own ``drive``: never run, typed only."""
    return 0.0, 0.0


@overload(plug_drive, inline="always")
def _ov_drive(plug, state, work, k, v, soc, t, v_des, gr, dt, h, bat, hk, e_soc, bms, audit):
    found = _registered(plug)
    if found is None:
        return None
    fn = _no_drive if found.drive is None else found.drive

    def impl(plug, state, work, k, v, soc, t, v_des, gr, dt, h, bat, hk, e_soc, bms, audit):
        return fn(plug, state, work, k, v, soc, t, v_des, gr, dt, h, bat, hk, e_soc, bms, audit)

    return impl


def engine_state(on):
    """(engine turning: counts a start, engine fired: counts engine time) of ``commit``'s ``on``
    (compiled code only: the target of :func:`_ov_engine_state`)."""
    raise NotImplementedError(_PY_CALL.format("engine_state"))


@overload(engine_state, inline="always")
def _ov_engine_state(on):
    if isinstance(on, types.Boolean):  # on: fired (the code of every plug-in but the series)
        return lambda on: (on, on)
    return lambda on: (on > 0.0, on >= 1.0)  # 1 fired; 0 < on < 1 turning unfired (a series genset)


# numba inlines a plug-in's choice (with the point kernels inlined in it) at each of the loop's
# four call sites of plug_choose, as the loops before it inlined the point kernels; its SSA
# reconstruction then reports the phi variables of the copies (the BEV's _feasible) with an
# "internal pedantic check". The code is right (the compiled runs equal the Python loop to the
# last bit, tests/test_forward_compiled_*.py); the warning, for these inlined copies only, would
# reach a user at the first compile. (One call site instead: no warning, but numba's LLVM then
# inlines the HEV controller into the loop, 20 % slower.)
warnings.filterwarnings(
    "ignore", message="variable '_ov_choose__locals__impl", category=NumbaIRAssumptionWarning
)


# ------------------------------------------------------------------------- shared pieces
@njit(cache=True, inline="always")
def add_road_audit(audit, v0, v1, v_mid, a, g, f, mass_kg, m_eff, crr, crr_v, dt):
    """Add one step's road energies [J] to ``audit[3:7]`` (:data:`AUDIT_ROAD`): speeds at the
    start, end and middle of the step [m/s], acceleration [m/s²], grade [-], wheel force [N],
    mass and effective (rotating) mass [kg], rolling coefficients [-] and [s/m], step [s]. Aero is the
    rest of the road load of eq (32); nothing is added at a standstill."""
    if v_mid > 0.0:
        f_grade = grade_force(mass_kg, g)
        f_roll = rolling_force(mass_kg, g, crr, crr_v, v_mid)
        f_aero = f - m_eff * a - f_roll - f_grade
        audit[3] += f_aero * v_mid * dt
        audit[4] += f_roll * v_mid * dt
        audit[5] += f_grade * v_mid * dt
        audit[6] += 0.5 * m_eff * (v1 * v1 - v0 * v0)


@njit(cache=True, inline="always")
def track_step(err, v_mid, dt, limited, err_sq, err_max, dist, lim_s):
    """One step of the trace-following bookkeeping: speed error at the step's start
    ``err`` [m/s], mid-step speed [m/s], step [s], ``limited`` (1.0 when the car fell behind
    the trace, else 0.0). Returns the updated (sum of squared errors [m²/s²], largest error
    [m/s], distance [m], time limited [s])."""
    return err_sq + err * err, max(err_max, abs(err)), dist + v_mid * dt, lim_s + limited * dt


@njit(cache=True, inline="always")
def write_summary(summary, err_end, err_sq, err_max, n, dist, fuel, soc, eon, starts, lim_s, duration):
    """Fill ``summary`` (:data:`hevsim.sim.kernel.SUMMARY`) at the end of a run of ``n`` steps:
    the end error ``err_end`` [m/s] joins the RMS (over the ``n + 1`` samples) and the largest
    error; distance [m], fuel [kg], final SOC [-], engine-on time [s], engine starts, time
    limited [s], duration [s]."""
    err_sq += err_end * err_end
    err_max = max(err_max, abs(err_end))
    summary[K.S_DIST], summary[K.S_FUEL], summary[K.S_SOCF] = dist, fuel, soc
    summary[K.S_RMS], summary[K.S_MAXERR], summary[K.S_EON] = np.sqrt(err_sq / (n + 1)), err_max, eon
    summary[K.S_STARTS], summary[K.S_BLIM], summary[K.S_DUR] = starts, lim_s, duration


@njit(cache=True, inline="always", error_model="numpy")
def demand(v0, v1, k, dt, gr, h):
    """The driver (eq 32): (mid-step speed [m/s], acceleration [m/s²], grade [-], wheel force
    [N]) of the step ``k`` from ``v0`` to ``v1`` [m/s] (grades ``gr`` [-], :class:`RunConstants`
    ``h``)."""
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


@njit(cache=True, inline="always", error_model="numpy")
def _battery(soc, h, ptab):
    """(OCV [V], discharge and charge resistance [ohm], largest charge power [W], charge OCV
    [V]: the same) at ``soc`` (the forward loop's battery state: no charging when full)."""
    ocv, r_dis, r_chg = pack_ocv_r_both(soc, h.temperature_k, h.n_series, h.n_parallel, h.r_extra_ohm, ptab)
    p_chg = battery_power_limits(ocv, r_dis, ocv, r_chg, h.i_discharge_max_a, h.i_charge_max_a)[1]
    if soc >= h.soc_max:  # full: no charging (regeneration goes to the friction brakes)
        p_chg = 0.0
    return ocv, r_dis, r_chg, p_chg, ocv


@njit(cache=True, inline="always")
def _step_constants(h, i_dis, i_chg, aux_w):
    """``h`` with the battery's current limits [A] and the bus's other load [W] of one step
    (a pack's BMS limits and cooling load, :func:`battery_begin`)."""
    return RunConstants(
        h.motor_kind, h.motor_efficiency, h.motor_torque_scale, h.n_series, h.n_parallel, h.r_extra_ohm,
        h.temperature_k, i_dis, i_chg, h.coulombic_efficiency, h.capacity_as, h.soc_min, h.soc_max, aux_w,
        h.mass_kg, h.mass_factor, h.drag_coefficient, h.frontal_area_m2, h.air_density_kgpm3, h.headwind_mps,
        h.rolling_resistance, h.rolling_resistance_speed_s_per_m, h.radius_m, h.lhv_jpkg,
    )  # fmt: skip


@njit(cache=True, inline="always", error_model="numpy")
def battery_begin(soc, h, ptab, pk, rtol_dis, rtol_chg):
    """The battery model's start of a step: (the bus's battery state ``(OCV [V], discharge
    and charge resistance [ohm], largest charge power [W], charge OCV [V])``, the run
    constants for the step; a pack's BMS limits there divided by ``1 + rtol_dis``, ``1 +
    rtol_chg``: :attr:`Plugin.limit_rtol`).
    ``ptab`` None: no battery (zeros, ``h`` as it is). ``pk`` None: the pack tables ``ptab``
    at the vehicle's ``soc`` [-] (:func:`_battery`) and ``h`` as it is. ``pk`` a pack's
    :class:`~hevsim.battery.pack_run.PackArrays` (``[battery] model = "pack"``): the pack's
    compiled step begins (:func:`~hevsim.battery.pack_run.pack_begin`: BMS limits, Thevenin
    pairs, cooling decision) and :func:`~hevsim.battery.pack_run.pack_bus_state` gives the
    state, the current limits and the cooling load on the bus (in ``h``), as the Python loop's
    :meth:`hevsim.battery.bms.PackRun.vehicle_step`. ``pk`` a ``[battery] model = "cell"``
    battery's :data:`~hevsim.battery.vehicle.CellBusTables`: the pack's step pairs of its
    representative cell (:func:`~hevsim.battery.vehicle.cell_bus_state`), the limits and load of
    ``h``, as :meth:`hevsim.battery.cell_run.CellRun.vehicle_step`. Both through
    :func:`~hevsim.battery.vehicle.vehicle_bus_begin`."""
    if ptab is None:
        return (0.0, 0.0, 0.0, 0.0, 0.0), h
    if pk is None:
        return _battery(soc, h, ptab), h
    ocv, r_dis, r_chg, p_chg, i_dis, i_chg, aux_w, ocv_chg = vehicle_bus_begin(
        pk, soc, h.soc_max, h.i_discharge_max_a, h.i_charge_max_a, h.aux_power_w, rtol_dis, rtol_chg
    )
    return (ocv, r_dis, r_chg, p_chg, ocv_chg), _step_constants(h, i_dis, i_chg, aux_w)


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


# ------------------------------------------------------------------------- the loop
@njit(cache=True, nogil=True, error_model="numpy", **NO_REFCOUNT)
def run_loop(plug, soc0, t, v_des, gr, h, ptab, state, work, det, loss, ext, slots, cols, audit, summary, pk):
    """One forward run (the compiled :func:`hevsim.sim.forward._run`) of the architecture of
    the plug-in ``plug`` (module docstring) from the SOC ``soc0`` [-] over the grid ``t`` [s],
    ``v_des`` [m/s], ``gr`` [-] (``n + 1`` points), with the run constants ``h``
    (:class:`RunConstants`), the battery's tables ``ptab`` (None: no battery) and the
    controller's ``state`` (set by the caller, updated by the plug-in). ``work``: the
    plug-in's work arrays; ``det``, ``loss``, ``ext``: the step's details, audit powers [W]
    (``fuel`` first) and extra channels, filled by the plug-in; ``slots``: the audit index of
    each entry of ``loss`` (-1: none). Fills ``cols`` (channels x ``n + 1``: :data:`BASE_COLUMNS`,
    the details, ``power_mode``, ``traction_limited``, the extras, with a battery
    :data:`BATTERY_COLUMNS`; fewer than ``n + 1`` columns: no time series), ``audit`` (the
    indices of ``slots``, :data:`AUDIT_BASE`, ``battery_loss`` last with a battery; [J]) and
    ``summary`` (:data:`hevsim.sim.kernel.SUMMARY`). Returns (status :data:`ERR_NONE` or
    :data:`ERR_STUCK`, step index, final speed [m/s], positive wheel energy [J]). ``pk``:
    None, or the pack or cell battery stepped in the loop (:func:`battery_begin`,
    :func:`battery_end`)."""
    n = t.shape[0] - 1
    dt = t[1] - t[0]
    nd, nl, nx = det.shape[0], loss.shape[0], ext.shape[0]
    has_battery = ptab is not None
    has_pack = pk is not None
    record = cols.shape[1] > n
    m_eff = h.mass_kg * h.mass_factor
    r = h.radius_m
    q_as = h.capacity_as
    i_batloss = audit.shape[0] - 1
    v, soc, fuel = v_des[0], soc0, 0.0
    err_sq = err_max = dist = eon = starts = lim_s = traction = 0.0
    was_on = False
    own_drive = plug_drives(plug)
    rtol_dis, rtol_chg = plug_limit_rtol(plug)
    bms = vehicle_bus_has_bms(pk)
    for k in range(n):
        bat, hk = battery_begin(soc, h, ptab, pk, rtol_dis, rtol_chg)
        ocv = bat[0]
        e_soc = q_as * ocv if has_battery else 1.0
        if own_drive:  # the plug-in's driver and vehicle dynamics, with its road audit
            ok, v1, v_mid, a, g, f, limited, fuel_kg, d_soc = plug_drive(
                plug, state, work, k, v, soc, t, v_des, gr, dt, h, bat, hk, e_soc, bms, audit
            )
            if not ok:
                return ERR_STUCK, k, v, traction * dt
        else:  # the loop's driver: the cycle's next speed (eq 32), the plug-in's choice, a bisection
            v1 = v_des[k + 1]
            v_mid, a, g, f = demand(v, v1, k, dt, gr, h)
            found, c0, c1, filled, fuel_kg, d_soc = plug_choose(
                plug, state, work, v_mid, v_mid / r, f * r, soc, dt, e_soc, bat, hk
            )
            limited = 0.0
            if not found:  # beyond the powertrain: lower the end speed until a control exists
                limited = 1.0
                lo, hi, have = 0.0, v1, False
                bv = ba = bg = bf = bc0 = bc1 = 0.0
                for _ in range(BISECTION_STEPS):
                    mid = 0.5 * (lo + hi)
                    tv, ta, tg, tf = demand(v, mid, k, dt, gr, h)
                    ok, x0, x1, _, _, _ = plug_choose(
                        plug, state, work, tv, tv / r, tf * r, soc, dt, e_soc, bat, hk
                    )
                    if not ok:
                        hi = mid
                    else:
                        lo, have = mid, True
                        bv, ba, bg, bf, bc0, bc1 = tv, ta, tg, tf, x0, x1
                if not have:
                    bv, ba, bg, bf = demand(v, 0.0, k, dt, gr, h)
                    ok, bc0, bc1, _, _, _ = plug_choose(
                        plug, state, work, bv, bv / r, bf * r, soc, dt, e_soc, bat, hk
                    )
                    if not ok and bf > 0.0 and has_pack:  # coast to rest (forward._run, with a pack)
                        bf = 0.0
                        ok, bc0, bc1, _, _, _ = plug_choose(
                            plug, state, work, bv, bv / r, bf * r, soc, dt, e_soc, bat, hk
                        )
                    if not ok:
                        return ERR_STUCK, k, v, traction * dt
                v_mid, a, g, f, c0, c1 = bv, ba, bg, bf, bc0, bc1
                v1 = v_mid * 2.0 - v
                filled = False
            if not filled:  # the chosen control's details and audit powers
                fuel_kg, d_soc = plug_point(
                    plug, state, work, c0, c1, v_mid, v_mid / r, f * r, soc, dt, bat, hk
                )
        on, mode, p_bat, i_bat, p_wheel = plug_commit(
            plug, state, work, v_mid, f, soc, dt, e_soc, hk, has_pack
        )
        # ---- energy audit [J]
        for j in range(nl):
            if slots[j] >= 0:
                audit[slots[j]] += loss[j] * dt
        if not own_drive:  # (a plug-in with its own driver keeps its battery's and road audit)
            if has_battery:
                e_chem = -d_soc * q_as * ocv
                audit[2] += e_chem
                audit[i_batloss] += e_chem - p_bat * dt
            add_road_audit(
                audit, v, v1, v_mid, a, g, f, h.mass_kg, m_eff, h.rolling_resistance,
                h.rolling_resistance_speed_s_per_m, dt,
            )  # fmt: skip
        # ---- bookkeeping
        running, fired = engine_state(on)
        if running and not was_on:
            starts += 1.0
        was_on = running
        fuel += fuel_kg
        eon += dt if fired else 0.0
        err_sq, err_max, dist, lim_s = track_step(
            v_des[k] - v, v_mid, dt, limited, err_sq, err_max, dist, lim_s
        )
        traction += max(p_wheel, 0.0)
        if record:
            row = (v_des[k], v, a, f, p_wheel, f - m_eff * a, fuel, soc)
            for j in range(len(row)):
                cols[j, k] = row[j]
            b = len(BASE_COLUMNS)
            for j in range(nd):
                cols[b + j, k] = det[j]
            b += nd
            cols[b, k] = mode
            cols[b + 1, k] = limited
            b += 2
            for j in range(nx):
                cols[b + j, k] = ext[j]
            if has_battery:
                b += nx
                cols[b, k] = ocv
                cols[b + 1, k] = p_bat / i_bat if i_bat != 0.0 else ocv
        v, soc = v1, battery_end(soc, d_soc, p_bat, pk)
    write_summary(summary, v_des[n] - v, err_sq, err_max, n, dist, fuel, soc, eon, starts, lim_s, t[n] - t[0])
    return ERR_NONE, n, v, traction * dt


# ------------------------------------------------------------------------- Python side
def audit_slots(loss_terms: tuple[str, ...], audit_names: tuple[str, ...]) -> np.ndarray:
    """The ``slots`` of :func:`run_loop`: for each of the architecture's audit powers
    ``loss_terms``, its index in ``audit_names`` (``wheel``: -1, not an audit term)."""
    return np.array([-1 if term == "wheel" else audit_names.index(term) for term in loss_terms], np.int64)


def grid_arrays(grid: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(time [s], speed [m/s], grade [-]) of a resampled cycle as writable C-contiguous
    float64 arrays (one numba type for every run)."""
    return tuple(np.require(a, np.float64, ("C", "W")) for a in (grid.time_s, grid.speed_mps, grid.grade))  # type: ignore[return-value]


def writable(tab: Any) -> Any:
    """``tab`` (a named tuple of arrays and scalars) with its read-only arrays copied: a
    read-only array is another numba type, so a machine whose map arrays are read-only would
    compile :func:`run_loop` a second time (about 20 s) for the same architecture."""
    if all(a.flags.writeable for a in tab if isinstance(a, np.ndarray)):
        return tab
    return type(tab)(*(a.copy() if isinstance(a, np.ndarray) and not a.flags.writeable else a for a in tab))


def pack_arrays(pack: Any, model: Any, steps: int) -> Any:
    """The ``pk`` argument of :func:`run_loop`: None without a pack; for a
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


MODEL_KEYS = ("body.mass_kg", "body.mass_factor", "body.drag_coefficient", "body.frontal_area_m2",
              "body.rolling_resistance", "tire.radius_m", "engine.torque_scale")  # fmt: skip
"""Configuration keys a threaded compiled batch varies on the built model (others: the Python path)."""


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


def threaded_batch(
    model: Any, variants: dict[str, np.ndarray], grid: Any, controller: Any, soc_initial: np.ndarray, run: Any
) -> BatchRecord | None:
    """Every variant (:func:`_variant`) a compiled run on its own thread of a pool (the
    compiled loop releases the GIL): ``run(variant model, its controller, initial SOC)``
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

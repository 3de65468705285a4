"""Parallel hybrid-electric vehicle: model, admissible controls and THE power flow.

The architecture is the one of the thesis's appendix DP script (Loghavi 2015): an engine
driving the wheels through a clutch, a multi-speed gearbox and the final drive, and an
electric machine coupled to the final-drive input through a fixed gear ("EM gear ratio",
a P3 machine; ``[motor_coupling] position = "p3"``). With ``position = "p2"`` the machine
sits between the clutch and the gearbox instead (engine - clutch - machine - gearbox): it
turns with the gearbox input and drives through the gearbox, in EV mode too. At a
standstill, or when the engine cannot turn at its running speed in the chosen gear, the
clutch opens and the machine alone drives. The battery sits on the machine's DC bus.

Controls (:data:`CONTROLS`): the gear (1..G) and the engine throttle ``u`` in [0, 1];
``u = 0`` is engine off with the clutch open (EV mode; the gear is then irrelevant for P3).

:func:`mechanical` and :func:`electrical` are the one vectorised power flow of this
architecture: (wheel demand, control) -> engine and gearbox operating points, then (state)
-> machine, battery, SOC change and fuel, with every component limit as a flag. The DP
(:mod:`hevsim.optimal._parallel_dp`) calls them over the whole grid of steps x gears x
throttles x SOC; the forward simulator (:mod:`hevsim.sim.forward`) and the online
controllers (:mod:`hevsim.control`) call them for the candidate controls of one step, and
:func:`loss_powers` turns the same operating points into the energy audit's terms.

A configuration file holds ``[powertrain] architecture = "parallel"`` and the shared sections
of :mod:`hevsim.config` (:class:`~hevsim.config.ParallelHEVConfig`: body, tire, final_drive,
gearbox, engine, motor, motor_coupling, battery, simulation, controller, optimization,
metrics); every key is checked on load. ``examples/parallel_hev.toml`` documents every key.
"""

from __future__ import annotations

import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from hevsim.architectures._build import build_battery, build_engine, build_machine
from hevsim.architectures._common import (
    NO_REFCOUNT,
    GearboxModel,
    broadcast_loop,
    chassis,
    fixed_gear,
    max_machine_speed_radps,
)
from hevsim.components.battery import BatteryPack
from hevsim.components.body import VehicleBody
from hevsim.components.driveline import Gear, Tire, gear_input_torque, gear_output_torque
from hevsim.components.electric_machine import ElectricMachine
from hevsim.components.engine import Engine, fired_fuel_from_maps, torque_from_maps
from hevsim.config import ParallelHEVConfig, config_from_dict, load_vehicle_config
from hevsim.errors import ConfigError
from hevsim.fuels import with_config_fuel

__all__ = ["ARCHITECTURE", "ParallelHEV", "ParallelHEVConfig", "build_parallel_hev", "load_parallel_config",
           "parallel_from_dict"]  # fmt: skip

ARCHITECTURE = "parallel"
"""Value of ``[powertrain] architecture`` of a parallel-HEV configuration file."""
HAS_CLUTCH = True
"""An engine clutch: the forward results carry ``clutch_closed`` (closed iff the engine is on)."""


def parallel_from_dict(
    data: dict[str, Any], source: str = "<config>", base_dir: Path | None = None
) -> ParallelHEVConfig:
    """Validate a parsed parallel-HEV mapping (``[powertrain]`` may be omitted here)."""
    data = dict(data)
    if "powertrain" not in data and "architecture" not in data:
        data["powertrain"] = {"architecture": ARCHITECTURE}
    cfg = config_from_dict(data, source, base_dir)
    if not isinstance(cfg, ParallelHEVConfig):
        raise ConfigError(
            f"{source}: key 'powertrain.architecture' = {cfg.architecture!r}; expected {ARCHITECTURE!r} here."
        )
    return cfg


def load_parallel_config(path: str | Path) -> ParallelHEVConfig:
    """Read and validate a parallel-HEV TOML configuration file."""
    p = Path(path)
    cfg = load_vehicle_config(p)
    if not isinstance(cfg, ParallelHEVConfig):
        raise ConfigError(
            f"{p}: key 'powertrain.architecture' = {cfg.architecture!r}; expected {ARCHITECTURE!r} here."
        )
    return cfg


@dataclass(frozen=True, eq=False)
class ParallelHEV(GearboxModel):
    """A parallel hybrid vehicle: its configuration and component objects.

    Attributes:
        gears: one :class:`Gear` per gearbox ratio (engine path, with the gearbox efficiency).
        final_drive: final drive (both paths). motor_coupling: machine to final-drive input.
    """

    config: ParallelHEVConfig
    body: VehicleBody
    tire: Tire
    final_drive: Gear
    gears: tuple[Gear, ...]
    engine: Engine
    motor: ElectricMachine
    motor_coupling: Gear
    battery: BatteryPack
    machine_position: str = "p3"
    """``"p3"``: machine on the final-drive input; ``"p2"``: on the gearbox input."""
    aux_power_w: float = 0.0
    """Electrical auxiliary load on the bus [W]: ``[controller] aux_power_w`` (plus a pack's
    cooling, :mod:`hevsim.sim.pack_vehicle`)."""

    architecture: typing.ClassVar[str] = ARCHITECTURE


def build_parallel_hev(cfg: ParallelHEVConfig) -> ParallelHEV:
    """Build the component objects of a parallel HEV from its configuration."""
    base = Path(cfg.base_dir)
    engine = build_engine(cfg.engine, base)
    g = cfg.gearbox
    return ParallelHEV(
        **chassis(cfg),
        gears=tuple(Gear(ratio=r, efficiency=g.efficiency) for r in g.ratios),
        engine=with_config_fuel(engine, cfg),  # [fuel] section of the configuration
        motor=build_machine(cfg.motor, "motor", base),
        motor_coupling=fixed_gear(cfg.motor_coupling),
        battery=build_battery(cfg.battery, base)[0],
        machine_position=cfg.motor_coupling.position,
        aux_power_w=cfg.controller.aux_power_w,
    )


# ------------------------------------------------------------------------------------------
# The power flow (one copy: DP grid, ECMS candidates, forward step, energy audit)
# ------------------------------------------------------------------------------------------
CONTROLS: tuple[str, ...] = ("gear", "throttle")
"""Control inputs of the parallel HEV: gear (1..G; ignored with the engine off) and engine
throttle [-] (0 = engine off, clutch open)."""
CONTROL_UNITS: tuple[str, ...] = ("-", "-")


class ParallelTables(NamedTuple):
    """The parallel HEV's driveline constants for compiled code, by name (a swapped value is a
    name error): gearbox ratios and efficiencies per gear [-], final drive and machine
    coupling ratio and efficiency [-], ``p2`` (machine on the gearbox input), the engine's
    running window [rad/s], ``torque_scale`` [-], torque-map / fuel-map switches, fuel LHV
    [J/kg], the machine's highest speed [rad/s] (inf without a map) and the auxiliary load on
    the bus [W]."""

    gear_ratio: np.ndarray
    gear_efficiency: np.ndarray
    final_drive_ratio: float
    final_drive_efficiency: float
    coupling_ratio: float
    coupling_efficiency: float
    p2: bool
    stall_radps: float
    redline_radps: float
    engine_torque_scale: float
    use_torque_map: bool
    use_fuel_map: bool
    lhv_jpkg: float
    motor_max_speed_radps: float
    aux_power_w: float


def kernel_tables(hev: ParallelHEV) -> ParallelTables:
    """The :class:`ParallelTables` of a model (the engine's and machine's tables are their
    own ``kernel_tables()``)."""
    eng, fd, cpl = hev.engine, hev.final_drive, hev.motor_coupling
    return ParallelTables(
        gear_ratio=hev.gear_ratios, gear_efficiency=np.array([g.efficiency for g in hev.gears]),
        final_drive_ratio=float(fd.ratio), final_drive_efficiency=float(fd.efficiency),
        coupling_ratio=float(cpl.ratio), coupling_efficiency=float(cpl.efficiency),
        p2=hev.machine_position == "p2", stall_radps=float(eng.stall_speed_radps),
        redline_radps=float(eng.redline_radps), engine_torque_scale=float(eng.torque_scale),
        use_torque_map=eng.torque_map is not None, use_fuel_map=eng.fuel_map is not None,
        lhv_jpkg=float(eng.fuel_lhv_jpkg), motor_max_speed_radps=max_machine_speed_radps(hev.motor),
        aux_power_w=float(hev.aux_power_w),
    )  # fmt: skip


@njit(cache=True, inline="always")
def mechanical_point(wheel_speed_radps, wheel_torque_nm, gear, throttle, grid_duplicates, d, etab):
    """The state-independent half of the power flow at one point (THE scalar kernel; see
    :func:`mechanical`): the final drive, then :func:`driveline_point`. ``d``:
    :class:`ParallelTables`; ``etab``: the engine's :class:`~hevsim.components.engine.EngineTables`.

    Returns (gi, on, engine_speed, motor_speed, bad, w_fd, w_e, t_e, t_e_fd, t_fd, fuel,
    w_em, t_em_req).
    """
    w_fd, t_fd = final_drive_point(wheel_speed_radps, wheel_torque_nm, d)
    return driveline_point(w_fd, t_fd, gear, throttle, grid_duplicates, d, etab)


@njit(cache=True, inline="always")
def final_drive_point(wheel_speed_radps, wheel_torque_nm, d):
    """(speed [rad/s], required torque [N·m]) at the final-drive input for a wheel demand."""
    return (wheel_speed_radps * d.final_drive_ratio,
            gear_input_torque(wheel_torque_nm, d.final_drive_ratio, d.final_drive_efficiency))  # fmt: skip


@njit(cache=True, inline="always")
def driveline_point(w_fd, t_fd, gear, throttle, grid_duplicates, d, etab):
    """:func:`mechanical_point` from the final-drive input's speed [rad/s] and required torque
    [N·m] (loops over many controls at one wheel demand compute those once)."""
    gi = int(np.rint(gear)) - 1
    ratio, eff = d.gear_ratio[gi], d.gear_efficiency[gi]
    w_e = w_fd * ratio
    fired, can_run, on, t_e = engine_torque_point(w_e, throttle, d, etab)
    fuel = t_e_fd = t_in_req = 0.0
    if on:
        fuel = fired_fuel_from_maps(
            t_e, w_e, d.use_fuel_map, d.lhv_jpkg, d.stall_radps, d.redline_radps, d.engine_torque_scale,
            etab.tmax_x, etab.tmax_y, etab.fuel_x, etab.fuel_y, etab.fuel_z,
        )  # fmt: skip
    if d.p2:  # machine on the gearbox input, after the clutch: it turns with the gearbox input
        t_in_req = gear_input_torque(t_fd, ratio, eff)
        w_em = w_e * d.coupling_ratio
        t_em_req = gear_input_torque(t_in_req - t_e, d.coupling_ratio, d.coupling_efficiency)
    else:  # P3: on the final-drive input in every gear (it cannot be declutched)
        if on:
            t_e_fd = gear_output_torque(t_e, ratio, eff)
        w_em = w_fd * d.coupling_ratio
        t_em_req = gear_input_torque(t_fd - t_e_fd, d.coupling_ratio, d.coupling_efficiency)
    engine_speed = fired and not can_run
    motor_speed = abs(w_em) > d.motor_max_speed_radps
    bad = engine_speed or not np.isfinite(fuel) or motor_speed
    if grid_duplicates and not d.p2:  # P3: with the engine off the gear does not matter
        bad = bad or (not fired and gi > 0)
    return gi, on, engine_speed, motor_speed, bad, w_fd, w_e, t_e, t_e_fd, t_fd, fuel, w_em, t_em_req


@njit(cache=True, inline="always")
def engine_torque_point(w_e, throttle, d, etab):
    """The engine of :func:`driveline_point` at speed ``w_e`` [rad/s] and ``throttle`` [-]:
    (fired (``throttle > 0``), within its running window, on (both), brake torque [N·m], 0
    unless on)."""
    fired = throttle > 0.0
    can_run = w_e >= d.stall_radps and w_e <= d.redline_radps
    on = fired and can_run
    t_e = 0.0
    if on:
        t_e = torque_from_maps(
            throttle, w_e, d.use_torque_map, d.stall_radps, d.redline_radps, d.engine_torque_scale,
            etab.tmax_x, etab.tmax_y, etab.tct_x, etab.tct_y, etab.tmap_x, etab.tmap_y, etab.tmap_z,
        )  # fmt: skip
    return fired, can_run, on, t_e


def torque_rises_with_throttle(hev: ParallelHEV, throttles: Any) -> bool:
    """Whether :func:`engine_torque_point`'s torque never falls from one of ``throttles`` [-]
    to the next at any engine speed: the throttles ascend from >= 0 and the engine reads no
    torque map (its torque is ``torque_scale x throttle x max torque(speed)``) with a
    max-torque curve and scale >= 0 (rounding keeps the order of such products)."""
    thr = np.asarray(throttles, dtype=np.float64)
    eng = hev.engine
    return bool(
        eng.torque_map is None
        and eng.torque_scale >= 0.0
        and np.all(eng.kernel_tables().tmax_y >= 0.0)
        and np.all(thr >= 0.0)
        and np.all(np.diff(thr) >= 0.0)
    )


MECH_FLOATS: tuple[str, ...] = ("w_fd", "w_e", "t_e", "t_e_fd", "t_fd", "fuel", "w_em", "t_em_req")
"""Float outputs of :func:`mechanical_point`, in order (keys of :func:`mechanical`)."""
MECH_FLAGS: tuple[str, ...] = ("on", "engine_speed", "motor_speed", "bad")
"""Boolean outputs of :func:`mechanical_point`, in order."""


@njit(cache=True, **NO_REFCOUNT)
def _mechanical_many(w_wheel, t_wheel, gear, throttle, grid_duplicates, d, etab, gi, flags, floats):
    """:func:`mechanical_point` over flat arrays; fills ``gi``, ``flags`` (4, n) and ``floats`` (8, n)."""
    w_last, t_last, w_fd, t_fd = np.nan, np.nan, 0.0, 0.0
    for i in range(w_wheel.shape[0]):
        if w_wheel[i] != w_last or t_wheel[i] != t_last:  # the final drive once per wheel demand
            w_last, t_last = w_wheel[i], t_wheel[i]
            w_fd, t_fd = final_drive_point(w_last, t_last, d)
        r = driveline_point(w_fd, t_fd, gear[i], throttle[i], grid_duplicates, d, etab)
        gi[i] = r[0]
        flags[0, i], flags[1, i], flags[2, i], flags[3, i] = r[1], r[2], r[3], r[4]
        floats[0, i], floats[1, i], floats[2, i], floats[3, i] = r[5], r[6], r[7], r[8]
        floats[4, i], floats[5, i], floats[6, i], floats[7, i] = r[9], r[10], r[11], r[12]


def mechanical(
    hev: ParallelHEV,
    wheel_speed_radps: Any,
    wheel_torque_nm: Any,
    gear: Any,
    throttle: Any,
    *,
    grid_duplicates: bool = False,
) -> dict[str, Any]:
    """The state-independent half of the power flow, broadcast over every argument.

    Wheel demand: speed [rad/s] and torque [N·m] at the wheels. Control: gear (1..G) and
    throttle [-]. The final-drive input turns at ``w_fd = w_wheel i_fd`` and must receive
    ``T_fd`` (the wheel torque through the final drive). In gear ``g`` the engine turns at
    ``w_e = w_fd i_g``; with ``u > 0`` it is fired and clutched in, must turn within its
    running window (stall..redline, eq 29), gives ``T_e = Engine.torque(u, w_e)`` and burns
    ``Engine.fuel_rate(T_e, w_e)`` [kg/s]; the gearbox passes ``Gear.output_torque(T_e)``.
    ``u = 0``: engine off and declutched. The machine (coupling gear on the final-drive
    input) must give the rest: ``t_em_req``. The machine turns with the final-drive input
    (P3, in every gear and in EV mode: it cannot be declutched) or the gearbox input (P2);
    above its highest speed the point is infeasible (``motor_speed``), never extrapolated.
    ``grid_duplicates`` marks every gear but the first with the engine off (duplicates on a
    DP grid) as infeasible. Every point is :func:`mechanical_point` (one compiled loop).

    Returns a dict of arrays: gi (gear index 0..G-1), thr, on, engine_speed (fired but
    outside the running window), motor_speed, bad, w_fd, w_e, t_e, t_e_fd, t_fd, fuel
    [kg/s], w_em, t_em_req.
    """
    b = np.broadcast_arrays(*(np.asarray(a, np.float64) for a in (wheel_speed_radps, wheel_torque_nm, gear,
                                                                  throttle)))  # fmt: skip
    shape = b[0].shape
    w, t, g, thr = (np.array(a.ravel()) for a in b)
    gi = np.empty(w.size, np.int64)
    flags = np.empty((4, w.size), np.bool_)
    floats = np.empty((8, w.size))
    _mechanical_many(w, t, g, thr, bool(grid_duplicates), kernel_tables(hev), hev.engine.kernel_tables(), gi,
                     flags, floats)  # fmt: skip
    out: dict[str, Any] = {"gi": gi.reshape(shape), "thr": thr.reshape(shape)}
    out.update({k: flags[j].reshape(shape) for j, k in enumerate(MECH_FLAGS)})
    out.update({k: floats[j].reshape(shape) for j, k in enumerate(MECH_FLOATS)})
    return out


LOSS_TERMS: tuple[str, ...] = ("fuel", "engine_loss", "gearbox_loss", "motor_loss", "coupling_loss",
                                "friction_brakes", "final_drive_loss", "aux", "wheel")  # fmt: skip
"""Energy-audit terms of :func:`loss_powers` / :func:`losses_point`, in order."""


@njit(cache=True, inline="always")
def losses_point(wheel_speed_radps, gi, on, w_fd, w_e, t_e, t_e_fd, t_fd, fuel, w_em, t_em, p_el, d):
    """Power [W] of every audit term at one point (scalar kernel of :func:`loss_powers`, in the
    order of :data:`LOSS_TERMS`), from :func:`mechanical_point`'s operating point, the
    machine torque [N·m] and electrical power [W] of the bus balance and ``d``
    (:class:`ParallelTables`).

    The engine and the machine deliver at the final-drive input: P3 adds the machine after
    the gearbox, P2 before it (the gearbox carries engine + machine); the friction brakes
    take, at the final-drive input, whatever braking torque they leave.
    """
    t_em_shaft = gear_output_torque(t_em, d.coupling_ratio, d.coupling_efficiency)
    if d.p2:
        t_in = t_e + t_em_shaft
        t_delivered = gear_output_torque(t_in, d.gear_ratio[gi], d.gear_efficiency[gi])
        w_shaft, t_gearbox_out = w_e, t_delivered  # the coupling delivers on the gearbox input
    else:
        t_in = t_e
        t_delivered = t_e_fd + t_em_shaft
        w_shaft, t_gearbox_out = w_fd, t_e_fd
    fric = min(t_fd - t_delivered, 0.0)
    t_fd_total = t_delivered + fric
    p_wheel = (
        gear_output_torque(t_fd_total, d.final_drive_ratio, d.final_drive_efficiency) * wheel_speed_radps
    )
    p_fuel = fuel * d.lhv_jpkg
    p_eng = t_e * (w_e if on else 0.0)
    p_motor = t_em * w_em
    return (p_fuel, p_fuel - p_eng, t_in * w_e - t_gearbox_out * w_fd, p_el - p_motor,
            p_motor - t_em_shaft * w_shaft, -fric * w_fd, t_fd_total * w_fd - p_wheel, d.aux_power_w,
            p_wheel)  # fmt: skip


@njit(cache=True, **NO_REFCOUNT)
def _losses_many(w_wheel, gi, on, w_fd, w_e, t_e, t_e_fd, t_fd, fuel, w_em, t_em, p_el, d, out):
    """:func:`losses_point` over flat arrays; fills ``out`` (9, n)."""
    for i in range(w_wheel.shape[0]):
        r = losses_point(w_wheel[i], gi[i], on[i], w_fd[i], w_e[i], t_e[i], t_e_fd[i], t_fd[i],
                         fuel[i], w_em[i], t_em[i], p_el[i], d)  # fmt: skip
        for j in range(len(r)):
            out[j, i] = r[j]


def _losses(hev: ParallelHEV, mech: dict[str, Any], flow: Any, wheel_speed_radps: Any) -> dict[str, Any]:
    """:func:`losses_point` broadcast over a :func:`mechanical` result and its bus balance."""
    names = ("gi", "on", "w_fd", "w_e", "t_e", "t_e_fd", "t_fd", "fuel", "w_em")
    args = [np.asarray(wheel_speed_radps, np.float64), *(mech[n] for n in names), flow.torque_nm,
            flow.power_elec_w]  # fmt: skip
    return broadcast_loop(_losses_many, LOSS_TERMS, args, kernel_tables(hev))


DETAILS: tuple[str, ...] = ("gear", "engine_on", "engine_speed_radps", "engine_torque_nm", "engine_throttle",
                            "engine_power_w", "fuel_rate_gps", "motor_speed_radps", "motor_torque_nm",
                            "motor_power_elec_w", "battery_current_a", "battery_power_w",
                            "friction_brake_power_w")  # fmt: skip
"""Operating-point channels of :func:`electrical` (``details``) / :func:`details_point`, in order."""


@njit(cache=True, inline="always")
def details_point(gi, on, w_e, t_e, throttle, fuel, w_em, t_em, p_el, current_a, p_bat, brakes_w, p2, out):
    """Fill ``out`` with the :data:`DETAILS` of one point (scalar kernel): the gear shown
    (0 when neither the engine nor, for P2, the machine drives through the gearbox), engine
    on, speed [rad/s], torque [N·m], throttle [-], power [W], fuel rate [g/s], machine speed
    [rad/s], torque [N·m], electrical power [W], battery current [A] and power [W], friction
    brake power [W]."""
    w_on = w_e if on else 0.0
    out[0] = gi + 1.0 if (on or p2) else 0.0
    out[1] = 1.0 if on else 0.0
    out[2] = w_on
    out[3] = t_e
    out[4] = throttle if on else 0.0
    out[5] = t_e * w_on
    out[6] = fuel * 1e3
    out[7], out[8], out[9], out[10], out[11], out[12] = w_em, t_em, p_el, current_a, p_bat, brakes_w


@njit(cache=True, **NO_REFCOUNT)
def _details_many(gi, on, w_e, t_e, thr, fuel, w_em, t_em, p_el, current_a, p_bat, brakes_w, p2, out):
    """:func:`details_point` over flat arrays; fills ``out`` (13, n)."""
    for i in range(gi.shape[0]):
        details_point(gi[i], on[i], w_e[i], t_e[i], thr[i], fuel[i], w_em[i], t_em[i], p_el[i], current_a[i],
                      p_bat[i], brakes_w[i], p2, out[:, i])  # fmt: skip


def electrical(
    hev: ParallelHEV,
    mech: dict[str, Any],
    soc: Any,
    dt_s: Any,
    regen_ok: Any,
    battery_state: Any = None,
    *,
    detail: bool = False,
) -> Any:
    """The SOC-dependent half of the power flow: machine, battery, SOC change and fuel.

    ``mech`` from :func:`mechanical`; ``soc`` [-], step ``dt_s`` [s] and ``regen_ok``
    (regeneration allowed: the car moves) broadcast against it; ``battery_state`` a
    :class:`~hevsim.optimal._hev_common.BatteryState` at ``soc`` when already known. The
    machine and the battery meet in the shared bus balance
    (:func:`~hevsim.optimal._hev_common.electric_flow`); the friction brakes take, at the
    final-drive input, whatever braking torque the engine path and the machine leave.

    Returns a :class:`~hevsim.optimal._hev_common.Stage` (SOC change, fuel mass [kg] over the
    step, infeasibility, limit flags) whose ``details`` (with ``detail``) hold the operating
    points; the bus balance is attached as ``stage.flow`` for :func:`loss_powers`.
    """
    from hevsim.components.flow import Stage, electric_flow

    m = mech
    flow = electric_flow(hev.motor, hev.battery, m["t_em_req"], m["w_em"], hev.aux_power_w, soc, dt_s,
                         regen_ok, battery_state)  # fmt: skip
    flags = {"engine_speed": m["engine_speed"], "motor_speed": m["motor_speed"], **flow.flags}
    st = Stage(d_soc=flow.d_soc, cost_kg=m["fuel"] * dt_s, infeasible=flow.infeasible | m["bad"], flags=flags)
    st.flow = flow
    if detail:
        brakes = _losses(hev, m, flow, 0.0)["friction_brakes"]
        args = [m["gi"], m["on"], *(m[n] for n in ("w_e", "t_e", "thr", "fuel", "w_em")), flow.torque_nm,
                flow.power_elec_w, flow.current_a, flow.battery_power_w, brakes]  # fmt: skip
        st.details = broadcast_loop(_details_many, DETAILS, args, hev.machine_position == "p2")
    return st


def power_flow(
    hev: ParallelHEV,
    wheel_speed_radps: Any,
    wheel_torque_nm: Any,
    gear: Any,
    throttle: Any,
    soc: Any,
    dt_s: Any,
    regen_ok: Any,
    battery_state: Any = None,
    *,
    detail: bool = False,
) -> Any:
    """(wheel demand, control, state) -> operating points, fuel, battery power, SOC change:
    :func:`electrical` of :func:`mechanical` (see both), broadcast over every argument."""
    mech = mechanical(hev, wheel_speed_radps, wheel_torque_nm, gear, throttle)
    st = electrical(hev, mech, soc, dt_s, regen_ok, battery_state, detail=detail)
    st.mech = mech
    return st


def loss_powers(hev: ParallelHEV, stage: Any, wheel_speed_radps: Any, wheel_torque_nm: Any) -> dict[str, Any]:
    """Power [W] of every energy-audit term of a :func:`power_flow` result (> 0 dissipated).

    ``stage`` from :func:`power_flow`. ``fuel`` (fuel x LHV, a source), ``engine_loss``
    (fuel power - shaft power), ``gearbox_loss``,
    ``motor_loss`` (electrical - mechanical), ``coupling_loss``, ``final_drive_loss``,
    ``friction_brakes`` (at the final-drive input) and ``wheel`` (the power delivered to the
    wheels, = road load x speed); the battery terms come from its current (see the forward
    simulator). Every term is a product of the flow's own torques and speeds, so the balance
    ``fuel + battery terminal = losses + wheel`` closes to round-off.
    """
    return _losses(hev, stage.mech, stage.flow, wheel_speed_radps)


def candidate_controls(hev: ParallelHEV, throttle_points: int) -> tuple[np.ndarray, np.ndarray]:
    """The admissible control grid of one step, flat: P3: engine off once (gear 1, throttle
    0) and every gear with ``throttle_points - 1`` throttles in (0, 1]; P2: every gear with
    ``throttle_points`` throttles in [0, 1] (the machine drives through the gearbox, so EV
    mode has a gear too). Returns (gear, throttle)."""
    n = int(throttle_points)
    G = len(hev.gears)
    if hev.machine_position == "p2":
        thr = np.linspace(0.0, 1.0, n)
        return np.repeat(np.arange(1, G + 1, dtype=np.float64), n), np.tile(thr, G)
    thr = np.linspace(0.0, 1.0, n)[1:]
    gears = np.repeat(np.arange(1, G + 1, dtype=np.float64), thr.size)
    return np.concatenate([[1.0], gears]), np.concatenate([[0.0], np.tile(thr, G)])


MODES: tuple[str, ...] = ("standstill", "ev", "engine", "assist", "charging", "regen")
"""Power modes: standstill; EV (engine off, machine drives); engine only (machine idle);
engine with machine assist; engine charging the battery; braking with regeneration."""


def power_mode(details: dict[str, float], wheel_force_n: float, v_mid_mps: float) -> int:
    """Index in :data:`MODES` of one step's operating point (``details`` of :func:`electrical`)."""
    return int(
        power_mode_point(details["engine_on"], details["motor_power_elec_w"], wheel_force_n, v_mid_mps)
    )


@njit(cache=True)
def power_mode_point(engine_on, motor_power_elec_w, wheel_force_n, v_mid_mps):
    """Index in :data:`MODES` (scalar kernel) from engine on (> 0), the machine's electrical
    power [W], the wheel force [N] and the mid-step speed [m/s]."""
    on = engine_on > 0.0
    p_m = motor_power_elec_w
    if v_mid_mps <= 0.0:
        return 0
    if wheel_force_n < 0.0 or (not on and p_m < 0.0):
        return 5
    if not on:
        return 1
    if p_m > POWER_EPS_W:
        return 3
    if p_m < -POWER_EPS_W:
        return 4
    return 2


POWER_EPS_W = 1e-9
"""Machine electrical power [W] below which the machine counts as idle (power modes)."""


CAPABILITY_THROTTLE_POINTS = 11
"""Throttles per gear (0..1) of the performance envelope's candidates [-] (full throttle
is on the grid: the envelope needs only the extremes)."""


def capability_controls(hev: ParallelHEV) -> tuple[np.ndarray, ...]:
    """Candidate controls that span the powertrain's capability (performance tests)."""
    return candidate_controls(hev, CAPABILITY_THROTTLE_POINTS)

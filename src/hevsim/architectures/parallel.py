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
from typing import Any

import numpy as np

from hevsim.architectures._common import GearboxModel, battery_details, chassis, fixed_gear, machine_details
from hevsim.components.battery import BatteryPack
from hevsim.components.body import VehicleBody
from hevsim.components.driveline import Gear, Tire
from hevsim.components.electric_machine import ElectricMachine
from hevsim.components.engine import Engine
from hevsim.config import ParallelHEVConfig, config_from_dict, load_vehicle_config
from hevsim.errors import ConfigError
from hevsim.fuels import with_config_fuel
from hevsim.sim.model import build_battery, build_engine, build_machine

__all__ = ["ARCHITECTURE", "ParallelHEV", "ParallelHEVConfig", "build_parallel_hev", "load_parallel_config",
           "parallel_from_dict"]  # fmt: skip

ARCHITECTURE = "parallel"
"""Value of ``[powertrain] architecture`` of a parallel-HEV configuration file."""


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
    )


# ------------------------------------------------------------------------------------------
# The power flow (one copy: DP grid, ECMS candidates, forward step, energy audit)
# ------------------------------------------------------------------------------------------
CONTROLS: tuple[str, ...] = ("gear", "throttle")
"""Control inputs of the parallel HEV: gear (1..G; ignored with the engine off) and engine
throttle [-] (0 = engine off, clutch open)."""
CONTROL_UNITS: tuple[str, ...] = ("-", "-")


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
    input) must give the rest: ``t_em_req``. ``grid_duplicates`` marks every gear but the
    first with the engine off (duplicates on a DP grid) as infeasible.

    Returns a dict of arrays: gi (gear index 0..G-1), thr, on, engine_speed (fired but
    outside the running window), bad, w_fd, w_e, t_e, t_e_fd, t_fd, fuel [kg/s], w_em,
    t_em_req.
    """
    eng = hev.engine
    gi = np.rint(np.asarray(gear, dtype=np.float64)).astype(np.int64) - 1
    w_fd = np.asarray(wheel_speed_radps, dtype=np.float64) * hev.final_drive.ratio
    t_fd = np.asarray(hev.final_drive.input_torque(np.asarray(wheel_torque_nm, np.float64)), dtype=np.float64)
    w_fd, t_fd, gi, thr = (
        np.array(a) for a in np.broadcast_arrays(w_fd, t_fd, gi, np.asarray(throttle, dtype=np.float64))
    )
    p2 = hev.machine_position == "p2"
    w_e = w_fd * hev.gear_ratios[gi]
    fired = thr > 0.0
    can_run = (w_e >= eng.stall_speed_radps) & (w_e <= eng.redline_radps)
    on = fired & can_run
    t_e = np.zeros(gi.shape)
    fuel = np.zeros(gi.shape)
    t_e_fd = np.zeros(gi.shape)
    t_in_req = np.zeros(gi.shape)  # P2: gearbox input torque the wheels need
    if on.any():
        t_e[on] = eng.torque(thr[on], w_e[on])
        fuel[on] = eng.fuel_rate(t_e[on], w_e[on])
    for g, gearbox in enumerate(hev.gears):
        sel = gi == g
        if p2 and sel.any():
            t_in_req[sel] = gearbox.input_torque(t_fd[sel])
        sel = sel & on
        if not p2 and sel.any():
            t_e_fd[sel] = gearbox.output_torque(t_e[sel])
    bad = (fired & ~can_run) | ~np.isfinite(fuel)
    if grid_duplicates and not p2:  # P3: with the engine off the gear does not matter
        bad = bad | (~fired & (gi > 0))
    if p2:  # machine on the gearbox input, after the clutch: it turns with the gearbox input
        w_em = w_e * hev.motor_coupling.ratio
        t_em_req = hev.motor_coupling.input_torque(t_in_req - t_e)
    else:
        w_em = w_fd * hev.motor_coupling.ratio
        t_em_req = hev.motor_coupling.input_torque(t_fd - t_e_fd)
    return {
        "gi": gi, "thr": thr, "on": on, "engine_speed": fired & ~can_run, "bad": bad,
        "w_fd": w_fd, "w_e": w_e, "t_e": t_e, "t_e_fd": t_e_fd, "t_fd": t_fd, "fuel": fuel,
        "w_em": w_em, "t_em_req": np.asarray(t_em_req, dtype=np.float64),
    }  # fmt: skip


def delivered_fd_torque(hev: ParallelHEV, mech: dict[str, Any], t_em: Any) -> tuple[Any, Any]:
    """(torque the engine and machine deliver at the final-drive input [N·m], gearbox
    input torque [N·m]) for machine torque ``t_em``: P3 adds the machine after the gearbox,
    P2 before it (the gearbox carries engine + machine)."""
    t_em_shaft = np.asarray(hev.motor_coupling.output_torque(t_em), dtype=np.float64)
    if hev.machine_position != "p2":
        return mech["t_e_fd"] + t_em_shaft, mech["t_e"]
    t_in = np.broadcast_to(
        mech["t_e"] + t_em_shaft, np.broadcast_shapes(np.shape(t_em_shaft), mech["gi"].shape)
    )
    gi = np.broadcast_to(mech["gi"], t_in.shape)
    out = np.zeros(t_in.shape)
    for g, gearbox in enumerate(hev.gears):
        sel = gi == g
        if sel.any():
            out[sel] = gearbox.output_torque(t_in[sel])
    return out, t_in


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
    from hevsim.optimal._hev_common import Stage, electric_flow

    m = mech
    flow = electric_flow(hev.motor, hev.battery, m["t_em_req"], m["w_em"], 0.0, soc, dt_s, regen_ok,
                         battery_state)  # fmt: skip
    flags = {"engine_speed": m["engine_speed"], **flow.flags}
    st = Stage(d_soc=flow.d_soc, cost_kg=m["fuel"] * dt_s, infeasible=flow.infeasible | m["bad"], flags=flags)
    st.flow = flow
    if detail:
        on, w_e, t_e = m["on"], m["w_e"], m["t_e"]
        fric = np.minimum(m["t_fd"] - delivered_fd_torque(hev, m, flow.torque_nm)[0], 0.0)
        shape = np.shape(flow.torque_nm)
        gear_on = on | (hev.machine_position == "p2")  # P2: the machine drives through the gearbox
        st.details = {
            "gear": np.where(gear_on, m["gi"] + 1, 0).astype(np.float64),
            "engine_on": on.astype(np.float64),
            "engine_speed_radps": np.where(on, w_e, 0.0),
            "engine_torque_nm": t_e,
            "engine_throttle": np.where(on, m["thr"], 0.0),
            "engine_power_w": t_e * np.where(on, w_e, 0.0),
            "fuel_rate_gps": m["fuel"] * 1e3,
            **machine_details(flow, m["w_em"], shape),
            **battery_details(flow),
            "friction_brake_power_w": -fric * m["w_fd"],
        }
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
    flow, mech = stage.flow, stage.mech
    w_fd = mech["w_fd"]
    on = mech["on"]
    lhv = hev.engine.fuel_lhv_jpkg
    p_eng = mech["t_e"] * np.where(on, mech["w_e"], 0.0)
    t_em = flow.torque_nm
    t_em_shaft = np.asarray(hev.motor_coupling.output_torque(t_em))
    t_delivered, t_in = delivered_fd_torque(hev, mech, t_em)
    fric = np.minimum(mech["t_fd"] - t_delivered, 0.0)
    t_fd_total = t_delivered + fric
    p_wheel = np.asarray(hev.final_drive.output_torque(t_fd_total)) * np.asarray(wheel_speed_radps)
    w_shaft = mech["w_e"] if hev.machine_position == "p2" else w_fd  # where the coupling delivers
    p_gearbox_in = t_in * mech["w_e"]
    p_gearbox_out = (t_delivered if hev.machine_position == "p2" else mech["t_e_fd"]) * w_fd
    return {
        "fuel": mech["fuel"] * lhv,
        "engine_loss": mech["fuel"] * lhv - p_eng,
        "gearbox_loss": p_gearbox_in - p_gearbox_out,
        "motor_loss": flow.power_elec_w - t_em * mech["w_em"],
        "coupling_loss": t_em * mech["w_em"] - t_em_shaft * w_shaft,
        "friction_brakes": -fric * w_fd,
        "final_drive_loss": t_fd_total * w_fd - p_wheel,
        "wheel": p_wheel,
    }


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
    on = details["engine_on"] > 0.0
    p_m = details["motor_power_elec_w"]
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

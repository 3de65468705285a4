"""Vehicle configuration: one set of section types for every architecture, validated on load.

A vehicle file (TOML) names its topology in ``[powertrain] architecture = "series" |
"parallel" | "conventional" | "bev" | "power_split"`` and describes its components in shared
sections: ``[body]``, ``[tire]``, ``[final_drive]``, ``[gearbox]``, ``[planetary]``,
``[engine]``, ``[motor]`` / ``[generator]``, ``[battery]``, ``[simulation]``,
``[controller]``, ... Each section is ONE frozen dataclass
below, used by every architecture, with one set of defaults. Every numeric field carries its
validated range and unit next to it (``field(metadata={"bounds": ..., "unit": ...})``, made
by :func:`param`); every float must be finite unless the field says ``allow_inf`` (only the
battery current limits, where ``inf`` means "no limit").

Every key is checked: an unknown key, a wrong type, a value out of range or not one of the
choices raises :class:`~hevsim.errors.ConfigError` naming the file, the key, the value and
what was expected. A file must hold every component section its architecture needs (the
message lists the missing ones) unless it asks for defaults with ``preset = "defaults"``, or
starts from a shipped tutorial vehicle with ``preset = "tutorial_level_N"`` (N = 1..8, the
levels of :mod:`hevsim.refinement`; the file's keys override the preset's).

Units are in the key names; the few non-SI keys (``*_rpm``, ``*_per_mph``, ``*_c``) are
converted when the model is built (SI, kelvin inside). Component data (``data = "..."``) names
a shipped folder under ``hevsim/data/components`` or a path relative to the configuration file.

Architectures are looked up by name in :data:`ARCHITECTURES` (config class, builder,
required sections); :func:`register_architecture` adds one.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, TypeVar

from hevsim import schema
from hevsim.errors import ConfigError
from hevsim.fuels import FuelSection

INF = math.inf
T = TypeVar("T")


def param(default: Any, lo: float, hi: float, unit: str, *, allow_inf: bool = False) -> Any:
    """A numeric field with its inclusive range [lo, hi] and unit (``"-"``: dimensionless)."""
    return field(default=default, metadata={"bounds": (lo, hi), "unit": unit, "allow_inf": allow_inf})


def choice(default: str, *options: str) -> Any:
    """A string field that must be one of ``options``."""
    return field(default=default, metadata={"choices": options})


# ------------------------------------------------------------------------------------------
# Sections (one class per concept, shared by every architecture)
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PowertrainSection:
    """Topology: the name of a registered architecture (see :data:`ARCHITECTURES`)."""

    architecture: str = "series"


@dataclass(frozen=True)
class SimulationSection:
    """Run settings: default cycle, fixed time step [s], initial SOC [-]."""

    cycle: str = "udds"
    dt_s: float = param(0.5, 1e-3, 10.0, "s")
    soc_initial: float = param(0.7, 0.0, 1.0, "-")


@dataclass(frozen=True)
class BodySection:
    """Vehicle body (thesis Table 2.2; defaults are the Simscape Vehicle Body block's).

    The road load is given in one of two forms, never both: the physical form (``mass_kg``,
    ``drag_coefficient``, ``frontal_area_m2``, ``rolling_resistance`` and the optional
    speed-proportional ``rolling_resistance_speed_s_per_m``), or the coast-down form as the
    EPA states it: target coefficients ``road_load_a_n`` [N], ``road_load_b_n_per_m_s``
    [N/(m/s)], ``road_load_c_n_per_m2_s2`` [N/(m/s)^2] (F = A + B v + C v^2 on level road in
    still air) and the equivalent test weight as a mass, ``test_mass_kg`` [kg] (0, the default:
    the physical form). :meth:`hevsim.components.body.VehicleBody.from_section` turns the
    coast-down form into the body's coefficients.
    """

    mass_kg: float = param(1200.0, 1.0, 1e6, "kg")
    drag_coefficient: float = param(0.4, 0.0, 10.0, "-")
    frontal_area_m2: float = param(3.0, 0.0, 100.0, "m^2")
    rolling_resistance: float = param(0.0, 0.0, 1.0, "-")
    rolling_resistance_speed_s_per_m: float = param(0.0, -0.1, 0.1, "s/m")
    road_load_a_n: float = param(0.0, 0.0, 1e5, "N")
    road_load_b_n_per_m_s: float = param(0.0, -1e4, 1e4, "N/(m/s)")
    road_load_c_n_per_m2_s2: float = param(0.0, 0.0, 1e3, "N/(m/s)^2")
    test_mass_kg: float = param(0.0, 0.0, 1e6, "kg")
    mass_factor: float = param(1.0, 1.0, 10.0, "-")
    air_density_kgpm3: float = param(1.18, 0.0, 10.0, "kg/m^3")
    headwind_mps: float = param(0.0, -100.0, 100.0, "m/s")
    cg_height_m: float = param(0.5, 0.0, 10.0, "m")
    front_axle_to_cg_m: float = param(1.4, 0.0, 50.0, "m")
    rear_axle_to_cg_m: float = param(1.6, 0.0, 50.0, "m")
    wheels_per_axle: int = param(2, 1, 20, "-")
    min_turning_radius_m: float = param(5.0, 0.1, 100.0, "m")  # hevsim lap: sharper track corners refused


@dataclass(frozen=True)
class TireSection:
    """Tire rolling radius [m] (no slip) and the adhesion limit of the performance tests.

    ``friction_coefficient`` [-]: peak tire-road friction coefficient; the default 0.9 is the
    upper end of the peak values for dry asphalt and concrete, 0.8-0.9, in Wong, *Theory of
    Ground Vehicles*, 4th ed. (2008), Table 1.3. ``driven_axle``: the axle whose normal load
    (static share plus load transfer, :func:`hevsim.components.body.axle_normal_loads`)
    limits the tractive force, ``"front"``, ``"rear"`` or ``"all"`` (all-wheel drive).
    ``friction_coefficient_x`` / ``_y`` [-]: the semi-axes of the friction ellipse of the lap
    simulation (longitudinal, lateral; :mod:`hevsim.sim.lap`); 0 (the default) takes
    ``friction_coefficient``.
    """

    radius_m: float = param(0.3, 0.01, 5.0, "m")
    friction_coefficient: float = param(0.9, 0.05, 2.0, "-")
    driven_axle: str = choice("front", "front", "rear", "all")
    friction_coefficient_x: float = param(0.0, 0.0, 3.0, "-")  # hevsim lap; 0: friction_coefficient
    friction_coefficient_y: float = param(0.0, 0.0, 3.0, "-")  # hevsim lap; 0: friction_coefficient


@dataclass(frozen=True)
class AeroSection:
    """Aerodynamic downforce of the lap simulation (:mod:`hevsim.sim.lap`); the drag stays in
    ``[body]``. Downforce = 0.5 rho ``downforce_coefficient`` A v^2 [N] on the ``[body]``
    frontal area A and air density rho; ``downforce_coefficient`` [-] is -C_L (> 0 presses the
    car onto the road; the default 0 is a car without downforce), ``front_downforce_fraction``
    [-] the share carried by the front axle (aero balance).
    """

    downforce_coefficient: float = param(0.0, -2.0, 10.0, "-")
    front_downforce_fraction: float = param(0.5, 0.0, 1.0, "-")


@dataclass(frozen=True)
class GearSection:
    """A fixed gear: ratio [-] (input speed / output speed) and efficiency [-].

    Used for ``[final_drive]`` and the parallel HEV's ``[motor_coupling]`` (machine speed /
    final-drive input speed).
    """

    ratio: float = param(2.0, 1e-3, 1e3, "-")
    efficiency: float = param(1.0, 0.01, 1.0, "-")


@dataclass(frozen=True)
class MotorCouplingSection(GearSection):
    """The parallel HEV's machine coupling: ``position`` "p3" (on the final-drive input, after
    the gearbox) or "p2" (on the gearbox input, between the clutch and the gearbox), and the
    fixed gear from the machine: ratio [-] (machine speed / shaft speed) and efficiency [-]."""

    position: str = choice("p3", "p2", "p3")
    ratio: float = param(1.0, 1e-3, 1e3, "-")


@dataclass(frozen=True)
class PlanetarySection:
    """One planetary gear set (power split): sun and ring tooth numbers [-]. The planets have
    ``(ring - sun) / 2`` teeth, so the ring must have more teeth than the sun, by an even
    number."""

    sun_teeth: int = param(30, 1, 10_000, "-")
    ring_teeth: int = param(78, 1, 10_000, "-")


@dataclass(frozen=True)
class GearboxSection:
    """Gearbox ratios [-] (first gear first) and efficiency [-] in the engine path."""

    ratios: tuple[float, ...] = param((3.78, 2.12, 1.36, 1.03, 0.84), 1e-3, 1e3, "-")
    efficiency: float = param(0.97, 0.01, 1.0, "-")


@dataclass(frozen=True)
class BrakesSection:
    """Friction brakes: max deceleration they can give [m/s^2]; regeneration cut-in [m/s];
    brake blending (BEV): the largest share of the braking torque the machine takes [-]."""

    max_decel_mps2: float = param(7.0, 0.0, 100.0, "m/s^2")
    regen_min_speed_mps: float = param(0.0, 0.0, 100.0, "m/s")
    regen_fraction: float = param(1.0, 0.0, 1.0, "-")


@dataclass(frozen=True)
class MachineSection:
    """Electric machine (``[motor]``, ``[generator]``): "ideal" | "constant_efficiency" | "map".

    ``max_torque_nm`` and ``efficiency`` apply to the first two; ``data`` and ``rating`` to
    "map". ``torque_scale`` scales the torque limits of every model.
    """

    model: str = choice("ideal", "ideal", "constant_efficiency", "map")
    max_torque_nm: float = param(200.0, 1e-6, 1e5, "N·m")
    efficiency: float = param(1.0, 0.01, 1.0, "-")
    data: str = "honda_pm49"
    rating: str = choice("cont", "cont", "peak")
    torque_scale: float = param(1.0, 1e-3, 1e3, "-")
    inertia_kgm2: float = param(0.0, 0.0, 100.0, "kg·m^2")


@dataclass(frozen=True)
class EngineSection:
    """Engine: model "constant_torque" (ideal fuel) | "map" (measured maps in ``data``)."""

    model: str = choice("map", "constant_torque", "map")
    max_torque_nm: float = param(200.0, 1e-6, 1e5, "N·m")
    data: str = "vw_1p9_tdi_ci67"
    inertia_kgm2: float = param(0.12, 0.0, 100.0, "kg·m^2")
    stall_speed_rpm: float = param(750.0, 1.0, 1e5, "rpm")
    redline_rpm: float = param(4400.0, 1.0, 1e5, "rpm")
    torque_scale: float = param(1.0, 1e-3, 1e3, "-")


@dataclass(frozen=True)
class AlternatorSection:
    """The conventional vehicle's alternator: it supplies the electrical auxiliary load
    (``[controller] aux_power_w``) from the crankshaft with this efficiency [-] (electrical
    out / mechanical in). The default 0.6 is an assumed mid-range value for a claw-pole
    alternator at part load; set the value of your machine."""

    efficiency: float = param(0.6, 0.01, 1.0, "-")


@dataclass(frozen=True)
class GensetSection:
    """Series genset: kind "none" | "current_source" (ideal constant current) | "engine"."""

    kind: str = choice("engine", "none", "current_source", "engine")
    current_a: float = param(50.0, 0.0, 1e4, "A")


@dataclass(frozen=True)
class BatterySection:
    """Battery: model "ideal" | "rint" | "table" (cell tables in ``data``) | "cell" | "pack".

    ``"cell"`` (every architecture with a traction battery): an ``n_series`` x ``n_parallel``
    pack of the electro-thermal cell model of :mod:`hevsim.battery` (``data`` names a shipped
    cell parameter set or a TOML path), with its RC and thermal dynamics; ``temperature_c`` is
    its initial and heat-port temperature (a run's ambient may replace the port's,
    :mod:`hevsim.sim.cell_vehicle`). The current limits accept ``inf`` (the default): no limit.

    ``"pack"`` (every architecture with a traction battery: series, parallel, power split,
    BEV): the pack file ``pack`` (a pack TOML as
    ``examples/pack.toml``, relative to this file) with every cell, its module thermal model,
    cooling loop and BMS (:mod:`hevsim.sim.pack_vehicle`); the pack file's arrangement, limits
    and temperatures replace this section's, except ``soc_min`` / ``soc_max``.
    """

    model: str = choice("ideal", "ideal", "rint", "table", "cell", "pack")
    pack: str = ""
    # the DC bus window the motor inverter accepts [V] (a "pack" must lie inside it; the
    # defaults accept any pack)
    bus_min_v: float = param(0.0, 0.0, 1e5, "V")
    bus_max_v: float = param(1e5, 1e-3, 1e5, "V")
    ocv_v: float = param(336.0, 1e-3, 1e5, "V")
    resistance_ohm: float = param(0.0, 0.0, 1e3, "ohm")
    capacity_ah: float = param(8.5, 1e-6, 1e6, "A·h")
    data: str = "nimh_spiral_6ah_insight_prius_nimh6"
    n_series: int = param(1, 1, 10_000, "-")
    n_parallel: int = param(1, 1, 10_000, "-")
    r_extra_ohm: float = param(0.0, 0.0, 1e3, "ohm")
    temperature_c: float = param(25.0, -60.0, 150.0, "degC")
    max_discharge_current_a: float = param(INF, 1e-6, INF, "A", allow_inf=True)
    max_charge_current_a: float = param(INF, 1e-6, INF, "A", allow_inf=True)
    soc_min: float = param(0.0, 0.0, 1.0, "-")
    soc_max: float = param(1.0, 0.0, 1.0, "-")


@dataclass(frozen=True)
class DriverSection:
    """Proportional speed controller: request = gain x error (per mph, as in the tutorial)."""

    kind: str = choice("proportional", "proportional")
    gain_per_mph: float = param(0.5, 0.0, 100.0, "1/mph")
    feedforward: float = param(0.0, 0.0, 100.0, "s^2/m")


CONTROLLER_KINDS: tuple[str, ...] = (
    "thermostat", "schedule", "electric_assist", "ecms", "aecms", "shift_schedule", "direct",
    "power_follower", "load_follower",
)  # fmt: skip
"""Every ``[controller] kind``; which ones an architecture admits is in
:data:`ARCHITECTURES` (``controllers``)."""
SERIES_ONLINE_CONTROLLERS: tuple[str, ...] = ("ecms", "aecms")
"""The series HEV's controllers of :mod:`hevsim.control` (run on its quasi-static power flow in
:mod:`hevsim.sim.forward`, not in its compiled kernel)."""


@dataclass(frozen=True)
class ControllerSection:
    """Supervisory controller (:mod:`hevsim.control`), selected by ``kind``.

    Series HEV: ``"thermostat"`` (genset on SOC, engine operating point, speed loop) or
    ``"schedule"`` (a genset schedule CSV ``schedule``: time_s, engine_speed_rpm,
    engine_throttle, e.g. a DP optimum). Parallel HEV: ``"electric_assist"`` (rule-based:
    EV below ``ev_speed_mps`` and ``ev_power_w``, engine load-following in the gear of the
    ``upshift_rpm``/``downshift_rpm`` schedule plus ``charge_power_w`` below ``soc_low`` and
    at least ``engine_min_power_w`` below ``soc_high``, machine assist; the engine fired
    whatever the SOC and demand above ``engine_on_speed_mps``), ``"ecms"`` (equivalence
    factor ``equivalence_factor``, over ``control_points`` throttles per gear) or ``"aecms"``
    (ECMS with the factor corrected by a PI loop on the SOC error from the run's initial SOC
    less the recoverable share ``aecms_kinetic_fraction`` of the kinetic energy, gains
    ``aecms_kp`` [-] and ``aecms_ki`` [1/s]). Conventional: ``"shift_schedule"`` (the gear of
    the ``upshift_rpm`` / ``downshift_rpm`` schedule, kick-down when the engine cannot give the
    torque; the engine idles, or with ``stop_start = "on"`` stops, when there is no traction demand; braking
    with the gearbox input above ``fuel_cut_speed_rpm`` cuts the fuel and lets the engine
    drag). BEV:
    ``"direct"`` (the machine gives what the driver asks, within its and the battery's limits).
    Power split: ``"power_follower"`` (rule-based: EV below ``ev_speed_mps`` and ``ev_power_w``
    with SOC above ``soc_low``, else the engine gives the demand plus the charging power, at
    least ``engine_min_power_w`` while the SOC is below ``soc_high``, at the candidate of least
    fuel per unit of engine work near that power: its optimal operating line), ``"ecms"``,
    ``"aecms"`` (candidates: ``engine_speed_points``
    engine speeds x ``control_points`` throttles, and engine off). Fuel-cell vehicle:
    ``"load_follower"`` (the fuel cell follows the bus load, ``soc_low``..``soc_high``,
    ``charge_power_w``; kept running whatever the SOC and load above ``fuel_cell_on_speed_mps``
    and, once started, until it has run ``fuel_cell_min_on_time_s``), ``"ecms"``, ``"aecms"``
    (candidates: ``control_points`` net powers from 0 = off to the rating, moved into the ramp
    window of each step).
    """

    kind: str = choice("thermostat", *CONTROLLER_KINDS)
    schedule: str = ""
    soc_low: float = param(0.6, 0.0, 1.0, "-")
    soc_high: float = param(0.7, 0.0, 1.0, "-")
    soc_boost: float = param(0.0, 0.0, 1.0, "-")
    engine_speed_rpm: float = param(1800.0, 0.0, 1e5, "rpm")
    start_speed_rpm: float = param(1500.0, 0.0, 1e5, "rpm")
    throttle: float = param(0.5, 0.0, 1.0, "-")
    throttle_boost: float = param(1.0, 0.0, 1.0, "-")
    speed_gain_per_rpm: float = param(0.01, 0.0, 100.0, "1/rpm")
    pure_ice_band_w: float = param(500.0, 0.0, 1e7, "W")
    aux_power_w: float = param(0.0, 0.0, 1e7, "W")
    # parallel HEV (hevsim.control): electric assist, ECMS, adaptive ECMS
    ev_speed_mps: float = param(8.0, 0.0, 100.0, "m/s")
    ev_power_w: float = param(8000.0, 0.0, 1e7, "W")
    charge_power_w: float = param(4000.0, 0.0, 1e7, "W")
    # electric assist: above this vehicle speed the engine is fired whatever the SOC and the demand
    # (braking and coasting included, then at its smallest throttle): FASTSim's `mph_fc_on`;
    # the default (1000 m/s) is above any road speed: never
    engine_on_speed_mps: float = param(1000.0, 0.0, 1000.0, "m/s")
    # power split (power_follower) and electric assist: the engine, once on, gives at least this power
    # while the SOC is below soc_high (the surplus charges the battery): keeps it off the inefficient
    # low-load end of its operating range; 0 = the demand only
    engine_min_power_w: float = param(0.0, 0.0, 1e7, "W")
    # load follower (FCEV): above this vehicle speed the fuel cell runs whatever the SOC and the
    # load (at no net output if need be, drawing its idle hydrogen): FASTSim's `mph_fc_on`; the
    # default (1000 m/s) is above any road speed: never
    fuel_cell_on_speed_mps: float = param(1000.0, 0.0, 1000.0, "m/s")
    # load follower (FCEV): a fuel cell that starts keeps running until it has run this long
    # (FASTSim's `min_fc_time_on` rule: forced on while 0 < time on < this - dt); 0 = no minimum
    fuel_cell_min_on_time_s: float = param(0.0, 0.0, 1e5, "s")
    upshift_rpm: float = param(2000.0, 1.0, 1e5, "rpm")
    downshift_rpm: float = param(1100.0, 1.0, 1e5, "rpm")
    equivalence_factor: float = param(2.5, 0.0, 100.0, "-")
    aecms_kp: float = param(150.0, 0.0, 1e5, "-")
    aecms_ki: float = param(0.2, 0.0, 1e5, "1/s")
    aecms_kinetic_fraction: float = param(0.5, 0.0, 1.0, "-")
    control_points: int = param(101, 2, 100_000, "-")
    # power split: engine speeds on the candidate grid (with control_points throttles each)
    engine_speed_points: int = param(12, 2, 10_000, "-")
    # conventional vehicle: engine off instead of idling when there is no traction demand
    stop_start: str = choice("off", "off", "on")
    # conventional vehicle: deceleration fuel cut above this engine speed [rpm] (clutch closed,
    # the engine drags with its closed-throttle torque). Default: fuel injection resumes below
    # 1,200 rpm in the 2007 Pontiac Vibe (Toyota 1ZZ-FE) service manual, "Fuel System
    # Description - Fuel Cutoff"; a value above the redline turns the fuel cut off.
    fuel_cut_speed_rpm: float = param(1200.0, 0.0, 1e5, "rpm")


@dataclass(frozen=True)
class FuelCellSection:
    """Fuel-cell system of a fuel-cell vehicle (``architecture = "fcev"``,
    :class:`hevsim.components.fuel_cell.FuelCellSystem`): ``data`` names a folder (shipped under
    ``hevsim/data/components/fuel_cells`` or relative to the file) with ``efficiency.csv``, the
    net system efficiency vs net power as a fraction of ``max_power_w`` [W]; ``min_power_w``
    [W]: idle (the system never runs below it); ramp limits ``ramp_up_w_per_s`` and
    ``ramp_down_w_per_s`` [W/s] on its net power; ``initial_power_w`` [W]: its power before the
    first step (clipped to the idle and rated power); ``idle_fuel_power_w`` [W]: the least hydrogen
    power (LHV basis) a running system draws, at low or no net output (FASTSim's ``idle_fc_kw``;
    0: none)."""

    data: str = "fastsim_h2fc"
    max_power_w: float = param(114000.0, 1.0, 1e7, "W")
    min_power_w: float = param(2000.0, 0.0, 1e7, "W")
    ramp_up_w_per_s: float = param(20000.0, 1e-3, 1e9, "W/s")
    ramp_down_w_per_s: float = param(40000.0, 1e-3, 1e9, "W/s")
    initial_power_w: float = param(0.0, 0.0, 1e7, "W")
    idle_fuel_power_w: float = param(0.0, 0.0, 1e7, "W")


PLUGIN_MODES: tuple[str, ...] = ("off", "ev_first", "blended")
"""``[plugin] mode`` values: ``"off"`` (a charge-sustaining hybrid) or a plug-in hybrid's
charge-depleting strategy."""


@dataclass(frozen=True)
class PluginSection:
    """Plug-in hybrid (PHEV): any series, parallel or power-split HEV with ``mode`` other than
    ``"off"`` charges from the grid and runs charge-depleting (CD) while its SOC lies above
    ``cs_soc`` [-], then charge-sustaining (CS) with its own ``[controller]``.

    ``mode = "ev_first"``: in CD the vehicle drives electrically whenever it can (the engine
    only helps where the machine or battery cannot give the demand; ECMS prices battery energy
    at 0). ``mode = "blended"``: in CD the rule-based controllers start the engine only above
    the wheel power ``blended_engine_power_w`` [W] (and add no charging power), ECMS / A-ECMS
    use ``blended_equivalence_factor`` [-]. The usable window is the battery's
    ``soc_min``..``soc_max``: a label's CD test starts full (``soc_max``) and ``cs_soc`` must
    lie strictly inside it. ``charger_efficiency`` [-]: wall (AC) to battery energy, for the
    label's electricity from the wall (default 0.86, FASTSim's ``chg_eff``).
    """

    mode: str = choice("off", *PLUGIN_MODES)
    cs_soc: float = param(0.3, 0.0, 1.0, "-")
    blended_engine_power_w: float = param(20000.0, 0.0, 1e7, "W")
    blended_equivalence_factor: float = param(1.0, 0.0, 100.0, "-")
    charger_efficiency: float = param(0.86, 0.01, 1.0, "-")


def is_plugin(cfg: Any) -> bool:
    """Whether a configuration is a plug-in hybrid (``[plugin] mode`` other than ``"off"``)."""
    plugin = getattr(cfg, "plugin", None)
    return plugin is not None and plugin.mode != "off"


@dataclass(frozen=True)
class OptimizationSection:
    """Dynamic-programming settings (``hevsim optimize``), one section for every architecture
    with a DP formulation; these defaults are the parallel HEV's (the appendix's problem), the
    series and power split take :class:`SustainingOptimizationSection`'s.

    ``cycle`` (empty: the ``[simulation]`` cycle); ``soc_initial`` [-]; ``final_soc``
    ``"window"`` (``final_soc_min``..``final_soc_max`` [-]), ``"sustain"`` (within
    ``soc_tolerance`` [-] of the initial SOC) or, for a plug-in hybrid, ``"deplete"`` (within
    ``soc_tolerance`` of ``plugin.cs_soc``: the depletion target); ``soc_grid_points`` over the battery's SOC
    window; ``input_grid_points``: the control grid (parallel: throttles, series: genset
    electrical powers, power split: throttles per engine speed, fuel-cell vehicle: fuel-cell
    net powers), 0 = the architecture's default (parallel: ``throttle_grid_points``, series: 101,
    power split and fuel-cell vehicle: ``controller.control_points``); ``final_constraint``: the
    solver's final-state method.
    """

    cycle: str = "udds"
    soc_initial: float = param(0.8, 0.0, 1.0, "-")
    final_soc: str = choice("window", "window", "sustain", "deplete")
    final_soc_min: float = param(0.7, 0.0, 1.0, "-")
    final_soc_max: float = param(0.8, 0.0, 1.0, "-")
    soc_tolerance: float = param(0.005, 0.0, 1.0, "-")
    soc_grid_points: int = param(400, 2, 100_000, "-")
    input_grid_points: int = param(0, 0, 100_000, "-")
    throttle_grid_points: int = param(400, 2, 100_000, "-")
    final_constraint: str = choice("auto", "auto", "boundary_line", "levelset", "wall", "penalty")


SOC_INITIAL_FROM_SIMULATION = -1.0
"""``optimization.soc_initial`` default of :class:`SustainingOptimizationSection`: the
``[simulation]`` initial SOC (any other value must lie in the battery's SOC window)."""


@dataclass(frozen=True)
class SustainingOptimizationSection(OptimizationSection):
    """The ``[optimization]`` defaults of the series and power-split HEV and the fuel-cell
    vehicle: charge sustaining on the ``[simulation]`` cycle from its initial SOC (``soc_initial`` default
    :data:`SOC_INITIAL_FROM_SIMULATION`), 201 SOC points; a ``"window"`` final SOC defaults
    to the battery's SOC window (``final_soc_min``/``max`` clipped to it)."""

    cycle: str = ""
    soc_initial: float = param(SOC_INITIAL_FROM_SIMULATION, SOC_INITIAL_FROM_SIMULATION, 1.0, "-")
    final_soc: str = choice("sustain", "window", "sustain", "deplete")
    final_soc_min: float = param(0.0, 0.0, 1.0, "-")
    final_soc_max: float = param(1.0, 0.0, 1.0, "-")
    soc_grid_points: int = param(201, 2, 100_000, "-")


@dataclass(frozen=True)
class MetricsSection:
    """Fuel-economy settings: fuel-to-battery conversion efficiency of eq (16) [-]; the open-circuit
    voltage of eq (15) [V] (0: the battery's OCV at the mean of initial and final SOC; a value
    > 0 replaces it, as the tutorial's post file used 366 V while its ideal battery held 336 V;
    forward simulations only, dynamic programming always uses the battery's OCV)."""

    conversion_efficiency: float = param(0.25, 0.01, 1.0, "-")
    soc_correction_ocv_v: float = param(0.0, 0.0, 1e5, "V")


# ------------------------------------------------------------------------------------------
# Vehicle configurations (one per architecture, built from the sections above)
# ------------------------------------------------------------------------------------------
class _VehicleConfig:
    """Behaviour shared by the vehicle configurations (``name``, ``powertrain``, ``base_dir``)."""

    name: str
    base_dir: str
    powertrain: PowertrainSection

    @property
    def architecture(self) -> str:
        """The architecture name (``powertrain.architecture``)."""
        return self.powertrain.architecture

    def to_dict(self) -> dict[str, Any]:
        """Plain dict of every value (the resolved configuration, for results)."""
        return schema.to_dict(self)

    def replace(self: T, **changes: Any) -> T:
        """Copy with dotted-key overrides, e.g. ``replace(**{"body.mass_kg": 1500.0})``.

        The copy is validated like a file: an override out of range raises ConfigError (a key
        that does nothing for this vehicle is not refused here, only in files).
        """
        me: Any = self
        data = schema.with_changes(me.to_dict(), changes)
        out: T = config_from_dict(
            data, source=f"{me.name} (modified)", base_dir=Path(me.base_dir), inert=False
        )
        return out


@dataclass(frozen=True)
class SeriesHEVConfig(_VehicleConfig):
    """A series-HEV configuration (thesis Fig. 2.3)."""

    name: str = "vehicle"
    description: str = ""
    preset: str = ""
    powertrain: PowertrainSection = field(default_factory=lambda: PowertrainSection("series"))
    simulation: SimulationSection = field(default_factory=SimulationSection)
    body: BodySection = field(default_factory=BodySection)
    tire: TireSection = field(default_factory=TireSection)
    aero: AeroSection = field(default_factory=AeroSection)
    final_drive: GearSection = field(default_factory=GearSection)
    brakes: BrakesSection = field(default_factory=BrakesSection)
    motor: MachineSection = field(default_factory=MachineSection)
    generator: MachineSection = field(default_factory=MachineSection)
    engine: EngineSection = field(default_factory=EngineSection)
    genset: GensetSection = field(default_factory=GensetSection)
    battery: BatterySection = field(default_factory=BatterySection)
    driver: DriverSection = field(default_factory=DriverSection)
    controller: ControllerSection = field(default_factory=ControllerSection)
    optimization: SustainingOptimizationSection = field(default_factory=SustainingOptimizationSection)
    metrics: MetricsSection = field(default_factory=MetricsSection)
    fuel: FuelSection = field(default_factory=FuelSection)  # hevsim.fuels: choose/override the fuel
    plugin: PluginSection = field(default_factory=PluginSection)  # plug-in hybrid (PHEV)
    base_dir: str = "."


VehicleConfig = SeriesHEVConfig
"""Former name of :class:`SeriesHEVConfig`."""


@dataclass(frozen=True)
class ParallelHEVConfig(_VehicleConfig):
    """A parallel-HEV configuration (the thesis appendix's DP vehicle; see hevsim.parallel)."""

    name: str = "parallel_hev"
    description: str = ""
    preset: str = ""
    powertrain: PowertrainSection = field(default_factory=lambda: PowertrainSection("parallel"))
    body: BodySection = field(default_factory=BodySection)
    tire: TireSection = field(default_factory=TireSection)
    aero: AeroSection = field(default_factory=AeroSection)
    final_drive: GearSection = field(default_factory=GearSection)
    gearbox: GearboxSection = field(default_factory=GearboxSection)
    engine: EngineSection = field(default_factory=EngineSection)
    motor: MachineSection = field(default_factory=MachineSection)
    motor_coupling: MotorCouplingSection = field(default_factory=MotorCouplingSection)
    battery: BatterySection = field(default_factory=BatterySection)
    simulation: SimulationSection = field(default_factory=SimulationSection)
    controller: ControllerSection = field(default_factory=lambda: ControllerSection(kind="electric_assist"))
    optimization: OptimizationSection = field(default_factory=OptimizationSection)
    metrics: MetricsSection = field(default_factory=MetricsSection)
    fuel: FuelSection = field(default_factory=FuelSection)  # hevsim.fuels: choose/override the fuel
    plugin: PluginSection = field(default_factory=PluginSection)  # plug-in hybrid (PHEV)
    base_dir: str = "."


@dataclass(frozen=True)
class ConventionalConfig(_VehicleConfig):
    """A conventional vehicle: engine, launch clutch, automatic gearbox, final drive, brakes."""

    name: str = "conventional"
    description: str = ""
    preset: str = ""
    powertrain: PowertrainSection = field(default_factory=lambda: PowertrainSection("conventional"))
    body: BodySection = field(default_factory=BodySection)
    tire: TireSection = field(default_factory=TireSection)
    aero: AeroSection = field(default_factory=AeroSection)
    final_drive: GearSection = field(default_factory=GearSection)
    gearbox: GearboxSection = field(default_factory=GearboxSection)
    engine: EngineSection = field(default_factory=EngineSection)
    brakes: BrakesSection = field(default_factory=BrakesSection)
    alternator: AlternatorSection = field(default_factory=AlternatorSection)
    simulation: SimulationSection = field(default_factory=SimulationSection)
    controller: ControllerSection = field(default_factory=lambda: ControllerSection(kind="shift_schedule"))
    metrics: MetricsSection = field(default_factory=MetricsSection)
    fuel: FuelSection = field(default_factory=FuelSection)
    base_dir: str = "."


@dataclass(frozen=True)
class BEVConfig(_VehicleConfig):
    """A battery-electric vehicle: machine on a single reduction, battery, blended brakes."""

    name: str = "bev"
    description: str = ""
    preset: str = ""
    powertrain: PowertrainSection = field(default_factory=lambda: PowertrainSection("bev"))
    body: BodySection = field(default_factory=BodySection)
    tire: TireSection = field(default_factory=TireSection)
    aero: AeroSection = field(default_factory=AeroSection)
    final_drive: GearSection = field(default_factory=GearSection)
    motor: MachineSection = field(default_factory=MachineSection)
    battery: BatterySection = field(default_factory=BatterySection)
    brakes: BrakesSection = field(default_factory=BrakesSection)
    simulation: SimulationSection = field(default_factory=SimulationSection)
    controller: ControllerSection = field(default_factory=lambda: ControllerSection(kind="direct"))
    metrics: MetricsSection = field(default_factory=lambda: MetricsSection(conversion_efficiency=1.0))
    fuel: FuelSection = field(default_factory=FuelSection)
    base_dir: str = "."


@dataclass(frozen=True)
class FCEVConfig(_VehicleConfig):
    """A fuel-cell vehicle: the series HEV's electric drive (machine on a single reduction,
    battery on the DC bus, blended brakes) with a fuel-cell system in place of the genset;
    ``[optimization]`` as the series HEV's (charge sustaining, input the fuel cell's net power)."""

    name: str = "fcev"
    description: str = ""
    preset: str = ""
    powertrain: PowertrainSection = field(default_factory=lambda: PowertrainSection("fcev"))
    body: BodySection = field(default_factory=BodySection)
    tire: TireSection = field(default_factory=TireSection)
    aero: AeroSection = field(default_factory=AeroSection)
    final_drive: GearSection = field(default_factory=GearSection)
    motor: MachineSection = field(default_factory=MachineSection)
    fuel_cell: FuelCellSection = field(default_factory=FuelCellSection)
    battery: BatterySection = field(default_factory=BatterySection)
    brakes: BrakesSection = field(default_factory=BrakesSection)
    simulation: SimulationSection = field(default_factory=SimulationSection)
    controller: ControllerSection = field(default_factory=lambda: ControllerSection(kind="load_follower"))
    optimization: SustainingOptimizationSection = field(default_factory=SustainingOptimizationSection)
    metrics: MetricsSection = field(default_factory=MetricsSection)
    fuel: FuelSection = field(default_factory=lambda: FuelSection(name="hydrogen"))
    base_dir: str = "."


@dataclass(frozen=True)
class PowerSplitConfig(_VehicleConfig):
    """A power-split HEV (Toyota THS style): engine on the planet carrier, generator (MG1) on
    the sun, motor (MG2, through ``motor_coupling``) and the final drive on the ring."""

    name: str = "power_split"
    description: str = ""
    preset: str = ""
    powertrain: PowertrainSection = field(default_factory=lambda: PowertrainSection("power_split"))
    body: BodySection = field(default_factory=BodySection)
    tire: TireSection = field(default_factory=TireSection)
    aero: AeroSection = field(default_factory=AeroSection)
    final_drive: GearSection = field(default_factory=GearSection)
    planetary: PlanetarySection = field(default_factory=PlanetarySection)
    engine: EngineSection = field(default_factory=EngineSection)
    generator: MachineSection = field(default_factory=MachineSection)
    motor: MachineSection = field(default_factory=MachineSection)
    motor_coupling: GearSection = field(default_factory=lambda: GearSection(ratio=1.0))
    battery: BatterySection = field(default_factory=BatterySection)
    brakes: BrakesSection = field(default_factory=BrakesSection)
    simulation: SimulationSection = field(default_factory=SimulationSection)
    controller: ControllerSection = field(default_factory=lambda: ControllerSection(kind="power_follower"))
    optimization: SustainingOptimizationSection = field(default_factory=SustainingOptimizationSection)
    metrics: MetricsSection = field(default_factory=MetricsSection)
    fuel: FuelSection = field(default_factory=FuelSection)
    plugin: PluginSection = field(default_factory=PluginSection)  # plug-in hybrid (PHEV)
    base_dir: str = "."


def _pairs_below(cfg: Any, source: str, pairs: tuple[tuple[str, str], ...]) -> None:
    for lo_key, hi_key in pairs:
        lo, hi = _get(cfg, lo_key), _get(cfg, hi_key)
        if lo >= hi:
            raise ConfigError(f"{source}: key '{lo_key}' = {lo} must be below '{hi_key}' = {hi}.")


def _get(cfg: Any, dotted: str) -> Any:
    sec, _, name = dotted.partition(".")
    return getattr(getattr(cfg, sec), name)


def check_controller(cfg: Any, source: str) -> None:
    """ConfigError unless ``cfg.controller.kind`` is admitted by ``cfg``'s architecture."""
    spec = ARCHITECTURES.get(cfg.architecture)
    kind = cfg.controller.kind
    if spec is not None and kind not in spec.controllers:
        raise ConfigError(
            f"{source}: key 'controller.kind' = {kind!r} is not defined for the {spec.name} "
            f"architecture{_energy_split_refusal(cfg, kind)}; expected one of {', '.join(spec.controllers)}."
        )


ENERGY_SPLIT_CONTROLLERS: tuple[str, ...] = ("ecms", "aecms")
"""Controllers that split the demand between fuel and battery energy (need both)."""


def _energy_split_refusal(cfg: Any, kind: str) -> str:
    """Why ``kind`` cannot run on ``cfg`` when it splits fuel and battery energy and ``cfg``
    lacks one of them (", ..." to append to a refusal), else ""."""
    if kind not in ENERGY_SPLIT_CONTROLLERS:
        return ""
    if not hasattr(cfg, "battery"):
        return " (it splits the demand between fuel and battery; the vehicle has no [battery]: one source)"
    if not hasattr(cfg, "engine"):
        return " (it splits the demand between fuel and battery; the vehicle has no [engine]: one source)"
    return ""


_check_controller = check_controller


def _check_optimization(cfg: Any, source: str) -> None:
    """The ``[optimization]`` section against the battery's SOC window (every DP architecture).

    A sustaining section's default window (0..1) is clipped to the battery's window when used
    (``hevsim.optimal.hev``), so only the parallel HEV's explicit window must lie inside it.
    """
    _pairs_below(cfg, source, (("optimization.final_soc_min", "optimization.final_soc_max"),))
    b, o = cfg.battery, cfg.optimization
    inherits = isinstance(o, SustainingOptimizationSection) and o.soc_initial == SOC_INITIAL_FROM_SIMULATION
    if not inherits and not b.soc_min <= o.soc_initial <= b.soc_max:
        raise ConfigError(
            f"{source}: key 'optimization.soc_initial' = {o.soc_initial} lies outside the SOC window "
            f"[battery.soc_min, battery.soc_max] = [{b.soc_min}, {b.soc_max}]."
        )
    window_inside = o.final_soc_min >= b.soc_min and o.final_soc_max <= b.soc_max
    if o.final_soc == "window" and not window_inside and not isinstance(o, SustainingOptimizationSection):
        raise ConfigError(
            f"{source}: keys 'optimization.final_soc_min'/'final_soc_max' = [{o.final_soc_min}, "
            f"{o.final_soc_max}] must lie inside the SOC window [{b.soc_min}, {b.soc_max}]."
        )


RULE_BASED_CONTROLLERS: tuple[str, ...] = ("thermostat", "schedule", "electric_assist", "power_follower")
"""Controller kinds that hold the SOC in a ``soc_low``..``soc_high`` band (charge sustaining)."""


def _check_plugin(cfg: Any, source: str) -> None:
    """The ``[plugin]`` section of a hybrid: ``cs_soc`` strictly inside the usable SOC window,
    the rule-based controller's charge-sustaining band at or below it, a power rule for a
    blended strategy, and the DP's ``"deplete"`` target only for a plug-in hybrid."""
    pl, b = cfg.plugin, cfg.battery
    o = getattr(cfg, "optimization", None)
    if pl.mode == "off":
        if o is not None and o.final_soc == "deplete":
            raise ConfigError(
                f"{source}: key 'optimization.final_soc' = 'deplete' needs a plug-in hybrid; got "
                "'plugin.mode' = 'off' (expected 'ev_first' or 'blended', or final_soc 'sustain'/'window')."
            )
        return
    if not b.soc_min < pl.cs_soc < b.soc_max:
        raise ConfigError(
            f"{source}: key 'plugin.cs_soc' = {pl.cs_soc} lies outside the usable SOC window "
            f"('battery.soc_min', 'battery.soc_max') = ({b.soc_min}, {b.soc_max}); expected a value "
            "strictly inside it (charge depleting runs from soc_max down to cs_soc)."
        )
    kind = cfg.controller.kind
    if kind in RULE_BASED_CONTROLLERS and cfg.controller.soc_high > pl.cs_soc:
        raise ConfigError(
            f"{source}: key 'controller.soc_high' = {cfg.controller.soc_high} lies above 'plugin.cs_soc' = "
            f"{pl.cs_soc}; expected the charge-sustaining band 'controller.soc_low'..'soc_high' at or below "
            "the charge-depleting threshold."
        )
    if pl.mode == "blended" and cfg.architecture == "series" and kind in ("thermostat", "schedule"):
        raise ConfigError(
            f"{source}: key 'plugin.mode' = 'blended' needs a controller with a power rule; the series HEV's "
            f"'controller.kind' = {kind!r} starts its genset on the SOC only; expected 'plugin.mode' = "
            "'ev_first' or 'controller.kind' = 'ecms' / 'aecms'."
        )


def _check_series(cfg: SeriesHEVConfig, source: str) -> None:
    _check_controller(cfg, source)
    _check_plugin(cfg, source)
    if cfg.controller.kind in SERIES_ONLINE_CONTROLLERS:
        check_series_online(cfg, source, cfg.controller.kind)
    _pairs_below(cfg, source, (("controller.soc_low", "controller.soc_high"),
                               ("battery.soc_min", "battery.soc_max"),
                               ("engine.stall_speed_rpm", "engine.redline_rpm")))  # fmt: skip
    _check_optimization(cfg, source)


def check_series_online(cfg: SeriesHEVConfig, source: str, kind: str) -> None:
    """ConfigError unless the series HEV ``cfg`` can run the online controller ``kind``
    (:data:`SERIES_ONLINE_CONTROLLERS`) on its quasi-static power flow."""
    why = _series_online_refusal(cfg)
    if why:
        raise ConfigError(
            f"{source}: key 'controller.kind' = {kind!r} runs the series HEV on its quasi-static power flow "
            f"(the DP's stage model), which needs {why}."
        )


def _series_online_refusal(cfg: SeriesHEVConfig) -> str:
    """Why a series HEV cannot run its online controllers (:data:`SERIES_ONLINE_CONTROLLERS`:
    the quasi-static power flow has an engine genset and a table battery, or a cell or pack
    battery stepped in the loop), "" when it can."""
    needs = (("genset.kind", cfg.genset.kind, ("engine",)),
             ("battery.model", cfg.battery.model, ("ideal", "rint", "table", "cell", "pack")))  # fmt: skip
    for key, value, expected in needs:
        if value not in expected:
            return f"'{key}' = {' or '.join(expected)}; got '{key}' = {value!r}"
    return ""


def _check_parallel(cfg: ParallelHEVConfig, source: str) -> None:
    _check_controller(cfg, source)
    _check_plugin(cfg, source)
    _pairs_below(cfg, source, (("battery.soc_min", "battery.soc_max"),
                               ("controller.soc_low", "controller.soc_high"),
                               ("controller.downshift_rpm", "controller.upshift_rpm"),
                               ("engine.stall_speed_rpm", "engine.redline_rpm")))  # fmt: skip
    _check_shift_schedule(cfg, source)
    _check_optimization(cfg, source)
    if cfg.engine.model != "map":
        raise ConfigError(
            f"{source}: key 'engine.model' = {cfg.engine.model!r} is not supported by the parallel "
            "HEV; expected 'map' (its DP needs a fuel map)."
        )


def _check_shift_schedule(cfg: Any, source: str) -> None:
    ratios = cfg.gearbox.ratios  # never empty: the schema asks for a non-empty list
    c = cfg.controller
    for g in range(len(ratios) - 1):  # after an upshift the engine must stay above the downshift speed
        after = c.upshift_rpm * ratios[g + 1] / ratios[g]
        if after <= c.downshift_rpm:
            raise ConfigError(
                f"{source}: shift schedule 'controller.upshift_rpm' = {c.upshift_rpm:g} / "
                f"'controller.downshift_rpm' = {c.downshift_rpm:g} is infeasible: an upshift from "
                f"gear {g + 1} to {g + 2} (ratios {ratios[g]:g} -> {ratios[g + 1]:g}) lands at "
                f"{after:.0f} rpm, at or below the downshift speed (the gears would hunt); expected "
                f"upshift_rpm > downshift_rpm x {ratios[g] / ratios[g + 1]:.3g}."
            )


def _check_conventional(cfg: ConventionalConfig, source: str) -> None:
    _check_controller(cfg, source)
    _pairs_below(cfg, source, (("engine.stall_speed_rpm", "engine.redline_rpm"),
                               ("controller.downshift_rpm", "controller.upshift_rpm")))  # fmt: skip
    _check_shift_schedule(cfg, source)


def _check_bev(cfg: BEVConfig, source: str) -> None:
    _check_controller(cfg, source)
    _pairs_below(cfg, source, (("battery.soc_min", "battery.soc_max"),))


def _check_power_split(cfg: PowerSplitConfig, source: str) -> None:
    _check_controller(cfg, source)
    _check_plugin(cfg, source)
    _pairs_below(cfg, source, (("battery.soc_min", "battery.soc_max"),
                               ("controller.soc_low", "controller.soc_high"),
                               ("engine.stall_speed_rpm", "engine.redline_rpm"),
                               ("planetary.sun_teeth", "planetary.ring_teeth")))  # fmt: skip
    _check_optimization(cfg, source)
    zs, zr = cfg.planetary.sun_teeth, cfg.planetary.ring_teeth
    if (zr - zs) % 2:
        raise ConfigError(
            f"{source}: keys 'planetary.sun_teeth' = {zs} and 'planetary.ring_teeth' = {zr} do not form a "
            f"planetary set: the planets would need (ring - sun) / 2 = {(zr - zs) / 2:g} teeth; expected "
            "tooth numbers whose difference is even."
        )
    if cfg.engine.model != "map":
        raise ConfigError(
            f"{source}: key 'engine.model' = {cfg.engine.model!r} is not supported by the power split; "
            "expected 'map' (its DP needs a fuel map)."
        )


def _check_fcev(cfg: FCEVConfig, source: str) -> None:
    _check_controller(cfg, source)
    _pairs_below(cfg, source, (("battery.soc_min", "battery.soc_max"),
                               ("controller.soc_low", "controller.soc_high")))  # fmt: skip
    fc = cfg.fuel_cell
    if fc.min_power_w >= fc.max_power_w:
        raise ConfigError(
            f"{source}: key 'fuel_cell.min_power_w' = {fc.min_power_w} must be below "
            f"'fuel_cell.max_power_w' = {fc.max_power_w}."
        )
    _check_optimization(cfg, source)


def _series_required(data: dict[str, Any]) -> tuple[str, ...]:
    genset = data.get("genset", {})
    kind = genset.get("kind", GensetSection.kind) if isinstance(genset, dict) else GensetSection.kind
    extra = ("engine", "generator") if kind == "engine" else ()
    return ("body", "tire", "final_drive", "motor", "battery", *extra)


# ------------------------------------------------------------------------------------------
# Registry of architectures
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ArchitectureSpec:
    """What a vehicle file of one architecture holds (the file schema; what the file becomes,
    its builder, lives in the one registry :data:`hevsim.architectures.ARCHITECTURES`).

    Attributes:
        name: value of ``[powertrain] architecture``. config_type: its configuration class.
        controllers: the ``[controller] kind`` values it admits, the rule-based one first.
        required: the component sections a file must hold, from the parsed file mapping.
        check: cross-key checks of a validated configuration (raise ConfigError).
    """

    name: str
    config_type: type
    controllers: tuple[str, ...]
    required: Callable[[dict[str, Any]], tuple[str, ...]]
    check: Callable[[Any, str], None]


ARCHITECTURES: dict[str, ArchitectureSpec] = {}
"""Registered architectures by name (``[powertrain] architecture = ...``)."""


def register_architecture(spec: ArchitectureSpec) -> None:
    """Add (or replace) an architecture in :data:`ARCHITECTURES`."""
    ARCHITECTURES[spec.name] = spec


register_architecture(ArchitectureSpec(
    "series", SeriesHEVConfig, ("thermostat", "schedule", *SERIES_ONLINE_CONTROLLERS), _series_required,
    _check_series,
))  # fmt: skip
register_architecture(ArchitectureSpec(
    "parallel", ParallelHEVConfig, ("electric_assist", "ecms", "aecms"),
    lambda data: ("body", "tire", "final_drive", "gearbox", "engine", "motor", "motor_coupling", "battery"),
    _check_parallel,
))  # fmt: skip


register_architecture(ArchitectureSpec(
    "conventional", ConventionalConfig, ("shift_schedule",),
    lambda data: ("body", "tire", "final_drive", "gearbox", "engine"), _check_conventional,
))  # fmt: skip
register_architecture(ArchitectureSpec(
    "bev", BEVConfig, ("direct",),
    lambda data: ("body", "tire", "final_drive", "motor", "battery"), _check_bev,
))  # fmt: skip


register_architecture(ArchitectureSpec(
    "power_split", PowerSplitConfig, ("power_follower", "ecms", "aecms"),
    lambda data: ("body", "tire", "final_drive", "planetary", "engine", "generator", "motor", "battery"),
    _check_power_split,
))  # fmt: skip


register_architecture(ArchitectureSpec(
    "fcev", FCEVConfig, ("load_follower", "ecms", "aecms"),
    lambda data: ("body", "tire", "final_drive", "motor", "fuel_cell", "battery"), _check_fcev,
))  # fmt: skip


def architecture_of(cfg: Any) -> ArchitectureSpec:
    """The registered architecture of a configuration object."""
    for spec in ARCHITECTURES.values():
        if isinstance(cfg, spec.config_type):
            return spec
    raise ConfigError(
        f"{type(cfg).__name__} is not a vehicle configuration; expected one of "
        f"{', '.join(s.config_type.__name__ for s in ARCHITECTURES.values())}."
    )


def with_overrides(cfg: Any, overrides: dict[str, Any], source: str = "study case") -> Any:
    """Copy of ``cfg`` with ``section.field`` overrides (values already range-checked) and the
    architecture's cross-key checks applied (ConfigError on a violation)."""
    by_section: dict[str, dict[str, Any]] = {}
    for key, value in overrides.items():
        sec, _, name = key.partition(".")
        by_section.setdefault(sec, {})[name] = value
    changes = {sec: dataclasses.replace(getattr(cfg, sec), **kw) for sec, kw in by_section.items()}
    new = dataclasses.replace(cfg, **changes)
    architecture_of(new).check(new, source)
    return new


# ------------------------------------------------------------------------------------------
# Layout, presets, completeness
# ------------------------------------------------------------------------------------------
RENAMED_SECTIONS: dict[str, str] = {"gear": "final_drive", "traction_motor": "motor"}
"""Old series-file sections and their new names."""
RENAMED_KEYS: dict[str, str] = {
    "motor.coupling_ratio": "[motor_coupling] ratio",
    "motor.coupling_efficiency": "[motor_coupling] efficiency",
}
"""Old parallel-file keys and where they moved."""
PRESET_DEFAULTS = "defaults"
"""``preset`` value: every omitted section takes its class defaults (a toy vehicle)."""


def presets() -> list[str]:
    """Valid ``preset`` values: ``"defaults"`` and ``"tutorial_level_N"`` (refinement levels)."""
    return [PRESET_DEFAULTS, *(f"tutorial_level_{i}" for i in range(1, len(_level_files()) + 1))]


def _level_files() -> list[Path]:
    root = Path(str(resources.files("hevsim") / "data" / "refinement"))
    return sorted(root.glob("level*.toml"))


def _old_layout(data: dict[str, Any], source: str) -> None:
    fixes: list[str] = []
    if "architecture" in data:
        fixes.append(
            f"move the top-level key 'architecture' = {data['architecture']!r} into a "
            f"[powertrain] section (architecture = {data['architecture']!r})"
        )
    for old, new in RENAMED_SECTIONS.items():
        if old in data:
            fixes.append(f"rename [{old}] to [{new}]")
    for old, new in RENAMED_KEYS.items():
        sec, _, key = old.partition(".")
        if isinstance(data.get(sec), dict) and key in data[sec]:
            fixes.append(f"move '{old}' to {new}")
    if fixes:
        arch = "" if "powertrain" in data or "architecture" in data else (
            "; add [powertrain] architecture = \"series\"" if any(s in data for s in RENAMED_SECTIONS) else ""
        )  # fmt: skip
        raise ConfigError(f"{source}: old configuration layout: {'; '.join(fixes)}{arch}.")


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        out[k] = {**out[k], **v} if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _apply_preset(data: dict[str, Any], source: str) -> dict[str, Any]:
    name = data.get("preset", "")
    if name in ("", PRESET_DEFAULTS):
        return data
    valid = presets()
    if not isinstance(name, str) or name not in valid:
        raise ConfigError(
            f"{source}: key 'preset' = {name!r} is not known; expected one of {', '.join(valid)}."
        )
    base = schema.read_toml(_level_files()[int(name.rsplit("_", 1)[1]) - 1])
    base.pop("name", None)
    return _merge(base, data)


def config_from_dict(
    data: dict[str, Any], source: str = "<config>", base_dir: Path | None = None, *, inert: bool = True
) -> Any:
    """Validate a parsed vehicle mapping into the configuration of its architecture.

    With ``inert`` (a file, the default), a key of ``data`` that does nothing for this vehicle
    (:func:`inert_keys`) is refused, and so is a section of another architecture.

    Raises:
        ConfigError: old layout (with what to rename), unknown architecture (with the valid
            names), missing component sections (all listed), a key that does nothing, or any
            invalid key.
    """
    _old_layout(data, source)
    explicit = [f"{sec}.{key}" for sec, keys in data.items() if isinstance(keys, dict) for key in keys]
    data = _apply_preset(data, source)
    pt = data.get("powertrain")
    if pt is None:
        raise ConfigError(
            f"{source}: section [powertrain] is missing; expected [powertrain] architecture = one "
            f"of {', '.join(repr(a) for a in ARCHITECTURES)}"
            + ("." if data.get("preset") else f" (then the sections it needs: {_needs()}).")
        )
    name = pt.get("architecture") if isinstance(pt, dict) else None
    spec = ARCHITECTURES.get(name) if isinstance(name, str) else None
    if spec is None:
        raise ConfigError(
            f"{source}: key 'powertrain.architecture' = {name!r} is not known; expected one of "
            f"{', '.join(ARCHITECTURES)}."
        )
    if inert:
        _foreign_sections(data, spec, source)
    cfg: Any = schema.build_config(spec.config_type, data, source, base_dir, {}, {})
    if not data.get("preset"):
        missing = [s for s in spec.required(data) if s not in data]
        if missing:
            raise ConfigError(
                f"{source}: the {spec.name} architecture needs sections that are missing: "
                f'{", ".join(f"[{s}]" for s in missing)}; add them, or set preset = "defaults" '
                "to take the defaults of every omitted section."
            )
    spec.check(cfg, source)
    if inert:
        check_road_load_form(explicit, source, ARCHITECTURE_LABELS.get(spec.name, f"{spec.name} vehicle"))
        check_inert(cfg, explicit, source)
    return cfg


ROAD_LOAD_PHYSICAL = ("mass_kg", "drag_coefficient", "frontal_area_m2", "rolling_resistance",
                      "rolling_resistance_speed_s_per_m")  # fmt: skip
"""``[body]`` keys of the physical road-load form."""
ROAD_LOAD_COASTDOWN = ("road_load_a_n", "road_load_b_n_per_m_s", "road_load_c_n_per_m2_s2", "test_mass_kg")
"""``[body]`` keys of the coast-down road-load form (all four together)."""


def check_road_load_form(keys: list[str], source: str, label: str = "vehicle") -> None:
    """ConfigError when the dotted ``keys`` a file sets mix the two road-load forms of
    :class:`BodySection` (naming the keys of each) or give only part of the coast-down form."""
    coast = [f"body.{k}" for k in ROAD_LOAD_COASTDOWN if f"body.{k}" in keys]
    if not coast:
        return
    physical = [f"body.{k}" for k in ROAD_LOAD_PHYSICAL if f"body.{k}" in keys]
    if physical:
        raise ConfigError(
            f"{source}: key '{coast[0]}' does nothing for a {label} whose road load is given in the physical "
            f"form (keys {', '.join(repr(k) for k in physical)}): keys {', '.join(repr(k) for k in coast)} "
            "mix the two road-load forms; give either the physical form (mass, drag, rolling resistance) "
            "or the coast-down form (road_load_a_n, road_load_b_n_per_m_s, road_load_c_n_per_m2_s2, "
            "test_mass_kg), not both."
        )
    missing = [f"body.{k}" for k in ROAD_LOAD_COASTDOWN if f"body.{k}" not in keys]
    if missing:
        raise ConfigError(
            f"{source}: the coast-down road load ({', '.join(repr(k) for k in coast)}) needs "
            f"{', '.join(repr(k) for k in missing)} too; expected all of "
            f"{', '.join('body.' + k for k in ROAD_LOAD_COASTDOWN)}."
        )


# ------------------------------------------------------------------------------------------
# Keys that do nothing for a vehicle (refused in files: issue 26)
# ------------------------------------------------------------------------------------------
ARCHITECTURE_LABELS: dict[str, str] = {
    "series": "series HEV", "parallel": "parallel HEV", "power_split": "power-split HEV",
    "conventional": "conventional vehicle", "bev": "battery-electric vehicle", "fcev": "fuel-cell vehicle",
}  # fmt: skip
"""How messages name the vehicle of an architecture."""

COMMAND_KEYS: dict[str, str] = {
    "body.cg_height_m": "hevsim performance (axle loads of the traction limit)",
    "body.front_axle_to_cg_m": "hevsim performance (axle loads of the traction limit)",
    "body.rear_axle_to_cg_m": "hevsim performance (axle loads of the traction limit)",
    "body.wheels_per_axle": "hevsim performance (axle loads of the traction limit)",
    "tire.friction_coefficient": "hevsim performance (tire adhesion limit)",
    "tire.driven_axle": "hevsim performance (tire adhesion limit)",
    "tire.friction_coefficient_x": "hevsim lap (friction ellipse)",
    "tire.friction_coefficient_y": "hevsim lap (friction ellipse)",
    "body.min_turning_radius_m": "hevsim lap (sharpest corner of a track)",
    "aero.*": "hevsim lap (downforce)",
    "optimization.*": "hevsim optimize (the DP problem)",
    "plugin.charger_efficiency": "hevsim label (a plug-in hybrid's electricity from the wall)",
}
"""Keys that act only in another command than ``simulate``, and where (kept, not refused)."""

SERIES_CONTROLLER_KEYS: dict[str, tuple[str, ...]] = {
    "thermostat": ("soc_low", "soc_high", "soc_boost", "engine_speed_rpm", "start_speed_rpm", "throttle",
                   "throttle_boost", "speed_gain_per_rpm", "pure_ice_band_w"),
    "schedule": ("schedule", "soc_low", "soc_high", "soc_boost", "engine_speed_rpm", "start_speed_rpm",
                 "throttle", "throttle_boost", "speed_gain_per_rpm", "pure_ice_band_w"),
}  # fmt: skip
"""``[controller]`` keys the series HEV's compiled controllers read, by kind."""
CONTROLLER_KEYS: dict[str, tuple[str, ...]] = {
    **SERIES_CONTROLLER_KEYS,
    "electric_assist": ("soc_low", "soc_high", "ev_speed_mps", "ev_power_w", "charge_power_w", "upshift_rpm",
                        "downshift_rpm", "control_points", "engine_on_speed_mps", "engine_min_power_w"),
    "ecms": ("equivalence_factor", "control_points"),
    "aecms": ("equivalence_factor", "aecms_kp", "aecms_ki", "aecms_kinetic_fraction", "control_points"),
    "shift_schedule": ("upshift_rpm", "downshift_rpm"),
    "power_follower": ("soc_low", "soc_high", "ev_speed_mps", "ev_power_w", "charge_power_w",
                       "engine_min_power_w", "control_points"),
    "direct": (),
    "load_follower": ("soc_low", "soc_high", "charge_power_w", "fuel_cell_on_speed_mps",
                      "fuel_cell_min_on_time_s"),
}  # fmt: skip
"""``[controller]`` keys each controller kind reads (the one table: :data:`hevsim.control.CONTROLLERS`
takes its ``parameters`` from here, and :func:`inert_keys` refuses the others)."""
ARCHITECTURE_CONTROLLER_KEYS: dict[str, tuple[str, ...]] = {
    "conventional": ("stop_start", "fuel_cut_speed_rpm"),
    "power_split": ("engine_speed_points",),
}
"""``[controller]`` keys an architecture reads whatever its controller kind."""
_SERIES_ONLY = "only the series HEV's driver limits the braking force and models shaft inertia"
_MACHINE_KEYS: dict[str, tuple[str, ...]] = {
    "ideal": ("max_torque_nm", "torque_scale", "inertia_kgm2"),
    "constant_efficiency": ("max_torque_nm", "efficiency", "torque_scale", "inertia_kgm2"),
    "map": ("data", "rating", "torque_scale", "inertia_kgm2"),
}
_BATTERY_KEYS: dict[str, tuple[str, ...]] = {
    "ideal": ("ocv_v", "capacity_ah"),
    "rint": ("ocv_v", "resistance_ohm", "capacity_ah"),
    "table": ("data",),
    "cell": ("data",),
}
"""Battery keys of one model (the shared ones, limits, arrangement, SOC window, apply to all)."""
_BATTERY_MODEL_ONLY = ("ocv_v", "resistance_ohm", "capacity_ah", "data", "pack", "bus_min_v", "bus_max_v")


DATA_KEYS = ("motor.rating", "generator.rating", "battery.temperature_c")
"""Keys whose effect depends on the component data they select (checked when a file sets them)."""


def inert_keys(cfg: Any) -> dict[str, str]:
    """Dotted keys of ``cfg``'s sections that do nothing for this vehicle -> why (``"sec.*"``:
    the whole section). A file setting one is refused (:func:`check_inert`)."""
    arch = cfg.architecture
    out: dict[str, str] = {}
    # --controller chooses any kind the architecture admits (the series HEV: the thermostat, its
    # online controllers where it can run them, and the schedule only when the file names it: it
    # needs its CSV)
    if arch == "series":
        online = () if _series_online_refusal(cfg) else SERIES_ONLINE_CONTROLLERS
        kinds: tuple[str, ...] = tuple(dict.fromkeys((cfg.controller.kind, "thermostat", *online)))
    else:
        kinds = ARCHITECTURES[arch].controllers if arch in ARCHITECTURES else (cfg.controller.kind,)
    reads: list[str] = ["kind", "aux_power_w", *ARCHITECTURE_CONTROLLER_KEYS.get(arch, ())]
    for kind in kinds:
        reads += CONTROLLER_KEYS.get(kind, ())
    for f in dataclasses.fields(ControllerSection):
        if f.name not in reads:
            out[f"controller.{f.name}"] = f"none of its controllers ({', '.join(kinds)}) reads it"
    plugin = getattr(cfg, "plugin", None)
    if plugin is not None and plugin.mode != "blended":
        why = "plugin.mode = 'off' (a charge-sustaining hybrid)" if plugin.mode == "off" else (
            "plugin.mode = 'ev_first' (only 'blended' reads it)"
        )  # fmt: skip
        for f in dataclasses.fields(PluginSection):
            if f.name != "mode" and (plugin.mode == "off" or f.name.startswith("blended_")):
                out[f"plugin.{f.name}"] = why
    body = getattr(cfg, "body", None)
    if body is not None and body.test_mass_kg > 0.0:
        for name in ROAD_LOAD_PHYSICAL:
            out[f"body.{name}"] = "its road load is given in the coast-down form (body.test_mass_kg > 0)"
    elif body is not None:
        for name in ROAD_LOAD_COASTDOWN:
            out[f"body.{name}"] = "body.test_mass_kg = 0 selects the physical road-load form"
    battery = getattr(cfg, "battery", None)
    if battery is None:
        out["simulation.soc_initial"] = "it has no traction battery"
        out["metrics.conversion_efficiency"] = "it has no traction battery (no SOC correction)"
        out["metrics.soc_correction_ocv_v"] = "it has no traction battery (no SOC correction)"
        out["brakes.regen_min_speed_mps"] = out["brakes.regen_fraction"] = "it has no machine to regenerate"
    else:
        keep = ("pack", "bus_min_v", "bus_max_v") if battery.model == "pack" else _BATTERY_KEYS[battery.model]
        for name in _BATTERY_MODEL_ONLY:
            if name not in keep:
                out[f"battery.{name}"] = f"the battery model {battery.model!r} does not read it"
        if battery.model == "pack":
            for f in dataclasses.fields(BatterySection):
                if f.name not in (*keep, "model", "soc_min", "soc_max"):
                    out[f"battery.{f.name}"] = (
                        "the pack file's arrangement, limits and temperatures replace it"
                    )
    if arch != "series":
        out["brakes.max_decel_mps2"] = _SERIES_ONLY
        for sec in ("engine", "motor", "generator"):
            out[f"{sec}.inertia_kgm2"] = _SERIES_ONLY
    if arch not in ("bev", "fcev") and hasattr(cfg, "brakes"):
        out.setdefault(
            "brakes.regen_fraction", "only the battery-electric and fuel-cell vehicles blend their brakes"
        )
    if arch not in ("series", "bev", "fcev") and hasattr(
        cfg, "brakes"
    ):  # the power split regenerates at any speed
        out.setdefault("brakes.regen_min_speed_mps", "it regenerates down to standstill")
    for sec in ("motor", "generator"):
        m = getattr(cfg, sec, None)
        if m is not None:
            for f in dataclasses.fields(MachineSection):
                if f.name not in (*_MACHINE_KEYS[m.model], "model"):
                    out.setdefault(f"{sec}.{f.name}", f"the machine model {m.model!r} does not read it")
    e = getattr(cfg, "engine", None)
    if e is not None:
        out["engine.max_torque_nm" if e.model == "map" else "engine.data"] = (
            f"the engine model {e.model!r} does not read it"
        )
    if arch == "series":
        if cfg.genset.kind != "current_source":
            out["genset.current_a"] = f"the genset kind {cfg.genset.kind!r} does not read it"
        if cfg.genset.kind != "engine":
            out["engine.*"] = out["generator.*"] = f"the genset kind {cfg.genset.kind!r} has no engine"
    if arch == "bev":
        out["fuel.lower_heating_value_j_per_kg"] = "it burns no fuel"
    if arch == "conventional" and cfg.controller.aux_power_w == 0.0:
        out["alternator.efficiency"] = "the alternator carries no load (controller.aux_power_w = 0)"
    if battery is not None and battery.model in ("ideal", "rint"):
        out["battery.temperature_c"] = f"the battery model {battery.model!r} does not depend on temperature"
    return out


def _data_inert(cfg: Any, key: str) -> str | None:
    """Why ``key`` does nothing with the component data ``cfg`` names (a map without a peak
    rating, cell tables equal at every temperature), else None. Read only for keys a file
    sets."""
    import numpy as np

    def folder_of(data: str, kind: str) -> Path | None:  # as hevsim.sim.model.resolve_component
        for cand in (
            (base / data).expanduser(),
            Path(str(resources.files("hevsim") / "data" / "components")) / kind / data,
        ):
            if cand.is_dir():
                return cand
        return None  # the model's builder names the missing folder

    sec, _, name = key.partition(".")
    part = getattr(cfg, sec, None)
    base = Path(cfg.base_dir)
    if name == "rating" and isinstance(part, MachineSection) and part.model == "map":
        folder = folder_of(part.data, "motors")
        if folder is None or not (folder / "torque_limits.csv").is_file():
            return None
        t = np.genfromtxt(folder / "torque_limits.csv", delimiter=",", names=True)
        cols = t.dtype.names or ()
        pairs = [(f"max_{m}_torque_cont_N_m", f"max_{m}_torque_peak_N_m") for m in ("motoring", "generating")]
        if all(c not in cols or p not in cols or np.array_equal(t[c], t[p]) for c, p in pairs):
            return f"the map {part.data!r} has the same continuous and peak torque curves"
    if key == "battery.temperature_c" and isinstance(part, BatterySection) and part.model == "table":
        folder = folder_of(part.data, "batteries")
        if folder is None:
            return None
        for f in ("ocv.csv", "r_discharge.csv", "r_charge.csv", "capacity.csv"):
            t = np.genfromtxt(folder / f, delimiter=",", names=True)
            names = t.dtype.names or ()
            values = [n for n in names if n not in ("temperature_degC", "soc_fraction")]
            by_soc = t["soc_fraction"] if "soc_fraction" in names else np.zeros(t.shape)
            for v in values:
                for x in np.unique(by_soc):
                    if np.ptp(t[v][by_soc == x]) > 0.0:
                        return None
        return f"the cell tables {part.data!r} are the same at every temperature"
    return None


def check_inert(cfg: Any, keys: list[str], source: str) -> None:
    """ConfigError naming the first of the dotted ``keys`` (those a file sets) that does
    nothing for ``cfg``'s vehicle (:func:`inert_keys`)."""
    inert = inert_keys(cfg)
    label = ("plug-in " if is_plugin(cfg) else "") + ARCHITECTURE_LABELS.get(
        cfg.architecture, f"{cfg.architecture} vehicle"
    )
    for key in keys:
        why = inert.get(key) or inert.get(f"{key.partition('.')[0]}.*")
        if not why and key in DATA_KEYS:
            why = _data_inert(cfg, key)
        if why:
            raise ConfigError(
                f"{source}: key '{key}' does nothing for a {label} ({why}); remove it or change the "
                "key it depends on."
            )


def _foreign_sections(data: dict[str, Any], spec: ArchitectureSpec, source: str) -> None:
    """ConfigError for a section of another architecture in a file of ``spec``'s."""
    own = {f.name for f in dataclasses.fields(spec.config_type)}
    label = ARCHITECTURE_LABELS.get(spec.name, f"{spec.name} vehicle")
    for sec, value in data.items():
        if sec in own or not isinstance(value, dict):
            continue
        users = [
            s.name
            for s in ARCHITECTURES.values()
            if sec in {f.name for f in dataclasses.fields(s.config_type)}
        ]
        if users:
            first = next(iter(value), "")
            key = f"{sec}.{first}" if first else sec
            why = (
                "; it has no traction battery: every battery model, 'pack' included, needs an electric drive"
            )
            shown = f"value {value[first]!r}" if first and not isinstance(value[first], dict) else ""
            shown += why if sec == "battery" else ""
            raise ConfigError(
                f"{source}: key '{key}' does nothing for a {label}{f' ({shown})' if shown else ''}: section "
                f"[{sec}] belongs to the {', '.join(users)} architecture(s); remove it."
            )


def _needs() -> str:
    return "; ".join(f"{a}: {', '.join(s.required({}))}" for a, s in ARCHITECTURES.items())


def load_vehicle_config(path: str | Path) -> Any:
    """Read and validate a vehicle TOML file of any registered architecture."""
    p = Path(path)
    return config_from_dict(schema.read_toml(p), source=str(p), base_dir=p.resolve().parent)


def _of_architecture(cfg: Any, name: str, source: str) -> Any:
    if cfg.architecture != name:
        raise ConfigError(
            f"{source}: key 'powertrain.architecture' = {cfg.architecture!r}; expected {name!r} here."
        )
    return cfg


def from_dict(
    data: dict[str, Any], source: str = "<config>", base_dir: Path | None = None
) -> SeriesHEVConfig:
    """Validate a series-HEV mapping (``[powertrain]`` may be omitted: it defaults to series)."""
    data = dict(data)
    if "powertrain" not in data and "architecture" not in data:
        data["powertrain"] = {"architecture": "series"}
    cfg: SeriesHEVConfig = _of_architecture(config_from_dict(data, source, base_dir), "series", source)
    return cfg


def load_config(path: str | Path) -> Any:
    """Read and validate a vehicle TOML file of any registered architecture: the configuration
    type its ``[powertrain] architecture`` names (:class:`SeriesHEVConfig`,
    :class:`ParallelHEVConfig`, :class:`PowerSplitConfig`, :class:`ConventionalConfig`,
    :class:`BEVConfig`); the same as :func:`load_vehicle_config`."""
    return load_vehicle_config(path)


def fields_with_bounds(cls: type) -> list[tuple[str, dataclasses.Field[Any]]]:
    """Every (dotted key, field) of a configuration class and its sections, for tests/docs."""
    out: list[tuple[str, dataclasses.Field[Any]]] = []
    for f in dataclasses.fields(cls):
        tp = f.default_factory() if f.default_factory is not dataclasses.MISSING else None
        if tp is not None and dataclasses.is_dataclass(tp):
            out.extend((f"{f.name}.{g.name}", g) for g in dataclasses.fields(tp))
        else:
            out.append((f.name, f))
    return out

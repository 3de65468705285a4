"""Parallel hybrid-electric vehicle: configuration (TOML, validated) and component assembly.

The architecture is the one of the thesis's appendix DP script (Loghavi 2015): an engine
driving the wheels through a clutch, a multi-speed gearbox and the final drive, and an
electric machine coupled to the final-drive input through a fixed gear ("EM gear ratio").
At a standstill, or when the engine cannot turn at its running speed in the chosen gear,
the clutch opens and the machine alone drives. The battery sits on the machine's DC bus.

A configuration file holds ``architecture = "parallel"`` and the sections below; every key
is checked on load: an unknown key, a wrong type, a bad choice or an out-of-range value
raises :class:`~hevsim.errors.ConfigError` naming the file and the key. Units are in the key
names; ``*_rpm`` and ``*_c`` are converted when the model is built. Component data
(``data = "..."``) names a shipped folder under ``hevsim/data/components`` or a path relative
to the configuration file. ``examples/parallel_hev.toml`` documents every key.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hevsim import schema
from hevsim.components.battery import BatteryPack
from hevsim.components.body import VehicleBody
from hevsim.components.driveline import Gear, Tire
from hevsim.components.electric_machine import ElectricMachine
from hevsim.components.engine import Engine
from hevsim.fuels import with_config_fuel
from hevsim.errors import ConfigError
from hevsim.fuels import FuelSection
from hevsim.sim.model import resolve_component
from hevsim.units import c_to_k, rpm_to_radps

ARCHITECTURE = "parallel"
"""Value of the top-level ``architecture`` key of a parallel-HEV configuration file."""


@dataclass(frozen=True)
class BodySection:
    """Vehicle body; defaults are the appendix DP script's (2011 VW Jetta data)."""

    mass_kg: float = 1389.0
    drag_coefficient: float = 0.32
    frontal_area_m2: float = 2.642
    rolling_resistance: float = 0.013
    mass_factor: float = 1.2
    air_density_kgpm3: float = 1.25
    headwind_mps: float = 0.0


@dataclass(frozen=True)
class TireSection:
    """Tire rolling radius [m] (no slip)."""

    radius_m: float = 0.25


@dataclass(frozen=True)
class FinalDriveSection:
    """Final drive ratio [-] and efficiency [-]."""

    ratio: float = 3.65
    efficiency: float = 1.0


@dataclass(frozen=True)
class GearboxSection:
    """Gearbox ratios [-] (first gear first) and efficiency [-] in the engine path."""

    ratios: tuple[float, ...] = (3.78, 2.12, 1.36, 1.03, 0.84)
    efficiency: float = 0.97


@dataclass(frozen=True)
class EngineSection:
    """Engine maps (shipped name or folder) and running-speed window."""

    data: str = "vw_1p9_tdi_ci67"
    stall_speed_rpm: float = 800.0
    redline_rpm: float = 4400.0
    torque_scale: float = 1.0


@dataclass(frozen=True)
class MotorSection:
    """Electric machine and its coupling gear to the final-drive input."""

    model: str = "constant_efficiency"
    max_torque_nm: float = 600.0
    efficiency: float = 0.6
    data: str = "honda_pm49"
    rating: str = "cont"
    torque_scale: float = 1.0
    coupling_ratio: float = 1.0
    coupling_efficiency: float = 1.0


@dataclass(frozen=True)
class BatterySection:
    """Battery pack: "ideal" | "rint" (constant OCV and R) | "table" (cell tables in data)."""

    model: str = "ideal"
    ocv_v: float = 300.0
    capacity_ah: float = 5.0
    resistance_ohm: float = 0.0
    data: str = "nimh_spiral_6ah_insight_prius_nimh6"
    n_series: int = 1
    n_parallel: int = 1
    r_extra_ohm: float = 0.0
    temperature_c: float = 25.0
    max_discharge_current_a: float = 200.0
    max_charge_current_a: float = 200.0
    soc_min: float = 0.4
    soc_max: float = 0.8


@dataclass(frozen=True)
class OptimizationSection:
    """Dynamic-programming settings (the appendix's problem by default)."""

    cycle: str = "udds"
    soc_initial: float = 0.8
    final_soc: str = "window"
    final_soc_min: float = 0.7
    final_soc_max: float = 0.8
    soc_tolerance: float = 0.005
    soc_grid_points: int = 400
    throttle_grid_points: int = 400
    final_constraint: str = "auto"


@dataclass(frozen=True)
class MetricsSection:
    """Fuel-to-battery conversion efficiency of the SOC correction, eq (16) [-]."""

    conversion_efficiency: float = 0.25


@dataclass(frozen=True)
class ParallelHEVConfig:
    """A whole parallel-HEV configuration."""

    name: str = "parallel_hev"
    description: str = ""
    architecture: str = ARCHITECTURE
    body: BodySection = field(default_factory=BodySection)
    tire: TireSection = field(default_factory=TireSection)
    final_drive: FinalDriveSection = field(default_factory=FinalDriveSection)
    gearbox: GearboxSection = field(default_factory=GearboxSection)
    engine: EngineSection = field(default_factory=EngineSection)
    motor: MotorSection = field(default_factory=MotorSection)
    battery: BatterySection = field(default_factory=BatterySection)
    optimization: OptimizationSection = field(default_factory=OptimizationSection)
    metrics: MetricsSection = field(default_factory=MetricsSection)
    fuel: FuelSection = field(default_factory=FuelSection)  # hevsim.fuels: choose/override the fuel
    base_dir: str = "."

    def to_dict(self) -> dict[str, Any]:
        """Plain dict of every value (the resolved configuration, for results)."""
        return schema.to_dict(self)

    def replace(self, **changes: Any) -> ParallelHEVConfig:
        """Copy with dotted-key overrides, e.g. ``replace(**{"body.mass_kg": 1500.0})``."""
        data = schema.with_changes(self.to_dict(), changes)
        return parallel_from_dict(data, source=f"{self.name} (modified)", base_dir=Path(self.base_dir))


CHOICES: dict[str, tuple[str, ...]] = {
    "architecture": (ARCHITECTURE,),
    "motor.model": ("ideal", "constant_efficiency", "map"),
    "motor.rating": ("cont", "peak"),
    "battery.model": ("ideal", "rint", "table"),
    "optimization.final_soc": ("window", "sustain"),
    "optimization.final_constraint": ("auto", "boundary_line", "levelset", "wall", "penalty"),
}
"""Allowed values of the string keys."""

_POS = (1e-9, math.inf)
BOUNDS: dict[str, tuple[float, float]] = {
    "body.mass_kg": (1.0, 1e6),
    "body.drag_coefficient": (0.0, 10.0),
    "body.frontal_area_m2": (0.0, 100.0),
    "body.rolling_resistance": (0.0, 1.0),
    "body.mass_factor": (1.0, 10.0),
    "body.air_density_kgpm3": (0.0, 10.0),
    "tire.radius_m": (0.01, 5.0),
    "final_drive.ratio": (1e-3, 1e3),
    "final_drive.efficiency": (0.01, 1.0),
    "gearbox.ratios": (1e-3, 1e3),
    "gearbox.efficiency": (0.01, 1.0),
    "engine.stall_speed_rpm": (1.0, 1e5),
    "engine.redline_rpm": (1.0, 1e5),
    "engine.torque_scale": _POS,
    "motor.max_torque_nm": _POS,
    "motor.efficiency": (0.01, 1.0),
    "motor.torque_scale": _POS,
    "motor.coupling_ratio": (1e-3, 1e3),
    "motor.coupling_efficiency": (0.01, 1.0),
    "battery.ocv_v": _POS,
    "battery.capacity_ah": (1e-6, 1e6),
    "battery.resistance_ohm": (0.0, 1e3),
    "battery.n_series": (1, 10000),
    "battery.n_parallel": (1, 10000),
    "battery.r_extra_ohm": (0.0, 1e3),
    "battery.max_discharge_current_a": _POS,
    "battery.max_charge_current_a": _POS,
    "battery.soc_min": (0.0, 1.0),
    "battery.soc_max": (0.0, 1.0),
    "optimization.soc_initial": (0.0, 1.0),
    "optimization.final_soc_min": (0.0, 1.0),
    "optimization.final_soc_max": (0.0, 1.0),
    "optimization.soc_tolerance": (0.0, 1.0),
    "optimization.soc_grid_points": (2, 100_000),
    "optimization.throttle_grid_points": (2, 100_000),
    "metrics.conversion_efficiency": (0.01, 1.0),
}
"""Inclusive (low, high) bounds of the numeric keys (each element of a list)."""


def parallel_from_dict(
    data: dict[str, Any], source: str = "<config>", base_dir: Path | None = None
) -> ParallelHEVConfig:
    """Validate a parsed configuration mapping into a :class:`ParallelHEVConfig`."""
    cfg = schema.build_config(ParallelHEVConfig, data, source, base_dir, CHOICES, BOUNDS)
    b, e, o = cfg.battery, cfg.engine, cfg.optimization
    pairs = (
        ("battery.soc_min", b.soc_min, "battery.soc_max", b.soc_max),
        ("engine.stall_speed_rpm", e.stall_speed_rpm, "engine.redline_rpm", e.redline_rpm),
        ("optimization.final_soc_min", o.final_soc_min, "optimization.final_soc_max", o.final_soc_max),
    )
    for k_lo, v_lo, k_hi, v_hi in pairs:
        if v_lo >= v_hi:
            raise ConfigError(f"{source}: key '{k_lo}' = {v_lo} must be below '{k_hi}' = {v_hi}.")
    for key, value in (("optimization.soc_initial", o.soc_initial),):
        if not b.soc_min <= value <= b.soc_max:
            raise ConfigError(
                f"{source}: key '{key}' = {value} lies outside the SOC window "
                f"[battery.soc_min, battery.soc_max] = [{b.soc_min}, {b.soc_max}]."
            )
    if o.final_soc == "window" and (o.final_soc_min < b.soc_min or o.final_soc_max > b.soc_max):
        raise ConfigError(
            f"{source}: keys 'optimization.final_soc_min'/'final_soc_max' = [{o.final_soc_min}, "
            f"{o.final_soc_max}] must lie inside the SOC window [{b.soc_min}, {b.soc_max}]."
        )
    return cfg


def load_parallel_config(path: str | Path) -> ParallelHEVConfig:
    """Read and validate a parallel-HEV TOML configuration file."""
    p = Path(path)
    data = schema.read_toml(p)
    if "architecture" not in data:
        raise ConfigError(f"{p}: key 'architecture' is missing; expected architecture = \"{ARCHITECTURE}\".")
    return parallel_from_dict(data, source=str(p), base_dir=p.resolve().parent)


@dataclass(frozen=True, eq=False)
class ParallelHEV:
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

    architecture: typing.ClassVar[str] = ARCHITECTURE

    @property
    def name(self) -> str:
        """Configuration name."""
        return self.config.name

    @property
    def gear_ratios(self) -> np.ndarray:
        """Gearbox ratios [-], first gear first."""
        return np.array([g.ratio for g in self.gears])


def _motor(sec: MotorSection, base: Path) -> ElectricMachine:
    if sec.model == "map":
        folder = resolve_component(sec.data, "motor", base, "motor.data")
        return ElectricMachine.from_directory(
            folder, rating=sec.rating, torque_scale=sec.torque_scale, name=f"motor: {folder.name}"
        )
    eff = sec.efficiency if sec.model == "constant_efficiency" else 1.0
    m = ElectricMachine.constant_torque(
        f"motor: constant {sec.max_torque_nm:g} N·m", sec.max_torque_nm, efficiency=eff
    )
    if sec.torque_scale != 1.0 or (sec.model == "constant_efficiency" and eff == 1.0):
        return dataclasses.replace(m, kind=sec.model, torque_scale=sec.torque_scale)
    return m


def _battery(sec: BatterySection, base: Path) -> BatteryPack:
    common: dict[str, Any] = {
        "max_discharge_current_a": sec.max_discharge_current_a,
        "max_charge_current_a": sec.max_charge_current_a,
        "temperature_k": c_to_k(sec.temperature_c),
        "r_extra_ohm": sec.r_extra_ohm,
        "n_series": sec.n_series,
        "n_parallel": sec.n_parallel,
    }
    if sec.model == "table":
        folder = resolve_component(sec.data, "battery", base, "battery.data")
        return BatteryPack.from_directory(folder, **common)
    r = sec.resistance_ohm if sec.model == "rint" else 0.0
    return BatteryPack.constant(f"{sec.model} {sec.ocv_v:g} V {sec.capacity_ah:g} Ah", sec.model, sec.ocv_v,
                                sec.capacity_ah, r, **common)  # fmt: skip


def build_parallel_hev(cfg: ParallelHEVConfig) -> ParallelHEV:
    """Build the component objects of a parallel HEV from its configuration."""
    base = Path(cfg.base_dir)
    body = VehicleBody.from_section(cfg.body)
    e = cfg.engine
    folder = resolve_component(e.data, "engine", base, "engine.data")
    engine = Engine.from_directory(
        folder,
        stall_speed_radps=rpm_to_radps(e.stall_speed_rpm),
        redline_radps=rpm_to_radps(e.redline_rpm),
        torque_scale=e.torque_scale,
    )
    g = cfg.gearbox
    return ParallelHEV(
        config=cfg,
        body=body,
        tire=Tire(radius_m=cfg.tire.radius_m),
        final_drive=Gear(ratio=cfg.final_drive.ratio, efficiency=cfg.final_drive.efficiency),
        gears=tuple(Gear(ratio=r, efficiency=g.efficiency) for r in g.ratios),
        engine=with_config_fuel(engine, cfg),  # [fuel] section of the configuration
        motor=_motor(cfg.motor, base),
        motor_coupling=Gear(ratio=cfg.motor.coupling_ratio, efficiency=cfg.motor.coupling_efficiency),
        battery=_battery(cfg.battery, base),
    )

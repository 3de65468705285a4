"""Vehicle configuration files (TOML), validated on load.

A configuration is a set of sections, each a frozen dataclass below. Every key is checked:
an unknown key, a wrong type or an out-of-range value raises :class:`ConfigError` naming the
file, the key, the value and what was expected. Units are in the key names; the few
non-SI keys (``*_rpm``, ``*_per_mph``, ``*_c``) are converted when the model is built.
Component data (``data = "..."``) names a shipped folder under ``hevsim/data/components`` or a
path relative to the configuration file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hevsim import schema
from hevsim.errors import ConfigError
from hevsim.fuels import FuelSection


@dataclass(frozen=True)
class SimulationSection:
    """Run settings: default cycle, fixed time step [s], initial SOC [-]."""

    cycle: str = "udds"
    dt_s: float = 0.5
    soc_initial: float = 0.7


@dataclass(frozen=True)
class BodySection:
    """Vehicle body (thesis Table 2.2; defaults are the Simscape Vehicle Body block's)."""

    mass_kg: float = 1200.0
    drag_coefficient: float = 0.4
    frontal_area_m2: float = 3.0
    rolling_resistance: float = 0.0
    mass_factor: float = 1.0
    air_density_kgpm3: float = 1.18
    headwind_mps: float = 0.0
    cg_height_m: float = 0.5
    front_axle_to_cg_m: float = 1.4
    rear_axle_to_cg_m: float = 1.6
    wheels_per_axle: int = 2


@dataclass(frozen=True)
class TireSection:
    """Tire rolling radius [m] (no slip in the forward simulator)."""

    radius_m: float = 0.3


@dataclass(frozen=True)
class GearSection:
    """Final drive ratio [-] and efficiency [-]."""

    ratio: float = 2.0
    efficiency: float = 1.0


@dataclass(frozen=True)
class BrakesSection:
    """Friction brakes: max deceleration they can give [m/s^2]; regeneration cut-in [m/s]."""

    max_decel_mps2: float = 7.0
    regen_min_speed_mps: float = 0.0


@dataclass(frozen=True)
class MachineSection:
    """Electric machine: model "ideal" | "constant_efficiency" | "map"."""

    model: str = "ideal"
    max_torque_nm: float = 200.0
    efficiency: float = 1.0
    data: str = "honda_pm49"
    rating: str = "cont"
    torque_scale: float = 1.0
    inertia_kgm2: float = 0.0


@dataclass(frozen=True)
class EngineSection:
    """Engine: model "constant_torque" (ideal fuel) | "map" (measured maps in ``data``)."""

    model: str = "map"
    max_torque_nm: float = 200.0
    data: str = "vw_1p9_tdi_ci67"
    inertia_kgm2: float = 0.12
    stall_speed_rpm: float = 750.0
    redline_rpm: float = 4400.0
    torque_scale: float = 1.0


@dataclass(frozen=True)
class GensetSection:
    """Genset: kind "none" | "current_source" (ideal constant current) | "engine"."""

    kind: str = "engine"
    current_a: float = 50.0


@dataclass(frozen=True)
class BatterySection:
    """Battery: model "ideal" | "rint" | "table" (cell tables in ``data``) | "cell".

    ``"cell"``: an ``n_series`` x ``n_parallel`` pack of the electro-thermal cell model of
    :mod:`hevsim.battery` (``data`` names a shipped cell parameter set or a TOML path), with
    its RC and thermal dynamics; ``temperature_c`` is its initial and heat-port temperature.
    """

    model: str = "ideal"
    ocv_v: float = 336.0
    resistance_ohm: float = 0.0
    capacity_ah: float = 8.5
    data: str = "nimh_spiral_6ah_insight_prius_nimh6"
    n_series: int = 1
    n_parallel: int = 1
    r_extra_ohm: float = 0.0
    temperature_c: float = 25.0
    max_discharge_current_a: float = math.inf
    max_charge_current_a: float = math.inf
    soc_min: float = 0.0
    soc_max: float = 1.0


@dataclass(frozen=True)
class DriverSection:
    """Proportional speed controller: request = gain x error (per mph, as in the tutorial)."""

    kind: str = "proportional"
    gain_per_mph: float = 0.5
    feedforward: float = 0.0


@dataclass(frozen=True)
class ControllerSection:
    """Supervisory controller: genset thermostat on SOC, engine operating point, speed loop.

    ``kind = "schedule"`` follows a genset schedule CSV (``schedule``: time_s,
    engine_speed_rpm, engine_throttle) instead, e.g. a DP optimum.
    """

    kind: str = "thermostat"
    schedule: str = ""
    soc_low: float = 0.6
    soc_high: float = 0.7
    soc_boost: float = 0.0
    engine_speed_rpm: float = 1800.0
    start_speed_rpm: float = 1500.0
    throttle: float = 0.5
    throttle_boost: float = 1.0
    speed_gain_per_rpm: float = 0.01
    pure_ice_band_w: float = 500.0
    aux_power_w: float = 0.0


@dataclass(frozen=True)
class MetricsSection:
    """Fuel-economy settings: fuel-to-battery conversion efficiency of eq (16) [-]."""

    conversion_efficiency: float = 0.25


@dataclass(frozen=True)
class VehicleConfig:
    """A whole series-HEV configuration."""

    name: str = "vehicle"
    description: str = ""
    simulation: SimulationSection = field(default_factory=SimulationSection)
    body: BodySection = field(default_factory=BodySection)
    tire: TireSection = field(default_factory=TireSection)
    gear: GearSection = field(default_factory=GearSection)
    brakes: BrakesSection = field(default_factory=BrakesSection)
    traction_motor: MachineSection = field(default_factory=MachineSection)
    generator: MachineSection = field(default_factory=MachineSection)
    engine: EngineSection = field(default_factory=EngineSection)
    genset: GensetSection = field(default_factory=GensetSection)
    battery: BatterySection = field(default_factory=BatterySection)
    driver: DriverSection = field(default_factory=DriverSection)
    controller: ControllerSection = field(default_factory=ControllerSection)
    metrics: MetricsSection = field(default_factory=MetricsSection)
    fuel: FuelSection = field(default_factory=FuelSection)  # hevsim.fuels: choose/override the fuel
    base_dir: str = "."

    def to_dict(self) -> dict[str, Any]:
        """Plain dict of every value (the resolved configuration, for results)."""
        return schema.to_dict(self)

    def replace(self, **changes: Any) -> VehicleConfig:
        """Copy with dotted-key overrides, e.g. ``replace(**{"body.mass_kg": 1500.0})``."""
        data = schema.with_changes(self.to_dict(), changes)
        return from_dict(data, source=f"{self.name} (modified)", base_dir=Path(self.base_dir))


# Allowed values of the string choices, checked on load.
CHOICES: dict[str, tuple[str, ...]] = {
    "traction_motor.model": ("ideal", "constant_efficiency", "map"),
    "generator.model": ("ideal", "constant_efficiency", "map"),
    "traction_motor.rating": ("cont", "peak"),
    "generator.rating": ("cont", "peak"),
    "engine.model": ("constant_torque", "map"),
    "genset.kind": ("none", "current_source", "engine"),
    "battery.model": ("ideal", "rint", "table", "cell"),
    "controller.kind": ("thermostat", "schedule"),
    "driver.kind": ("proportional",),
}
# (low, high) inclusive bounds of numeric keys.
BOUNDS: dict[str, tuple[float, float]] = {
    "simulation.dt_s": (1e-3, 10.0),
    "simulation.soc_initial": (0.0, 1.0),
    "body.mass_kg": (1.0, 1e6),
    "tire.radius_m": (0.01, 5.0),
    "gear.ratio": (1e-3, 1e3),
    "gear.efficiency": (0.01, 1.0),
    "traction_motor.efficiency": (0.01, 1.0),
    "generator.efficiency": (0.01, 1.0),
    "controller.soc_low": (0.0, 1.0),
    "controller.soc_high": (0.0, 1.0),
    "controller.throttle": (0.0, 1.0),
    "controller.throttle_boost": (0.0, 1.0),
    "metrics.conversion_efficiency": (0.01, 1.0),
    "battery.n_series": (1, 10000),
    "battery.n_parallel": (1, 10000),
    "battery.capacity_ah": (1e-6, 1e6),
    "battery.soc_min": (0.0, 1.0),
    "battery.soc_max": (0.0, 1.0),
}


def from_dict(data: dict[str, Any], source: str = "<config>", base_dir: Path | None = None) -> VehicleConfig:
    """Validate a parsed configuration mapping into a :class:`VehicleConfig`."""
    cfg = schema.build_config(VehicleConfig, data, source, base_dir, CHOICES, BOUNDS)
    c = cfg.controller
    if c.soc_low >= c.soc_high:
        raise ConfigError(
            f"{source}: key 'controller.soc_low' = {c.soc_low} must be below "
            f"'controller.soc_high' = {c.soc_high}."
        )
    return cfg


def load_config(path: str | Path) -> VehicleConfig:
    """Read and validate a TOML configuration file."""
    p = Path(path)
    return from_dict(schema.read_toml(p), source=str(p), base_dir=p.resolve().parent)

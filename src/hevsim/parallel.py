"""Parallel hybrid-electric vehicle: configuration (TOML, validated) and component assembly.

The architecture is the one of the thesis's appendix DP script (Loghavi 2015): an engine
driving the wheels through a clutch, a multi-speed gearbox and the final drive, and an
electric machine coupled to the final-drive input through a fixed gear ("EM gear ratio").
At a standstill, or when the engine cannot turn at its running speed in the chosen gear,
the clutch opens and the machine alone drives. The battery sits on the machine's DC bus.

A configuration file holds ``[powertrain] architecture = "parallel"`` and the shared sections
of :mod:`hevsim.config` (:class:`~hevsim.config.ParallelHEVConfig`: body, tire, final_drive,
gearbox, engine, motor, motor_coupling, battery, optimization, metrics); every key is checked
on load. ``examples/parallel_hev.toml`` documents every key.
"""

from __future__ import annotations

import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

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


def build_parallel_hev(cfg: ParallelHEVConfig) -> ParallelHEV:
    """Build the component objects of a parallel HEV from its configuration."""
    base = Path(cfg.base_dir)
    body = VehicleBody.from_section(cfg.body)
    engine = build_engine(cfg.engine, base)
    g = cfg.gearbox
    return ParallelHEV(
        config=cfg,
        body=body,
        tire=Tire(radius_m=cfg.tire.radius_m),
        final_drive=Gear(ratio=cfg.final_drive.ratio, efficiency=cfg.final_drive.efficiency),
        gears=tuple(Gear(ratio=r, efficiency=g.efficiency) for r in g.ratios),
        engine=with_config_fuel(engine, cfg),  # [fuel] section of the configuration
        motor=build_machine(cfg.motor, "motor", base),
        motor_coupling=Gear(ratio=cfg.motor_coupling.ratio, efficiency=cfg.motor_coupling.efficiency),
        battery=build_battery(cfg.battery, base)[0],
    )

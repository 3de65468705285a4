"""Pieces shared by the architecture models: the configuration-name and gear-ratio
properties of the model dataclasses, a machine's speed limit and the bus-balance entries of
a power flow's ``details``."""

from __future__ import annotations

from typing import Any

import numpy as np

from hevsim.components.body import VehicleBody
from hevsim.components.driveline import Gear, Tire
from hevsim.components.electric_machine import ElectricMachine

FUEL_CONVERTERS: tuple[str, ...] = ("engine", "fuel_cell")
"""Model fields that hold a vehicle's fuel converter (an engine, a fuel-cell system), in the order
:func:`fuel_converter` looks for them."""


def fuel_converter(model: Any) -> Any:
    """A vehicle model's fuel converter: its engine, or a fuel-cell vehicle's fuel-cell system
    (both carry ``name``, ``fuel_name``, ``fuel_lhv_jpkg`` [J/kg], ``fuel_density_kgpm3``,
    ``heating_value_btu_per_gal``, ``co2_kg_per_kg``); None when it has none (a BEV)."""
    for name in FUEL_CONVERTERS:
        conv = getattr(model, name, None)
        if conv is not None:
            return conv
    return None


class NamedModel:
    """Mixin of the architecture models (frozen dataclasses with a ``config`` field)."""

    config: Any

    @property
    def name(self) -> str:
        """Configuration name."""
        return str(self.config.name)


class GearboxModel(NamedModel):
    """Mixin of the models with a multi-speed gearbox (a ``gears`` field)."""

    gears: tuple[Gear, ...]

    @property
    def gear_ratios(self) -> np.ndarray:
        """Gearbox ratios [-], first gear first."""
        return np.array([g.ratio for g in self.gears])


def fixed_gear(section: Any) -> Gear:
    """The :class:`Gear` of a configuration section with ``ratio`` and ``efficiency``
    (final drive, motor coupling)."""
    return Gear(ratio=section.ratio, efficiency=section.efficiency)


def chassis(cfg: Any) -> dict[str, Any]:
    """The fields every architecture model builds alike from its configuration: ``config``,
    ``body``, ``tire`` and ``final_drive`` (keyword arguments of the model dataclass)."""
    return {
        "config": cfg,
        "body": VehicleBody.from_section(cfg.body),
        "tire": Tire(radius_m=cfg.tire.radius_m),
        "final_drive": fixed_gear(cfg.final_drive),
    }


def max_machine_speed_radps(machine: ElectricMachine) -> float:
    """Highest speed [rad/s] of a map machine's torque-limit curve (no limit for the ideal
    and constant-efficiency models): the machine cannot turn faster."""
    if machine.kind != "map":
        return float("inf")
    return float(machine.kernel_tables().lim_x[-1])


def machine_details(flow: Any, speed_radps: Any, shape: tuple[int, ...]) -> dict[str, Any]:
    """``details`` entries of the machine in the bus balance ``flow``
    (:class:`~hevsim.optimal._hev_common.ElectricFlow`) turning at ``speed_radps``."""
    return {
        "motor_speed_radps": np.broadcast_to(speed_radps, shape),
        "motor_torque_nm": flow.torque_nm,
        "motor_power_elec_w": flow.power_elec_w,
    }


def battery_details(flow: Any) -> dict[str, Any]:
    """``details`` entries of the battery in the bus balance ``flow``."""
    return {"battery_current_a": flow.current_a, "battery_power_w": flow.battery_power_w}


NO_REFCOUNT: dict[str, Any] = {"_nrt": False}
"""numba options of a loop that allocates nothing: no reference counting. Passing component
tables (tuples of arrays) into a per-point kernel otherwise costs about 100 ns of
reference-count traffic per call, more than the physics of the point."""


def broadcast_loop(kernel: Any, names: tuple[str, ...], arrays: list[Any], *constants: Any) -> dict[str, Any]:
    """Call a compiled loop over the broadcast of ``arrays``: ``kernel(*flat arrays,
    *constants, out)`` fills ``out`` (len(names), n); returns ``{name: array}`` in the
    broadcast shape (how the numpy methods of an architecture call its scalar kernels)."""
    b = np.broadcast_arrays(*(np.asarray(a) for a in arrays))
    flat = [np.array(a.ravel()) for a in b]
    out = np.empty((len(names), flat[0].size))
    kernel(*flat, *constants, out)
    return {k: out[j].reshape(b[0].shape) for j, k in enumerate(names)}

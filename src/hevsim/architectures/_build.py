"""The component builders every architecture shares: an electric machine, an engine or a
battery from its configuration section, component data resolved against the configuration's
folder or the shipped data, and the vehicle's nominal view of a whole pack.

They build physics objects from configuration sections and are called by every architecture's
builder, so they live in the architectures layer, below the simulator (moved from
:mod:`hevsim.sim.model` and :mod:`hevsim.sim.pack_vehicle`, which re-export them; issue 24).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.battery.pack import load_pack_config
from hevsim.components.battery import BatteryPack
from hevsim.components.electric_machine import ElectricMachine
from hevsim.components.engine import Engine
from hevsim.config import BatterySection, EngineSection, MachineSection
from hevsim.errors import ConfigError
from hevsim.io import cached_build
from hevsim.tables import Table1D
from hevsim.units import c_to_k, rpm_to_radps

COMPONENT_KINDS = {"engine": "engines", "motor": "motors", "battery": "batteries", "fuel_cell": "fuel_cells"}


def shipped_components(kind: str) -> list[str]:
    """Names of the shipped component folders of ``kind`` ("engine", "motor", "battery")."""
    root = resources.files("hevsim") / "data" / "components" / COMPONENT_KINDS[kind]
    return sorted(p.name for p in root.iterdir() if p.is_dir())


def resolve_component(name: str, kind: str, base_dir: Path, key: str) -> Path:
    """Folder for component data ``name``: a path relative to the config, or a shipped name."""
    candidate = (base_dir / name).expanduser()
    if candidate.is_dir():
        return candidate
    shipped = resources.files("hevsim") / "data" / "components" / COMPONENT_KINDS[kind] / name
    if shipped.is_dir():
        return Path(str(shipped))
    raise ConfigError(
        f"key '{key}' = {name!r}: no folder {candidate} and no shipped {kind} of that name; "
        f"shipped {kind}s are: {', '.join(shipped_components(kind))}."
    )


def build_machine(sec: MachineSection, label: str, base: Path) -> ElectricMachine:
    """Electric machine of a ``[motor]``/``[generator]`` section (any architecture).

    ``torque_scale`` scales the torque limits of every model (map, ideal, constant efficiency).
    """
    if sec.model == "map":
        folder = resolve_component(sec.data, "motor", base, f"{label}.data")
        return cached_build(  # parsed and checked once per content of the folder's files
            folder,
            ElectricMachine.from_directory,
            rating=sec.rating,
            torque_scale=sec.torque_scale,
            inertia_kgm2=sec.inertia_kgm2,
            name=f"{label}: {folder.name}",
        )
    eff = sec.efficiency if sec.model == "constant_efficiency" else 1.0
    m = ElectricMachine.constant_torque(
        f"{label}: constant {sec.max_torque_nm:g} N·m", sec.max_torque_nm, efficiency=eff,
        inertia_kgm2=sec.inertia_kgm2,
    )  # fmt: skip
    if sec.torque_scale != 1.0 or (sec.model == "constant_efficiency" and eff == 1.0):
        return dataclasses.replace(m, kind=sec.model, torque_scale=sec.torque_scale)
    return m


def build_engine(e: EngineSection, base: Path) -> Engine:
    """Engine of an ``[engine]`` section: measured maps, or a constant-torque ideal-fuel engine."""
    common = {
        "inertia_kgm2": e.inertia_kgm2,
        "stall_speed_radps": rpm_to_radps(e.stall_speed_rpm),
        "redline_radps": rpm_to_radps(e.redline_rpm),
        "torque_scale": e.torque_scale,
    }
    if e.model == "map":
        folder = resolve_component(e.data, "engine", base, "engine.data")
        return cached_build(folder, Engine.from_directory, **common)  # once per content
    x = np.array([0.0])
    return Engine(
        name=f"constant {e.max_torque_nm:g} N·m engine (ideal fuel)",
        max_torque=Table1D(x, np.array([e.max_torque_nm])),
        closed_throttle_torque=Table1D(x, np.array([0.0])),
        fuel_map=None,
        **common,  # type: ignore[arg-type]
    )


def build_battery(bs: BatterySection, base: Path) -> tuple[BatteryPack, Any]:
    """(pack, cell parameters or None) of a ``[battery]`` section; temperatures in K inside."""
    limits = {
        "max_discharge_current_a": bs.max_discharge_current_a,
        "max_charge_current_a": bs.max_charge_current_a,
        "temperature_k": c_to_k(bs.temperature_c),
        "r_extra_ohm": bs.r_extra_ohm,
        "n_series": bs.n_series,
        "n_parallel": bs.n_parallel,
    }
    if bs.model == "table":
        folder = resolve_component(bs.data, "battery", base, "battery.data")
        return cached_build(folder, BatteryPack.from_directory, **limits), None  # once per content
    if bs.model == "pack":  # the vehicle's view of it; the pack itself: hevsim.sim.pack_vehicle
        return nominal_battery(bs, base), None
    if bs.model == "cell":
        from hevsim.battery.vehicle import quasi_static_pack

        cell = cell_parameters(bs, base)
        pack = quasi_static_pack(
            cell,
            bs.n_series,
            bs.n_parallel,
            c_to_k(bs.temperature_c),
            max_discharge_current_a=bs.max_discharge_current_a,
            max_charge_current_a=bs.max_charge_current_a,
            r_extra_ohm=bs.r_extra_ohm,
        )
        return pack, cell
    pack = BatteryPack.constant(
        f"{bs.model} {bs.ocv_v:g} V {bs.capacity_ah:g} Ah",
        bs.model,
        bs.ocv_v,
        bs.capacity_ah,
        bs.resistance_ohm if bs.model == "rint" else 0.0,
        **limits,
    )
    return pack, None


def cell_parameters(bs: Any, base: Path) -> Any:
    """The cell (:class:`~hevsim.battery.params.CellParameters`) of a ``[battery] model =
    "cell"`` section: ``data`` a cell TOML relative to the vehicle file, or a shipped cell's name.
    Parsed once per file content (:func:`hevsim.io.cached_by_content`; the vehicle's runs only
    read the cell's arrays)."""
    from hevsim.battery.params import load_cell_parameters
    from hevsim.io import cached_by_content

    path = base / bs.data
    try:
        if not (path.suffix == ".toml" and path.is_file()):
            path = _shipped_cells_dir() / f"{bs.data}.toml"
            if Path(bs.data).suffix or not path.is_file():
                return load_cell_parameters(bs.data)  # a path elsewhere, or the error naming the shipped sets
        return cached_by_content(path, load_cell_parameters)
    except ConfigError as exc:
        raise ConfigError(f"{base}: key 'battery.data' = {bs.data!r}: {exc}") from exc


@functools.cache
def _shipped_cells_dir() -> Path:
    """The folder of the shipped cell parameter sets (``hevsim/data/cells``)."""
    return Path(str(resources.files("hevsim") / "data" / "cells"))


def pack_file(bs: Any, base: Path) -> Path:
    """The pack file of a ``[battery] model = "pack"`` section (ConfigError when missing)."""
    if not bs.pack:
        raise ConfigError("key 'battery.pack' is empty; expected a pack TOML file for model = 'pack'.")
    path = Path(bs.pack) if Path(bs.pack).is_absolute() else base / bs.pack
    if not path.is_file():
        raise ConfigError(f"key 'battery.pack' = {bs.pack!r}: no such file {path}; expected a pack TOML.")
    return path


def nominal_battery(bs: Any, base: Path) -> Any:
    """The vehicle's nominal view of the pack (a quasi-static :class:`BatteryPack` of its cells,
    all modules' series groups in series): capacity and OCV for the SOC correction of the
    fuel economy; the run itself uses the pack (:class:`~hevsim.battery.bms.PackRun`)."""
    from hevsim.battery.params import load_cell_parameters
    from hevsim.battery.vehicle import quasi_static_pack
    from hevsim.units import c_to_k

    path = pack_file(bs, base)
    cfg = load_pack_config(path)
    par = cfg.cells.parameters
    params = load_cell_parameters(str(path.parent / par) if (path.parent / par).is_file() else par)
    n_s = cfg.pack.n_modules * cfg.module.n_series
    i_max = cfg.pack.max_current_a
    t0 = c_to_k(cfg.pack.initial_temp_c)
    qs = quasi_static_pack(
        params, n_s, cfg.module.n_parallel, t0, max_discharge_current_a=i_max, max_charge_current_a=i_max
    )
    return replace(qs, name=f"pack {cfg.name} ({path.name})")

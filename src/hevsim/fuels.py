"""Fuel properties: one cited table (``hevsim/data/fuels.toml``) behind a name lookup.

Each engine map declares its fuel in its ``meta.toml`` (``fuel = "gasoline"``); the engine
then carries that fuel's lower heating value [J/kg], density [kg/m^3], CO2 factor [kg/kg] and
per-gallon heating value for the MPGGE calculation [BTU/gal]. A configuration may pick another
fuel or override single values in its ``[fuel]`` section (:class:`FuelSection`; every key
carries its unit). The MPGGE reference gallon (thesis eq 19: reformulated gasoline,
114871.7446 BTU/gal) is in the same table (:func:`mpgge_reference_btu_per_us_gal`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from hevsim.errors import ConfigError, InputError

DEFAULT_FUEL = "diesel"
"""Fuel of an engine that declares none (the ideal constant-torque engine, an ideal genset):
the thesis's series HEV burns diesel (tutorial lecture 7)."""

PROPERTIES = (
    "lower_heating_value_j_per_kg",
    "density_kg_per_m3",
    "co2_kg_per_kg",
    "heating_value_btu_per_us_gal",
)
"""The numeric properties of a fuel, with their units in the names."""

TABLE_PATH = "data/fuels.toml"
"""The table, relative to the installed ``hevsim`` package."""

_ENGINE_FIELDS = {
    "lower_heating_value_j_per_kg": "fuel_lhv_jpkg",
    "density_kg_per_m3": "fuel_density_kgpm3",
    "co2_kg_per_kg": "co2_kg_per_kg",
    "heating_value_btu_per_us_gal": "heating_value_btu_per_gal",
}


@dataclass(frozen=True)
class Fuel:
    """One fuel's properties (SI and BTU per US gallon, units in the names)."""

    name: str
    description: str
    lower_heating_value_j_per_kg: float
    density_kg_per_m3: float
    co2_kg_per_kg: float
    heating_value_btu_per_us_gal: float
    overridden: tuple[str, ...] = ()

    def engine_kwargs(self) -> dict[str, Any]:
        """The :class:`hevsim.components.engine.Engine` fields this fuel sets."""
        kw: dict[str, Any] = {"fuel_name": self.name}
        kw.update({field: getattr(self, key) for key, field in _ENGINE_FIELDS.items()})
        return kw

    @property
    def label(self) -> str:
        """The name, with the overridden keys when a configuration changed any."""
        return f"{self.name} (overridden: {', '.join(self.overridden)})" if self.overridden else self.name

    def metadata(self) -> dict[str, Any]:
        """What a result records about the fuel it used."""
        out: dict[str, Any] = {"name": self.label, "description": self.description}
        out.update({key: getattr(self, key) for key in PROPERTIES})
        out["mpgge_reference_heating_value_btu_per_us_gal"] = mpgge_reference_btu_per_us_gal()
        out["table"] = f"hevsim/{TABLE_PATH}"
        return out


def _meta(unit: str) -> dict[str, Any]:
    """Schema metadata of a ``[fuel]`` value: >= 0 (0 = the table's value), with its unit."""
    return {"bounds": (0.0, math.inf), "unit": unit}


@dataclass(frozen=True)
class FuelSection:
    """``[fuel]`` of a vehicle configuration: choose or override the engine's fuel.

    ``name`` "" keeps the fuel the engine map declares (diesel for an ideal engine); a value
    of 0 keeps the table's value of that property; any other value replaces it.
    """

    name: str = ""
    lower_heating_value_j_per_kg: float = field(default=0.0, metadata=_meta("J/kg"))
    density_kg_per_m3: float = field(default=0.0, metadata=_meta("kg/m^3"))
    co2_kg_per_kg: float = field(default=0.0, metadata=_meta("kg/kg"))
    heating_value_btu_per_us_gal: float = field(default=0.0, metadata=_meta("BTU/gal"))


def _table_file() -> Path:
    return Path(str(resources.files("hevsim") / TABLE_PATH))


@functools.lru_cache(maxsize=1)
def _table() -> tuple[dict[str, Fuel], float]:
    import tomllib

    path = _table_file()
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    fuels: dict[str, Fuel] = {}
    for name, entry in data.get("fuels", {}).items():
        values: dict[str, Any] = {}
        for key in PROPERTIES:
            v = entry.get(key)
            zero_ok = key == "co2_kg_per_kg"  # a carbon-free fuel (hydrogen) emits none
            if isinstance(v, bool) or not isinstance(v, int | float) or not (v > 0 or (zero_ok and v == 0)):
                what = "a number >= 0" if zero_ok else "a positive number"
                raise InputError(f"{path}: key 'fuels.{name}.{key}' = {v!r}; expected {what}.")
            values[key] = float(v)
        fuels[name] = Fuel(name=name, description=str(entry.get("description", "")), **values)
    ref = data.get("mpgge", {}).get("reference_heating_value_btu_per_us_gal")
    if isinstance(ref, bool) or not isinstance(ref, int | float) or not ref > 0:
        key = "mpgge.reference_heating_value_btu_per_us_gal"
        raise InputError(f"{path}: key '{key}' = {ref!r}; expected a positive number.")
    return fuels, float(ref)


def fuel_names() -> tuple[str, ...]:
    """Names of the fuels in the table, sorted."""
    return tuple(sorted(_table()[0]))


def get_fuel(name: str, where: str = "fuel") -> Fuel:
    """The fuel called ``name``; ``where`` (file and key) prefixes the error if it is unknown."""
    fuels = _table()[0]
    if name not in fuels:
        valid = ", ".join(fuel_names())
        raise ConfigError(f"{where} = {name!r} is not a known fuel; expected one of {valid}.")
    return fuels[name]


def mpgge_reference_btu_per_us_gal() -> float:
    """Energy of the MPGGE gallon of gasoline equivalent, eq (19) [BTU/gal]."""
    return _table()[1]


def declared_fuel(meta: dict[str, Any], folder: str | Path) -> Fuel:
    """The fuel an engine folder's ``meta.toml`` declares (key ``fuel``)."""
    where = f"{Path(folder) / 'meta.toml'}: key 'fuel'"
    name = meta.get("fuel")
    if not isinstance(name, str):
        raise ConfigError(f"{where} = {name!r}; expected a fuel name, one of {', '.join(fuel_names())}.")
    return get_fuel(name, where)


def resolve(section: FuelSection, default: str, source: str) -> Fuel:
    """The fuel of a configuration: ``section.name`` or ``default``, then single-value overrides.

    ``source`` (the configuration's name or file) prefixes errors.
    """
    name = section.name or default
    fuel = get_fuel(name, f"{source}: key 'fuel.name'" if section.name else f"{source}: fuel")
    changes = {key: getattr(section, key) for key in PROPERTIES if getattr(section, key) != 0.0}
    for key, value in changes.items():
        if not (math.isfinite(value) and value > 0):
            raise ConfigError(
                f"{source}: key 'fuel.{key}' = {value!r}; expected a positive number (0 = the table's value)."
            )
    if not changes:
        return fuel
    return dataclasses.replace(fuel, overridden=tuple(changes), **changes)


def with_config_fuel(engine: Any, cfg: Any) -> Any:
    """``engine`` (an :class:`~hevsim.components.engine.Engine`) burning the fuel of the
    configuration ``cfg``: its ``[fuel]`` section, else the engine's declared fuel."""
    section = getattr(cfg, "fuel", None) or FuelSection()
    fuel = resolve(section, engine.fuel_name, str(getattr(cfg, "name", "configuration")))
    return dataclasses.replace(engine, **fuel.engine_kwargs())


def config_fuel(cfg: Any, engine: Any) -> Fuel:
    """The fuel a run of ``cfg`` counts: the engine's, or (no engine, e.g. an ideal genset) the
    ``[fuel]`` section's, else :data:`DEFAULT_FUEL`."""
    if engine is not None:
        return fuel_of_engine(engine)
    section = getattr(cfg, "fuel", None) or FuelSection()
    return resolve(section, DEFAULT_FUEL, str(getattr(cfg, "name", "configuration")))


def fuel_of_engine(engine: Any) -> Fuel:
    """The :class:`Fuel` an engine (or None: no engine, :data:`DEFAULT_FUEL`) burns, with the
    properties it actually carries (keys that differ from the table are listed as overridden)."""
    if engine is None:
        return get_fuel(DEFAULT_FUEL)
    fuel = get_fuel(engine.fuel_name, "engine fuel_name")
    values: dict[str, Any] = {key: float(getattr(engine, f)) for key, f in _ENGINE_FIELDS.items()}
    changed = tuple(key for key, v in values.items() if v != getattr(fuel, key))
    return dataclasses.replace(fuel, overridden=changed, **values) if changed else fuel

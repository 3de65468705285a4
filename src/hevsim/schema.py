"""Validation of TOML configurations into frozen dataclasses (shared by every architecture).

A configuration class is a dataclass whose fields are scalars (float, int, str), tuples of
scalars, or section dataclasses of such fields. Every key is checked: an unknown key, a
wrong type, a value outside ``bounds`` or not in ``choices`` raises :class:`ConfigError`
naming the file, the key, the value and what was expected.

A field states its own range next to it: ``field(metadata={"bounds": (lo, hi), "unit": "kg"})``
(or ``"choices": (...)``); the ``choices``/``bounds`` mappings by dotted key are the older
form, still accepted. Floats must be finite (``inf`` and ``nan`` are rejected) unless the
field's metadata says ``"allow_inf": True``. :func:`check_option` applies a field's range to a
command-line option, so options and files share one validation.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import tomllib
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from hevsim.errors import ConfigError
from hevsim.io import (
    cached_by_content,
    read_text_utf8,  # re-exported: the one UTF-8 reader lives in ground
)

T = TypeVar("T")
Choices = Mapping[str, tuple[str, ...]]
Bounds = Mapping[str, tuple[float, float]]


def _check_scalar(value: Any, tp: Any, where: str, allow_inf: bool = False) -> Any:
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where}: value {value!r} has the wrong type; expected a number.")
        if math.isnan(value):
            raise ConfigError(f"{where}: value nan is not a number; expected a number.")
        if math.isinf(value) and not allow_inf:
            raise ConfigError(f"{where}: value {value} is not finite; expected a finite number.")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: value {value!r} has the wrong type; expected an integer.")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: value {value!r} has the wrong type; expected a string.")
        return value
    raise ConfigError(f"{where}: unsupported type {tp}.")  # pragma: no cover


def _unit_text(unit: str) -> str:
    return f" {unit}" if unit and unit != "-" else ""


def check_value(
    value: Any, tp: Any, source: str, full: str, choices: Choices, bounds: Bounds,
    meta: Mapping[str, Any] | None = None, where: str | None = None,
) -> Any:  # fmt: skip
    """Check one value of type ``tp`` at dotted key ``full``; returns it converted.

    ``meta`` is the field's metadata (``bounds``, ``unit``, ``choices``, ``allow_inf``); it
    takes precedence over the ``choices``/``bounds`` mappings. ``where`` replaces the
    ``"<source>: key '<full>'"`` prefix of messages (e.g. ``"--soc-initial"``).
    """
    meta = meta or {}
    where = where or f"{source}: key '{full}'"
    allow_inf = bool(meta.get("allow_inf", False))
    if typing.get_origin(tp) is tuple:
        (item_tp, _) = typing.get_args(tp)
        if not isinstance(value, list | tuple) or not value:
            raise ConfigError(
                f"{where}: value {value!r} has the wrong type; expected a non-empty list of numbers."
            )
        out = tuple(_check_scalar(v, item_tp, f"{where}[{i}]", allow_inf) for i, v in enumerate(value))
        items: tuple[Any, ...] = out
    else:
        out = _check_scalar(value, tp, where, allow_inf)
        items = (out,)
    options = meta.get("choices", choices.get(full))
    if options is not None and out not in options:
        raise ConfigError(f"{where} = {value!r} is not a valid choice; expected one of {', '.join(options)}.")
    rng = meta.get("bounds", bounds.get(full))
    if rng is not None:
        lo, hi = rng
        unit = _unit_text(str(meta.get("unit", "")))
        for v in items:
            if not lo <= v <= hi:
                raise ConfigError(
                    f"{where} = {value!r} is out of range; expected a value between {lo:g} and {hi:g}{unit}."
                )
    return out


def field_of(cls: type, key: str) -> tuple[Any, Mapping[str, Any]]:
    """(type, metadata) of the field at dotted ``key`` of configuration class ``cls``."""
    tp: Any = cls
    meta: Mapping[str, Any] = {}
    for name in key.split("."):
        fields = {f.name: f for f in dataclasses.fields(tp)}
        if name not in fields:
            raise KeyError(key)
        f = fields[name]
        meta = f.metadata
        tp = type_hints(tp)[name]
    return tp, meta


def check_option(option: str, value: Any, cls: type, key: str) -> Any:
    """Validate a command-line ``option``'s value with the range of field ``key`` of ``cls``.

    Example: ``check_option("--soc-initial", 1.5, SimulationSection, "soc_initial")`` raises
    ConfigError("--soc-initial = 1.5 is out of range; expected a value between 0 and 1.").
    """
    if value is None:
        return None
    tp, meta = field_of(cls, key)
    return check_value(value, tp, "", key, {}, {}, meta, where=option)


def type_hints(cls: Any) -> dict[str, Any]:
    """``typing.get_type_hints(cls)``, once per class (batches validate thousands of variants)."""
    return _type_hints(cls)


@functools.cache
def _type_hints(cls: Any) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def build_section(cls: type[T], data: Any, source: str, section: str, choices: Choices, bounds: Bounds) -> T:
    """Validate the table ``[section]`` into the dataclass ``cls``."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: [{section}]: expected a table of keys, got {data!r}.")
    hints = type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        if key not in fields:
            raise ConfigError(
                f"{source}: key '{section}.{key}' is not known; valid keys in [{section}] are: "
                f"{', '.join(fields)}."
            )
        kwargs[key] = check_value(
            value, hints[key], source, f"{section}.{key}", choices, bounds, fields[key].metadata
        )
    return cls(**kwargs)


def build_config(
    cls: type[T], data: Mapping[str, Any], source: str, base_dir: Path | None, choices: Choices,
    bounds: Bounds,
) -> T:  # fmt: skip
    """Validate a parsed configuration mapping into ``cls`` (which has a ``base_dir`` field)."""
    hints = type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    valid = [n for n in fields if n != "base_dir"]
    kwargs: dict[str, Any] = {"base_dir": str(base_dir or Path("."))}
    for key, value in data.items():
        if key not in valid:
            raise ConfigError(
                f"{source}: key '{key}' is not known; valid top-level keys are: {', '.join(valid)}."
            )
        tp = hints[key]
        if isinstance(tp, type) and dataclasses.is_dataclass(tp):
            kwargs[key] = build_section(tp, value, source, key, choices, bounds)
        else:
            kwargs[key] = check_value(value, tp, source, key, choices, bounds, fields[key].metadata)
    return cls(**kwargs)


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML configuration file (UTF-8, :func:`read_text_utf8`); ``name`` defaults to
    the file's stem. Parsed once per file content (:func:`hevsim.io.cached_by_content`): the
    dictionary returned is the caller's own (deep) copy."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: configuration file not found; expected a TOML file.")
    return copy.deepcopy(cached_by_content(p, _parse_toml))


def _parse_toml(p: Path) -> dict[str, Any]:
    """:func:`read_toml`'s parser."""
    try:
        data = tomllib.loads(read_text_utf8(p))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML ({exc}).") from exc
    data.setdefault("name", p.stem)
    return data


def to_dict(cfg: Any) -> dict[str, Any]:
    """Plain dict of every value of a configuration (tuples as lists), without ``base_dir``."""

    def plain(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        if isinstance(v, tuple):
            return [plain(x) for x in v]
        return v

    d = plain(dataclasses.asdict(cfg))
    d.pop("base_dir", None)
    return d


def with_changes(data: dict[str, Any], changes: Mapping[str, Any]) -> dict[str, Any]:
    """Apply dotted-key overrides (``{"body.mass_kg": 1500.0}``) to a configuration dict."""
    for key, value in changes.items():
        section, _, name = key.partition(".")
        if name:
            data.setdefault(section, {})[name] = value
        else:
            data[section] = value
    return data

"""Units on co-simulation connections: declared units -> affine conversion (factor, offset).

A unit is a base-dimension exponent vector (kg, m, s, A, K, mol, cd, rad), a factor and an
offset so that ``value_SI = factor * value + offset`` (the FMI / SSP ``BaseUnit`` convention).
Configurations can declare more units (SSP ``ssc:Unit``, the thesis CSE ``UnitDefinitions``).
"""

from __future__ import annotations

from dataclasses import dataclass

from hevsim.errors import ConfigError

BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


@dataclass(frozen=True)
class Unit:
    """A unit: ``exponents`` over :data:`BASE`, ``value_SI = factor * value + offset``."""

    name: str
    exponents: tuple[int, ...]
    factor: float = 1.0
    offset: float = 0.0


def _u(name: str, factor: float = 1.0, offset: float = 0.0, **exp: int) -> Unit:
    return Unit(name, tuple(int(exp.get(b, 0)) for b in BASE), factor, offset)


KCAL_J = 4186.8
"""International-table kilocalorie [J] (the thesis's kcal/kg definition, appendix 3)."""

BUILTIN: dict[str, Unit] = {
    u.name: u
    for u in (
        _u(""),
        _u("1"),
        _u("-"),
        _u("s", s=1),
        _u("min", 60.0, s=1),
        _u("h", 3600.0, s=1),
        _u("K", K=1),
        _u("degC", 1.0, 273.15, K=1),
        _u("degF", 5.0 / 9.0, 273.15 - 32.0 * 5.0 / 9.0, K=1),
        _u("W", kg=1, m=2, s=-3),
        _u("kW", 1e3, kg=1, m=2, s=-3),
        _u("J", kg=1, m=2, s=-2),
        _u("kJ", 1e3, kg=1, m=2, s=-2),
        _u("kcal", KCAL_J, kg=1, m=2, s=-2),
        _u("Wh", 3600.0, kg=1, m=2, s=-2),
        _u("J/kg", m=2, s=-2),
        _u("kcal/kg", KCAL_J, m=2, s=-2),
        _u("W/m2", kg=1, s=-3),
        _u("W/m3", kg=1, m=-1, s=-3),
        _u("W/(m2.K)", kg=1, s=-3, K=-1),
        _u("W/K", kg=1, m=2, s=-3, K=-1),
        _u("J/K", kg=1, m=2, s=-2, K=-1),
        _u("V", kg=1, m=2, s=-3, A=-1),
        _u("A", A=1),
        _u("Ohm", kg=1, m=2, s=-3, A=-2),
        _u("C", s=1, A=1),
        _u("Ah", 3600.0, s=1, A=1),
        _u("m", m=1),
        _u("m2", m=2),
        _u("m3", m=3),
        _u("kg", kg=1),
        _u("kg/s", kg=1, s=-1),
        _u("N", kg=1, m=1, s=-2),
        _u("Pa", kg=1, m=-1, s=-2),
        _u("bar", 1e5, kg=1, m=-1, s=-2),
        _u("m/s", m=1, s=-1),
        _u("rad/s", s=-1, rad=1),
        _u("rpm", 2.0 * 3.141592653589793 / 60.0, s=-1, rad=1),
    )
}


def unit_from_base(name: str, attrs: dict[str, str]) -> Unit:
    """A :class:`Unit` from an FMI/SSP/CSE ``BaseUnit`` element's attributes."""
    try:
        exp = {b: int(float(attrs.get(b, "0"))) for b in BASE}
        return _u(name, float(attrs.get("factor", "1")), float(attrs.get("offset", "0")), **exp)
    except ValueError as exc:
        raise ConfigError(f"unit {name!r}: BaseUnit attributes {attrs} are not numbers.") from exc


def lookup(name: str | None, extra: dict[str, Unit] | None = None) -> Unit:
    """The unit called ``name`` (None or "" is dimensionless); ``extra`` units take precedence."""
    name = name or ""
    if extra and name in extra:
        return extra[name]
    if name in BUILTIN:
        return BUILTIN[name]
    known = sorted(set(BUILTIN) | set(extra or {}))
    raise ConfigError(f"unknown unit {name!r}; known units: {', '.join(k for k in known if k)}.")


def conversion(
    src: str | None, dst: str | None, extra: dict[str, Unit] | None = None, what: str = ""
) -> tuple[float, float]:
    """``(factor, offset)`` with ``value_dst = factor * value_src + offset``.

    An undeclared unit (None or "") on either side means no conversion (FMI: unit unknown).
    Raises :class:`ConfigError` naming ``what`` when the dimensions differ.
    """
    if not src or not dst:
        return 1.0, 0.0
    a, b = lookup(src, extra), lookup(dst, extra)
    if a.exponents != b.exponents:
        raise ConfigError(
            f"{what or 'connection'}: incompatible units {a.name or '1'!r} -> {b.name or '1'!r} "
            f"(dimensions {_dims(a)} vs {_dims(b)})."
        )
    # SI = fa*x + oa ; y = (SI - ob)/fb
    return a.factor / b.factor, (a.offset - b.offset) / b.factor


def _dims(u: Unit) -> str:
    parts = [f"{b}^{e}" for b, e in zip(BASE, u.exponents, strict=True) if e]
    return "·".join(parts) or "1"

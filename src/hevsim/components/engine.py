"""Internal-combustion engine from measured maps (thesis section 2.4, tutorial lectures 6-7).

Torque comes from a map over speed and throttle, or from the max-torque curve times the
throttle (throttle = normalised torque request). Fuel rate comes from a map over speed and
torque. No fuel flows at zero throttle, below the minimum running (stall) speed or above the
redline (fuel cut); the unfired engine then drags with its closed-throttle (friction) torque.
An engine without a fuel map is *ideal*: its fuel power equals its brake power (used by the
early refinement levels of the tutorial, where the engine is a constant-torque source).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numba import njit

from hevsim.fuels import declared_fuel
from hevsim.tables import FloatArray, Table1D, Table2D, interp1, interp2, read_meta
from hevsim.units import rpm_to_radps

DIESEL_HEATING_VALUE_BTU_PER_GAL = 133393.1102
"""Heating value of B-20 diesel used by the tutorial (lecture 7) and eq (17) [BTU/gal]."""
DIESEL_CO2_KG_PER_KG = 3.16
"""CO2 emitted per kg of diesel burnt (carbon fraction 0.862, complete combustion) [kg/kg]."""


class EngineTables(NamedTuple):
    """An engine's tables for compiled code, by name (a swapped array is a name error).

    ``tmax_y`` max torque and ``tct_y`` closed-throttle torque [N·m] over the speed axes
    ``tmax_x``, ``tct_x`` [rad/s]; ``tmap_z`` torque [N·m] over ``tmap_x`` speed [rad/s] x
    ``tmap_y`` throttle [-]; ``fuel_z`` fuel rate [kg/s] over ``fuel_x`` speed [rad/s] x
    ``fuel_y`` torque [N·m]; all of the unscaled (``torque_scale`` = 1) engine.
    """

    tmax_x: FloatArray
    tmax_y: FloatArray
    tct_x: FloatArray
    tct_y: FloatArray
    tmap_x: FloatArray
    tmap_y: FloatArray
    tmap_z: FloatArray
    fuel_x: FloatArray
    fuel_y: FloatArray
    fuel_z: FloatArray


@njit(cache=True, inline="always")
def torque_from_maps(
    throttle, omega_radps, use_tmap, stall_radps, redline_radps, torque_scale, tmax_x, tmax_y,
    tct_x, tct_y, tmap_x, tmap_y, tmap_z,
):  # fmt: skip
    """Brake torque [N·m] at throttle [0-1] and speed [rad/s] (scalar kernel).

    Fired (throttle > 0, stall <= speed <= redline): the torque map at (speed, throttle), or
    throttle x max-torque curve. Unfired: the closed-throttle torque (<= 0) while turning.
    Arrays as in :class:`EngineTables` (compiled loops unpack the tables once).
    """
    fired = throttle > 0.0 and omega_radps >= stall_radps and omega_radps <= redline_radps
    if fired:
        if use_tmap:
            return torque_scale * interp2(tmap_x, tmap_y, tmap_z, omega_radps, throttle, False)
        return torque_scale * throttle * interp1(tmax_x, tmax_y, omega_radps, False)
    if omega_radps > 0.0:
        return torque_scale * interp1(tct_x, tct_y, omega_radps, False)
    return 0.0


@njit(cache=True, inline="always")
def fuel_from_map(
    torque_nm, omega_radps, fired, use_fuel_map, lhv_jpkg, torque_scale, fuel_x, fuel_y, fuel_z
):
    """Fuel mass rate [kg/s] at brake torque [N·m] and speed [rad/s] (scalar kernel).

    Zero when not fired. With a fuel map the map is read at (speed, torque / torque_scale) and
    scaled (the engine's torque axis and fuel flow scale together); an ideal engine burns
    exactly its brake power.
    """
    if not fired or (torque_nm <= 0.0 and not use_fuel_map):
        return 0.0
    if use_fuel_map:
        rate = torque_scale * interp2(fuel_x, fuel_y, fuel_z, omega_radps, torque_nm / torque_scale, False)
        return max(rate, 0.0)
    return torque_nm * omega_radps / lhv_jpkg


@njit(cache=True, inline="always")
def max_torque_from_curve(omega_radps, torque_scale, tmax_x, tmax_y):
    """Max brake torque [N·m] of the (scaled) engine at speed [rad/s] (scalar kernel)."""
    return torque_scale * interp1(tmax_x, tmax_y, omega_radps, False)


@njit(cache=True, inline="always")
def fired_fuel_from_maps(
    torque_nm, omega_radps, use_fuel_map, lhv_jpkg, stall_radps, redline_radps, torque_scale,
    tmax_x, tmax_y, fuel_x, fuel_y, fuel_z,
):  # fmt: skip
    """:func:`fuel_from_map` of a fired engine [kg/s]; NaN outside stall..redline or above
    the max-torque curve (an infeasible operating point)."""
    tmax = max_torque_from_curve(omega_radps, torque_scale, tmax_x, tmax_y)
    if omega_radps < stall_radps or omega_radps > redline_radps or torque_nm > tmax * (1 + 1e-9):
        return np.nan
    return fuel_from_map(
        torque_nm, omega_radps, True, use_fuel_map, lhv_jpkg, torque_scale, fuel_x, fuel_y, fuel_z
    )


# The same kernels reading an :class:`EngineTables` by name (per-step code); loops over many
# points unpack the tables once (passing the tuple costs reference counting per call).
@njit(cache=True, inline="always")
def engine_torque(throttle, omega_radps, use_tmap, stall_radps, redline_radps, torque_scale, tab):
    """:func:`torque_from_maps` with the engine's :class:`EngineTables`."""
    return torque_from_maps(
        throttle, omega_radps, use_tmap, stall_radps, redline_radps, torque_scale, tmax_x=tab.tmax_x,
        tmax_y=tab.tmax_y, tct_x=tab.tct_x, tct_y=tab.tct_y, tmap_x=tab.tmap_x, tmap_y=tab.tmap_y,
        tmap_z=tab.tmap_z,
    )  # fmt: skip


@njit(cache=True, inline="always")
def engine_fuel_rate(torque_nm, omega_radps, fired, use_fuel_map, lhv_jpkg, torque_scale, tab):
    """:func:`fuel_from_map` with the engine's :class:`EngineTables`."""
    return fuel_from_map(
        torque_nm, omega_radps, fired, use_fuel_map, lhv_jpkg, torque_scale, fuel_x=tab.fuel_x,
        fuel_y=tab.fuel_y, fuel_z=tab.fuel_z,
    )  # fmt: skip


@njit(cache=True)
def engine_max_torque(omega_radps, torque_scale, tab):
    """:func:`max_torque_from_curve` with the engine's :class:`EngineTables`."""
    return max_torque_from_curve(omega_radps, torque_scale, tmax_x=tab.tmax_x, tmax_y=tab.tmax_y)


@njit(cache=True)
def fired_fuel_rate(
    torque_nm, omega_radps, use_fuel_map, lhv_jpkg, stall_radps, redline_radps, torque_scale, tab
):  # fmt: skip
    """:func:`fired_fuel_from_maps` with the engine's :class:`EngineTables`."""
    return fired_fuel_from_maps(
        torque_nm, omega_radps, use_fuel_map, lhv_jpkg, stall_radps, redline_radps, torque_scale,
        tmax_x=tab.tmax_x, tmax_y=tab.tmax_y, fuel_x=tab.fuel_x, fuel_y=tab.fuel_y, fuel_z=tab.fuel_z,
    )  # fmt: skip


@njit(cache=True)
def _engine_torque_many(throttle, omega_radps, use_tmap, stall_radps, redline_radps, torque_scale, tab):
    """:func:`torque_from_maps` over flat arrays of throttle [-] and speed [rad/s] -> [N·m]."""
    tmax_x, tmax_y, tct_x, tct_y = tab.tmax_x, tab.tmax_y, tab.tct_x, tab.tct_y
    tmap_x, tmap_y, tmap_z = tab.tmap_x, tab.tmap_y, tab.tmap_z
    out = np.empty(throttle.shape[0])
    for i in range(throttle.shape[0]):
        out[i] = torque_from_maps(
            throttle[i], omega_radps[i], use_tmap, stall_radps, redline_radps, torque_scale, tmax_x,
            tmax_y, tct_x, tct_y, tmap_x, tmap_y, tmap_z,
        )  # fmt: skip
    return out


@njit(cache=True)
def _fired_fuel_rate_many(
    torque_nm, omega_radps, use_fuel_map, lhv_jpkg, stall_radps, redline_radps, torque_scale, tab
):  # fmt: skip
    """:func:`fired_fuel_from_maps` over flat arrays of torque [N·m] and speed [rad/s]."""
    tmax_x, tmax_y, fuel_x, fuel_y, fuel_z = tab.tmax_x, tab.tmax_y, tab.fuel_x, tab.fuel_y, tab.fuel_z
    out = np.empty(torque_nm.shape[0])
    for i in range(torque_nm.shape[0]):
        out[i] = fired_fuel_from_maps(
            torque_nm[i], omega_radps[i], use_fuel_map, lhv_jpkg, stall_radps, redline_radps,
            torque_scale, tmax_x, tmax_y, fuel_x, fuel_y, fuel_z,
        )  # fmt: skip
    return out


@njit(cache=True)
def _fuel_map_rate_many(torque_nm, omega_radps, torque_scale, tab):
    """:func:`fuel_from_map` of a fired engine with a fuel map, no limits -> [kg/s]."""
    fuel_x, fuel_y, fuel_z = tab.fuel_x, tab.fuel_y, tab.fuel_z
    out = np.empty(torque_nm.shape[0])
    for i in range(torque_nm.shape[0]):
        out[i] = fuel_from_map(
            torque_nm[i], omega_radps[i], True, True, 1.0, torque_scale, fuel_x, fuel_y, fuel_z
        )
    return out


@njit(cache=True)
def _max_torque_many(omega_radps, torque_scale, tab):
    """:func:`max_torque_from_curve` over a flat array of speed [rad/s] -> [N·m]."""
    tmax_x, tmax_y = tab.tmax_x, tab.tmax_y
    out = np.empty(omega_radps.shape[0])
    for i in range(omega_radps.shape[0]):
        out[i] = max_torque_from_curve(omega_radps[i], torque_scale, tmax_x, tmax_y)
    return out


def scaled_fuel_map_rate(fuel_map: Table2D, torque_scale: float, torque_nm, omega_radps):
    """Fuel rate [kg/s] of a fired engine sized by ``torque_scale`` from its unscaled
    ``fuel_map`` [kg/s over rad/s x N·m], at broadcast torque [N·m] and speed [rad/s]
    (:func:`engine_fuel_rate`, without the engine's speed and torque limits)."""
    z1 = np.zeros(1)
    tab = EngineTables(z1, z1, z1, z1, z1, z1, np.zeros((1, 1)), fuel_map.x, fuel_map.y, fuel_map.z)
    shape, (t, w) = _flat(torque_nm, omega_radps)
    return _fuel_map_rate_many(t, w, float(torque_scale), tab).reshape(shape)


def scaled_max_torque(max_torque: Table1D, torque_scale: float, omega_radps):
    """Max brake torque [N·m] of an engine sized by ``torque_scale`` from its unscaled
    ``max_torque`` curve [N·m over rad/s], at speeds [rad/s] of any shape
    (:func:`max_torque_from_curve`, the kernel :meth:`Engine.max_torque_nm` uses)."""
    shape, (w,) = _flat(omega_radps)
    return _max_torque_many(w, float(torque_scale), _curve_tables(max_torque)).reshape(shape)


def _curve_tables(max_torque: Table1D) -> EngineTables:
    """An :class:`EngineTables` holding only a max-torque curve (the other tables dummies)."""
    z1 = np.zeros(1)
    z2 = np.zeros((1, 1))
    return EngineTables(
        tmax_x=max_torque.x, tmax_y=max_torque.y, tct_x=z1, tct_y=z1, tmap_x=z1, tmap_y=z1, tmap_z=z2,
        fuel_x=z1, fuel_y=z1, fuel_z=z2,
    )  # fmt: skip


def _flat(*arrays: object) -> tuple[tuple[int, ...], list[FloatArray]]:
    """Broadcast arrays, return the shape and contiguous flat float64 copies."""
    b = np.broadcast_arrays(*(np.asarray(a, np.float64) for a in arrays))
    return b[0].shape, [np.ascontiguousarray(x.ravel()) for x in b]


@dataclass(frozen=True, eq=False)
class Engine:
    """Engine parameters and maps (SI).

    Attributes:
        max_torque: max brake torque [N·m] vs speed [rad/s].
        closed_throttle_torque: unfired drag torque (<= 0) [N·m] vs speed [rad/s].
        fuel_map: fuel rate [kg/s] over speed [rad/s] x torque [N·m]; None = ideal engine.
        torque_map: optional brake torque [N·m] over speed [rad/s] x throttle [-].
        inertia_kgm2: rotating inertia [kg·m^2].
        stall_speed_radps: minimum running speed [rad/s]; redline_radps: fuel cut [rad/s].
        fuel_lhv_jpkg [J/kg], fuel_density_kgpm3 [kg/m^3], heating_value_btu_per_gal [BTU/gal],
        co2_kg_per_kg [kg/kg]: properties of the fuel ``fuel_name`` (from :mod:`hevsim.fuels`;
        the defaults equal the table's diesel, which the builders pass explicitly);
        torque_scale [-] scales torque and fuel (engine sizing).
    """

    name: str
    max_torque: Table1D
    closed_throttle_torque: Table1D
    fuel_map: Table2D | None = None
    torque_map: Table2D | None = None
    inertia_kgm2: float = 0.12
    stall_speed_radps: float = rpm_to_radps(750.0)
    redline_radps: float = rpm_to_radps(4500.0)
    fuel_lhv_jpkg: float = 42.937e6
    fuel_density_kgpm3: float = 843.0
    heating_value_btu_per_gal: float = DIESEL_HEATING_VALUE_BTU_PER_GAL
    co2_kg_per_kg: float = DIESEL_CO2_KG_PER_KG
    torque_scale: float = 1.0
    fuel_name: str = "diesel"

    def kernel_tables(self) -> EngineTables:
        """The engine's tables for compiled code (:class:`EngineTables`; built once)."""
        return self._tables

    @cached_property
    def _tables(self) -> EngineTables:
        dummy2 = Table2D(np.array([0.0]), np.array([0.0]), np.zeros((1, 1)))
        tmap = self.torque_map or dummy2
        fuel = self.fuel_map or dummy2
        return EngineTables(
            tmax_x=self.max_torque.x, tmax_y=self.max_torque.y,
            tct_x=self.closed_throttle_torque.x, tct_y=self.closed_throttle_torque.y,
            tmap_x=tmap.x, tmap_y=tmap.y, tmap_z=tmap.z, fuel_x=fuel.x, fuel_y=fuel.y, fuel_z=fuel.z,
        )  # fmt: skip

    def torque(self, throttle, omega_radps):
        """Vectorised brake torque [N·m] at throttle [-] and speed [rad/s]."""
        shape, (thr, w) = _flat(throttle, omega_radps)
        out = _engine_torque_many(
            thr, w, self.torque_map is not None, self.stall_speed_radps, self.redline_radps,
            self.torque_scale, self.kernel_tables(),
        )  # fmt: skip
        return out.reshape(shape)

    def max_torque_nm(self, omega_radps):
        """Vectorised max brake torque [N·m] of the (scaled) engine at speed [rad/s]."""
        shape, (w,) = _flat(omega_radps)
        return _max_torque_many(w, self.torque_scale, self.kernel_tables()).reshape(shape)

    def fuel_rate(self, torque_nm, omega_radps):
        """Vectorised fuel rate [kg/s] of a fired engine at torque [N·m] and speed [rad/s].

        Operating points outside stall..redline or with torque above the max-torque curve
        return NaN, so callers (DP) can mark them infeasible.
        """
        shape, (t, w) = _flat(torque_nm, omega_radps)
        out = _fired_fuel_rate_many(
            t, w, self.fuel_map is not None, self.fuel_lhv_jpkg, self.stall_speed_radps,
            self.redline_radps, self.torque_scale, self.kernel_tables(),
        )  # fmt: skip
        return out.reshape(shape)

    def fuel_map_rate(self, torque_nm, omega_radps):
        """Vectorised fuel rate [kg/s] read from the (scaled) fuel map at torque [N·m] and
        speed [rad/s], without the engine's speed and torque limits (maps, plots)."""
        if self.fuel_map is None:
            raise ValueError(f"engine '{self.name}' has no fuel map")
        return scaled_fuel_map_rate(self.fuel_map, self.torque_scale, torque_nm, omega_radps)

    @classmethod
    def from_directory(cls, path: str | Path, **overrides: float) -> Engine:
        """Load a shipped-format engine folder (meta.toml + CSV maps, see data/PROVENANCE.md)."""
        d = Path(path)
        meta = read_meta(d, "engine")
        params = meta.get("parameters", {})
        max_torque = Table1D.from_csv(d / "max_torque.csv", "speed_rad_per_s", "max_torque_N_m")
        ct_path = d / "closed_throttle_torque.csv"
        closed = (
            Table1D.from_csv(ct_path, "speed_rad_per_s", "closed_throttle_torque_N_m")
            if ct_path.is_file()
            else Table1D(max_torque.x, np.zeros_like(max_torque.x), source=str(d))
        )
        fuel = Table2D.from_long_csv(
            d / "fuel_rate_map.csv", "speed_rad_per_s", "torque_N_m", "fuel_rate_g_per_s",
            scale=1e-3,
        )  # fmt: skip
        kwargs: dict[str, object] = {
            "name": str(meta.get("name", d.name)),
            "max_torque": max_torque,
            "closed_throttle_torque": closed,
            "fuel_map": fuel,
            "stall_speed_radps": float(max_torque.x[0]) * 0.9,
            "redline_radps": float(max_torque.x[-1]),
        }
        if "rotational_inertia_kg_m2" in params:
            kwargs["inertia_kgm2"] = float(params["rotational_inertia_kg_m2"])
        kwargs.update(declared_fuel(meta, d).engine_kwargs())  # meta.toml `fuel`, hevsim/data/fuels.toml
        kwargs.update(overrides)
        return cls(**kwargs)  # type: ignore[arg-type]

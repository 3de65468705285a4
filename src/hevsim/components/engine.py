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
from pathlib import Path

import numpy as np
from numba import njit

from hevsim.fuels import declared_fuel
from hevsim.tables import FloatArray, Table1D, Table2D, interp1, interp2, read_meta
from hevsim.units import rpm_to_radps

DIESEL_HEATING_VALUE_BTU_PER_GAL = 133393.1102
"""Heating value of B-20 diesel used by the tutorial (lecture 7) and eq (17) [BTU/gal]."""
DIESEL_CO2_KG_PER_KG = 3.16
"""CO2 emitted per kg of diesel burnt (carbon fraction 0.862, complete combustion) [kg/kg]."""


@njit(cache=True)
def engine_torque(
    throttle, omega_radps, tmax_x, tmax_y, tct_x, tct_y, tmap_x, tmap_y, tmap_z, use_tmap,
    stall_radps, redline_radps, torque_scale,
):  # fmt: skip
    """Brake torque [N·m] at throttle [0-1] and speed [rad/s] (scalar kernel).

    Fired (throttle > 0, stall <= speed <= redline): the torque map at (speed, throttle), or
    throttle x max-torque curve. Unfired: the closed-throttle torque (<= 0) while turning.
    """
    fired = throttle > 0.0 and omega_radps >= stall_radps and omega_radps <= redline_radps
    if fired:
        if use_tmap:
            return torque_scale * interp2(tmap_x, tmap_y, tmap_z, omega_radps, throttle, False)
        return torque_scale * throttle * interp1(tmax_x, tmax_y, omega_radps, False)
    if omega_radps > 0.0:
        return torque_scale * interp1(tct_x, tct_y, omega_radps, False)
    return 0.0


@njit(cache=True)
def _engine_torque_many(
    throttle, omega_radps, tmax_x, tmax_y, tct_x, tct_y, tmap_x, tmap_y, tmap_z, use_tmap,
    stall_radps, redline_radps, torque_scale,
):  # fmt: skip
    """:func:`engine_torque` over flat arrays of throttle [-] and speed [rad/s] -> [N·m]."""
    out = np.empty(throttle.shape[0])
    for i in range(throttle.shape[0]):
        out[i] = engine_torque(
            throttle[i], omega_radps[i], tmax_x, tmax_y, tct_x, tct_y, tmap_x, tmap_y, tmap_z,
            use_tmap, stall_radps, redline_radps, torque_scale,
        )  # fmt: skip
    return out


@njit(cache=True)
def engine_fuel_rate(
    torque_nm, omega_radps, fired, fuel_x, fuel_y, fuel_z, use_fuel_map, lhv_jpkg, torque_scale
):  # fmt: skip
    """Fuel mass rate [kg/s] at brake torque [N·m] and speed [rad/s] (scalar kernel).

    Zero when not fired. With a fuel map the map is read at (speed, torque / torque_scale) and
    scaled; an ideal engine burns exactly its brake power.
    """
    if not fired or (torque_nm <= 0.0 and not use_fuel_map):
        return 0.0
    if use_fuel_map:
        rate = torque_scale * interp2(fuel_x, fuel_y, fuel_z, omega_radps, torque_nm / torque_scale, False)
        return max(rate, 0.0)
    return torque_nm * omega_radps / lhv_jpkg


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

    def kernel_tables(self) -> tuple[FloatArray, ...]:
        """Arrays for compiled loops: (tmax_x, tmax_y, tct_x, tct_y, tmap_x, tmap_y, tmap_z,
        fuel_x, fuel_y, fuel_z)."""
        dummy2 = Table2D(np.array([0.0]), np.array([0.0]), np.zeros((1, 1)))
        tmap = self.torque_map or dummy2
        fuel = self.fuel_map or dummy2
        return (
            self.max_torque.x, self.max_torque.y,
            self.closed_throttle_torque.x, self.closed_throttle_torque.y,
            tmap.x, tmap.y, tmap.z, fuel.x, fuel.y, fuel.z,
        )  # fmt: skip

    def torque(self, throttle, omega_radps):
        """Vectorised brake torque [N·m] at throttle [-] and speed [rad/s]."""
        t = self.kernel_tables()
        thr, w = np.broadcast_arrays(np.asarray(throttle, float), np.asarray(omega_radps, float))
        out = _engine_torque_many(
            np.ascontiguousarray(thr.ravel()), np.ascontiguousarray(w.ravel()),
            t[0], t[1], t[2], t[3], t[4], t[5], t[6], self.torque_map is not None,
            self.stall_speed_radps, self.redline_radps, self.torque_scale,
        )  # fmt: skip
        return out.reshape(thr.shape)

    def fuel_rate(self, torque_nm, omega_radps):
        """Vectorised fuel rate [kg/s] of a fired engine at torque [N·m] and speed [rad/s].

        Operating points outside stall..redline or with torque above the max-torque curve
        return NaN, so callers (DP) can mark them infeasible.
        """
        torque, w = np.broadcast_arrays(np.asarray(torque_nm, float), np.asarray(omega_radps, float))
        if self.fuel_map is None:
            rate = np.maximum(torque * w, 0.0) / self.fuel_lhv_jpkg
        else:
            rate = self.torque_scale * np.maximum(self.fuel_map(w, torque / self.torque_scale), 0.0)
        tmax = self.torque_scale * self.max_torque(w)
        bad = (w < self.stall_speed_radps) | (w > self.redline_radps) | (torque > tmax * (1 + 1e-9))
        return np.where(bad, np.nan, rate)

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

"""Material properties of the module parts (thesis Table 4.3) and their lookup by part."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hevsim.errors import ConfigError

#: a property table: rows (temperature [K], value) by increasing temperature; empty: constant
Table = tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class Material:
    """Isotropic solid: conductivity [W/(m K)], density [kg/m^3], specific heat [J/(kg K)].

    A property may depend on temperature: ``conductivity_table`` / ``density_table`` /
    ``specific_heat_table`` hold rows (temperature [K], value), linear between rows and
    constant beyond the first and last (as Abaqus interpolates material tables); the scalar
    is then the first row's value. Only
    :class:`~hevsim.thermal.solver.NonlinearHeatModel` uses the tables; the linear solver
    refuses such a material (:attr:`temperature_dependent`).
    """

    name: str
    conductivity_w_mk: float
    density_kg_m3: float
    specific_heat_j_kgk: float
    conductivity_table: Table = ()
    density_table: Table = ()
    specific_heat_table: Table = ()

    def check(self, where: str) -> Material:
        """Raise :class:`ConfigError` unless every property is finite and positive (and every
        table has increasing finite temperatures [K] and finite positive values)."""
        for key in ("conductivity_w_mk", "density_kg_m3", "specific_heat_j_kgk"):
            v = getattr(self, key)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0.0):
                raise ConfigError(
                    f"{where}: material '{self.name}' key '{key}' = {v!r} is not physical; "
                    "expected a finite positive number."
                )
        for key in ("conductivity_table", "density_table", "specific_heat_table"):
            rows = np.asarray(getattr(self, key), dtype=float).reshape(-1, 2)
            t, v = rows[:, 0], rows[:, 1]
            if not (np.all(np.isfinite(rows)) and np.all(v > 0.0) and np.all(np.diff(t) > 0.0)):
                raise ConfigError(
                    f"{where}: material '{self.name}' {key} {rows.tolist()} is not valid; expected "
                    "rows (temperature [K], value > 0) by strictly increasing temperature."
                )
        return self

    @property
    def temperature_dependent(self) -> bool:
        """True when a property has a table (of more than one row)."""
        return any(
            len(t) > 1 for t in (self.conductivity_table, self.density_table, self.specific_heat_table)
        )

    @staticmethod
    def _at(table: Table, constant: float, temp_k: np.ndarray) -> np.ndarray:
        t = np.asarray(temp_k, dtype=float)
        if len(table) < 2:
            return np.full(t.shape, float(table[0][1]) if table else constant)
        rows = np.asarray(table, dtype=float)
        return np.interp(t, rows[:, 0], rows[:, 1])

    def conductivity_at(self, temp_k: np.ndarray) -> np.ndarray:
        """Conductivity [W/(m K)] at ``temp_k`` [K]."""
        return self._at(self.conductivity_table, self.conductivity_w_mk, temp_k)

    def heat_capacity_at(self, temp_k: np.ndarray) -> np.ndarray:
        """rho(T) c_p(T) [J/(m^3 K)] at ``temp_k`` [K]."""
        return self._at(self.density_table, self.density_kg_m3, temp_k) * self._at(
            self.specific_heat_table, self.specific_heat_j_kgk, temp_k
        )

    def enthalpy_j_m3(self, temp_k: np.ndarray) -> np.ndarray:
        """Volumetric enthalpy [J/m^3]: the integral of rho(T) c_p(T) from the lowest table
        temperature (0 K without tables) to ``temp_k`` [K]. Exact: rho c_p is quadratic between
        the union of the tables' temperatures, and Simpson's rule integrates it exactly."""
        t = np.asarray(temp_k, dtype=float)
        knots = np.unique([r[0] for r in (*self.density_table, *self.specific_heat_table)])
        if knots.size == 0:
            knots = np.zeros(1)
        g = self.heat_capacity_at

        def simpson(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return (b - a) / 6.0 * (g(a) + 4.0 * g(0.5 * (a + b)) + g(b))

        cum = np.concatenate([[0.0], np.cumsum(simpson(knots[:-1], knots[1:]))])
        i = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, knots.size - 1)
        return cum[i] + simpson(knots[i], t)

    @property
    def volumetric_heat_capacity_j_m3k(self) -> float:
        """rho * c_p [J/(m^3 K)]."""
        return self.density_kg_m3 * self.specific_heat_j_kgk


#: Thesis Table 4.3 (also the *Material blocks of Standard.inp, appendix 3).
TABLE_4_3: dict[str, Material] = {
    "aluminium": Material("aluminium", 167.0, 2700.0, 902.0),  # cooling plate
    "plastic": Material("plastic", 0.2, 2000.0, 1800.0),  # cover, housing, cell, clips, BMS cover
    "copper": Material("copper", 400.0, 8960.0, 385.0),  # connecting plate
    "silicon": Material("silicon", 149.0, 2329.0, 700.0),  # BMS circuit
}

#: Default material of each part of the parametric module (Table 4.3 row assignment).
DEFAULT_PART_MATERIALS: dict[str, str] = {
    "plate": "aluminium",
    "holder": "plastic",
    "cells": "plastic",
    "housing": "plastic",
    "cover": "plastic",
    "connector": "copper",
    "bms": "silicon",
}

#: Gap conductance at zero clearance [W/(m^2 K)] (Standard.inp *Gap Conductance, 20000 at 0 mm).
GAP_CONDUCTANCE_W_M2K = 20000.0
#: Film coefficient on the external surfaces [W/(m^2 K)] (thesis section 4.1.2).
FILM_COEFFICIENT_W_M2K = 0.01

"""Material properties of the module parts (thesis Table 4.3) and their lookup by part."""

from __future__ import annotations

import math
from dataclasses import dataclass

from hevsim.errors import ConfigError


@dataclass(frozen=True)
class Material:
    """Isotropic solid: conductivity [W/(m K)], density [kg/m^3], specific heat [J/(kg K)]."""

    name: str
    conductivity_w_mk: float
    density_kg_m3: float
    specific_heat_j_kgk: float

    def check(self, where: str) -> Material:
        """Raise :class:`ConfigError` unless every property is finite and positive."""
        for key in ("conductivity_w_mk", "density_kg_m3", "specific_heat_j_kgk"):
            v = getattr(self, key)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0.0):
                raise ConfigError(
                    f"{where}: material '{self.name}' key '{key}' = {v!r} is not physical; "
                    "expected a finite positive number."
                )
        return self

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

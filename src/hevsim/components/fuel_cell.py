"""Hydrogen fuel-cell system: net DC power, net system efficiency, hydrogen rate, ramp limits.

The system's net efficiency ``eta(P)`` (hydrogen lower heating value to net DC power at the bus,
balance of plant included) is a measured curve over the net power as a fraction of the rating
(``efficiency.csv``: ``net_power_fraction``, ``efficiency``), linear between points. At net power
``P`` [W] the system draws hydrogen at ``P / (eta(P) LHV)`` [kg/s] (``LHV`` [J/kg], 120 MJ/kg for
hydrogen); it runs between ``min_power_w`` (idle) and ``max_power_w`` and its net power changes
by at most ``ramp_up_w_per_s`` / ``ramp_down_w_per_s`` [W/s].
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import ConfigError

HYDROGEN_LHV_J_PER_KG = 120.0e6
"""Lower heating value of hydrogen [J/kg] (120 MJ/kg; U.S. DOE Hydrogen Program Record 9002, and
FASTSim's ``H2FC`` vehicles' fuel)."""


@dataclass(frozen=True)
class FuelCellSystem:
    """A fuel-cell system of rating ``max_power_w`` [W] with its efficiency curve
    (``power_fraction`` [-] -> ``efficiency`` [-]), idle power ``min_power_w`` [W], ramp limits
    [W/s] and hydrogen heating value ``lhv_j_per_kg`` [J/kg]."""

    power_fraction: np.ndarray
    efficiency_curve: np.ndarray
    max_power_w: float
    min_power_w: float
    ramp_up_w_per_s: float
    ramp_down_w_per_s: float
    lhv_j_per_kg: float = HYDROGEN_LHV_J_PER_KG
    source: str = ""

    def efficiency(self, net_power_w: Any) -> Any:
        """Net system efficiency [-] at ``net_power_w`` [W] (array-like; linear in the curve)."""
        frac = np.asarray(net_power_w, dtype=np.float64) / self.max_power_w
        return np.interp(frac, self.power_fraction, self.efficiency_curve)

    def hydrogen_power_w(self, net_power_w: Any) -> Any:
        """Hydrogen chemical power [W] (LHV basis) at ``net_power_w`` [W]: ``P / eta(P)``."""
        p = np.asarray(net_power_w, dtype=np.float64)
        return np.where(p > 0.0, p / self.efficiency(p), 0.0)

    def hydrogen_rate_kgps(self, net_power_w: Any) -> Any:
        """Hydrogen mass flow [kg/s] at ``net_power_w`` [W]."""
        return self.hydrogen_power_w(net_power_w) / self.lhv_j_per_kg

    def ramp_window(self, previous_w: float, dt_s: float) -> tuple[float, float]:
        """(lowest, highest) net power [W] reachable in ``dt_s`` [s] from ``previous_w`` [W],
        within the idle and rated power."""
        lo = max(self.min_power_w, previous_w - self.ramp_down_w_per_s * dt_s)
        hi = min(self.max_power_w, previous_w + self.ramp_up_w_per_s * dt_s)
        return (lo, hi) if lo <= hi else (hi, hi)

    @classmethod
    def from_directory(cls, folder: Path, key: str = "fuel_cell.data", **kw: Any) -> FuelCellSystem:
        """Read ``folder/efficiency.csv`` (columns ``net_power_fraction``, ``efficiency``),
        checked: fractions strictly increasing from 0 to 1, efficiencies in (0, 1]."""
        path = Path(folder) / "efficiency.csv"
        if not path.is_file():
            raise ConfigError(
                f"key '{key}': no file {path}; expected efficiency.csv in the fuel-cell folder."
            )
        try:
            t = np.genfromtxt(path, delimiter=",", names=True)
        except ValueError as exc:
            raise ConfigError(f"{path}: not a CSV table of net_power_fraction, efficiency ({exc}).") from None
        names = t.dtype.names or ()
        for col in ("net_power_fraction", "efficiency"):
            if col not in names:
                raise ConfigError(f"{path}: missing column '{col}'; found {', '.join(names)}.")
        x = np.atleast_1d(np.asarray(t["net_power_fraction"], dtype=np.float64))
        y = np.atleast_1d(np.asarray(t["efficiency"], dtype=np.float64))
        if x.size < 2 or not np.all(np.isfinite(x)) or np.any(np.diff(x) <= 0) or x[0] != 0.0 or x[-1] != 1.0:
            raise ConfigError(
                f"{path}: column 'net_power_fraction' = {x.tolist()}; expected finite values strictly "
                "increasing from 0 to 1."
            )
        if not np.all(np.isfinite(y)) or np.any((y <= 0.0) | (y > 1.0)):
            bad = float(y[~np.isfinite(y) | (y <= 0.0) | (y > 1.0)][0])
            raise ConfigError(f"{path}: column 'efficiency' holds {bad!r}; expected values in (0, 1].")
        return cls(x, y, source=str(path), **kw)

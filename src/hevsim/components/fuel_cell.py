"""Hydrogen fuel-cell system: net DC power, net system efficiency, hydrogen rate, ramp limits.

The system's net efficiency ``eta(P)`` (hydrogen lower heating value to net DC power at the bus,
balance of plant included) is a measured curve over the net power as a fraction of the rating
(``efficiency.csv``: ``net_power_fraction``, ``efficiency``), linear between points. At net power
``P`` [W] the system draws hydrogen at ``P / (eta(P) LHV)`` [kg/s] (``LHV`` [J/kg], 120 MJ/kg for
hydrogen); it runs between ``min_power_w`` (idle) and ``max_power_w`` and its net power changes
by at most ``ramp_up_w_per_s`` / ``ramp_down_w_per_s`` [W/s]. Net power 0 is the system off
(no hydrogen): it starts at or below idle plus one step's ramp-up and stops from at most idle plus
one step's ramp-down (:meth:`FuelCellSystem.reachable`). A running system draws at least
``idle_fuel_power_w`` [W] of hydrogen (LHV basis; its balance of plant at low or no net output,
FASTSim's ``idle_fc_kw``): ``max(P / eta(P), idle_fuel_power_w)`` for ``P > 0`` (default 0: no
floor). A system kept running with no net output (a controller's forced-on rule) runs at
:data:`RUNNING_ZERO_W`, a net power too small to change any sum it enters, which is not off.

As a fuel converter it carries the fuel fields an :class:`~hevsim.components.engine.Engine`
carries (``fuel_name``, ``fuel_lhv_jpkg``, ``fuel_density_kgpm3``, ``heating_value_btu_per_gal``,
``co2_kg_per_kg``), so the DP's metrics and the ECMS score read either alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from hevsim.errors import ConfigError
from hevsim.tables import interp1

HYDROGEN_LHV_J_PER_KG = 120.0e6
"""Lower heating value of hydrogen [J/kg] (120 MJ/kg; U.S. DOE Hydrogen Program Record 9002, and
FASTSim's ``H2FC`` vehicles' fuel)."""
HYDROGEN_KG_PER_M3_GALLON = 264.1720524
"""Density of hydrogen's "gallon" [kg/m^3]: 1 kg per US gallon (hevsim/data/fuels.toml: the EPA
counts 1 kg of hydrogen as a gallon of gasoline equivalent)."""
HYDROGEN_BTU_PER_GALLON = 113738.5978
"""Heating value of that "gallon" (1 kg at 120 MJ/kg) [BTU/gal] (hevsim/data/fuels.toml)."""
RUNNING_ZERO_W = 1e-300
"""Net power [W] of a system running with no net output (on, not off: it draws its idle hydrogen
``idle_fuel_power_w``); added to any bus power of a vehicle it leaves the sum unchanged."""


@njit(cache=True, inline="always")
def ramp_window_point(previous_w, dt_s, min_power_w, max_power_w, ramp_up_w_per_s, ramp_down_w_per_s):
    """(lowest, highest) net power [W] reachable in ``dt_s`` [s] from ``previous_w`` [W], within
    idle ``min_power_w`` and the rating ``max_power_w`` [W], ramp limits [W/s] (scalar kernel of
    :meth:`FuelCellSystem.ramp_window`)."""
    lo = max(min_power_w, previous_w - ramp_down_w_per_s * dt_s)
    hi = min(max_power_w, previous_w + ramp_up_w_per_s * dt_s)
    if lo <= hi:
        return lo, hi
    return hi, hi


@njit(cache=True, inline="always")
def reachable_window_point(previous_w, dt_s, min_power_w, max_power_w, ramp_up_w_per_s, ramp_down_w_per_s):
    """(lowest, highest running net power [W], off reachable) in ``dt_s`` [s] from ``previous_w``
    [W] (0 = off; scalar kernel of :meth:`FuelCellSystem.reachable_window`)."""
    if previous_w <= 0.0:
        return min_power_w, max(min_power_w, min(max_power_w, ramp_up_w_per_s * dt_s)), True
    lo, hi = ramp_window_point(previous_w, dt_s, min_power_w, max_power_w, ramp_up_w_per_s, ramp_down_w_per_s)
    return lo, hi, previous_w - ramp_down_w_per_s * dt_s <= min_power_w


@njit(cache=True, inline="always")
def reachable_point(
    previous_w, dt_s, net_power_w, min_power_w, max_power_w, ramp_up_w_per_s, ramp_down_w_per_s
):
    """Whether the net power ``net_power_w`` [W] is reachable in ``dt_s`` [s] from ``previous_w``
    [W] (scalar kernel of :meth:`FuelCellSystem.reachable`)."""
    lo, hi, off_ok = reachable_window_point(
        previous_w, dt_s, min_power_w, max_power_w, ramp_up_w_per_s, ramp_down_w_per_s
    )
    tol = 1e-9 * max_power_w
    return (net_power_w == 0.0 and off_ok) or (net_power_w >= lo - tol and net_power_w <= hi + tol)


@njit(cache=True, inline="always")
def efficiency_point(net_power_w, max_power_w, power_fraction, efficiency_curve):
    """Net system efficiency [-] at ``net_power_w`` [W] (scalar kernel of
    :meth:`FuelCellSystem.efficiency`: linear in the curve, held at its ends; numpy's ``interp``
    to round-off)."""
    return interp1(power_fraction, efficiency_curve, net_power_w / max_power_w, False)


@njit(cache=True, inline="always")
def hydrogen_power_point(net_power_w, max_power_w, power_fraction, efficiency_curve, idle_fuel_power_w):
    """(net efficiency [-], hydrogen chemical power [W], LHV basis) at ``net_power_w`` [W]:
    ``max(P / eta(P), idle_fuel_power_w)`` while running, 0 when off (scalar kernel of
    :meth:`FuelCellSystem.hydrogen_power_w`)."""
    eta = efficiency_point(net_power_w, max_power_w, power_fraction, efficiency_curve)
    return eta, (max(net_power_w / eta, idle_fuel_power_w) if net_power_w > 0.0 else 0.0)


@dataclass(frozen=True)
class FuelCellSystem:
    """A fuel-cell system of rating ``max_power_w`` [W] with its efficiency curve
    (``power_fraction`` [-] -> ``efficiency`` [-]), idle power ``min_power_w`` [W], ramp limits
    [W/s], hydrogen heating value ``lhv_j_per_kg`` [J/kg] and the least hydrogen power a running
    system draws, ``idle_fuel_power_w`` [W] (LHV basis)."""

    power_fraction: np.ndarray
    efficiency_curve: np.ndarray
    max_power_w: float
    min_power_w: float
    ramp_up_w_per_s: float
    ramp_down_w_per_s: float
    lhv_j_per_kg: float = HYDROGEN_LHV_J_PER_KG
    source: str = ""
    fuel_name: str = "hydrogen"
    fuel_density_kgpm3: float = HYDROGEN_KG_PER_M3_GALLON
    heating_value_btu_per_gal: float = HYDROGEN_BTU_PER_GALLON
    co2_kg_per_kg: float = 0.0
    idle_fuel_power_w: float = 0.0

    @property
    def name(self) -> str:
        """The efficiency curve's folder name (its source), else ``"fuel_cell"``."""
        return Path(self.source).parent.name if self.source else "fuel_cell"

    @property
    def fuel_lhv_jpkg(self) -> float:
        """Lower heating value of its fuel [J/kg] (``lhv_j_per_kg``; the engine's field name)."""
        return float(self.lhv_j_per_kg)

    def efficiency(self, net_power_w: Any) -> Any:
        """Net system efficiency [-] at ``net_power_w`` [W] (array-like; linear in the curve)."""
        frac = np.asarray(net_power_w, dtype=np.float64) / self.max_power_w
        return np.interp(frac, self.power_fraction, self.efficiency_curve)

    def hydrogen_power_w(self, net_power_w: Any) -> Any:
        """Hydrogen chemical power [W] (LHV basis) at ``net_power_w`` [W]: ``max(P / eta(P),
        idle_fuel_power_w)`` where running (``P > 0``), 0 where off."""
        p = np.asarray(net_power_w, dtype=np.float64)
        return np.where(p > 0.0, np.maximum(p / self.efficiency(p), self.idle_fuel_power_w), 0.0)

    def hydrogen_rate_kgps(self, net_power_w: Any) -> Any:
        """Hydrogen mass flow [kg/s] at ``net_power_w`` [W]."""
        return self.hydrogen_power_w(net_power_w) / self.lhv_j_per_kg

    def ramp_window(self, previous_w: float, dt_s: float) -> tuple[float, float]:
        """(lowest, highest) net power [W] reachable in ``dt_s`` [s] from ``previous_w`` [W],
        within the idle and rated power."""
        lo, hi = ramp_window_point(float(previous_w), float(dt_s), *self._limits())
        return float(lo), float(hi)

    def _limits(self) -> tuple[float, float, float, float]:
        """(idle, rating [W], ramp up, ramp down [W/s]) as the scalar kernels take them."""
        return (float(self.min_power_w), float(self.max_power_w), float(self.ramp_up_w_per_s),
                float(self.ramp_down_w_per_s))  # fmt: skip

    def reachable(self, previous_w: float, dt_s: float, net_power_w: Any) -> Any:
        """Whether each net power ``net_power_w`` [W] (array-like) is reachable in ``dt_s`` [s]
        from ``previous_w`` [W]: 0 (off) from off or from at most ``min_power_w + ramp_down x
        dt``; a running power within idle..rating and the ramp window from the previous power
        (from off: idle up to ``max(idle, ramp_up x dt)``). Boolean array."""
        lo, hi, off_ok = self.reachable_window(previous_w, dt_s)
        p = np.asarray(net_power_w, dtype=np.float64)
        tol = 1e-9 * self.max_power_w
        return ((p == 0.0) & off_ok) | ((p >= lo - tol) & (p <= hi + tol))

    def reachable_window(self, previous_w: float, dt_s: float) -> tuple[float, float, bool]:
        """(lowest, highest running net power [W], off reachable) in ``dt_s`` [s] from
        ``previous_w`` [W] (0 = off; see :meth:`reachable`)."""
        lo, hi, off_ok = reachable_window_point(float(previous_w), float(dt_s), *self._limits())
        return float(lo), float(hi), bool(off_ok)

    def project(self, previous_w: float, dt_s: float, net_power_w: Any) -> Any:
        """``net_power_w`` [W] moved into what is reachable in ``dt_s`` [s] from
        ``previous_w`` [W]: 0 stays 0 where off is reachable, every other value is clipped to
        the running window (:meth:`reachable_window`)."""
        lo, hi, off_ok = self.reachable_window(previous_w, dt_s)
        p = np.asarray(net_power_w, dtype=np.float64)
        return np.where((p == 0.0) & off_ok, 0.0, np.clip(p, lo, hi))

    def shutdown_energy_j(self, net_power_w: Any, dt_s: float, load_w: float = 0.0) -> Any:
        """Net energy [J] the system still delivers above a bus load ``load_w`` [W] on its fastest
        way from ``net_power_w`` [W] (array-like) to off, in steps of ``dt_s`` [s]: each step at
        the lowest power the ramp-down limit reaches (never below idle) until off is reachable
        (:meth:`reachable_window`): ``sum_j max(P_j - load, 0) dt`` with ``P_j = max(P - j r dt,
        idle)`` while ``P_{j-1} - r dt > idle``. 0 where off is reachable in the next step. What
        the battery must be able to take if the bus load falls to ``load_w`` at once (a full
        battery cannot: :class:`hevsim.control.parallel._GridController`)."""
        p = np.asarray(net_power_w, dtype=np.float64)
        step = self.ramp_down_w_per_s * float(dt_s)
        out = np.zeros(p.shape)
        cur = p.copy()
        if step <= 0.0:
            return np.where(p > 0.0, np.inf, 0.0)
        while True:
            running = cur - step > self.min_power_w  # off is not reachable from cur yet
            if not running.any():
                return out
            cur = np.where(running, np.maximum(cur - step, self.min_power_w), 0.0)
            out += np.where(running, np.maximum(cur - load_w, 0.0) * float(dt_s), 0.0)

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

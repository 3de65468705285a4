"""The plug-in hybrid's label tests: SAE J1711 charge-depleting range and SAE J2841 utility factors.

A plug-in hybrid (``[plugin] mode`` other than ``"off"``, :class:`hevsim.config.PluginSection`)
is labelled as SAE J1711 (2010) prescribes, on each of the label's cycles:

* **Charge-depleting (CD) test**: the cycle is repeated from a full battery (``battery.soc_max``),
  each run starting at the previous run's final SOC, until the SOC reaches ``plugin.cs_soc``
  during a run (the *transition cycle*; the next one is charge sustaining). The *cycle
  range* ``R_cdc`` is the distance of the CD runs, transition included; the *actual range*
  ``R_cda`` is the distance driven until the SOC first reaches ``cs_soc`` (interpolated in the
  transition run). Each run's DC energy is the battery's net energy change (charge drawn x
  open-circuit voltage, eq 15 of :mod:`hevsim.sim.metrics`); the electricity from the wall is
  their sum divided by ``plugin.charger_efficiency`` (the recharge energy), per mile of
  ``R_cda``.
* **Charge-sustaining (CS) test**: the SOC-balanced run of a hybrid
  (:func:`hevsim.sim.label.balance_soc`), started at ``cs_soc``.
* **Utility-factor weighting** (SAE J1711 with SAE J2841's fleet utility factor, FUF)::

      UF(d) = 1 - exp(-sum_i C_i (d / ND)^i),    ND = 399 mi, C = 10.52, -7.282, -26.37, 79.08,
                                                 -77.36, 26.07 (SAE J2841 Sept. 2010, Table 2)
      fuel  = sum_j [UF(D_j) - UF(D_j-1)] fuel_j / d_j + (1 - UF(R_cdc)) fuel_cs      [gal/mi]
      electricity = sum_j [UF(D_j) - UF(D_j-1)] E_ac,j / d_j                          [kWh/mi]

  over the CD runs j (distance ``d_j``, cumulative ``D_j``). The constants live in
  ``hevsim/data/epa_label.toml`` (``[utility_factor]``). FASTSim tabulates the same fleet curve
  (``longparams.json``, ``rechgFreqMiles`` / ``ufArray``, read with ``interp1d(kind="previous")``);
  the fit above is within 0.6 percentage points of that table up to 200 mi
  (``tests/test_plugin_hybrid.py``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import ConfigError, InputError
from hevsim.units import J_PER_WH, M_PER_MILE

CD_MAX_CYCLES = 200
"""Most repetitions of a cycle in a charge-depleting test before it is refused."""


@dataclass(frozen=True)
class UtilityFactorCurve:
    """SAE J2841's utility-factor fit: normalising distance ``norm_distance_mi`` [mi] and the
    polynomial coefficients ``coefficients`` [-] (lowest power first)."""

    name: str
    norm_distance_mi: float
    coefficients: tuple[float, ...]

    def __call__(self, distance_mi: Any) -> Any:
        """The utility factor [-] of a charge-depleting range ``distance_mi`` [mi] (array-like)."""
        d = np.asarray(distance_mi, dtype=np.float64)
        if np.any(d < 0.0) or not np.all(np.isfinite(d)):
            raise ConfigError(f"utility factor: distance {distance_mi!r} mi; expected finite values >= 0.")
        x = d / self.norm_distance_mi
        s = np.zeros_like(x)
        for i, c in enumerate(self.coefficients, start=1):
            s = s + c * x**i
        return 1.0 - np.exp(-s)


@functools.lru_cache(maxsize=1)
def fleet_utility_factor() -> UtilityFactorCurve:
    """SAE J2841's fleet utility factor (FUF), read and checked from ``data/epa_label.toml``."""
    import tomllib

    path = Path(str(resources.files("hevsim") / "data" / "epa_label.toml"))
    data = tomllib.loads(path.read_text(encoding="utf-8")).get("utility_factor", {})
    where = f"{path} [utility_factor]"
    nd = data.get("norm_distance_mi")
    coef = data.get("coefficients")
    if isinstance(nd, bool) or not isinstance(nd, int | float) or not nd > 0:
        raise InputError(f"{where}: key 'norm_distance_mi' = {nd!r}; expected a number > 0.")
    if not isinstance(coef, list) or not coef or not all(isinstance(c, int | float) for c in coef):
        raise InputError(f"{where}: key 'coefficients' = {coef!r}; expected a non-empty list of numbers.")
    return UtilityFactorCurve(str(data.get("name", "FUF")), float(nd), tuple(float(c) for c in coef))


@dataclass
class DepletingRun:
    """One run of a charge-depleting test: SOC at its start and end [-], distance [m], fuel
    [kg], the battery's net energy change [J] (DC, positive when discharged)."""

    soc_initial: float
    soc_final: float
    distance_m: float
    fuel_kg: float
    dc_energy_j: float
    result: Any = field(repr=False)


@dataclass
class DepletingTest:
    """A charge-depleting test on one cycle (SAE J1711): its runs (the transition run last),
    the actual range ``range_cda_m`` and cycle range ``range_cdc_m`` [m]."""

    cycle: str
    cs_soc: float
    runs: list[DepletingRun]
    range_cda_m: float
    range_cdc_m: float

    @property
    def dc_energy_j(self) -> float:
        """Net battery energy over the test [J]."""
        return float(sum(r.dc_energy_j for r in self.runs))

    @property
    def fuel_kg(self) -> float:
        """Fuel over the test [kg]."""
        return float(sum(r.fuel_kg for r in self.runs))


def distance_to_soc(result: Any, soc_target: float) -> float:
    """Distance [m] driven in a run until its SOC first reaches ``soc_target`` (linear between
    samples; the run's distance if it never does)."""
    ts = result.timeseries
    t = ts["time_s"].to_numpy(float)
    v = ts["speed_mps"].to_numpy(float)
    soc = ts["soc"].to_numpy(float)
    dist = np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))))
    total = float(result.metrics["distance_m"]["value"])
    scale = total / dist[-1] if dist[-1] > 0 else 1.0
    below = np.flatnonzero(soc <= soc_target)
    if below.size == 0:
        return total
    k = int(below[0])
    if k == 0:
        return 0.0
    f = (soc[k - 1] - soc_target) / (soc[k - 1] - soc[k]) if soc[k - 1] != soc[k] else 1.0
    return float(scale * (dist[k - 1] + f * (dist[k] - dist[k - 1])))


def uf_weighted(
    test: DepletingTest, cs_fuel_gal_per_mi: float, gallons_of: Any, charger_efficiency: float,
    uf: UtilityFactorCurve,
) -> dict[str, float]:  # fmt: skip
    """SAE J1711's utility-factor-weighted fuel [gal/mi] and electricity from the wall [kWh/mi]
    of a charge-depleting ``test`` and the charge-sustaining fuel ``cs_fuel_gal_per_mi``
    (``gallons_of(kg)`` converts fuel mass to gallons), with the utility factor ``uf``."""
    d_end = np.cumsum([r.distance_m for r in test.runs]) / M_PER_MILE
    d_start = np.concatenate(([0.0], d_end[:-1]))
    weights = uf(d_end) - uf(d_start)
    fuel = 0.0
    elec = 0.0
    for w, r in zip(weights, test.runs, strict=True):
        miles = r.distance_m / M_PER_MILE
        fuel += float(w) * gallons_of(r.fuel_kg) / miles
        elec += float(w) * r.dc_energy_j / charger_efficiency / J_PER_WH / 1000.0 / miles
    uf_cdc = float(uf(test.range_cdc_m / M_PER_MILE))
    fuel += (1.0 - uf_cdc) * cs_fuel_gal_per_mi
    return {"fuel_gal_per_mi": fuel, "electricity_kwh_per_mi": elec, "uf_cdc": uf_cdc}


def plugin_figures(
    model: Any, cd: dict[str, DepletingTest], cs_mpg: dict[str, float], gallons_of: Any, constants: Any,
    coef: Any, adjusted_electric_mpge: Any,
) -> dict[str, Any]:  # fmt: skip
    """The label figures of a plug-in hybrid from its charge-depleting tests ``cd`` and its
    unadjusted charge-sustaining fuel economy ``cs_mpg`` [mi/gal] by test ("city", "highway");
    ``adjusted_electric_mpge(mpge, test, coef, factor)``: the label's electric adjustment
    (:func:`hevsim.sim.label.adjusted_electric_mpge`)."""

    pl = model.config.plugin
    eff = float(pl.charger_efficiency)
    uf = fleet_utility_factor()
    w = constants.city_weight
    kwh_gal = constants.kwh_per_gallon_equivalent
    range_cda = {n: t.range_cda_m / M_PER_MILE for n, t in cd.items()}
    range_cdc = {n: t.range_cdc_m / M_PER_MILE for n, t in cd.items()}
    kwh_mi = {}
    for n, t in cd.items():
        if t.range_cda_m <= 0.0 or t.dc_energy_j <= 0.0:
            raise ConfigError(
                f"{model.name} on {t.cycle}: no charge-depleting distance or energy; expected > 0."
            )
        kwh_mi[n] = t.dc_energy_j / eff / J_PER_WH / 1000.0 / (t.range_cda_m / M_PER_MILE)
    weighted = {n: uf_weighted(t, 1.0 / cs_mpg[n], gallons_of, eff, uf) for n, t in cd.items()}
    mpge_cd = {n: kwh_gal / v for n, v in kwh_mi.items()}
    adj_mpge_cd = {n: adjusted_electric_mpge(mpge_cd[n], n, coef, constants.electric_adjustment_factor)
                   for n in mpge_cd}  # fmt: skip
    factor = constants.electric_adjustment_factor
    out_range = {n: range_cda[n] for n in range_cda}
    out_range["combined"] = w * range_cda["city"] + (1 - w) * range_cda["highway"]
    kwh_mi["combined"] = w * kwh_mi["city"] + (1 - w) * kwh_mi["highway"]
    adj_kwh = {n: kwh_gal / v for n, v in adj_mpge_cd.items()}
    adj_kwh["combined"] = w * adj_kwh["city"] + (1 - w) * adj_kwh["highway"]
    fuel_uf = {n: v["fuel_gal_per_mi"] for n, v in weighted.items()}
    elec_uf = {n: v["electricity_kwh_per_mi"] for n, v in weighted.items()}
    fuel_uf["combined"] = w * fuel_uf["city"] + (1 - w) * fuel_uf["highway"]
    elec_uf["combined"] = w * elec_uf["city"] + (1 - w) * elec_uf["highway"]
    return {
        "charge_depleting_range_mi": {
            "actual_unadjusted": out_range,
            "cycle_unadjusted": range_cdc,
            "actual_adjusted": {n: factor * v for n, v in out_range.items()},
        },
        "charge_depleting_kwh_per_100mi": {
            "unadjusted": {n: 100 * v for n, v in kwh_mi.items()},
            "adjusted": {n: 100 * v for n, v in adj_kwh.items()},
        },
        "charge_depleting_mpge": {
            "unadjusted": {n: kwh_gal / v for n, v in kwh_mi.items()},
            "adjusted": {n: kwh_gal / v for n, v in adj_kwh.items()},
        },
        "charge_depleting_fuel_gal": {n: gallons_of(t.fuel_kg) for n, t in cd.items()},
        "uf_weighted": {
            "utility_factor": {n: v["uf_cdc"] for n, v in weighted.items()},
            "mpg": {n: (1.0 / v if v > 0 else math.inf) for n, v in fuel_uf.items()},
            "kwh_per_100mi": {n: 100 * v for n, v in elec_uf.items()},
            "mpge": {n: 1.0 / (fuel_uf[n] + elec_uf[n] / kwh_gal) for n in fuel_uf},
            "curve": f"SAE J2841 {uf.name} (ND = {uf.norm_distance_mi:g} mi)",
        },
        "charge_depleting_runs": {n: [_run_dict(r) for r in t.runs] for n, t in cd.items()},
        "charger_efficiency": eff,
        "cs_soc": float(pl.cs_soc),
        "mode": pl.mode,
    }


def _run_dict(r: DepletingRun) -> dict[str, float]:
    return {
        "soc_initial": r.soc_initial,
        "soc_final": r.soc_final,
        "distance_mi": r.distance_m / M_PER_MILE,
        "fuel_kg": r.fuel_kg,
        "dc_energy_kwh": r.dc_energy_j / J_PER_WH / 1000.0,
    }

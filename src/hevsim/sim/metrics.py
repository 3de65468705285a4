"""Fuel economy (MPG, MPGGE with SOC correction, eqs 14-20), CO2 and the energy audit.

The SOC correction follows the thesis and tutorial lecture 7 exactly:

1. ``Ah = (SOC_i - SOC_f) x capacity``                                   (14)
2. ``E_battery [Wh] = Ah x OCV`` (OCV at the mean of initial and final SOC)  (15)
3. ``E_electrical [BTU] = 3.412 x E_battery / eta_conversion``            (16)
4. ``E_fuel [BTU] = gallons x heating value of the fuel [BTU/gal]``     (17)
5. ``E_total = E_fuel + E_electrical``                                    (18)
6. ``gallons_RFG = E_total / 114871.7446`` (RFG heating value)            (19)
7. ``MPGGE = miles / gallons_RFG``                                        (20)

The fuel's heating value, density and CO2 factor are those of the engine's fuel
(:mod:`hevsim.fuels`, ``hevsim/data/fuels.toml``): the thesis's B-20 diesel value
133393.1102 BTU/gal for diesel, 114871.7446 BTU/gal for gasoline. The reference gallon of
eq (19) is the table's ``mpgge.reference_heating_value_btu_per_us_gal``. So MPGGE is
"miles per US gallon of gasoline equivalent": the distance over the gasoline gallons holding
the same energy as the fuel burnt plus the SOC change; a gasoline vehicle with no SOC change
has MPGGE = MPG, and two vehicles using the same fuel energy have the same MPGGE whatever
they burn.

A depleted battery (SOC_f < SOC_i) adds energy and lowers MPGGE; a charged one subtracts.
(The tutorial's printed example shows its "electrical energy consumed" as -151.694 BTU but its
MPGGE adds +151.694: its battery was depleted, as in hevsim's thesis-calibrated level 5, and
the equations reproduce its 102.221 MPGGE; docs/refinement.md.) The OCV of step 2 is
``[metrics] soc_correction_ocv_v`` instead when that is > 0 (:func:`soc_correction_ocv`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hevsim.fuels import mpgge_reference_btu_per_us_gal
from hevsim.sim import kernel as K
from hevsim.units import BTU_PER_WH, J_PER_WH, M3_PER_US_GALLON, M_PER_MILE, MPS_PER_MPH

SOURCES = ("fuel", "genset_source", "battery_chemical")
MPGGE_DESCRIPTION = (
    "MPGGE: miles per US gallon of gasoline equivalent with SOC correction, eqs 14-20: distance / "
    "((fuel energy + battery energy / conversion efficiency) / reference gallon energy), "
    "reference gallon = the fuel table's mpgge reference (RFG, 114871.7446 BTU/gal, thesis eq 19)"
)
"""What the ``mpgge`` metric is (its unit is mi/gal)."""


def metric(value: float, unit: str, description: str) -> dict[str, Any]:
    """One metric entry."""
    return {"value": float(value), "unit": unit, "description": description}


def energy_audit(energy: np.ndarray) -> dict[str, float]:
    """Named energy terms [J] plus the residual (sources - sinks) [J]."""
    audit = {name: float(energy[i]) for i, name in enumerate(K.ENERGY_TERMS)}
    sources = sum(audit[s] for s in SOURCES)
    sinks = sum(v for k, v in audit.items() if k not in SOURCES)
    audit["residual"] = sources - sinks
    return audit


def audit_residual_fraction(audit: dict[str, float]) -> float:
    """``|residual|`` relative to the gross energy throughput (sum of ``|terms|``) [-]."""
    gross = sum(abs(v) for k, v in audit.items() if k != "residual") / 2.0
    return abs(audit["residual"]) / gross if gross > 0 else 0.0


def soc_correction_ocv(ocv_override_v: float, battery: Any, soc_initial: float, soc_final: float) -> float:
    """Open-circuit voltage [V] of eq (15): ``ocv_override_v`` if > 0 (``[metrics]
    soc_correction_ocv_v``), else the battery's OCV at the mean of initial and final SOC."""
    if ocv_override_v > 0.0:
        return float(ocv_override_v)
    return float(np.asarray(battery.ocv(0.5 * (soc_initial + soc_final))))


def fuel_economy(
    distance_m: float,
    fuel_kg: float,
    soc_initial: float,
    soc_final: float,
    capacity_ah: float,
    ocv_v: float,
    fuel_density_kgpm3: float,
    heating_value_btu_per_gal: float,
    conversion_efficiency: float,
    genset_source_j: float = 0.0,
    reference_btu_per_gal: float | None = None,
) -> dict[str, float]:
    """MPG and SOC-corrected MPGGE, eqs (14)-(20).

    ``heating_value_btu_per_gal`` [BTU/gal] and ``fuel_density_kgpm3`` [kg/m^3] are the
    burnt fuel's; ``reference_btu_per_gal`` [BTU/gal] is the gasoline-equivalent gallon of
    eq (19) (None: the fuel table's). ``genset_source_j`` [J] is electrical energy from an
    ideal genset (no engine model); it is counted as fuel energy at 100 % conversion.
    Returns miles, gallons, BTU terms and both fuel economies [mi/gal] (inf when nothing is
    consumed).
    """
    reference = mpgge_reference_btu_per_us_gal() if reference_btu_per_gal is None else reference_btu_per_gal
    miles = distance_m / M_PER_MILE
    gallons = fuel_kg / fuel_density_kgpm3 / M3_PER_US_GALLON
    e_fuel_btu = gallons * heating_value_btu_per_gal + genset_source_j / J_PER_WH * BTU_PER_WH
    ah = (soc_initial - soc_final) * capacity_ah
    e_batt_wh = ah * ocv_v
    e_elec_btu = BTU_PER_WH * e_batt_wh / conversion_efficiency
    e_total = e_fuel_btu + e_elec_btu
    gal_rfg = e_total / reference
    fuel_gal_total = gallons + genset_source_j / J_PER_WH * BTU_PER_WH / heating_value_btu_per_gal
    return {
        "miles": miles,
        "gallons": gallons,
        "ah_consumed": ah,
        "e_battery_wh": e_batt_wh,
        "e_electrical_btu": e_elec_btu,
        "e_fuel_btu": e_fuel_btu,
        "e_total_btu": e_total,
        "gallons_rfg": gal_rfg,
        "mpg": miles / fuel_gal_total if fuel_gal_total > 0 else float("inf"),
        "mpgge": miles / gal_rfg if gal_rfg > 0 else float("inf"),
    }


def compute_metrics(
    summary: np.ndarray,
    audit: dict[str, float],
    soc_initial: float,
    capacity_ah: float,
    ocv_mean_v: float,
    fuel_density_kgpm3: float,
    heating_value_btu_per_gal: float,
    co2_kg_per_kg: float,
    conversion_efficiency: float,
) -> dict[str, dict[str, Any]]:
    """All scalar metrics of one run, with units and descriptions."""
    dist = summary[K.S_DIST]
    fuel = summary[K.S_FUEL]
    socf = summary[K.S_SOCF]
    fe = fuel_economy(
        dist, fuel, soc_initial, socf, capacity_ah, ocv_mean_v, fuel_density_kgpm3,
        heating_value_btu_per_gal, conversion_efficiency, audit["genset_source"],
    )  # fmt: skip
    km = dist / 1000.0
    liters = fuel / fuel_density_kgpm3 * 1000.0
    eq_fuel_kg = fe["e_total_btu"] / heating_value_btu_per_gal * M3_PER_US_GALLON * fuel_density_kgpm3
    return {
        "distance_m": metric(dist, "m", "distance travelled"),
        "distance_mi": metric(fe["miles"], "mi", "distance travelled"),
        "duration_s": metric(summary[K.S_DUR], "s", "simulated time"),
        "fuel_kg": metric(fuel, "kg", "fuel burnt"),
        "fuel_l": metric(liters, "L", "fuel burnt"),
        "fuel_gal": metric(fe["gallons"], "gal", "fuel burnt (US gallons)"),
        "mpg": metric(fe["mpg"], "mi/gal", "miles per US gallon of the fuel burnt, no SOC correction"),
        "l_per_100km": metric(
            liters / km * 100.0 if km > 0 else float("nan"),
            "L/100km",
            "fuel consumption, no SOC correction",
        ),
        "mpgge": metric(fe["mpgge"], "mi/gal", MPGGE_DESCRIPTION),
        "fuel_equivalent_kg": metric(
            eq_fuel_kg, "kg", "fuel burnt plus the fuel equivalent of the SOC change"
        ),
        "co2_g_per_km": metric(
            fuel * co2_kg_per_kg * 1e3 / km if km > 0 else float("nan"),
            "g/km",
            "tailpipe CO2 from fuel burnt",
        ),
        "co2_soc_corrected_g_per_km": metric(
            eq_fuel_kg * co2_kg_per_kg * 1e3 / km if km > 0 else float("nan"),
            "g/km",
            "CO2 of the SOC-corrected fuel equivalent",
        ),
        "soc_initial": metric(soc_initial, "-", "initial state of charge"),
        "soc_final": metric(socf, "-", "final state of charge"),
        "battery_energy_wh": metric(fe["e_battery_wh"], "Wh", "eq (15): energy drawn from the battery"),
        "speed_error_rms_mph": metric(summary[K.S_RMS] / MPS_PER_MPH, "mph", "RMS speed-tracking error"),
        "speed_error_max_mph": metric(summary[K.S_MAXERR] / MPS_PER_MPH, "mph", "max speed-tracking error"),
        "engine_on_time_s": metric(summary[K.S_EON], "s", "time with the engine fired"),
        "engine_starts": metric(summary[K.S_STARTS], "-", "genset start requests"),
        "battery_limited_s": metric(summary[K.S_BLIM], "s", "time with battery power limited"),
        "energy_audit_residual_pct": metric(
            100.0 * audit_residual_fraction(audit), "%", "energy audit residual / gross throughput"
        ),
    }

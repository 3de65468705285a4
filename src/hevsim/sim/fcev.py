"""Forward simulation of the fuel-cell vehicle: :func:`hevsim.sim.forward.simulate_architecture`
(its Python loop) with the hydrogen and MPGe metrics."""

from __future__ import annotations

from typing import Any

from hevsim.sim.forward import simulate_architecture
from hevsim.units import M_PER_MILE


def simulate_fcev(model: Any, *args: Any, **kwargs: Any) -> Any:
    """Simulate a fuel-cell vehicle forward (see :func:`simulate_architecture`; the Python loop),
    with its hydrogen ``hydrogen_kg`` [kg] and ``mpge`` [mi/gal-equivalent]: miles per kg of
    hydrogen plus the battery's net energy at 33.705 kWh per gallon equivalent (the EPA counts
    1 kg of hydrogen as one gallon of gasoline equivalent; hydrogen's LHV, 120 MJ/kg =
    33.3 kWh/kg, is 1.1 % below that gallon)."""
    from hevsim.sim.label import constants

    res = simulate_architecture("fcev", model, *args, **kwargs)
    m = res.metrics
    kg = float(m["fuel_kg"]["value"])
    nec_kwh = float(m["battery_energy_wh"]["value"]) / 1000.0
    gallons = kg + nec_kwh / constants().kwh_per_gallon_equivalent
    miles = float(m["distance_m"]["value"]) / M_PER_MILE
    m["hydrogen_kg"] = {"value": kg, "unit": "kg", "description": "hydrogen consumed"}
    m["mpge"] = {
        "value": miles / gallons if gallons > 0 else float("inf"), "unit": "mi/gal-equivalent",
        "description": "mi per (kg of hydrogen + battery net energy / 33.705 kWh): EPA MPGe, 1 kg H2 = 1 gge",
    }  # fmt: skip
    return res

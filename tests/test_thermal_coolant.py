"""Channel model vs the analytic constant-wall-temperature solution (issue 5, items 4 and 6)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hevsim.errors import ConfigError
from hevsim.thermal.coolant import ChannelModel, Coolant, nusselt, segments_along_path

FLOW_10_L_MIN = 10.0 / 60000.0


def test_outlet_matches_exponential_solution_for_constant_wall() -> None:
    ch = ChannelModel(25, inlet_temp_k=288.15, flow_m3_s=FLOW_10_L_MIN, width_m=0.008, height_m=0.004)
    perimeter, length, t_wall = 2 * (0.008 + 0.004), 1.2, 320.0
    area = np.full(25, perimeter * length / 25)
    mean = ch.fluid_temperature_k(np.full(25, t_wall), area)
    ntu = ch.h_w_m2k * perimeter * length / ch.capacity_rate_w_k
    exact_out = t_wall + (288.15 - t_wall) * math.exp(-ntu)
    assert ch.outlet_temp_k == pytest.approx(exact_out, rel=1e-12)
    # local fluid temperature along x, segment means from the exact profile
    x = (np.arange(25) + 0.5) * length / 25
    exact_mid = t_wall + (288.15 - t_wall) * np.exp(-ntu * x / length)
    assert np.max(np.abs(mean - exact_mid)) < 1e-3
    # heat balance: m c (Tout - Tin) = sum h A (Tw - Tmean)
    assert ch.heat_w == pytest.approx(float(np.sum(ch.h_w_m2k * area * (t_wall - mean))), rel=1e-10)


def test_regimes_and_defaults() -> None:
    c = Coolant()
    assert (c.conductivity_w_mk, c.density_kg_m3, c.viscosity_pa_s) == (0.43, 1056.0, 0.0085)
    assert nusselt(1000.0, 60.0) == 3.66
    assert nusselt(1e4, 60.0) > 50.0
    assert 3.66 < nusselt(2600.0, 60.0) < nusselt(3000.0, 60.0)
    ch = ChannelModel(4, inlet_temp_k=288.15, flow_m3_s=FLOW_10_L_MIN, width_m=0.008, height_m=0.004)
    assert ch.capacity_rate_w_k == pytest.approx(1056 * FLOW_10_L_MIN * 3300)


def test_segments_along_path() -> None:
    path = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    pts = np.array([[0.1, 0.01, 0.0], [0.9, -0.01, 0.0], [1.01, 0.4, 0.0], [1.0, 0.99, 0.0]])
    assert segments_along_path(pts, path, 4).tolist() == [0, 1, 2, 3]


def test_bad_coolant_values() -> None:
    with pytest.raises(ConfigError, match="flow_m3_s"):
        ChannelModel(4, inlet_temp_k=288.0, flow_m3_s=-1.0, width_m=0.01, height_m=0.01)
    with pytest.raises(ConfigError, match="viscosity_pa_s"):
        Coolant(viscosity_pa_s=0.0).check()


def test_meg50_table_interpolation_and_range() -> None:
    from hevsim.thermal.coolant import MEG50_TABLE, meg50_coolant

    for i, t in enumerate(MEG50_TABLE["temp_c"]):  # exact at the table points
        c = meg50_coolant(t)
        assert c.viscosity_pa_s == pytest.approx(MEG50_TABLE["viscosity_pa_s"][i], rel=1e-12)
        assert c.specific_heat_j_kgk == pytest.approx(MEG50_TABLE["specific_heat_j_kgk"][i], rel=1e-12)
    mid = meg50_coolant(25.0)  # between 20 and 30 °C: geometric mean viscosity, mean density
    assert mid.viscosity_pa_s == pytest.approx(math.sqrt(2.019e-3 * 1.552e-3), rel=1e-12)
    assert mid.density_kg_m3 == pytest.approx(1076.0)
    mus = [meg50_coolant(t).viscosity_pa_s for t in np.linspace(-10, 40, 21)]
    assert np.all(np.diff(mus) < 0)  # viscosity falls with temperature
    with pytest.raises(ConfigError, match="outside the MEG 50 table"):
        meg50_coolant(60.0)


def test_temperature_dependent_properties_change_nusselt_and_outlet_consistently() -> None:
    from hevsim.thermal.coolant import meg50_coolant

    perimeter, length, t_wall, t_in = 2 * (0.008 + 0.004), 1.2, 303.15, 288.15
    area = np.full(20, perimeter * length / 20)
    chans = {}
    for label, coolant, inlet in (
        ("table", Coolant(), t_in),
        ("meg15", meg50_coolant(15.0), t_in),
        ("meg35", meg50_coolant(35.0), 308.15),
    ):
        ch = ChannelModel(
            20, inlet_temp_k=inlet, flow_m3_s=FLOW_10_L_MIN, width_m=0.008, height_m=0.004, coolant=coolant
        )
        ch.fluid_temperature_k(np.full(20, t_wall if inlet == t_in else 323.15), area)
        ntu = ch.h_w_m2k * perimeter * length / ch.capacity_rate_w_k
        tw = t_wall if inlet == t_in else 323.15
        assert ch.outlet_temp_k == pytest.approx(tw + (inlet - tw) * math.exp(-ntu), rel=1e-12)
        chans[label] = ch
    tab, m15, m35 = chans["table"], chans["meg15"], chans["meg35"]
    # Table 4.4's 8.5 mPa s vs 2.3 mPa s at 15 °C: higher Re, higher Nu, warmer outlet
    assert m15.reynolds == pytest.approx(tab.reynolds * 0.0085 / 2.326e-3 * 1082 / 1056, rel=1e-9)
    assert m15.nusselt > tab.nusselt and m15.h_w_m2k > tab.h_w_m2k
    assert m15.outlet_temp_k > tab.outlet_temp_k
    # a warmer inlet thins the coolant further: Re and Nu rise again
    assert m35.reynolds > m15.reynolds and m35.nusselt > m15.nusselt

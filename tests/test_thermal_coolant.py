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

"""Modules of n_s x n_p cells: parallel current sharing, conservation, spread (issue 4, item 3)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from tests.test_cell_model import cell_dict

from hevsim.battery import Cell, Module, load_cell_parameters
from hevsim.battery import kernel as K
from hevsim.battery.params import parameters_from_dict


def _linear_ocv_cell(rc: bool) -> dict:
    d = cell_dict()
    d["tables"]["ocv_charge_v"] = [[3.0, 4.0]]
    d["tables"]["ocv_discharge_v"] = [[3.0, 4.0]]
    if not rc:
        d.pop("rc_discharge")
        d.pop("rc_charge")
    return d


def test_two_parallel_cells_match_hand_solution() -> None:
    """E1 = 3.8 V, R1 = 10 mΩ; E2 = 3.5 V, R2 = 20 mΩ; 10 A total.

    Equal voltages: 3.8 - 0.01 I1 = 3.5 - 0.02 I2, I1 + I2 = 10 -> I1 = 50/3 A, I2 = -20/3 A
    (the weaker cell is charged by the stronger one), V = 3.8 - 1/6 V.
    """
    p = parameters_from_dict(_linear_ocv_cell(rc=False), "two.toml")
    m = Module(p, n_series=1, n_parallel=2, soc_initial=0.8, temp_k=298.15)
    m.p[1, K.SOCINI] = 0.5
    m.p[1, K.RSCALE] = 2.0
    r = m.simulate([10.0], 1e-6, 298.15)
    i = r.cells[0, :, 0]
    assert i[0] == pytest.approx(50.0 / 3.0, rel=1e-9)
    assert i[1] == pytest.approx(-20.0 / 3.0, rel=1e-9)
    assert r.timeseries["voltage_v"].iloc[0] == pytest.approx(3.8 - 1.0 / 6.0, rel=1e-9)


def test_two_parallel_cells_with_rc_match_hand_solution() -> None:
    """With one RC element, a step of dt from rest: Z = R_s + R1 (1 - tau/dt (1 - e^{-dt/tau}))."""
    p = parameters_from_dict(_linear_ocv_cell(rc=True), "two.toml")
    m = Module(p, n_series=1, n_parallel=2, soc_initial=0.8)
    m.p[1, K.RSCALE] = 1.5
    dt = 5.0
    r = m.simulate([20.0], dt, 298.15)
    g = 30.0 / dt * (1 - math.exp(-dt / 30.0))
    z1 = 0.01 + 0.02 * (1 - g)
    z2 = 1.5 * z1
    i1 = 20.0 * z2 / (z1 + z2)
    np.testing.assert_allclose(r.cells[0, :, 0], [i1, 20.0 - i1], rtol=1e-12)
    # and the step-average voltages of both branches agree: the cells stepped alone reproduce it
    v = []
    for k, ik in enumerate((i1, 20.0 - i1)):
        c = Cell(p, soc_initial=0.8)
        c.p[K.RSCALE] = 1.0 if k == 0 else 1.5
        v.append(c.simulate([ik], dt, 298.15).timeseries["voltage_avg_v"].iloc[0])
    assert v[0] == pytest.approx(v[1], rel=1e-12)
    assert r.timeseries["voltage_avg_v"].iloc[0] == pytest.approx(v[0], rel=1e-12)


def test_module_defaults_to_2s6p_and_conserves_current() -> None:
    m = Module("saft_li_ion_6ah", capacity_spread=0.05, resistance_spread=0.08, seed=7, soc_initial=0.6)
    assert (m.n_series, m.n_parallel, m.n_cells) == (2, 6, 12)
    rng = np.random.default_rng(0)
    prof = np.repeat(rng.normal(5.0, 40.0, 120), 5)
    r = m.simulate(prof, 1.0, 300.0)
    i_cells = r.cells[:, :, 0]
    for s in range(2):
        np.testing.assert_allclose(i_cells[:, s * 6 : (s + 1) * 6].sum(axis=1), prof, rtol=1e-9, atol=1e-9)
    # not an even split, and each cell has its own SOC and temperature
    assert np.ptp(i_cells[10]) > 0.1
    assert np.ptp(r.cells[-1, :, 1]) > 1e-4 and np.ptp(r.cells[-1, :, 2]) > 1e-4
    # module energy: electrical out + heat = chemical energy released (no RC in this set)
    assert np.isfinite(r.metrics["electrical_energy_out_j"])


def test_identical_cells_split_evenly_and_match_single_cell() -> None:
    m = Module("thesis_table_4_1", n_series=3, n_parallel=4, soc_initial=0.9, temp_k=295.0)
    prof = np.r_[np.full(50, 8.0), np.zeros(20), np.full(30, -6.0)]
    r = m.simulate(prof, 1.0, 295.0)
    np.testing.assert_allclose(
        r.cells[:, :, 0], np.repeat(prof[:, None] / 4, 12, axis=1), rtol=1e-10, atol=1e-12
    )
    single = Cell("thesis_table_4_1", soc_initial=0.9, temp_k=295.0).simulate(prof / 4, 1.0, 295.0)
    np.testing.assert_allclose(r.timeseries["voltage_v"], 3 * single.timeseries["voltage_v"], rtol=1e-10)
    np.testing.assert_allclose(r.timeseries["heat_w"], 12 * single.timeseries["heat_w"], rtol=1e-10)


def test_spread_is_seeded_and_reproducible(tmp_path: Path) -> None:
    a = Module("thesis_table_4_1", capacity_spread=0.03, resistance_spread=0.05, seed=11)
    b = Module("thesis_table_4_1", capacity_spread=0.03, resistance_spread=0.05, seed=11)
    c = Module("thesis_table_4_1", capacity_spread=0.03, resistance_spread=0.05, seed=12)
    np.testing.assert_array_equal(a.p, b.p)
    assert not np.array_equal(a.p, c.p)
    prof = np.full(60, 12.0)
    ra, rb = a.simulate(prof, 1.0), b.simulate(prof, 1.0)
    np.testing.assert_array_equal(ra.cells, rb.cells)
    out = ra.save(tmp_path / "mod")
    assert (out / "cells_current_a.csv").is_file() and (out / "metrics.json").is_file()


def test_port_temperature_per_cell() -> None:
    p = load_cell_parameters("thesis_table_4_1")
    m = Module(p, n_series=1, n_parallel=2, soc_initial=0.9, temp_k=300.0)
    tp = np.tile([300.0, 320.0], (300, 1))
    r = m.simulate(np.full(300, 0.5), 10.0, tp)
    assert r.cells[-1, 1, 2] > r.cells[-1, 0, 2] + 5.0
    # the hotter cell has the higher R_s (alphaRs > 0) and so carries less current
    assert r.cells[-1, 1, 0] < r.cells[-1, 0, 0]

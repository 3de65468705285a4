"""Loads, CCCV charger, cycling and temperature cut-off (issue 4, item 4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim.battery import Cell
from hevsim.battery.loads import LoadProfile, cycle_cell, profile_from_array, pulse_train
from hevsim.errors import InputError


def test_cccv_charge_holds_vmax_and_ends_on_current() -> None:
    cell = Cell("saft_li_ion_6ah", soc_initial=0.1, temp_k=298.15)
    idle = profile_from_array([0.0], 1.0)
    r = cycle_cell(
        cell,
        idle,
        4 * 3600.0,
        v_min=2.0,
        v_max=3.9,
        i_charge_a=7.0,
        i_end_a=0.5,
        port_temperature=298.15,
        start_with="charge",
    )
    ts = r.timeseries
    cc = ts[ts["mode"] == "charge_cc"]
    cv = ts[ts["mode"] == "charge_cv"]
    assert len(cc) > 100 and len(cv) > 10
    np.testing.assert_allclose(cc["current_a"], -7.0)
    np.testing.assert_allclose(cv["voltage_avg_v"], 3.9, atol=1e-9)  # CV holds the limit exactly
    assert ts["voltage_avg_v"].max() <= 3.9 + 1e-9
    after = ts[ts["time_s"] > cv["time_s"].iloc[-1]]
    assert (after["mode"] == "load").all() and cv["current_a"].iloc[-1] >= -0.5
    assert len(after) > 0
    assert ts["soc"].iloc[-1] > 0.9


def test_cycling_alternates_load_and_charger() -> None:
    cell = Cell("thesis_table_4_1", soc_initial=0.6, temp_k=298.15)
    load = pulse_train(8.0, 1.0, period_s=10.0, duty=0.3, duration_s=600.0, dt_s=1.0)
    r = cycle_cell(
        cell, load, 4 * 3600.0, v_min=3.2, v_max=3.85, i_charge_a=1.6, i_end_a=0.1, i_discharge_max_a=6.0
    )
    ts = r.timeseries
    assert r.metrics["charges_started"] >= 2
    assert ts.loc[ts["mode"] == "load", "current_a"].max() == pytest.approx(6.0)  # discharge limit
    assert ts["voltage_avg_v"].max() <= 3.85 + 1e-9
    assert r.metrics["stop_reason"] == 0.0


def test_temperature_cutoff_stops_the_thesis_discharge() -> None:
    cell = Cell("thesis_table_4_1", soc_initial=1.0, temp_k=296.15)
    r = cycle_cell(
        cell,
        profile_from_array([40.0], 1.0),
        600.0,
        v_min=0.0,
        v_max=4.2,
        i_charge_a=30.0,
        i_end_a=1.0,
        port_temperature=296.15,
        temp_cutoff_k=353.15,
    )
    assert r.metadata["stop_reason"] == "temperature cut-off"
    assert r.timeseries["temp_k"].iloc[-1] >= 353.15 > r.timeseries["temp_k"].iloc[-2]
    assert 100.0 < r.metrics["stop_time_s"] < 300.0


def test_power_profile_delivers_the_power() -> None:
    cell = Cell("saft_li_ion_6ah", soc_initial=0.8)
    p = np.r_[np.full(50, 60.0), np.full(50, -40.0)]
    r = cycle_cell(
        cell, profile_from_array(p, 1.0, "power"), 100.0, v_min=2.0, v_max=3.95, i_charge_a=20.0, i_end_a=0.5
    )
    ts = r.timeseries
    np.testing.assert_allclose(ts["voltage_avg_v"] * ts["current_a"], p, rtol=1e-9)


def test_load_profile_csv_and_errors(tmp_path: Path) -> None:
    f = tmp_path / "load.csv"
    f.write_text("time_s,current_a\n0,1\n1,2\n2,3\n3,4\n")
    lp = LoadProfile.from_csv(f, 0.5)
    np.testing.assert_allclose(lp.values, [1, 1.5, 2, 2.5, 3, 3.5])
    f.write_text("time_s,amps\n0,1\n1,2\n")
    with pytest.raises(InputError, match="current_a"):
        LoadProfile.from_csv(f, 1.0)
    f.write_text("time_s,current_a\n0,1\n1,2\n2,2\n100,3\n")
    with pytest.raises(InputError, match=r"gap of 98\.0 s"):
        LoadProfile.from_csv(f, 1.0)
    with pytest.raises(InputError, match="kind"):
        LoadProfile(np.ones(3), 1.0, "torque")
    with pytest.raises(InputError, match="v_min"):
        cycle_cell(Cell("saft_li_ion_6ah"), lp, 10.0, 4.0, 3.0, 1.0, 0.1)

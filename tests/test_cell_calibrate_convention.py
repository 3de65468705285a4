"""``hevsim cell`` and ``hevsim calibrate`` share one row convention (issue 10, item 6).

Row k of a record is step k: the current over (t_k - dt, t_k], voltage and temperature at
t_k, the initial state one step before row 0. Fitting a cell's own output therefore recovers
its parameters exactly; the shipped example record is fitted through the command line.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from hevsim.battery import load_cell_parameters
from hevsim.battery.calibrate import CellTestRecord, calibrate, simulate_record
from hevsim.battery.cell import Cell

ROOT = Path(__file__).resolve().parents[1]
FIT = {
    "c_heat_j_per_k": (60.0, 10.0, 500.0),
    "r_skin_k_per_w": (5.0, 0.5, 50.0),
    "rc_discharge[0].r_ohm": (0.01, 1e-4, 0.1),
    "rc_discharge[0].tau_s": (40.0, 1.0, 300.0),
    "rc_charge[0].r_ohm": (0.008, 1e-4, 0.1),
}
TRUTH = {"c_heat_j_per_k": 96.0, "r_skin_k_per_w": 10.0, "rc_discharge[0].r_ohm": 0.005,
         "rc_discharge[0].tau_s": 20.0, "rc_charge[0].r_ohm": 0.004}  # fmt: skip


def _example_module() -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "make_calibration_pulse", ROOT / "examples" / "make_calibration_pulse.py"
    )
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _cell_output_record() -> CellTestRecord:
    p = load_cell_parameters("thesis_table_4_1")
    t = np.arange(900.0)
    i = np.where((t % 300) < 60, 8.0, np.where((t % 300) < 120, -4.0, 0.0))  # first row: a pulse
    ts = Cell(p, soc_initial=0.9, temp_k=296.15).simulate(i, 1.0, 296.15).timeseries
    t_s, i_a, v_v, temp_k = (ts[c].to_numpy() for c in ("time_s", "current_a", "voltage_v", "temp_k"))
    return CellTestRecord(t_s, i_a, v_v, temp_k, source="cell output")


def test_calibrate_replays_cell_output_exactly() -> None:
    p = load_cell_parameters("thesis_table_4_1")
    rec = _cell_output_record()
    v, temp = simulate_record(p, p.vector(0.9), p.rc_discharge, p.rc_charge, rec, 296.15, 296.15)
    np.testing.assert_allclose(v, rec.voltage_v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(temp, rec.temp_k, rtol=0, atol=1e-10)


def test_fitting_cell_output_recovers_parameters() -> None:
    res = calibrate("thesis_table_4_1", _cell_output_record(), FIT, soc_initial=0.9, port_temp_k=296.15)
    for name, value in TRUTH.items():
        assert res.values[name] == pytest.approx(value, rel=1e-4), name
    assert res.rmse["voltage_v"] < 1e-8


def test_shipped_example_is_reproducible_and_calibrates(tmp_path: Path) -> None:
    from hevsim.cli import main

    mod = _example_module()
    shipped = ROOT / "examples" / "calibration_pulse.csv"
    assert mod.write(tmp_path / "again.csv").read_bytes() == shipped.read_bytes()
    out = tmp_path / "fit"
    fit = [f"{k}={lo},{a},{b}" for k, (lo, a, b) in FIT.items() if k in mod.TRUTH]
    args = ["calibrate", "thesis_table_4_1", str(shipped), "--soc-initial", "0.9", "--ambient-c", "23"]
    assert main([*args, "--fit", *fit, "--out", str(out)]) == 0
    result = json.loads((out / "fit.json").read_text())
    for name, value in mod.TRUTH.items():
        got, err = result["values"][name], result["std_errors"][name]
        assert got == pytest.approx(value, rel=0.03), name  # noise: 2 mV, 0.05 K
        assert abs(got - value) < 4 * err, name
    assert result["rmse"]["voltage_v"] == pytest.approx(mod.SIGMA_V_V, rel=0.1)

"""Calibration recovers known parameters from noisy synthetic data (issue 4, item 5)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim.battery import load_cell_parameters
from hevsim.battery.calibrate import CellTestRecord, calibrate, simulate_record
from hevsim.errors import InputError


def _synthetic(noise: bool = True) -> CellTestRecord:
    """Thesis-like test: 20 A discharge for 300 s then 300 s rest, 23 degC ambient."""
    p = load_cell_parameters("thesis_table_4_1")
    t = np.arange(0.0, 601.0, 1.0)
    i = np.where((t > 0) & (t <= 300), 8.0, 0.0)  # 10 C on the 0.8 A h cell, then rest
    rec0 = CellTestRecord(t, i, np.zeros_like(t), np.full_like(t, 296.15))
    vec = p.vector(1.0)
    v, temp = simulate_record(p, vec, p.rc_discharge, p.rc_charge, rec0, 296.15)
    v[0] = p.ocv_discharge_v[-1, 0]
    if noise:
        rng = np.random.default_rng(0)
        v = v + rng.normal(0, 0.002, v.size)
        temp = temp + rng.normal(0, 0.05, v.size)
    return CellTestRecord(t, i, v, temp, "synthetic")


def test_recovers_known_parameters_from_noisy_data(tmp_path: Path) -> None:
    rec = _synthetic()
    fit = {
        "c_heat_j_per_k": (60.0, 10.0, 500.0),
        "r_skin_k_per_w": (5.0, 0.5, 50.0),
        "rc_discharge[0].r_ohm": (0.01, 1e-4, 0.1),
        "rc_discharge[0].tau_s": (40.0, 1.0, 300.0),
    }
    res = calibrate(
        "thesis_table_4_1", rec, fit, soc_initial=1.0, port_temp_k=296.15, sigma_v=0.002, sigma_t=0.05
    )
    truth = {"c_heat_j_per_k": 96.0, "r_skin_k_per_w": 10.0, "rc_discharge[0].r_ohm": 0.005,
             "rc_discharge[0].tau_s": 20.0}  # fmt: skip
    for k, v in truth.items():
        assert res.values[k] == pytest.approx(v, rel=0.05), k
        assert abs(res.values[k] - v) < 4 * res.std_errors[k] + 1e-12, k
    assert res.rmse["voltage_v"] < 0.003 and res.rmse["temp_k"] < 0.08
    out = res.save(tmp_path / "fit")
    assert {f.name for f in out.iterdir()} == {"fit.json", "timeseries.csv", "overlay.png", ".hevsim-results"}


def test_test_file_errors(tmp_path: Path) -> None:
    f = tmp_path / "t.csv"
    f.write_text("time_s,current_a,voltage_v\n0,1,3.7\n1,1,3.6\n2,1,3.6\n")
    with pytest.raises(InputError, match="temp_k"):
        CellTestRecord.from_csv(f)
    f.write_text("time_s,current_a,voltage_v,temp_k\n0,1,3.7,300\n1,1,3.6,300\n2,1,3.6,300\n7,1,3.6,300\n")
    with pytest.raises(InputError, match=r"not uniformly sampled: step 5\.0 s after 2\.0 s"):
        CellTestRecord.from_csv(f)
    rec = _synthetic(noise=False)
    with pytest.raises(InputError, match="not fittable"):
        calibrate("thesis_table_4_1", rec, {"colour": (1.0, 0.0, 2.0)})
    with pytest.raises(InputError, match="RC element"):
        calibrate("thesis_table_4_1", rec, {"rc_charge[3].r_ohm": (0.01, 0.0, 1.0)})
    with pytest.raises(InputError, match="lower < upper"):
        calibrate("thesis_table_4_1", rec, {"c_heat_j_per_k": (1.0, 5.0, 2.0)})


def test_calibrate_and_cell_commands(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import json

    import pandas as pd

    from hevsim.cli import main

    rec = _synthetic(noise=False)
    csv = tmp_path / "test.csv"
    cols = {
        "time_s": rec.time_s,
        "current_a": rec.current_a,
        "voltage_v": rec.voltage_v,
        "temp_k": rec.temp_k,
    }
    pd.DataFrame(cols).to_csv(csv, index=False)
    out = tmp_path / "fit"
    args = ["calibrate", "thesis_table_4_1", str(csv), "--fit", "c_heat_j_per_k=60,10,500"]
    assert main([*args, "--ambient-c", "23", "--out", str(out)]) == 0
    fit = json.loads((out / "fit.json").read_text())
    assert fit["values"]["c_heat_j_per_k"] == pytest.approx(96.0, rel=1e-3)
    assert "RMSE" in capsys.readouterr().out
    assert main([*args[:-1], "c_heat=1,2", "--out", str(tmp_path / "bad")]) == 2
    assert "NAME=INITIAL,LOWER,UPPER" in capsys.readouterr().err
    root = Path(__file__).resolve().parents[1]
    assert main(["cell", str(root / "examples" / "cell.toml"), "--out", str(tmp_path / "cell")]) == 0
    assert (tmp_path / "cell" / "timeseries.csv").is_file()

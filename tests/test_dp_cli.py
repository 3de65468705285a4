"""`hevsim optimize` and `hevsim compare`: results folders, tables, infeasible runs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hevsim.cli import main

ROOT = Path(__file__).resolve().parents[1]
PARALLEL = ROOT / "examples" / "parallel_hev.toml"
SERIES = ROOT / "examples" / "series_hev.toml"


def test_optimize_writes_results_and_plots(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "opt"
    args = ["optimize", str(PARALLEL), "--cycle", "fu505", "--out", str(out), "--soc-points", "101"]
    assert main([*args, "--input-points", "101"]) == 0
    for name in ("timeseries.parquet", "metrics.json", "costate.csv", "cost_to_go.npz",
                 "soc_trajectory.png", "power_split.png", "gear.png", "cost_to_go.png",
                 "engine_operating_points.png", "operating_points_by_gear.png"):  # fmt: skip
        assert (out / name).is_file(), name
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["mpg"]["value"] > 0 and metrics["co2_g_per_km"]["unit"] == "g/km"
    costate = pd.read_csv(out / "costate.csv")
    # more charge never costs fuel; inside the final window at the end it is free
    assert (costate["costate_kg_per_soc"] <= 0).all()
    assert costate["costate_kg_per_soc"].median() < 0
    assert "DP optimum" in capsys.readouterr().out
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_compare_table_reports_infeasible_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from hevsim.cycles import load_cycle

    fast = load_cycle("fu505")
    csv = tmp_path / "fast.csv"
    pd.DataFrame({"time_s": fast.time_s, "speed_mps": fast.speed_mps * 3.0}).to_csv(csv, index=False)
    out = tmp_path / "cmp"
    args = ["compare", str(PARALLEL), str(SERIES), "--cycles", f"fu505,{csv}", "--out", str(out)]
    assert main([*args, "--soc-points", "81", "--input-points", "61", "--soc-initial", "0.7"]) == 0
    table = pd.read_csv(out / "comparison.csv")
    assert len(table) == 4
    ok = table[table["cycle"] == "fu505"]
    assert np.isfinite(ok["mpg"]).all() and (ok["compute_time_s"] > 0).all()
    # equal terms: both vehicles start at 0.7 and sustain their charge
    assert np.allclose(ok["soc_initial"], 0.7)
    assert (abs(ok["soc_final"] - 0.7) <= 0.005 + 1e-9).all()
    bad = table[table["cycle"] != "fu505"]
    assert bad["mpg"].isna().all() and bad["note"].str.contains("cannot follow").all()
    text = (out / "comparison.md").read_text()
    assert "cannot follow the cycle" in text and "| parallel |" in text
    assert "MPG" in capsys.readouterr().out


def test_optimize_bad_config_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "car.toml"
    bad.write_text(PARALLEL.read_text() + "\n[nonsense]\n")
    assert main(["optimize", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "nonsense" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_simulate_replays_dp_schedule(tmp_path: Path) -> None:
    """The DP optimum of the series HEV, replayed by the forward simulator, beats the rules."""
    opt = tmp_path / "opt"
    assert main(["optimize", str(SERIES), "--cycle", "fu505", "--out", str(opt), "--no-plots"]) == 0
    rep, rule = tmp_path / "rep", tmp_path / "rule"
    sched = ["--schedule", str(opt / "timeseries.csv")]
    assert main(["simulate", str(SERIES), "--cycle", "fu505", "--out", str(rep), "--no-plots", *sched]) == 0
    assert main(["simulate", str(SERIES), "--cycle", "fu505", "--out", str(rule), "--no-plots"]) == 0

    def fuel_eq(folder: Path) -> float:
        return float(json.loads((folder / "metrics.json").read_text())["fuel_equivalent_kg"]["value"])

    dp = fuel_eq(opt)
    assert dp <= fuel_eq(rep) <= fuel_eq(rule)
    # --replay: the DP's decisions applied as its quasi-static model took them burn its fuel (to
    # the round-off of the CSV: the API test, tests/test_dp_vehicle_series.py, holds 1e-9)
    exact = tmp_path / "exact"
    assert main(["simulate", str(SERIES), "--cycle", "fu505", "--out", str(exact), "--no-plots", *sched,
                 "--replay"]) == 0  # fmt: skip
    fuel = json.loads((exact / "metrics.json").read_text())["fuel_kg"]["value"]
    assert fuel == pytest.approx(json.loads((opt / "metrics.json").read_text())["fuel_kg"]["value"], rel=1e-7)


def test_replay_without_schedule_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", str(SERIES), "--replay", "--out", str(tmp_path / "o")]) == 2
    assert "--schedule" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()

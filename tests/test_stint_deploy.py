"""A stint whose laps drive the optimal deployment, re-solved with the BMS's limits at the start
of each lap (issue 29 item 4 with item 3): :mod:`hevsim.optimal.stint_deploy`.

The small pack of tests/test_stint.py (the shipped car, one representative cell per module) on
the handling circuit at 2 m steps, the deployment problem at 10 m, charge-sustaining. Derated:
soaked at 46 degC with the cooling off (the BMS derates from 45 degC), 3 laps. Not derated:
twice the cells in parallel at the file's ambient."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from tests.test_stint import ROOT, STEP_M, small_car

from hevsim import tracks
from hevsim.cli import main
from hevsim.config import load_vehicle_config
from hevsim.optimal import lap_deploy as D
from hevsim.optimal.stint_deploy import simulate_stint_optimized
from hevsim.sim.stint import stint_vehicle

pytest.importorskip("cvxpy")

HOT = {"ambient_temp_c": 46.0, "soak": True, "cooling_off": True}
"""A stint that derates: the pack soaked above the BMS's derating onset, no cooling."""


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    cfg = load_vehicle_config(small_car(tmp_path_factory.mktemp("stint_deploy")))
    track = tracks.load_track("handling", step_m=STEP_M)
    soc0 = cfg.simulation.soc_initial
    vehicle = stint_vehicle(cfg, soc0)
    prob, _ = D.build_problem(cfg, track.resampled(10.0), step_m=10.0, soc=soc0)
    return cfg, track, vehicle, prob


@pytest.fixture(scope="module")
def hot(setup):  # type: ignore[no-untyped-def]
    cfg, track, vehicle, prob = setup
    kw = {"problem": prob, "vehicle": vehicle, "step_m": STEP_M, **HOT}
    once = simulate_stint_optimized(cfg, track, 3, reoptimize_rtol=math.inf, **kw)
    again = simulate_stint_optimized(cfg, track, 3, **kw)
    return once, again


def test_reoptimised_stint_is_not_slower_and_faster_where_the_derate_binds(hot) -> None:  # type: ignore[no-untyped-def]
    once, again = hot
    a, b = once.laps, again.laps
    assert once.summary["deploy_solves"] == 1
    assert list(b["reoptimized"]) == [1, 1, 1]  # the limit falls lap after lap
    assert np.all(b["lap_time_s"].to_numpy() <= a["lap_time_s"].to_numpy() + 1e-9)
    # where the lap-start limit is below the limit the held map was solved for, it binds
    binds = a["lap_start_discharge_limit_kw"] < a["deploy_map_max_kw"] * 0.98
    assert binds.sum() >= 2, a[["lap_start_discharge_limit_kw", "deploy_map_max_kw"]]
    gain = (a["lap_time_s"] - b["lap_time_s"])[binds].to_numpy()
    assert np.all(gain > 0.02), gain  # measured 0.05-0.13 s
    assert again.summary["total_time_s"] < once.summary["total_time_s"] - 0.05


def test_reoptimised_deployment_respects_the_derated_limits(hot, setup) -> None:  # type: ignore[no-untyped-def]
    again = hot[1]
    lp = again.laps
    # the map was solved for this lap's limit, which fell below the first lap's
    assert np.allclose(lp["deploy_discharge_limit_kw"], lp["lap_start_discharge_limit_kw"], rtol=1e-12)
    assert lp["deploy_discharge_limit_kw"].iloc[-1] < 0.8 * lp["deploy_discharge_limit_kw"].iloc[0]
    assert np.all(lp["deploy_map_max_kw"] <= lp["deploy_discharge_limit_kw"] * (1.0 + 1e-4))
    # the lap's deployment (its battery chemical power) keeps to it, and no pack step's current
    # exceeds its BMS limit
    for k, lap in enumerate(again.lap_results):
        chem = lap.timeseries["battery_chemical_power_w"].to_numpy()
        assert chem.max() <= lp["deploy_discharge_limit_kw"].iloc[k] * 1e3 * (1.0 + 1e-3)
    ts = again.timeseries
    assert np.all(ts["current_a"] <= ts["discharge_available_a"] + 1e-9)


def test_problem_with_battery_limits_dp_and_convex_agree(setup) -> None:  # type: ignore[no-untyped-def]
    """The problem with a binding discharge and charge limit: the two solvers (independent
    methods) agree within 0.1 %, keep to both limits and are slower than without them."""
    prob = setup[3]
    free = D.solve_convex(prob)
    lim = prob.with_battery(discharge_max_w=60e3, charge_max_w=40e3)
    cvx, dp = D.solve_convex(lim), D.solve_dp(lim)
    assert abs(dp.lap_time_s / cvx.lap_time_s - 1.0) < 1e-3
    assert cvx.lap_time_s > free.lap_time_s + 0.05
    for res in (cvx, dp):
        p = res.battery_power_w
        assert p.max() <= 60e3 * (1 + 1e-4) and p.min() >= -40e3 * (1 + 1e-4), (p.max(), p.min())
        assert abs(res.battery_energy_j.sum() - lim.budget_j) < 2e3
    assert free.battery_power_w.max() > 100e3  # without the limit it deploys more


def test_dp_stint_respects_the_derated_limit(setup) -> None:  # type: ignore[no-untyped-def]
    """The DP as the stint's solver: the same lap-start limit, kept, and the lap within 0.1 %
    of the convex one (the two solvers agree on the problem)."""
    cfg, track, vehicle, prob = setup
    kw = {"problem": prob, "vehicle": vehicle, "step_m": STEP_M, **HOT}
    dp = simulate_stint_optimized(cfg, track, 1, method="dp", **kw).laps
    cvx = simulate_stint_optimized(cfg, track, 1, **kw).laps
    assert dp["lap_start_discharge_limit_kw"].iloc[0] == cvx["lap_start_discharge_limit_kw"].iloc[0]
    assert dp["deploy_map_max_kw"].iloc[0] <= dp["deploy_discharge_limit_kw"].iloc[0] * (1.0 + 1e-9)
    assert abs(dp["deploy_lap_time_s"].iloc[0] / cvx["deploy_lap_time_s"].iloc[0] - 1.0) < 1e-3
    assert abs(dp["lap_time_s"].iloc[0] / cvx["lap_time_s"].iloc[0] - 1.0) < 1e-2


def test_energy_balance_closes_per_lap(hot) -> None:  # type: ignore[no-untyped-def]
    for res in hot:
        bal = res.laps["energy_balance_relative"].to_numpy()
        assert np.all(np.abs(bal) < 1e-9), bal
        assert np.all(res.laps["pack_throughput_j"] > 1e6)


def test_no_derating_same_laps_with_and_without_reoptimisation(tmp_path: Path) -> None:
    cfg = load_vehicle_config(small_car(tmp_path, n_parallel=6))
    track = tracks.load_track("handling", step_m=STEP_M)
    soc0 = cfg.simulation.soc_initial
    kw = {"vehicle": stint_vehicle(cfg, soc0), "step_m": STEP_M}
    prob, _ = D.build_problem(cfg, track.resampled(10.0), step_m=10.0, soc=soc0)
    once = simulate_stint_optimized(cfg, track, 2, problem=prob, reoptimize_rtol=math.inf, **kw)
    every = simulate_stint_optimized(cfg, track, 2, problem=prob, reoptimize_rtol=0.0, **kw)
    assert every.summary["deploy_solves"] == 2 and once.summary["deploy_solves"] == 1
    assert every.laps["derated_s"].sum() == 0.0
    d = np.abs(every.laps["lap_time_s"].to_numpy() - once.laps["lap_time_s"].to_numpy())
    assert d.max() < 1e-6, d  # measured 0 (the same map: the limits never bind)
    assert np.allclose(every.laps["soc_end"], once.laps["soc_end"], rtol=0, atol=1e-9)


def test_cli_stint_optimize(setup, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    car = small_car(tmp_path)
    out = tmp_path / "out"
    argv = ["stint", str(car), "handling", "--laps", "1", "--step", "2", "--optimize", "convex"]
    assert main([*argv, "--ambient", "46", "--soak", "--cooling-off", "--no-plots", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "reoptimized" in text
    import pandas as pd

    laps = pd.read_csv(out / "laps.csv")
    assert laps["reoptimized"].tolist() == [1]
    assert main([*argv, "--reoptimize-rtol", "-1", "--out", str(tmp_path / "x")]) == 2
    assert "--reoptimize-rtol" in capsys.readouterr().err
    table_car = str(ROOT / "examples" / "high_performance_parallel_hev.toml")
    bad = ["stint", table_car, "handling", "--laps", "1", "--optimize", "convex"]
    bad += ["--out", str(tmp_path / "y")]
    assert main(bad) == 2
    assert "battery.model" in capsys.readouterr().err

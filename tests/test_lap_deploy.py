"""Optimal deployment over the lap (issue 29 item 3): convex and DP on the same problem,
budgets, rule-based peers, replay in the QSS lap, bad input."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from hevsim.errors import ConfigError, InputError
from hevsim.optimal import lap_deploy as D

REPO = Path(__file__).resolve().parents[1]
CFG = REPO / "examples" / "high_performance_parallel_hev.toml"
TRACK = "handling"
STEP = 10.0


@pytest.fixture(scope="module")
def built():
    return D.build_problem(CFG, TRACK, step_m=STEP, budget_kj=0.0)


@pytest.fixture(scope="module")
def convex(built):
    return D.solve_convex(built[0])


@pytest.fixture(scope="module")
def dp(built):
    return D.solve_dp(built[0])


def test_dp_and_convex_agree_within_0p1_percent(convex, dp):
    assert convex.info["status"] == "optimal"
    rel = abs(dp.lap_time_s / convex.lap_time_s - 1.0)
    assert rel < 1e-3, (dp.lap_time_s, convex.lap_time_s)
    # the convex relaxation of the step time is tight
    assert abs(convex.info["relaxation_gap_s"]) < 1e-3 * convex.lap_time_s


def test_dp_converges_with_the_speed_grid(built, convex):
    """Coarser DP (fewer passes) is further from the convex optimum; each is never faster
    than it by more than the solver tolerance (the convex optimum is a lower bound)."""
    prob = built[0]
    t = [D.solve_dp(prob, passes=p).lap_time_s for p in (1, 3)]
    assert t[0] >= t[1] - 1e-9 * t[1]
    assert abs(t[1] / convex.lap_time_s - 1) < 5e-3
    assert min(t) >= convex.lap_time_s * (1 - 2e-4)


def test_budget_met(built, convex, dp):
    prob = built[0]
    for res in (convex, dp):
        net = float(res.battery_energy_j.sum())
        assert net <= prob.budget_j + 50.0  # J: solver tolerance
        assert net >= prob.budget_j - 5e3  # and the budget is used (charge-sustaining)
    # the map's powers respect the machine limit and the energy window
    for res in (convex, dp):
        pm = res.machine_work_j / res.dt_s
        assert np.all(np.abs(pm) <= prob.machine_power_i_w * (1 + 1e-6) + 1.0)


def test_net_deployment_budget_is_faster(built, convex):
    """A positive net deployment (the battery gives 300 kJ per lap) is faster than
    charge-sustaining and uses its budget."""
    import dataclasses

    prob = dataclasses.replace(built[0], budget_j=300e3)
    res = D.solve_convex(prob)
    assert res.lap_time_s < convex.lap_time_s - 0.05
    net = float(res.battery_energy_j.sum())
    assert 290e3 <= net <= 300e3 + 50.0


@pytest.mark.parametrize("rule", ["flat", "straights", "late"])
def test_optimal_never_slower_than_rule_based(built, convex, rule):
    """Rule-based deployments on the same model that meet the same budget (charge-sustaining):
    the fastest level of each rule is still slower than the optimum."""
    prob = built[0]
    best = np.inf
    for level in np.linspace(-1.0, 1.0, 41):
        t, net = D.simulate_rule(prob, D.rule_based(prob, rule, float(level)))
        if net <= prob.budget_j:
            best = min(best, t)
    assert np.isfinite(best)
    assert convex.lap_time_s <= best + 1e-6


def test_replay_in_the_qss_lap(built, convex):
    """The map replayed in the QSS lap: the battery never exceeds the map's power, and the
    lap time lies between the lap without the battery and the lap without a limit."""
    from hevsim.sim.lap import simulate_lap
    from hevsim.tracks import load_track

    veh = built[1]
    trk = load_track(TRACK, step_m=STEP)
    rep = D.replay_qss(CFG, trk, convex, step_m=STEP, vehicle=veh)
    df = convex.frame()
    lim = np.interp(
        trk.distance_m, df["distance_m"], np.maximum(df["battery_power_w"], 0), period=trk.length_m
    )
    p_b = rep.timeseries["battery_chemical_power_w"].to_numpy()
    assert np.all(p_b <= lim * (1 + 1e-6) + 1.0)
    none = simulate_lap(CFG, trk, step_m=STEP, battery_power_max_w=0.0, vehicle=veh, operating_points=False)
    full = simulate_lap(CFG, trk, step_m=STEP, vehicle=None, operating_points=False)
    assert full.lap_time_s < rep.lap_time_s < none.lap_time_s


def test_cli_optimize_and_deploy_replay(tmp_path, capsys):
    from hevsim.cli import main

    out = tmp_path / "opt"
    rc = main(["lap", str(CFG), TRACK, "--optimize", "dp", "--step", "10", "--out", str(out), "--no-plots"])
    assert rc == 0
    assert (out / "deploy_map.csv").exists() and (out / "lap.csv").exists()
    out2 = tmp_path / "replay"
    rc = main(
        ["lap", str(CFG), TRACK, "--step", "10", "--deploy", str(out / "deploy_map.csv"), "--out", str(out2)]
    )
    assert rc == 0
    import json

    s1 = json.loads((out / "summary.json").read_text())
    s2 = json.loads((out2 / "summary.json").read_text())
    assert s2["lap_time_s"] == pytest.approx(s1["lap_time_s"], rel=1e-6)


def test_unreachable_budget_exits_2_with_location(tmp_path, capsys):
    from hevsim.cli import main

    rc = main(
        [
            "lap",
            str(CFG),
            TRACK,
            "--optimize",
            "dp",
            "--budget-kj",
            "-6000",
            "--step",
            "10",
            "--out",
            str(tmp_path / "x"),
        ]
    )
    assert rc == 2
    err = capsys.readouterr().err
    assert "budget -6000.0 kJ" in err and "distance" in err


def test_bad_deploy_map(tmp_path, built):
    from hevsim.tracks import load_track

    trk = load_track(TRACK, step_m=STEP)
    p = tmp_path / "m.csv"
    p.write_text("distance_m,power\n0,1\n10,2\n")
    with pytest.raises(InputError, match="battery_power_w"):
        D.read_deploy_map(p, trk)
    p.write_text("distance_m,battery_power_w\n0,1\n1e9,2\n")
    with pytest.raises(InputError, match="inside the track"):
        D.read_deploy_map(p, trk)


def test_without_cvxpy_names_the_extra(monkeypatch, built):
    monkeypatch.setitem(sys.modules, "cvxpy", None)
    with pytest.raises(ConfigError, match=r"hevsim\[lap\]"):
        D.solve_convex(built[0])


def test_replay_in_the_forward_model(convex):
    """The optimal speed trace driven by the forward model's driver, the supervisor following
    the map's battery power: the lap (the time to cover its length) within 1 % and the net
    battery (chemical) energy per lap within 2 % of the energy the map deploys (issue 29; the
    follower before the fix: 7.9 %, measured now 0.02 %). The energy deployed and harvested
    each within 10 % (measured +5.9 %: docs/lap.md "Replays")."""
    out = D.replay_forward(CFG, convex)
    assert out["forward_lap_time_s"] == pytest.approx(out["optimal_lap_time_s"], rel=0.01)
    dep = out["optimal_battery_deployed_j"]
    assert abs(out["forward_battery_chemical_net_j"] - out["optimal_battery_net_j"]) <= 0.02 * dep
    assert out["forward_battery_chemical_deployed_j"] == pytest.approx(dep, rel=0.10)
    harvested = out["optimal_battery_harvested_j"]
    assert out["forward_battery_chemical_harvested_j"] == pytest.approx(harvested, rel=0.10)
    # the per-step chemical energy sums to the run's own SOC metric
    net = out["forward_battery_net_j"]
    assert out["forward_battery_chemical_net_j"] == pytest.approx(net, abs=0.02 * dep)


def test_fuel_budget_binds(built, convex):
    """A fuel budget 3 % below the fuel of the unconstrained optimum is met and costs time."""
    import dataclasses

    prob = built[0]
    fuel = float(np.sum(convex.engine_work_j)) / prob.engine_efficiency
    res = D.solve_convex(dataclasses.replace(prob, fuel_budget_j=0.97 * fuel))
    assert float(np.sum(res.engine_work_j)) / prob.engine_efficiency <= 0.97 * fuel * (1 + 1e-6)
    assert res.lap_time_s > convex.lap_time_s + 1e-3
    assert float(res.battery_energy_j.sum()) <= prob.budget_j + 50.0

"""DP energy management of the appendix's parallel HEV: consistency, limits, costate, errors.

The replay is independent of the DP formulation's code: it drives the optimal gear and
throttle through the component methods one step at a time, at the actual SOC, with the
power flow written out here (eq 32 road load, gearbox, final drive, machine coupling,
battery eqs 13 and 21).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from tests.dp_replay_helpers import assert_replay_matches_dp

import hevsim.optimal._solver as dp_solver
from hevsim.components.electric_machine import ElectricMachine
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.errors import ConfigError, DPInfeasibleError, DPSetupError
from hevsim.optimal import ARCHITECTURES, OptimizationResult, optimize
from hevsim.parallel import ParallelHEV, build_parallel_hev, load_parallel_config

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "parallel_hev.toml"
N_SOC, N_THR = 201, 101  # coarser than the appendix's 400 x 400 to keep the tests quick


@pytest.fixture(scope="module")
def hev() -> ParallelHEV:
    return build_parallel_hev(load_parallel_config(EXAMPLE))


@pytest.fixture(scope="module")
def window_run(hev: ParallelHEV) -> OptimizationResult:
    """The appendix problem (SOC 0.8 -> final window 0.7-0.8) on FU505."""
    return optimize(hev, "fu505", soc_grid_points=N_SOC, input_grid_points=N_THR, store_cost_to_go=True)


@pytest.fixture(scope="module")
def sustain_run(hev: ParallelHEV) -> OptimizationResult:
    """Charge sustaining from SOC 0.6 within 0.005 on FU505."""
    return optimize(
        hev, "fu505", soc_grid_points=N_SOC, input_grid_points=N_THR, soc_initial=0.6, final_soc="sustain"
    )


def replay(hev: ParallelHEV, cycle: DriveCycle, gear: np.ndarray, throttle: np.ndarray, soc0: float):
    """Fuel [kg], SOC trajectory and per-step operating points of a gear/throttle schedule."""
    t, v, grade = cycle.time_s, cycle.speed_mps, cycle.grade
    soc = [soc0]
    fuel = 0.0
    rows = []
    r = hev.tire.radius_m
    for k in range(t.size - 1):
        dt = t[k + 1] - t[k]
        v_mid = 0.5 * (v[k] + v[k + 1])
        accel = (v[k + 1] - v[k]) / dt
        force = float(hev.body.road_load_force(v_mid, accel, 0.5 * (grade[k] + grade[k + 1])))
        wheel_torque = force * r if v_mid > 0 else 0.0
        w_fd = v_mid / r * hev.final_drive.ratio
        t_fd = float(hev.final_drive.input_torque(wheel_torque))
        t_e = w_e = 0.0
        t_e_fd = 0.0
        if gear[k] > 0 and throttle[k] > 0:
            g = hev.gears[int(gear[k]) - 1]
            w_e = w_fd * g.ratio
            t_e = float(hev.engine.torque(throttle[k], w_e))
            fuel += float(hev.engine.fuel_rate(t_e, w_e)) * dt
            t_e_fd = float(g.output_torque(t_e))
        w_em = w_fd * hev.motor_coupling.ratio
        t_em = float(hev.motor_coupling.input_torque(t_fd - t_e_fd))
        t_max, t_min = (float(x) for x in hev.motor.limits(w_em))
        if t_em < 0 and v_mid > 0:
            t_em = max(t_em, t_min)
        p_el = float(hev.motor.electrical_power(t_em, w_em))
        current = float(hev.battery.current(p_el, soc[-1]))
        soc.append(soc[-1] + float(hev.battery.soc_rate(current)) * dt)
        rows.append((w_e, t_e, w_em, t_em, t_max, t_min, current))
    return fuel, np.array(soc), np.array(rows)


def _assert_replay_reproduces(hev: ParallelHEV, run: OptimizationResult) -> None:
    """Replaying ``run``'s gears and throttles on ``hev`` gives its (positive) fuel and SOC."""
    ts = run.timeseries
    gear = ts["gear"].to_numpy()[:-1]
    thr = ts["engine_throttle"].to_numpy()[:-1]
    fuel, soc, _ = replay(hev, run.cycle, gear, thr, float(ts["soc"].iloc[0]))
    assert run.value("fuel_kg") > 0
    assert_replay_matches_dp(run, fuel, soc)


def test_replay_reproduces_dp_fuel_and_soc(hev: ParallelHEV, window_run: OptimizationResult) -> None:
    _assert_replay_reproduces(hev, window_run)


@pytest.mark.parametrize("scale", [0.7, 1.4])
def test_replay_with_a_scaled_map_motor(hev: ParallelHEV, scale: float) -> None:
    """Issue 18: a sized map machine (efficiency map read at torque / torque_scale) replays
    within the same bound as the example's constant-efficiency machine."""
    folder = ROOT / "src" / "hevsim" / "data" / "components" / "motors" / "honda_pm49"
    motor = ElectricMachine.from_directory(folder, torque_scale=scale)
    scaled = dataclasses.replace(hev, motor=motor)
    run = optimize(scaled, "fu505", soc_grid_points=101, input_grid_points=51)
    _assert_replay_reproduces(scaled, run)


def test_final_soc_targets(window_run: OptimizationResult, sustain_run: OptimizationResult) -> None:
    socf = window_run.value("soc_final")
    assert 0.7 - 1e-9 <= socf <= 0.8 + 1e-9
    assert window_run.value("soc_initial") == pytest.approx(0.8)
    # the battery is worth using: the optimum ends at the bottom of the window
    assert socf == pytest.approx(0.7, abs=2e-3)
    s0, sf = sustain_run.value("soc_initial"), sustain_run.value("soc_final")
    assert abs(sf - s0) <= 0.005 + 1e-9
    # SOC-corrected, the two runs agree to a few percent (the battery energy is priced)
    assert sustain_run.value("mpgge") == pytest.approx(window_run.value("mpgge"), rel=0.15)


def test_every_component_limit_holds(hev: ParallelHEV, window_run: OptimizationResult) -> None:
    ts = window_run.timeseries.iloc[:-1]
    eng = hev.engine
    on = ts["engine_on"].to_numpy()
    w_e = ts["engine_speed_radps"].to_numpy()[on]
    t_e = ts["engine_torque_nm"].to_numpy()[on]
    assert on.any() and (~on).any()
    assert np.all(w_e >= eng.stall_speed_radps) and np.all(w_e <= eng.redline_radps)
    assert np.all(t_e <= eng.max_torque(w_e) * (1 + 1e-9))
    assert np.all(ts["gear"].to_numpy()[on] >= 1) and np.all(ts["gear"].to_numpy()[~on] == 0)
    t_max, t_min = hev.motor.limits(ts["motor_speed_radps"].to_numpy())
    t_em = ts["motor_torque_nm"].to_numpy()
    assert np.all(t_em <= t_max * (1 + 1e-9)) and np.all(t_em >= t_min * (1 + 1e-9))
    i = ts["battery_current_a"].to_numpy()
    assert np.all(i <= hev.battery.max_discharge_current_a * (1 + 1e-6))
    assert np.all(i >= -hev.battery.max_charge_current_a * (1 + 1e-6))
    soc = window_run.timeseries["soc"].to_numpy()
    assert soc.min() >= 0.4 - 1e-9 and soc.max() <= 0.8 + 1e-9
    # at a standstill the engine is off and nothing flows
    stopped = (ts["speed_mps"].to_numpy() == 0) & (window_run.timeseries["speed_mps"].to_numpy()[1:] == 0)
    assert np.all(~on[stopped]) and np.all(ts["fuel_rate_gps"].to_numpy()[stopped] == 0)
    # power balance: engine + machine + friction meet the wheel demand (gearbox and machine losses)
    p_req = ts["power_required_w"].to_numpy()
    assert np.all(ts["friction_brake_power_w"].to_numpy() >= 0)
    assert np.all(ts["friction_brake_power_w"].to_numpy()[p_req > 0] == 0)


def test_costate_sign_magnitude_and_slope(hev: ParallelHEV, window_run: OptimizationResult) -> None:
    ts = window_run.timeseries
    lam = ts["costate_kg_per_soc"].to_numpy()[:-1]
    s = ts["equivalence_factor"].to_numpy()[:-1]
    ok = np.isfinite(lam)
    assert ok.mean() > 0.95
    assert np.all(lam[ok] <= 0)  # more charge, less fuel to go
    med = float(np.median(s[ok]))
    assert 1.5 < med < 4.5  # a diesel and a 60 % machine: between 1/0.6/eta_e and 1/(eta_e 0.6)
    assert window_run.value("equivalence_factor_median") == pytest.approx(med)
    # the costate at the start is the slope of the optimal cost in the initial SOC
    kw = {"soc_grid_points": N_SOC, "input_grid_points": N_THR, "final_soc": (0.6, 0.62)}
    r_lo = optimize(hev, "fu505", soc_initial=0.59, **kw)
    r_hi = optimize(hev, "fu505", soc_initial=0.61, **kw)
    r_mid = optimize(hev, "fu505", soc_initial=0.60, **kw)
    slope = (r_hi.dp.total_cost - r_lo.dp.total_cost) / 0.02
    lam0 = r_mid.timeseries["costate_kg_per_soc"].iloc[0]
    assert lam0 == pytest.approx(slope, rel=0.1)


def test_cost_to_go_kept_for_a_heat_map(window_run: OptimizationResult) -> None:
    ctg = window_run.cost_to_go
    assert ctg is not None and ctg.shape == (len(window_run.timeseries), N_SOC)
    assert window_run.soc_grid.shape == (N_SOC,)
    # x0 = 0.8 is the last node: the grid's cost-to-go estimate there and the cost of the
    # trajectory re-optimised at the actual (off-grid) states agree within grid error
    assert ctg[0, -1] == pytest.approx(window_run.dp.total_cost, rel=0.01)
    assert np.all(np.isfinite(ctg[-1][window_run.soc_grid >= 0.7 - 1e-12]))
    assert np.all(np.isinf(ctg[-1][window_run.soc_grid < 0.7 - 1e-12]))


def test_save_writes_atomically(window_run: OptimizationResult, tmp_path: Path) -> None:
    out = window_run.save(tmp_path / "run")
    names = {p.name for p in out.iterdir()}
    assert {"timeseries.parquet", "timeseries.csv", "metrics.json", "costate.csv", "metadata.json"} <= names
    assert "cost_to_go.npz" in names
    metrics = json.loads((out / "metrics.json").read_text())
    for key in ("fuel_kg", "fuel_l", "mpg", "l_per_100km", "mpgge", "co2_g_per_km", "soc_initial",
                "soc_final", "engine_on_time_s", "compute_time_s", "dp_total_cost"):  # fmt: skip
        assert set(metrics[key]) == {"value", "unit", "description"}
    window_run.save(tmp_path / "run", plots=True)  # replaces the folder, adds the figures
    assert {"soc_trajectory.png", "cost_to_go.png", "gear.png"} <= {p.name for p in out.iterdir()}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no temporary folders left


def test_hull_pruning_is_exact(hev: ParallelHEV, monkeypatch: pytest.MonkeyPatch) -> None:
    """The solver's convex-hull fast path gives the generic kernel's answer."""
    kw = {"soc_grid_points": 101, "input_grid_points": 61, "store_cost_to_go": True}
    cyc = load_cycle("udds").truncated(300.0)
    fast = optimize(hev, cyc, **kw)
    monkeypatch.setattr(dp_solver, "USE_HULL", False)
    slow = optimize(hev, cyc, **kw)
    assert fast.dp.total_cost == pytest.approx(slow.dp.total_cost, rel=1e-12)
    assert fast.cost_to_go is not None and slow.cost_to_go is not None
    assert np.array_equal(np.isfinite(fast.cost_to_go), np.isfinite(slow.cost_to_go))
    fin = np.isfinite(fast.cost_to_go)
    assert np.allclose(fast.cost_to_go[fin], slow.cost_to_go[fin], rtol=1e-12, atol=1e-15)


def test_example_file_loads_and_optimizes() -> None:
    cfg = load_parallel_config(EXAMPLE)
    assert cfg.gearbox.ratios == (3.78, 2.12, 1.36, 1.03, 0.84)
    assert cfg.body.mass_kg == 1389.0 and cfg.optimization.soc_grid_points == 400
    res = optimize(EXAMPLE, "fu505", soc_grid_points=101, input_grid_points=51)
    assert res.architecture == "parallel"
    assert 0.7 - 1e-9 <= res.value("soc_final") <= 0.8 + 1e-9
    assert 30 < res.value("mpg") < 200


@pytest.mark.parametrize(
    ("old", "new", "needle"),
    [
        ("mass_kg = 1389.0", "mass_kgg = 1.0", "key 'body.mass_kgg' is not known"),
        ("mass_kg = 1389.0", 'mass_kg = "heavy"', "key 'body.mass_kg'"),
        ("ratios = [3.78, 2.12, 1.36, 1.03, 0.84]", 'ratios = [3.0, "x"]', "key 'gearbox.ratios'[1]"),
        ("ratios = [3.78, 2.12, 1.36, 1.03, 0.84]", "ratios = 3.0", "key 'gearbox.ratios'"),
        ('model = "constant_efficiency"', 'model = "turbo"', "key 'motor.model'"),
        ("soc_min = 0.4 ", "soc_min = 0.9 ", "battery.soc_min"),
        ('name = "parallel_hev"', 'name = "parallel_hev"\ncolour = 1', "key 'colour' is not known"),
    ],
)
def test_bad_config_names_file_and_key(tmp_path: Path, old: str, new: str, needle: str) -> None:
    path = tmp_path / "bad.toml"
    text = EXAMPLE.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(ConfigError) as err:
        load_parallel_config(path)
    assert str(path) in str(err.value) and needle in str(err.value)
    with pytest.raises(ConfigError):
        optimize(path, "fu505")


def test_architecture_registry_and_dispatch(tmp_path: Path) -> None:
    assert set(ARCHITECTURES) >= {"parallel", "series"}
    path = tmp_path / "x.toml"
    path.write_text('[powertrain]\narchitecture = "planetary"\n')
    with pytest.raises(ConfigError, match="architecture"):
        optimize(path, "fu505")
    with pytest.raises(ConfigError, match="architecture"):
        optimize(42, "fu505")
    with pytest.raises(DPSetupError, match="final_soc"):
        optimize(load_parallel_config(EXAMPLE), "fu505", final_soc="sometimes")
    with pytest.raises(DPSetupError, match="soc_grid_points"):
        optimize(load_parallel_config(EXAMPLE), "fu505", soc_grid_points=1)


def test_cycle_too_fast_is_a_clear_error(hev: ParallelHEV) -> None:
    udds = load_cycle("udds")
    fast = DriveCycle("udds_x3", udds.time_s, 3.0 * udds.speed_mps)
    with pytest.raises(DPInfeasibleError) as err:
        optimize(hev, fast, soc_grid_points=51, input_grid_points=21)
    msg = str(err.value)
    assert "cannot follow drive cycle 'udds_x3'" in msg
    assert "step" in msg and "t = " in msg and "m/s" in msg
    assert "battery discharge current above 200 A" in msg or "machine torque" in msg


def test_steep_grade_is_a_clear_error(hev: ParallelHEV) -> None:
    t = np.arange(0.0, 61.0)
    v = np.minimum(t, 10.0)
    hill = DriveCycle("wall", t, v, grade=np.where(t > 30, 1.5, 0.0))
    with pytest.raises(DPInfeasibleError) as err:
        optimize(hev, hill, soc_grid_points=51, input_grid_points=21)  # 5 gears x 21 throttles
    msg = str(err.value)
    # step 30 climbs the mean grade 0.75 (feasible); step 31 the full 1.5 is too much
    assert "at step 31 (t = 31 to 32 s" in msg
    assert "grade 1.5" in msg and "required wheel force 11489 N" in msg
    assert "battery discharge current above 200 A (105 of 105 choices)" in msg


def test_soc_dependent_battery(hev: ParallelHEV) -> None:
    """A table battery (OCV and R vary with SOC) takes the general path: the model evaluates
    the battery on the whole (SOC x input) block; the replay still reproduces the DP."""
    cfg = hev.config.replace(**{
        "battery.model": "table", "battery.n_series": 234, "battery.soc_min": 0.4, "battery.soc_max": 0.8,
    })  # fmt: skip
    table_hev = build_parallel_hev(cfg)
    res = optimize(
        table_hev, "fu505", soc_grid_points=81, input_grid_points=41, soc_initial=0.6, final_soc="sustain"
    )
    assert res.metadata["battery_soc_invariant"] is False
    ts = res.timeseries
    gear = ts["gear"].to_numpy()[:-1]
    thr = ts["engine_throttle"].to_numpy()[:-1]
    fuel, soc, _ = replay(table_hev, res.cycle, gear, thr, 0.6)
    assert abs(fuel - res.value("fuel_kg")) <= 1e-9 * fuel
    assert np.max(np.abs(soc - ts["soc"].to_numpy())) < 1e-12
    assert abs(res.value("soc_final") - 0.6) <= 0.005 + 1e-9

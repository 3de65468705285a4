"""The compiled conventional-vehicle run equals the Python loop; the deceleration fuel cut."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from hevsim import config as C
from hevsim.cycles import DriveCycle
from hevsim.errors import ConfigError
from hevsim.sim.forward import simulate_conventional
from hevsim.sim.simulator import simulate_batch
from hevsim.units import RADPS_PER_RPM

ROOT = Path(__file__).resolve().parents[1]
CONVENTIONAL = ROOT / "examples" / "conventional_sedan.toml"
ENGINE_DIR = ROOT / "src" / "hevsim" / "data" / "components" / "engines" / "vw_1p9_tdi_ci67"
RTOL = 1e-9


def assert_same_run(a: Any, b: Any) -> None:
    """Two results have the same channels, events, audit terms and metrics (to 1e-9)."""
    ta, tb = a.timeseries, b.timeseries
    assert list(ta.columns) == list(tb.columns)
    for col in ta.columns:
        x, y = ta[col].to_numpy(), tb[col].to_numpy()
        if x.dtype.kind in "fc":
            scale = max(float(np.max(np.abs(y))), 1e-30)
            assert np.allclose(x, y, rtol=RTOL, atol=RTOL * scale), col
        else:
            assert (x == y).all(), col
    pd.testing.assert_frame_equal(a.events, b.events)
    assert a.energy_audit.keys() == b.energy_audit.keys()
    traction = b.value("traction_energy_j")
    for key, val in b.energy_audit.items():
        assert a.energy_audit[key] == pytest.approx(val, rel=RTOL, abs=RTOL * traction), key
    assert a.metrics.keys() == b.metrics.keys()
    for key, m in b.metrics.items():
        tol = 1e-6 if key.startswith("energy_audit_residual") else 0.0  # round-off [%]
        assert a.value(key) == pytest.approx(m["value"], rel=RTOL, abs=tol), key


@pytest.fixture(scope="module")
def cfg() -> Any:
    return C.load_vehicle_config(CONVENTIONAL)


@pytest.mark.parametrize("cycle", ["udds", "hwfet", "us06"])
def test_compiled_run_equals_the_python_loop(cfg: Any, cycle: str) -> None:
    fast = simulate_conventional(cfg, cycle)
    ref = simulate_conventional(cfg, cycle, compiled=False)
    assert fast.metadata["compiled"] and not ref.metadata["compiled"]
    assert_same_run(fast, ref)
    assert abs(fast.energy_audit["residual"]) < 1e-9 * fast.value("traction_energy_j")
    assert fast.timeseries["fuel_cut"].any() and fast.timeseries["gear"].nunique() == len(cfg.gearbox.ratios)


def test_compiled_run_equals_the_python_loop_when_the_car_cannot_follow(
    cfg: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    weak = cfg.replace(**{"engine.torque_scale": 0.35, "controller.stop_start": "on"})
    fast = simulate_conventional(weak, "us06")
    monkeypatch.setenv("HEVSIM_FORWARD", "python")  # the environment switch selects the loop too
    ref = simulate_conventional(weak, "us06")
    assert not ref.metadata["compiled"] and fast.metadata["compiled"]
    assert ref.value("traction_limited_s") > 20.0  # the driver's bisection ran
    assert_same_run(fast, ref)


def test_compiled_batch_equals_runs_one_by_one(cfg: Any) -> None:
    variants = {"body.mass_kg": [1300.0, 1474.18, 1700.0], "controller.upshift_rpm": [2200.0, 2400.0, 2600.0]}
    fast = simulate_batch(cfg, variants, "udds")
    ref = simulate_batch(cfg, variants, "udds", compiled=False)
    assert list(fast.table.columns) == list(ref.table.columns)
    for col in ref.table.columns:
        tol = 1e-6 if col == "energy_audit_residual_traction_pct" else 0.0
        assert fast.table[col].to_numpy() == pytest.approx(ref.table[col].to_numpy(), rel=RTOL, abs=tol), col
    assert np.all(np.diff(fast.table["fuel_kg"].to_numpy()) > 0)
    # a key the compiled batch does not vary runs variant by variant, same numbers
    other = simulate_batch(cfg, {"gearbox.efficiency": [0.95]}, "udds")
    assert other.table["fuel_kg"].iloc[0] == pytest.approx(ref.table["fuel_kg"].iloc[1], rel=0.05)


def _coast_cycle() -> DriveCycle:
    """Accelerate to 25 m/s, cruise, then decelerate at 1.5 m/s² to a stop."""
    up = np.linspace(0.0, 25.0, 26)
    cruise = np.full(20, 25.0)
    down = np.clip(25.0 - 1.5 * np.arange(1, 19), 0.0, None)
    v = np.concatenate([up, cruise, down, np.zeros(5)])
    t = np.arange(v.size, dtype=np.float64)
    return DriveCycle("coast_down", t, v, np.zeros_like(v))


def test_fuel_cut_burns_no_fuel_and_the_engine_drags_with_its_closed_throttle_torque(cfg: Any) -> None:
    cyc = _coast_cycle()
    csv = np.loadtxt(ENGINE_DIR / "closed_throttle_torque.csv", delimiter=",", skiprows=1)
    ratios, eff = np.asarray(cfg.gearbox.ratios), cfg.gearbox.efficiency
    fd, fd_eff, radius = cfg.final_drive.ratio, cfg.final_drive.efficiency, cfg.tire.radius_m
    for compiled in (True, False):
        r = simulate_conventional(cfg, cyc, compiled=compiled)
        ts = r.timeseries.iloc[:-1]
        # expected independently: braking, gearbox input in [1200 rpm, redline], and the demand
        # at the wheels at least the engine's closed-throttle drag carried through the gears
        w_in = ts["gearbox_input_speed_radps"].to_numpy()
        drag_wheel = np.interp(w_in, csv[:, 0], csv[:, 1]) * ratios[ts["gear"] - 1] / eff * fd / fd_eff
        speed_ok = (w_in >= 1200.0 * RADPS_PER_RPM) & (w_in <= cfg.engine.redline_rpm * RADPS_PER_RPM)
        expected = (ts["wheel_force_n"] < 0) & speed_ok & (ts["wheel_force_n"] * radius <= drag_wheel)
        assert expected.sum() >= 8 and (~expected & (ts["wheel_force_n"] < 0)).sum() >= 1
        assert (ts["fuel_cut"] == expected).all()
        cut = ts[expected]
        assert (cut["fuel_rate_gps"] == 0.0).all() and cut["clutch_closed"].all()
        assert (cut["power_mode_name"] == "fuel_cut").all()
        w = cut["engine_speed_radps"].to_numpy()
        assert np.allclose(cut["engine_torque_nm"], np.interp(w, csv[:, 0], csv[:, 1]), rtol=1e-12)
        assert np.array_equal(w, cut["gearbox_input_speed_radps"].to_numpy())
        assert abs(r.energy_audit["residual"]) < 1e-9 * r.value("traction_energy_j")
        assert r.energy_audit["engine_loss"] > 0.0
    # fuel cut off (above the redline): the same deceleration idles and burns fuel
    off = simulate_conventional(cfg.replace(**{"controller.fuel_cut_speed_rpm": 99_999.0}), cyc)
    ts_off = off.timeseries.iloc[cut.index]
    assert not off.timeseries["fuel_cut"].any() and (ts_off["fuel_rate_gps"] > 0).all()
    assert off.value("fuel_kg") > r.value("fuel_kg")


def test_fuel_cut_speed_is_validated(cfg: Any) -> None:
    with pytest.raises(ConfigError, match="fuel_cut_speed_rpm"):
        cfg.replace(**{"controller.fuel_cut_speed_rpm": -5.0})


@pytest.mark.parametrize("path", ["conventional_sedan.toml", "parallel_hev.toml", "bev.toml"])
def test_batch_variants_are_validated_like_a_file(path: str) -> None:
    """The batch's fast variant validation gives the configuration cfg.replace gives, and
    the same errors (a bound, a cross-key check)."""
    from hevsim.architectures import architecture
    from hevsim.sim.forward import variant_config

    cfg = C.load_vehicle_config(ROOT / "examples" / path)
    spec, cache = architecture(cfg.architecture).spec, {}
    for changes in (
        {"body.mass_kg": 1500.0},
        {"body.mass_kg": 1400.0, "final_drive.ratio": 3.0, "tire.radius_m": 0.3},
    ):
        assert variant_config(cfg, changes, spec, cache) == cfg.replace(**changes)
    bads: list[dict[str, float]] = [{"body.mass_kg": -1.0}, {"battery.soc_min": 0.99}]
    if cfg.architecture != "bev":  # a shift schedule that hunts
        bads.append({"controller.upshift_rpm": 1.0, "controller.downshift_rpm": 5000.0})
    for bad in bads:
        with pytest.raises(ConfigError) as fast:
            variant_config(cfg, bad, spec, cache)
        with pytest.raises(ConfigError) as ref:
            cfg.replace(**bad)
        assert str(fast.value) == str(ref.value)

"""Tiers 1-3 for the forward simulator: analytic solutions, references, invariants."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hevsim.config import VehicleConfig, from_dict
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.sim import kernel as K
from hevsim.sim.simulator import simulate, simulate_batch


def _ev_config(**body: float) -> VehicleConfig:
    return from_dict({
        "name": "ev",
        "body": {"mass_kg": 1200.0, **body},
        "tire": {"radius_m": 0.3},
        "final_drive": {"ratio": 2.0},
        "motor": {"model": "ideal", "max_torque_nm": 200.0},
        "genset": {"kind": "none"},
        "battery": {"model": "ideal", "capacity_ah": 1000.0},
    })  # fmt: skip


def _constant_torque_run(cfg: VehicleConfig, dt: float = 0.01) -> np.ndarray:
    """Full torque request for 10 s: a cycle far above the car's speed saturates the driver."""
    t = np.arange(0.0, 10.0 + dt / 2, dt)
    target = np.full(t.size, 100.0)  # far above reach, below hevsim.cycles.MAX_SPEED_MPS
    target[0] = 0.0  # start at rest
    cyc = DriveCycle("launch", t, target)
    r = simulate(cfg, cyc, dt_s=dt)
    assert np.all(r.timeseries["driver_request"].iloc[:-1] == 1.0)
    return r.timeseries["speed_mps"].to_numpy()


def test_constant_torque_launch_eq8() -> None:
    """200 N·m x ratio 2 on 1200 kg with r = 0.3 m: 11.1 m/s after 10 s (eq 8)."""
    cfg = _ev_config(drag_coefficient=0.0, rolling_resistance=0.0)
    v = _constant_torque_run(cfg)
    assert v[-1] == pytest.approx(200 * 2 / (1200 * 0.3) * 10, rel=0.005)


def test_launch_with_drag_matches_ode() -> None:
    """With drag on, the speed follows the ODE of eq (1) within 0.5 %."""
    cfg = _ev_config(drag_coefficient=0.4, frontal_area_m2=3.0)
    v = _constant_torque_run(cfg)
    f_x = 200 * 2 / 0.3

    def rhs(_t: float, y: np.ndarray) -> list[float]:
        return [(f_x - 0.5 * 0.4 * 1.18 * 3.0 * y[0] * abs(y[0])) / 1200.0]

    sol = solve_ivp(rhs, (0, 10), [0.0], rtol=1e-10, atol=1e-12)
    assert v[-1] == pytest.approx(sol.y[0, -1], rel=0.005)
    assert v[-1] < 11.1  # drag is felt


def test_udds_tracking_with_enough_torque() -> None:
    cfg = _ev_config(drag_coefficient=0.4, frontal_area_m2=3.0).replace(**{"motor.max_torque_nm": 600.0})
    r = simulate(cfg, "udds")
    assert r.value("speed_error_rms_mph") < 1.0


@pytest.mark.parametrize("cycle", ["udds", "hwfet", "us06"])
def test_energy_audit_closes(series_cfg: VehicleConfig, cycle: str) -> None:
    r = simulate(series_cfg, cycle)
    assert r.value("energy_audit_residual_pct") < 0.5
    audit = r.energy_audit
    assert audit["fuel"] > 0 and audit["engine_loss"] > 0 and audit["motor_loss"] > 0
    # tractive energy at the wheels equals road losses + brakes + kinetic change
    assert abs(audit["residual"]) < 1e-6 * audit["fuel"]


def test_mpgge_insensitive_to_initial_soc(series_cfg: VehicleConfig) -> None:
    lo = simulate(series_cfg, "udds", soc_initial=0.6).value("mpgge")
    hi = simulate(series_cfg, "udds", soc_initial=0.7).value("mpgge")
    assert abs(hi - lo) / hi < 0.02


def test_charge_sustaining_on_repeated_cycles(series_cfg: VehicleConfig) -> None:
    cyc = load_cycle("udds").repeated(4)
    r = simulate(series_cfg, cyc)
    ctl = series_cfg.controller
    assert ctl.soc_low - 0.02 <= r.value("soc_final") <= ctl.soc_high + 0.02
    soc = r.timeseries["soc"]
    assert soc.min() > ctl.soc_low - 0.1  # the thermostat keeps the battery in its band


def test_time_step_convergence(series_cfg: VehicleConfig) -> None:
    f1 = simulate(series_cfg, "udds", dt_s=0.5).value("fuel_kg")
    f2 = simulate(series_cfg, "udds", dt_s=0.25).value("fuel_kg")
    assert abs(f1 - f2) / f2 < 0.005


def test_mode_history_and_reasons(series_cfg: VehicleConfig) -> None:
    r = simulate(series_cfg, "udds")
    modes = set(r.timeseries["power_mode_name"])
    assert {"pure_ev", "charging", "ice_charging"} <= modes
    genset = r.events[r.events["kind"] == "genset"]
    assert len(genset) >= 2
    assert genset["reason"].str.contains("SOC").any()
    assert (r.timeseries["mode_reason"] >= 0).all()


def test_batch_matches_single_runs(series_cfg: VehicleConfig) -> None:
    masses = np.array([1100.0, 1200.0, 1500.0])
    batch = simulate_batch(series_cfg, {"mass_kg": masses}, "udds")
    assert len(batch.table) == 3
    for m, row in zip(masses, batch.table.itertuples(), strict=True):
        single = simulate(series_cfg.replace(**{"body.mass_kg": float(m)}), "udds")
        assert row.fuel_kg == pytest.approx(single.value("fuel_kg"), rel=1e-12)
    assert batch.table["fuel_equivalent_kg"].is_monotonic_increasing


def test_batch_rejects_unknown_parameter(series_cfg: VehicleConfig) -> None:
    from hevsim.errors import ConfigError

    with pytest.raises(ConfigError, match="not known"):
        simulate_batch(series_cfg, {"mass": [1.0]})


def test_channels_are_unit_suffixed(series_cfg: VehicleConfig) -> None:
    r = simulate(series_cfg, "fu505")
    unitless = {"driver_request", "soc", "engine_throttle", "genset_state", "power_mode",
                "mode_reason", "battery_limited", "power_mode_name", "genset_state_name"}  # fmt: skip
    units = {
        "s",
        "mps",
        "mph",
        "mps2",
        "radps",
        "rpm",
        "nm",
        "w",
        "a",
        "v",
        "ohm",
        "n",
        "kg",
        "gps",
    }
    for col in r.timeseries.columns:
        assert col in unitless or col.rsplit("_", 1)[-1] in units, col
    assert len(K.CHANNELS) + 5 == len(r.timeseries.columns)


def test_schedule_supervisor_replays_thermostat_run(series_cfg: VehicleConfig) -> None:
    """A genset schedule recorded from a thermostat run reproduces its fuel and SOC."""
    from hevsim.sim.simulator import GensetSchedule
    from hevsim.units import rpm_to_radps

    ref = simulate(series_cfg, "udds")
    ts = ref.timeseries
    on = ts["genset_state"].to_numpy() != K.GS_OFF
    target = np.where(on, rpm_to_radps(series_cfg.controller.engine_speed_rpm), 0.0)
    throttle = np.where(on, series_cfg.controller.throttle, 0.0)
    sched = GensetSchedule(ts["time_s"].to_numpy(), target, throttle)
    rep = simulate(series_cfg, "udds", schedule=sched)
    assert rep.value("fuel_kg") == pytest.approx(ref.value("fuel_kg"), rel=0.03)
    assert rep.value("soc_final") == pytest.approx(ref.value("soc_final"), abs=0.01)
    assert rep.events["reason"].str.startswith("schedule").any()
    assert rep.value("energy_audit_residual_pct") < 0.5


def test_schedule_from_config_csv(tmp_path, series_cfg: VehicleConfig) -> None:  # type: ignore[no-untyped-def]
    from pathlib import Path

    from hevsim.config import load_config

    root = Path(__file__).resolve().parents[1]

    (tmp_path / "sched.csv").write_text(
        "time_s,engine_speed_rpm,engine_throttle\n0,0,0\n100,1500,0.6\n300,0,0\n"
    )
    text = (root / "examples" / "series_hev.toml").read_text()
    text = text.replace("[controller]\n", '[controller]\nkind = "schedule"\nschedule = "sched.csv"\n')
    (tmp_path / "car.toml").write_text(text)
    r = simulate(load_config(tmp_path / "car.toml"), "fu505")
    fired = r.timeseries.loc[r.timeseries["fuel_rate_gps"] > 0, "time_s"]
    assert fired.min() >= 100.0 and fired.max() < 300.0

"""QSS lap simulation (issue 29 item 2): closed forms (skidpad with and without downforce,
constant-power launch, braking distance), agreement with ``hevsim performance``, mesh
convergence, operating points and energy per lap, bad tracks refused with the location."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from hevsim import tracks
from hevsim.config import load_vehicle_config
from hevsim.errors import InputError
from hevsim.sim.lap import LapVehicle, lap_time_s, lap_vehicle, qss_speed, simulate_lap

ROOT = Path(__file__).resolve().parents[1]
HP = ROOT / "examples" / "high_performance_parallel_hev.toml"
G = 9.80665


def point_vehicle(
    *, mu: float = 1.0, power_w: float = 1e9, mass_kg: float = 1000.0, **kw: float
) -> LapVehicle:
    """A vehicle of the kernel alone: no drag, no rolling resistance, a constant-power
    envelope P / v (capped at 100 g)."""
    v = np.arange(0.0, 110.0 + 1e-9, 0.02)
    f = np.minimum(power_w / np.maximum(v, 1e-9), 100.0 * mass_kg * G)
    base = dict(
        name="point",
        mass_kg=mass_kg,
        mass_factor=1.0,
        drag_coefficient=0.0,
        frontal_area_m2=2.0,
        air_density_kgpm3=1.2,
        rolling_resistance=0.0,
        cg_height_m=0.5,
        front_axle_to_cg_m=1.4,
        rear_axle_to_cg_m=1.6,
        mu_x=mu,
        mu_y=mu,
        downforce_coefficient=0.0,
        front_downforce_fraction=0.5,
        driven_axle="all",
        min_turning_radius_m=1.0,
        envelope_speed_mps=v,
        envelope_force_n=f,
    )
    base.update(kw)
    return LapVehicle(**base)  # type: ignore[arg-type]


def hairpin_straight(length_m: float, step_m: float) -> tracks.Track:
    """A straight whose first sample is a corner of radius 1 mm (the apex: a standing start
    and the end of the braking zone of the loop). The corner's own step has no grip left
    for the longitudinal force: the launch starts at ``step_m``, the braking ends at
    ``length_m - step_m``."""
    n = round(length_m / step_m)
    k = np.zeros(n)
    k[0] = 1e3
    z = np.zeros(n)
    return tracks.Track("hairpin", step_m, np.arange(n) * step_m, k, z, z, z, z, z, z)


@pytest.fixture(scope="module")
def hp_vehicle() -> LapVehicle:
    return lap_vehicle(HP)


# ---------------------------------------------------------------------------------------------
# Closed forms
# ---------------------------------------------------------------------------------------------
def test_skidpad_speed_is_sqrt_mu_g_r() -> None:
    veh = point_vehicle(mu=0.95)
    tr = tracks.skidpad(step_m=0.5)
    v, _ = qss_speed(veh, tr)
    expected = math.sqrt(0.95 * G * tracks.SKIDPAD_RADIUS_M)
    assert np.allclose(v, expected, rtol=1e-12)
    assert lap_time_s(v, tr.step_m) == pytest.approx(
        2 * math.pi * tracks.SKIDPAD_RADIUS_M / expected, rel=1e-12
    )


def test_skidpad_with_downforce_matches_the_closed_form() -> None:
    mu, cl, area, rho, m, r = 1.3, 3.0, 1.5, 1.2, 750.0, 100.0
    veh = point_vehicle(
        mu=mu, mass_kg=m, downforce_coefficient=cl, frontal_area_m2=area, air_density_kgpm3=rho
    )
    v, _ = qss_speed(veh, tracks.skidpad(r, step_m=1.0))
    v2 = mu * G * r / (1.0 - mu * rho * cl * area * r / (2.0 * m))
    assert np.allclose(v, math.sqrt(v2), rtol=1e-12)
    assert v2 > 1.5 * mu * G * r  # the downforce matters here


def test_banked_skidpad_matches_the_closed_form() -> None:
    # v^2 = g R (mu cos b + sin b) / (cos b - mu sin b), banked into the (left-hand) corner
    mu, r, bank_deg = 0.8, 50.0, 15.0
    t = tracks.skidpad(r, step_m=1.0)
    banked = dataclasses.replace(t, banking_rad=np.full(t.distance_m.size, math.radians(bank_deg)))
    v, _ = qss_speed(point_vehicle(mu=mu), banked)
    b = math.radians(bank_deg)
    v2 = G * r * (mu * math.cos(b) + math.sin(b)) / (math.cos(b) - mu * math.sin(b))
    assert np.allclose(v, math.sqrt(v2), rtol=1e-12)


def test_skidpad_of_a_real_car_with_drag_stays_at_its_limit() -> None:
    res = simulate_lap(HP, "skidpad", step_m=0.5)
    mu = load_vehicle_config(HP).tire.friction_coefficient
    v_lim = math.sqrt(mu * G * tracks.SKIDPAD_RADIUS_M)
    v = res.timeseries["speed_mps"].to_numpy()
    # the apex speed leaves no grip for the drag: the car sheds a little speed and holds it
    assert np.all(v <= v_lim * (1 + 1e-12)) and np.all(v >= 0.998 * v_lim)
    assert res.summary["max_lateral_g"] == pytest.approx(mu, rel=1e-3)


def test_constant_power_launch_matches_the_closed_form() -> None:
    # traction-limited at mu g up to v1 = P / (m mu g), then v^3 = v1^3 + 3 P (s - s1) / m
    mu, p, m, ds = 1.0, 100e3, 1000.0, 0.25
    veh = point_vehicle(mu=mu, power_w=p, mass_kg=m)
    tr = hairpin_straight(20000.0, ds)
    v, _ = qss_speed(veh, tr)
    v1 = p / (m * mu * G)
    s1 = v1**2 / (2 * mu * G)
    s = np.array([3.0, 200.0, 1000.0])
    v_closed = np.where(s < s1, np.sqrt(2 * mu * G * s), np.cbrt(v1**3 + 3 * p / m * (s - s1)))
    v_sim = np.interp(s + ds, tr.distance_m, v)
    assert s[0] < s1 < s[1]
    assert np.allclose(v_sim, v_closed, rtol=0.01)


def test_braking_distance_is_v2_over_2_mu_g() -> None:
    mu, ds = 0.9, 0.5
    veh = point_vehicle(mu=mu)
    tr = hairpin_straight(3000.0, ds)
    v, _ = qss_speed(veh, tr)
    v0 = math.sqrt(mu * G * 1e-3)  # the apex speed of the 1 mm corner
    d = np.array([10.0, 100.0, 400.0])  # before the corner at the end of the loop
    v_sim = np.interp(tr.length_m - ds - d, tr.distance_m, v)
    assert np.allclose(v_sim, np.sqrt(v0**2 + 2 * mu * G * d), rtol=1e-9)


def test_rear_drive_traction_limit_has_the_load_transfer_closed_form() -> None:
    # a = mu g (l_f / L) / (1 - mu h / L) for a rear-wheel drive car (performance's eq)
    mu, h, lf, lr = 1.0, 0.5, 1.4, 1.6
    veh = point_vehicle(mu=mu, driven_axle="rear", cg_height_m=h, front_axle_to_cg_m=lf, rear_axle_to_cg_m=lr)
    tr = hairpin_straight(2000.0, 0.05)
    v, _ = qss_speed(veh, tr)
    a = mu * G * (lf / (lf + lr)) / (1 - mu * h / (lf + lr))
    assert np.interp(10.0 + tr.step_m, tr.distance_m, v) == pytest.approx(math.sqrt(2 * a * 10.0), rel=2e-3)


def test_launch_agrees_with_hevsim_performance(hp_vehicle: LapVehicle) -> None:
    """0-100 km/h over distance with the powertrain envelope vs the forward-in-time
    performance run of the same car (same power flow, traction with load transfer)."""
    from hevsim.sim.performance import performance

    veh = hp_vehicle
    tr = hairpin_straight(5000.0, 0.1)
    v, _ = qss_speed(veh, tr)
    target = 100.0 / 3.6
    k = int(np.flatnonzero(v >= target)[0])
    vm = 0.5 * (v[2 : k + 1] + v[1:k])  # from the end of the corner's step (hairpin_straight)
    t_lap = float(np.sum(tr.step_m / vm)) - (v[k] - target) / ((v[k] - v[k - 1]) / (tr.step_m / vm[-1]))
    t_perf = performance(HP).value("0-100 km/h")
    assert t_lap == pytest.approx(t_perf, rel=0.01)  # measured 0.26 %


def test_mesh_convergence_is_first_order(hp_vehicle: LapVehicle) -> None:
    veh = hp_vehicle
    times = []
    for ds in (1.0, 0.5, 0.25):
        tr = tracks.handling_circuit(step_m=ds)
        times.append(lap_time_s(qss_speed(veh, tr)[0], tr.step_m))
    d1, d2 = times[0] - times[1], times[1] - times[2]
    rate = math.log2(d1 / d2)
    assert 0.7 < rate < 1.5  # explicit Euler in v^2: first order (measured 1.06)
    extrapolated = times[2] - d2  # Richardson, first order
    assert abs(times[0] - extrapolated) / extrapolated < 2e-3


# ---------------------------------------------------------------------------------------------
# The lap of a real car
# ---------------------------------------------------------------------------------------------
def test_lap_outputs_and_energy_by_source(tmp_path: Path, hp_vehicle: LapVehicle) -> None:
    res = simulate_lap(HP, "handling", vehicle=hp_vehicle)
    ts, s = res.timeseries, res.summary
    for col in ("speed_mps", "ax_mps2", "ay_mps2", "gear", "engine_speed_radps", "engine_torque_nm",
                "motor_speed_radps", "motor_torque_nm", "battery_power_w", "fuel_kg"):  # fmt: skip
        assert col in ts, col
    assert s["lap_time_s"] == pytest.approx(float(ts["dt_s"].sum()))
    assert s["fuel_kg"] > 0 and s["battery_energy_discharged_j"] > 0 and s["battery_energy_charged_j"] > 0
    # grip: inside the friction ellipse everywhere (no downforce, mu_x = mu_y = 1)
    g_tot = np.hypot(ts["ax_mps2"], ts["ay_mps2"]) / G
    assert g_tot.max() < 1.06  # drag adds to braking (at most ~0.05 g at 215 km/h)
    # the wheel energy of the lap is supplied by the sources (fuel and battery) with losses
    wheel_pos_j = float(np.sum(np.maximum(ts["wheel_power_w"], 0.0) * ts["dt_s"]))
    assert s["fuel_energy_j"] * 0.45 + s["battery_energy_discharged_j"] > wheel_pos_j
    out = res.save(tmp_path / "lap")
    assert {"lap.csv", "summary.json", "speed.png", "gg.png", "track_speed.png", "track.png"} <= {
        p.name for p in out.iterdir()
    }
    assert json.loads((out / "summary.json").read_text())["lap_time_s"] == pytest.approx(s["lap_time_s"])


def test_deployment_limit_caps_the_battery_power_and_slows_the_lap(hp_vehicle: LapVehicle) -> None:
    tr = tracks.handling_circuit()
    free = simulate_lap(HP, tr, vehicle=hp_vehicle)
    cap = 20e3
    held = simulate_lap(HP, tr, battery_power_max_w=cap)
    ts = held.timeseries
    assert ts["battery_chemical_power_w"].max() <= cap * (1 + 1e-6)
    assert free.timeseries["battery_chemical_power_w"].max() > 5 * cap
    assert held.lap_time_s > free.lap_time_s + 0.5
    assert held.summary["battery_energy_discharged_j"] < 0.5 * free.summary["battery_energy_discharged_j"]
    # no limit at all (inf) is the free lap
    assert simulate_lap(HP, tr, vehicle=hp_vehicle, operating_points=False).lap_time_s == free.lap_time_s


def test_reused_operating_points_are_the_same_bit_for_bit() -> None:
    """``simulate_lap(..., reuse=)`` keeps a previous lap's operating-point search where the
    samples are the same (a stint's further pass): the lap is the one computed afresh, bit for
    bit, with part of its samples reused."""
    tr = tracks.handling_circuit()
    veh = lap_vehicle(HP, battery_levels_w=np.linspace(0.0, 150e3, 5))
    limit = np.full(tr.distance_m.size, 100e3)
    first = simulate_lap(HP, tr, vehicle=veh, battery_power_max_w=limit)
    limit[400:600] = 40e3  # a window lowered, as a stint's pass does
    fresh = simulate_lap(HP, tr, vehicle=veh, battery_power_max_w=limit)
    again = simulate_lap(HP, tr, vehicle=veh, battery_power_max_w=limit, reuse=first)
    assert fresh.timeseries.equals(again.timeseries)
    assert fresh.summary == again.summary
    assert first.search is not None and again.search is not None
    v0, f0, d0, l0 = first.search[:4]
    v1, f1, d1, l1 = again.search[:4]
    same = (v0 == v1) & (f0 == f1) & (d0 == d1) & (l0 == l1)
    assert 0.2 < same.mean() < 1.0, same.mean()  # part reused, part searched again
    assert fresh.lap_time_s > first.lap_time_s


def test_deployment_rows_interpolate_the_envelope(hp_vehicle: LapVehicle) -> None:
    veh = lap_vehicle(HP, battery_levels_w=[0.0, 50e3, 100e3])
    v = np.array([20.0, 40.0])
    f0, f50, f100 = (veh.force_n(v, np.full(2, p)) for p in (0.0, 50e3, 100e3))
    assert np.all(f0 < f50) and np.all(f50 < f100)
    assert np.all(f100 <= hp_vehicle.force_n(v) * (1 + 1e-9))
    # halfway between two rows
    assert np.allclose(veh.force_n(v, np.full(2, 25e3)), 0.5 * (f0 + f50))


@pytest.mark.parametrize("name", ["bev", "conventional_sedan"])
def test_energy_sources_of_single_source_cars(name: str) -> None:
    res = simulate_lap(ROOT / "examples" / f"{name}.toml", "oval", step_m=2.0)
    if name == "bev":
        assert res.summary["fuel_kg"] == 0.0 and res.summary["battery_energy_discharged_j"] > 0
    else:
        assert res.summary["fuel_kg"] > 0 and res.summary["battery_chemical_energy_j"] == 0.0


def test_downforce_and_friction_keys_speed_the_car_up() -> None:
    cfg = load_vehicle_config(HP)
    base = simulate_lap(cfg, "handling", operating_points=False).lap_time_s
    aero = cfg.replace(**{"aero.downforce_coefficient": 1.0})
    grip = cfg.replace(**{"tire.friction_coefficient_y": 1.2})
    assert simulate_lap(aero, "handling", operating_points=False).lap_time_s < base
    assert simulate_lap(grip, "handling", operating_points=False).lap_time_s < base


def test_default_keys_leave_existing_vehicles_unchanged() -> None:
    cfg = load_vehicle_config(HP)
    assert cfg.aero.downforce_coefficient == 0.0
    assert cfg.tire.friction_coefficient_x == 0.0 and cfg.tire.friction_coefficient_y == 0.0
    veh = lap_vehicle(cfg)
    assert veh.mu_x == veh.mu_y == cfg.tire.friction_coefficient


# ---------------------------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------------------------
def test_corner_tighter_than_the_turning_radius_is_refused_with_its_distance() -> None:
    cfg = load_vehicle_config(HP).replace(**{"body.min_turning_radius_m": 40.0})
    with pytest.raises(InputError, match=r"distance 99[45].[0-9] m .* minimum turning radius 40 m"):
        simulate_lap(cfg, "handling", operating_points=False)


def test_out_of_range_aero_key_names_the_key(tmp_path: Path) -> None:
    from hevsim.errors import ConfigError

    text = HP.read_text(encoding="utf-8") + "\n[aero]\nfront_downforce_fraction = 1.5\n"
    p = tmp_path / "car.toml"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=r"aero.front_downforce_fraction"):
        load_vehicle_config(p)


def test_cli_refuses_an_open_track_with_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from hevsim.cli import main

    t = np.linspace(0.0, math.radians(300.0), 150)
    p = tmp_path / "open.csv"
    p.write_text("x_m,y_m\n" + "\n".join(f"{50 * math.cos(a)},{50 * math.sin(a)}" for a in t) + "\n",
                 encoding="utf-8")  # fmt: skip
    assert main(["lap", str(HP), str(p), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "does not close" in err and "distance 26" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_cli_writes_the_lap(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from hevsim.cli import main

    assert main(["lap", str(ROOT / "examples" / "bev.toml"), "skidpad", "--out", str(tmp_path / "o"),
                 "--no-plots"]) == 0  # fmt: skip
    assert "lap time" in capsys.readouterr().out
    assert (tmp_path / "o" / "lap.csv").is_file()


def test_vehicle_is_immutable_dataclass() -> None:
    veh = point_vehicle()
    with pytest.raises(dataclasses.FrozenInstanceError):
        veh.mu_x = 2.0  # type: ignore[misc]

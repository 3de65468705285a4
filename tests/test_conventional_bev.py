"""Issue 11 item 4: conventional and battery-electric vehicles in the forward simulator.

Analytic full-throttle launch in a fixed gear with a constant-torque engine (clutch slip,
then locked); fuel at constant speed against the engine map at the operating point the road
load gives; the energy audit of both shipped examples on UDDS, HWFET and US06; brake
blending of the BEV; bad input.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tests.arch_helpers import assert_bad_config_exits_2

from hevsim import config as C
from hevsim.architectures import architecture
from hevsim.cli import main
from hevsim.cycles import DriveCycle
from hevsim.errors import ConfigError
from hevsim.sim.forward import simulate_architecture, simulate_bev, simulate_conventional
from hevsim.units import rpm_to_radps

ROOT = Path(__file__).resolve().parents[1]
CONVENTIONAL = ROOT / "examples" / "conventional_sedan.toml"
BEV = ROOT / "examples" / "bev.toml"


def _launch_config(ratio: float = 2.0) -> C.ConventionalConfig:
    base = C.load_vehicle_config(CONVENTIONAL)
    return base.replace(**{
        "body.drag_coefficient": 0.0, "body.rolling_resistance": 0.0, "body.mass_kg": 1000.0,
        "body.mass_factor": 1.1, "engine.model": "constant_torque", "engine.max_torque_nm": 200.0,
        "engine.redline_rpm": 6000.0, "gearbox.ratios": [ratio], "gearbox.efficiency": 0.9,
        "final_drive.ratio": 3.0, "final_drive.efficiency": 0.95, "tire.radius_m": 0.3,
    })  # fmt: skip


def test_constant_gear_full_throttle_launch_is_the_analytic_solution() -> None:
    """v(t) = T i_g eta_g i_fd eta_fd t / (r m delta): the driver asks for far more than the
    engine gives, so every step is the engine's full (constant) torque, through the slipping
    launch clutch first and the locked one after."""
    cfg = _launch_config()
    t = np.arange(0.0, 5.0 + 1e-9, 0.1)
    cyc = DriveCycle("wall", t, np.where(t > 0, 100.0, 0.0))
    r = simulate_conventional(cfg, cyc, dt_s=0.1)
    ts = r.timeseries
    a = 200.0 * 2.0 * 0.9 * 3.0 * 0.95 / (0.3 * 1000.0 * 1.1)
    np.testing.assert_allclose(ts["speed_mps"].to_numpy(), a * t, rtol=1e-8, atol=1e-8)
    assert r.value("traction_limited_s") == pytest.approx(5.0)
    slip = ts["clutch_slipping"].to_numpy()[:-1]
    w_in = ts["gearbox_input_speed_radps"].to_numpy()[:-1]
    idle = rpm_to_radps(cfg.engine.stall_speed_rpm)
    assert slip.any() and (~slip).any()
    np.testing.assert_array_equal(slip, w_in < idle)  # slips exactly while below idle speed
    np.testing.assert_allclose(ts["engine_torque_nm"].to_numpy()[:-1], 200.0, rtol=1e-8)
    audit = r.energy_audit
    assert audit["clutch_loss"] > 0.0
    assert abs(audit["residual"]) < 1e-9 * r.value("traction_energy_j")
    # the kinetic energy is the wheel work: 1/2 m delta v^2
    v_end = ts["speed_mps"].iloc[-1]
    assert audit["kinetic_vehicle"] == pytest.approx(0.5 * 1000.0 * 1.1 * v_end**2, rel=1e-9)


def test_fuel_at_constant_speed_is_the_map_at_the_road_load_operating_point() -> None:
    cfg = C.load_vehicle_config(CONVENTIONAL)
    veh = architecture("conventional").build(cfg)
    v = 25.0
    t = np.arange(0.0, 60.0 + 1e-9, 1.0)
    r = simulate_conventional(veh, DriveCycle("cruise", t, np.full(t.size, v)), dt_s=1.0)
    ts = r.timeseries
    assert set(ts["gear"].iloc[:-1]) == {5}
    b = cfg.body
    force = (
        0.5 * b.air_density_kgpm3 * b.drag_coefficient * b.frontal_area_m2 * v**2
        + b.rolling_resistance * b.mass_kg * 9.81
    )
    t_e = (
        force
        * cfg.tire.radius_m
        / (cfg.final_drive.ratio * cfg.final_drive.efficiency * 0.76 * cfg.gearbox.efficiency)
    )
    w_e = v / cfg.tire.radius_m * cfg.final_drive.ratio * 0.76
    np.testing.assert_allclose(ts["engine_torque_nm"].iloc[:-1], t_e, rtol=2e-3)  # g = 9.81 vs 9.80665
    rate = float(veh.engine.fuel_map_rate(ts["engine_torque_nm"].iloc[0], w_e))
    assert r.value("fuel_kg") == pytest.approx(rate * 60.0, rel=1e-12)
    bsfc_g_per_kwh = rate * 1e3 / (t_e * w_e / 3.6e6)
    assert 190.0 < bsfc_g_per_kwh < 320.0  # a 1.9 L TDI at part load


@pytest.mark.parametrize("cycle", ["udds", "hwfet", "us06"])
@pytest.mark.parametrize("path", [CONVENTIONAL, BEV])
def test_energy_audit_closes(path: Path, cycle: str) -> None:
    cfg = C.load_vehicle_config(path)
    r = simulate_architecture(cfg.architecture, cfg, cycle)
    traction = r.value("traction_energy_j")
    assert traction > 1e6
    assert abs(r.energy_audit["residual"]) < 0.005 * traction  # issue 11: < 0.5 %
    assert abs(r.energy_audit["residual"]) < 1e-9 * traction  # in fact round-off
    if cfg.architecture == "conventional":
        assert r.value("fuel_kg") > 0 and r.value("soc_final") == r.value("soc_initial")
    else:
        assert r.value("fuel_kg") == 0 and r.value("soc_final") < r.value("soc_initial")
        assert np.isfinite(r.value("mpgge"))


def test_stop_start_saves_the_idle_fuel() -> None:
    cfg = C.load_vehicle_config(CONVENTIONAL)
    idle = simulate_conventional(cfg, "udds")
    ss = simulate_conventional(cfg.replace(**{"controller.stop_start": "on"}), "udds")
    assert ss.value("fuel_kg") < idle.value("fuel_kg")
    off = ss.timeseries["power_mode_name"] == "engine_off"
    assert off.sum() > 100 and (ss.timeseries.loc[off, "fuel_rate_gps"] == 0).all()
    fired = idle.timeseries.iloc[:-1].query("not fuel_cut")  # idling burns fuel (no fuel cut)
    assert len(fired) > 1000 and (fired["fuel_rate_gps"] > 0).all()


def test_bev_brake_blending_limits_regeneration() -> None:
    cfg = C.load_vehicle_config(BEV)
    full = simulate_bev(cfg.replace(**{"brakes.regen_fraction": 1.0}), "udds")
    blended = simulate_bev(cfg, "udds")
    assert blended.energy_audit["friction_brakes"] > full.energy_audit["friction_brakes"]
    assert blended.value("soc_final") < full.value("soc_final")
    ts = blended.timeseries
    braking = (ts["wheel_force_n"] < 0) & (ts["speed_mps"] > 2.0)
    p_fric = ts.loc[braking, "friction_brake_power_w"]
    p_wheel = -ts.loc[braking, "wheel_power_w"]
    assert (p_fric >= 0.2 * p_wheel * 0.97 - 1e-6).all()  # at least 1 - regen_fraction at the wheels


@pytest.mark.parametrize(
    ("path", "old", "new", "needles"),
    [
        (CONVENTIONAL, 'upshift_rpm = 2400.0', 'upshift_rpm = 1500.0', ["upshift_rpm", "1500", "infeasible"]),
        (BEV, 'kind = "direct"', 'kind = "ecms"', ["controller.kind", "'ecms'", "bev", "direct"]),
        (CONVENTIONAL, 'architecture = "conventional"', 'architecture = "steam"',
         ["'steam'", "conventional, bev"]),
    ],
)  # fmt: skip
def test_bad_input_is_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], path: Path, old: str, new: str, needles: list[str]
) -> None:
    text = path.read_text()
    assert old in text
    assert_bad_config_exits_2(tmp_path, capsys, text.replace(old, new, 1), needles)


def test_cli_simulates_both(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for path in (CONVENTIONAL, BEV):
        out = tmp_path / path.stem
        assert main(["simulate", str(path), "--cycle", "hwfet", "--no-plots", "--out", str(out)]) == 0
        assert (out / "energy_audit.json").is_file()
    assert "mpgge" in capsys.readouterr().out
    with pytest.raises(ConfigError, match="no DP formulation"):
        architecture("bev").formulation()


def test_simulate_and_simulate_batch_take_every_architecture() -> None:
    """One entry point: hevsim.sim.simulator.simulate / simulate_batch dispatch by architecture."""
    from hevsim.sim.simulator import simulate, simulate_batch

    cfg = C.load_vehicle_config(CONVENTIONAL)
    r = simulate(cfg, "hwfet")
    assert r.metadata["architecture"] == "conventional" and r.value("fuel_kg") > 0
    batch = simulate_batch(cfg, {"body.mass_kg": [1200.0, 1500.0, 1800.0]}, "hwfet")
    fuel = batch.table["fuel_kg"].to_numpy()
    assert list(batch.table["body.mass_kg"]) == [1200.0, 1500.0, 1800.0]
    assert np.all(np.diff(fuel) > 0)  # heavier burns more
    assert fuel[1] == pytest.approx(
        simulate(cfg.replace(**{"body.mass_kg": 1500.0}), "hwfet").value("fuel_kg")
    )
    with pytest.raises(ConfigError, match=r"body\.mass_kg"):
        simulate_batch(cfg, {"body.mass_kg": [-1.0]}, "hwfet")

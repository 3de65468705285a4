"""Issue 11: the power-split HEV (THS style) - Willis kinematics, electric balance, energy
audit, DP replay, ECMS from the DP, adaptive ECMS, bad tooth numbers, performance."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tests.arch_helpers import assert_bad_config_exits_2

from hevsim import config as C
from hevsim.architectures import architecture
from hevsim.architectures import power_split as ps
from hevsim.cli import main
from hevsim.control.parallel import ControlSchedule, ecms_from_dp
from hevsim.cycles import load_cycle
from hevsim.optimal.hev import OptimizationResult, optimize
from hevsim.sim.forward import simulate_power_split
from hevsim.sim.performance import performance

ROOT = Path(__file__).resolve().parents[1]
PRIUS = ROOT / "examples" / "prius_like_power_split.toml"


@pytest.fixture(scope="module")
def hev() -> ps.PowerSplitHEV:
    return architecture("power_split").build(C.load_vehicle_config(PRIUS))


@pytest.fixture(scope="module")
def dp_runs(hev: ps.PowerSplitHEV) -> dict[str, OptimizationResult]:
    """Charge-sustaining DP optima (SOC grid 101, 13 engine speeds x 11 throttles)."""
    return {
        c: optimize(hev, c, soc_grid_points=101, input_grid_points=11, progress=False)
        for c in ("udds", "hwfet")
    }


@pytest.mark.parametrize("cycle", ["udds", "hwfet", "us06"])
def test_willis_electric_balance_and_audit_at_every_step(hev: ps.PowerSplitHEV, cycle: str) -> None:
    r = simulate_power_split(hev, cycle, controller="ecms")
    ts = r.timeseries.iloc[:-1]
    zs, zr = hev.sun_teeth, hev.ring_teeth
    w_e, w_s, w_r = (
        ts[c].to_numpy() for c in ("engine_speed_radps", "generator_speed_radps", "ring_speed_radps")
    )
    scale = np.maximum(np.abs(w_r), 1.0)
    np.testing.assert_allclose(((zs + zr) * w_e - zs * w_s - zr * w_r) / scale, 0.0, atol=1e-12)  # Willis
    # MG1 + MG2 electrical power + auxiliaries = battery terminal power (losses inside each term)
    p_bus = ts["generator_power_elec_w"] + ts["motor_power_elec_w"] + hev.aux_power_w
    np.testing.assert_allclose(ts["battery_power_w"], p_bus, rtol=1e-12, atol=1e-9)
    # MG1 holds the sun: T_MG1 = -T_e Zs / (Zs + Zr)
    np.testing.assert_allclose(
        ts["generator_torque_nm"], -ts["engine_torque_nm"] * zs / (zs + zr), atol=1e-12
    )
    assert abs(r.energy_audit["residual"]) < 1e-9 * r.value("traction_energy_j")
    assert r.energy_audit["generator_loss"] > 0 and r.energy_audit["motor_loss"] > 0
    on = ts["engine_on"].to_numpy()
    assert on.any() and (~on).any()
    assert np.all(np.abs(w_s) <= float(hev.generator.kernel_tables().lim_x[-1]) + 1e-9)


@pytest.mark.parametrize("cycle", ["udds", "hwfet"])
def test_dp_replay_and_ecms_from_dp(
    hev: ps.PowerSplitHEV, dp_runs: dict[str, OptimizationResult], cycle: str
) -> None:
    dp = dp_runs[cycle]
    dp_fuel = dp.value("fuel_kg")
    replay = simulate_power_split(hev, cycle, controller=ControlSchedule.from_optimization(dp))
    assert replay.value("fuel_kg") == pytest.approx(dp_fuel, rel=1e-9)
    assert replay.value("soc_final") == pytest.approx(dp.value("soc_final"), abs=1e-9)
    ecms = simulate_power_split(hev, cycle, controller="ecms", control_points=11, **ecms_from_dp(dp))
    soc0 = hev.config.simulation.soc_initial
    # the NiMH pack's OCV and resistance vary with SOC, so the DP's equivalence factor varies
    # along its path; ECMS with one number (the median) drifts a little
    assert abs(ecms.value("soc_final") - soc0) <= 0.03
    lam = -float(np.nanmedian(dp.timeseries["costate_kg_per_soc"]))
    corrected = ecms.value("fuel_kg") + lam * (dp.value("soc_final") - ecms.value("soc_final"))
    assert 0.995 * dp_fuel <= corrected <= 1.03 * dp_fuel  # (0.5 %: the DP's own grid error)


@pytest.mark.parametrize("cycle", ["udds", "hwfet", "us06", "wltc3b"])
def test_adaptive_ecms_is_charge_sustaining(hev: ps.PowerSplitHEV, cycle: str) -> None:
    r = simulate_power_split(hev, cycle, controller="aecms")
    assert abs(r.value("soc_final") - hev.config.simulation.soc_initial) <= 0.01


def test_rule_based_power_follower(hev: ps.PowerSplitHEV) -> None:
    r = simulate_power_split(hev, "udds")
    assert r.metadata["controller"] == "power_follower"
    c = hev.config.controller
    assert c.soc_low - 0.05 <= r.value("soc_final") <= c.soc_high
    assert set(r.timeseries["power_mode_name"]) >= {"ev", "regen"}


def test_cli_ecms_from_a_dp_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--ecms-from turns the configured rule-based controller (power_follower here) into ECMS
    with the DP's s (it passed equivalence_factor to the power follower: exit 2)."""
    dp_dir, out, csv = tmp_path / "dp", tmp_path / "sim", tmp_path / "hwfet_200s.csv"
    cyc = load_cycle("hwfet").truncated(200.0)
    np.savetxt(csv, np.c_[cyc.time_s, cyc.speed_mps], delimiter=",", header="time_s,speed_mps", comments="")
    common = ["--cycle", str(csv), "--no-plots", "--out"]
    grid = ["--soc-points", "41", "--input-points", "21", "--final-soc", "sustain"]
    assert main(["optimize", str(PRIUS), *grid, *common, str(dp_dir)]) == 0
    assert main(["simulate", str(PRIUS), "--ecms-from", str(dp_dir), *common, str(out)]) == 0
    assert "controller: ecms (s = " in capsys.readouterr().out
    assert '"controller": "ecms"' in (out / "metadata.json").read_text()


@pytest.mark.parametrize("compiled", [True, False])
def test_no_clutch_channel(hev: ps.PowerSplitHEV, compiled: bool) -> None:
    """The planetary set has no clutch: no ``clutch_closed`` channel in either loop (both used
    to copy engine_on into it, as for the parallel HEV)."""
    r = simulate_power_split(hev, load_cycle("udds").truncated(60.0), compiled=compiled)
    assert "engine_on" in r.timeseries
    assert "clutch_closed" not in r.timeseries


@pytest.mark.parametrize(
    ("old", "new", "needles"),
    [
        ("ring_teeth = 78", "ring_teeth = 77", ["planetary.sun_teeth", "planetary.ring_teeth", "77", "even"]),
        ("sun_teeth = 30", "sun_teeth = 90", ["planetary.sun_teeth", "90", "below"]),
        ('kind = "power_follower"', 'kind = "shift_schedule"', ["controller.kind", "power_split", "ecms"]),
    ],
)
def test_bad_input_is_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str], old: str, new: str,
                             needles: list[str]) -> None:  # fmt: skip
    text = PRIUS.read_text()
    assert old in text
    assert_bad_config_exits_2(tmp_path, capsys, text.replace(old, new, 1), needles)


def test_performance_and_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    res = performance(PRIUS)
    assert 8.0 < res.value("0-60 mph") < 25.0
    assert 70.0 < res.value("top speed") < 120.0
    out = tmp_path / "sim"
    assert main(["simulate", str(PRIUS), "--cycle", "hwfet", "--controller", "aecms", "--no-plots",
                 "--out", str(out)]) == 0  # fmt: skip
    assert "controller: aecms" in capsys.readouterr().out

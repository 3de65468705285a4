"""Issue 11: the parallel HEV in the forward simulator (architecture layer, controllers).

Forward runs of the shipped example (examples/parallel_hev.toml, 1 s steps) with the
rule-based electric assist, ECMS and adaptive ECMS; DP replay; ECMS tuned from the DP
costate; the energy audit; bad input.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tests.arch_helpers import assert_bad_config_exits_2

from hevsim import config as C
from hevsim.architectures import ARCHITECTURES, architecture
from hevsim.architectures import parallel as P
from hevsim.cli import main
from hevsim.control import CONTROLLERS, make_controller
from hevsim.control.parallel import ControlSchedule, ecms_from_dp
from hevsim.cycles import load_cycle
from hevsim.errors import ConfigError
from hevsim.optimal.hev import OptimizationResult, optimize
from hevsim.sim.forward import simulate_parallel

ROOT = Path(__file__).resolve().parents[1]
PARALLEL = ROOT / "examples" / "parallel_hev.toml"
SOC0 = 0.6


@pytest.fixture(scope="module")
def hev() -> P.ParallelHEV:
    return P.build_parallel_hev(P.load_parallel_config(PARALLEL))


@pytest.fixture(scope="module")
def dp_runs(hev: P.ParallelHEV) -> dict[str, OptimizationResult]:
    """Charge-sustaining DP optima (SOC grid 201, 101 throttles) on UDDS and HWFET."""
    return {
        c: optimize(
            hev,
            c,
            soc_grid_points=201,
            input_grid_points=101,
            final_soc="sustain",
            soc_initial=SOC0,
            progress=False,
        )
        for c in ("udds", "hwfet")
    }


# ---------------------------------------------------------------- one power flow
def test_registry_holds_each_architecture_with_its_pieces() -> None:
    assert set(ARCHITECTURES) >= {"series", "parallel"}
    par = architecture("parallel")
    assert par.controls == P.CONTROLS
    assert par.formulation().__name__ == "ParallelFormulation"
    assert par.controllers[0] == "electric_assist" and all(k in CONTROLLERS for k in par.controllers)
    assert architecture("series").formulation().__name__ == "SeriesFormulation"
    with pytest.raises(
        ConfigError, match=r"'powertrain\.architecture' = 'tandem' is not known; expected one of"
    ):
        architecture("tandem")


def test_dp_stage_is_the_shared_power_flow(hev: P.ParallelHEV) -> None:
    """The DP formulation evaluates exactly :func:`parallel.power_flow` (no second copy)."""
    from hevsim.optimal._hev_common import CycleSteps
    from hevsim.optimal._parallel_dp import ParallelFormulation
    from hevsim.optimal._problem import FinalTarget

    cyc = load_cycle("udds").truncated(200.0)
    form = ParallelFormulation(
        hev,
        cyc,
        soc_grid=np.linspace(0.4, 0.8, 5),
        throttle_points=11,
        soc_initial=0.6,
        target=FinalTarget(lower=0.5, upper=0.8),
    )
    steps = CycleSteps.from_cycle(cyc, hev.body, hev.tire)
    rng = np.random.default_rng(1)
    k = rng.integers(0, steps.n_steps, 200)
    gear = rng.integers(1, len(hev.gears) + 1, 200).astype(float)
    thr = rng.choice(np.linspace(0, 1, 11), 200)
    soc = rng.uniform(0.45, 0.75, 200)
    a = form.stage(k, (gear, thr), soc)
    b = P.power_flow(
        hev,
        steps.wheel_speed_radps[k],
        steps.wheel_torque_nm[k],
        gear,
        thr,
        soc,
        steps.dt_s[k],
        steps.v_mid_mps[k] > 0,
    )
    np.testing.assert_array_equal(a.infeasible, b.infeasible)
    ok = ~a.infeasible
    assert ok.sum() > 50
    np.testing.assert_array_equal(a.d_soc[ok], b.d_soc[ok])
    np.testing.assert_array_equal(a.cost_kg[ok], b.cost_kg[ok])


# ---------------------------------------------------------------- forward runs
@pytest.mark.parametrize("cycle", ["udds", "hwfet", "us06"])
def test_energy_audit_closes_and_channels_are_there(hev: P.ParallelHEV, cycle: str) -> None:
    r = simulate_parallel(hev, cycle, soc_initial=SOC0)
    audit = r.energy_audit
    traction = r.value("traction_energy_j")
    assert traction > 1e6
    assert abs(audit["residual"]) < 0.005 * traction  # issue 11: < 0.5 % of traction energy
    assert abs(audit["residual"]) < 1e-9 * traction  # in fact round-off
    assert audit["fuel"] > 0 and audit["engine_loss"] > 0 and audit["aero"] > 0
    ts = r.timeseries
    for col in (
        "gear",
        "clutch_closed",
        "engine_speed_rpm",
        "engine_torque_nm",
        "motor_torque_nm",
        "motor_power_elec_w",
        "battery_current_a",
        "soc",
        "fuel_rate_gps",
        "power_mode_name",
    ):
        assert col in ts.columns, col
    b = hev.config.battery
    assert ts["soc"].between(b.soc_min - 1e-9, b.soc_max + 0.01).all()
    # engine on only inside its running window and only with the clutch closed
    on = ts["engine_on"].to_numpy()
    w = ts["engine_speed_radps"].to_numpy()[on]
    assert np.all((w >= hev.engine.stall_speed_radps - 1e-9) & (w <= hev.engine.redline_radps + 1e-9))
    assert np.array_equal(on, ts["clutch_closed"].to_numpy())
    assert r.value("speed_error_max_mph") < 1e-6 and r.value("traction_limited_s") == 0.0
    assert set(r.events["kind"]) >= {"power_mode", "gear"}


def test_rule_based_stays_in_its_soc_band(hev: P.ParallelHEV) -> None:
    r = simulate_parallel(hev, "udds", soc_initial=0.65, controller="electric_assist")
    c = hev.config.controller
    assert c.soc_low - 0.03 <= r.value("soc_final") <= c.soc_high + 0.03
    gears = r.timeseries["gear"].to_numpy()
    assert set(np.unique(gears)) - {0} == set(range(1, len(hev.gears) + 1))  # the schedule uses every gear


def test_traction_limit_lowers_the_speed_and_keeps_the_audit(hev: P.ParallelHEV) -> None:
    """A weak machine and engine cannot follow US06: the car falls behind, the audit still closes."""
    cfg = hev.config.replace(**{"engine.torque_scale": 0.4, "motor.max_torque_nm": 80.0})
    r = simulate_parallel(cfg, "us06", soc_initial=SOC0)
    assert r.value("traction_limited_s") > 10.0
    assert r.value("speed_error_max_mph") > 1.0
    assert abs(r.energy_audit["residual"]) < 1e-9 * r.value("traction_energy_j")


# ---------------------------------------------------------------- DP, ECMS, A-ECMS
@pytest.mark.parametrize("cycle", ["udds", "hwfet"])
def test_dp_replay_and_ecms_tuned_from_dp(
    hev: P.ParallelHEV, dp_runs: dict[str, OptimizationResult], cycle: str
) -> None:
    dp = dp_runs[cycle]
    dp_fuel = dp.value("fuel_kg")
    replay = simulate_parallel(hev, cycle, soc_initial=SOC0, controller=ControlSchedule.from_optimization(dp))
    assert abs(replay.value("fuel_kg") - dp_fuel) <= 0.02 * dp_fuel  # issue 11: within 2 %
    assert abs(replay.value("fuel_kg") - dp_fuel) <= 1e-9 * dp_fuel  # in fact exact
    assert replay.value("soc_final") == pytest.approx(dp.value("soc_final"), abs=1e-9)
    params = ecms_from_dp(dp)
    assert 1.0 < params["equivalence_factor"] < 5.0
    ecms = simulate_parallel(hev, cycle, soc_initial=SOC0, controller="ecms", control_points=101, **params)
    assert abs(ecms.value("soc_final") - SOC0) <= 0.01  # charge-sustaining
    # ECMS fuel corrected to the DP's final SOC with the DP's costate [kg per unit SOC]
    lam = -float(np.nanmedian(dp.timeseries["costate_kg_per_soc"]))
    corrected = ecms.value("fuel_kg") + lam * (dp.value("soc_final") - ecms.value("soc_final"))
    # never below the DP (up to the DP's own grid error, 0.5 %) and within 3 % of it
    assert 0.995 * dp_fuel <= corrected <= 1.03 * dp_fuel


@pytest.mark.parametrize("cycle", ["udds", "hwfet", "us06", "wltc3b"])
def test_adaptive_ecms_is_charge_sustaining_without_the_cycle(hev: P.ParallelHEV, cycle: str) -> None:
    r = simulate_parallel(hev, cycle, soc_initial=SOC0, controller="aecms")
    assert abs(r.value("soc_final") - SOC0) <= 0.01
    assert r.value("fuel_kg") > 0


def test_ecms_grid_has_at_least_50_points(hev: P.ParallelHEV) -> None:
    ctl = make_controller(hev, "ecms")
    assert ctl.gears.size >= 50 and ctl.gears.size == ctl.throttles.size


# ---------------------------------------------------------------- CLI and bad input
def test_cli_simulates_the_parallel_hev_and_tunes_ecms_from_a_dp_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    dp_dir = tmp_path / "dp"
    assert (
        main(
            [
                "optimize",
                str(PARALLEL),
                "--cycle",
                "hwfet",
                "--soc-points",
                "81",
                "--input-points",
                "41",
                "--final-soc",
                "sustain",
                "--no-plots",
                "--out",
                str(dp_dir),
            ]
        )
        == 0
    )
    out = tmp_path / "sim"
    assert (
        main(
            [
                "simulate",
                str(PARALLEL),
                "--cycle",
                "hwfet",
                "--ecms-from",
                str(dp_dir),
                "--no-plots",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "controller: ecms (s = " in text and "mpgge" in text
    meta = (out / "metadata.json").read_text()
    assert '"controller": "ecms"' in meta
    assert (out / "timeseries.parquet").is_file() and (out / "energy_audit.json").is_file()


@pytest.mark.parametrize(
    ("changes", "needles"),
    [
        ("[gearbox]\nratios = []\nefficiency = 0.97\n", ["gearbox.ratios", "[]", "non-empty"]),
        (
            '[controller]\nkind = "thermostat"\n',
            ["controller.kind", "'thermostat'", "parallel", "electric_assist"],
        ),
        (
            '[controller]\nkind = "electric_assist"\nupshift_rpm = 1200.0\ndownshift_rpm = 1100.0\n',
            ["upshift_rpm", "1200", "downshift_rpm", "1100", "infeasible"],
        ),
    ],
)
def test_bad_parallel_input_is_exit_2_naming_file_key_value(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], changes: str, needles: list[str]
) -> None:
    text = PARALLEL.read_text()
    section = changes.split("\n", 1)[0]
    start = text.index("\n" + section) + 1
    end = text.find("\n[", start + 1)
    assert_bad_config_exits_2(tmp_path, capsys, text[:start] + changes + text[end + 1 :], needles)


def test_series_refuses_a_parallel_controller(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    series = ROOT / "examples" / "series_hev.toml"
    text = series.read_text()
    bad = tmp_path / "s.toml"
    bad.write_text(text.replace("[controller]\n", '[controller]\nkind = "electric_assist"\n', 1))
    assert 'kind = "electric_assist"' in bad.read_text()
    with pytest.raises(
        ConfigError, match=r"'controller\.kind' = 'electric_assist' is not defined for the series"
    ):
        C.load_vehicle_config(bad)
    assert (
        main(["simulate", str(series), "--controller", "electric_assist", "--out", str(tmp_path / "o")]) == 2
    )
    assert "--controller" in capsys.readouterr().err


# ---------------------------------------------------------------- P2 (machine on the gearbox input)
@pytest.fixture(scope="module")
def p2() -> P.ParallelHEV:
    cfg = P.load_parallel_config(PARALLEL).replace(**{"motor_coupling.position": "p2"})
    return P.build_parallel_hev(cfg)


@pytest.mark.parametrize("cycle", ["udds", "hwfet", "us06"])
def test_p2_audit_closes_and_the_machine_turns_with_the_gearbox_input(p2: P.ParallelHEV, cycle: str) -> None:
    r = simulate_parallel(p2, cycle, soc_initial=SOC0, controller="ecms")
    assert abs(r.energy_audit["residual"]) < 1e-9 * r.value("traction_energy_j")
    ts = r.timeseries.iloc[:-1]
    moving = ts["speed_mps"] > 0.5
    gear = ts["gear"].to_numpy()
    assert (gear[moving.to_numpy()] >= 1).all()  # P2: a gear in EV mode too
    ratio = p2.gear_ratios[gear[moving.to_numpy()] - 1]
    w_fd = (ts["speed_mps"] + 0.5 * ts["accel_mps2"] * r.metadata["dt_s"])[moving] / p2.tire.radius_m
    w_fd = w_fd.to_numpy() * p2.final_drive.ratio
    np.testing.assert_allclose(
        ts["motor_speed_radps"][moving], w_fd * ratio * p2.motor_coupling.ratio, rtol=1e-9
    )
    ev = moving & ~ts["engine_on"] & (ts["motor_torque_nm"] > 0)
    assert ev.any()


def test_p2_dp_replay_and_ecms(p2: P.ParallelHEV) -> None:
    dp = optimize(
        p2,
        "udds",
        soc_grid_points=201,
        input_grid_points=101,
        final_soc="sustain",
        soc_initial=SOC0,
        progress=False,
    )
    assert (dp.timeseries["gear"].iloc[:-1][dp.timeseries["speed_mps"].iloc[:-1] > 1.0] >= 1).all()
    replay = simulate_parallel(p2, "udds", soc_initial=SOC0, controller=ControlSchedule.from_optimization(dp))
    assert replay.value("fuel_kg") == pytest.approx(dp.value("fuel_kg"), rel=1e-9)
    ecms = simulate_parallel(p2, "udds", soc_initial=SOC0, controller="ecms", **ecms_from_dp(dp))
    lam = -float(np.nanmedian(dp.timeseries["costate_kg_per_soc"]))
    corrected = ecms.value("fuel_kg") + lam * (dp.value("soc_final") - ecms.value("soc_final"))
    assert 0.995 * dp.value("fuel_kg") <= corrected <= 1.03 * dp.value("fuel_kg")

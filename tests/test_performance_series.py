"""Issue 11 item 4 for the series HEV: `hevsim performance` on its quasi-static power flow
(:mod:`hevsim.architectures.series`) against closed forms, the DP's stage model, the shipped
example and refinement levels, the binding limit, and the studies' performance solver."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import brentq

from hevsim import config as C
from hevsim.architectures import series
from hevsim.architectures._common import max_machine_speed_radps
from hevsim.cli import main
from hevsim.components.body import grade_force
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.optimal._hev_common import CycleSteps
from hevsim.optimal._problem import FinalTarget
from hevsim.optimal._series_dp import SeriesFormulation
from hevsim.sim.forward import simulate_architecture
from hevsim.sim.performance import LIMIT_NAMES, TOP_SPEED_ACCEL_MPS2, _Capability, performance
from hevsim.units import MPS_PER_MPH, STANDARD_GRAVITY, rpm_to_radps

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "series_hev.toml"
LEVELS = ROOT / "src" / "hevsim" / "data" / "refinement"
BUS_SHORT = f"{LIMIT_NAMES['battery_discharge_current']}, {LIMIT_NAMES['genset_power']}"
# launch: motor torque [N·m], final drive ratio and efficiency [-], tire radius [m], mass [kg],
# rotating-mass factor [-]
T_M, RATIO, ETA, R, M, DELTA = 150.0, 4.0, 0.95, 0.3, 1000.0, 1.05


def _example(**changes: object) -> C.SeriesHEVConfig:
    cfg = C.load_vehicle_config(EXAMPLE)
    assert isinstance(cfg, C.SeriesHEVConfig)
    return cfg.replace(**changes) if changes else cfg


def _launch(inertia_kgm2: float) -> C.SeriesHEVConfig:
    """Constant-torque ideal motor, ideal battery without a current limit that binds, no drag
    or rolling resistance: the launch is v = F t / m_eff."""
    return _example(**{
        "body.drag_coefficient": 0.0, "body.rolling_resistance": 0.0, "body.mass_kg": M,
        "body.mass_factor": DELTA, "motor.model": "ideal", "motor.max_torque_nm": T_M,
        "motor.inertia_kgm2": inertia_kgm2, "final_drive.ratio": RATIO, "final_drive.efficiency": ETA,
        "tire.radius_m": R, "battery.model": "ideal", "battery.ocv_v": 400.0, "battery.n_series": 1,
        "battery.capacity_ah": 50.0,
        "battery.max_discharge_current_a": 1e4, "battery.max_charge_current_a": 1e4,
    })  # fmt: skip


@pytest.mark.parametrize("inertia_kgm2", [0.0, 0.2])
def test_constant_torque_launch_is_v_equals_f_over_m_t(inertia_kgm2: float) -> None:
    force = T_M * RATIO * ETA / R
    m_eff = M * DELTA + inertia_kgm2 * (RATIO / R) ** 2  # the kernel's effective mass
    a = force / m_eff
    res = performance(_launch(inertia_kgm2), dt_s=0.2, grade_speed_mps=10.0, duration_s=25.0)
    assert res.value("0-60 mph") == pytest.approx(60.0 * MPS_PER_MPH / a, rel=1e-6)
    assert res.value("0-100 km/h") == pytest.approx(100.0 / 3.6 / a, rel=1e-6)
    assert res.value("quarter mile") == pytest.approx(math.sqrt(2.0 * 402.336 / a), rel=1e-3)
    assert res.runs["standing_start"]["accel_mps2"].to_numpy()[:40] == pytest.approx(a, rel=1e-9)
    assert res.binding("0-60 mph") == LIMIT_NAMES["motor_torque"]
    # holding 10 m/s on the steepest grade: m g sin(alpha) = F (no rolling resistance)
    g = res.value("gradeability at 22 mph") / 100.0
    assert float(grade_force(M, g)) == pytest.approx(force, rel=1e-9)
    assert res.binding("gradeability at 22 mph") == LIMIT_NAMES["motor_torque"]
    # an ideal constant-torque motor on a road without drag: no top speed within the search
    assert res.binding("top speed") == "none within the search range"


# top speed: battery OCV [V], resistance [ohm] and discharge limit [A], auxiliary load [W]
OCV, RES, I_MAX, AUX = 300.0, 0.1, 60.0, 500.0


def _top_speed_car(genset: str) -> C.SeriesHEVConfig:
    """Drag and rolling resistance; a strong ideal motor (efficiency 1); the bus power is
    the battery's at its discharge-current limit plus the genset's largest, less the
    auxiliaries. Genset: a 20 A current source, or a 100 N·m constant-torque engine
    (ideal fuel) on an ideal generator, redline 4000 rpm."""
    changes: dict[str, object] = {
        "body.drag_coefficient": 0.35, "body.frontal_area_m2": 2.2, "body.rolling_resistance": 0.01,
        "body.mass_kg": 1300.0, "body.mass_factor": 1.0, "motor.model": "ideal",
        "motor.max_torque_nm": 1000.0, "motor.inertia_kgm2": 0.05, "battery.model": "rint",
        "battery.ocv_v": OCV, "battery.n_series": 1, "battery.resistance_ohm": RES,
        "battery.capacity_ah": 20.0, "battery.max_discharge_current_a": I_MAX,
        "battery.max_charge_current_a": 1e4, "controller.aux_power_w": AUX, "genset.kind": genset,
        "genset.current_a": 20.0, "engine.model": "constant_torque", "engine.max_torque_nm": 100.0,
        "engine.redline_rpm": 4000.0, "generator.model": "ideal", "generator.max_torque_nm": 150.0,
    }  # fmt: skip
    return _example(**changes)


@pytest.mark.parametrize("genset", ["current_source", "engine"])
def test_top_speed_is_where_the_road_load_takes_the_bus_power(genset: str) -> None:
    cfg = _top_speed_car(genset)
    b = cfg.body
    p_genset = OCV * 20.0 if genset == "current_source" else 100.0 * rpm_to_radps(4000.0)
    p_battery = (OCV - RES * I_MAX) * I_MAX
    p_wheel = cfg.final_drive.efficiency * (p_battery + p_genset - AUX)  # ideal motor: no loss
    m_eff = (
        b.mass_kg * b.mass_factor + cfg.motor.inertia_kgm2 * (cfg.final_drive.ratio / cfg.tire.radius_m) ** 2
    )

    def surplus(v: float) -> float:  # road load (eq 32) with the search's 1e-3 m/s^2 margin
        drag = 0.5 * b.air_density_kgpm3 * b.drag_coefficient * b.frontal_area_m2 * v * v
        roll = b.rolling_resistance * b.mass_kg * STANDARD_GRAVITY
        return p_wheel - (drag + roll + m_eff * TOP_SPEED_ACCEL_MPS2) * v

    dt = 0.5
    v_mid = brentq(surplus, 1.0, 100.0, xtol=1e-12)
    res = performance(cfg, dt_s=dt, duration_s=2.0)
    v_top = v_mid - 0.5 * TOP_SPEED_ACCEL_MPS2 * dt  # the search's speed is the step's start
    assert res.value("top speed") * MPS_PER_MPH == pytest.approx(v_top, rel=1e-5)
    assert res.binding("top speed") == BUS_SHORT


def test_top_speed_at_the_end_of_the_motor_map() -> None:
    """A tall final drive (ratio 12): the motor reaches the last speed of its map (8500 rpm)
    while it still has power to spare, so the top speed is that speed at the wheels."""
    cfg = _example(**{"final_drive.ratio": 12.0})
    hev = series.build_series_hev(cfg)
    v_max = max_machine_speed_radps(hev.traction_motor) * cfg.tire.radius_m / 12.0
    res = performance(cfg, dt_s=0.5, duration_s=2.0)
    v_top = v_max - 0.5 * TOP_SPEED_ACCEL_MPS2 * 0.5  # the step's mid speed is at the limit
    assert res.value("top speed") * MPS_PER_MPH == pytest.approx(v_top, rel=1e-9)
    assert res.binding("top speed") == LIMIT_NAMES["motor_speed"]


def test_power_flow_is_the_dp_stage_model() -> None:
    """Without rotor inertia the quasi-static power flow and the DP's stage model are the
    same physics: equal SOC change, fuel and feasibility at every UDDS step and genset power."""
    cfg = _example(**{"motor.inertia_kgm2": 0.0})
    hev = series.build_series_hev(cfg)
    cycle = load_cycle("udds")
    dp = SeriesFormulation(hev, cycle, soc_grid=np.linspace(0.3, 0.9, 7), power_points=21, soc_initial=0.7,
                           target=FinalTarget())  # fmt: skip
    grid = dp.input_grids[0]
    k = np.arange(dp.steps.n_steps)[:, None]
    ref = dp.stage(k, (grid[None, :],), 0.6)
    s: CycleSteps = dp.steps
    got = series.power_flow(hev, s.wheel_speed_radps[:, None], s.wheel_torque_nm[:, None], grid[None, :], 0.6,
                            s.dt_s[:, None], (s.v_mid_mps > 0.0)[:, None])  # fmt: skip
    np.testing.assert_allclose(got.d_soc, ref.d_soc, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(got.cost_kg, ref.cost_kg, rtol=1e-12, atol=1e-15)
    assert np.array_equal(got.infeasible, ref.infeasible)
    assert np.count_nonzero(~got.infeasible) > 0.5 * got.infeasible.size  # mostly feasible: a real check


def test_quasi_static_run_closes_its_energy_audit() -> None:
    """Launch, cruise and braking (regeneration, friction brakes) with the genset at the
    largest power the bus admits: fuel + battery = losses + road + kinetic, to round-off."""
    hev = series.quasi_static_model(series.build_series_hev(_example()))
    t = np.arange(0.0, 40.5, 0.5)
    v = np.interp(t, [0.0, 12.0, 25.0, 35.0, 40.0], [0.0, 20.0, 20.0, 0.0, 0.0])
    res = simulate_architecture("series", hev, DriveCycle("launch_brake", t, v), dt_s=0.5, soc_initial=0.7,
                                controller=_Capability(series.capability_controls(hev)))  # fmt: skip
    audit = res.energy_audit
    assert audit["fuel"] > 0.0 and audit["friction_brakes"] > 0.0 and audit["motor_loss"] > 0.0
    assert res.metrics["energy_audit_residual_traction_pct"]["value"] < 1e-9
    assert res.value("speed_error_rms_mph") < 0.01  # the powertrain follows this cycle


def _quick(cfg: C.SeriesHEVConfig) -> pd.DataFrame:
    return performance(cfg, dt_s=0.5, duration_s=30.0).table.set_index("test")


def test_binding_limit_follows_the_limiting_component() -> None:
    base = _quick(_example())
    assert base.loc["0-60 mph", "binding_limit"] == LIMIT_NAMES["motor_torque"]
    small = _quick(_example(**{"battery.max_discharge_current_a": 10.0}))
    assert small.loc["0-60 mph", "binding_limit"] == BUS_SHORT
    assert small.loc["0-60 mph", "value"] > base.loc["0-60 mph", "value"]
    slick = _quick(_example(**{"tire.friction_coefficient": 0.3}))
    assert slick.loc["0-60 mph", "binding_limit"] == LIMIT_NAMES["traction"]
    assert slick.loc["gradeability at 30 mph", "binding_limit"] == LIMIT_NAMES["traction"]
    assert slick.loc["0-60 mph", "value"] > base.loc["0-60 mph", "value"]


@pytest.mark.parametrize(
    "level", ["level1_ev_constant_torque", "level3_constant_current_genset", "level4_engine_speed_control",
              "level8_motor_maps"],
)  # fmt: skip
def test_refinement_levels_run(level: str) -> None:
    res = performance(LEVELS / f"{level}.toml", dt_s=0.5, duration_s=25.0)
    assert 8.0 < res.value("0-60 mph") < 20.0
    assert 60.0 < res.value("top speed") < 150.0
    assert 5.0 < res.value("gradeability at 30 mph") < 60.0
    names = set(LIMIT_NAMES.values())
    for test in ("0-60 mph", "top speed", "gradeability at 30 mph"):
        assert set(res.binding(test).split(", ")) <= names, (test, res.binding(test))


def test_cli_runs_the_series_example(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "perf"
    assert main(["performance", str(EXAMPLE), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "series_hev (series): performance" in text and "binding limit" in text
    assert "0-60 mph" in text and "top speed" in text and LIMIT_NAMES["motor_torque"] in text
    for f in ("performance.csv", "performance.md", "metadata.json", "standing_start.csv",
              "passing_50_80_mph.csv", "speed_power.png"):  # fmt: skip
        assert (out / f).is_file(), f
    table = pd.read_csv(out / "performance.csv").set_index("test")
    assert 10.0 < table.loc["0-60 mph", "value"] < 16.0
    run = pd.read_csv(out / "standing_start.csv")
    assert run["genset_power_w"].iloc[5] > 30e3  # the genset at (near) its largest power
    assert (run["engine_on"].iloc[1:] > 0).all()


def test_studies_performance_solver_accepts_the_series_hev() -> None:
    from hevsim.studies.runner import run_study
    from hevsim.studies.solvers import OK
    from hevsim.studies.spec import study_from_dict

    study = study_from_dict({
        "name": "series_perf", "vehicle": str(EXAMPLE), "cycles": ["udds"],
        "metrics": ["time_0_60_mph_s", "top_speed_mph"],
        "parameters": {"battery.max_discharge_current_a": [10.0]},
        "solvers": [{"name": "performance", "dt_s": 0.5}],
    })  # fmt: skip
    rows = run_study(study, scheduler="in-process", progress=False)
    assert (rows["status"] == OK).all(), rows["error"].tolist()
    ref = performance(_example(**{"battery.max_discharge_current_a": 10.0}), dt_s=0.5)
    assert rows["time_0_60_mph_s"].iloc[0] == ref.value("0-60 mph")
    assert rows["top_speed_mph"].iloc[0] == ref.value("top speed")

"""Issue 11 item 4: the tire-adhesion limit of the performance tests against closed forms."""

from __future__ import annotations

from pathlib import Path

import pytest

from hevsim import config as C
from hevsim.errors import ConfigError
from hevsim.sim.performance import performance
from hevsim.units import MPS_PER_MPH, STANDARD_GRAVITY

ROOT = Path(__file__).resolve().parents[1]
# friction coefficient, CG height [m], CG to front / rear axle [m], rotating-mass factor
MU, H, A_F, B_R, DELTA = 1.0, 0.5, 1.4, 1.6, 1.1
TRACTION = "traction (tire adhesion)"


def _powerful(axle: str, mu: float = MU) -> C.ConventionalConfig:
    """One gear, 1500 N·m constant-torque engine (12.8 kN at the wheels, 1.3 g on 1000 kg), no
    drag or rolling resistance: the launch is traction-limited whichever axle drives."""
    return C.load_vehicle_config(ROOT / "examples" / "conventional_sedan.toml").replace(**{
        "body.drag_coefficient": 0.0, "body.rolling_resistance": 0.0, "body.mass_kg": 1000.0,
        "body.mass_factor": DELTA, "body.cg_height_m": H, "body.front_axle_to_cg_m": A_F,
        "body.rear_axle_to_cg_m": B_R, "engine.model": "constant_torque", "engine.max_torque_nm": 1500.0,
        "engine.redline_rpm": 6000.0, "gearbox.ratios": [1.0], "gearbox.efficiency": 0.9,
        "final_drive.ratio": 3.0, "final_drive.efficiency": 0.95, "tire.radius_m": 0.3,
        "tire.friction_coefficient": mu, "tire.driven_axle": axle,
    })  # fmt: skip


def _closed_form_accel(axle: str) -> float:
    """a = mu g (static share) / (delta -/+ mu h / L): F = delta m a = mu (static load +/- m a h / L)."""
    wheelbase = A_F + B_R
    if axle == "all":
        return MU * STANDARD_GRAVITY / DELTA
    share, sign = (A_F / wheelbase, 1.0) if axle == "rear" else (B_R / wheelbase, -1.0)
    return MU * STANDARD_GRAVITY * share / (DELTA - sign * MU * H / wheelbase)


@pytest.mark.parametrize("axle", ["front", "rear", "all"])
def test_traction_limited_launch_matches_the_closed_form(axle: str) -> None:
    a = _closed_form_accel(axle)
    assert DELTA * 1000.0 * a < 1500.0 * 0.9 * 3.0 * 0.95 / 0.3  # the engine could give more
    res = performance(_powerful(axle), dt_s=0.1, grade_speed_mps=10.0)
    assert res.value("0-60 mph") == pytest.approx(60 * MPS_PER_MPH / a, rel=1e-6)
    assert res.value("0-100 km/h") == pytest.approx(100 / 3.6 / a, rel=1e-6)
    assert res.binding("0-60 mph") == TRACTION
    accel = res.runs["standing_start"]["accel_mps2"].to_numpy()[:20]
    assert accel == pytest.approx(a, rel=1e-6)


def test_load_transfer_favours_the_rear_axle() -> None:
    assert _closed_form_accel("rear") > _closed_form_accel("front")
    share = B_R / (A_F + B_R)  # front static share, without load transfer: mu g share / delta
    assert _closed_form_accel("front") < MU * STANDARD_GRAVITY * share / DELTA


def test_gradeability_all_wheel_drive_is_mu() -> None:
    """Holding speed on grade alpha: m g sin(alpha) = mu m g cos(alpha), so the grade is mu."""
    res = performance(_powerful("all", mu=0.8), dt_s=0.1, grade_speed_mps=10.0)
    assert res.value("gradeability at 22 mph") == pytest.approx(80.0, rel=1e-6)
    assert res.binding("gradeability at 22 mph") == TRACTION


def test_rear_drive_that_would_wheelie_is_refused() -> None:
    cfg = _powerful("rear").replace(**{"tire.friction_coefficient": 2.0, "body.cg_height_m": 1.6})
    with pytest.raises(ConfigError, match=r"tire\.friction_coefficient"):
        performance(cfg)


def test_friction_coefficient_is_bounded() -> None:
    with pytest.raises(ConfigError, match="friction_coefficient"):
        _powerful("front", mu=3.0)

"""Issue 11 item 5: `hevsim performance` (accelerations, top speed, gradeability, binding limit)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim import config as C
from hevsim.cli import main
from hevsim.components.body import grade_force
from hevsim.sim.performance import performance
from hevsim.units import MPS_PER_MPH, rpm_to_radps

ROOT = Path(__file__).resolve().parents[1]


def _toy() -> C.ConventionalConfig:
    """One gear, constant-torque engine, no drag or rolling resistance: everything analytic."""
    return C.load_vehicle_config(ROOT / "examples" / "conventional_sedan.toml").replace(**{
        "body.drag_coefficient": 0.0, "body.rolling_resistance": 0.0, "body.mass_kg": 1000.0,
        "body.mass_factor": 1.1, "engine.model": "constant_torque", "engine.max_torque_nm": 300.0,
        "engine.redline_rpm": 6000.0, "gearbox.ratios": [1.0], "gearbox.efficiency": 0.9,
        "final_drive.ratio": 3.0, "final_drive.efficiency": 0.95, "tire.radius_m": 0.3,
    })  # fmt: skip


def test_analytic_vehicle() -> None:
    cfg = _toy()
    force = 300.0 * 1.0 * 0.9 * 3.0 * 0.95 / 0.3
    a = force / (1000.0 * 1.1)
    res = performance(cfg, dt_s=0.1, grade_speed_mps=10.0)
    # constant force until the redline: v = a t, s = a t^2 / 2
    assert res.value("0-60 mph") == pytest.approx(60 * MPS_PER_MPH / a, rel=1e-6)
    assert res.value("0-100 km/h") == pytest.approx(100 / 3.6 / a, rel=1e-6)
    v_red = rpm_to_radps(6000.0) * 0.3 / 3.0
    assert res.value("top speed") == pytest.approx(v_red / MPS_PER_MPH, rel=1e-5)  # (the 1e-3 m/s^2 margin)
    assert res.binding("top speed") == "engine speed (redline)"
    assert res.binding("0-60 mph") == "engine torque"
    g = res.value("gradeability at 22 mph") / 100.0
    assert float(grade_force(1000.0, g)) == pytest.approx(force, rel=1e-9)
    assert res.binding("gradeability at 22 mph") == "engine torque"
    t_q = np.sqrt(2 * 402.336 / a)
    if a * t_q < v_red:
        assert res.value("quarter mile") == pytest.approx(t_q, rel=1e-3)


@pytest.mark.parametrize(
    ("name", "lo_060", "hi_060", "binding_top"),
    [("conventional_sedan", 8.0, 16.0, "engine torque"), ("bev", 4.0, 12.0, "machine speed (end of its map)"),
     ("parallel_hev", 4.0, 12.0, "battery discharge current")],
)  # fmt: skip
def test_shipped_vehicles_are_plausible(name: str, lo_060: float, hi_060: float, binding_top: str) -> None:
    res = performance(ROOT / "examples" / f"{name}.toml")
    assert lo_060 < res.value("0-60 mph") < hi_060
    assert res.value("0-60 mph") < res.value("0-100 km/h") < res.value("quarter mile")
    assert 70.0 < res.value("top speed") < 150.0
    assert res.binding("top speed") == binding_top
    assert 0.0 < res.value("50-80 mph") < 30.0


def test_cli_writes_the_table_and_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "perf"
    assert main(["performance", str(ROOT / "examples" / "conventional_sedan.toml"), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "0-60 mph" in text and "binding limit" in text and "engine torque" in text
    for f in ("performance.csv", "performance.md", "standing_start.csv", "speed_power.png"):
        assert (out / f).is_file(), f


def test_cli_refuses_an_architecture_without_an_envelope_and_bad_options(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every shipped architecture has a performance envelope (``capability_controls``); one
    registered without it (here: the series entry pointed at a module without one) is refused
    with the list of those that have it, taken from the registry."""
    import dataclasses

    from hevsim.architectures import ARCHITECTURES

    no_envelope = dataclasses.replace(ARCHITECTURES["series"], module="hevsim.architectures._common")
    monkeypatch.setitem(ARCHITECTURES, "series", no_envelope)
    out = tmp_path / "o"
    assert main(["performance", str(ROOT / "examples" / "series_hev.toml"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "series_hev" in err and "'series'" in err and "parallel, conventional, bev, power_split" in err
    assert not out.exists()
    monkeypatch.undo()
    assert main(["performance", str(ROOT / "examples" / "bev.toml"), "--soc", "1.5", "--out", str(out)]) == 2
    assert "--soc = 1.5" in capsys.readouterr().err
    assert not out.exists()

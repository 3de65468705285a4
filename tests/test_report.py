"""Report: every plot is written as a valid PNG, the Markdown report lists metrics and plots."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from hevsim.report import PLOT_FILES, REPORT_FILE, build_report, plot_all, write_report
from hevsim.report.markdown import MAX_EVENT_ROWS, format_number
from hevsim.report.plots import bsfc_grid, fuel_rate_kgps, plot_engine_operating_points
from hevsim.tables import Table1D, Table2D

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
N_ROWS = 200
LHV_JPKG = 42.6e6  # gasoline lower heating value [J/kg], only to shape the fake map
ENGINE_FILES = {PLOT_FILES["engine"], PLOT_FILES["engine_operating_points"]}
MODE_NAMES = ("pure_ev", "pure_ice", "combined", "ice_charging", "charging")


def fake_engine(torque_scale: float = 1.0) -> SimpleNamespace:
    """An engine with a smooth, bowl-shaped efficiency map (best ~ 250 rad/s, 100 N·m)."""
    speed = np.linspace(100.0, 450.0, 8)
    torque = np.linspace(0.0, 120.0, 9)
    w, t = np.meshgrid(speed, torque, indexing="ij")
    eta = np.clip(0.36 - 0.10 * ((w - 250.0) / 200.0) ** 2 - 0.12 * ((t - 100.0) / 110.0) ** 2, 0.1, None)
    fuel = 1e-4 + w * t / (eta * LHV_JPKG)
    return SimpleNamespace(
        name="fake 1.5 L",
        fuel_map=Table2D(speed, torque, fuel),
        max_torque=Table1D(speed, np.array([80.0, 95.0, 105.0, 112.0, 115.0, 114.0, 108.0, 100.0])),
        torque_scale=torque_scale,
    )


def fake_timeseries(engine: SimpleNamespace | None, fired: bool = True) -> pd.DataFrame:
    t = np.arange(N_ROWS, dtype=float)
    v_des = 20.0 * np.sin(np.pi * t / N_ROWS) ** 2
    v = v_des - 0.1 * np.sin(t / 7.0)
    genset = np.zeros(N_ROWS, dtype=np.int64)
    if engine is not None and fired:
        genset[40:43] = 1
        genset[43:150] = 2
    running = genset == 2
    eng_w = np.where(running, 220.0 + 60.0 * np.sin(t / 15.0), 0.0)
    eng_t = np.where(running, 70.0 + 30.0 * np.cos(t / 11.0), 0.0)
    fuel = np.where(running, engine.fuel_map(eng_w, eng_t), 0.0) if engine is not None else np.zeros(N_ROWS)
    mode = np.where(running, np.where(v_des > 15.0, 2, 3), np.where(v_des > 18.0, 4, 0))
    gen_i = np.where(running, -eng_w * eng_t * 0.9 / 200.0, 0.0)
    mot_i = 0.5 * 1400.0 * v / 200.0 * np.cos(t / 30.0)
    return pd.DataFrame(
        {
            "time_s": t,
            "speed_desired_mps": v_des,
            "speed_mps": v,
            "motor_current_a": mot_i,
            "generator_current_a": gen_i,
            "battery_current_a": mot_i + gen_i,
            "engine_speed_radps": eng_w,
            "engine_torque_nm": eng_t,
            "engine_throttle": np.where(running, eng_t / 115.0, 0.0),
            "fuel_rate_kgps": fuel,
            "soc": 0.6 - 0.0004 * t + 0.0008 * np.cumsum(running) / 2.0,
            "genset_state": genset,
            "power_mode": mode,
            "power_mode_name": [MODE_NAMES[m] for m in mode],
        }
    )


def fake_result(engine: SimpleNamespace | None, fired: bool = True) -> SimpleNamespace:
    metrics = {
        name: {"value": value, "unit": unit, "description": f"{name} | test metric"}
        for name, value, unit in (
            ("mpg", 52.345678, "mpg"),
            ("mpgge", 49.9, "mpgge"),
            ("distance_mi", 1.5234, "mi"),
            ("fuel_l", 0.1234567, "L"),
            ("co2_g_per_km", 123.456, "g/km"),
            ("speed_error_rms_mph", 0.0712, "mph"),
            ("energy_audit_residual_pct", 1.2e-5, "%"),
            ("soc_final", 0.6123, "-"),
        )
    }
    audit = {
        "fuel": 3.0e7,
        "battery_chemical": 1.5e6,
        "aero": 3.0e6,
        "rolling": 2.0e6,
        "grade": 0.0,
        "kinetic_vehicle": -1.0e4,
        "friction_brakes": 4.0e5,
        "engine_loss": 2.1e7,
        "generator_loss": 8.0e5,
        "motor_loss": 1.2e6,
        "battery_loss": 3.0e5,
        "aux": 2.8e6,
    }
    audit["residual"] = (
        audit["fuel"]
        + audit["battery_chemical"]
        - sum(v for k, v in audit.items() if k not in ("fuel", "battery_chemical"))
    )
    n_events = 25
    events = pd.DataFrame(
        {
            "time_s": np.linspace(10.0, 190.0, n_events),
            "kind": ["genset" if i % 3 == 0 else "power_mode" for i in range(n_events)],
            "from_state": [i % 3 for i in range(n_events)],
            "to_state": [(i + 1) % 3 for i in range(n_events)],
            "reason": [i % 4 for i in range(n_events)],
        }
    )
    return SimpleNamespace(
        timeseries=fake_timeseries(engine, fired),
        metrics=metrics,
        energy_audit=audit,
        events=events,
        metadata={"config_name": "series_test", "cycle_name": "udds", "timings": {"run_s": 0.42}},
        engine=engine,
    )


def assert_png(path: Path) -> None:
    assert path.is_file(), path
    data = path.read_bytes()
    assert len(data) > 1000, path
    assert data[:8] == PNG_SIGNATURE, path


def test_plot_all_and_report(tmp_path: Path) -> None:
    result = fake_result(fake_engine())
    plots = plot_all(result, tmp_path)
    assert {p.name for p in plots} == set(PLOT_FILES.values())
    for p in plots:
        assert p.parent == tmp_path
        assert_png(p)
    report = write_report(result, tmp_path, plots)
    assert report == tmp_path / REPORT_FILE
    text = report.read_text(encoding="utf-8")
    assert text.startswith("# hevsim report: series_test on udds")
    for name in result.metrics:
        assert f"`{name}`" in text
    for p in plots:
        assert f"]({p.name})" in text
    assert "52.35" in text  # mpg rounded to 4 significant digits
    assert "test metric" in text and "\\|" in text  # pipe in description escaped
    assert "## Energy audit" in text and "residual" in text.lower()
    assert f"First {MAX_EVENT_ROWS} of 25 events" in text
    assert not list(tmp_path.glob("*.tmp"))


def test_plot_all_without_engine(tmp_path: Path) -> None:
    result = fake_result(None)
    plots = plot_all(result, tmp_path / "out")
    names = {p.name for p in plots}
    assert names == set(PLOT_FILES.values()) - ENGINE_FILES
    for p in plots:
        assert_png(p)
    assert not any((tmp_path / "out" / f).exists() for f in ENGINE_FILES)
    report = build_report(result, tmp_path / "out")
    text = report.read_text(encoding="utf-8")
    for p in plots:
        assert f"]({p.name})" in text
    assert "engine_operating_points" not in text


def test_operating_points_without_fired_points_still_draws_map(tmp_path: Path) -> None:
    engine = fake_engine(torque_scale=1.3)
    ts = fake_timeseries(engine, fired=False)
    out = plot_engine_operating_points(ts, engine, tmp_path / "op.png")
    assert out is not None
    assert_png(out)
    assert plot_engine_operating_points(ts, None, tmp_path / "none.png") is None
    assert not (tmp_path / "none.png").exists()


def test_bsfc_grid_is_plausible_and_scales_with_torque() -> None:
    _, t, bsfc = bsfc_grid(fake_engine())
    best = np.nanmin(bsfc)
    # at the fake map's best point (250 rad/s, 100 N·m, efficiency 0.36 plus the idle fuel)
    # BSFC = 3.6e9 * (1e-4 / 25e3 + 1 / (0.36 * 42.6e6)) = 249 g/kWh [g/kWh]
    expected = 3.6e9 * (1e-4 / (250.0 * 100.0) + 1.0 / (0.36 * LHV_JPKG))
    assert best == pytest.approx(expected, rel=0.03)
    assert np.nanmax(bsfc) > 1.5 * best  # the bowl is resolved, not flat
    _, t_scaled, bsfc_scaled = bsfc_grid(fake_engine(torque_scale=1.3))
    assert t_scaled[-1] == pytest.approx(1.3 * t[-1])
    assert np.nanmin(bsfc_scaled) == pytest.approx(best, rel=1e-6)


def test_fuel_rate_in_grams_per_second_is_understood(tmp_path: Path) -> None:
    """The simulator may store the fuel rate in [g/s]; the operating points must still show."""
    engine = fake_engine()
    ts = fake_timeseries(engine)
    ts["fuel_rate_gps"] = ts.pop("fuel_rate_kgps") * 1000.0
    out = plot_engine_operating_points(ts, engine, tmp_path / "op.png")
    assert out is not None
    assert_png(out)
    np.testing.assert_allclose(fuel_rate_kgps(ts), fuel_rate_kgps(fake_timeseries(engine)))


def test_report_without_events_or_audit(tmp_path: Path) -> None:
    result = fake_result(None)
    result.events = result.events.iloc[0:0]
    result.energy_audit = {}
    plots = plot_all(result, tmp_path)
    assert PLOT_FILES["energy_audit"] not in {p.name for p in plots}
    text = write_report(result, tmp_path, plots).read_text(encoding="utf-8")
    assert "No mode-change events." in text
    assert "No energy audit." in text


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        (52.345678, "52.35"),
        (0.1234567, "0.1235"),
        (12345.6, "12346"),
        (3.0, "3"),
        (1.2e-5, "1.2e-05"),
        (49.90, "49.9"),
        (2.5e13, "2.5e+13"),
        (12345678.9, "12345679"),
        (0.0, "0"),
        (float("nan"), "nan"),
        ("abc", "abc"),
    ],
)
def test_format_number(value: object, expected: str) -> None:
    assert format_number(value) == expected

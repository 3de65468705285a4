"""Tracks (issue 29 item 1): geometry of the shipped tracks, the two CSV layouts, smoothing,
resampling, and bad tracks refused with the place along the track."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hevsim import tracks
from hevsim.errors import InputError


def _circle_xy(radius_m: float, n: int, turn_deg: float = 360.0) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, math.radians(turn_deg), n, endpoint=turn_deg < 360.0)
    return radius_m * np.cos(t), radius_m * np.sin(t)


def test_skidpad_is_a_circle_of_the_stated_radius() -> None:
    t = tracks.skidpad()
    assert t.length_m == pytest.approx(2.0 * math.pi * tracks.SKIDPAD_RADIUS_M, rel=1e-12)
    assert np.allclose(t.curvature_1pm, 1.0 / tracks.SKIDPAD_RADIUS_M, rtol=1e-12)
    r = np.hypot(t.x_m - t.x_m.mean(), t.y_m - t.y_m.mean())
    assert np.allclose(r, tracks.SKIDPAD_RADIUS_M, rtol=1e-3)


def test_handling_circuit_closes_with_the_stated_lengths() -> None:
    t = tracks.handling_circuit(step_m=0.5)
    q = 0.5 * math.pi
    expected = 700 + q * 60 + 200 + q * 30 + 150 + q * 40 + 100 + q * 40 + 530 + q * 50 + 340 + q * 80
    assert t.length_m == pytest.approx(expected, rel=1e-12)
    assert np.sum(t.curvature_1pm) * t.step_m == pytest.approx(2.0 * math.pi, abs=0.02)
    assert 1.0 / np.max(np.abs(t.curvature_1pm)) == pytest.approx(30.0)
    # the corner T2 (R 30 m) starts 700 + 94.2 + 200 m from the start
    i = int(np.flatnonzero(np.abs(t.curvature_1pm) > 1.0 / 30.5)[0])
    assert t.distance_m[i] == pytest.approx(700 + q * 60 + 200, abs=t.step_m)


def test_oval_length() -> None:
    t = tracks.oval()
    assert t.length_m == pytest.approx(2 * 800 + 2 * math.pi * 200, rel=1e-12)


def test_xy_circle_smoothed_curvature_is_one_over_radius(tmp_path: Path) -> None:
    x, y = _circle_xy(50.0, 200)
    p = tmp_path / "ring.csv"
    rows = "\n".join(f"{a:.6f},{b:.6f},5.0,6.0" for a, b in zip(x, y, strict=True))
    p.write_text("# x_m,y_m,w_tr_right_m,w_tr_left_m\n" + rows + "\n", encoding="utf-8")
    t = tracks.load_track_csv(p, step_m=1.0)
    assert t.length_m == pytest.approx(2 * math.pi * 50.0, rel=1e-3)
    assert np.allclose(t.curvature_1pm, 1.0 / 50.0, rtol=5e-3)
    assert np.allclose(t.width_right_m, 5.0) and np.allclose(t.width_left_m, 6.0)


def test_distance_curvature_csv_with_elevation(tmp_path: Path) -> None:
    r = 40.0
    length = 2 * math.pi * r
    s = np.linspace(0.0, length, 101)
    p = tmp_path / "dk.csv"
    lines = ["distance_m,curvature_1pm,elevation_m"]
    lines += [f"{a:.9f},{1.0 / r:.12f},{2.0 * math.sin(2 * math.pi * a / length):.9f}" for a in s]
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    t = tracks.load_track_csv(p, step_m=0.5)
    assert t.length_m == pytest.approx(length)
    assert np.allclose(t.curvature_1pm, 1.0 / r)
    assert np.max(t.elevation_m) == pytest.approx(2.0, abs=0.01)
    assert np.max(np.abs(t.grade)) == pytest.approx(2.0 * 2 * math.pi / length, rel=0.01)


def test_shipped_monza_is_the_real_length_and_smooth() -> None:
    t = tracks.load_track("monza")
    assert t.length_m == pytest.approx(5793.0, rel=0.002)  # official length of the circuit
    assert 1.0 / np.max(np.abs(t.curvature_1pm)) > 10.0
    assert np.all(np.isfinite(t.width_right_m)) and np.all(t.width_right_m > 3.0)


def test_resampled_keeps_the_loop() -> None:
    t = tracks.handling_circuit(step_m=1.0)
    u = t.resampled(2.0)
    assert u.length_m == pytest.approx(t.length_m)
    assert u.step_m == pytest.approx(2.0, rel=1e-3)


def test_plot_writes_a_png(tmp_path: Path) -> None:
    out = tracks.skidpad().plot(tmp_path / "t.png")
    assert out.stat().st_size > 1000


# ---------------------------------------------------------------------------------------------
# Bad tracks: exit 2 with the location along the track
# ---------------------------------------------------------------------------------------------
def test_xy_track_that_does_not_close_names_the_gap_and_distance(tmp_path: Path) -> None:
    x, y = _circle_xy(50.0, 150, turn_deg=300.0)
    p = tmp_path / "open.csv"
    p.write_text(
        "x_m,y_m\n" + "\n".join(f"{a},{b}" for a, b in zip(x, y, strict=True)) + "\n", encoding="utf-8"
    )
    with pytest.raises(InputError, match=r"does not close: the last point \(distance 26[0-9.]+ m"):
        tracks.load_track_csv(p)


def test_curvature_track_that_does_not_close_names_its_end() -> None:
    with pytest.raises(InputError, match=r"does not close: at distance 300.0 m"):
        tracks.from_curvature("arc", [0.0, 300.0], [1.0 / 50.0, 1.0 / 50.0])


def test_self_intersecting_track_names_the_crossing(tmp_path: Path) -> None:
    t = np.linspace(0.0, 2 * math.pi, 400, endpoint=False) + 1.0
    x, y = 100.0 * np.sin(t), 50.0 * np.sin(2 * t)  # a figure eight crossing at the origin
    p = tmp_path / "eight.csv"
    p.write_text(
        "x_m,y_m\n" + "\n".join(f"{a},{b}" for a, b in zip(x, y, strict=True)) + "\n", encoding="utf-8"
    )
    # the crossing is at the origin, t = pi, 201 m round the loop from t = 1
    with pytest.raises(
        InputError, match=r"crosses itself at distance 20[01].[0-9] m \(x = -?0.[0-9] m, y = -?0.[0-9] m"
    ):
        tracks.load_track_csv(p)


def test_curvature_spike_beyond_the_turning_radius_names_the_distance() -> None:
    t = tracks.handling_circuit()
    t.check_radius(29.0)  # the tightest corner is R 30 m
    with pytest.raises(
        InputError, match=r"at distance 99[45].[0-9] m .* below the minimum turning radius 40 m"
    ):
        t.check_radius(40.0)


def test_bad_number_names_line_and_column(tmp_path: Path) -> None:
    p = tmp_path / "bad.csv"
    p.write_text("x_m,y_m\n0,0\n1,abc\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"line 3, column 'y_m': value 'abc'"):
        tracks.load_track_csv(p)


def test_unknown_layout_lists_the_expected_columns(tmp_path: Path) -> None:
    p = tmp_path / "bad.csv"
    p.write_text("a,b\n0,0\n1,1\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"expected 'x_m', 'y_m'"):
        tracks.load_track_csv(p)


def test_segment_rows_csv_reproduces_the_geometry(tmp_path: Path) -> None:
    d, k = tracks.segment_rows(tracks.geometry("handling"))
    p = tmp_path / "handling.csv"
    rows = "\n".join(f"{a:.10f},{b:.12g}" for a, b in zip(d, k, strict=True))
    p.write_text("distance_m,curvature_1pm\n" + rows, encoding="utf-8")
    back = tracks.load_track_csv(p, step_m=1.0)
    ref = tracks.handling_circuit(step_m=1.0)
    assert back.length_m == pytest.approx(ref.length_m, rel=1e-12)
    assert np.abs(back.curvature_1pm - ref.curvature_1pm).max() < 1e-9
    assert np.hypot(back.x_m - ref.x_m, back.y_m - ref.y_m).max() < 1e-5  # the 1 um ramps

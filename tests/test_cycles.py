"""Drive cycles: shipped data against its metadata, derived cycles, user CSV files, errors."""

from __future__ import annotations

import tomllib
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hevsim.cycles import (
    CYCLE_NAMES,
    DriveCycle,
    list_cycles,
    load_cycle,
    load_cycle_csv,
)
from hevsim.errors import InputError
from hevsim.units import MPS_PER_MPH

# registered name -> table in data/cycles/cycles.toml (derived cycles have none)
TOML_KEYS = {
    "udds": "udds",
    "ftp75": "ftp75",
    "hwfet": "hwfet",
    "us06": "us06",
    "sc03": "sc03",
    "nycc": "nycc",
    "la92": "la92",
    "wltc3b": "wltc_class3b",
    "wltc3a": "wltc_class3a",
    "nedc": "nedc_approx",
    "manhattan_bus": "manhattan_bus",
    "hotlap_0_200": "hotlap_0_200",
}
DERIVED = {"fu505", "fu505x10"}
MAX_SPEED_TOL_MPS = 1e-4  # cycles.toml rounds speeds to 4 decimals [m/s]


def _metadata() -> dict[str, Any]:
    with (files("hevsim") / "data" / "cycles" / "cycles.toml").open("rb") as stream:
        return tomllib.load(stream)


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def test_registry_covers_every_cycle() -> None:
    assert set(CYCLE_NAMES) == set(TOML_KEYS) | DERIVED


def test_udds_headline_figures() -> None:
    stats = load_cycle("udds").summary()
    assert stats["duration_s"] == 1369.0
    assert stats["distance_mi"] == pytest.approx(7.45, abs=0.01)
    assert stats["max_speed_mph"] == pytest.approx(56.7, abs=0.05)


@pytest.mark.parametrize("name", CYCLE_NAMES)
def test_registered_cycle_loads_and_matches_metadata(name: str) -> None:
    cycle = load_cycle(name)
    assert cycle.name == name
    assert cycle.description
    assert cycle.source
    assert not cycle.time_s.flags.writeable
    if name in DERIVED:
        return
    meta = _metadata()[TOML_KEYS[name]]
    assert cycle.n_samples == meta["n_samples"]
    assert cycle.duration_s == pytest.approx(meta["duration_s"], abs=1e-9)
    assert cycle.distance_m == pytest.approx(meta["distance_m"], rel=1e-3)
    assert cycle.max_speed_mps == pytest.approx(meta["max_speed_m_per_s"], abs=MAX_SPEED_TOL_MPS)


def test_nedc_description_keeps_quality_warning() -> None:
    warning = _metadata()["nedc_approx"]["quality_warning"]
    assert warning in load_cycle("nedc").description


def test_fu505_is_first_505_s_of_udds() -> None:
    udds = load_cycle("udds")
    fu505 = load_cycle("fu505")
    assert fu505.duration_s == 505.0
    n = fu505.n_samples
    assert n == 506
    np.testing.assert_array_equal(fu505.time_s, udds.time_s[:n])
    np.testing.assert_array_equal(fu505.speed_mps, udds.speed_mps[:n])
    np.testing.assert_array_equal(fu505.grade, udds.grade[:n])
    assert fu505.speed_mps[-1] == 0.0


def test_fu505x10_is_ten_repeats() -> None:
    fu505 = load_cycle("fu505")
    fu505x10 = load_cycle("fu505x10")
    assert fu505x10.duration_s == 5050.0
    assert fu505x10.n_samples == 10 * (fu505.n_samples - 1) + 1
    assert fu505x10.distance_m == pytest.approx(10 * fu505.distance_m, rel=1e-9)
    np.testing.assert_array_equal(np.diff(fu505x10.time_s), 1.0)
    # repeat k is fu505 shifted by 505 k seconds
    np.testing.assert_array_equal(fu505x10.speed_mps[505 * 3 : 505 * 4 + 1], fu505.speed_mps)


def test_resampled_preserves_distance_and_end_point() -> None:
    udds = load_cycle("udds")
    fine = udds.resampled(0.5)
    assert fine.time_s[0] == udds.time_s[0]
    assert fine.time_s[-1] == udds.time_s[-1]
    assert fine.n_samples == 2 * (udds.n_samples - 1) + 1
    assert fine.distance_m == pytest.approx(udds.distance_m, rel=1e-3)
    odd = udds.resampled(0.7)  # 1369 / 0.7 is not whole: a shorter last step
    assert odd.time_s[-1] == udds.time_s[-1]
    assert odd.distance_m == pytest.approx(udds.distance_m, rel=1e-3)


def test_speed_at_interpolates_and_clamps() -> None:
    cycle = DriveCycle("ramp", np.array([1.0, 3.0]), np.array([2.0, 6.0]))
    np.testing.assert_allclose(cycle.speed_at([0.0, 1.0, 2.0, 3.0, 9.0]), [2, 2, 4, 6, 6])
    assert cycle.speed_at(np.zeros((2, 3))).shape == (2, 3)
    np.testing.assert_array_equal(cycle.grade_at([1.5, 2.5]), 0.0)
    assert cycle.duration_s == 2.0
    assert cycle.distance_m == pytest.approx(8.0)
    assert cycle.mean_speed_mps == pytest.approx(4.0)


def test_truncated_between_samples_adds_interpolated_end() -> None:
    cycle = DriveCycle("ramp", np.array([0.0, 2.0, 4.0]), np.array([0.0, 4.0, 0.0]))
    short = cycle.truncated(1.0)
    np.testing.assert_array_equal(short.time_s, [0.0, 1.0])
    np.testing.assert_array_equal(short.speed_mps, [0.0, 2.0])


def test_repeated_without_matching_ends_inserts_one_step() -> None:
    cycle = DriveCycle("up", np.array([0.0, 1.0]), np.array([0.0, 1.0]))
    twice = cycle.repeated(2)
    np.testing.assert_array_equal(twice.time_s, [0.0, 1.0, 2.0, 3.0])
    np.testing.assert_array_equal(twice.speed_mps, [0.0, 1.0, 0.0, 1.0])


def test_user_csv_in_mph_with_grade(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "my_cycle.csv",
        "time_s,speed_mph,grade\n0,0,0\n1,10,0.01\n2,20,0.02\n3,0,0\n",
    )
    cycle = load_cycle_csv(path)
    assert cycle.name == "my_cycle"
    np.testing.assert_allclose(cycle.speed_mps, np.array([0, 10, 20, 0]) * MPS_PER_MPH)
    np.testing.assert_allclose(cycle.grade, [0, 0.01, 0.02, 0])
    assert load_cycle(str(path)).max_speed_mps == pytest.approx(20 * MPS_PER_MPH)


def test_user_csv_in_kmh(tmp_path: Path) -> None:
    path = _write(tmp_path / "kmh.csv", "# a comment\ntime_s, speed_kmh\n\n0, 0\n1, 36\n")
    cycle = load_cycle(Path(path))
    np.testing.assert_allclose(cycle.speed_mps, [0.0, 10.0])
    np.testing.assert_array_equal(cycle.grade, 0.0)


def test_list_cycles_rows() -> None:
    rows = list_cycles()
    assert [r["name"] for r in rows] == list(CYCLE_NAMES)
    udds = next(r for r in rows if r["name"] == "udds")
    assert udds["distance_mi"] == pytest.approx(7.45, abs=0.01)
    assert set(udds) == {"name", "description", "duration_s", "distance_mi", "max_speed_mph"}


# ---------------------------------------------------------------------- bad input
def test_missing_speed_column(tmp_path: Path) -> None:
    path = _write(tmp_path / "nospeed.csv", "time_s,velocity\n0,0\n1,1\n")
    with pytest.raises(InputError) as err:
        load_cycle_csv(path)
    msg = str(err.value)
    assert "nospeed.csv" in msg
    assert "velocity" in msg
    for accepted in ("speed_mps", "speed_m_per_s", "speed_mph", "speed_kmh"):
        assert accepted in msg


def test_missing_time_column(tmp_path: Path) -> None:
    path = _write(tmp_path / "notime.csv", "t,speed_mps\n0,0\n1,1\n")
    with pytest.raises(InputError) as err:
        load_cycle_csv(path)
    assert "notime.csv" in str(err.value)
    assert "time_s" in str(err.value)


def test_non_monotonic_time(tmp_path: Path) -> None:
    path = _write(tmp_path / "backwards.csv", "time_s,speed_mps\n0,0\n1,1\n2,2\n1.5,0\n")
    with pytest.raises(InputError) as err:
        load_cycle_csv(path)
    msg = str(err.value)
    assert "backwards.csv" in msg
    assert "line 5" in msg
    assert "1.5" in msg


def test_nan_value(tmp_path: Path) -> None:
    path = _write(tmp_path / "hole.csv", "time_s,speed_mps\n0,0\n1,nan\n2,0\n")
    with pytest.raises(InputError) as err:
        load_cycle_csv(path)
    msg = str(err.value)
    assert "hole.csv" in msg
    assert "line 3" in msg
    assert "nan" in msg
    assert "speed_mps" in msg


def test_non_numeric_value(tmp_path: Path) -> None:
    path = _write(tmp_path / "text.csv", "time_s,speed_mps\n0,0\n1,fast\n")
    with pytest.raises(InputError) as err:
        load_cycle_csv(path)
    msg = str(err.value)
    assert "text.csv" in msg
    assert "line 3" in msg
    assert "'fast'" in msg


def test_negative_speed(tmp_path: Path) -> None:
    path = _write(tmp_path / "reverse.csv", "time_s,speed_mph\n0,0\n1,2\n2,-3\n")
    with pytest.raises(InputError) as err:
        load_cycle_csv(path)
    msg = str(err.value)
    assert "reverse.csv" in msg
    assert "line 4" in msg
    assert "-3" in msg
    assert "speed_mph" in msg


def test_infinite_grade(tmp_path: Path) -> None:
    path = _write(tmp_path / "cliff.csv", "time_s,speed_mps,grade\n0,0,0\n1,1,inf\n")
    with pytest.raises(InputError) as err:
        load_cycle_csv(path)
    msg = str(err.value)
    assert "cliff.csv" in msg
    assert "line 3" in msg
    assert "grade" in msg


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "absent.csv"
    with pytest.raises(InputError) as err:
        load_cycle_csv(path)
    assert "absent.csv" in str(err.value)
    with pytest.raises(InputError, match=r"absent\.csv"):
        load_cycle(path)


def test_unknown_name() -> None:
    with pytest.raises(InputError) as err:
        load_cycle("uds")
    msg = str(err.value)
    assert "'uds'" in msg
    for name in CYCLE_NAMES:
        assert name in msg


@pytest.mark.parametrize(
    ("time_s", "speed_mps", "grade", "expected"),
    [
        ([0.0, 2.0, 1.0], [0.0, 1.0, 0.0], None, "index 2"),
        ([0.0, 1.0, 2.0], [0.0, np.nan, 0.0], None, "index 1"),
        ([0.0, 1.0, 2.0], [0.0, -1.0, 0.0], None, "index 1"),
        ([0.0, 1.0, 2.0], [0.0, 1.0], None, "length mismatch"),
        ([0.0, 1.0], [0.0, 1.0], [0.0], "length mismatch"),
        ([0.0], [0.0], None, "at least 2"),
    ],
)
def test_drive_cycle_validation(
    time_s: list[float], speed_mps: list[float], grade: list[float] | None, expected: str
) -> None:
    with pytest.raises(InputError) as err:
        if grade is None:
            DriveCycle("bad", np.array(time_s), np.array(speed_mps))
        else:
            DriveCycle("bad", np.array(time_s), np.array(speed_mps), np.array(grade))
    assert "'bad'" in str(err.value)
    assert expected in str(err.value)


def test_derived_cycle_arguments_are_checked() -> None:
    udds = load_cycle("udds")
    with pytest.raises(InputError, match="udds"):
        udds.resampled(0.0)
    with pytest.raises(InputError, match="udds"):
        udds.repeated(0)
    with pytest.raises(InputError, match="udds"):
        udds.truncated(-1.0)

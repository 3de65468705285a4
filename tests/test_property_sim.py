"""Property test: a vehicle drawn inside the validated parameter ranges either runs to finite
metrics or stops with a clean HevsimError of exit status 2 or 3 — never NaN with success.

The ranges are the configuration's own (``bounds`` in the field metadata of the section
dataclasses of :mod:`hevsim.config`); where a field carries none, the fallback range below
is used and stated. The run is the first 200 s of the UDDS with the Python API.
"""

from __future__ import annotations

import json
import math
import tempfile
from dataclasses import fields
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, note, settings
from hypothesis import strategies as st

from hevsim.config import VehicleConfig, load_config
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.errors import HevsimError
from hevsim.sim.simulator import SimulationResult, simulate

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "series_hev.toml"

FALLBACK_RANGES: dict[str, tuple[float, float]] = {
    "body.mass_kg": (1.0, 1e6),
    "body.drag_coefficient": (0.0, 10.0),
    "body.frontal_area_m2": (0.0, 100.0),
    "body.rolling_resistance": (0.0, 1.0),
    "tire.radius_m": (0.01, 5.0),
    "gear.ratio": (1e-3, 1e3),
    "traction_motor.torque_scale": (1e-3, 1e3),
    "battery.n_parallel": (1, 100),
    "simulation.soc_initial": (0.0, 1.0),
    "controller.soc_low": (0.0, 1.0),
    "controller.soc_high": (0.0, 1.0),
}
"""Ranges used when the configuration states none for a field (the battery's capacity is
drawn as its number of parallel strings: the example's table battery takes its cell capacity
from data)."""

INFINITE_OK = ("mpg", "mpgge")
"""Metrics that are +inf, legitimately, when nothing was consumed (written as null in JSON)."""


def _section(name: str) -> str:
    from hevsim import config

    return getattr(config, "RENAMED_SECTIONS", {}).get(name, name)


def _key(key: str) -> str:
    section, _, rest = key.partition(".")
    return f"{_section(section)}.{rest}"


@cache
def _base() -> VehicleConfig:
    return load_config(EXAMPLE)


@cache
def _cycle() -> DriveCycle:
    return load_cycle("udds").truncated(200.0)


def _range(key: str) -> tuple[float, float]:
    """The validated range of ``key`` (``section.field``) or its fallback."""
    section, _, name = _key(key).partition(".")
    obj = getattr(_base(), section)
    for f in fields(obj):
        if f.name == name and "bounds" in f.metadata:
            lo, hi = f.metadata["bounds"]
            return float(lo), float(hi)
    return FALLBACK_RANGES[key]


def _floats(key: str) -> st.SearchStrategy[float]:
    lo, hi = _range(key)
    return st.floats(lo, min(hi, 1e9), allow_nan=False, allow_infinity=False)


@st.composite
def vehicles(draw: st.DrawFn) -> dict[str, Any]:
    """Overrides of the example's values, every one inside its validated range."""
    values: dict[str, Any] = {
        key: draw(_floats(key))
        for key in (
            "body.mass_kg",
            "body.drag_coefficient",
            "body.frontal_area_m2",
            "body.rolling_resistance",
            "tire.radius_m",
            "gear.ratio",
            "traction_motor.torque_scale",
            "simulation.soc_initial",
        )
    }
    lo, hi = _range("battery.n_parallel")
    values["battery.n_parallel"] = draw(st.integers(int(lo), int(min(hi, 100))))
    c_lo, c_hi = _range("controller.soc_low")
    low = draw(st.floats(c_lo, min(c_hi, 0.98), allow_nan=False))
    values["controller.soc_low"] = low
    values["controller.soc_high"] = draw(
        st.floats(min(low + 0.01, 1.0), min(_range("controller.soc_high")[1], 1.0))
    )
    return {_key(k): v for k, v in values.items()}


PLAUSIBLE_RANGES: dict[str, tuple[float, float]] = {
    "body.mass_kg": (800.0, 2500.0),
    "body.drag_coefficient": (0.2, 0.5),
    "body.frontal_area_m2": (1.5, 3.5),
    "body.rolling_resistance": (0.005, 0.015),
    "tire.radius_m": (0.25, 0.4),
    "gear.ratio": (2.5, 6.0),
    "traction_motor.torque_scale": (0.7, 2.0),
    "simulation.soc_initial": (0.4, 0.9),
}
"""Passenger-car sub-ranges (inside the validated ones) for a second draw whose runs mostly
succeed, so the success branch of the property is exercised as much as the error branch."""


@st.composite
def passenger_cars(draw: st.DrawFn) -> dict[str, Any]:
    values: dict[str, Any] = {}
    for key, (lo, hi) in PLAUSIBLE_RANGES.items():
        v_lo, v_hi = _range(key)
        values[key] = draw(st.floats(max(lo, v_lo), min(hi, v_hi), allow_nan=False))
    values["battery.n_parallel"] = draw(st.integers(1, 3))
    low = draw(st.floats(0.4, 0.7, allow_nan=False))
    values["controller.soc_low"] = low
    values["controller.soc_high"] = draw(st.floats(low + 0.02, 0.85, allow_nan=False))
    return {_key(k): v for k, v in values.items()}


def _check_finite(result: SimulationResult) -> None:
    for name, m in result.metrics.items():
        value = float(m["value"])
        assert not math.isnan(value), f"metric {name} is NaN with success"
        if not math.isfinite(value):
            assert name in INFINITE_OK and value == math.inf, f"metric {name} = {value}"
    numeric = result.timeseries.select_dtypes(include=[np.number]).to_numpy(dtype=float)
    assert np.isfinite(numeric).all(), "a time-series channel is not finite with success"
    soc = result.timeseries["soc"].to_numpy()
    assert soc.min() >= -1e-6 and soc.max() <= 1 + 1e-6


def _raise_on_constant(token: str) -> None:
    raise ValueError(f"non-standard JSON token {token}")


def _check_strict_json(result: SimulationResult) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as d:
        out = result.save(Path(d) / "run", plots=False)
        metrics = json.loads((out / "metrics.json").read_text(), parse_constant=_raise_on_constant)
        for name in ("energy_audit.json", "config.json", "metadata.json"):
            json.loads((out / name).read_text(), parse_constant=_raise_on_constant)
    assert isinstance(metrics, dict)
    return metrics


def _runs_finite_or_fails_cleanly(overrides: dict[str, Any], plain_numbers: bool = False) -> None:
    """Simulate the base vehicle with ``overrides``: finite results, or a HevsimError with exit
    code 2/3 and a one-line message (``plain_numbers``: and no ``np.float64`` reprs in it)."""
    note(repr(overrides))
    try:
        result = simulate(_base().replace(**overrides), _cycle())
    except HevsimError as exc:
        assert exc.exit_code in (2, 3), exc
        message = str(exc)
        assert message and "\n" not in message
        if plain_numbers:
            assert "np.float64" not in message
        return
    _check_finite(result)


@settings(
    max_examples=30,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(vehicles())
def test_random_vehicle_runs_finite_or_fails_cleanly(overrides: dict[str, Any]) -> None:
    _runs_finite_or_fails_cleanly(overrides, plain_numbers=True)


@settings(
    max_examples=25,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(passenger_cars())
def test_random_passenger_car_runs_finite_or_fails_cleanly(overrides: dict[str, Any]) -> None:
    _runs_finite_or_fails_cleanly(overrides)


def test_mid_range_vehicle_succeeds() -> None:
    """The property's success branch is reachable: the example itself, on the same cycle."""
    result = simulate(_base(), _cycle())
    _check_finite(result)
    metrics = _check_strict_json(result)
    assert metrics["mpgge"]["value"] > 0


def test_no_fuel_run_writes_null_mpg_with_a_note() -> None:
    """SOC far above the genset's start threshold: no fuel in 200 s, MPG +inf -> null + note."""
    result = simulate(_base(), _cycle(), soc_initial=0.85)
    assert result.value("fuel_kg") == 0.0 and result.value("mpg") == math.inf
    metrics = _check_strict_json(result)
    assert metrics["mpg"]["value"] is None
    assert "inf" in metrics["mpg"]["note"]
    assert metrics["distance_mi"]["value"] > 0


@pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
def test_write_json_is_strict(value: float, tmp_path: Path) -> None:
    from hevsim.io import write_json

    write_json(tmp_path / "m.json", {"x": {"value": np.float64(value), "unit": "-"}, "y": [1.0, value]})
    data = json.loads((tmp_path / "m.json").read_text(), parse_constant=_raise_on_constant)
    assert data["x"]["value"] is None and data["y"] == [1.0, None]
    assert "written as null" in data["x"]["note"]

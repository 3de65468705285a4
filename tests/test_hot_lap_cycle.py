"""Issue 12 item 5: the shipped hot-lap cycle is what examples/make_hot_lap_cycle.py makes,
and the high-performance HEV follows its first launches and falls behind once its pack is empty."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hevsim.cycles import load_cycle
from hevsim.sim.forward import simulate_architecture

ROOT = Path(__file__).resolve().parents[1]


def _maker() -> Any:
    path = ROOT / "examples" / "make_hot_lap_cycle.py"
    spec = importlib.util.spec_from_file_location("make_hot_lap_cycle", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def maker() -> Any:
    return _maker()


def test_shipped_cycle_is_what_the_script_makes(maker: Any, tmp_path: Path) -> None:
    out = tmp_path / "hotlap.csv"
    assert maker.main(["--out", str(out)]) == 0
    shipped = load_cycle("hotlap_0_200")
    fresh = np.loadtxt(out, delimiter=",", skiprows=1)
    assert fresh.shape[0] == shipped.n_samples
    np.testing.assert_allclose(fresh[:, 1], shipped.speed_mps, atol=2e-4)


def test_cycle_structure(maker: Any) -> None:
    c = load_cycle("hotlap_0_200")
    v = c.speed_mps
    top = maker.TOP_KMH / 3.6
    assert v.max() == pytest.approx(top, abs=1e-4)
    starts = np.flatnonzero((v[:-1] == 0.0) & (v[1:] > 0.0))
    assert starts.size == maker.LAPS
    assert np.diff(v).min() == pytest.approx(-maker.BRAKE_MPS2, abs=1e-3)
    assert np.allclose(np.diff(c.time_s), 1.0)


def test_high_performance_hev_follows_the_first_laps() -> None:
    res = simulate_architecture(
        "parallel", str(ROOT / "examples" / "high_performance_parallel_hev.toml"), "hotlap_0_200"
    )
    ts = res.timeseries
    lap_s = 8 + 14 + 3 + 7  # stop, launch to 200 km/h (13 s of samples), hold, braking samples
    first = ts[ts["time_s"] < 3 * lap_s]
    assert first["traction_limited"].sum() == 0  # a charged pack follows the envelope
    assert ts["traction_limited"].sum() > 0  # ... and an empty one cannot
    assert res.metrics["energy_audit_residual_traction_pct"]["value"] < 0.5

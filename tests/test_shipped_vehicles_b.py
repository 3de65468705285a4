"""Issue 11 item 5: the shipped high-performance parallel HEV and the 2016 Prius power split
(examples/high_performance_parallel_hev.toml, examples/prius_2016_like_power_split.toml)."""

from __future__ import annotations

import importlib.util
import sys
import tomllib
from pathlib import Path
from typing import Any

import pytest

from hevsim import config as C
from hevsim.sim.forward import simulate_architecture
from hevsim.sim.performance import performance

ROOT = Path(__file__).resolve().parents[1]
HP = ROOT / "examples" / "high_performance_parallel_hev.toml"
PRIUS = ROOT / "examples" / "prius_2016_like_power_split.toml"
VALIDATION = ROOT / "examples" / "validation"


def _validation() -> Any:
    spec = importlib.util.spec_from_file_location("prius_2016_fastsim", VALIDATION / "prius_2016_fastsim.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def test_high_performance_hev_loads_as_assembled_p2() -> None:
    cfg: Any = C.load_vehicle_config(HP)
    assert cfg.architecture == "parallel" and cfg.motor_coupling.position == "p2"
    assert "ASSEMBLED" in HP.read_text(encoding="utf-8")
    assert cfg.engine.torque_scale > 1.0 and cfg.motor.rating == "peak"


@pytest.mark.parametrize("cycle", ["udds", "us06"])
def test_high_performance_hev_follows_the_cycle(cycle: str) -> None:
    m = simulate_architecture("parallel", str(HP), cycle).metrics
    assert m["speed_error_max_mph"]["value"] < 0.5  # a 362 kW car follows US06 exactly
    assert m["energy_audit_residual_traction_pct"]["value"] < 0.5
    assert 15.0 < m["mpgge"]["value"] < 60.0


def test_high_performance_hev_performance_band() -> None:
    """0-60 mph in 3.0-4.5 s (362 kW of engine + machine peak power on 1950 kg: the band of
    the large performance hybrids), 0-100 km/h under 5 s, and never more than the AWD adhesion
    limit mu g / delta (mu = 1, delta = 1.08)."""
    res = performance(HP)
    assert 3.0 < res.value("0-60 mph") < 4.5
    assert res.value("0-100 km/h") < 5.0
    assert 150.0 < res.value("top speed") < 210.0
    accel = res.runs["standing_start"]["accel_mps2"].to_numpy()
    assert accel.max() <= 1.0 * 9.81 / 1.08 * (1.0 + 1e-9)


@pytest.fixture(scope="module")
def prius_runs() -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = _validation().run_hevsim()
    return out


def test_prius_2016_loads_with_its_sources() -> None:
    cfg: Any = C.load_vehicle_config(PRIUS)
    assert (cfg.planetary.sun_teeth, cfg.planetary.ring_teeth) == (30, 78)
    assert cfg.body.mass_kg == 1635.0 and cfg.body.drag_coefficient == 0.306  # FASTSim 2016 Prius Two
    assert cfg.battery.n_series == 56  # the 2016 Li-ion pack: 56 x 3.6 A·h, 0.75 kWh (assembled cell)
    assert cfg.battery.data == "li_ion_3p6ah_prius_2016_assembled"


def test_prius_2016_audit_and_fuel_economy_band(prius_runs: dict[str, dict[str, float]]) -> None:
    """SOC-corrected MPGGE within a band of the EPA label's raw test value (label 54/50 mpg city
    / highway, raw 77.4/72.3 mpg by the derived 5-cycle equations) and of FASTSim 3's run on its
    own 2016 Prius (stored figures). The 1998 engine map (39.4 % peak) is the main gap: it stays
    below both (measured with the 0.75 kWh pack and the power follower on its optimal operating
    line, issue 25: -25 %/-12 % vs EPA raw, -9 %/-9 % vs FASTSim; the old follower: -30 %/-18 %).
    The 0.75 kWh pack follows both traces. A single run from SOC 0.6 ends within 0.12 of it (0.58
    / 0.71: the HWFET's last stop from 60 mph regenerates about 0.1 of this small pack after the
    engine's 15 kW floor has held it near soc_high; issue 25 changed the bound from 0.05, which the
    old follower met by charging less); the label balances each test to 1 % (tests/test_label.py)."""
    val = _validation()
    stored = tomllib.loads((VALIDATION / "prius_2016_fastsim.toml").read_text(encoding="utf-8"))
    assert val.epa_unadjusted_mpg("udds") == pytest.approx(77.36, abs=0.01)
    for cycle in ("udds", "hwfet"):
        r = prius_runs[cycle]
        assert r["energy_audit_residual_pct"] < 0.5
        assert 0.55 < r["mpgge"] / val.epa_unadjusted_mpg(cycle) < 1.05
        assert 0.65 < r["mpgge"] / stored[cycle]["mpg"] < 1.05
        assert abs(r["soc_final"] - 0.6) < 0.12  # measured 0.582 / 0.711 (old follower 0.569 / 0.614)
        assert r["traction_limited_s"] == 0.0  # follows the trace: the DP can run the same cycle


def test_stored_fastsim_figures_reproduce() -> None:
    pytest.importorskip("fastsim")
    stored = tomllib.loads((VALIDATION / "prius_2016_fastsim.toml").read_text(encoding="utf-8"))
    fresh = _validation().run_fastsim()
    if fresh["fastsim_version"] != stored["fastsim_version"]:
        pytest.skip(
            f"FASTSim {fresh['fastsim_version']} installed, figures stored from {stored['fastsim_version']}"
        )
    for cycle in ("udds", "hwfet"):
        assert fresh[cycle]["mpg"] == pytest.approx(stored[cycle]["mpg"], rel=1e-9)

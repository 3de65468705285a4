"""Issue 18 leftover: ``[optimization]`` is one section accepted by every architecture with a
DP formulation (parallel, series, power split), validated like the others; the defaults are
the formulations' former constants, so results without the section do not change."""

from __future__ import annotations

from pathlib import Path

import pytest

from hevsim.config import (
    SOC_INITIAL_FROM_SIMULATION,
    OptimizationSection,
    SustainingOptimizationSection,
    load_vehicle_config,
)
from hevsim.errors import ConfigError
from hevsim.optimal import optimize
from hevsim.optimal.hev import resolve_model

ROOT = Path(__file__).resolve().parents[1]
SERIES = ROOT / "examples" / "series_hev.toml"
POWER_SPLIT = ROOT / "examples" / "prius_like_power_split.toml"
PARALLEL = ROOT / "examples" / "parallel_hev.toml"


def _with_section(tmp_path: Path, source: Path, section: str) -> Path:
    path = tmp_path / source.name
    path.write_text(source.read_text() + "\n[optimization]\n" + section)
    return path


@pytest.mark.parametrize("source", [SERIES, POWER_SPLIT])
def test_defaults_are_the_former_constants(source: Path) -> None:
    """No section: charge sustaining on the [simulation] cycle from its initial SOC, 201 SOC
    points, the architecture's input grid (series 101 powers, power split its controller's
    control_points throttles)."""
    cfg = load_vehicle_config(source)
    o = cfg.optimization
    assert type(o) is SustainingOptimizationSection and o.soc_initial == SOC_INITIAL_FROM_SIMULATION
    arch, hev = resolve_model(cfg)
    s = arch.settings(hev)
    assert (s.cycle, s.soc_initial) == (cfg.simulation.cycle, cfg.simulation.soc_initial)
    assert (s.final_soc, s.soc_tolerance, s.soc_points, s.final_constraint) == ("sustain", 0.005, 201, "auto")
    expected_inputs = 101 if source is SERIES else cfg.controller.control_points
    assert s.input_points == expected_inputs
    assert s.final_window == (cfg.battery.soc_min, cfg.battery.soc_max)


def test_parallel_defaults_unchanged() -> None:
    cfg = load_vehicle_config(PARALLEL)
    assert type(cfg.optimization) is OptimizationSection
    arch, hev = resolve_model(cfg)
    s = arch.settings(hev)
    assert s.input_points == cfg.optimization.throttle_grid_points
    assert s.final_window == (cfg.optimization.final_soc_min, cfg.optimization.final_soc_max)


def test_series_section_drives_the_dp(tmp_path: Path) -> None:
    path = _with_section(
        tmp_path,
        SERIES,
        'cycle = "fu505"\nsoc_initial = 0.65\nsoc_grid_points = 41\ninput_grid_points = 21\n',
    )
    res = optimize(path, progress=False)
    meta = res.metadata
    assert meta["cycle"] == "fu505" and meta["soc_initial"] == 0.65
    assert meta["soc_grid"]["points"] == 41 and meta["inputs"]["genset_power_w"]["points"] == 21
    assert abs(res.value("soc_final") - 0.65) <= 0.005 + 1e-9


@pytest.mark.parametrize(
    ("source", "section", "match"),
    [
        (SERIES, "soc_grid_points = 1\n", r"optimization\.soc_grid_points' = 1 is out of range"),
        (SERIES, "soc_initial = 0.2\n", r"optimization\.soc_initial' = 0\.2 lies outside the SOC window"),
        (POWER_SPLIT, 'final_soc = "both"\n', r"optimization\.final_soc' = 'both' is not a valid choice"),
        (POWER_SPLIT, "grid = 3\n", r"key 'optimization\.grid' is not known"),
        (
            SERIES,
            "final_soc_min = 0.8\nfinal_soc_max = 0.6\n",
            r"'optimization\.final_soc_min' = 0\.8 must be below",
        ),
    ],
)
def test_bad_sections_are_config_errors(tmp_path: Path, source: Path, section: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        load_vehicle_config(_with_section(tmp_path, source, section))

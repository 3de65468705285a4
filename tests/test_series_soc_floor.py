"""Issue 18 leftover: the series kernel never takes the pack below ``battery.soc_min``.

Before the fix only the traction motor was bounded at the floor, and only at the step's start
speed: genset cranking, the auxiliaries and a launch from rest kept discharging the pack below
its floor (an EV with a 500 W auxiliary load ended 0.066 below it; a genset cranked from 1e-4
above the floor took the SOC 3.3e-4 below it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim.config import VehicleConfig, load_config
from hevsim.errors import ConfigError, TrackingError
from hevsim.sim.simulator import SimulationResult, simulate

ROOT = Path(__file__).resolve().parents[1]
LEVEL2 = ROOT / "src" / "hevsim" / "data" / "refinement" / "level2_ideal_battery_soc.toml"


def _audit_closes(res: SimulationResult) -> None:
    assert res.value("energy_audit_residual_pct") < 1e-6


def test_auxiliaries_are_shed_at_the_floor_of_an_ev() -> None:
    """No genset: at the floor the pack gives nothing, so the 500 W auxiliary load is shed and
    the car falls behind, flagged battery-limited; the SOC stays on the floor exactly."""
    cfg = load_config(LEVEL2).replace(**{"controller.aux_power_w": 500.0, "battery.soc_min": 0.5})
    res = simulate(cfg, "udds", soc_initial=0.52, tracking=None)
    soc = res.timeseries["soc"].to_numpy()
    assert soc.min() >= 0.5 - 1e-12
    assert soc[-1] == pytest.approx(0.5, abs=1e-9)
    served = res.energy_audit["aux"]
    assert 0.0 < served < 0.5 * 500.0 * res.value("duration_s")  # most of the cycle at the floor: shed
    drawing = (soc <= 0.5 + 1e-12) & (res.timeseries["battery_power_w"].to_numpy() >= 0.0)
    assert drawing[:-1].sum() > 1000 and res.timeseries["battery_limited"].to_numpy()[:-1][drawing[:-1]].all()
    _audit_closes(res)


def test_genset_cranking_stops_at_the_floor(series_cfg: VehicleConfig) -> None:
    """A genset cranked by the generator from 1e-4 above the floor: the pack gives what it
    has, never more; the engine cannot reach its start speed, the car cannot follow and the
    tracking check says the battery is empty."""
    soc_min = series_cfg.battery.soc_min
    with pytest.raises(TrackingError, match="battery is empty") as err:
        simulate(series_cfg, "udds", soc_initial=soc_min + 1e-4)
    res = err.value.result
    ts = res.timeseries
    assert ts["soc"].min() >= soc_min - 1e-12
    assert (ts["genset_state_name"] == "starting").any()
    assert not (ts["genset_state_name"] == "running").any()
    assert ts["generator_power_elec_w"].max() > 0.0  # it did crank with what there was
    _audit_closes(res)


def test_normal_start_above_the_floor_unchanged(series_cfg: VehicleConfig) -> None:
    """With the cranking energy available the genset starts and the SOC dips no lower than
    the floor allows (the run of the shipped example from 0.305)."""
    res = simulate(series_cfg, "udds", soc_initial=0.305)
    soc = res.timeseries["soc"].to_numpy()
    assert soc.min() >= series_cfg.battery.soc_min
    assert (res.timeseries["genset_state_name"] == "running").any()
    assert np.all(np.isfinite(soc))


@pytest.mark.parametrize(
    ("changes", "soc_initial", "match"),
    [
        ({}, 0.25, r"soc_initial = 0\.25 lies outside \[battery\.soc_min, battery\.soc_max\]"),
        ({"controller.soc_low": 0.3}, None, r"'controller\.soc_low' = 0\.3 must be above 'battery\.soc_min'"),
        (
            {"controller.start_speed_rpm": 1500.0},
            None,
            r"'controller\.start_speed_rpm' = 1500 must be below 'controller\.engine_speed_rpm' = 1500",
        ),
    ],
)
def test_runs_that_could_never_start_the_genset_are_config_errors(
    series_cfg: VehicleConfig, changes: dict[str, float], soc_initial: float | None, match: str
) -> None:
    cfg = series_cfg.replace(**changes) if changes else series_cfg
    with pytest.raises(ConfigError, match=match):
        simulate(cfg, "udds", soc_initial=soc_initial)

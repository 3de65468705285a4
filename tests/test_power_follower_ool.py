"""The power split's power follower on the engine's optimal operating line (issue 25 item 6).

The old follower took the least *fuel* of the candidates within 10 % of its target power, which
favours the lowest power in the band, and ran the engine at any power above ``ev_power_w``
once the car was faster than ``ev_speed_mps`` (4-6 kW on light cruise, 25-30 % efficient). It
now takes the least fuel per unit of engine work (the most efficient candidate: the optimal
operating line on the candidate grid) and, with ``engine_min_power_w``, keeps the engine at or
above a floor while the SOC is below ``soc_high``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim.architectures import architecture
from hevsim.config import load_vehicle_config, with_overrides
from hevsim.sim.forward import simulate_architecture
from hevsim.sim.label import label

ROOT = Path(__file__).resolve().parents[1]
PRIUS = ROOT / "examples" / "prius_2016_like_power_split.toml"
OLD_SETTINGS = {"controller.ev_speed_mps": 12.5, "controller.engine_min_power_w": 0.0}
"""The example's controller before issue 25 (the selection rule changed as well)."""


@pytest.fixture(scope="module")
def prius() -> object:
    cfg = load_vehicle_config(PRIUS)
    return architecture("power_split").build(cfg)


def _optimal_line_efficiency(engine: object, power_w: np.ndarray) -> np.ndarray:
    """Best brake efficiency [-] of ``engine`` at each power [W]: dense search over speed and
    torque of its map (independent of the controller's candidate grid)."""
    w = np.linspace(engine.stall_speed_radps, engine.redline_radps, 241)  # type: ignore[attr-defined]
    t_max = np.asarray(engine.max_torque_nm(w))  # type: ignore[attr-defined]
    best = np.zeros(power_w.size)
    for wi, ti in zip(w, t_max, strict=True):
        t = power_w / wi
        ok = (t > 0) & (t <= ti)
        if ok.any():
            fuel = np.asarray(engine.fuel_rate(t[ok], np.full(ok.sum(), wi)))  # type: ignore[attr-defined]
            eff = power_w[ok] / (fuel * engine.fuel_lhv_jpkg)  # type: ignore[attr-defined]
            best[ok] = np.maximum(best[ok], eff)
    return best


def test_engine_runs_on_its_optimal_operating_line(prius: object) -> None:
    """99 % of the engine-on steps of UDDS and HWFET are within 0.5 efficiency points of the map's
    best at their power (the candidate grid is 13 speeds x 20 throttles), and fewer than 8 % run
    below 10 kW (measured 0 % / 5.6 %; the old follower ran half of its UDDS engine time below
    10 kW). The HWFET's low-power steps are above soc_high at 55-60 mph, where the engine must
    turn (engine off would overspeed MG1) and gives the small demand; one is at 0.9 kW, 3
    points off the line."""
    engine = prius.engine  # type: ignore[attr-defined]
    for cycle in ("udds", "hwfet"):
        ts = simulate_architecture("power_split", prius, cycle).timeseries
        on = ts["engine_on"].to_numpy().astype(bool)
        p = ts["engine_power_w"].to_numpy()[on]
        eff = p / (ts["fuel_rate_gps"].to_numpy()[on] * 1e-3 * engine.fuel_lhv_jpkg)
        gap = _optimal_line_efficiency(engine, p) - eff
        assert np.percentile(gap, 99) < 0.005 and gap.max() < 0.035, (cycle, float(gap.max()))
        assert np.mean(p < 10e3) < 0.08, (cycle, float(np.mean(p < 10e3)))


def test_engine_work_is_more_efficient_than_the_old_settings(prius: object) -> None:
    """Fuel-weighted engine efficiency on UDDS: >= 0.375 now (the line reaches 38 % at 15 kW),
    below 0.36 with the old settings."""
    cfg = prius.config  # type: ignore[attr-defined]
    effs = []
    for c in (cfg, with_overrides(cfg, OLD_SETTINGS)):
        r = simulate_architecture("power_split", c, "udds")
        a = r.energy_audit
        effs.append((a["fuel"] - a["engine_loss"]) / a["fuel"])
    assert effs[0] >= 0.375 > 0.36 > effs[1], effs


def test_engine_is_off_below_the_power_threshold(prius: object) -> None:
    """Below ev_power_w at the wheels, with SOC above soc_low, the engine is off wherever EV can
    drive (engine off is feasible: at the HWFET's 60 mph MG1 would overspeed)."""
    c = prius.config.controller  # type: ignore[attr-defined]
    for cycle in ("udds", "hwfet"):
        ts = simulate_architecture("power_split", prius, cycle).timeseries
        on = ts["engine_on"].to_numpy().astype(bool)
        pw = ts["wheel_power_w"].to_numpy()
        soc = ts["soc"].to_numpy()
        v = ts["speed_mps"].to_numpy()
        low = (pw > 0) & (pw < c.ev_power_w) & (soc > c.soc_low + 0.01) & (v < 20.0)
        assert low.sum() > 20 and not (on & low).any(), (cycle, int(low.sum()))


@pytest.mark.parametrize("compiled", [True, False])
def test_compiled_and_python_loops_agree(prius: object, compiled: bool) -> None:
    r = simulate_architecture("power_split", prius, "udds", compiled=compiled)
    assert r.metadata["compiled"] is compiled
    ref = simulate_architecture("power_split", prius, "udds", compiled=True)
    assert r.value("fuel_kg") == pytest.approx(ref.value("fuel_kg"), rel=1e-12)
    assert r.value("soc_final") == pytest.approx(ref.value("soc_final"), abs=1e-12)


def test_label_gains_over_the_old_settings() -> None:
    """SOC-balanced unadjusted fuel economy (hevsim label): 58.65 / 61.77 mpg, against 56.44 /
    57.79 with the old settings and the new selection rule (+3.9 % / +6.9 %) and 55.07 / 58.58
    on the tree before issue 25; the DP optimum is 58.95 / 63.71 (`hevsim optimize`)."""
    cfg = load_vehicle_config(PRIUS)
    new = label(cfg).figures["unadjusted_mpg"]
    old = label(with_overrides(cfg, OLD_SETTINGS)).figures["unadjusted_mpg"]
    assert new["city"] > 1.03 * old["city"] and new["highway"] > 1.05 * old["highway"], (new, old)

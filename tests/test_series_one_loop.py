"""The series HEV runs in the one compiled loop (issue 24 item 2): a plug-in of
:func:`hevsim.sim._loop.run_loop` with its own driver (the loop's ``drive`` hook), not a loop of
its own. Its numbers are the old loop's bit for bit (tests/test_series_kernel_regression.py, to
1e-9, unchanged); here: the old loop is gone, the series compiles the one loop once (single runs
of every battery-table refinement level, map and constant-efficiency machines, and the batch),
and the loop's engine bookkeeping keeps the series's meaning (a start is a genset start request,
engine time is time fired) against the recorded genset states."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest

from hevsim.config import load_config
from hevsim.sim import kernel as K
from hevsim.sim._compiled_series import SeriesPlug, series_drive
from hevsim.sim._loop import PLUGINS, _no_choose, _no_point, run_loop
from hevsim.sim.simulator import simulate, simulate_batch

ROOT = Path(__file__).resolve().parents[1]
LEVELS = Path(str(files("hevsim") / "data" / "refinement"))


def test_the_series_loop_of_its_own_is_gone() -> None:
    assert not hasattr(K, "run_series") and not hasattr(K, "run_series_batch")
    plugin = PLUGINS[SeriesPlug]
    assert plugin.drive is series_drive  # the driver hook: proportional driver, explicit Euler, genset shaft
    assert plugin.choose is _no_choose and plugin.point is _no_point  # the loop's own driver is not used


def test_the_series_compiles_the_one_loop_once() -> None:
    """Map machines (read-only tables) and constant-efficiency ones, an engine genset, a
    current source and none, single runs and the batch: one compiled run_loop for the series
    with a table battery (another would compile the loop again, about 20 s)."""
    for name in ("level1_ev_constant_torque", "level3_constant_current_genset", "level8_motor_maps"):
        simulate(load_config(LEVELS / f"{name}.toml"), "udds")
    cfg = load_config(ROOT / "examples" / "series_hev.toml")
    simulate(cfg, "udds")
    batch = simulate_batch(cfg, {"mass_kg": [1300.0, 1500.0]}, "udds")
    assert len(batch.table) == 2
    series = [s for s in run_loop.signatures if str(s[0]).startswith("SeriesPlug(")]
    tables = [s for s in series if "PackKernelTables" not in str(s[0])]
    assert len(tables) == 1, series


@pytest.mark.parametrize(
    ("name", "fired"),
    [("level3_constant_current_genset", False), ("level4_engine_speed_control", True)],
)
def test_engine_starts_and_time_keep_the_series_meaning(name: str, fired: bool) -> None:
    """The loop counts a start where the genset leaves ``off`` (cranking or a current source
    on: the plug-in's engine state 0.5) and engine time only where the engine fired: a
    current-source genset starts but never fires."""
    res = simulate(load_config(LEVELS / f"{name}.toml"), "us06")
    ts = res.timeseries
    on = ts["genset_state"].to_numpy() != 0
    starts = int(np.sum(on[1:] & ~on[:-1]) + on[0])
    assert starts > 0
    assert res.value("engine_starts") == starts
    dt = float(ts["time_s"].iloc[1] - ts["time_s"].iloc[0])
    if fired:
        burning = ts["fuel_rate_gps"].to_numpy()[:-1] > 0.0
        assert 0.0 < res.value("engine_on_time_s") <= np.sum(on[:-1]) * dt
        assert res.value("engine_on_time_s") == pytest.approx(np.sum(burning) * dt)
    else:
        assert res.value("engine_on_time_s") == 0.0

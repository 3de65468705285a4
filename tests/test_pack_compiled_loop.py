"""Issue 24 items 1-2: the pack of a ``[battery] model = "pack"`` vehicle steps inside the
compiled forward loop of every architecture (BEV, power split, parallel P3 and P2), with the one
compiled pack step (:func:`hevsim.battery.pack_run.pack_begin` /
:func:`~hevsim.battery.pack_run.pack_bus_state` / :func:`~hevsim.battery.pack_run.pack_finish_power`)
that the Python reference loop of :mod:`hevsim.sim.forward` also calls step by step.

Reference: the Python loop (``HEVSIM_FORWARD=python``) on the shipped pack examples. Every
channel (vehicle and pack: SOC, every cell statistic, temperatures, currents, fuel), metric,
audit term and pack energy term must agree to :data:`RTOL` relative (measured: equal to the
last bit on these cases). Before this change the pack ran only in the Python loop, so the
``compiled`` flag of the first assertion fails on the old tree.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hevsim.config import load_vehicle_config
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.sim.pack_vehicle import simulate_pack_vehicle

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"
RTOL = 1e-9
"""Relative tolerance of compiled against Python (absolute floor :data:`ATOL` for channels near 0)."""
ATOL = 1e-9

CASES = {  # vehicle example, cycle, seconds (short: the Python reference loop is slow)
    "bev": ("bev_pack.toml", "us06", 150.0),
    "power_split": ("prius_like_power_split_pack.toml", "us06", 120.0),
    "parallel_p3": ("parallel_hev_pack.toml", "udds", 150.0),
    "parallel_p2": ("high_performance_parallel_hev_pack.toml", "us06", 120.0),
    "fcev": ("fcev_pack.toml", "us06", 60.0),  # sheds fuel-cell power at 13 s (the BMS charge limit)
}


def _short(cycle: str, seconds: float) -> DriveCycle:
    c = load_cycle(cycle)
    keep = np.asarray(c.time_s) <= seconds
    return DriveCycle(f"{c.name}_{seconds:g}s", np.asarray(c.time_s)[keep], np.asarray(c.speed_mps)[keep],
                      np.asarray(c.grade)[keep])  # fmt: skip


def _close(a: float, b: float) -> bool:
    if a == b:  # also inf (a BEV's mpg)
        return True
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return abs(a - b) <= ATOL + RTOL * abs(b)


@pytest.mark.parametrize("case", list(CASES))
def test_compiled_pack_loop_equals_the_python_loop(case: str, monkeypatch: pytest.MonkeyPatch) -> None:
    vehicle, cycle, seconds = CASES[case]
    cfg = load_vehicle_config(EX / vehicle)
    cyc = _short(cycle, seconds)
    fast = simulate_pack_vehicle(cfg, cyc, 1.0, ambient_temp_c=35.0, soak=True)
    monkeypatch.setenv("HEVSIM_FORWARD", "python")
    ref = simulate_pack_vehicle(cfg, cyc, 1.0, ambient_temp_c=35.0, soak=True)
    assert fast.metadata["compiled"] is True and ref.metadata["compiled"] is False
    ts, ts_ref = fast.timeseries, ref.timeseries
    assert list(ts.columns) == list(ts_ref.columns)
    for col in ts.columns:
        x, y = ts[col].to_numpy(), ts_ref[col].to_numpy()
        if x.dtype.kind in "fiu":
            x, y = x.astype(float), y.astype(float)
            bad = np.flatnonzero(np.abs(x - y) > ATOL + RTOL * np.abs(y))
            assert bad.size == 0, f"{case}: {col} at step {bad[:1]}: {x[bad[:1]]} vs {y[bad[:1]]}"
        else:
            assert (x == y).all(), col
    assert set(fast.metrics) == set(ref.metrics)
    for name, m in fast.metrics.items():
        assert _close(float(m["value"]), float(ref.metrics[name]["value"])), name
    assert set(fast.energy_audit) == set(ref.energy_audit)
    for name, v in fast.energy_audit.items():
        assert _close(float(v), float(ref.energy_audit[name])), name
    for name, v in fast.extra["pack_energy"].items():
        assert _close(float(v), float(ref.extra["pack_energy"][name])), name
    assert fast.events.reset_index(drop=True).equals(ref.events.reset_index(drop=True))
    # the run did work: the pack carried current both ways and its SOC moved
    i = ts["pack_current_a"].to_numpy()
    assert i.max() > 1.0 and ts["soc"].iloc[-1] != ts["soc"].iloc[0]


def test_compiled_pack_loop_tracks_the_ageing_stress(monkeypatch: pytest.MonkeyPatch) -> None:
    """The ageing stress the pack's compiled step accumulates (``--age-state``) is the Python
    loop's: every cell's age state after one run is the same either way, and it moved."""
    from hevsim.battery.life import PackAgeState
    from hevsim.battery.pack import Pack
    from hevsim.sim.pack_vehicle import vehicle_pack_config

    vehicle, cycle, seconds = CASES["bev"]
    cfg = load_vehicle_config(EX / vehicle)
    cyc = _short(cycle, seconds)
    n_cells = Pack(vehicle_pack_config(cfg, 1.0)[0]).n_cells
    cells = []
    for env in (None, "python"):
        if env:
            monkeypatch.setenv("HEVSIM_FORWARD", env)
        age = PackAgeState(n_cells)
        simulate_pack_vehicle(cfg, cyc, 1.0, age_state=age)
        cells.append(age.to_dict()["cells"])
    fast, ref = cells
    assert set(fast) == set(ref)
    for key in fast:
        np.testing.assert_allclose(fast[key], ref[key], rtol=RTOL, atol=1e-15, err_msg=key)
    assert max(fast["loss_cycle"]) > 0.0 and max(fast["throughput_ah"]) > 0.0  # the run aged the cells

"""Pieces of the compiled parallel / power-split forward run (issue 11): the electric
assist's throttle search equals the scan of every throttle (the Python controller's rule),
and one compiled specialisation serves every vehicle of an architecture."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim import config as C
from hevsim.architectures import architecture
from hevsim.architectures import parallel as P
from hevsim.control import make_controller
from hevsim.cycles import load_cycle
from hevsim.sim import _compiled_hev as H

ROOT = Path(__file__).resolve().parents[1]


def _parallel(**changes: object) -> P.ParallelHEV:
    cfg = C.load_vehicle_config(ROOT / "examples/parallel_hev.toml")
    return P.build_parallel_hev(cfg.replace(**changes) if changes else cfg)


@pytest.mark.parametrize(
    "changes",
    [
        {},
        {"engine.torque_scale": 0.3},
        {"motor.model": "map", "motor.rating": "peak", "motor_coupling.ratio": 2.0},
    ],
)
def test_assist_throttle_search_equals_the_scan_of_every_throttle(changes: dict[str, object]) -> None:
    """Bisection on the torque (``monotone``) and the full scan pick the same throttle at
    random wheel speeds (engine below, in and above its running window; machine beyond its
    map) and torque requests (none, within reach, a grid throttle's torque exactly, beyond
    full throttle)."""
    hev = _parallel(**changes)
    thr = make_controller(hev, "electric_assist").thr_grid
    assert P.torque_rises_with_throttle(hev, thr)
    d, etab = P.kernel_tables(hev), hev.engine.kernel_tables()
    rng = np.random.default_rng(11)
    w_max = d.redline_radps / (d.final_drive_ratio * d.gear_ratio[-1])
    picked = []
    for _ in range(3000):
        w_wheel = rng.uniform(0.0, 1.3 * w_max)
        g = int(rng.integers(1, d.gear_ratio.size + 1))
        w_e = w_wheel * d.final_drive_ratio * d.gear_ratio[g - 1]
        tie = P.engine_torque_point(w_e, thr[rng.integers(thr.size)], d, etab)[3]  # a throttle's own torque
        t_req = rng.choice([rng.uniform(-50.0, 400.0), tie, 1e6, -1e6, 0.0])
        fast = H._assist_throttle(w_wheel, g, t_req, thr, True, d, etab)
        scan = H._assist_throttle(w_wheel, g, t_req, thr, False, d, etab)
        assert fast == scan, (w_wheel, g, t_req)
        picked.append(fast)
    picked = np.array(picked)
    assert (picked == 0.0).any() and (picked == thr[-1]).any() and ((picked > 0) & (picked < thr[-1])).any()


def test_torque_rises_with_throttle_needs_ascending_throttles_and_no_torque_map() -> None:
    hev = _parallel()
    assert P.torque_rises_with_throttle(hev, [0.1, 0.5, 1.0])
    assert not P.torque_rises_with_throttle(hev, [0.5, 0.1, 1.0])
    assert not P.torque_rises_with_throttle(hev, [-0.1, 0.5])
    assert hev.engine.torque_map is None  # the shipped map engine reads throttle x max torque


def test_one_compiled_run_per_architecture() -> None:
    """Vehicles whose machine tables are read-only arrays (map machines) and writable ones
    (constant efficiency) share one compiled run per architecture and pack kind (another type
    would compile it again: about 20 s)."""
    grid = load_cycle("udds").resampled(1.0)
    vehicles = [
        ("parallel_hev.toml", {}),
        ("parallel_hev.toml", {"motor.model": "map", "motor.rating": "peak"}),
        ("prius_like_power_split.toml", {}),
        ("prius_2016_like_power_split.toml", {}),
    ]
    for name, changes in vehicles:
        cfg = C.load_vehicle_config(ROOT / "examples" / name)
        cfg = cfg.replace(**changes) if changes else cfg
        model = architecture(cfg.architecture).build(cfg)
        H._run_one(model, grid, make_controller(model), cfg.simulation.soc_initial, 0.0, 1.0)
    # count the runs without a pack (the last argument None): a pack vehicle compiled by an
    # earlier test in this process is its own, legitimate signature; the one loop run_loop is
    # compiled once per plug-in type (its first argument: the architecture)
    from hevsim.sim._loop import run_loop

    tables = {H.ParallelPlug.__name__: 0, H.PowerSplitPlug.__name__: 0}
    for sig in run_loop.signatures:
        if not str(sig[-1]).startswith("none"):
            continue
        plug = str(sig[0]).split("(")[0]
        if plug in tables:
            tables[plug] += 1
    assert tables == {"ParallelPlug": 1, "PowerSplitPlug": 1}, run_loop.signatures

"""Issue 24 item 2: the fuel-cell vehicle runs the one compiled forward loop
(:func:`hevsim.sim._loop.run_loop` with :mod:`hevsim.sim._compiled_fcev`'s plug-in) with its
``load_follower`` controller, and equals the Python reference loop of
:mod:`hevsim.sim.forward` (channels, events, audit, metrics to 1e-9; the ramp-down overrides
and the controller's last net power exactly). Before, the FCEV ran the Python loop only: the
``compiled`` flag fails on the old tree."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.test_forward_compiled_conventional import assert_same_run

from hevsim import config as C
from hevsim.architectures.fcev import build_fcev
from hevsim.components.fuel_cell import (
    efficiency_point,
    ramp_window_point,
    reachable_point,
    reachable_window_point,
)
from hevsim.control import make_controller
from hevsim.sim.forward import simulate_fcev

FCEV = Path(__file__).resolve().parents[1] / "examples" / "fcev.toml"


@pytest.fixture(scope="module")
def cfg() -> Any:
    return C.load_vehicle_config(FCEV)


def _both(cfg: Any, cycle: str, **kw: Any) -> tuple[Any, Any, Any, Any]:
    model = build_fcev(cfg)
    ctl_fast, ctl_ref = make_controller(model), make_controller(model)
    fast = simulate_fcev(model, cycle, controller=ctl_fast, **kw)
    ref = simulate_fcev(model, cycle, controller=ctl_ref, compiled=False, **kw)
    return fast, ref, ctl_fast, ctl_ref


@pytest.mark.parametrize("cycle", ["udds", "hwfet", "us06"])
def test_compiled_run_equals_the_python_loop(cfg: Any, cycle: str) -> None:
    fast, ref, ctl_fast, ctl_ref = _both(cfg, cycle)
    assert fast.metadata["compiled"] and not ref.metadata["compiled"]
    assert_same_run(fast, ref)
    assert ctl_fast.previous_w == pytest.approx(ctl_ref.previous_w, rel=1e-9)
    assert fast.metadata["ramp_down_overrides"] == ref.metadata["ramp_down_overrides"]
    assert abs(fast.energy_audit["residual"]) < 1e-9 * fast.value("traction_energy_j")
    assert fast.value("hydrogen_kg") > 0.0


@pytest.mark.parametrize(
    ("changes", "what"),
    [
        ({"motor.torque_scale": 0.3}, "machine torque: the driver's bisection"),
        ({"battery.max_charge_current_a": 8.0, "fuel_cell.ramp_down_w_per_s": 1500.0}, "shedding"),
        ({"battery.max_discharge_current_a": 40.0, "fuel_cell.ramp_up_w_per_s": 2000.0}, "ramp window"),
    ],
)
def test_compiled_run_equals_the_python_loop_at_the_limits(
    cfg: Any, changes: dict[str, float], what: str
) -> None:
    """The bisection on the end speed, the window's nearest feasible power and the shedding of
    power faster than the ramp-down limit, compiled as in the Python loop."""
    fast, ref, _, _ = _both(cfg.replace(**changes), "us06")
    assert_same_run(fast, ref)
    assert fast.metadata["ramp_down_overrides"] == ref.metadata["ramp_down_overrides"]
    if what == "shedding":
        assert ref.metadata["ramp_down_overrides"] > 0
    elif what.startswith("machine"):
        assert ref.value("traction_limited_s") > 10.0


def test_ecms_has_no_compiled_form_and_runs_the_python_loop(cfg: Any) -> None:
    r = simulate_fcev(cfg, "udds", controller="ecms")
    assert not r.metadata["compiled"]


def test_fuel_cell_scalar_kernels_equal_the_methods(cfg: Any) -> None:
    """The scalar kernels the compiled loop calls and the fuel-cell system's methods agree at
    random powers (off, idle, between, rating, beyond), previous powers and steps."""
    fc = build_fcev(cfg).fuel_cell
    lim = (fc.min_power_w, fc.max_power_w, fc.ramp_up_w_per_s, fc.ramp_down_w_per_s)
    rng = np.random.default_rng(24)
    for _ in range(500):
        prev = float(rng.choice([0.0, fc.min_power_w, fc.max_power_w, rng.uniform(0.0, fc.max_power_w)]))
        dt = float(rng.choice([0.1, 1.0, 5.0]))
        p = float(rng.choice([0.0, fc.min_power_w, rng.uniform(0.0, 1.2 * fc.max_power_w)]))
        assert ramp_window_point(prev, dt, *lim) == fc.ramp_window(prev, dt)
        assert reachable_window_point(prev, dt, *lim) == fc.reachable_window(prev, dt)
        assert reachable_point(prev, dt, p, *lim) == bool(fc.reachable(prev, dt, p))
        eta = efficiency_point(p, fc.max_power_w, fc.power_fraction, fc.efficiency_curve)
        assert eta == pytest.approx(float(fc.efficiency(p)), rel=1e-14)

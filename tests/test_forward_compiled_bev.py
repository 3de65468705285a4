"""The compiled BEV run equals the Python loop (channels, audit, metrics, events)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.test_forward_compiled_conventional import assert_same_run

from hevsim import config as C
from hevsim.errors import DomainError
from hevsim.sim.forward import simulate_bev

BEV = Path(__file__).resolve().parents[1] / "examples" / "bev.toml"


@pytest.fixture(scope="module")
def cfg() -> Any:
    return C.load_vehicle_config(BEV)


@pytest.mark.parametrize("cycle", ["udds", "hwfet", "us06"])
def test_compiled_run_equals_the_python_loop(cfg: Any, cycle: str) -> None:
    fast = simulate_bev(cfg, cycle)
    ref = simulate_bev(cfg, cycle, compiled=False)
    assert fast.metadata["compiled"] and not ref.metadata["compiled"]
    assert_same_run(fast, ref)
    assert abs(fast.energy_audit["residual"]) < 1e-9 * fast.value("traction_energy_j")
    modes = set(fast.timeseries["power_mode_name"])
    assert {"traction", "regen", "friction_braking", "standstill"} <= modes


@pytest.mark.parametrize(
    ("changes", "what"),
    [
        ({"motor.torque_scale": 0.3}, "machine torque"),
        ({"battery.max_discharge_current_a": 60.0, "battery.max_charge_current_a": 20.0}, "current limits"),
    ],
)
def test_compiled_run_equals_the_python_loop_at_the_limits(
    cfg: Any, changes: dict[str, float], what: str
) -> None:
    """The driver's bisection (machine torque, battery current) and the regeneration-current
    rule of the forward driver, compiled as in the Python loop."""
    var = cfg.replace(**changes)
    fast = simulate_bev(var, "us06")
    ref = simulate_bev(var, "us06", compiled=False)
    assert ref.value("traction_limited_s") > 10.0, what
    assert_same_run(fast, ref)


def test_an_empty_battery_stops_both_runs_at_the_same_step(cfg: Any) -> None:
    """At soc_min no discharge is allowed, not even the auxiliaries at a standstill."""
    var = cfg.replace(**{"simulation.soc_initial": 0.12})
    with pytest.raises(DomainError) as fast:
        simulate_bev(var, "us06")
    with pytest.raises(DomainError) as ref:
        simulate_bev(var, "us06", compiled=False)
    assert str(fast.value) == str(ref.value) and "no feasible control at t = " in str(ref.value)


BATCH = {
    "body.mass_kg": [1500.0, 1800.0, 2100.0],
    "body.drag_coefficient": [0.24, 0.28, 0.32],
    "tire.radius_m": [0.3, 0.32, 0.34],
    "simulation.soc_initial": [0.7, 0.8, 0.9],
}


@pytest.mark.parametrize("cycle", ["udds", "us06"])
def test_compiled_batch_equals_single_runs(cfg: Any, cycle: str) -> None:
    """The compiled batch (threads of compiled runs) gives every variant's metrics as its own
    single run (to 1e-12), through the compiled hook (not the variant-by-variant fallback)."""
    from hevsim.architectures import bev as B
    from hevsim.control import make_controller
    from hevsim.cycles import load_cycle
    from hevsim.sim.forward import compiled_loop
    from hevsim.sim.simulator import simulate_batch

    model = B.build_bev(cfg)
    grid = load_cycle(cycle).resampled(cfg.simulation.dt_s)
    arrays = {k: np.asarray(v) for k, v in BATCH.items()}
    run = compiled_loop("bev").simulate_batch_compiled
    rec = run(model, arrays, grid, make_controller(model), soc_initial=arrays["simulation.soc_initial"],
              soc_min=cfg.battery.soc_min, soc_max=cfg.battery.soc_max)  # fmt: skip
    assert rec is not None and rec.summary.shape[0] == 3
    batch = simulate_batch(cfg, BATCH, cycle)
    for i in range(3):
        single = simulate_bev(cfg.replace(**{k: v[i] for k, v in BATCH.items()}), cycle)
        for key, m in single.metrics.items():
            tol = 1e-9 if key.startswith("energy_audit_residual") else 0.0  # round-off [%]
            assert batch.table[key].iloc[i] == pytest.approx(m["value"], rel=1e-12, abs=tol), (i, key)
    assert batch.table["soc_final"].nunique() == 3  # the variants differ


def test_compiled_batch_leaves_other_keys_to_single_runs(cfg: Any) -> None:
    """A key the compiled batch cannot vary on the built model (the final drive) runs variant
    by variant, with the same metrics as single runs."""
    from hevsim.sim.simulator import simulate_batch

    batch = simulate_batch(cfg, {"final_drive.ratio": [7.0, 9.0]}, "hwfet")
    single = simulate_bev(cfg.replace(**{"final_drive.ratio": 9.0}), "hwfet")
    assert batch.table["soc_final"].iloc[1] == single.value("soc_final")
    assert batch.table["soc_final"].iloc[0] != batch.table["soc_final"].iloc[1]

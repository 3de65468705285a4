"""The compiled BEV run equals the Python loop (channels, audit, metrics, events)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

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


def test_simulate_batch_runs_bev_variants(cfg: Any) -> None:
    """No compiled batch for the BEV: the variants run one by one, same metrics as single runs."""
    from hevsim.sim.simulator import simulate_batch

    batch = simulate_batch(cfg, {"body.mass_kg": [1500.0, 1800.0]}, "hwfet")
    single = simulate_bev(cfg.replace(**{"body.mass_kg": 1800.0}), "hwfet")
    assert batch.table["soc_final"].iloc[1] == single.value("soc_final")
    assert batch.table["soc_final"].iloc[0] > batch.table["soc_final"].iloc[1]  # heavier uses more

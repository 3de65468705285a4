"""Compiled forward runs of the parallel (P3, P2) and power-split HEVs equal the Python loop
(every channel, event, audit term and metric to 1e-9) with every online controller, and the
P3 machine's over-speed is infeasible, never extrapolated (issue 11)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from hevsim import config as C
from hevsim.architectures import architecture
from hevsim.architectures import parallel as P
from hevsim.architectures._common import max_machine_speed_radps
from hevsim.cycles import load_cycle
from hevsim.sim.forward import simulate_architecture

ROOT = Path(__file__).resolve().parents[1]
RTOL = 1e-9
ROUND_OFF = ("energy_audit_residual_pct", "energy_audit_residual_traction_pct")
"""Metrics that are round-off (residual / energy): compared in absolute terms [%]."""
VEHICLES = {
    "p3": ("examples/parallel_hev.toml", {}),
    "p2": ("examples/parallel_hev.toml", {"motor_coupling.position": "p2"}),
    "power_split": ("examples/prius_like_power_split.toml", {}),
    "prius_2016": ("examples/prius_2016_like_power_split.toml", {}),
}


def _config(name: str, **changes: Any) -> Any:
    path, base = VEHICLES[name]
    return C.load_vehicle_config(ROOT / path).replace(**{**base, **changes})


def assert_same_run(a: Any, b: Any) -> None:
    """Two results have the same channels, events, audit terms [J] and metrics (to 1e-9)."""
    assert list(a.timeseries.columns) == list(b.timeseries.columns)
    for col in a.timeseries.columns:
        x, y = a.timeseries[col].to_numpy(), b.timeseries[col].to_numpy()
        if x.dtype.kind in "fc":
            assert np.allclose(x, y, rtol=RTOL, atol=RTOL * max(float(np.max(np.abs(y))), 1e-30)), col
        else:
            assert (x == y).all(), col
    pd.testing.assert_frame_equal(a.events, b.events)
    assert a.energy_audit.keys() == b.energy_audit.keys()
    scale = b.value("traction_energy_j")
    for key, val in b.energy_audit.items():
        assert a.energy_audit[key] == pytest.approx(val, rel=RTOL, abs=RTOL * scale), key
    assert a.metrics.keys() == b.metrics.keys()
    for key, m in b.metrics.items():
        assert a.value(key) == pytest.approx(m["value"], rel=RTOL, abs=1e-6 if key in ROUND_OFF else 0.0), key


def _both(cfg: Any, cycle: str, kind: str) -> tuple[Any, Any]:
    arch = architecture(cfg.architecture)
    model = arch.build(cfg)
    fast = simulate_architecture(cfg.architecture, model, cycle, controller=kind)
    ref = simulate_architecture(cfg.architecture, model, cycle, controller=kind, compiled=False)
    assert fast.metadata["compiled"] and not ref.metadata["compiled"]
    return fast, ref


@pytest.mark.parametrize("cycle", ["udds", "hwfet", "us06"])
@pytest.mark.parametrize(
    ("vehicle", "kind"),
    [("p3", "electric_assist"), ("p3", "ecms"), ("p3", "aecms"), ("p2", "electric_assist"), ("p2", "ecms"),
     ("p2", "aecms"), ("power_split", "power_follower"), ("power_split", "ecms"), ("power_split", "aecms")],
)  # fmt: skip
def test_compiled_run_equals_the_python_loop(vehicle: str, kind: str, cycle: str) -> None:
    fast, ref = _both(_config(vehicle), cycle, kind)
    assert_same_run(fast, ref)
    s_fast, s_ref = (r.metadata.get("equivalence_factor_final", 0.0) for r in (fast, ref))
    assert s_fast == pytest.approx(s_ref, rel=1e-9)
    assert abs(fast.energy_audit["residual"]) < 1e-6 * fast.value("traction_energy_j")


@pytest.mark.parametrize("vehicle", ["p2", "p3"])
def test_compiled_run_equals_the_python_loop_with_a_forced_on_engine(vehicle: str) -> None:
    """The electric assist with FASTSim's HEV rules (issue 25: the engine fired above
    ``engine_on_speed_mps``, braking included, at least ``engine_min_power_w`` below soc_high)."""
    changes = {"controller.engine_on_speed_mps": 3.0, "controller.engine_min_power_w": 15e3}
    fast, ref = _both(_config(vehicle, **changes), "udds", "electric_assist")
    assert_same_run(fast, ref)
    plain, _ = _both(_config(vehicle), "udds", "electric_assist")
    ts, ts0 = ref.timeseries, plain.timeseries
    moving = ts["speed_mps"].to_numpy() > 5.0
    assert ts["engine_on"].to_numpy()[moving].mean() > ts0["engine_on"].to_numpy()[moving].mean()


def test_engine_min_power_floors_the_fired_engine() -> None:
    """``engine_min_power_w``: below soc_high a fired engine gives at least the floor (the surplus
    charges the battery); without it the engine follows the load."""
    floor = 15e3
    cfg = _config("p2", **{"controller.engine_min_power_w": floor})
    run, _ = _both(cfg, "udds", "electric_assist")
    plain, _ = _both(_config("p2"), "udds", "electric_assist")

    def fired_below_soc_high(r: Any) -> np.ndarray:
        ts = r.timeseries
        return ts["engine_power_w"].to_numpy()[
            (ts["engine_on"] > 0).to_numpy() & (ts["soc"] < 0.7).to_numpy()
        ]

    p, p0 = fired_below_soc_high(run), fired_below_soc_high(plain)
    assert p.size > 20 and p0.size > 20
    assert np.median(p) >= 0.95 * floor > np.median(p0)
    assert run.value("fuel_kg") != pytest.approx(plain.value("fuel_kg"), rel=1e-3)


@pytest.mark.parametrize(
    ("vehicle", "kind", "changes"),
    [("p3", "electric_assist", {"engine.torque_scale": 0.3, "motor.max_torque_nm": 150.0}),
     ("p2", "aecms", {"engine.torque_scale": 0.3, "motor.max_torque_nm": 150.0}),
     ("power_split", "power_follower", {"engine.torque_scale": 0.4, "motor.torque_scale": 0.4})],
)  # fmt: skip
def test_compiled_run_equals_the_python_loop_when_the_car_cannot_follow(
    vehicle: str, kind: str, changes: dict[str, float]
) -> None:
    fast, ref = _both(_config(vehicle, **changes), "us06", kind)
    assert ref.value("traction_limited_s") > 10.0  # the driver's bisection ran
    assert_same_run(fast, ref)


@pytest.mark.parametrize("kind", ["power_follower", "ecms", "aecms"])
def test_compiled_run_equals_the_python_loop_with_the_small_pack(kind: str) -> None:
    """The shipped 2016 Prius's 0.75 kWh pack limits US06 (the driver's bisection runs), the
    power follower's fuel-ordered search and its fallback as the Python controller."""
    fast, ref = _both(_config("prius_2016"), "us06", kind)
    assert ref.value("traction_limited_s") > 10.0
    assert_same_run(fast, ref)


# ------------------------------------------------------------------ P3 machine over-speed
def _map_machine_p3(coupling_ratio: float) -> P.ParallelHEV:
    """The example with the shipped Honda map machine on the final-drive input, geared up so
    that it would exceed its highest map speed near the US06 top speed."""
    cfg = _config(
        "p3", **{"motor.model": "map", "motor.rating": "peak", "motor_coupling.ratio": coupling_ratio}
    )
    return P.build_parallel_hev(cfg)


def test_p3_machine_over_speed_is_infeasible_in_every_gear() -> None:
    hev = _map_machine_p3(2.0)
    w_max = max_machine_speed_radps(hev.motor)
    assert np.isfinite(w_max)
    w_wheel = 1.2 * w_max / (hev.final_drive.ratio * hev.motor_coupling.ratio)  # machine at 1.2 x its max
    gears, thr = P.candidate_controls(hev, 11)
    mech = P.mechanical(hev, w_wheel, 100.0, gears, thr)
    assert mech["motor_speed"].all() and mech["bad"].all()  # engine on or off, any gear: no way out
    below = P.mechanical(hev, 0.9 * w_wheel / 1.2, 100.0, gears, thr)
    assert not below["motor_speed"].any()
    st = P.power_flow(hev, w_wheel, 100.0, gears, thr, 0.6, 1.0, True)
    assert st.infeasible.all() and st.flags["motor_speed"].all()


@pytest.mark.parametrize("compiled", [True, False])
def test_p3_machine_never_turns_beyond_its_map_in_a_forward_run(compiled: bool) -> None:
    hev = _map_machine_p3(2.0)
    w_max = max_machine_speed_radps(hev.motor)
    cyc = load_cycle("us06")
    w_trace = np.max(cyc.speed_mps) / hev.tire.radius_m * hev.final_drive.ratio * hev.motor_coupling.ratio
    assert w_trace > 1.05 * w_max  # following the trace would over-speed the machine
    res = simulate_architecture("parallel", hev, cyc, controller="electric_assist", compiled=compiled)
    ts = res.timeseries
    assert np.max(np.abs(ts["motor_speed_radps"])) <= w_max * (1.0 + 1e-12)
    assert res.value("traction_limited_s") > 0.0  # the car falls behind the trace instead
    assert res.value("energy_audit_residual_traction_pct") < 1e-6


# ------------------------------------------------------------------ compiled batch
@pytest.mark.parametrize(
    ("vehicle", "changes", "variants"),
    [("p3", {}, {"body.mass_kg": [1100.0, 1250.0, 1400.0], "controller.soc_low": [0.45, 0.5, 0.55],
                 "controller.equivalence_factor": 2.5, "simulation.soc_initial": [0.55, 0.6, 0.65]}),
     ("p2", {"controller.kind": "aecms"}, {"engine.torque_scale": [0.8, 1.0, 1.2],
                                           "tire.radius_m": [0.3, 0.32, 0.34],
                                           "controller.equivalence_factor": [2.0, 2.5, 3.0]}),
     ("power_split", {"controller.kind": "ecms"}, {"body.drag_coefficient": [0.25, 0.3, 0.35],
                                                   "controller.equivalence_factor": [2.0, 2.5, 3.0]}),
     ("p3", {}, {"final_drive.ratio": [3.0, 3.5, 4.0]})],  # not compiled: runs one by one
)  # fmt: skip
def test_compiled_batch_equals_the_python_runs(
    vehicle: str, changes: dict[str, Any], variants: dict[str, Any]
) -> None:
    from hevsim.sim.simulator import simulate_batch

    cfg = _config(vehicle, **changes)
    fast = simulate_batch(cfg, variants, "udds")
    ref = simulate_batch(cfg, variants, "udds", compiled=False)
    assert list(fast.table.columns) == list(ref.table.columns)
    for col in ref.table.columns:
        tol = 1e-6 if col in ROUND_OFF else 0.0
        assert np.allclose(
            fast.table[col].to_numpy(float), ref.table[col].to_numpy(float), rtol=RTOL, atol=tol
        ), col
    assert fast.table["fuel_kg"].nunique() == len(fast.table)  # the variants differ


@pytest.mark.parametrize("kind", ["power_follower", "ecms"])
def test_compiled_batch_equals_single_compiled_runs_bit_for_bit(kind: str) -> None:
    """The threaded batch shares per-run data between variants (the power split's engine
    points, _compiled_hev.engine_points): interleaved engine variants, whose engine points
    differ, and body, SOC and controller variants give every metric of the single compiled
    run of the same configuration to the last bit (a variant reusing another's data would not)."""
    from hevsim.sim.simulator import simulate_batch

    cfg = _config("power_split", **{"controller.kind": kind})
    variants = {
        "engine.torque_scale": [1.0, 0.8, 1.0, 0.8, 1.0],
        "body.mass_kg": [1400.0, 1400.0, 1500.0, 1500.0, 1400.0],
        "simulation.soc_initial": [0.6, 0.6, 0.55, 0.65, 0.6],
        "controller.soc_low": [0.5, 0.5, 0.5, 0.45, 0.5],
    }
    table = simulate_batch(cfg, variants, "udds").table
    assert table["fuel_kg"].nunique() == 4  # the variants differ (the last repeats the first)
    for i in range(5):
        c = cfg.replace(**{k: v[i] for k, v in variants.items()})
        single = simulate_architecture(c.architecture, c, "udds")
        assert single.metadata["compiled"]
        for key, m in single.metrics.items():
            assert np.array_equal(table[key].iloc[i], m["value"], equal_nan=True), (i, key)

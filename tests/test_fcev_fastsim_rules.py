"""Issue 25, import item 1 for fuel-cell vehicles: FASTSim's fuel-converter keys of an ``H2FC``
vehicle carried as the HEV import carries them for the engine. ``mph_fc_on`` -> the load
follower's ``fuel_cell_on_speed_mps`` (the fuel cell runs above it whatever the SOC and load, at
no net output if need be), ``idle_fc_kw`` -> ``[fuel_cell] idle_fuel_power_w`` (a running fuel
cell draws at least that hydrogen power, FASTSim 3's ``pwr_idle_fuel``), and the load follower's
``fuel_cell_min_on_time_s`` (FASTSim's ``min_fc_time_on`` test; not carried by the import).

References: FASTSim's database rows (the Tucson Fuel Cell, row 23: ``mph_fc_on`` 1 mph,
``idle_fc_kw`` 2.68; the Mirai, row 24: 30 mph, 2.28 kW) and the closed form of the hydrogen,
``sum over running steps of max(P / eta(P), idle) dt / LHV`` with ``eta`` read from the written
``efficiency.csv`` with numpy. On the old tree the import wrote neither key (the fuel cell
stopped whenever the load follower's target was at or below zero, and burned ``P / eta``): the
tests fail there.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.test_forward_compiled_conventional import assert_same_run

from hevsim.architectures.fcev import build_fcev
from hevsim.components.fuel_cell import HYDROGEN_LHV_J_PER_KG, RUNNING_ZERO_W, FuelCellSystem
from hevsim.config import config_from_dict, load_vehicle_config
from hevsim.control import make_controller
from hevsim.control.simple import forced_on
from hevsim.errors import ConfigError
from hevsim.optimal import optimize
from hevsim.schema import read_toml
from hevsim.sim.forward import simulate_fcev
from hevsim.validation.fastsim_db import database_path
from hevsim.vehicle_import import import_vehicle, read_vehicle

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
MPH = 0.44704


def _import(tmp_path_factory: Any, row: int) -> tuple[Any, dict[str, Any], Path]:
    out = tmp_path_factory.mktemp(f"row{row}") / f"row{row}.toml"
    import_vehicle(database_path(), out, row=row)
    return load_vehicle_config(out), read_vehicle(database_path(), row=row), out


@pytest.fixture(scope="module")
def tucson(tmp_path_factory: Any) -> tuple[Any, dict[str, Any], Path]:
    return _import(tmp_path_factory, 23)


@pytest.fixture(scope="module")
def mirai(tmp_path_factory: Any) -> tuple[Any, dict[str, Any], Path]:
    return _import(tmp_path_factory, 24)


def _run(cfg: Any, cycle: str, compiled: bool = True) -> Any:
    model = build_fcev(cfg)
    return simulate_fcev(model, cycle, controller=make_controller(model), compiled=compiled)


def _steps(res: Any) -> tuple[np.ndarray, ...]:
    """(speed at the step's start and end [m/s], net power [W], hydrogen power [W], dt [s])."""
    ts = res.timeseries
    v = ts["speed_mps"].to_numpy()
    p = ts["fuel_cell_power_w"].to_numpy()[:-1]
    h2 = ts["hydrogen_rate_kgps"].to_numpy()[:-1] * HYDROGEN_LHV_J_PER_KG
    return v[:-1], v[1:], p, h2, np.diff(ts["time_s"].to_numpy())


def test_import_carries_mph_fc_on_and_idle_fc_kw(tucson: Any, mirai: Any) -> None:
    for cfg, v, _ in (tucson, mirai):
        assert cfg.fuel_cell.idle_fuel_power_w == pytest.approx(float(v["idle_fc_kw"]) * 1e3, rel=1e-15)
        assert cfg.controller.fuel_cell_on_speed_mps == pytest.approx(float(v["mph_fc_on"]) * MPH, rel=1e-15)
        assert cfg.controller.fuel_cell_min_on_time_s == 0.0  # min_fc_time_on: not carried
        assert cfg.controller.kind == "load_follower"
    assert (tucson[1]["mph_fc_on"], tucson[1]["idle_fc_kw"]) == (1.0, 2.68)
    assert (mirai[1]["mph_fc_on"], mirai[1]["idle_fc_kw"]) == (30.0, 2.28)


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("which", ["tucson", "mirai"])
def test_fuel_cell_runs_above_mph_fc_on_every_step_burning_idle_fuel(
    tucson: Any, mirai: Any, which: str, compiled: bool
) -> None:
    """Every step whose speed stays above ``mph_fc_on`` has the fuel cell running, and every
    running step burns at least ``idle_fc_kw``; with a 1 mph threshold (the Tucson) the fuel cell
    runs with no net output on many braking steps, which the old tree spent off."""
    cfg, v, _ = tucson if which == "tucson" else mirai
    res = _run(cfg, "udds", compiled)
    assert res.metadata["compiled"] is compiled
    v0, v1, p, h2, _ = _steps(res)
    above = np.minimum(v0, v1) > float(v["mph_fc_on"]) * MPH
    idle = float(v["idle_fc_kw"]) * 1e3
    assert above.sum() > 100
    assert np.all(p[above] > 0.0)
    running = p > 0.0
    assert np.all(h2[running] >= idle * (1.0 - 1e-12))
    assert np.all(h2[~running] == 0.0)
    no_output = above & (p <= RUNNING_ZERO_W)
    if which == "tucson":
        assert no_output.sum() > 100  # braking and coasting above 1 mph: on, no net output
        assert np.all(h2[no_output] == pytest.approx(idle, rel=1e-12))


@pytest.mark.parametrize("which", ["tucson", "mirai"])
def test_hydrogen_is_the_closed_form_with_the_idle_floor_and_the_audit_closes(
    tucson: Any, mirai: Any, which: str
) -> None:
    """Hydrogen mass x LHV = sum over running steps of max(P / eta(P), idle) dt, eta from the
    written efficiency.csv (numpy's interp); the floor binds on some steps; the audit closes."""
    cfg, v, out = tucson if which == "tucson" else mirai
    res = _run(cfg, "udds")
    _, _, p, _, dt = _steps(res)
    curve = np.loadtxt(out.with_name(f"{out.stem}_fuel_cell") / "efficiency.csv", delimiter=",", skiprows=1)
    eta = np.interp(p / (float(v["fc_max_kw"]) * 1e3), curve[:, 0], curve[:, 1])
    idle = float(v["idle_fc_kw"]) * 1e3
    chem = np.where(p > 0.0, np.maximum(p / eta, idle), 0.0)
    assert int(np.sum((p > 0.0) & (p / eta < idle))) > 10  # the floor binds
    kg = res.value("fuel_kg")
    assert kg * HYDROGEN_LHV_J_PER_KG == pytest.approx(float(np.sum(chem * dt)), rel=1e-12)
    a = res.energy_audit
    assert a["fuel"] == pytest.approx(float(np.sum(chem * dt)), rel=1e-12)
    assert a["fuel_cell_loss"] == pytest.approx(float(np.sum((chem - p) * dt)), rel=1e-12)
    assert abs(a["residual"]) < 1e-9 * (a["fuel"] + abs(a["battery_chemical"]))


@pytest.mark.parametrize("cycle", ["udds", "us06"])
def test_compiled_loop_equals_the_python_loop_with_the_rules(tucson: Any, mirai: Any, cycle: str) -> None:
    """The forced-on speed, the idle floor and a minimum on-time, compiled as in the Python loop
    (the one rule, :func:`hevsim.control.simple.forced_on`)."""
    for cfg in (tucson[0], mirai[0].replace(**{"controller.fuel_cell_min_on_time_s": 30.0})):
        model = build_fcev(cfg)
        fast_ctl, ref_ctl = make_controller(model), make_controller(model)
        fast = simulate_fcev(model, cycle, controller=fast_ctl)
        ref = simulate_fcev(model, cycle, controller=ref_ctl, compiled=False)
        assert fast.metadata["compiled"] and not ref.metadata["compiled"]
        assert_same_run(fast, ref)
        assert fast_ctl.on_time_s == ref_ctl.on_time_s and fast_ctl.previous_w == ref_ctl.previous_w


def _runs(p: np.ndarray) -> list[tuple[int, int]]:
    """(first step, length) of every run of steps with the fuel cell running."""
    on = np.concatenate(([0], (p > 0.0).astype(np.int8), [0]))
    starts, ends = np.flatnonzero(np.diff(on) == 1), np.flatnonzero(np.diff(on) == -1)
    return list(zip(starts.tolist(), (ends - starts).tolist(), strict=True))


def test_minimum_on_time_keeps_a_started_fuel_cell_running(mirai: Any) -> None:
    """``fuel_cell_min_on_time_s`` = 30 s: every run of the fuel cell that ends before the cycle
    does lasts at least 30 - dt = 29 steps (FASTSim's test: forced while 0 < time on < 30 - dt);
    without it some runs are shorter."""
    base = mirai[0]
    _, _, p0, _, _ = _steps(_run(base, "udds"))
    assert min(n for _, n in _runs(p0)) < 29
    _, _, p, _, _ = _steps(_run(base.replace(**{"controller.fuel_cell_min_on_time_s": 30.0}), "udds"))
    runs = [(k, n) for k, n in _runs(p) if k + n < p.size]
    assert runs and min(n for _, n in runs) >= 29


def test_forced_on_is_fastsims_rule() -> None:
    assert forced_on(0.5, 0.0, 1.0, 0.44704, 0.0) and not forced_on(0.44704, 0.0, 1.0, 0.44704, 0.0)
    assert forced_on(0.0, 1.0, 1.0, 1000.0, 30.0) and forced_on(0.0, 28.0, 1.0, 1000.0, 30.0)
    assert not forced_on(0.0, 29.0, 1.0, 1000.0, 30.0) and not forced_on(0.0, 0.0, 1.0, 1000.0, 30.0)


def test_idle_floor_in_the_component_kernel_and_method() -> None:
    """``max(P / eta(P), idle)`` while running, 0 off, the method a broadcast of the kernel; the
    default floor (0) leaves ``P / eta`` bit for bit."""
    from hevsim.components.fuel_cell import hydrogen_power_point

    x, y = np.array([0.0, 0.05, 0.2, 1.0]), np.array([0.1, 0.5, 0.6, 0.54])
    fc = FuelCellSystem(x, y, max_power_w=80e3, min_power_w=0.0, ramp_up_w_per_s=1e4,
                        ramp_down_w_per_s=1e4, idle_fuel_power_w=3000.0)  # fmt: skip
    p = np.array([0.0, RUNNING_ZERO_W, 500.0, 1500.0, 4000.0, 30e3, 80e3])
    eta = np.interp(p / 80e3, x, y)
    expect = np.where(p > 0.0, np.maximum(p / eta, 3000.0), 0.0)
    assert np.array_equal(fc.hydrogen_power_w(p), expect)
    kernel = [hydrogen_power_point(q, 80e3, x, y, 3000.0)[1] for q in p]
    assert np.allclose(kernel, expect, rtol=1e-15, atol=0.0)
    plain = FuelCellSystem(
        x, y, max_power_w=80e3, min_power_w=0.0, ramp_up_w_per_s=1e4, ramp_down_w_per_s=1e4
    )
    assert np.array_equal(plain.hydrogen_power_w(p), np.where(p > 0.0, p / eta, 0.0))


def test_dp_pays_the_idle_floor() -> None:
    """The DP reads the same hydrogen curve: its optimum's hydrogen is the closed form with the
    floor, and no lower than without the floor (a pointwise higher cost cannot lower the
    optimum on the same grids)."""
    cfg = load_vehicle_config(EXAMPLES / "fcev.toml")
    plain = optimize(build_fcev(cfg), "hwfet", progress=False)
    idle = 3000.0
    model = build_fcev(cfg.replace(**{"fuel_cell.idle_fuel_power_w": idle}))
    res = optimize(model, "hwfet", progress=False)
    ts = res.timeseries
    p, dt = ts["fuel_cell_power_w"].to_numpy()[:-1], ts["dt_s"].to_numpy()[:-1]
    chem = np.where(p > 0.0, np.maximum(p / model.fuel_cell.efficiency(p), idle), 0.0)
    assert res.value("fuel_kg") * HYDROGEN_LHV_J_PER_KG == pytest.approx(float(np.sum(chem * dt)), rel=1e-12)
    assert res.value("fuel_kg") >= plain.value("fuel_kg") * (1.0 - 1e-12)
    assert math.isfinite(res.value("fuel_kg"))


@pytest.mark.parametrize(
    ("section", "key", "value"),
    [
        ("fuel_cell", "idle_fuel_power_w", -1.0),
        ("controller", "fuel_cell_on_speed_mps", -2.0),
        ("controller", "fuel_cell_min_on_time_s", -5.0),
    ],
)
def test_bad_values_name_the_key(section: str, key: str, value: float) -> None:
    data = read_toml(EXAMPLES / "fcev.toml")
    data[section] = {**data.get(section, {}), key: value}
    with pytest.raises(ConfigError, match=rf"{section}\.{key}.*{value}"):
        config_from_dict(data, source="fcev-test", base_dir=EXAMPLES)

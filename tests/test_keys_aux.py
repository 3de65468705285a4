"""Issue 26, item 2a: the electrical auxiliary load (``[controller] aux_power_w``) acts on every
architecture: through an alternator on the conventional car (fuel via the engine), on the
bus of the parallel HEV (it was ignored before), with the energy audit closing.

References: the closed form P T / eta_alt on an ideal-fuel engine (fuel power = brake power),
and the shipped engine's fuel-map CSV read with scipy's bilinear interpolator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.interpolate import RegularGridInterpolator

from hevsim import config as C
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.sim.forward import simulate_architecture

ROOT = Path(__file__).resolve().parents[1]
ENGINE_MAP = (
    ROOT / "src" / "hevsim" / "data" / "components" / "engines" / "vw_1p9_tdi_ci67" / "fuel_rate_map.csv"
)


@pytest.fixture(scope="module")
def cycle() -> DriveCycle:
    c = load_cycle("udds")
    keep = np.asarray(c.time_s) <= 300.0
    return DriveCycle("udds300", np.asarray(c.time_s)[keep], np.asarray(c.speed_mps)[keep])


def _sedan(**changes: object) -> C.ConventionalConfig:
    cfg: C.ConventionalConfig = C.load_vehicle_config(ROOT / "examples" / "conventional_sedan.toml")
    return cfg.replace(**changes)


def _residual_pct(res: object) -> float:
    return float(res.value("energy_audit_residual_pct"))  # type: ignore[attr-defined]


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_conventional_aux_costs_p_t_over_eta_alt_on_an_ideal_engine(
    cycle: DriveCycle, compiled: bool
) -> None:
    """Ideal engine (fuel power = brake power), engine always on: the auxiliaries cost
    exactly P T / eta_alt of fuel energy; the audit closes and carries them."""
    p_w, eta = 400.0, 0.55
    ideal = {"engine.model": "constant_torque", "engine.max_torque_nm": 400.0, "alternator.efficiency": eta}
    base = simulate_architecture("conventional", _sedan(**ideal), cycle, compiled=compiled)
    aux = simulate_architecture(
        "conventional", _sedan(**ideal, **{"controller.aux_power_w": p_w}), cycle, compiled=compiled
    )
    duration = float(cycle.time_s[-1] - cycle.time_s[0])
    assert aux.value("traction_limited_s") == base.value("traction_limited_s") == 0.0
    d_fuel = aux.energy_audit["fuel"] - base.energy_audit["fuel"]
    assert d_fuel == pytest.approx(p_w * duration / eta, rel=1e-9)
    assert aux.energy_audit["aux"] == pytest.approx(p_w * duration, rel=1e-12)
    assert aux.energy_audit["alternator_loss"] == pytest.approx(p_w * duration * (1 / eta - 1), rel=1e-9)
    assert abs(aux.energy_audit["residual"]) < 1e-9 * aux.energy_audit["fuel"]
    assert aux.value("fuel_kg") > base.value("fuel_kg")


def test_conventional_aux_fuel_is_the_engine_map_at_the_loaded_point(cycle: DriveCycle) -> None:
    """Map engine: every fired step's fuel rate with the load equals the engine map (the
    shipped CSV, scipy bilinear) at the engine torque without it plus P / (eta_alt w_e);
    compiled and Python loops agree; the extra fuel energy is P T / (eta_alt eta_engine)
    with a marginal engine efficiency between 0.2 and 0.6."""
    p_w, eta = 2000.0, 0.6
    base = simulate_architecture("conventional", _sedan(), cycle)
    cfg = _sedan(**{"controller.aux_power_w": p_w, "alternator.efficiency": eta})
    aux = simulate_architecture("conventional", cfg, cycle)
    ref = simulate_architecture("conventional", cfg, cycle, compiled=False)
    for key in aux.energy_audit:
        assert aux.energy_audit[key] == pytest.approx(ref.energy_audit[key], rel=1e-9, abs=1e-6)
    assert abs(aux.energy_audit["residual"]) < 1e-9 * aux.energy_audit["fuel"]
    assert aux.value("traction_limited_s") == base.value("traction_limited_s")

    df = pd.read_csv(ENGINE_MAP)
    grid = df.pivot(index="speed_rad_per_s", columns="torque_N_m", values="fuel_rate_g_per_s")
    fuel_map = RegularGridInterpolator((grid.index.to_numpy(), grid.columns.to_numpy()), grid.to_numpy())
    b, a = base.timeseries.iloc[:-1], aux.timeseries.iloc[:-1]
    # fired in both runs (the alternator's drag can end a fuel cut: the braking demand must
    # then exceed the engine's drag plus the alternator's)
    fired = (a["engine_on"] & ~a["fuel_cut"] & ~b["fuel_cut"]).to_numpy()
    assert np.array_equal(a["gear"], b["gear"]) and fired.sum() > 100
    w = a["engine_speed_radps"].to_numpy()[fired]
    t_loaded = b["engine_torque_nm"].to_numpy()[fired] + p_w / (eta * w)
    assert np.allclose(a["engine_torque_nm"].to_numpy()[fired], t_loaded, rtol=1e-12, atol=1e-9)
    expected = fuel_map(np.column_stack([w, t_loaded]))
    assert np.allclose(a["fuel_rate_gps"].to_numpy()[fired], expected, rtol=1e-9, atol=1e-12)

    duration = float(cycle.time_s[-1] - cycle.time_s[0])
    eta_engine = p_w * duration / eta / (aux.energy_audit["fuel"] - base.energy_audit["fuel"])
    assert 0.2 < eta_engine < 0.6


def test_conventional_stop_start_aux_from_the_starter_battery(cycle: DriveCycle) -> None:
    """With the engine stopped the starter battery supplies the auxiliaries: the audit's
    battery_chemical source is P x engine-off time and still closes."""
    p_w = 500.0
    res = simulate_architecture(
        "conventional", _sedan(**{"controller.aux_power_w": p_w, "controller.stop_start": "on"}), cycle
    )
    ts = res.timeseries.iloc[:-1]
    dt = float(cycle.time_s[1] - cycle.time_s[0])
    off_s = float((~ts["engine_on"]).sum()) * dt
    assert off_s > 10.0
    assert res.energy_audit["battery_chemical"] == pytest.approx(p_w * off_s, rel=1e-12)
    assert abs(res.energy_audit["residual"]) < 1e-9 * res.energy_audit["fuel"]


@pytest.mark.parametrize("example", ["parallel_hev", "high_performance_parallel_hev"])
def test_parallel_aux_loads_the_bus(cycle: DriveCycle, example: str) -> None:
    """The parallel HEV's auxiliary load was ignored (same fuel and SOC with 5 kW); it now
    draws P T from the bus, in the audit's ``aux`` term, compiled = Python loop."""
    p_w = 1500.0
    cfg = C.load_vehicle_config(ROOT / "examples" / f"{example}.toml")
    base = simulate_architecture("parallel", cfg, cycle)
    loaded_cfg = cfg.replace(**{"controller.aux_power_w": p_w})
    aux = simulate_architecture("parallel", loaded_cfg, cycle)
    ref = simulate_architecture("parallel", loaded_cfg, cycle, compiled=False)
    duration = float(cycle.time_s[-1] - cycle.time_s[0])
    assert aux.energy_audit["aux"] == pytest.approx(p_w * duration, rel=1e-12)
    assert aux.energy_audit["aux"] == pytest.approx(ref.energy_audit["aux"], rel=1e-12)
    assert aux.value("fuel_kg") == pytest.approx(ref.value("fuel_kg"), rel=1e-9)
    assert abs(aux.energy_audit["residual"]) < 1e-8 * (
        aux.energy_audit["fuel"] + abs(aux.energy_audit["battery_chemical"])
    )
    sources = lambda r: r.energy_audit["fuel"] + r.energy_audit["battery_chemical"]  # noqa: E731
    assert sources(aux) - sources(base) > 0.8 * p_w * duration


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_parallel_aux_at_the_soc_floor(cycle: DriveCycle, compiled: bool) -> None:
    """At its SOC floor the battery may not discharge for traction but still feeds the
    auxiliaries (a P3 parallel HEV cannot charge at a standstill): the run goes on instead of
    stopping with "no feasible control even when stopping" at the first stop."""
    p_w = 3000.0
    cfg = C.load_vehicle_config(ROOT / "examples" / "parallel_hev.toml")
    cfg = cfg.replace(**{"controller.aux_power_w": p_w, "simulation.soc_initial": cfg.battery.soc_min})
    res = simulate_architecture("parallel", cfg, cycle, compiled=compiled)
    duration = float(cycle.time_s[-1] - cycle.time_s[0])
    assert res.energy_audit["aux"] == pytest.approx(p_w * duration, rel=1e-12)
    gross = res.energy_audit["fuel"] + abs(res.energy_audit["battery_chemical"])
    assert abs(res.energy_audit["residual"]) < 1e-8 * gross
    ts = res.timeseries
    floor = ts["soc"].to_numpy() < cfg.battery.soc_min
    # the floor admits the auxiliary load to the loop's relative 1e-6 (sim.forward Step.evaluate)
    assert (ts["battery_power_w"].to_numpy()[floor] <= p_w * (1.0 + 1e-6)).all()

"""Replaying a DP schedule on a ``[battery] model = "pack"`` vehicle (fuel-cell vehicle, power
split): the DP sees the pack's nominal current limits, the BMS in the forward loop derates
charging below them (54-60 A of the nominal 100 A on fcev_pack), so a scheduled control can be
infeasible at a step. The replay used to stop there with "no feasible control ... even when
stopping"; it now applies the closest feasible control, counts the step and reports the fuel
and final-SOC difference to the DP (``schedule_*`` metadata).

Independent checks: every step the schedule could follow replays it exactly (the DP's own
input); at a deviated step the pack's charge current sits at the BMS limit the run recorded
(the closest feasible power is on that boundary: within 0.5 %), never above it, and the fuel
cell / engine gives less than scheduled (the battery may take less).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim.architectures import build_vehicle
from hevsim.config import load_vehicle_config
from hevsim.control.parallel import ControlSchedule, InputSchedule
from hevsim.cycles import load_cycle
from hevsim.optimal import optimize
from hevsim.sim.pack_vehicle import simulate_pack_vehicle

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
DP_GRID = {"soc_grid_points": 41, "input_grid_points": 41}


def _replay(name: str, ambient_c: float | None) -> tuple[object, object, object]:
    model = build_vehicle(load_vehicle_config(EXAMPLES / name))
    cycle = load_cycle("udds").truncated(300.0)
    dp = optimize(model, cycle, progress=False, **DP_GRID)
    schedule = ControlSchedule.from_optimization(dp)
    options = {"ambient_temp_c": ambient_c, "soak": True} if ambient_c is not None else {}
    return dp, schedule, simulate_pack_vehicle(model, cycle, controller=schedule, **options)


def _assert_bms_held(ts: object, deviated: np.ndarray) -> None:
    i = ts["pack_current_a"].to_numpy()[:-1]  # type: ignore[index]
    chg = ts["bms_charge_limit_a"].to_numpy()[:-1]  # type: ignore[index]
    dis = ts["bms_discharge_limit_a"].to_numpy()[:-1]  # type: ignore[index]
    assert np.all(-i <= chg * (1 + 1e-9)) and np.all(i <= dis * (1 + 1e-9))
    assert np.all(-i[deviated] >= 0.995 * chg[deviated])  # on the boundary the BMS set


def test_fcev_pack_replay_takes_the_closest_feasible_power_where_the_bms_binds() -> None:
    """fcev_pack, 41 x 41 DP on UDDS's first 300 s: the DP schedules 31.4 kW at 299 s, the BMS
    allows 53.6 A of charge (the DP: 100 A); before, the replay stopped at 299 s."""
    dp, schedule, r = _replay("fcev_pack.toml", None)
    assert isinstance(schedule, InputSchedule)
    meta, ts = r.metadata, r.timeseries
    assert meta["schedule_deviated_steps"] >= 1
    assert r.value("traction_limited_s") == 0.0
    p_run = ts["fuel_cell_power_w"].to_numpy()[:-1]
    p_dp = dp.timeseries["fuel_cell_power_w"].to_numpy()[:-1]
    deviated = p_run != p_dp
    assert int(deviated.sum()) == meta["schedule_deviated_steps"]
    assert meta["schedule_deviated_first_s"] == ts["time_s"].to_numpy()[:-1][deviated][0]
    assert np.all(p_run[deviated] < p_dp[deviated])  # the fuel cell gives what the battery cannot take
    _assert_bms_held(ts, deviated)
    assert meta["schedule_fuel_difference_kg"] == pytest.approx(
        r.value("fuel_kg") - dp.value("fuel_kg"), abs=1e-15
    )
    assert meta["schedule_soc_final_difference"] == pytest.approx(
        r.value("soc_final") - dp.value("soc_final")
    )


def test_fcev_pack_cold_replay_runs_through() -> None:
    """The same at -10 degC after a soak: the BMS derates from the start (it stopped at 23 s)."""
    dp, _, r = _replay("fcev_pack.toml", -10.0)
    p_run = r.timeseries["fuel_cell_power_w"].to_numpy()[:-1]
    deviated = p_run != dp.timeseries["fuel_cell_power_w"].to_numpy()[:-1]
    assert r.metadata["schedule_deviated_steps"] == int(deviated.sum()) > 10
    assert r.value("traction_limited_s") == 0.0
    _assert_bms_held(r.timeseries, deviated)


def test_power_split_pack_replay_runs_through_a_cold_bms() -> None:
    """prius_like_power_split_pack at 0 degC after a soak (engine speed, throttle schedule): it
    stopped at 299 s; now the closest feasible (engine speed, throttle) there."""
    dp, schedule, r = _replay("prius_like_power_split_pack.toml", 0.0)
    assert isinstance(schedule, ControlSchedule)
    ts = r.timeseries
    u_run = ts["engine_throttle"].to_numpy()[:-1]
    u_dp = dp.timeseries["engine_throttle"].to_numpy()[:-1]
    deviated = ~np.isclose(u_run, u_dp, rtol=0.0, atol=1e-12) | ~np.isclose(
        ts["engine_speed_radps"].to_numpy()[:-1],
        dp.timeseries["engine_speed_radps"].to_numpy()[:-1],
        rtol=1e-12,
        atol=1e-9,
    )
    assert r.metadata["schedule_deviated_steps"] == int(deviated.sum()) >= 1
    assert r.value("traction_limited_s") == 0.0
    _assert_bms_held(ts, deviated)
    p_run = ts["engine_power_w"].to_numpy()[:-1]
    p_dp = dp.timeseries["engine_power_w"].to_numpy()[:-1]
    assert np.all(p_run[deviated] < p_dp[deviated])  # the engine charges less


def _ramp_down_violations(model: object, ts: object) -> np.ndarray:
    """Steps whose fuel-cell power fell faster than the ramp-down limit allows (to off: from above
    idle + one step's ramp-down); asserts the ramp-up limit holds at every step."""
    from hevsim.architectures import fcev as F

    fc = model.fuel_cell  # type: ignore[attr-defined]
    p = ts["fuel_cell_power_w"].to_numpy()[:-1]  # type: ignore[index]
    dt = float(np.diff(ts["time_s"].to_numpy())[0])  # type: ignore[index]
    prev = np.concatenate(([F.control_state(model)], p[:-1]))  # type: ignore[arg-type]
    up_ok = np.where(prev == 0.0, p <= max(fc.min_power_w, fc.ramp_up_w_per_s * dt) * (1 + 1e-12),
                     p - prev <= fc.ramp_up_w_per_s * dt * (1 + 1e-12))  # fmt: skip
    assert up_ok.all()
    step = fc.ramp_down_w_per_s * dt * (1 + 1e-12)
    return np.where(p == 0.0, (prev > 0.0) & (prev - step > fc.min_power_w), prev - p > step)


@pytest.mark.parametrize(("name", "window", "controller", "cycle"), [
    ("fcev_pack.toml", {}, {"controller": "load_follower"}, "us06"),
    ("fcev_pack.toml", {"battery.soc_min": 0.3, "battery.soc_max": 0.9},
     {"controller": "ecms", "equivalence_factor": 2.0}, "udds"),
])  # fmt: skip
def test_fuel_cell_sheds_power_where_the_bms_cannot_take_its_ramp_down(
    name: str, window: dict[str, float], controller: dict[str, object], cycle: str
) -> None:
    """fcev_pack: a fuel cell at 68 kW whose bus load falls to a coast within a second (US06 at
    13 s) can only drop to 45.6 kW at 22.8 kW/s, and the cold-derated pack takes 49 A: the load
    follower (the default controller) stopped with 'no feasible control'; ECMS at s = 2 in a
    0.3-0.9 window at UDDS 196 s the same (BMS charge limit 23 A). Now the fuel cell sheds power
    faster than its ramp-down limit there, the highest feasible power (the battery at its BMS
    charge limit), and the run counts those steps (metadata ``ramp_down_overrides``)."""
    import hevsim

    model = build_vehicle(load_vehicle_config(EXAMPLES / name).replace(**window))
    r = hevsim.simulate(model, cycle, **controller)
    ts = r.timeseries
    shed = _ramp_down_violations(model, ts)
    assert r.metadata["ramp_down_overrides"] == int(shed.sum()) >= 1
    _assert_bms_held(ts, np.zeros(shed.shape, dtype=bool))
    i = ts["pack_current_a"].to_numpy()[:-1]
    chg = ts["bms_charge_limit_a"].to_numpy()[:-1]
    assert np.all(-i[shed] >= 0.9 * chg[shed])  # it sheds no more than the BMS makes it (65-point grid)

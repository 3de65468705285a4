"""Energy management of the fuel-cell vehicle (issue 24 item 3, issue 25's FCEV): the DP over the
fuel cell's net power (0 = off) against closed-form optima, ECMS with s from the DP costate,
adaptive ECMS, the DP's replay in the forward loop, and the hydrogen bookkeeping.

Independent references: with an ideal battery (no loss, constant OCV) the hydrogen of any
schedule is at least the bus energy over the fuel cell's peak efficiency (``H(P) >= P /
eta_max``: the convex envelope of a curve rising to its peak, FASTSim's H2FC map), and with a
curve falling in power (``H`` convex) at least Jensen's ``T H(E / T)``; the DP must reach both
bounds within its grid's error and never go below them. The efficiency curve is read back from
its CSV with numpy here, not through :class:`~hevsim.components.fuel_cell.FuelCellSystem`.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import hevsim
from hevsim.architectures import ARCHITECTURES, build_vehicle
from hevsim.architectures import fcev as F
from hevsim.components.fuel_cell import HYDROGEN_LHV_J_PER_KG
from hevsim.config import load_vehicle_config
from hevsim.control import make_controller
from hevsim.control.parallel import ControlSchedule, InputSchedule, ecms_from_dp
from hevsim.cycles import load_cycle
from hevsim.optimal import OptimizationResult, optimize
from hevsim.optimal._fcev_dp import FCEVFormulation
from hevsim.optimal._hev_common import CycleSteps

ROOT = Path(__file__).resolve().parents[1]
FCEV = ROOT / "examples" / "fcev.toml"
CURVE = ROOT / "src" / "hevsim" / "data" / "components" / "fuel_cells" / "fastsim_h2fc" / "efficiency.csv"
ECMS_DP_BAND = (0.995, 1.02)
"""SOC-corrected ECMS hydrogen / DP hydrogen: at most 2 % above the optimum, no lower than the
DP's own grid error (0.5 %)."""


def _curve() -> tuple[np.ndarray, np.ndarray]:
    t = np.loadtxt(CURVE, delimiter=",", skiprows=1)
    return t[:, 0], t[:, 1]


@pytest.fixture(scope="module")
def fcev() -> F.FCEV:
    return build_vehicle(load_vehicle_config(FCEV))


@pytest.fixture(scope="module")
def dp_runs(fcev: F.FCEV) -> dict[str, OptimizationResult]:
    """Charge-sustaining DP optima on the default grids (SOC 201 x fuel-cell power 101)."""
    return {c: optimize(fcev, c, progress=False) for c in ("udds", "hwfet")}


def test_registered_with_its_formulation_and_online_controllers() -> None:
    arch = ARCHITECTURES["fcev"]
    assert arch.formulation() is FCEVFormulation
    assert arch.controllers == ("load_follower", "ecms", "aecms")


def test_candidates_are_the_dp_input_grid(fcev: F.FCEV, dp_runs: dict[str, OptimizationResult]) -> None:
    """ECMS scores the DP's own fuel-cell powers: 0 (off) to the rating, the same points."""
    (powers,) = make_controller(fcev, "ecms").controls
    grid = dp_runs["udds"].metadata["inputs"]["fuel_cell_power_w"]
    assert powers.size == grid["points"] == fcev.config.controller.control_points
    assert powers[0] == grid["min"] == 0.0 and powers[-1] == grid["max"] == fcev.fuel_cell.max_power_w


def _ideal(fcev: F.FCEV, **battery: float) -> F.FCEV:
    """``fcev`` with an ideal battery (no resistance, constant OCV) of 245 V x 20 Ah."""
    keys = {"battery.model": "ideal", "battery.ocv_v": 245.0, "battery.capacity_ah": 20.0,
            "battery.n_series": 1, **{f"battery.{k}": v for k, v in battery.items()}}  # fmt: skip
    return build_vehicle(fcev.config.replace(**keys))


def _bus_energy_j(model: F.FCEV, res: OptimizationResult) -> float:
    """Energy the bus needs over the DP's cycle with the fuel cell off [J]: machine electrical
    power (regeneration as large as it can be) + auxiliaries, each step."""
    steps = CycleSteps.from_cycle(res.cycle, model.body, model.tire)
    st = F.power_flow(model, steps.wheel_speed_radps, steps.wheel_torque_nm, 0.0, 0.6, steps.dt_s,
                      steps.v_mid_mps > 0.0, detail=True)  # fmt: skip
    return float(np.sum((st.details["motor_power_elec_w"] + model.aux_power_w) * steps.dt_s))


def _dp_energy_terms(model: F.FCEV, res: OptimizationResult) -> tuple[float, float, float]:
    """(DP hydrogen [kg], fuel-cell net energy [J], battery energy stored over the run [J])."""
    b = model.battery
    stored = (res.value("soc_final") - res.value("soc_initial")) * b.capacity_ah * 3600.0 * float(b.ocv(0.5))
    ts = res.timeseries
    e_fc = float(np.sum(ts["fuel_cell_power_w"].to_numpy()[:-1] * ts["dt_s"].to_numpy()[:-1]))
    return res.value("fuel_kg"), e_fc, stored


def test_dp_reaches_the_convex_envelope_of_the_efficiency_curve(fcev: F.FCEV) -> None:
    """FASTSim's H2FC curve rises to 60 % at 20 % load, then falls: ``H(P) = P / eta(P)`` is not
    convex, its convex envelope is the line ``P / 0.60`` up to the peak. With an ideal battery
    every schedule burns at least (bus energy + energy stored) / (0.60 LHV), and the DP reaches
    it by running the fuel cell at its peak point or off (the peak, 22.8 kW, is on the grid)."""
    frac, eta = _curve()
    eta_max = float(eta.max())
    p_star = float(frac[np.argmax(eta)]) * fcev.fuel_cell.max_power_w
    model = _ideal(fcev, max_discharge_current_a=400.0, max_charge_current_a=400.0)
    cyc = load_cycle("udds").truncated(400.0)
    res = optimize(model, cyc, soc_grid_points=201, input_grid_points=101, progress=False)
    h2, e_fc, stored = _dp_energy_terms(model, res)
    bound_kg = (_bus_energy_j(model, res) + stored) / (eta_max * HYDROGEN_LHV_J_PER_KG)
    assert e_fc == pytest.approx(_bus_energy_j(model, res) + stored, rel=1e-9)  # bus balance, no loss
    assert bound_kg * (1 - 1e-9) <= h2 <= bound_kg * 1.001  # 2e-4 above it (the SOC grid)
    p = res.timeseries["fuel_cell_power_w"].to_numpy()[:-1]
    on = p > 0.0
    assert np.sum(p[on & np.isclose(p, p_star)]) >= 0.95 * np.sum(p)  # bang-bang at the peak point


def test_dp_reaches_jensens_bound_with_a_convex_hydrogen_curve(fcev: F.FCEV) -> None:
    """Efficiency falling linearly with power, 60 % at 0 to 40 % at the rating: ``H(P)`` is
    convex, so (ideal battery, no binding limit) the least hydrogen runs the fuel cell at the
    mean bus power all the time, ``T H(E / T)``; the DP's grid (1.14 kW apart) mixes the two
    powers around the mean, within the chord's error."""
    model = _ideal(fcev, max_discharge_current_a=1000.0, max_charge_current_a=1000.0)
    fc = dataclasses.replace(model.fuel_cell, power_fraction=np.array([0.0, 1.0]),
                             efficiency_curve=np.array([0.6, 0.4]), min_power_w=0.0)  # fmt: skip
    model = dataclasses.replace(model, fuel_cell=fc)
    cyc = load_cycle("udds").truncated(400.0)
    res = optimize(model, cyc, soc_grid_points=401, input_grid_points=101, progress=False)
    h2, _, stored = _dp_energy_terms(model, res)
    t_total = float(res.cycle.time_s[-1] - res.cycle.time_s[0])
    p_mean = (_bus_energy_j(model, res) + stored) / t_total
    f = p_mean / fc.max_power_w
    jensen_kg = t_total * p_mean / (0.6 - 0.2 * f) / HYDROGEN_LHV_J_PER_KG
    assert jensen_kg * (1 - 1e-9) <= h2 <= jensen_kg * 1.001  # 1.2e-4 above it
    p = res.timeseries["fuel_cell_power_w"].to_numpy()[:-1]
    assert np.percentile(np.abs(p - p_mean), 90) <= 2 * fc.max_power_w / 100  # near the mean power


def test_dp_hydrogen_is_fuel_cell_energy_over_efficiency(
    fcev: F.FCEV, dp_runs: dict[str, OptimizationResult]
) -> None:
    frac, eta = _curve()
    for res in dp_runs.values():
        ts = res.timeseries
        p, dt = ts["fuel_cell_power_w"].to_numpy()[:-1], ts["dt_s"].to_numpy()[:-1]
        eff = np.interp(p / fcev.fuel_cell.max_power_w, frac, eta)
        chem = float(np.sum(np.where(p > 0, p / eff, 0.0) * dt))
        assert res.value("fuel_kg") * HYDROGEN_LHV_J_PER_KG == pytest.approx(chem, rel=1e-12)
        assert res.value("engine_on_time_s") == pytest.approx(float(np.sum(dt[p > 0])))  # fuel cell on
        assert abs(res.value("soc_final") - res.value("soc_initial")) <= 0.005 + 1e-12  # sustaining


@pytest.mark.parametrize("cycle", ["udds", "hwfet"])
def test_ecms_with_the_dp_costate_is_within_the_dp_bound(
    fcev: F.FCEV, dp_runs: dict[str, OptimizationResult], cycle: str
) -> None:
    dp = dp_runs[cycle]
    params = ecms_from_dp(dp)
    assert 1.0 < params["equivalence_factor"] < 3.0  # about 1 / (fuel-cell x battery efficiency)
    ecms = hevsim.simulate(fcev, cycle, controller="ecms", **params)
    assert ecms.metadata["controller"] == "ecms"
    assert ecms.metadata["equivalence_factor_final"] == params["equivalence_factor"]
    assert abs(ecms.value("soc_final") - fcev.config.simulation.soc_initial) <= 0.03
    lam = -float(np.nanmedian(dp.timeseries["costate_kg_per_soc"]))
    corrected = ecms.value("fuel_kg") + lam * (dp.value("soc_final") - ecms.value("soc_final"))
    lo, hi = ECMS_DP_BAND
    assert lo * dp.value("fuel_kg") <= corrected <= hi * dp.value("fuel_kg")
    assert ecms.value("traction_limited_s") == 0.0
    assert abs(ecms.energy_audit["residual"]) < 1e-11 * ecms.value("traction_energy_j")
    _assert_ramps_hold(fcev, ecms)
    _assert_hydrogen_is_energy_over_efficiency(ecms)


def _assert_ramps_hold(model: F.FCEV, res: object) -> None:
    """Every step's fuel-cell power is reachable from the one before (ramp limits, idle, off)."""
    ts = res.timeseries  # type: ignore[attr-defined]
    p = ts["fuel_cell_power_w"].to_numpy()[:-1]
    dt = float(np.diff(ts["time_s"].to_numpy())[0])
    prev = np.concatenate(([F.control_state(model)], p[:-1]))
    fc = model.fuel_cell
    for a, b in zip(prev, p, strict=True):
        up, down = b - a, a - b
        if b == 0.0:
            assert a == 0.0 or a - fc.ramp_down_w_per_s * dt <= fc.min_power_w
        elif a == 0.0:
            assert fc.min_power_w <= b <= max(fc.min_power_w, fc.ramp_up_w_per_s * dt) * (1 + 1e-12)
        else:
            assert up <= fc.ramp_up_w_per_s * dt * (1 + 1e-12)
            assert down <= fc.ramp_down_w_per_s * dt * (1 + 1e-12)


def _assert_hydrogen_is_energy_over_efficiency(res: object) -> None:
    ts = res.timeseries  # type: ignore[attr-defined]
    dt = float(np.diff(ts["time_s"].to_numpy())[0])
    p = ts["fuel_cell_power_w"].to_numpy()[:-1]
    eta = ts["fuel_cell_efficiency"].to_numpy()[:-1]
    chem = float(np.sum(np.where(p > 0, p / eta, 0.0)) * dt)
    kg = res.value("fuel_kg")  # type: ignore[attr-defined]
    assert kg * HYDROGEN_LHV_J_PER_KG == pytest.approx(chem, rel=1e-12)
    assert res.energy_audit["fuel"] == pytest.approx(chem, rel=1e-12)  # type: ignore[attr-defined]
    assert res.energy_audit["fuel_cell_loss"] == pytest.approx(  # type: ignore[attr-defined]
        float(np.sum(np.where(p > 0, p / eta - p, 0.0)) * dt), rel=1e-12
    )


@pytest.mark.parametrize("cycle", ["udds", "hwfet"])
def test_adaptive_ecms_is_charge_sustaining(fcev: F.FCEV, cycle: str) -> None:
    r = hevsim.simulate(fcev, cycle, controller="aecms")
    assert r.metadata["controller"] == "aecms"
    assert abs(r.value("soc_final") - fcev.config.simulation.soc_initial) <= 0.01
    assert abs(r.energy_audit["residual"]) < 1e-11 * r.value("traction_energy_j")
    _assert_ramps_hold(fcev, r)


def test_online_controllers_honour_a_slow_ramp(fcev: F.FCEV) -> None:
    """With 2 kW/s ramps (many steps want more) the candidates are moved into the ramp window:
    the limits bind and hold at every step, A-ECMS still ends charge sustaining, the audit
    closes. (The battery then meets the transients alone: at its current limit the car falls
    behind the trace for a few seconds, with the load follower too.)"""
    slow = build_vehicle(
        fcev.config.replace(**{"fuel_cell.ramp_up_w_per_s": 2000.0, "fuel_cell.ramp_down_w_per_s": 2000.0})
    )
    r = hevsim.simulate(slow, "udds", controller="aecms")
    _assert_ramps_hold(slow, r)
    p = r.timeseries["fuel_cell_power_w"].to_numpy()[:-1]
    running = (p[1:] > 0.0) & (p[:-1] > 0.0)
    assert np.max(np.abs(np.diff(p))[running]) == pytest.approx(2000.0)  # it binds
    assert abs(r.value("soc_final") - fcev.config.simulation.soc_initial) <= 0.01
    assert abs(r.energy_audit["residual"]) < 1e-11 * r.value("traction_energy_j")


@pytest.mark.parametrize("cycle", ["udds", "hwfet"])
def test_dp_replay_burns_the_dp_hydrogen(
    fcev: F.FCEV, dp_runs: dict[str, OptimizationResult], cycle: str
) -> None:
    """The DP's fuel-cell powers replayed in the forward loop: hydrogen and the SOC trace to 1e-9
    (the same power flow; the FCEV's machine inertia is in the vehicle mass for both)."""
    dp = dp_runs[cycle]
    schedule = ControlSchedule.from_optimization(dp)
    assert isinstance(schedule, InputSchedule)
    r = hevsim.simulate(fcev, cycle, dt_s=1.0, controller=schedule)
    assert r.value("traction_limited_s") == 0.0
    assert r.metadata["schedule_deviated_steps"] == 0  # the battery the DP saw: every step follows it
    assert abs(r.metadata["schedule_fuel_difference_kg"]) <= 1e-9 * dp.value("fuel_kg")
    assert abs(r.value("fuel_kg") - dp.dp.total_cost) <= 1e-9 * dp.value("fuel_kg")
    assert np.max(np.abs(r.timeseries["soc"].to_numpy() - dp.timeseries["soc"].to_numpy())) < 1e-9
    _assert_hydrogen_is_energy_over_efficiency(r)


def test_power_between_off_and_idle_is_infeasible(fcev: F.FCEV) -> None:
    fc = fcev.fuel_cell
    p = np.array([0.0, 0.5 * fc.min_power_w, fc.min_power_w])
    st = F.power_flow(fcev, 50.0, 100.0, p, 0.6, 1.0, True)
    assert st.flags["fuel_cell_power"].tolist() == [False, True, False]
    assert float(np.ravel(st.cost_kg)[0]) == 0.0  # off: no hydrogen


def test_cli_simulate_takes_ecms_from_a_saved_dp_result(
    dp_runs: dict[str, OptimizationResult], tmp_path: Path
) -> None:
    """`hevsim simulate examples/fcev.toml --ecms-from DP_DIR` (was: exit 2, 'ecms' not admitted)."""
    import json

    from hevsim.cli import main

    dp = dp_runs["udds"]
    dp.save(tmp_path / "dp")
    out = tmp_path / "ecms"
    assert main(["simulate", str(FCEV), "--cycle", "udds", "--ecms-from", str(tmp_path / "dp"), "--no-plots",
                 "--out", str(out)]) == 0  # fmt: skip
    meta = json.loads((out / "metadata.json").read_text())
    assert meta["controller"] == "ecms"
    s = ecms_from_dp(dp)["equivalence_factor"]
    assert meta["equivalence_factor_final"] == pytest.approx(s, rel=1e-7)  # costate.csv: 9 digits


def test_study_ecms_tuned_from_the_case_dp(fcev: F.FCEV) -> None:
    """A study's ``simulate`` solver with ``controller = "ecms_dp"`` on the FCEV (admitted now
    that it has ECMS and a DP): the same hydrogen as ECMS with the case DP's factor."""
    from hevsim.config import with_overrides
    from hevsim.studies.runner import run_study
    from hevsim.studies.spec import study_from_dict

    dp = {"soc_grid_points": 21, "input_grid_points": 21}
    study = study_from_dict({
        "name": "fcev_ecms_dp", "vehicle": str(FCEV), "cycles": ["hwfet"],
        "metrics": ["fuel_kg", "soc_final"],
        "parameters": {"body.mass_kg": [2000.0]},
        "solvers": [{"name": "simulate", "controller": "ecms_dp"}, {"name": "optimize", **dp}],
    })  # fmt: skip
    rows = run_study(study, scheduler="in-process", progress=False)
    assert (rows["status"] == "ok").all(), rows["error"].tolist()
    cfg = with_overrides(study.vehicle, {"body.mass_kg": 2000.0})
    s = ecms_from_dp(optimize(cfg, "hwfet", progress=False, **dp))["equivalence_factor"]
    ref = hevsim.simulate(cfg, "hwfet", controller="ecms", equivalence_factor=s)
    got = rows[rows["solver"] == "simulate[controller=ecms_dp]"].iloc[0]
    assert got["fuel_kg"] == pytest.approx(ref.value("fuel_kg"), rel=1e-12)


def test_shutdown_energy_is_the_ramp_down_sum(fcev: F.FCEV) -> None:
    """The energy a fuel cell at power P still gives on its fastest way to off (22.8 kW/s ramp,
    idle 1.5 kW, bus load 0.3 kW), summed by hand: from 114 kW it runs 91.2, 68.4, 45.6 and
    22.8 kW (from 22.8 kW off is reachable: 22.8 - 22.8 <= 1.5); from 30 kW, 7.2 kW; with
    0.5 s steps from 30 kW, 18.6 and 7.2 kW; from idle + one step's ramp-down or less, and
    off, nothing."""
    fc = fcev.fuel_cell
    assert (fc.ramp_down_w_per_s, fc.min_power_w) == (22800.0, 1500.0)
    e = fc.shutdown_energy_j(np.array([114e3, 30e3, 24.3e3, 1500.0, 0.0]), 1.0, 300.0)
    want = [(91.2e3 + 68.4e3 + 45.6e3 + 22.8e3) - 4 * 300.0, 7.2e3 - 300.0, 0.0, 0.0, 0.0]
    assert e == pytest.approx(want, rel=1e-12, abs=1e-9)
    assert fc.shutdown_energy_j(30e3, 0.5, 300.0) == pytest.approx((18.6e3 + 7.2e3 - 600.0) * 0.5, rel=1e-12)


def _wide_window(fcev: F.FCEV) -> F.FCEV:
    """The reported vehicle: SOC window 0.3-0.9 and 200 A current limits."""
    return build_vehicle(
        fcev.config.replace(**{"battery.soc_min": 0.3, "battery.soc_max": 0.9,
                               "battery.max_discharge_current_a": 200.0,
                               "battery.max_charge_current_a": 200.0})
    )  # fmt: skip


@pytest.mark.parametrize(("cycle", "s"), [("udds", 3.0), ("hwfet", 3.0), ("us06", 3.0), ("us06", 2.0),
                                          ("udds", 2.5)])  # fmt: skip
def test_ecms_keeps_room_for_the_fuel_cells_ramp_down(fcev: F.FCEV, cycle: str, s: float) -> None:
    """A factor that charges hard drove the SOC to ``soc_max`` with the fuel cell at tens of kW;
    the next step the full battery may not charge, the fuel cell cannot reach off within its
    ramp-down limit, and the run stopped with 'no feasible control ... even when stopping'
    (UDDS s = 3 at 72 s, HWFET at 74 s, US06 s = 2 at 422 s; the load follower ran). ECMS now
    keeps room for the fuel cell's ramp down (:meth:`FuelCellSystem.shutdown_energy_j`): the run
    ends, the ramps and the current limits hold, and the SOC exceeds ``soc_max`` at most by
    one step of braking (as with any controller)."""
    wide = _wide_window(fcev)
    assert hevsim.simulate(wide, cycle, controller="load_follower").value("fuel_kg") > 0.0
    r = hevsim.simulate(wide, cycle, controller="ecms", equivalence_factor=s)
    _assert_ramps_hold(wide, r)
    ts = r.timeseries
    assert np.max(np.abs(ts["battery_current_a"].to_numpy()[:-1])) <= 200.0 * (1 + 1e-9)
    assert ts["soc"].max() < 0.9 + 0.01
    assert abs(r.energy_audit["residual"]) < 1e-11 * r.value("traction_energy_j")


@pytest.mark.parametrize("cycle", ["udds", "hwfet", "us06"])
def test_aecms_runs_in_the_wide_window(fcev: F.FCEV, cycle: str) -> None:
    """The same vehicle with A-ECMS starting near the top (SOC 0.85) from a factor that charges
    hard (s0 = 5, kp = 5): it stopped 8 s into each cycle."""
    wide = _wide_window(fcev)
    r = hevsim.simulate(wide, cycle, controller="aecms", equivalence_factor=5.0, aecms_kp=5.0,
                        soc_initial=0.85)  # fmt: skip
    _assert_ramps_hold(wide, r)
    assert r.timeseries["soc"].max() < 0.9 + 0.01

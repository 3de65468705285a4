"""The battery pack inside the vehicle (issue 12 items 3-4): BMS, cooling load, derating,
ageing during the drive, bad input."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hevsim.battery.ageing import SECONDS_PER_DAY, AgeingState, Stress, load_ageing_model
from hevsim.battery.life import PackAgeState
from hevsim.cli import main
from hevsim.config import load_vehicle_config
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.sim.pack_vehicle import simulate_pack_vehicle

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"


def _copy_vehicle(tmp_path: Path, name: str, pack_edits: dict[str, str] | None = None,
                  vehicle_edits: dict[str, str] | None = None) -> Path:  # fmt: skip
    """A copy of an example pack vehicle and its pack file in ``tmp_path``, with text edits."""
    pack = (EX / "vehicle_pack.toml").read_text()
    pack = pack.replace(
        'thermal_config = "module_thermal.toml"', f'thermal_config = "{EX / "module_thermal.toml"}"'
    )
    for old, new in (pack_edits or {}).items():
        assert old in pack, old
        pack = pack.replace(old, new)
    (tmp_path / "vehicle_pack.toml").write_text(pack)
    veh = (EX / name).read_text()
    for old, new in (vehicle_edits or {}).items():
        assert old in veh, old
        veh = veh.replace(old, new)
    path = tmp_path / name
    path.write_text(veh)
    return path


def _short(cycle: str, seconds: float) -> DriveCycle:
    c = load_cycle(cycle)
    keep = np.asarray(c.time_s) <= seconds
    return DriveCycle(f"{c.name}_{seconds:g}s", np.asarray(c.time_s)[keep], np.asarray(c.speed_mps)[keep],
                      np.asarray(c.grade)[keep])  # fmt: skip


def test_series_udds_energy_balance_thevenin_and_cooling_load() -> None:
    """UDDS with cooling on: the pack's energy balance closes (< 0.1 % of the throughput; it is
    exact to rounding); the vehicle's bus used the pack's exact step pair (its terminal voltage
    equals the cells' step-average pack voltage, E - Z I, to 1e-9); the cooling power is a bus
    load (the audit's aux term equals the pump + fan + chiller energy) and the audit closes."""
    cfg = load_vehicle_config(EX / "series_hev_pack.toml")
    res = simulate_pack_vehicle(cfg, "udds", 1.0)
    e = res.extra["pack_energy"]
    assert e["throughput_j"] > 1e6
    assert abs(e["residual_relative"]) < 1e-3
    assert abs(e["residual_relative"]) < 1e-9
    ts = res.timeseries.iloc[:-1]
    i = ts["pack_current_a"].to_numpy()
    np.testing.assert_allclose(ts["battery_current_a"], i, rtol=0, atol=1e-9 * np.abs(i).max())
    v_pair = (ts["pack_ocv_v"] - ts["pack_resistance_ohm"] * ts["pack_current_a"]).to_numpy()
    v_cells = ts["pack_voltage_v"].to_numpy()
    # exact while every cell carries the pack's direction; below a few A the spread's
    # circulating currents turn some cells around (other OCV branch): bounded, tiny energy
    big = np.abs(i) > 5.0
    assert big.sum() > 500
    np.testing.assert_allclose(v_cells[big], v_pair[big], rtol=1e-9)
    np.testing.assert_allclose(ts["battery_voltage_v"].to_numpy()[big], v_cells[big], rtol=1e-9)
    assert abs(np.sum((v_cells - v_pair) * i)) < 1e-4 * np.sum(np.abs(v_cells * i))
    cooling = e["pump_work_j"] + e["chiller_electric_j"] + e["fan_electric_j"]
    assert cooling > 1e4
    assert res.energy_audit["aux"] == pytest.approx(cooling, rel=1e-9)
    assert abs(res.metrics["energy_audit_residual_pct"]["value"]) < 1e-6
    # the pack's SOC is what the supervisor saw
    mid_soc = 0.5 * (ts["cell_soc_min"] + ts["cell_soc_max"]).to_numpy()[:-1]
    np.testing.assert_allclose(res.timeseries["soc"].to_numpy()[1:-1], mid_soc, atol=0.02)


def test_parallel_pack_runs_and_carries_the_cooling_load(tmp_path: Path) -> None:
    """The parallel HEV (Python loop) with a pack: the pack's balance closes, the cooling load
    is in the audit (which closes), and a bigger fan load costs fuel."""
    cfg = load_vehicle_config(EX / "parallel_hev_pack.toml")
    cyc = _short("udds", 400.0)
    res = simulate_pack_vehicle(cfg, cyc)
    assert abs(res.extra["pack_energy"]["residual_relative"]) < 1e-9
    e = res.extra["pack_energy"]
    cooling = e["pump_work_j"] + e["chiller_electric_j"] + e["fan_electric_j"]
    assert res.energy_audit["aux"] == pytest.approx(cooling, rel=1e-9)
    assert abs(res.metrics["energy_audit_residual_pct"]["value"]) < 1e-6
    assert "module0_hottest_cell_temp_k" in res.timeseries and "cell_soc_spread" in res.timeseries
    hungry = _copy_vehicle(tmp_path, "parallel_hev_pack.toml",
                           {"pump_efficiency = 0.4": "pump_efficiency = 0.02"})  # fmt: skip
    res2 = simulate_pack_vehicle(load_vehicle_config(hungry), cyc)
    assert res2.metrics["pack_cooling_energy_j"]["value"] > cooling + 1e5
    assert res2.metrics["fuel_kg"]["value"] > res.metrics["fuel_kg"]["value"]


def test_hot_pack_derates_and_the_vehicle_says_so(caplog: pytest.LogCaptureFixture) -> None:
    """The shipped scenario (examples/ambient_study): 40 degC ambient, US06. Cooling off: the
    hottest cell passes the derating table's 45 degC, the BMS lowers the current, the car cannot
    follow the trace, and the run says when and why (events, log line, metrics). Cooling on: no
    derating."""
    cfg = load_vehicle_config(EX / "series_hev_pack.toml")
    off = simulate_pack_vehicle(cfg, "us06", 1.0, ambient_temp_c=40.0, soak=True, cooling_off=True)
    m = off.metrics
    assert m["pack_derated_s"]["value"] > 60.0
    assert m["pack_bms_limited_s"]["value"] > 0.0
    assert m["pack_peak_cell_temp_c"]["value"] > 45.0
    ev = off.events
    der = ev[(ev.kind == "derating") & (ev.to_state == "on")]
    assert len(der) >= 1 and der.time_s.iloc[0] == pytest.approx(m["pack_first_derating_s"]["value"])
    assert "hottest cell" in der.reason.iloc[0]
    held = ev[(ev.kind == "bms_limit") & (ev.to_state == "on")]
    assert len(held) >= 1 and "(temperature)" in held.reason.iloc[0]
    assert "pack derated" in caplog.text
    ts = off.timeseries
    assert (ts["bms_discharge_limit_a"] < 120.0 - 1e-9).any()
    derated = ts["derating_factor"] < 1.0
    assert (ts.loc[derated, "battery_limited"] > 0).any()  # the motor was held to the BMS's power
    on = simulate_pack_vehicle(cfg, "us06", 1.0, ambient_temp_c=40.0, soak=True)
    assert on.metrics["pack_derated_s"]["value"] == 0.0
    assert on.metrics["pack_cooling_energy_j"]["value"] > 1e5
    assert not (on.events.kind == "derating").any()


def test_ageing_over_n_runs_matches_the_closed_form() -> None:
    """Three identical runs with the age state carried: every cell's capacity fade and
    resistance growth equal the ageing model's closed form for three runs of stress (power laws
    in throughput and time, linear cycle resistance) within the model's own nonlinearity: the
    carried value lies between the closed forms at the first and at the last run's stress (the
    aged cells raise the C-rate a little). Not carrying the state, or adding the per-run
    losses, would be off by 3^0.55 or 3^0.45."""
    cfg = load_vehicle_config(EX / "series_hev_pack.toml")
    cyc = _short("us06", 200.0)
    state = PackAgeState(600)
    model = load_ageing_model(state.model)
    runs: list[list[Stress]] = []
    end = state.end

    def spy(pack: object, result: object = None) -> list[Stress]:
        runs.append(end(pack, result))
        return runs[-1]

    state.end = spy
    res = simulate_pack_vehicle(cfg, cyc, 1.0, age_state=state)
    one = [AgeingState(**vars(s)) for s in state.cells]
    for _ in range(2):
        simulate_pack_vehicle(cfg, cyc, 1.0, age_state=state)
    assert state.repetitions == 3 and len(runs) == 3
    assert state.distance_m == pytest.approx(3 * res.metrics["distance_m"]["value"])
    nominal = 0.8  # thesis cell [A h]
    cc, cal = model.data["cycle_capacity"], model.data["calendar"]
    scale_w = cc["reference_capacity_ah"] / nominal
    scale_s = model.data["cycle_resistance"]["reference_capacity_ah"] / nominal

    def closed_form(s: Stress) -> dict[str, float]:
        a_cap, a_res = model.calendar_rates(s)
        days = 3 * s.duration_s / SECONDS_PER_DAY
        return {
            "loss_cycle": model.cycle_capacity_rate(s) * (3 * s.throughput_ah * scale_w) ** cc["exponent"],
            "loss_calendar": a_cap * days ** cal["exponent"],
            "growth_calendar": a_res * days ** cal["exponent"],
            "growth_cycle": 3 * model.cycle_resistance_rate(s) * s.throughput_ah * scale_s,
        }

    for c in (0, 123, 599):
        first, last = closed_form(runs[0][c]), closed_form(runs[-1][c])
        got = state.cells[c]
        for key, v0 in first.items():
            v1 = last[key]
            assert v0 > 0 and abs(v1 / v0 - 1.0) < 0.01, (c, key)  # nearly identical runs
            lo, hi = min(v0, v1), max(v0, v1)
            assert lo * (1 - 1e-9) <= getattr(got, key) <= hi * (1 + 1e-9), (
                c,
                key,
                getattr(got, key),
                v0,
                v1,
            )
            if key != "growth_cycle":
                assert abs(getattr(one[c], key) * 3 / v0 - 1.0) > 0.3, (c, key)


def test_age_state_file_round_trip_and_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--age-state FILE: created on the first run, advanced by the second, written atomically;
    a state of another pack exits 2."""
    veh = _copy_vehicle(tmp_path, "series_hev_pack.toml")
    state = tmp_path / "age.json"
    cyc = tmp_path / "short.csv"
    c = _short("us06", 120.0)
    cyc.write_text(
        "time_s,speed_mps\n" + "".join(f"{t},{v}\n" for t, v in zip(c.time_s, c.speed_mps, strict=True))
    )
    args = ["simulate", str(veh), "--cycle", str(cyc), "--no-plots", "--age-state", str(state)]
    assert main([*args, "--out", str(tmp_path / "r1")]) == 0
    s1 = PackAgeState.load(state)
    assert s1.repetitions == 1 and s1.capacity_fraction().min() < 1.0
    assert main([*args, "--out", str(tmp_path / "r2")]) == 0
    s2 = PackAgeState.load(state)
    assert s2.repetitions == 2
    assert (s2.capacity_fraction() < s1.capacity_fraction()).all()
    other = PackAgeState(12)
    other.save(tmp_path / "other.json")
    bad = ["simulate", str(veh), "--cycle", str(cyc), "--age-state", str(tmp_path / "other.json")]
    assert main([*bad, "--out", str(tmp_path / "r3")]) == 2
    err = capsys.readouterr().err
    assert "other.json" in err and "12 cells" in err and "600 cells" in err


@pytest.mark.parametrize(
    ("pack_edits", "vehicle_edits", "needles"),
    [
        (
            {},
            {"bus_max_v = 450.0": "bus_max_v = 400.0"},
            ["vehicle_pack.toml", "pack.n_modules", "420", "bus_max_v"],
        ),
        (
            {"flow_l_min = 20.0": "flow_l_min = 0.0"},
            {},
            ["vehicle_pack.toml", "cooling.flow_l_min", "chiller"],
        ),
        (
            {"temp_c = [-40.0, 0.0, 45.0": "temp_c = [-20.0, 0.0, 45.0"},
            {},
            ["vehicle_pack.toml", "derating.temp_c", "-20", "-30"],
        ),
        ({}, {'pack = "vehicle_pack.toml"': 'pack = "missing.toml"'}, ["battery.pack", "missing.toml"]),
    ],
)
def test_bad_pack_vehicle_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], pack_edits: dict[str, str],
    vehicle_edits: dict[str, str], needles: list[str],
) -> None:  # fmt: skip
    """A pack whose voltage window the motor inverter cannot accept, a zero-flow loop with the
    chiller on, a derating table not covering the cells' temperature range, a missing pack
    file: exit 2 naming the file, the key and the value; no results folder."""
    veh = _copy_vehicle(tmp_path, "series_hev_pack.toml", pack_edits, vehicle_edits)
    out = tmp_path / "out"
    assert main(["simulate", str(veh), "--cycle", "udds", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    for n in needles:
        assert n in err, (n, err)
    assert not out.exists()


def test_bms_limits_are_exact_at_the_voltage_window() -> None:
    """The BMS's voltage limit is the current at which a series group's step-average voltage
    reaches the cells' v_min (closed form of the affine step pair): stepping the pack at that
    current puts the weakest group exactly at v_min (1e-9)."""
    from hevsim.battery.bms import PackRun
    from hevsim.sim.pack_vehicle import make_pack_run

    cfg = load_vehicle_config(EX / "series_hev_pack.toml")
    run: PackRun = make_pack_run(cfg, 1.0, 0.08)  # nearly empty: the voltage limit binds
    run.begin()
    ed, zd = run.group_pairs(1.0)
    v_min = run.pack.params.limits.v_min_v
    i_v = float(np.min((ed - v_min) / zd))
    assert run.limits.discharge_a <= i_v + 1e-12
    g = int(np.argmin((ed - v_min) / zd))
    cells = np.empty((run.pack.n_cells, 5))
    row, _ = run.pack.finish_step(run.start, i_v, cells_out=cells)
    n_p = run.pack.cfg.module.n_parallel
    assert cells[g * n_p : (g + 1) * n_p, 0].sum() == pytest.approx(i_v, rel=1e-12)
    # the cells' own step (share_current + cell_step) gives the pair's pack voltage E - Z I
    assert row["voltage_avg_v"] == pytest.approx(run.e_dis - run.z_dis * i_v, rel=1e-9)
    assert ed[g] - zd[g] * i_v == pytest.approx(v_min, rel=1e-12)
    assert math.isfinite(i_v) and i_v > 0


def test_life_checkpoint_resume(tmp_path: Path) -> None:
    """hevsim life's blocks: a run stopped after two blocks resumes from its checkpoint and
    continues the same table (the first blocks unchanged, the repetitions growing)."""
    from hevsim.sim.life import run_life

    cfg = load_vehicle_config(EX / "series_hev_pack.toml")
    cyc = tmp_path / "short.csv"
    c = _short("us06", 100.0)
    rows = "".join(f"{t},{v}\n" for t, v in zip(c.time_s, c.speed_mps, strict=True))
    cyc.write_text("time_s,speed_mps\n" + rows)
    ck = tmp_path / "life.checkpoint.json"
    first = run_life(cfg, str(cyc), 0.5, max_blocks=2, checkpoint=ck)
    assert ck.is_file() and len(first.table) == 2 and not first.reached
    more = run_life(cfg, str(cyc), 0.5, max_blocks=3, checkpoint=ck, resume=True)
    assert len(more.table) == 3
    np.testing.assert_allclose(more.table.iloc[:2].to_numpy(), first.table.to_numpy())
    assert more.table["repetitions"].is_monotonic_increasing
    assert more.table["soh_min"].iloc[2] < more.table["soh_min"].iloc[1] < 1.0
    assert more.state.repetitions == int(more.table["repetitions"].iloc[-1])

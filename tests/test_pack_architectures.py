"""``[battery] model = "pack"`` on every architecture with a traction battery (issue 24 items 3
and 7): the BEV, the power split and the parallel HEV (P3 and P2) run the whole pack (cells,
thermal model, cooling loop, BMS) through the one forward loop of :mod:`hevsim.sim.forward`.

Reference of the first test: the pack with one representative cell per module, no spread and an
ideal coolant reservoir (fixed temperature) is ``n_series`` identical cells carrying the pack
current over ``n_parallel``; the standalone electro-thermal cell model
(:class:`hevsim.battery.cell.Cell`, its own compiled loop :func:`hevsim.battery.kernel.run_cell`)
driven by that current must give the same voltage, SOC and temperature. The forward
architectures have no ``cell`` battery model of their own (config refuses it: a cell ECM in the
forward loop is a separate item), so this is the exact ``pack = cell`` comparison available.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from hevsim.battery.cell import Cell
from hevsim.battery.pack import load_pack_config
from hevsim.cli import main
from hevsim.config import load_vehicle_config
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.sim.pack_vehicle import simulate_pack_vehicle

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"

CASES = [  # (vehicle, its pack file, cycle, seconds): short cycles keep the file fast
    ("bev_pack.toml", "bev_battery.toml", "udds", 250.0),
    ("prius_like_power_split_pack.toml", "prius_like_battery.toml", "us06", 200.0),
    ("parallel_hev_pack.toml", "vehicle_pack.toml", "udds", 250.0),  # P3
    ("high_performance_parallel_hev_pack.toml", "hot_lap_pack.toml", "us06", 150.0),  # P2
]
IDS = ["bev", "power_split", "parallel_p3", "parallel_p2"]


def _short(cycle: str, seconds: float) -> DriveCycle:
    c = load_cycle(cycle)
    keep = np.asarray(c.time_s) <= seconds
    return DriveCycle(f"{c.name}_{seconds:g}s", np.asarray(c.time_s)[keep], np.asarray(c.speed_mps)[keep],
                      np.asarray(c.grade)[keep])  # fmt: skip


def _copy(tmp_path: Path, vehicle: str, pack: str, pack_edits: dict[str, str] | None = None,
          vehicle_edits: dict[str, str] | None = None) -> Path:  # fmt: skip
    """Copies of a shipped pack vehicle and its pack file in ``tmp_path``, with text edits."""
    text = (EX / pack).read_text()
    text = text.replace(
        'thermal_config = "module_thermal.toml"', f'thermal_config = "{EX / "module_thermal.toml"}"'
    )
    for old, new in (pack_edits or {}).items():
        assert old in text, old
        text = text.replace(old, new)
    (tmp_path / pack).write_text(text)
    veh = (EX / vehicle).read_text()
    for old, new in (vehicle_edits or {}).items():
        assert old in veh, old
        veh = veh.replace(old, new)
    (tmp_path / vehicle).write_text(veh)
    return tmp_path / vehicle


IDEAL_CELLS = {  # one representative cell per module, no spread, coolant an ideal reservoir
    "capacity_spread = 0.02": "capacity_spread = 0.0",
    "resistance_spread = 0.05": "resistance_spread = 0.0",
    "[cooling]\n": "[cooling]\ninfinite_capacity = 1\n",
}


def _representative(text_edits: dict[str, str], pack: str) -> dict[str, str]:
    edits = dict(text_edits)
    if '# cells = "representative"' in (EX / pack).read_text():
        edits['# cells = "representative"'] = 'cells = "representative"'
    else:
        edits['\nthermal = "coolant"'] = '\nthermal = "coolant"\ncells = "representative"'
    return edits


@pytest.mark.parametrize(("vehicle", "pack", "cycle", "seconds"), CASES, ids=IDS)
def test_fixed_coolant_representative_pack_equals_the_cell_model(
    tmp_path: Path, vehicle: str, pack: str, cycle: str, seconds: float
) -> None:
    """Pack in the vehicle = the electro-thermal cell model at the pack's current, to 1e-6
    (measured: 1e-15 voltage, 1e-16 SOC, 0 K temperature): pack voltage = n_series x the
    cell's step-average voltage, every cell's SOC and core temperature = the cell's; the
    vehicle's bus drew the pack's terminal power and its SOC is the cell's."""
    path = _copy(tmp_path, vehicle, pack, _representative(IDEAL_CELLS, pack))
    cfg = load_vehicle_config(path)
    res = simulate_pack_vehicle(cfg, _short(cycle, seconds), 1.0)
    ts = res.timeseries.iloc[:-1]
    pc = load_pack_config(tmp_path / pack)
    n_s, n_p = pc.pack.n_modules * pc.module.n_series, pc.module.n_parallel
    i = ts["pack_current_a"].to_numpy()
    assert i.max() > 20.0 and i.min() < -5.0  # both directions, real currents
    cell = Cell(
        pc.cells.parameters, soc_initial=cfg.simulation.soc_initial, temp_k=273.15 + pc.pack.initial_temp_c
    )
    ref = cell.simulate(i / n_p, 1.0, 273.15 + pc.cooling.supply_temp_c).timeseries
    v_ref = n_s * ref["voltage_avg_v"].to_numpy()
    np.testing.assert_allclose(ts["pack_voltage_v"], v_ref, rtol=1e-6)
    for col in ("cell_soc_min", "cell_soc_max"):
        np.testing.assert_allclose(ts[col], ref["soc"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(ts["hottest_cell_temp_k"], ref["temp_k"], rtol=0, atol=1e-6)
    assert np.ptp(ref["temp_k"]) > 0.01  # the cell's own thermal model is exercised
    p_pack = ts["pack_power_w"].to_numpy()
    np.testing.assert_allclose(ts["battery_power_w"], p_pack, rtol=0, atol=1e-6 * np.abs(p_pack).max())
    np.testing.assert_allclose(res.timeseries["soc"].to_numpy()[1:], ref["soc"], rtol=0, atol=1e-6)


@pytest.mark.parametrize(("vehicle", "pack", "cycle", "seconds", "edits"), [
    (*CASES[0], {"max_current_a = 400.0": "max_current_a = 80.0"}),  # the limit binds on UDDS
    (*CASES[1], {}),
    (*CASES[2], {"max_current_a = 120.0": "max_current_a = 40.0"}),
    (*CASES[3], {"max_current_a = 450.0": "max_current_a = 120.0"}),
], ids=IDS)  # fmt: skip
def test_pack_balance_bms_limits_and_cooling_load(
    tmp_path: Path, vehicle: str, pack: str, cycle: str, seconds: float, edits: dict[str, str]
) -> None:
    """Every cell with its spread: the pack's energy balance closes to 1e-9 of its throughput;
    no step's pack current exceeds the BMS's discharge or charge limit (and a limit binds, so
    the check is not idle); the cooling loop's electrical energy is the audit's bus load and
    the vehicle's audit closes; the pack metrics, channels and metadata are there."""
    res = simulate_pack_vehicle(load_vehicle_config(_copy(tmp_path, vehicle, pack, edits)),
                                _short(cycle, seconds), 1.0)  # fmt: skip
    e = res.extra["pack_energy"]
    assert e["throughput_j"] > 1e5
    assert abs(e["residual_relative"]) < 1e-9
    assert abs(res.metrics["pack_energy_balance_relative"]["value"]) < 1e-9
    ts = res.timeseries.iloc[:-1]
    i = ts["pack_current_a"].to_numpy()
    lim_d, lim_c = ts["bms_discharge_limit_a"].to_numpy(), ts["bms_charge_limit_a"].to_numpy()
    assert np.all(i <= lim_d * (1.0 + 1e-12))
    assert np.all(-i <= lim_c * (1.0 + 1e-12))
    assert max(np.max(i / lim_d), np.max(-i / lim_c)) > 0.99  # a limit binds
    cooling = e["pump_work_j"] + e["chiller_electric_j"] + e["fan_electric_j"]
    assert cooling > 0.0
    aux_w = load_vehicle_config(EX / vehicle).controller.aux_power_w
    assert res.energy_audit["aux"] == pytest.approx(cooling + aux_w * seconds, rel=1e-9)
    assert abs(res.metrics["energy_audit_residual_pct"]["value"]) < 1e-6
    for key in ("pack_peak_cell_temp_c", "pack_derated_s", "pack_cooling_energy_j", "pack_bms_limited_s"):
        assert math.isfinite(res.metrics[key]["value"]), key
    assert "module0_hottest_cell_temp_k" in res.timeseries and "coolant_loop_temp_k" in res.timeseries
    assert res.metadata["pack"]["n_cells"] == load_pack_config(tmp_path / pack).pack.n_modules * (
        load_pack_config(tmp_path / pack).module.n_series
        * load_pack_config(tmp_path / pack).module.n_parallel
    )


def test_bev_reaching_its_soc_floor_on_the_highway_coasts_to_rest() -> None:
    """The BEV's pack reaches battery.soc_min at highway speed: the car slows, then coasts to
    rest (the last crawl needs no push: the road load stops it within the step) and waits with
    the auxiliaries fed; before, the forward loop stopped with "no feasible control even when
    stopping". The audit still closes."""
    cfg = load_vehicle_config(EX / "bev_pack.toml")
    res = simulate_pack_vehicle(cfg, _short("hwfet", 200.0), 1.0, soc_initial=0.102)
    ts = res.timeseries
    assert ts["soc"].iloc[-1] < cfg.battery.soc_min + 1e-3
    assert ts["speed_mps"].iloc[-20:].max() < 1e-3 < ts["speed_desired_mps"].iloc[-20:].min()
    assert res.metrics["traction_limited_s"]["value"] > 20.0
    assert abs(res.metrics["energy_audit_residual_pct"]["value"]) < 1e-6
    assert abs(res.extra["pack_energy"]["residual_relative"]) < 1e-9


def test_batch_of_a_pack_vehicle_runs_the_pack() -> None:
    """``simulate_batch_architecture`` on the BEV with a pack: each variant runs the pack (the
    compiled batch, which knows only the nominal battery, is not used): its metrics equal a
    single pack run of that variant."""
    from hevsim.sim.forward import simulate_batch_architecture

    cyc = _short("udds", 120.0)
    batch = simulate_batch_architecture(EX / "bev_pack.toml", {"body.mass_kg": [1600.0, 1800.0]}, cyc)
    df = batch.table
    cfg = load_vehicle_config(EX / "bev_pack.toml").replace(**{"body.mass_kg": 1800.0})
    one = simulate_pack_vehicle(cfg, cyc)
    for key in ("soc_final", "pack_peak_cell_temp_c", "pack_cooling_energy_j"):
        assert df[key].iloc[1] == pytest.approx(one.metrics[key]["value"], rel=1e-12), key
    assert df["soc_final"].iloc[1] < df["soc_final"].iloc[0]


def test_conventional_with_a_pack_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A conventional car has no traction battery: [battery] model = "pack" is refused with
    exit 2 naming the file, the key, the value and the reason; no results folder."""
    text = (EX / "conventional_sedan.toml").read_text()
    text += '\n[battery]\nmodel = "pack"\npack = "vehicle_pack.toml"\n'
    path = tmp_path / "conventional_pack.toml"
    path.write_text(text)
    out = tmp_path / "out"
    assert main(["simulate", str(path), "--cycle", "udds", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    for needle in (str(path), "key 'battery.model'", "value 'pack'", "no traction battery", "conventional"):
        assert needle in err, (needle, err)
    assert not out.exists()


def test_bev_pack_outside_the_bus_window_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The BEV's inverter accepts 180-420 V; a bus_max_v of 380 V is below the pack's 390 V
    (100 x 3.9 V): exit 2 naming the pack file, its keys and both windows."""
    path = _copy(
        tmp_path,
        "bev_pack.toml",
        "bev_battery.toml",
        vehicle_edits={"bus_max_v = 420.0": "bus_max_v = 380.0"},
    )
    out = tmp_path / "out"
    assert main(["simulate", str(path), "--cycle", "udds", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    for needle in ("bev_battery.toml", "'pack.n_modules' = 50", "200 to 390 V", "bus_max_v = 380"):
        assert needle in err, (needle, err)
    assert not out.exists()


def test_simulate_ambient_soak_and_cooling_options(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``hevsim simulate --ambient-c -10 --soak`` on the BEV pack starts the cells at -10 degC
    (the BMS's cold derating shows); ``--cooling-off`` on the power split stops the pump;
    the options on a vehicle without a pack are refused (exit 2, the key and value named)."""
    cyc = tmp_path / "short.csv"
    c = _short("udds", 120.0)
    cyc.write_text(
        "time_s,speed_mps\n" + "".join(f"{t:g},{v:.6f}\n" for t, v in zip(c.time_s, c.speed_mps, strict=True))
    )
    out = tmp_path / "cold"
    assert main(["simulate", str(EX / "bev_pack.toml"), "--cycle", str(cyc), "--out", str(out), "--no-plots",
                 "--ambient-c", "-10", "--soak"]) == 0  # fmt: skip
    import json

    meta = json.loads((out / "metadata.json").read_text())
    assert meta["pack"]["ambient_temp_c"] == -10.0 and meta["pack"]["initial_temp_c"] == -10.0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["pack_peak_cell_temp_c"]["value"] < 0.0
    assert metrics["pack_derated_s"]["value"] > 0.0  # factor 0.9 at -10 degC
    out2 = tmp_path / "off"
    split = str(EX / "prius_like_power_split_pack.toml")
    assert main(["simulate", split, "--cycle", str(cyc), "--out", str(out2),
                 "--no-plots", "--ambient-c", "40", "--soak", "--cooling-off"]) == 0  # fmt: skip
    m2 = json.loads((out2 / "metrics.json").read_text())
    assert m2["pack_cooling_energy_j"]["value"] == 0.0
    capsys.readouterr()
    assert main(["simulate", str(EX / "bev.toml"), "--cycle", str(cyc), "--out", str(tmp_path / "x"),
                 "--ambient-c", "0"]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "--ambient-c" in err and "'battery.model' = 'table'" in err and "bev.toml" in err


def test_ambient_study_script_runs_each_new_example(tmp_path: Path) -> None:
    """examples/ambient_study/run_pack_architectures.py on 60 s cycles (its --seconds option):
    one BEV case from a nearly empty battery (its range run ends at the SOC floor) and the power
    split's cooling on/off pair; the report has both tables."""
    sys.path.insert(0, str(EX / "ambient_study"))
    try:
        import run_pack_architectures as study
    finally:
        sys.path.pop(0)
    out = tmp_path / "study"
    study.main(["--out", str(out), "--seconds", "60", "--workers", "1", "--ambient", "0",
                "--cycles", "udds", "--soc-initial", "0.11"])  # fmt: skip
    report = (out / "report.md").read_text()
    assert "bev_pack" in report and "prius_like_power_split_pack" in report
    import pandas as pd

    bev = pd.read_csv(out / "bev.csv")
    assert list(bev["cycle"]) == ["udds"] and bev["kwh_per_100km"].between(5.0, 40.0).all()
    # driven to empty: near the one-cycle extrapolation, the battery at its floor (0.1)
    assert bev["range_km"].iloc[0] == pytest.approx(bev["range_1cycle_km"].iloc[0], rel=0.3)
    assert bev["soc_at_empty"].iloc[0] == pytest.approx(0.1, abs=2e-3)
    split = pd.read_csv(out / "power_split.csv")
    assert sorted(split["cooling"]) == ["off", "on"]

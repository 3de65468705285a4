"""A stint with the pack (issue 29 item 4): N QSS laps with ``[battery] model = "pack"``, the
pack stepped along each lap, the lap limited by the BMS as the pack heats and derates.

A small pack for speed: the shipped high-performance parallel HEV with its hot-lap pack
(108s3p Saft 6 Ah) as one representative cell per module (54 simulated cells), on the
handling circuit at 2 m steps, 2-3 laps."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hevsim import tracks
from hevsim.cli import main
from hevsim.config import load_vehicle_config
from hevsim.sim.lap import simulate_lap
from hevsim.sim.stint import simulate_stint, stint_vehicle

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"
HP_PACK = EX / "high_performance_parallel_hev_pack.toml"
STEP_M = 2.0


def small_car(folder: Path, n_parallel: int = 3) -> Path:
    """The shipped car with its pack as one representative cell per module (no spread);
    ``n_parallel`` cells in parallel in each module (the shipped pack has 3; the pack's
    current limit scales with it)."""
    pack = (EX / "hot_lap_pack.toml").read_text()
    edits = {
        "n_parallel = 3 ": f"n_parallel = {n_parallel} ",
        "max_current_a = 450.0 ": f"max_current_a = {150.0 * n_parallel} ",
        "capacity_spread = 0.02 ": "capacity_spread = 0.0 ",
        "resistance_spread = 0.05 ": "resistance_spread = 0.0 ",
        'thermal_config = "module_thermal.toml"': (
            f'cells = "representative"\nthermal_config = "{EX / "module_thermal.toml"}"'
        ),
    }
    for old, new in edits.items():
        assert old in pack, old
        pack = pack.replace(old, new)
    (folder / f"small_pack_{n_parallel}p.toml").write_text(pack)
    car = HP_PACK.read_text().replace('pack = "hot_lap_pack.toml"', f'pack = "small_pack_{n_parallel}p.toml"')
    path = folder / f"car_{n_parallel}p.toml"
    path.write_text(car)
    return path


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    cfg = load_vehicle_config(small_car(tmp_path_factory.mktemp("stint")))
    track = tracks.load_track("handling", step_m=STEP_M)
    vehicle = stint_vehicle(cfg, cfg.simulation.soc_initial)
    return cfg, track, vehicle


@pytest.fixture(scope="module")
def on_off(setup):  # type: ignore[no-untyped-def]
    cfg, track, vehicle = setup
    on = simulate_stint(cfg, track, 3, step_m=STEP_M, vehicle=vehicle)
    off = simulate_stint(cfg, track, 3, step_m=STEP_M, vehicle=vehicle, cooling_off=True)
    return on, off


def test_pack_energy_balance_closes_per_lap(on_off) -> None:  # type: ignore[no-untyped-def]
    for res in on_off:
        bal = res.laps["energy_balance_relative"].to_numpy()
        assert np.all(np.abs(bal) < 1e-9), bal
        assert np.all(res.laps["pack_throughput_j"] > 1e6)
        assert abs(res.summary["stint_energy_balance_relative"]) < 1e-9


def test_pack_steps_carry_the_laps_energy(on_off) -> None:  # type: ignore[no-untyped-def]
    """The pack's steps on the stint clock take exactly the laps' battery energy: integrate the
    laps' piecewise-constant battery power back to back up to the last completed step."""
    res = on_off[0]
    t, e, t0, e0 = [0.0], [0.0], 0.0, 0.0
    for lap in res.lap_results:
        ts = lap.timeseries
        dt = ts["dt_s"].to_numpy()
        t.extend(t0 + np.cumsum(dt))
        e.extend(e0 + np.cumsum(ts["battery_power_w"].to_numpy() * dt))
        t0, e0 = t[-1], e[-1]
    ts = res.timeseries
    dt_s = res.summary["pack_dt_s"]
    end = ts["stint_time_s"].to_numpy()
    assert np.allclose(np.diff(end), dt_s, rtol=0, atol=1e-9)
    assert t0 - dt_s < end[-1] <= t0 + 1e-9
    asked = np.cumsum((ts["power_asked_w"] - ts["cooling_asked_w"]).to_numpy() * dt_s)
    ref = np.interp(end, np.array(t), np.array(e))
    assert np.allclose(asked, ref, rtol=1e-9, atol=1e-3 * np.abs(ref).max() * 1e-6)
    # lap boundaries: every pack step belongs to the lap it ends in
    lap_end = np.cumsum(res.laps["lap_time_s"].to_numpy())
    lap_of_step = np.searchsorted(lap_end, end - 1e-9) + 1
    assert np.array_equal(lap_of_step, ts["lap"].to_numpy())


def test_cooling_off_derates_earlier(on_off) -> None:  # type: ignore[no-untyped-def]
    on, off = on_off
    first_on = on.summary["first_derating_s"]
    first_off = off.summary["first_derating_s"]
    assert math.isfinite(first_off)
    assert first_off < (first_on if math.isfinite(first_on) else math.inf)
    assert off.summary["peak_cell_temp_c"] > on.summary["peak_cell_temp_c"]
    assert off.summary["cooling_energy_j"] < 0.1 * on.summary["cooling_energy_j"]
    assert off.laps["derated_s"].sum() > on.laps["derated_s"].sum()


def test_lap_time_grows_while_derating(on_off) -> None:  # type: ignore[no-untyped-def]
    for res in on_off:
        lt = res.laps["lap_time_s"].to_numpy()
        assert res.laps["derated_s"].sum() > 0.0
        assert np.all(np.diff(lt) >= -1e-9), lt
        assert np.all(res.laps["time_loss_s"] >= -1e-9)
        assert lt[-1] > res.summary["free_lap_time_s"] + 0.1  # the derated pack costs time
        # the lap was recomputed where a step's BMS limit bound: no discharge step above its limit
        ts = res.timeseries
        assert np.all(ts["current_a"] <= ts["bms_discharge_limit_a"] * (1 + 1e-9) + 1e-9)
        assert np.all(ts["current_a"] <= ts["discharge_available_a"] + 1e-9)
        assert res.summary["clamped_s"] <= 2.0 * res.summary["pack_dt_s"] * len(lt)


def test_no_binding_limit_is_the_single_lap(setup, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """Twice the cells in parallel (at most half the current per cell, a quarter of the heat):
    the BMS never binds, and every lap is the single QSS lap (speed, time and fuel)."""
    _, track, _ = setup
    cfg = load_vehicle_config(small_car(tmp_path, n_parallel=6))
    res = simulate_stint(cfg, track, 2, step_m=STEP_M, soc_initial=0.85)
    single = simulate_lap(cfg, track, step_m=STEP_M, soc=0.85)
    assert res.laps["derated_s"].sum() == 0.0
    assert res.laps["limited_s"].sum() == 0.0
    assert np.all(res.laps["passes"] == 1)
    for lap in res.lap_results:
        assert lap.lap_time_s == pytest.approx(single.lap_time_s, rel=1e-12)
        assert np.allclose(lap.timeseries["speed_mps"], single.timeseries["speed_mps"], rtol=1e-12, atol=0)
    assert res.laps["fuel_kg"].iloc[0] == pytest.approx(single.summary["fuel_kg"], rel=1e-12)


def test_save_writes_table_and_plots(on_off, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    out = on_off[1].save(tmp_path / "stint")
    names = {p.name for p in out.iterdir()}
    assert {"laps.csv", "pack.csv", "summary.json", "metadata.json", "lap_time.png"} <= names
    text = on_off[1].format()
    assert "peak_cell_temp_c" in text and len(text.splitlines()) == 3 + 2


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--laps", "0"], "--laps = 0"),
        (["--laps", "-2"], "--laps = -2"),
        (["--laps", "2", "--dt", "0"], "--dt = 0.0"),
    ],
)
def test_bad_options_exit_2(argv, message, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    rc = main(["stint", str(HP_PACK), "handling", *argv, "--out", str(tmp_path / "o")])
    assert rc == 2
    assert message in capsys.readouterr().err


def test_table_battery_refused(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    rc = main(["stint", str(EX / "high_performance_parallel_hev.toml"), "handling", "--laps", "2",
               "--out", str(tmp_path / "o")])  # fmt: skip
    assert rc == 2
    err = capsys.readouterr().err
    assert "battery.model" in err and "'table'" in err and "pack" in err


def test_pack_step_longer_than_half_a_lap_refused(setup) -> None:  # type: ignore[no-untyped-def]
    from hevsim.errors import ConfigError

    cfg, _, vehicle = setup
    skidpad = tracks.load_track("skidpad", step_m=STEP_M)  # an 11 s lap
    with pytest.raises(ConfigError, match=r"--dt = 8.0 s.*half a lap of 'skidpad'"):
        simulate_stint(cfg, skidpad, 2, step_m=STEP_M, dt_s=8.0, vehicle=vehicle)


def test_trial_passes_without_hot_spots_same_bit_for_bit(tmp_path: Path) -> None:
    """With module ROMs, the passes that may not be a lap's last skip the hot-spot search and a
    further pass reuses the previous one's operating points (``hevsim.sim.stint``, item 5): the
    stint is the same bit for bit as with every pass in full (the 600-cell pack of
    examples/vehicle_pack.toml on a coarse-mesh ROM, soaked at 46 degC with the cooling off, so
    that the laps take more than one pass)."""
    pytest.importorskip("skfem")
    pytest.importorskip("gmsh")
    from tests.thermal_helpers import COARSE_TOML

    from hevsim.thermal.rom import BuildOptions, build_rom_from_config

    (tmp_path / "module_coarse.toml").write_text(COARSE_TOML)
    rom, _ = build_rom_from_config(tmp_path / "module_coarse.toml", BuildOptions(tol_k=0.1))
    rom.save(tmp_path / "module.rom.npz")
    pack = (EX / "vehicle_pack.toml").read_text()
    edits = {
        '\nthermal = "coolant"': '\nthermal = "rom"',
        '\nthermal_config = "module_thermal.toml"': (
            '\nthermal_config = "module_coarse.toml"\nrom_file = "module.rom.npz"'
        ),
        "flow_l_min = 20.0": "flow_l_min = 500.0",  # 10 L/min per plate: the ROM's film range
        "flow_ref_l_min = 10.0": "flow_ref_l_min = 500.0",
    }
    for old, new in edits.items():
        assert pack.count(old) == 1, old
        pack = pack.replace(old, new)
    (tmp_path / "rom_pack.toml").write_text(pack)
    car = HP_PACK.read_text().replace('pack = "hot_lap_pack.toml"', 'pack = "rom_pack.toml"')
    (tmp_path / "car.toml").write_text(car)
    cfg = load_vehicle_config(tmp_path / "car.toml")
    track = tracks.load_track("handling", step_m=STEP_M)
    kw = {"step_m": STEP_M, "ambient_temp_c": 46.0, "soak": True, "cooling_off": True}
    fast = simulate_stint(cfg, track, 2, **kw)
    ref = simulate_stint(cfg, track, 2, full_passes=True, **kw)
    assert fast.metadata["thermal"] == "rom"
    assert fast.laps["passes"].max() > 1  # trial passes were taken
    assert fast.laps.equals(ref.laps)
    assert fast.timeseries.equals(ref.timeseries)
    assert not fast.timeseries.isna().any().any()
    assert fast.timeseries["hot_spot_temp_k"].max() > 46.0 + 273.15


def test_cooling_design_by_pack_changes(setup, on_off) -> None:  # type: ignore[no-untyped-def]
    """Another cooling design without another file: the loop without its chiller runs hotter
    and spends less cooling energy than the shipped loop, above the pack with its cooling off;
    no change is the file itself (bit for bit)."""
    cfg, track, vehicle = setup
    on, off = on_off
    same = simulate_stint(cfg, track, 3, step_m=STEP_M, vehicle=vehicle, pack_changes={})
    assert same.laps.equals(on.laps)
    no_chiller = simulate_stint(
        cfg, track, 3, step_m=STEP_M, vehicle=vehicle, pack_changes={"cooling.chiller": 0}
    )
    assert on.summary["cooling_energy_j"] > no_chiller.summary["cooling_energy_j"] > 0.0
    assert on.summary["peak_cell_temp_c"] < no_chiller.summary["peak_cell_temp_c"]
    assert no_chiller.summary["peak_cell_temp_c"] < off.summary["peak_cell_temp_c"]
    assert no_chiller.metadata["pack_changes"] == {"cooling.chiller": 0}


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--pack-set", "cooling.chiler=0"], "chiler"),  # an unknown key of the pack file
        (["--pack-set", "cooling.flow_l_min=-5"], "flow_l_min"),  # out of range
        (["--pack-set", "chiller=0"], "expected a key 'section.key'"),
        (["--pack-set", "cooling.chiller"], "expected section.key=VALUE"),
    ],
)
def test_bad_pack_changes_exit_2(argv, message, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    rc = main(["stint", str(HP_PACK), "handling", "--laps", "1", *argv, "--out", str(tmp_path / "o")])
    assert rc == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err

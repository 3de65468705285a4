"""``[battery] model = "cell"`` on the forward loop of every architecture (issue 24 item 3).

The reference is the standalone cell of :mod:`hevsim.battery` (:class:`hevsim.battery.Cell`,
the same kernel run on its own, with no vehicle): driven by the cell current the vehicle
recorded, it must give the vehicle's cell trajectory (step-average terminal voltage, SOC, core
temperature) to round-off. The bus must take exactly the pack's power, the vehicle's energy
audit and the cells' energy balance must close, and the compiled loop must equal the Python
reference loop. Before this change the parallel HEV, BEV, power split and FCEV refused the
model (ConfigError).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import hevsim
from hevsim.battery import Cell
from hevsim.cli import main
from hevsim.config import load_vehicle_config
from hevsim.sim.forward import simulate_architecture

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"
CASES = {  # row of the capability matrix -> (example, architecture, cells in series, in parallel)
    "parallel_p2": ("high_performance_parallel_hev.toml", "parallel", 100, 6),
    "parallel_p3": ("parallel_hev.toml", "parallel", 100, 6),
    "bev": ("bev.toml", "bev", 100, 40),
    "power_split": ("prius_like_power_split.toml", "power_split", 60, 8),
}
CELL = "thesis_table_4_1"  # one RC pair, lumped thermal (its charge OCV lies above the discharge OCV)


def cell_car(tmp: Path, example: str, n_s: int, n_p: int, cell: str = CELL, temp_c: float = 25.0) -> Path:
    """The shipped ``example`` with its ``[battery]`` replaced by a ``cell`` pack."""
    text = (EX / example).read_text()
    start = text.index("[battery]")
    end = text.index("\n[", start + 1) + 1
    section = (
        f'[battery]\nmodel = "cell"\ndata = "{cell}"\nn_series = {n_s}\nn_parallel = {n_p}\n'
        f"temperature_c = {temp_c}\nmax_discharge_current_a = 200.0\nmax_charge_current_a = 200.0\n"
        "soc_min = 0.3\nsoc_max = 0.9\n\n"
    )
    for p in EX.iterdir():
        if not (tmp / p.name).exists():
            (tmp / p.name).symlink_to(p)
    out = tmp / f"cell_{example}"
    out.write_text(text[:start] + section + text[end:])
    return out


def check_against_cell(res: object, n_s: int, n_p: int, port_k: float, temp0_k: float, soc0: float) -> None:
    """The vehicle's cell trajectory = the standalone cell driven by the recorded current."""
    ts = res.timeseries  # type: ignore[attr-defined]
    n = len(ts) - 1
    dt = float(ts["time_s"].iloc[1] - ts["time_s"].iloc[0])
    i_cell = ts["cell_current_a"].to_numpy()[:n]
    assert np.abs(i_cell).max() > 1.0  # the battery works
    cell = Cell(CELL, soc_initial=soc0, temp_k=temp0_k)
    ref = cell.simulate(i_cell, dt, port_temperature=port_k).timeseries
    for ours, theirs in (("cell_voltage_avg_v", "voltage_avg_v"), ("cell_voltage_v", "voltage_v"),
                         ("cell_soc", "soc"), ("cell_temp_k", "temp_k")):  # fmt: skip
        np.testing.assert_allclose(ts[ours].to_numpy()[:n], ref[theirs].to_numpy(), rtol=1e-9, err_msg=ours)
    # the vehicle's SOC is the cell's, and its bus takes exactly the pack's power
    np.testing.assert_allclose(ts["soc"].to_numpy()[1:], ref["soc"].to_numpy(), rtol=1e-9)
    p_pack = n_s * n_p * ref["voltage_avg_v"].to_numpy() * i_cell
    p_bus = ts["battery_power_w"].to_numpy()[:n]
    np.testing.assert_allclose(p_bus, p_pack, rtol=1e-9, atol=1e-9 * np.abs(p_pack).max())


@pytest.mark.parametrize("row", sorted(CASES))
def test_cell_battery_in_the_vehicle_is_the_standalone_cell(row: str, tmp_path: Path) -> None:
    example, arch, n_s, n_p = CASES[row]
    path = cell_car(tmp_path, example, n_s, n_p)
    cfg = load_vehicle_config(path)
    res = hevsim.simulate(cfg, "udds")
    assert res.metadata["compiled"]  # the architecture's compiled loop
    assert res.metadata["architecture"] == arch
    check_against_cell(res, n_s, n_p, 298.15, 298.15, cfg.simulation.soc_initial)
    # energy: the vehicle's audit and the cells' own balance close to round-off
    assert res.value("energy_audit_residual_traction_pct") < 1e-9
    e = res.extra["cell_energy"]
    assert e["throughput_j"] > 0.0 and abs(e["residual_relative"]) < 1e-9
    assert res.value("battery_peak_cell_temp_c") > 25.0  # the cells warm up
    # the compiled loop is the Python reference loop
    ref = simulate_architecture(arch, cfg, "udds", compiled=False)
    assert not ref.metadata["compiled"]
    for col in res.timeseries.columns:
        a, b = res.timeseries[col], ref.timeseries[col]
        if a.dtype.kind == "f":
            np.testing.assert_allclose(a.to_numpy(), b.to_numpy(), rtol=1e-12, atol=1e-12, err_msg=col)
    assert res.value("fuel_kg") == ref.value("fuel_kg")


def test_fcev_cell_battery(tmp_path: Path) -> None:
    """The fuel-cell vehicle (Python loop) takes the same battery step."""
    path = cell_car(tmp_path, "fcev.toml", 100, 6)
    cfg = load_vehicle_config(path)
    res = hevsim.simulate(cfg, "udds")
    check_against_cell(res, 100, 6, 298.15, 298.15, cfg.simulation.soc_initial)
    assert res.value("energy_audit_residual_traction_pct") < 1e-9


def test_ambient_and_soak(tmp_path: Path) -> None:
    """The cells' heat port at the run's ambient (``ambient_c``); with ``soak`` the cells start
    at it too; the standalone cell with that port (and start) temperature gives the trajectory."""
    path = cell_car(tmp_path, "bev.toml", 100, 40, temp_c=20.0)
    cfg = load_vehicle_config(path)
    soc0 = cfg.simulation.soc_initial
    warm = hevsim.simulate(cfg, "udds", ambient_c=40.0)
    check_against_cell(warm, 100, 40, 313.15, 293.15, soc0)
    assert warm.timeseries["cell_temp_k"].iloc[-1] > 300.0  # the port pulls the cells towards 40 degC
    cold = hevsim.simulate(cfg, "udds", ambient_c=0.0, soak=True)
    check_against_cell(cold, 100, 40, 273.15, 273.15, soc0)
    assert cold.metadata["cell"]["initial_temp_c"] == pytest.approx(0.0)
    assert cold.timeseries["cell_temp_k"].max() < warm.timeseries["cell_temp_k"].min()
    # the thesis cell's capacity (eq 35) falls with temperature (alpha_c < 0): the same drive
    # takes less SOC from the cold pack
    assert cold.value("soc_final") > warm.value("soc_final")
    with pytest.raises(hevsim.errors.ConfigError, match="cooling"):
        hevsim.simulate(cfg, "udds", ambient_c=0.0, cooling_off=True)


def test_cli_simulate_with_ambient(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = cell_car(tmp_path, "prius_like_power_split.toml", 60, 8)
    out = tmp_path / "out"
    code = main(["simulate", str(path), "--cycle", "udds", "--ambient-c", "35", "--soak", "--no-plots",
                 "--out", str(out)])  # fmt: skip
    assert code == 0
    import pandas as pd

    ts = pd.read_csv(out / "timeseries.csv") if (out / "timeseries.csv").is_file() else None
    if ts is None:
        ts = pd.read_parquet(out / "timeseries.parquet")
    assert ts["cell_temp_k"].iloc[0] == pytest.approx(308.15, abs=0.5)
    assert "cell" in capsys.readouterr().out
    code = main(["simulate", str(path), "--cycle", "udds", "--cooling-off", "--no-plots", "--out", str(out)])
    assert code == 2


def test_batch_runs_each_variant_with_its_own_cells(tmp_path: Path) -> None:
    path = cell_car(tmp_path, "parallel_hev.toml", 100, 6)
    cfg = load_vehicle_config(path)
    m = cfg.body.mass_kg
    b = hevsim.simulate_batch(cfg, {"body.mass_kg": [m, m + 300.0]}, "udds")
    one = hevsim.simulate(cfg.replace(**{"body.mass_kg": m + 300.0}), "udds")
    frame = b.frame if hasattr(b, "frame") else b.table
    assert frame["soc_final"].iloc[1] == pytest.approx(one.value("soc_final"), rel=1e-12)
    assert frame["soc_final"].iloc[0] != frame["soc_final"].iloc[1]


def test_series_cell_ambient_and_soak(tmp_path: Path) -> None:
    """The series HEV's kernel (ECM battery kind) takes the same options: with ``soak`` the run
    is the file with ``battery.temperature_c`` at the ambient; without, only the heat port
    moves (the cells start at the file's temperature and drift towards the ambient)."""
    path = cell_car(tmp_path, "series_hev.toml", 100, 6, temp_c=25.0)
    cfg = load_vehicle_config(path)
    soaked = hevsim.simulate(cfg, "udds", ambient_c=40.0, soak=True)
    hot = hevsim.simulate(cfg.replace(**{"battery.temperature_c": 40.0}), "udds")
    np.testing.assert_array_equal(soaked.timeseries["soc"], hot.timeseries["soc"])
    port = hevsim.simulate(cfg, "udds", ambient_c=40.0)
    base = hevsim.simulate(cfg, "udds")
    soc = [r.timeseries["soc"].to_numpy() for r in (base, port, hot)]
    assert soc[1][10] == pytest.approx(soc[0][10], abs=1e-6)  # the cells start at 25 degC
    assert not np.array_equal(soc[1], soc[0])  # the port warms them
    assert not np.array_equal(soc[1], soc[2])


def test_series_online_controller_with_cells(tmp_path: Path) -> None:
    """The series HEV's ECMS (its quasi-static power flow in the forward loop; was refused with
    a cell battery) steps the same cells: the standalone cell reproduces them, at an ambient too."""
    path = cell_car(tmp_path, "series_hev.toml", 100, 6)
    cfg = load_vehicle_config(path)
    res = hevsim.simulate(cfg, "udds", controller="ecms")
    assert res.metadata["controller"] == "ecms"
    check_against_cell(res, 100, 6, 298.15, 298.15, cfg.simulation.soc_initial)
    assert res.value("energy_audit_residual_traction_pct") < 1e-9
    warm = hevsim.simulate(cfg, "udds", controller="ecms", ambient_c=35.0)
    check_against_cell(warm, 100, 6, 308.15, 298.15, cfg.simulation.soc_initial)


@pytest.mark.parametrize(("row", "kind"), [("parallel_p3", "aecms"), ("power_split", "ecms")])
def test_online_controllers_with_cells_compiled_equal_python(row: str, kind: str, tmp_path: Path) -> None:
    """ECMS and A-ECMS score their candidates on the cells' step pairs in the compiled loop as in
    the Python loop; the cells are the standalone cell's."""
    example, arch, n_s, n_p = CASES[row]
    cfg = load_vehicle_config(cell_car(tmp_path, example, n_s, n_p))
    res = simulate_architecture(arch, cfg, "udds", controller=kind)
    ref = simulate_architecture(arch, cfg, "udds", controller=kind, compiled=False)
    assert res.metadata["compiled"] and not ref.metadata["compiled"]
    for col in ("soc", "fuel_kg", "cell_temp_k", "battery_power_w", "cell_current_a"):
        np.testing.assert_allclose(
            res.timeseries[col], ref.timeseries[col], rtol=1e-12, atol=1e-12, err_msg=col
        )
    check_against_cell(res, n_s, n_p, 298.15, 298.15, cfg.simulation.soc_initial)


PACKS = {  # row -> (pack vehicle, its pack file), as tests/test_pack_architectures.py
    "bev": ("bev_pack.toml", "bev_battery.toml"),
    "parallel_p3": ("parallel_hev_pack.toml", "vehicle_pack.toml"),  # the thesis cell (an RC pair)
    "parallel_p2": ("high_performance_parallel_hev_pack.toml", "hot_lap_pack.toml"),
    "series": ("series_hev_pack.toml", "vehicle_pack.toml"),
    "fcev": ("fcev_pack.toml", "prius_like_battery.toml"),
    "power_split": ("prius_like_power_split_pack.toml", "prius_like_battery.toml"),
}
WIDER = {
    "prius_like_battery.toml": {
        "n_parallel = 1 ": "n_parallel = 3 ",
        "max_current_a = 100.0": "max_current_a = 300.0",
    }
}
"""Pack edits that keep a row's BMS from holding the current back on the drive: the Prius-like
2s1p pack's cell-voltage limit caps the power split's regeneration from 115 s of UDDS (60 A)
and the FCEV's regeneration meets the pack's 100 A; three cells in parallel carry a third of
the current each, under a 300 A pack limit."""


@pytest.mark.parametrize("row", sorted(PACKS))
def test_pack_with_one_cell_per_module_equals_the_cell_battery(row: str, tmp_path: Path) -> None:
    """Issue 24, "pack in every architecture": a pack with one representative cell per module,
    no spread, its coolant an ideal reservoir (the cells' port at the supply temperature) and the
    cooling loop off (no bus load), on a drive where its BMS never holds the current back, is
    the ``cell`` battery of the same cells with that ambient: the same SOC, pack voltage and
    current, cell temperature and bus power, to 1e-6 (measured 1e-15 on 600 s of UDDS), on every
    architecture with a battery. The Prius-like pack of the power split and the FCEV runs with
    three cells in parallel (:data:`WIDER`): as shipped, from 115 s its BMS's cell-voltage limit
    caps the regeneration current (60 A, which the car takes to within 0.1 %), and a ``cell``
    battery has no BMS, only the ``[battery]`` current limits."""
    from hevsim.battery.pack import load_pack_config
    from hevsim.battery.params import load_cell_parameters
    from hevsim.sim.pack_vehicle import simulate_pack_vehicle

    try:
        from tests.test_pack_architectures import IDEAL_CELLS, _copy, _representative, _short
    except ImportError:  # pytest put tests/ itself on the path
        from test_pack_architectures import IDEAL_CELLS, _copy, _representative, _short  # type: ignore[no-redef]

    vehicle, pack_file = PACKS[row]
    edits = _representative({**IDEAL_CELLS, **WIDER.get(pack_file, {})}, pack_file)
    cfg = load_vehicle_config(_copy(tmp_path, vehicle, pack_file, edits))
    pc = load_pack_config(tmp_path / pack_file)
    cyc = _short("udds", 600.0)
    pack = simulate_pack_vehicle(cfg, cyc, 1.0, cooling_off=True)
    i_max = pc.pack.max_current_a
    n_s, n_p = pc.pack.n_modules * pc.module.n_series, pc.module.n_parallel
    cell = cfg.replace(**{
        "battery.model": "cell", "battery.data": pc.cells.parameters,
        "battery.temperature_c": pc.pack.initial_temp_c, "battery.n_series": n_s, "battery.n_parallel": n_p,
        "battery.max_discharge_current_a": i_max, "battery.max_charge_current_a": i_max,
    })  # fmt: skip
    res = hevsim.simulate(cell, cyc, 1.0, ambient_c=pc.cooling.supply_temp_c)
    a, b = pack.timeseries.iloc[:-1], res.timeseries.iloc[:-1]
    assert a["cooling_power_w"].max() == 0.0
    i = a["pack_current_a"].to_numpy()
    held = (i >= a["bms_discharge_limit_a"] * (1 - 1e-2)) | (-i >= a["bms_charge_limit_a"] * (1 - 1e-2))
    assert not held.any()
    pairs = (("soc", "soc", 1.0), ("pack_voltage_v", "cell_voltage_avg_v", n_s),
             ("pack_current_a", "cell_current_a", n_p), ("hottest_cell_temp_k", "cell_temp_k", 1.0),
             ("battery_power_w", "battery_power_w", 1.0), ("fuel_kg", "fuel_kg", 1.0))  # fmt: skip
    # Inside the cells' charge/discharge dead band the two models solve the step's current from
    # the bus's power with different pairs (the cell battery with the pair of the direction its
    # cells keep, the pack with the power's direction's), so there the current is compared to
    # the band: on the series HEV's UDDS one step of 600 (-5.9 W, 2.7 mA a cell) differs by
    # 1e-4 A; SOC, voltage and temperature stay within 1e-6 on every step.
    band = load_cell_parameters(pc.cells.parameters).resistance.switch_band_a
    in_band = np.abs(b["cell_current_a"].to_numpy()) <= band
    for x, y, scale in pairs:
        u, v = a[x].to_numpy(), b[y].to_numpy() * scale
        tol = 1e-6 * max(np.abs(v).max(), 1e-12)
        if x == "pack_current_a":
            np.testing.assert_allclose(u[in_band], v[in_band], rtol=0, atol=band * n_p, err_msg=x)
            u, v = u[~in_band], v[~in_band]
        np.testing.assert_allclose(u, v, rtol=1e-6, atol=tol, err_msg=x)
    # the drive exercises the cells: heat, discharge and charge (the FCEV's fuel cell carries
    # most of its drive: its battery discharges up to 13 A)
    assert np.ptp(b["cell_temp_k"]) > 0.01 and np.abs(i).max() > 20.0 and i.max() > 5.0 and i.min() < -5.0


def test_unknown_cell_exits_2_naming_the_key(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = cell_car(tmp_path, "parallel_hev.toml", 100, 6, cell="unobtainium")
    code = main(["simulate", str(path), "--cycle", "udds", "--no-plots", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2
    for word in ("battery.data", "'unobtainium'", "thesis_table_4_1", str(tmp_path)):
        assert word in err, (word, err)


def test_cold_ambient_beyond_the_cell_tables_warns(tmp_path: Path) -> None:
    """The Saft cell's tables start at 273.15 K: a soak at -20 degC runs on their edge column,
    with the standalone cell's warning."""
    from hevsim.battery.params import TemperatureRangeWarning

    cfg = load_vehicle_config(cell_car(tmp_path, "bev.toml", 100, 8, cell="saft_li_ion_6ah"))
    with pytest.warns(TemperatureRangeWarning, match="vehicle's cell temperature"):
        res = hevsim.simulate(cfg, "udds", ambient_c=-20.0, soak=True)
    assert res.timeseries["cell_temp_k"].iloc[0] < 260.0

"""The series HEV runs in the one compiled loop (issue 24 item 2): a plug-in of
:func:`hevsim.sim._loop.run_loop` with its own driver (the loop's ``drive`` hook), not a loop of
its own. Its numbers are the old loop's bit for bit (tests/test_series_kernel_regression.py, to
1e-9, unchanged); here: the old loop is gone, the series compiles the one loop once (single runs
of every battery-table refinement level, map and constant-efficiency machines, and the batch),
and the loop's engine bookkeeping keeps the series's meaning (a start is a genset start request,
engine time is time fired) against the recorded genset states."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest

from hevsim.config import load_config
from hevsim.sim import kernel as K
from hevsim.sim._compiled_series import SeriesPlug, series_drive
from hevsim.sim._loop import PLUGINS, _no_choose, _no_point, run_loop
from hevsim.sim.simulator import simulate, simulate_batch

ROOT = Path(__file__).resolve().parents[1]
LEVELS = Path(str(files("hevsim") / "data" / "refinement"))


def test_the_series_loop_of_its_own_is_gone() -> None:
    assert not hasattr(K, "run_series") and not hasattr(K, "run_series_batch")
    plugin = PLUGINS[SeriesPlug]
    assert plugin.drive is series_drive  # the driver hook: proportional driver, explicit Euler, genset shaft
    assert plugin.choose is _no_choose and plugin.point is _no_point  # the loop's own driver is not used


def test_the_series_compiles_the_one_loop_once() -> None:
    """Map machines (read-only tables) and constant-efficiency ones, an engine genset, a
    current source and none, single runs and the batch: one compiled run_loop for the series
    with a table battery (another would compile the loop again, about 20 s)."""
    for name in ("level1_ev_constant_torque", "level3_constant_current_genset", "level8_motor_maps"):
        simulate(load_config(LEVELS / f"{name}.toml"), "udds")
    cfg = load_config(ROOT / "examples" / "series_hev.toml")
    simulate(cfg, "udds")
    batch = simulate_batch(cfg, {"mass_kg": [1300.0, 1500.0]}, "udds")
    assert len(batch.table) == 2
    series = [s for s in run_loop.signatures if str(s[0]).startswith("SeriesPlug(")]
    tables = [s for s in series if str(s[-1]) == "none"]  # the loop's battery: a table battery
    assert len(tables) == 1, series


@pytest.mark.parametrize(
    ("name", "fired"),
    [("level3_constant_current_genset", False), ("level4_engine_speed_control", True)],
)
def test_engine_starts_and_time_keep_the_series_meaning(name: str, fired: bool) -> None:
    """The loop counts a start where the genset leaves ``off`` (cranking or a current source
    on: the plug-in's engine state 0.5) and engine time only where the engine fired: a
    current-source genset starts but never fires."""
    res = simulate(load_config(LEVELS / f"{name}.toml"), "us06")
    ts = res.timeseries
    on = ts["genset_state"].to_numpy() != 0
    starts = int(np.sum(on[1:] & ~on[:-1]) + on[0])
    assert starts > 0
    assert res.value("engine_starts") == starts
    dt = float(ts["time_s"].iloc[1] - ts["time_s"].iloc[0])
    if fired:
        burning = ts["fuel_rate_gps"].to_numpy()[:-1] > 0.0
        assert 0.0 < res.value("engine_on_time_s") <= np.sum(on[:-1]) * dt
        assert res.value("engine_on_time_s") == pytest.approx(np.sum(burning) * dt)
    else:
        assert res.value("engine_on_time_s") == 0.0


def test_the_series_battery_is_the_loops_battery_step() -> None:
    """Issue 24 item 2: the battery models plug into the one loop's battery hooks
    (``battery_begin``/``battery_end``) for the series HEV too, not into a dispatch of its own:
    no battery kinds, battery role or battery step in its kernel, and its plug-in runs the loop
    with a cell battery's ``CellBusTables`` and a pack's ``PackArrays`` as the loop's battery."""
    import inspect

    import hevsim.architectures.series_kernel as SK
    import hevsim.battery.vehicle as BV
    from hevsim.components.kernel_params import PARAMS
    from hevsim.sim import _compiled_series

    for name in ("BATTERY_KINDS", "EXACT_LIMIT_KINDS", "battery_state", "battery_tables", "BATKIND"):
        assert not hasattr(SK, name), name
    assert "battery_kind" not in PARAMS
    for name in (
        "PackKernelTables",
        "pack_kernel_tables",
        "battery_pack_begin",
        "battery_pack",
        "battery_pack_advance",
    ):
        assert not hasattr(BV, name), name
    source = inspect.getsource(_compiled_series)
    for word in ("battery_ecm", "battery_pack", "cell_step", "pack_finish", "pack_begin", "BATKIND"):
        assert word not in source, word
    cfg = load_config(ROOT / "examples" / "series_hev_pack.toml")
    simulate(cfg, "udds")
    cell = cfg.replace(**{"battery.model": "cell", "battery.data": "thesis_table_4_1",
                          "battery.n_series": 100, "battery.n_parallel": 6})  # fmt: skip
    simulate(cell, "udds")
    batteries = {str(s[-1]).split("(")[0] for s in run_loop.signatures if str(s[0]).startswith("SeriesPlug(")}
    assert {"PackArrays", "CellBusTables"} <= batteries, batteries


def test_series_pack_records_every_step() -> None:
    """The pack's record of a series run holds every vehicle step (the run's grid: 0.5 s steps
    on the 1 s UDDS); before, rows were reserved for the cycle's own samples, so the pack's
    channels stopped halfway and its peak temperature missed the second half of the drive."""
    res = simulate(load_config(ROOT / "examples" / "series_hev_pack.toml"), "udds")
    ts = res.timeseries
    n = len(ts) - 1
    assert float(ts["time_s"].iloc[1] - ts["time_s"].iloc[0]) == 0.5
    i_pack, i_bus = ts["pack_current_a"].to_numpy()[:n], ts["battery_current_a"].to_numpy()[:n]
    assert np.abs(i_bus[n // 2 :]).max() > 10.0
    np.testing.assert_array_equal(i_pack, i_bus)  # the pack stepped at the bus's current, every step
    # the vehicle's SOC is the pack's mean cell SOC after each step
    soc_min, soc_max = ts["cell_soc_min"].to_numpy()[:n], ts["cell_soc_max"].to_numpy()[:n]
    soc = ts["soc"].to_numpy()[1:]
    assert np.all(soc >= soc_min - 1e-12) and np.all(soc <= soc_max + 1e-12)
    peak = ts["hottest_cell_temp_k"].to_numpy()[:n].max() - 273.15
    assert res.value("pack_peak_cell_temp_c") == pytest.approx(peak, rel=1e-12)


def test_series_cell_battery_is_the_standalone_cell(tmp_path: Path) -> None:
    """The series HEV's ``cell`` battery is the one every architecture runs
    (:class:`~hevsim.battery.cell_run.CellRun` stepped by the loop): driven by the cell current
    the vehicle recorded, the standalone :class:`hevsim.battery.Cell` gives its voltage, SOC and
    temperature; the vehicle's SOC is the cell's (eq 37, its capacity at the cell's
    temperature), and the bus takes exactly the pack's power except where it asked for more
    than the pack's maximum power (the bus sags: ``battery_limited``). Before, the series
    counted its own SOC at the capacity of the initial temperature and had no cell channels."""
    from hevsim.battery import Cell

    try:
        from tests.test_cell_forward import CELL, cell_car
    except ImportError:  # pytest put tests/ itself on the path
        from test_cell_forward import CELL, cell_car  # type: ignore[no-redef]

    for temp_c, n_p, cycle in ((25.0, 6, "udds"), (40.0, 3, "us06")):
        path = cell_car(tmp_path, "series_hev.toml", 100, n_p, temp_c=temp_c)
        cfg = load_config(path)
        res = simulate(cfg, cycle)
        ts = res.timeseries
        n = len(ts) - 1
        dt = float(ts["time_s"].iloc[1] - ts["time_s"].iloc[0])
        i_cell = ts["cell_current_a"].to_numpy()[:n]
        assert np.abs(i_cell).max() > 1.0
        t_k = temp_c + 273.15
        ref = Cell(CELL, soc_initial=cfg.simulation.soc_initial, temp_k=t_k)
        ref_ts = ref.simulate(i_cell, dt, port_temperature=t_k).timeseries
        for ours, theirs in (
            ("cell_voltage_avg_v", "voltage_avg_v"),
            ("cell_soc", "soc"),
            ("cell_temp_k", "temp_k"),
        ):
            np.testing.assert_allclose(
                ts[ours].to_numpy()[:n], ref_ts[theirs].to_numpy(), rtol=1e-9, err_msg=ours
            )
        np.testing.assert_allclose(ts["soc"].to_numpy()[1:], ref_ts["soc"].to_numpy(), rtol=1e-9)
        p_pack = 100 * n_p * ref_ts["voltage_avg_v"].to_numpy() * i_cell
        p_bus = ts["battery_power_w"].to_numpy()[:n]
        sags = ts["battery_limited"].to_numpy()[:n] > 0
        tol = 1e-9 * np.abs(p_pack).max()
        np.testing.assert_allclose(p_bus[~sags], p_pack[~sags], rtol=1e-9, atol=tol)
        assert np.all(p_bus[sags] >= p_pack[sags] - tol)  # where not, the bus asked beyond the pack
        assert res.value("energy_audit_residual_pct") < 1e-9
        assert abs(res.extra["cell_energy"]["residual_relative"]) < 1e-9

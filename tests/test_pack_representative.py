"""``[module] cells = "representative"`` (issue 12 speed): one simulated cell per module stands
for its ``n_series x n_parallel`` cells (current / n_parallel, voltage x n_series, heat and
stored energies x cells). Without cell-to-cell spread and with every cell's port at its plate's
coolant (``thermal = "coolant"``) the full pack's cells are identical, so the representative
pack must give the full simulation's results to rounding."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hevsim.battery.pack import Pack, load_pack_config, pack_config_from_dict
from hevsim.config import load_vehicle_config
from hevsim.errors import ConfigError
from hevsim.schema import read_toml
from hevsim.sim.pack_vehicle import simulate_pack_vehicle

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"
NO_SPREAD = {
    "capacity_spread = 0.02 ": "capacity_spread = 0.0 ",
    "resistance_spread = 0.05 ": "resistance_spread = 0.0 ",
}


def _vehicle(tmp_path: Path, cells: str) -> Path:
    """series_hev_pack.toml with its pack without spread, ``[module] cells = cells``."""
    pack = (EX / "vehicle_pack.toml").read_text()
    pack = pack.replace(
        'thermal_config = "module_thermal.toml"', f'thermal_config = "{EX / "module_thermal.toml"}"'
    )
    edits = {**NO_SPREAD, '\nthermal = "coolant"': f'\nthermal = "coolant"\ncells = "{cells}"'}
    for old, new in edits.items():
        assert old in pack, old
        pack = pack.replace(old, new)
    (tmp_path / f"pack_{cells}.toml").write_text(pack)
    veh = (
        (EX / "series_hev_pack.toml")
        .read_text()
        .replace('pack = "vehicle_pack.toml"', f'pack = "pack_{cells}.toml"')
    )
    path = tmp_path / f"veh_{cells}.toml"
    path.write_text(veh)
    return path


def _pack_cfg(cells: str):  # type: ignore[no-untyped-def]
    cfg = load_pack_config(EX / "vehicle_pack.toml")
    return replace(
        cfg,
        cells=replace(cfg.cells, capacity_spread=0.0, resistance_spread=0.0),
        module=replace(cfg.module, cells=cells, n_series=3, n_parallel=4),
        pack=replace(cfg.pack, n_modules=5, max_current_a=60.0),
    )


def test_representative_pack_equals_full_pack_without_spread() -> None:
    """Pack.simulate over a current with both directions, rests and derating: every channel
    and energy term of the representative pack equals the full pack's (3s4p modules) to 1e-9."""
    t = np.arange(1500.0)
    current = 70.0 * np.sin(t / 37.0) + 25.0 * np.sign(np.sin(t / 5.0)) * (t % 200 < 150)
    full = Pack(_pack_cfg("all")).simulate(current)
    rep = Pack(_pack_cfg("representative")).simulate(current)
    assert full.cells.shape[1] == 60 and rep.cells.shape[1] == 5
    for col in full.timeseries:
        a, b = full.timeseries[col].to_numpy(), rep.timeseries[col].to_numpy()
        np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-9 * max(1.0, np.abs(a).max()), err_msg=col)
    assert np.ptp(full.timeseries["current_a"]) > 100.0 and full.timeseries["plate_heat_w"].max() > 1.0
    for key, val in full.energy.items():
        assert rep.energy[key] == pytest.approx(val, rel=1e-9, abs=1e-9 * full.energy["throughput_j"]), key
    # the representative cell is the full pack's cell 0 (current, SOC, temperature, port heat, voltage)
    np.testing.assert_allclose(rep.cells[:, 0, :], full.cells[:, 0, :], rtol=1e-9, atol=1e-9)


def test_representative_vehicle_equals_full_vehicle_without_spread(tmp_path: Path) -> None:
    """A series HEV on 600 s of US06 (BMS limits, cooling load, pack Thevenin pairs): the
    representative pack's vehicle time series equals the full pack's to 1e-9."""
    from hevsim.cycles import DriveCycle, load_cycle

    c = load_cycle("us06")
    keep = np.asarray(c.time_s) <= 600.0
    cyc = DriveCycle(
        "us06_600", np.asarray(c.time_s)[keep], np.asarray(c.speed_mps)[keep], np.asarray(c.grade)[keep]
    )
    full = simulate_pack_vehicle(load_vehicle_config(_vehicle(tmp_path, "all")), cyc, 1.0)
    rep = simulate_pack_vehicle(load_vehicle_config(_vehicle(tmp_path, "representative")), cyc, 1.0)
    assert np.abs(full.timeseries["pack_current_a"]).max() > 50.0
    for col in full.timeseries:
        a = full.timeseries[col].to_numpy()
        if a.dtype.kind not in "fiu":
            continue
        b = rep.timeseries[col].to_numpy()
        np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-9 * max(1.0, np.abs(a).max()), err_msg=col)
    assert rep.metadata["pack"]["n_cells"] == 50 and full.metadata["pack"]["n_cells"] == 600


def test_representative_refuses_spread_and_unknown_mode() -> None:
    data = read_toml(EX / "vehicle_pack.toml")
    data["module"]["cells"] = "representative"
    with pytest.raises(ConfigError, match=r"representative.*spread"):
        pack_config_from_dict(data, "vehicle_pack.toml")
    data["module"]["cells"] = "some"
    with pytest.raises(ConfigError, match=r"module\.cells"):
        pack_config_from_dict(data, "vehicle_pack.toml")

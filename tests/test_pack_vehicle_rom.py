"""The series HEV whose pack modules carry the module thermal ROM (issue 12 items 1-3 together).

tests/test_pack_vehicle.py drives the vehicle with coolant-port packs and tests/test_pack.py the
ROM pack on its own; here the compiled series kernel steps 50 module ROMs inside its loop: the
pack's energy balance (electrical + chemical + heat stored in the cells, the module FEM through
the ROM and the coolant + heat to the ambient and the chiller - pump work) closes over a UDDS
stretch with the cooling on, the cooling power is the vehicle's auxiliary load, the module
thermal model stores heat, and the kernel's compiled pack step equals the same pack stepped
from Python at the kernel's currents.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.thermal_helpers import COARSE_TOML

from hevsim.config import load_vehicle_config
from hevsim.cycles import DriveCycle, load_cycle

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"


@pytest.fixture(scope="module")
def rom_vehicle(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """examples/series_hev_pack.toml with its 50 thesis 2s6p modules on a coarse-mesh ROM."""
    pytest.importorskip("skfem")
    pytest.importorskip("gmsh")
    from hevsim.thermal.rom import BuildOptions, build_rom_from_config

    d = tmp_path_factory.mktemp("pack_vehicle_rom")
    (d / "module_coarse.toml").write_text(COARSE_TOML)
    rom, _ = build_rom_from_config(d / "module_coarse.toml", BuildOptions(tol_k=0.1))
    rom.save(d / "module.rom.npz")
    pack = (EX / "vehicle_pack.toml").read_text()
    edits = {
        '\nthermal = "coolant"': '\nthermal = "rom"',
        '\nthermal_config = "module_thermal.toml"': (
            '\nthermal_config = "module_coarse.toml"\nrom_file = "module.rom.npz"'
        ),
    }
    for old, new in edits.items():
        assert pack.count(old) == 1, old
        pack = pack.replace(old, new)
    (d / "vehicle_pack.toml").write_text(pack)
    (d / "series_hev_pack.toml").write_text((EX / "series_hev_pack.toml").read_text())
    return d / "series_hev_pack.toml"


def _udds(seconds: float) -> DriveCycle:
    c = load_cycle("udds")
    keep = np.asarray(c.time_s) <= seconds
    return DriveCycle(f"udds_{seconds:g}s", np.asarray(c.time_s)[keep], np.asarray(c.speed_mps)[keep],
                      np.asarray(c.grade)[keep])  # fmt: skip


def test_series_hev_with_module_roms_balances_and_equals_python_steps(rom_vehicle: Path) -> None:
    from hevsim.sim.pack_vehicle import make_pack_run, simulate_pack_vehicle

    cfg = load_vehicle_config(rom_vehicle)
    assert cfg.battery.model == "pack"
    res = simulate_pack_vehicle(cfg, _udds(400.0), 1.0)
    e: dict[str, Any] = res.extra["pack_energy"]
    assert e["throughput_j"] > 1e6
    assert abs(e["residual_relative"]) < 1e-3  # the bound
    assert abs(e["residual_relative"]) < 1e-9  # exact to rounding
    assert abs(e["delta_modules_j"]) > 1e3  # the module ROMs store heat (no ROM: 0)
    assert e["plate_heat_j"] != 0.0
    cooling = e["pump_work_j"] + e["chiller_electric_j"] + e["fan_electric_j"]
    assert cooling > 0.0
    assert res.energy_audit["aux"] == pytest.approx(cooling, rel=1e-9)
    assert abs(res.metrics["energy_audit_residual_pct"]["value"]) < 1e-6
    ts = res.timeseries
    assert "module49_hottest_cell_temp_k" in ts
    # the compiled step inside the kernel = the pack stepped from Python at the kernel's currents
    run = make_pack_run(cfg, 1.0, float(cfg.simulation.soc_initial))
    for i_a in ts["pack_current_a"].to_numpy()[:-1]:
        run.begin()
        run.finish_current(float(i_a))
    ref = run.frame(len(ts))
    for col in ref.columns:
        np.testing.assert_allclose(ts[col].to_numpy(), ref[col].to_numpy(), rtol=1e-9, atol=1e-9, err_msg=col)
    e_py = run.energy()
    for key in ("electrical_out_j", "plate_heat_j", "delta_modules_j", "chiller_j", "pump_work_j"):
        assert e[key] == pytest.approx(e_py[key], rel=1e-9, abs=1e-6), key

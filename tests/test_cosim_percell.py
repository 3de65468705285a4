"""Per-cell coupling of the module with the FEM module (issue 6, item 4): energy is
conserved cell by cell and the cells see different temperatures."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim.battery.kernel import STEMP
from hevsim.cosim.system import run_cosim

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_module_cells_port_heat_matches_module_total() -> None:
    from hevsim.cosim.participant import ModuleCellsParticipant

    bat = ModuleCellsParticipant("b", soc_initial=0.9, temp_initial_k=303.15, n_series=2, n_parallel=6)
    bat.setup(0.0)
    temps = np.linspace(290.0, 310.0, bat.n_cells)
    for k in range(5):
        bat.set_inputs({"current_a": 30.0 if k % 2 else -20.0})
        bat.set_inputs({f"cell{c}_port_temp_k": temps[c] for c in range(bat.n_cells)})
        bat.do_step(float(k), 1.0)
        out = bat.get_outputs()
        cells = np.array([out[f"cell{c}_port_heat_w"] for c in range(bat.n_cells)])
        assert cells.sum() == pytest.approx(out["port_heat_w"], rel=1e-12, abs=1e-12)
    # cooler ports draw more heat; cell temperatures follow their own ports
    assert cells[0] > cells[-1]
    t_cell = bat.stepper.m.state[:, STEMP]
    assert np.all(np.diff(t_cell) > 0)
    # state round trip keeps the per-cell outputs
    st = bat.get_state()
    bat.do_step(5.0, 1.0)
    bat.set_state(st)
    assert bat.get_outputs() == out


def test_per_cell_coupling_conserves_energy_and_cells_differ() -> None:
    """Each step: the heat each FEM cell receives is the heat the battery's cell put into its
    port (so their sums agree with the module's port heat), and the temperature each battery
    cell's port sees is its own FEM cell's temperature."""
    from hevsim.cosim.fem import FemModuleParticipant
    from hevsim.cosim.participant import ModuleCellsParticipant

    bat = ModuleCellsParticipant(
        "battery", soc_initial=0.9, temp_initial_k=303.15, n_series=2, n_parallel=6, power_input=True
    )
    fem = FemModuleParticipant("fem", EXAMPLES / "module_thermal.toml", mesh_size_m=0.008)
    bat.setup(0.0)
    fem.setup(0.0)
    n = bat.n_cells
    assert n == fem.n_cells
    out_f = fem.get_outputs()
    for k in range(12):
        power = 250.0 if k % 10 < 5 else -150.0
        ports = {f"cell{c}_port_temp_k": out_f[f"cell{c}_temp_k"] for c in range(n)}
        bat.set_inputs({"power_w": power, **ports})
        bat.do_step(float(k), 1.0)
        out_b = bat.get_outputs()
        sent = np.array([out_b[f"cell{c}_port_heat_w"] for c in range(n)])
        fem.set_inputs({f"cell{c}_heat_w": sent[c] for c in range(n)})
        fem.do_step(float(k), 1.0)
        received = np.asarray(fem.model.cell_heat_w)
        np.testing.assert_array_equal(received, sent)
        assert received.sum() == pytest.approx(out_b["port_heat_w"], rel=1e-12, abs=1e-12)
        out_f = fem.get_outputs()
    fem_t = np.array([out_f[f"cell{c}_temp_k"] for c in range(n)])
    assert np.ptp(fem_t) > 1e-3  # cells sit at different places on the cooling plate
    bat_t = bat.stepper.m.state[:, STEMP]
    assert np.ptp(bat_t) > 1e-5  # and the battery's cells follow their own ports
    assert np.ptp(sent) > 0.0


def test_shipped_module_case_is_per_cell(cosim_module_dir: Path, tmp_path: Path) -> None:
    import dataclasses

    from hevsim.cosim.ssd import read_ssd

    desc = read_ssd(cosim_module_dir / "module.ssd")  # the shipped SSD with its FMU built
    pairs = {(c.src, c.src_var, c.dst, c.dst_var) for c in desc.connections}
    for c in range(12):
        assert ("battery", f"cell{c}_port_heat_w", "fem", f"cell{c}_heat_w") in pairs
        assert ("fem", f"cell{c}_temp_k", "battery", f"cell{c}_port_temp_k") in pairs
    res = run_cosim(dataclasses.replace(desc, stop_time_s=5.0), tmp_path / "out")
    heats = np.array([res[f"battery.cell{c}_port_heat_w"] for c in range(12)])
    np.testing.assert_allclose(heats.sum(axis=0), res["battery.port_heat_w"], rtol=1e-9, atol=1e-9)
    temps = np.array([res[f"fem.cell{c}_temp_k"][-1] for c in range(12)])
    assert np.ptp(temps) > 1e-3

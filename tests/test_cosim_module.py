"""The thesis module co-simulation example (issue 6, item 4), short and on a coarse mesh."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from tests.cosim_helpers import interrupt_after

from hevsim.cosim.datacheck import datacheck
from hevsim.cosim.ssd import read_ssd
from hevsim.cosim.system import run_cosim, run_system

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "cosim_module"


def _example():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("run_module", EXAMPLE / "run_module.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_shipped_ssd_matches_script_and_checks() -> None:
    ex = _example()
    shipped = read_ssd(EXAMPLE / "module.ssd")
    built = ex.module_system()
    assert [c.parameters for c in shipped.components] == [c.parameters for c in built.components]
    assert shipped.connections == built.connections and shipped.master == built.master
    datacheck(shipped)


def test_shipped_fmu_is_current(tmp_path: Path) -> None:
    """The shipped module FMU is what ``export_module_fmu`` builds from today's code and data
    (model script with the embedded cell parameters, variables, units, capabilities)."""
    import zipfile

    from fmpy import read_model_description

    ex = _example()
    fresh = ex.export_module_fmu(tmp_path / "fresh.fmu")
    shipped = EXAMPLE / ex.FMU

    def script(path: Path) -> str:
        with zipfile.ZipFile(path) as z:
            return z.read("resources/HevsimModule2s6p.py").decode()

    assert script(shipped) == script(fresh), "re-run examples/cosim_module/run_module.py --write-shipped"

    def variables(path: Path) -> list[tuple[str, str, str | None]]:
        md = read_model_description(str(path))
        return [(v.name, v.causality, v.unit) for v in md.modelVariables]

    assert variables(shipped) == variables(fresh)
    assert read_model_description(str(shipped)).coSimulation.canGetAndSetFMUstate


def test_fmu_battery_is_a_drop_in_for_the_in_process_module(tmp_path: Path) -> None:
    ex = _example()
    fmu = run_system(ex.module_system(duration_s=6.0, mesh_size_m=0.008))
    inproc = run_system(ex.module_system(duration_s=6.0, mesh_size_m=0.008, battery="inprocess"))
    for c in range(12):
        np.testing.assert_allclose(fmu[f"fem.cell{c}_temp_k"], inproc[f"fem.cell{c}_temp_k"], rtol=1e-12)
    np.testing.assert_allclose(fmu["battery.voltage_v"], inproc["battery.voltage_v"], rtol=1e-12)
    np.testing.assert_allclose(
        fmu["battery.terminal_current_a"][1:], inproc["battery.current_a"][1:], rtol=1e-12
    )


def test_module_cosim_physics_and_resume(tmp_path: Path) -> None:
    ex = _example()
    desc = ex.module_system(duration_s=20.0, mesh_size_m=0.008)
    res = run_cosim(desc, tmp_path / "out")
    t_cell, t_out = res["fem.cell_mean_temp_k"], res["coolant.outlet_temp_k"]
    assert np.all(np.isfinite(res.data))
    assert t_cell[0] == pytest.approx(303.15)
    assert 288.15 < t_out[-1] < t_cell[-1]  # outlet between inlet (15 degC) and the cells
    assert res["coolant.cooling_power_w"][1] > 0  # the coolant takes heat from the 30 degC module
    assert res["fem.wall_heat_w"][-1] > 0  # heat leaves the plate through the channel wall
    v = res["battery.voltage_v"]
    assert v[1:].max() > v[1:].min() + 0.1  # the square power cycle shows in the voltage
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["error"] is None and summary["stats"]["steps"] == 20

    ck = tmp_path / "ck.pkl"
    desc.master["checkpoint_every"] = 1
    interrupt_after(lambda **kw: run_system(desc, **kw), 7.5, checkpoint_path=ck)
    resumed = run_system(desc, checkpoint_path=ck, resume=True)
    assert np.array_equal(resumed.data, res.data)


def test_module_pictures(tmp_path: Path) -> None:
    ex = _example()
    run_cosim(ex.module_system(duration_s=3.0, mesh_size_m=0.008), tmp_path / "out")
    made = sorted((tmp_path / "out" / "pictures").glob("*.png"))
    names = {p.name for p in made}
    assert {"battery_current_voltage.png", "coolant_coolant_outlet.png", "coolant_cooling_power.png",
            "fem_cell_temperature.png", "fem_plate_and_wall_heat.png", "fem_plate_temperature.png",
            "fem_cells_temperature.png", "fem_cells_section.png"} <= names, names  # fmt: skip
    assert all(p.read_bytes()[:4] == b"\x89PNG" and p.stat().st_size > 1000 for p in made)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    fem = summary["fields"]["fem"]
    assert (tmp_path / "out" / fem["pvd"]).is_file() and len(fem["hot_spots"]) == 10
    spots = [h["temp_c"] for h in fem["hot_spots"]]
    assert spots == sorted(spots, reverse=True)
    assert fem["plate_min_temp_c"] < fem["plate_max_temp_c"] < spots[0]  # the plate is cooled


def test_module_cosim_agrees_with_monolithic_solve(tmp_path: Path) -> None:
    """Gauss-Seidel co-simulation vs a strongly coupled in-process solve (per step, the cell
    and FEM models are iterated to a consistent port temperature) of the same module."""
    from hevsim.cosim.fem import FemModuleParticipant
    from hevsim.cosim.library import power_cycle
    from hevsim.cosim.participant import ModuleCellsParticipant

    ex = _example()
    duration, mesh = 20.0, 0.008
    cosim = run_cosim(ex.module_system(duration_s=duration, mesh_size_m=mesh), tmp_path / "out")

    params = {p.name: p.parameters for p in ex.module_system().components}
    load = power_cycle("load", **params["load"])
    bat = ModuleCellsParticipant("battery", **ex.BATTERY, power_input=True)
    fem = FemModuleParticipant("fem", EXAMPLE.parent / "module_thermal.toml", mesh_size_m=mesh)
    for p in (load, bat, fem):
        p.setup(0.0)
    n = bat.n_cells

    def cell_temps() -> np.ndarray:
        out = fem.get_outputs()
        return np.array([out[f"cell{c}_temp_k"] for c in range(n)])

    temps, t = [cell_temps()], 0.0
    port = temps[0]
    for _ in range(int(duration)):
        load.do_step(t, 1.0)
        power = load.get_outputs()["power_w"]
        sb, sf = bat.get_state(), fem.get_state()
        for _it in range(30):
            bat.set_state(sb)
            fem.set_state(sf)
            bat.set_inputs({"power_w": power, **{f"cell{c}_port_temp_k": port[c] for c in range(n)}})
            bat.do_step(t, 1.0)
            out = bat.get_outputs()
            fem.set_inputs({f"cell{c}_heat_w": out[f"cell{c}_port_heat_w"] for c in range(n)})
            fem.do_step(t, 1.0)
            new = cell_temps()
            if np.abs(new - port).max() < 1e-10:
                break
            port = new
        t += 1.0
        temps.append(cell_temps())
    mono = np.array(temps)
    co = np.array([cosim[f"fem.cell{c}_temp_k"] for c in range(n)]).T
    rise = mono - mono[0]
    err = np.abs(co - mono).max()
    assert err < 0.02 * np.abs(rise).max() + 1e-3, (err, np.abs(rise).max())

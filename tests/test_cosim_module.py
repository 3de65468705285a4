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


def _example(folder: Path = EXAMPLE):  # type: ignore[no-untyped-def]
    """``run_module.py`` of ``folder`` (its systems' relative paths start from ``folder``)."""
    spec = importlib.util.spec_from_file_location(f"run_module_{abs(hash(folder))}", folder / "run_module.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_shipped_ssd_matches_script_and_checks(cosim_module_dir: Path) -> None:
    ex = _example()
    shipped = read_ssd(EXAMPLE / "module.ssd")
    built = ex.module_system()
    assert [c.parameters for c in shipped.components] == [c.parameters for c in built.components]
    assert [(c.name, c.type, c.source) for c in shipped.components] == [
        (c.name, c.type, c.source) for c in built.components
    ]
    assert shipped.connections == built.connections and shipped.master == built.master
    datacheck(read_ssd(cosim_module_dir / "module.ssd"))  # with the FMU built in the copy


def test_module_fmu_is_built_native_and_rebuilt_only_when_stale(
    cosim_module_dir: Path, tmp_path: Path
) -> None:
    """The FMU is not in git; the example builds the native FMU (no Python inside) when it is
    missing or stale and leaves a current one alone."""
    import shutil
    import subprocess

    from fmpy import read_model_description

    from hevsim.battery.native import is_native_fmu

    assert "examples/cosim_module/module_2s6p.fmu" in (EXAMPLE.parents[1] / ".gitignore").read_text()
    tracked = subprocess.run(["git", "ls-files", "examples/cosim_module"], cwd=EXAMPLE.parents[1],
                             capture_output=True, text=True, check=False)  # fmt: skip
    if tracked.returncode == 0:  # a git checkout
        assert not [f for f in tracked.stdout.split() if f.endswith(".fmu")], tracked.stdout
    ex = _example(cosim_module_dir)
    fmu = cosim_module_dir / ex.FMU
    assert is_native_fmu(fmu)
    md = read_model_description(str(fmu))
    assert md.coSimulation.modelIdentifier == "HevsimModule2s6p" and md.coSimulation.canGetAndSetFMUstate
    names = {v.name for v in md.modelVariables}
    assert {"power_w", "power_input", "per_cell_ports", "cell11_port_temp_k", "cell11_port_heat_w"} <= names

    shutil.copytree(cosim_module_dir, tmp_path / "ex")
    ex2 = _example(tmp_path / "ex")
    before = (tmp_path / "ex" / ex.FMU).read_bytes()
    assert ex2.build_fmu() == (tmp_path / "ex" / ex.FMU, False)  # current: kept as it is
    assert (tmp_path / "ex" / ex.FMU).read_bytes() == before
    (tmp_path / "ex" / ex.FMU).write_bytes(b"PK\x03\x04 not an fmu")  # stale / broken: rebuilt
    assert ex2.build_fmu()[1] and ex2.fmu_guid(tmp_path / "ex" / ex.FMU) == md.guid


def test_cosim_without_the_built_fmu_says_how_to_build_it(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    import shutil

    from hevsim.cli import main

    shutil.copytree(EXAMPLE, tmp_path / "cosim_module", ignore=shutil.ignore_patterns("*.fmu"))
    shutil.copy(EXAMPLE.parent / "module_thermal.toml", tmp_path / "module_thermal.toml")
    assert main(["cosim", str(tmp_path / "cosim_module" / "module.ssd"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "module_2s6p.fmu" in err and "does not exist" in err and "make examples" in err, err
    assert "run_module.py --build-fmu" in err
    assert not (tmp_path / "out").exists()


def test_fmu_battery_is_a_drop_in_for_the_in_process_module(cosim_module_dir: Path) -> None:
    """The native module FMU (worker process and in process) vs hevsim's in-process module."""
    ex = _example(cosim_module_dir)
    fmu = run_system(ex.module_system(duration_s=6.0, mesh_size_m=0.008))
    inproc = run_system(ex.module_system(duration_s=6.0, mesh_size_m=0.008, battery="inprocess"))
    desc = ex.module_system(duration_s=6.0, mesh_size_m=0.008)
    desc.master["fmu_process"] = "inprocess"  # the C FMU loaded into this process
    assert np.array_equal(run_system(desc).data, fmu.data)
    for c in range(12):
        np.testing.assert_allclose(fmu[f"fem.cell{c}_temp_k"], inproc[f"fem.cell{c}_temp_k"], rtol=1e-12)
    np.testing.assert_allclose(fmu["battery.voltage_v"], inproc["battery.voltage_v"], rtol=1e-12)
    np.testing.assert_allclose(
        fmu["battery.terminal_current_a"][1:], inproc["battery.current_a"][1:], rtol=1e-12
    )


def test_module_cosim_physics_and_resume(cosim_module_dir: Path, tmp_path: Path) -> None:
    ex = _example(cosim_module_dir)
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


def test_module_pictures(cosim_module_dir: Path, tmp_path: Path) -> None:
    ex = _example(cosim_module_dir)
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


def test_module_cosim_agrees_with_monolithic_solve(cosim_module_dir: Path, tmp_path: Path) -> None:
    """Gauss-Seidel co-simulation vs a strongly coupled in-process solve (per step, the cell
    and FEM models are iterated to a consistent port temperature) of the same module."""
    from hevsim.cosim.fem import FemModuleParticipant
    from hevsim.cosim.library import power_cycle
    from hevsim.cosim.participant import ModuleCellsParticipant

    ex = _example(cosim_module_dir)
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

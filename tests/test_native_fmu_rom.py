"""Native (compiled C99) FMU of the module thermal ROM (issue 16 item 3).

The FMU, exported by ``hevsim export-fmu ROM.npz``, equals the ROM stepped in Python
(:class:`hevsim.thermal.rom.RomStepper`) to 1e-12 per output and step over the three validation
loads of the ROM (square-wave heat, coolant step, US06-like heat; each coupled to the 1-D coolant
channel as :func:`hevsim.thermal.rom.compare_with_fem` does), FMI 2.0 and 3.0; FMPy validates it,
its binary needs no libpython, its state round-trips bit for bit, its sources compile with
strict warnings, it refuses a wall film outside the ROM's range, and libcosim runs it.
On the coarse test mesh (the default mesh is in ``benchmarks/bench_native_fmu.py``).
"""

from __future__ import annotations

import copy
import json
import subprocess
import sys
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("skfem")
pytest.importorskip("gmsh")

from tests.test_native_fmu import CC, COMPILERS, TOL, Runner, compile_strict
from tests.thermal_helpers import COARSE_TOML

from hevsim.battery.native import native_binary
from hevsim.cli import main
from hevsim.thermal.rom import RomStepper, ThermalRom, load_rom, validation_loads
from hevsim.thermal.run import KELVIN, load_thermal_config, module_model

pytestmark = pytest.mark.skipif(not CC, reason="no C compiler")
ROOT = Path(__file__).resolve().parents[1]
VERSIONS = (2, 3)


@pytest.fixture(scope="module")
def case(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The coarse module ROM, its FMI 2.0 and 3.0 FMUs (exported by the command line, the
    default native path) and the configured coolant channel."""
    from hevsim.thermal.geometry import build_module_mesh

    d = tmp_path_factory.mktemp("romfmu")
    toml = d / "module_coarse.toml"
    toml.write_text(COARSE_TOML)
    rom_path = d / "module.rom.npz"
    assert main(["rom", "build", str(toml), "-o", str(rom_path)]) == 0
    fmus = {}
    for v in VERSIONS:
        fmus[v] = d / f"rom_{v}.fmu"
        assert main(["export-fmu", str(rom_path), "-o", str(fmus[v]), "--fmi-version", str(v)]) == 0
    cfg = load_thermal_config(toml)
    _, channel, _ = module_model(cfg, build_module_mesh(cfg.geometry))
    return {"rom": load_rom(rom_path), "rom_path": rom_path, "fmus": fmus, "cfg": cfg, "channel": channel}


def names(rom: ThermalRom) -> dict[str, list[str]]:
    nc, ns = rom.n_cells, rom.n_segments
    return {
        "heat": [f"cell{c}_heat_w" for c in range(nc)],
        "fluid": [f"segment{s}_fluid_temp_k" for s in range(ns)],
        "out": [f"cell{c}_mean_temp_k" for c in range(nc)]
        + [f"cell{c}_max_temp_k" for c in range(nc)]
        + [f"segment{s}_wall_temp_k" for s in range(ns)]
        + [f"segment{s}_wall_heat_w" for s in range(ns)]
        + ["ambient_heat_w", "stored_heat_j"],
    }


def rom_outputs(
    rom: ThermalRom, z: np.ndarray, fluid_k: np.ndarray, ambient_k: float, h: float
) -> np.ndarray:
    """The FMU's outputs (:func:`names` order) from the Python ROM."""
    return np.concatenate(
        [
            rom.cell_mean_k(z),
            rom.cell_max_k(z),
            rom.wall_temp_k(z),
            rom.wall_heat_w(z, fluid_k, h),
            [rom.ambient_heat_w(z, ambient_k), rom.stored_j(z)],
        ]
    )


def cosim(
    case: dict[str, Any], fmu: Path, heat_w: Callable[[float], np.ndarray], inlet_k: Callable[[float], float],
    steps: int, dt: float = 1.0, wall_h: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The FMU and the Python ROM each coupled to its own copy of the coolant channel (fluid
    temperatures from the wall temperatures at the start of the step, as compare_with_fem):
    per step the outputs of both, (steps, n_out) each."""
    rom: ThermalRom = case["rom"]
    n = names(rom)
    h = rom.wall_h_range_w_m2k[1] if wall_h is None else wall_h
    amb = float(rom.metadata["ambient_k"])
    t0 = float(rom.metadata["initial_temp_k"])
    ch_fmu, ch_py = copy.deepcopy(case["channel"]), copy.deepcopy(case["channel"])
    ch_fmu.h_w_m2k = ch_py.h_w_m2k = h
    r = Runner(fmu, params={"wall_h_w_m2k": h})
    st = RomStepper(rom, dt, h, t0)
    wall_vr = [f"segment{s}_wall_temp_k" for s in range(rom.n_segments)]
    wall_fmu = np.array(r.get(wall_vr))
    got, ref = np.empty((steps, len(n["out"]))), np.empty((steps, len(n["out"])))
    for k in range(steps):
        t = (k + 1) * dt
        q = np.asarray(heat_w(t), float)
        ch_fmu.inlet_temp_k = ch_py.inlet_temp_k = inlet_k(t)
        fluid_fmu = ch_fmu.fluid_temperature_k(wall_fmu, rom.wall_area_m2)
        fluid_py = ch_py.fluid_temperature_k(rom.wall_temp_k(st.z[0]), rom.wall_area_m2)
        for name, value in zip(
            n["heat"] + n["fluid"] + ["ambient_temp_k"], [*q, *fluid_fmu, amb], strict=True
        ):
            r.set(name, value)
        r.step(dt)
        got[k] = r.get(n["out"])
        wall_fmu = got[k, 2 * rom.n_cells : 2 * rom.n_cells + rom.n_segments]
        st.step(q[None, :], fluid_py[None, :], amb)
        ref[k] = rom_outputs(rom, st.z[0], fluid_py, amb, h)
    r.close()
    return got, ref


def assert_per_output(got: np.ndarray, ref: np.ndarray, tol: float, what: str) -> None:
    """|FMU - Python| <= tol x max(1, max |output|) for every output column, every step."""
    scale = np.maximum(1.0, np.abs(ref).max(axis=0))
    err = np.abs(got - ref) / scale
    worst = int(np.argmax(err.max(axis=0)))
    assert err.max() <= tol, f"{what}: output {worst}: relative error {err.max():.3g} > {tol:g}"


def square_heat(t: float) -> np.ndarray:
    return np.linspace(0.8, 1.2, 12) * (2.0 if (t % 10.0) < 5.0 else 0.8)


def us06_heat() -> Callable[[float], np.ndarray]:
    """Per-cell heat of the thesis 2s6p module (3 % / 5 % spread) under 6x the US06 road-load
    cell current (as benchmarks/bench_rom.py's load (c)), 600 s."""
    from hevsim.battery.module import Module
    from hevsim.battery.profiles import cycle_cell_current

    current = 6.0 * cycle_cell_current("us06", duration_s=600, dt_s=1.0)
    mod = Module("thesis_table_4_1", 2, 6, soc_initial=0.95, temp_k=303.15, capacity_spread=0.03,
                 resistance_spread=0.05, seed=2)  # fmt: skip
    heat = np.asarray(mod.simulate(current, 1.0, port_temperature=303.15).cells[:, :, 3])
    return lambda t: heat[round(t) - 1]


LOADS: dict[str, tuple[Callable[[], Callable[[float], np.ndarray]], Callable[[float], float], int]] = {
    "square_wave_heat": (lambda: square_heat, lambda t: 15.0 + KELVIN, 300),
    "coolant_step": (lambda: lambda t: np.ones(12), lambda t: KELVIN + (15.0 if t < 100.0 else 25.0), 300),
    "us06_heat": (us06_heat, lambda t: 15.0 + KELVIN, 600),
    # issue 26: heat of both signs moving the hot spot inside the cells (the FMU's screened
    # all-nodes hot spot, single precision then double, against every row in Python)
    "multisine_moving_hot_spot": (lambda: validation_loads(12)["multisine"][0], lambda t: 15.0 + KELVIN, 300),
}


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("load", sorted(LOADS))
def test_rom_fmu_equals_python_rom_over_validation_loads(
    case: dict[str, Any], load: str, version: int
) -> None:
    heat, inlet, steps = LOADS[load]
    got, ref = cosim(case, case["fmus"][version], heat(), inlet, steps)
    assert ref[:, :12].max() - ref[0, :12].min() > 0.5 or load in (
        "coolant_step",
        "multisine_moving_hot_spot",
    )
    assert_per_output(got, ref, TOL, f"{load} FMI {version}")


@pytest.mark.parametrize("version", VERSIONS)
def test_other_step_and_wall_film_are_computed_by_the_fmu(case: dict[str, Any], version: int) -> None:
    """A communication step and a wall film other than the export's: the FMU computes its step
    matrix itself (LU); it equals numpy's inverse to its rounding (1e-10 relative: the two
    inverses of I/dt + K(h) differ by cond x eps)."""
    rom: ThermalRom = case["rom"]
    h = 0.5 * sum(rom.wall_h_range_w_m2k)
    got, ref = cosim(case, case["fmus"][version], square_heat, lambda t: 15.0 + KELVIN, 150, dt=2.0, wall_h=h)
    assert_per_output(got, ref, 1e-10, "dt 2 s")
    assert ref[-1, 0] - ref[0, 0] > 0.5


def test_rom_fmu_passes_validation_and_needs_no_python(case: dict[str, Any], tmp_path: Path) -> None:
    from fmpy import read_model_description
    from fmpy.model_description import read_build_description
    from fmpy.validation import validate_fmu

    rom: ThermalRom = case["rom"]
    for v, fmu in case["fmus"].items():
        assert validate_fmu(str(fmu)) == [], fmu
        (config,) = read_build_description(str(fmu), validate=True)
        assert config.sourceFileSets[0].sourceFiles == [f"fmi{v}_model.c"]
        with zipfile.ZipFile(fmu) as z:
            assert {"sources/model_data.h", "sources/hevsim_rom.h", "sources/hevsim_fmi.h"} <= set(
                z.namelist()
            )
        md = read_model_description(str(fmu))
        var = {x.name: x for x in md.modelVariables}
        assert var["cell0_heat_w"].causality == "input" and var["cell0_heat_w"].unit == "W"
        assert var["cell11_max_temp_k"].causality == "output" and var["cell11_max_temp_k"].unit == "K"
        assert var["wall_h_w_m2k"].causality == "parameter" and var["wall_h_w_m2k"].unit == "W/(m2.K)"
        assert float(var["rom_order"].start) == rom.order
        assert f"segment{rom.n_segments - 1}_wall_heat_w" in var
        assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
        name, data = native_binary(fmu)
        lib = tmp_path / Path(name).name
        lib.write_bytes(data)
        dyn = subprocess.run(["readelf", "-d", str(lib)], capture_output=True, text=True, check=True).stdout
        needed = [line for line in dyn.splitlines() if "(NEEDED)" in line]
        assert needed and not any("python" in line.lower() for line in needed), needed


@pytest.mark.parametrize("version", VERSIONS)
def test_rom_fmu_state_round_trip_is_bit_identical(case: dict[str, Any], version: int) -> None:
    n = names(case["rom"])
    heat = {name: np.linspace(0.5, 3.0, 60) for name in n["heat"]}
    r = Runner(case["fmus"][version])
    r.run({k: v[:20] for k, v in heat.items()}, 1.0, n["out"])
    state = r.get_state()
    blob = r.serialize(state)
    t0 = r.t
    first = r.run({k: v[20:] for k, v in heat.items()}, 1.0, n["out"])
    r.set_state(state)
    r.t = t0
    np.testing.assert_array_equal(r.run({k: v[20:] for k, v in heat.items()}, 1.0, n["out"]), first)
    r2 = Runner(case["fmus"][version])
    r2.set_state(r2.deserialize(blob))
    r2.t = t0
    np.testing.assert_array_equal(r2.run({k: v[20:] for k, v in heat.items()}, 1.0, n["out"]), first)
    r.free_state(state)
    r.close()
    r2.close()


@pytest.mark.parametrize("cc", COMPILERS)
@pytest.mark.parametrize("version", VERSIONS)
def test_rom_fmu_sources_compile_with_strict_warnings(
    case: dict[str, Any], tmp_path: Path, version: int, cc: str
) -> None:
    compile_strict(case["fmus"][version], version, tmp_path, cc)


@pytest.mark.parametrize("version", VERSIONS)
def test_rom_fmu_refuses_a_wall_film_outside_its_range(case: dict[str, Any], version: int) -> None:
    from fmpy.fmi1 import FMICallException

    rom: ThermalRom = case["rom"]
    r = Runner(case["fmus"][version])
    bad = 2.0 * rom.wall_h_range_w_m2k[1]
    with pytest.raises(FMICallException):
        r.set("wall_h_w_m2k", bad)
    assert any("wall_h_w_m2k = " in m and "outside its range" in m for m in r.messages), r.messages
    with pytest.raises(FMICallException):
        r.set("segment0_fluid_temp_k", -3.0)
    with pytest.raises(FMICallException):
        r.set("cell0_mean_temp_k", 300.0)
    assert any("'cell0_mean_temp_k'" in m and "output" in m for m in r.messages), r.messages
    r.close()


def test_pythonfmu_rom_is_refused(
    case: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "x.fmu"
    assert main(["export-fmu", str(case["rom_path"]), "-o", str(out), "--pythonfmu"]) == 2
    assert "native only" in capsys.readouterr().err and not out.exists()


LIBCOSIM_ROM = """
import json, sys
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimManipulator import CosimManipulator
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimSlave import CosimLocalSlave

log_output_level(CosimLogLevel.ERROR)
req = json.load(sys.stdin)
ex = CosimExecution.from_step_size(step_size=int(1e9))
idx = ex.add_local_slave(local_slave=CosimLocalSlave(fmu_path=req["fmu"], instance_name="rom"))
vr = {v.name.decode(): v.reference for v in ex.slave_variables(idx)}
man = CosimManipulator.create_override()
ex.add_manipulator(manipulator=man)
obs = CosimObserver.create_last_value()
ex.add_observer(observer=obs)
out = []
for q in req["heat_w"]:
    man.slave_real_values(idx, [vr[n] for n in req["heat_names"]], q)
    ex.step()
    out.append(obs.last_real_values(idx, [vr[n] for n in req["outputs"]]))
print(json.dumps(out))
"""


def test_libcosim_runs_the_rom_fmu(case: dict[str, Any]) -> None:
    """libcosim (C++ FMI host) steps the FMI 2.0 ROM FMU to the Python ROM's results."""
    pytest.importorskip("libcosimpy")
    rom: ThermalRom = case["rom"]
    n = names(rom)
    heat = [square_heat(k + 1.0).tolist() for k in range(120)]
    req = {"fmu": str(case["fmus"][2]), "heat_w": heat, "heat_names": n["heat"], "outputs": n["out"]}
    proc = subprocess.run([sys.executable, "-c", LIBCOSIM_ROM], input=json.dumps(req), capture_output=True,
                          text=True, timeout=120, check=False)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = np.array(json.loads(proc.stdout.strip().splitlines()[-1]))
    h, amb = rom.wall_h_range_w_m2k[1], float(rom.metadata["ambient_k"])
    fluid = np.full(rom.n_segments, float(rom.metadata["inlet_temp_k"]))
    st = RomStepper(rom, 1.0, h, float(rom.metadata["initial_temp_k"]))
    ref = np.array([rom_outputs(rom, st.step(np.array(q)[None, :], fluid[None, :], amb)[0], fluid, amb, h)
                    for q in heat])  # fmt: skip
    assert_per_output(got, ref, TOL, "libcosim")


HOST_SCRIPT = """
import sys
from fmpy import simulate_fmu

for path in sys.argv[1:]:
    res = simulate_fmu(path, stop_time=5.0, output_interval=1.0, fmi_type="CoSimulation")
    print(path, len(res), res[res.dtype.names[1]][-1])
"""


def test_default_exported_fmus_survive_fresh_fmpy_hosts(case: dict[str, Any], tmp_path: Path) -> None:
    """Issue 13 item 8 for the default export: the cell, module and ROM FMUs (``hevsim
    export-fmu`` without options: native FMI 2.0) each loaded, run, freed and unloaded by FMPy
    (``simulate_fmu``: ``freeInstance`` and ``dlclose``) in 5 fresh host processes: no aborts (they
    carry no interpreter, so none of the pythonfmu exit fault of tests/test_fmu_host_exit.py)."""
    from hevsim.battery.native import is_native_fmu

    fmus = []
    for example in ("cell", "module"):
        out = tmp_path / f"{example}.fmu"
        assert main(["export-fmu", str(ROOT / "examples" / f"{example}.toml"), "-o", str(out)]) == 0
        fmus.append(str(out))
    fmus.append(str(case["fmus"][2]))
    assert all(is_native_fmu(f) for f in fmus)
    for k in range(5):
        proc = subprocess.run([sys.executable, "-c", HOST_SCRIPT, *fmus], capture_output=True, text=True,
                              timeout=120, check=False)  # fmt: skip
        assert proc.returncode == 0, (k, proc.returncode, proc.stderr[-2000:])
        assert len(proc.stdout.splitlines()) == 3, proc.stdout
        assert "corrupted" not in proc.stderr and "Abort" not in proc.stderr, proc.stderr


def test_bad_rom_file_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A missing or foreign ``.npz`` is refused before any compilation, naming the file."""
    missing = tmp_path / "missing.rom.npz"
    assert main(["export-fmu", str(missing), "-o", str(tmp_path / "a.fmu")]) == 2
    assert "missing.rom.npz" in capsys.readouterr().err
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, x=np.ones(3))
    assert main(["export-fmu", str(foreign), "-o", str(tmp_path / "b.fmu")]) == 2
    err = capsys.readouterr().err
    assert "foreign.npz" in err and "not a hevsim thermal ROM" in err, err
    assert not (tmp_path / "a.fmu").exists() and not (tmp_path / "b.fmu").exists()


@pytest.mark.parametrize("version", VERSIONS)
def test_initial_temperature_parameter_sets_a_uniform_field(case: dict[str, Any], version: int) -> None:
    rom: ThermalRom = case["rom"]
    n = names(rom)
    r = Runner(case["fmus"][version], params={"initial_temp_k": 310.0})
    got = np.array(r.get(n["out"]))
    r.close()
    z0 = rom.state_of_uniform(310.0)
    amb = float(rom.metadata["ambient_k"])
    fluid = np.full(rom.n_segments, float(rom.metadata["inlet_temp_k"]))
    ref = rom_outputs(rom, z0, fluid, amb, rom.wall_h_range_w_m2k[1])
    assert_per_output(got[None, :], ref[None, :], TOL, "initial state")
    np.testing.assert_allclose(got[: 2 * rom.n_cells], 310.0, rtol=1e-12)

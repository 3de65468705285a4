"""Native (compiled C99) FMUs of the cell and the module (issue 16): FMPy validates them, they
need no libpython, they equal the in-process model to 1e-12 per output and step over the
shipped load profiles for every shipped cell parameter set, their state round-trips bit for
bit, their sources compile with strict warnings, they refuse bad values with a logger message
and run in fresh host processes and in libcosim (a C++ FMI host)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hevsim.battery import Cell, Module
from hevsim.battery import kernel as K
from hevsim.battery.ageing import soh_of_state
from hevsim.battery.fmu import CellStepper, ModuleStepper, current_for_power
from hevsim.battery.params import load_cell_parameters, shipped_cells
from hevsim.battery.profiles import cycle_cell_current
from hevsim.cli import main

pytest.importorskip("fmpy")
CC = shutil.which("cc") or shutil.which("gcc") or ""
pytestmark = pytest.mark.skipif(not CC, reason="no C compiler")

from hevsim.battery.native import NativeFMUError, export_native_fmu, native_binary  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TOL = 1e-12
CELL_OUTPUTS = ("voltage_v", "soc", "temp_k", "port_heat_w", "soh", "terminal_current_a")


class Runner:
    """An FMI 2.0 or 3.0 native FMU instance stepped through FMPy's low-level calls, with the
    messages of its logger collected."""

    def __init__(
        self, fmu: Path, params: dict[str, float] | None = None, booleans: dict[str, bool] | None = None
    ) -> None:
        from fmpy import extract, read_model_description

        self.md = read_model_description(str(fmu))
        self.v3 = self.md.fmiVersion.startswith("3")
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.messages: list[str] = []
        kw = {
            "guid": self.md.guid,
            "unzipDirectory": extract(str(fmu)),
            "modelIdentifier": self.md.coSimulation.modelIdentifier,
            "instanceName": "native",
        }
        self.slave: Any
        if self.v3:
            from fmpy.fmi3 import FMU3Slave

            def log3(env: Any, status: int, category: Any, message: bytes) -> None:
                self.messages.append(message.decode())

            self.slave = FMU3Slave(**kw)
            self.slave.instantiate(logMessage=log3)
            self.slave.enterInitializationMode(startTime=0.0)
            self._set, self._get, self._set_bool = (
                self.slave.setFloat64,
                self.slave.getFloat64,
                self.slave.setBoolean,
            )
        else:
            from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

            def log2(env: Any, name: Any, status: int, category: Any, message: bytes) -> None:
                self.messages.append(message.decode())

            self.callbacks = fmi2CallbackFunctions()
            self.callbacks.logger = fmi2CallbackLoggerTYPE(log2)
            self.slave = FMU2Slave(**kw)
            self.slave.instantiate(callbacks=self.callbacks)
            self.slave.setupExperiment(startTime=0.0)
            self.slave.enterInitializationMode()
            self._set, self._get, self._set_bool = (
                self.slave.setReal,
                self.slave.getReal,
                self.slave.setBoolean,
            )
        for name, value in (params or {}).items():
            self.set(name, value)
        for name, flag in (booleans or {}).items():
            self._set_bool([self.vr[name]], [flag])
        self.slave.exitInitializationMode()
        self.t = 0.0

    def set(self, name: str, value: float) -> None:
        self._set([self.vr[name]], [float(value)])

    def get(self, names: tuple[str, ...] | list[str]) -> list[float]:
        return list(self._get([self.vr[n] for n in names]))

    def step(self, dt: float) -> None:
        self.slave.doStep(self.t, dt)
        self.t += dt

    def run(self, inputs: dict[str, Any], dt: float, outputs: tuple[str, ...] | list[str]) -> np.ndarray:
        n = len(next(iter(inputs.values())))
        refs = [self.vr[k] for k in inputs]
        cols = np.column_stack([np.broadcast_to(np.asarray(v, float), (n,)) for v in inputs.values()])
        out = np.empty((n, len(outputs)))
        for k in range(n):
            self._set(refs, cols[k].tolist())
            self.step(dt)
            out[k] = self.get(outputs)
        return out

    def get_state(self) -> Any:
        return self.slave.getFMUState() if self.v3 else self.slave.getFMUstate()

    def set_state(self, state: Any) -> None:
        (self.slave.setFMUState if self.v3 else self.slave.setFMUstate)(state)

    def free_state(self, state: Any) -> None:
        (self.slave.freeFMUState if self.v3 else self.slave.freeFMUstate)(state)

    def serialize(self, state: Any) -> bytes:
        return bytes(self.slave.serializeFMUState(state) if self.v3 else self.slave.serializeFMUstate(state))

    def deserialize(self, blob: bytes) -> Any:
        return self.slave.deserializeFMUState(blob) if self.v3 else self.slave.deSerializeFMUstate(blob)

    def close(self) -> None:
        self.slave.terminate()
        self.slave.freeInstance()


VERSIONS = (2, 3)


@pytest.fixture(scope="module")
def cell_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, int], Path]:
    """Native FMI 2.0 and 3.0 cell FMUs of every shipped parameter set (start SOC 0.9, 298.15 K)."""
    folder = tmp_path_factory.mktemp("native")
    return {
        (name, v): export_native_fmu(name, folder / f"{name}_{v}.fmu", 0.9, 298.15, fmi_version=v)
        for name in shipped_cells()
        for v in VERSIONS
    }


def _cli_export(folder: Path, example: str) -> dict[int, Path]:
    out = {}
    for v in VERSIONS:
        out[v] = folder / f"{example}_{v}.fmu"
        args = ["export-fmu", str(ROOT / "examples" / f"{example}.toml"), "-o", str(out[v])]
        assert main([*args, "--fmi-version", str(v)]) == 0
    return out


@pytest.fixture(scope="module")
def cli_cell_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """examples/cell.toml exported by the command line, FMI 2.0 and 3.0."""
    return _cli_export(tmp_path_factory.mktemp("cli"), "cell")


@pytest.fixture(scope="module")
def module_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """examples/module.toml (2s6p with spread) exported by the command line, FMI 2.0 and 3.0."""
    return _cli_export(tmp_path_factory.mktemp("cli"), "module")


@pytest.fixture(scope="module")
def cli_cell_fmu(cli_cell_fmus: dict[int, Path]) -> Path:
    return cli_cell_fmus[2]


@pytest.fixture(scope="module")
def module_fmu(module_fmus: dict[int, Path]) -> Path:
    return module_fmus[2]


def load_profiles(c0_c: float) -> Iterator[tuple[str, np.ndarray, float]]:
    """The shipped load profiles as cell currents [A] for a cell of capacity ``c0_c`` [C]:
    drive-cycle road-load currents (scaled from the pack's 7 A h cell by capacity, x3 for a
    hard drive: up to 9 C) and the shipped calibration pulse test (of the 0.8 A h cell)."""
    scale = 3.0 * c0_c / 25326.0
    for cycle, seconds in (("udds", 1369.0), ("us06", 600.0), ("hwfet", 765.0)):
        yield cycle, scale * cycle_cell_current(cycle, seconds, 1.0), 1.0
    pulse = np.genfromtxt(ROOT / "examples" / "calibration_pulse.csv", delimiter=",", names=True)
    yield "calibration_pulse", c0_c / 2880.0 * np.asarray(pulse["current_a"], float), 1.0


def assert_close(got: np.ndarray, ref: np.ndarray, what: str) -> None:
    scale = max(1.0, float(np.max(np.abs(ref))))
    err = float(np.max(np.abs(got - ref)))
    assert err <= TOL * scale, f"{what}: max |native - in-process| = {err:.3g} > {TOL} x {scale:g}"


def test_fmus_pass_fmpy_validation(
    cell_fmus: dict[tuple[str, int], Path], module_fmus: dict[int, Path], cli_cell_fmus: dict[int, Path]
) -> None:
    from fmpy import read_model_description
    from fmpy.model_description import read_build_description
    from fmpy.validation import validate_fmu

    for fmu in [*cell_fmus.values(), *module_fmus.values(), *cli_cell_fmus.values()]:
        assert validate_fmu(str(fmu)) == [], fmu
        cs = read_model_description(str(fmu)).coSimulation  # FMI 3.0: canGetAndSetFMUState (capital S)
        assert cs.canGetAndSetFMUstate and cs.canSerializeFMUstate, fmu
        (config,) = read_build_description(str(fmu), validate=True)
        version = 3 if fmu.stem.endswith("_3") else 2
        assert config.sourceFileSets[0].sourceFiles == [f"fmi{version}_model.c"]
        with zipfile.ZipFile(fmu) as z:
            names = set(z.namelist())
        assert {"sources/model_data.h", "sources/hevsim_kernel.h", "sources/hevsim_model.h"} <= names


def test_binary_needs_no_python(
    module_fmus: dict[int, Path], cli_cell_fmus: dict[int, Path], tmp_path: Path
) -> None:
    for fmu in (*cli_cell_fmus.values(), *module_fmus.values()):
        name, data = native_binary(fmu)
        lib = tmp_path / Path(name).name
        lib.write_bytes(data)
        dyn = subprocess.run(["readelf", "-d", str(lib)], capture_output=True, text=True, check=True).stdout
        needed = [line for line in dyn.splitlines() if "(NEEDED)" in line]
        assert needed, dyn
        assert not any("python" in line.lower() for line in needed), needed
        ldd = subprocess.run(["ldd", str(lib)], capture_output=True, text=True, check=False).stdout
        assert "python" not in ldd.lower(), ldd


def test_same_interface_as_pythonfmu_fmu(cli_cell_fmu: Path, module_fmu: Path) -> None:
    """The pythonfmu FMU's variables with their value references, causality, variability,
    initial, units and start values, and its capabilities; plus two constants."""
    from fmpy import read_model_description

    from hevsim.battery.fmu import export_fmu

    for fmu, kw in (
        (cli_cell_fmu, {"params": "thesis_table_4_1", "soc_initial": 1.0, "temp_initial_k": 296.15}),
        (
            module_fmu,
            {
                "params": "saft_li_ion_6ah",
                "soc_initial": 0.8,
                "temp_initial_k": 298.15,
                "n_series": 2,
                "n_parallel": 6,
                "capacity_spread": 0.03,
                "resistance_spread": 0.05,
                "seed": 42,
            },
        ),
    ):
        py = export_fmu(out_fmu=fmu.with_suffix(".py.fmu"), **kw)  # type: ignore[arg-type]
        a, b = read_model_description(str(py)), read_model_description(str(fmu))
        assert a.coSimulation.modelIdentifier == b.coSimulation.modelIdentifier
        for cap in ("canGetAndSetFMUstate", "canSerializeFMUstate", "canHandleVariableCommunicationStepSize"):
            assert getattr(b.coSimulation, cap) is True
        assert b.coSimulation.needsExecutionTool is False
        native = {v.name: v for v in b.modelVariables}
        for v in a.modelVariables:
            w = native[v.name]
            for attr in ("valueReference", "causality", "variability", "initial", "type", "unit"):
                assert getattr(w, attr) == getattr(v, attr), (v.name, attr)
            if v.type == "Boolean":
                assert w.start == v.start, v.name
            else:
                assert float(w.start) == pytest.approx(float(v.start), rel=1e-15, abs=0), v.name
        extra = {v.name: v for v in b.modelVariables if v.name not in {u.name for u in a.modelVariables}}
        assert sorted(extra) == ["v_max_v", "v_min_v"]
        assert all(v.variability == "constant" for v in extra.values())


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("name", shipped_cells())
def test_cell_equals_in_process_model_over_shipped_profiles(
    cell_fmus: dict[tuple[str, int], Path], name: str, version: int
) -> None:
    p = load_cell_parameters(name)
    for label, current, dt in load_profiles(p.capacity.c0_c):
        port = 298.15 + 5.0 * np.sin(np.arange(current.size) / 200.0)
        r = Runner(cell_fmus[name, version])
        got = r.run({"current_a": current, "port_temp_k": port}, dt, CELL_OUTPUTS)
        r.close()
        cell = Cell(p, soc_initial=0.9, temp_k=298.15)
        ts = cell.simulate(current, dt, port).timeseries
        for j, out in enumerate(CELL_OUTPUTS[:4]):
            assert_close(got[:, j], ts[out].to_numpy(), f"{name} {label} {out}")
        soh = soh_of_state(cell.p, ts["qabs_c"].to_numpy(), cell.p[K.C0], p.ageing.x_c)
        assert_close(got[:, 4], soh, f"{name} {label} soh")
        np.testing.assert_array_equal(got[:, 5], current)


@pytest.mark.parametrize("version", VERSIONS)
def test_cell_power_input_equals_in_process_solver(
    cell_fmus: dict[tuple[str, int], Path], version: int
) -> None:
    """Power input: the same secant solve of the current as the pythonfmu FMU's stepper."""
    name = "thesis_table_4_1"
    p = load_cell_parameters(name)
    power = 3.6 * np.concatenate([np.full(60, 3.0), np.full(40, -1.5), 2.0 * np.sin(np.arange(100) / 7.0)])
    r = Runner(cell_fmus[name, version], booleans={"power_input": True})
    got = r.run(
        {"power_w": power, "port_temp_k": np.full(power.size, 300.0)}, 1.0, ("current_a", "voltage_v", "soc")
    )
    r.close()
    stepper = CellStepper(p, 0.9, 298.15)
    for k, pw in enumerate(power):
        i = current_for_power(stepper, float(pw), 300.0, 1.0)
        out = stepper.step(i, 300.0, 1.0)
        assert abs(got[k, 0] - i) <= TOL * max(1.0, abs(i)), k
        assert abs(got[k, 1] - out["voltage_v"]) <= TOL * 4.0, k
        assert abs(got[k, 2] - out["soc"]) <= TOL, k


@pytest.mark.parametrize("version", VERSIONS)
def test_module_equals_in_process_module(module_fmus: dict[int, Path], version: int) -> None:
    """The examples/module.toml module (2s6p, spread): module and per-cell outputs, lumped
    and per-cell ports, current and power input."""
    n, dt = 1369, 1.0
    current = 12.0 * cycle_cell_current("udds", n, dt) * 6
    mod = Module("saft_li_ion_6ah", 2, 6, 0.8, 298.15, 0.03, 0.05, seed=42)
    heat_cap = mod.p[:, K.CHEAT].copy()
    res = mod.simulate(current, dt, 303.15)
    cells = [f"cell{c}_temp_k" for c in range(12)] + [f"cell{c}_port_heat_w" for c in range(12)]
    r = Runner(module_fmus[version])
    got = r.run(
        {"current_a": current, "port_temp_k": np.full(n, 303.15)},
        dt,
        ["voltage_v", "soc", "temp_k", "port_heat_w", *cells],
    )
    r.close()
    ts = res.timeseries
    assert_close(got[:, 0], ts["voltage_v"].to_numpy(), "voltage_v")
    assert_close(got[:, 1], res.cells[:, :, 1].mean(axis=1), "soc")
    assert_close(got[:, 2], res.cells[:, :, 2].max(axis=1), "temp_k")
    assert_close(got[:, 3], ts["port_heat_w"].to_numpy(), "port_heat_w")
    temps = res.cells[:, :, 2]
    assert_close(got[:, 4:16], temps, "cell temperatures")
    prev = np.vstack([np.full(12, 298.15), temps[:-1]])
    port_heat = res.cells[:, :, 3] - heat_cap * (temps - prev) / dt
    assert_close(got[:, 16:28], port_heat, "cell port heat")

    # per-cell ports and power input against the pythonfmu FMU's in-process stepper
    steps = 200
    tp = 295.0 + np.linspace(0.0, 10.0, 12)[None, :] + 0.01 * np.arange(steps)[:, None]
    power = np.where(np.arange(steps) < 120, 400.0, -150.0)
    inputs = {"power_w": power, **{f"cell{c}_port_temp_k": tp[:, c] for c in range(12)}}
    r = Runner(module_fmus[version], booleans={"power_input": True, "per_cell_ports": True})
    got = r.run(inputs, dt, ["current_a", "voltage_v", "soc", "port_heat_w", *cells])
    r.close()
    st = ModuleStepper(load_cell_parameters("saft_li_ion_6ah"), 0.8, 298.15, 2, 6, 0.03, 0.05, 42)
    for k in range(steps):
        i = current_for_power(st, float(power[k]), tp[k], dt)
        out = st.step(i, tp[k], dt)
        want = [
            i,
            out["voltage_v"],
            out["soc"],
            out["port_heat_w"],
            *st.m.state[:, K.STEMP],
            *st.cell_port_heat_w,
        ]
        assert_close(got[k], np.array(want), f"power step {k}")


@pytest.mark.parametrize("version", VERSIONS)
def test_state_round_trip_is_bit_identical(
    cli_cell_fmus: dict[int, Path], module_fmus: dict[int, Path], version: int
) -> None:
    cell, module = cli_cell_fmus[version], module_fmus[version]
    for fmu, outs in ((cell, list(CELL_OUTPUTS)), (module, ["voltage_v", "soc", "cell7_temp_k"])):
        scale = 1.0 if fmu == cell else 30.0
        current = scale * np.sin(np.arange(120) / 5.0)
        r = Runner(fmu, {"soc_initial": 0.8})  # (from full, the charge half-waves would overfill it)
        r.run({"current_a": current[:40]}, 1.0, outs)
        state = r.get_state()
        blob = r.serialize(state)
        t0 = r.t
        first = r.run({"current_a": current[40:]}, 1.0, outs)
        r.set_state(state)
        r.t = t0
        again = r.run({"current_a": current[40:]}, 1.0, outs)
        np.testing.assert_array_equal(again, first)
        # a new instance resumes from the serialised state
        r2 = Runner(fmu, {"soc_initial": 0.8})
        r2.set_state(r2.deserialize(blob))
        r2.t = t0
        np.testing.assert_array_equal(r2.run({"current_a": current[40:]}, 1.0, outs), first)
        r.free_state(state)
        r.close()
        r2.close()


COMPILERS = [c for c in dict.fromkeys([CC, shutil.which("clang") or ""]) if c]
"""The system compiler and, if installed, clang (a second C99 compiler)."""


def compile_strict(fmu: Path, version: int, tmp_path: Path, cc: str = CC) -> None:
    """Compile the FMU's sources with ``cc -std=c99 -Wall -Wextra -Werror -pedantic``."""
    import fmpy

    headers = Path(fmpy.__file__).parent / "c-code"
    src = tmp_path / f"{fmu.stem}_{Path(cc).name}"
    with zipfile.ZipFile(fmu) as z:
        z.extractall(src, [n for n in z.namelist() if n.startswith("sources/")])
    cmd = [
        cc,
        "-std=c99",
        "-Wall",
        "-Wextra",
        "-Werror",
        "-pedantic",
        "-fPIC",
        "-shared",
        f"-I{headers}",
        f"-I{src / 'sources'}",
        str(src / "sources" / f"fmi{version}_model.c"),
        "-o",
        str(src / "m.so"),
        "-lm",
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("cc", COMPILERS)
@pytest.mark.parametrize("version", VERSIONS)
def test_sources_compile_with_strict_warnings(
    cli_cell_fmus: dict[int, Path], module_fmus: dict[int, Path], tmp_path: Path, version: int, cc: str
) -> None:
    for fmu in (cli_cell_fmus[version], module_fmus[version]):
        compile_strict(fmu, version, tmp_path, cc)


MINGW = shutil.which("x86_64-w64-mingw32-gcc") or ""
"""MinGW-w64's cross compiler to Windows x86-64, if installed (Debian: gcc-mingw-w64-x86-64)."""


@pytest.mark.skipif(not MINGW, reason="MinGW-w64 (x86_64-w64-mingw32-gcc) is not installed")
@pytest.mark.parametrize("version", VERSIONS)
def test_sources_cross_compile_to_a_windows_dll(
    cli_cell_fmus: dict[int, Path], module_fmus: dict[int, Path], tmp_path: Path, version: int
) -> None:
    """What an FMI tool on Windows rebuilds from sources/: the cell and module sources compile to a
    Windows x86-64 DLL (strict C99) that imports only the C runtime and exports the FMI calls."""
    for fmu in (cli_cell_fmus[version], module_fmus[version]):
        compile_strict(fmu, version, tmp_path, MINGW)
        dll = tmp_path / f"{fmu.stem}_{Path(MINGW).name}" / "m.so"
        dump = subprocess.run([MINGW.replace("-gcc", "-objdump"), "-p", str(dll)], capture_output=True,
                              text=True, check=True).stdout  # fmt: skip
        assert "file format pei-x86-64" in dump, dump[:300]
        imported = {
            line.split(":", 1)[1].strip().lower() for line in dump.splitlines() if "DLL Name:" in line
        }
        assert imported and imported <= {"kernel32.dll", "msvcrt.dll"}, imported
        for call in ("Instantiate", "DoStep", "GetFMUstate" if version == 2 else "GetFMUState"):
            assert f"fmi{version}{call}" in dump, call


@pytest.mark.skipif(not shutil.which("clang"), reason="clang is not installed")
@pytest.mark.parametrize("version", VERSIONS)
def test_fmu_built_by_clang_equals_in_process_model(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, version: int
) -> None:
    """A second compiler ($CC = clang) builds FMUs that give the same results (1e-12)."""
    monkeypatch.setenv("CC", shutil.which("clang") or "")
    p = load_cell_parameters(option_source("all", tmp_path))
    current = 2.5 * cycle_cell_current("udds", 600.0, 1.0)
    fmu = export_native_fmu(p, tmp_path / "clang.fmu", 0.7, 298.15, fmi_version=version)
    with zipfile.ZipFile(fmu) as z:
        assert "clang" in z.read(next(n for n in z.namelist() if n.startswith("binaries/"))).decode("latin-1")
    r = Runner(fmu)
    got = r.run({"current_a": current}, 1.0, CELL_OUTPUTS[:4])
    r.close()
    ts = Cell(p, soc_initial=0.7, temp_k=298.15).simulate(current, 1.0, 298.15).timeseries
    for j, out in enumerate(CELL_OUTPUTS[:4]):
        assert_close(got[:, j], ts[out].to_numpy(), f"clang {out}")


@pytest.mark.parametrize("version", VERSIONS)
def test_set_real_on_a_constant_or_output_is_refused(cli_cell_fmus: dict[int, Path], version: int) -> None:
    from fmpy.fmi1 import FMICallException

    r = Runner(cli_cell_fmus[version])
    for name in ("v_min_v", "voltage_v"):
        with pytest.raises(FMICallException):
            r.set(name, 1.0)
    assert any("'v_min_v'" in m and "constant" in m for m in r.messages), r.messages
    assert any("'voltage_v'" in m and "output" in m for m in r.messages), r.messages
    assert r.get(["v_min_v"]) == [load_cell_parameters("thesis_table_4_1").limits.v_min_v]
    r.close()


@pytest.mark.parametrize("version", VERSIONS)
def test_out_of_range_values_return_error_with_message(cli_cell_fmus: dict[int, Path], version: int) -> None:
    """A parameter outside the table range, a port temperature outside the model's range and
    a current beyond the short-circuit current: fmi2Error, a message naming the variable and
    the value, and the state as before (the next valid step equals the in-process model)."""
    from fmpy.fmi1 import FMICallException

    r = Runner(cli_cell_fmus[version])
    with pytest.raises(FMICallException):
        r.set("soc_initial", 1.5)
    assert any("soc_initial = 1.5" in m and "SOC axis" in m for m in r.messages), r.messages
    r.run({"current_a": [4.0] * 10}, 1.0, CELL_OUTPUTS)
    r.set("port_temp_k", 612.5)
    with pytest.raises(FMICallException):
        r.step(1.0)
    assert any("port_temp_k = 612.5 K" in m for m in r.messages), r.messages
    r.set("port_temp_k", 296.15)
    r.set("current_a", 5000.0)
    with pytest.raises(FMICallException):
        r.step(1.0)
    assert any("voltage_v = -" in m and "5000 A" in m for m in r.messages), r.messages
    got = r.run({"current_a": [4.0] * 5}, 1.0, ("voltage_v",))
    r.close()
    ref = Cell("thesis_table_4_1", 1.0, 296.15).simulate([4.0] * 15, 1.0, 296.15).timeseries["voltage_v"]
    np.testing.assert_array_equal(got[:, 0], ref.to_numpy()[10:])


HOST_C = r"""
#include <dlfcn.h>
#include <stdio.h>
#include <stdarg.h>
#include "fmi2Functions.h"
static void logger(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c, fmi2String m, ...)
{ (void)e; (void)n; (void)s; (void)c; fprintf(stderr, "%s\n", m); }
#define SYM(T, name) T name = (T)dlsym(h, #name); if (!name) return 3
int main(int argc, char **argv)
{
    void *h = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    fmi2CallbackFunctions cb = {logger, NULL, NULL, NULL, NULL};
    fmi2Component c;
    fmi2ValueReference vr_i = 0, vr_v = 12;
    fmi2Real i = 4.0, v = 0.0, t = 0.0;
    int k;
    if (!h || argc < 3) return 2;
    {
        SYM(fmi2InstantiateTYPE *, fmi2Instantiate);
        SYM(fmi2SetupExperimentTYPE *, fmi2SetupExperiment);
        SYM(fmi2EnterInitializationModeTYPE *, fmi2EnterInitializationMode);
        SYM(fmi2ExitInitializationModeTYPE *, fmi2ExitInitializationMode);
        SYM(fmi2SetRealTYPE *, fmi2SetReal);
        SYM(fmi2GetRealTYPE *, fmi2GetReal);
        SYM(fmi2DoStepTYPE *, fmi2DoStep);
        SYM(fmi2TerminateTYPE *, fmi2Terminate);
        SYM(fmi2FreeInstanceTYPE *, fmi2FreeInstance);
        c = fmi2Instantiate("host", fmi2CoSimulation, argv[2], "", &cb, fmi2False, fmi2False);
        if (!c) return 4;
        fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        fmi2EnterInitializationMode(c);
        fmi2ExitInitializationMode(c);
        for (k = 0; k < 20; k++, t += 1.0) {
            fmi2SetReal(c, &vr_i, 1, &i);
            if (fmi2DoStep(c, t, 1.0, fmi2True) != fmi2OK) return 5;
        }
        fmi2GetReal(c, &vr_v, 1, &v);
        fmi2Terminate(c);
        fmi2FreeInstance(c);
    }
    if (dlclose(h) != 0) return 6;
    printf("%.17g\n", v);
    return 0;
}
"""


def test_fresh_host_processes_load_and_unload_50_times(cli_cell_fmu: Path, tmp_path: Path) -> None:
    """A small C host (no Python): 50 processes each load the binary, run 20 steps, unload it."""
    import fmpy
    from fmpy import read_model_description

    md = read_model_description(str(cli_cell_fmu))
    assert {v.name: v.valueReference for v in md.modelVariables}["voltage_v"] == 12
    name, data = native_binary(cli_cell_fmu)
    lib = tmp_path / Path(name).name
    lib.write_bytes(data)
    (tmp_path / "host.c").write_text(HOST_C)
    host = tmp_path / "host"
    headers = Path(fmpy.__file__).parent / "c-code"
    cmd = [
        CC,
        "-std=c99",
        "-Wall",
        "-Werror",
        f"-I{headers}",
        str(tmp_path / "host.c"),
        "-o",
        str(host),
        "-ldl",
    ]
    subprocess.run(cmd, check=True, capture_output=True)
    ref = (
        Cell("thesis_table_4_1", 1.0, 296.15).simulate(np.full(20, 4.0), 1.0, 296.15).timeseries["voltage_v"]
    )
    for _ in range(50):
        proc = subprocess.run(
            [str(host), str(lib), md.guid], capture_output=True, text=True, timeout=30, check=False
        )
        assert proc.returncode == 0, (proc.returncode, proc.stderr)
        assert float(proc.stdout) == float(ref.iloc[-1])


LIBCOSIM_SCRIPT = """
import json, sys
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimManipulator import CosimManipulator
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimSlave import CosimLocalSlave

log_output_level(CosimLogLevel.ERROR)
req = json.load(sys.stdin)
ex = CosimExecution.from_step_size(step_size=int(req["dt_s"] * 1e9))
idx = ex.add_local_slave(local_slave=CosimLocalSlave(fmu_path=req["fmu"], instance_name="cell"))
vr = {v.name.decode(): v.reference for v in ex.slave_variables(idx)}
man = CosimManipulator.create_override()
ex.add_manipulator(manipulator=man)
obs = CosimObserver.create_last_value()
ex.add_observer(observer=obs)
out = []
for i, tp in zip(req["current_a"], req["port_temp_k"]):
    man.slave_real_values(idx, [vr["current_a"], vr["port_temp_k"]], [i, tp])
    ex.step()
    out.append(obs.last_real_values(idx, [vr[n] for n in req["outputs"]]))
print(json.dumps(out))
"""


def test_libcosim_runs_the_fmu(cli_cell_fmu: Path) -> None:
    """libcosim (C++ FMI host, through libcosimpy) steps the FMI 2.0 FMU to the same results."""
    pytest.importorskip("libcosimpy")
    n = 300
    current = np.where(np.arange(n) < 200, 4.0, -2.0)
    port = 296.15 + 0.01 * np.arange(n)
    outs = ["voltage_v", "soc", "temp_k", "port_heat_w"]
    req = {
        "fmu": str(cli_cell_fmu),
        "dt_s": 1.0,
        "current_a": current.tolist(),
        "port_temp_k": port.tolist(),
        "outputs": outs,
    }
    proc = subprocess.run(
        [sys.executable, "-c", LIBCOSIM_SCRIPT],
        input=json.dumps(req),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = np.array(json.loads(proc.stdout.strip().splitlines()[-1]))
    ts = Cell("thesis_table_4_1", 1.0, 296.15).simulate(current, 1.0, port).timeseries
    for j, name in enumerate(outs):
        assert_close(got[:, j], ts[name].to_numpy(), f"libcosim {name}")


MODEL_OPTIONS = {
    "rc_persistent": '[model]\nrc_mode = "persistent"',
    "ocv_step_consistent": '[model]\nocv_mode = "step_consistent"',
    "charge_transfer": "[charge_transfer]\ni0_a = 0.8\nscale = 1.3\nea_j_per_mol = 30000.0",
    "hysteresis": "[hysteresis]\nmax_v = 0.012\ngamma = 40.0",
}
MODEL_OPTIONS["all"] = (
    '[model]\nrc_mode = "persistent"\nocv_mode = "step_consistent"\n'
    + MODEL_OPTIONS["charge_transfer"]
    + "\n"
    + MODEL_OPTIONS["hysteresis"]
)


def option_source(name: str, folder: Path) -> Path:
    """A TOML file in ``folder`` of the thesis cell with the model option(s) ``name`` on."""
    src = Path(load_cell_parameters("thesis_table_4_1").source).read_text()
    out = folder / f"{name}.toml"
    out.write_text(src + f"\n{MODEL_OPTIONS[name]}\n")
    return out


@pytest.fixture(scope="module")
def option_params(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The thesis cell with each issue-14 model option on (and all of them), as TOML files."""
    folder = tmp_path_factory.mktemp("options")
    return {name: option_source(name, folder) for name in MODEL_OPTIONS}


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("option", sorted(MODEL_OPTIONS))
def test_model_options_equal_in_process_model(
    option_params: dict[str, Path], option: str, version: int, tmp_path: Path
) -> None:
    """Each cell model option of issue 14 in the C kernel: the cell FMU equals Cell.simulate and
    the 2s3p module FMU (with spread) Module.simulate, 1e-12 per output and step, over a
    UDDS-like current with reversals and rests (which exercise the RC switch, the hysteresis
    and the relinearised current sharing)."""
    p = load_cell_parameters(option_params[option])
    assert (
        p.model.rc_mode != "switched"
        or p.model.ocv_mode != "step_start"
        or (p.charge_transfer.i0_a > 0 or p.hysteresis.max_v > 0)
    )
    current = 2.5 * cycle_cell_current("udds", 600.0, 1.0)
    port = 298.15 + 3.0 * np.sin(np.arange(current.size) / 90.0)
    fmu = export_native_fmu(p, tmp_path / "cell.fmu", 0.7, 298.15, fmi_version=version)
    r = Runner(fmu)
    got = r.run({"current_a": current, "port_temp_k": port}, 1.0, CELL_OUTPUTS[:4])
    r.close()
    ts = Cell(p, soc_initial=0.7, temp_k=298.15).simulate(current, 1.0, port).timeseries
    for j, out in enumerate(CELL_OUTPUTS[:4]):
        assert_close(got[:, j], ts[out].to_numpy(), f"{option} cell {out}")
    mod_fmu = export_native_fmu(
        p, tmp_path / "m.fmu", 0.7, 298.15, None, 2, 3, 0.03, 0.05, 7, fmi_version=version
    )
    mod = Module(p, 2, 3, 0.7, 298.15, 0.03, 0.05, seed=7)
    res = mod.simulate(3.0 * current, 1.0, port)
    r = Runner(mod_fmu)
    cells = [f"cell{c}_temp_k" for c in range(6)]
    got = r.run({"current_a": 3.0 * current, "port_temp_k": port}, 1.0, ["voltage_v", "port_heat_w", *cells])
    r.close()
    assert_close(got[:, 0], res.timeseries["voltage_v"].to_numpy(), f"{option} module voltage_v")
    assert_close(got[:, 1], res.timeseries["port_heat_w"].to_numpy(), f"{option} module port_heat_w")
    assert_close(got[:, 2:], res.cells[:, :, 2], f"{option} module cell temperatures")


def test_missing_compiler_is_a_clear_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.delenv("CC", raising=False)
    with pytest.raises(NativeFMUError, match=r"no C compiler found.*apt-get install gcc"):
        export_native_fmu("thesis_table_4_1", tmp_path / "x.fmu")
    assert not (tmp_path / "x.fmu").exists()
    # the default export of the command line: exit 2, what to install and the --pythonfmu way
    assert main(["export-fmu", str(ROOT / "examples" / "cell.toml"), "-o", str(tmp_path / "x.fmu")]) == 2
    err = capsys.readouterr().err
    assert "no C compiler found" in err and "apt-get install gcc" in err and "--pythonfmu" in err, err
    assert not (tmp_path / "x.fmu").exists()


def test_fmi3_is_native_only(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "x.fmu"
    cmd = ["export-fmu", str(ROOT / "examples" / "cell.toml"), "-o", str(out), "--fmi-version", "3"]
    assert main([*cmd, "--pythonfmu"]) == 2
    assert "drop --pythonfmu" in capsys.readouterr().err and not out.exists()
    assert main(cmd) == 0  # native is the default
    from hevsim.battery.native import is_native_fmu

    assert is_native_fmu(out)

"""Issue 13 item 8 for ``hevsim export-fmu --pythonfmu``: hosts that load, step, free and unload
the exported pythonfmu cell and module FMUs exit normally (no "corrupted double-linked list"
abort at exit).

The cause: numba's first JIT compilation inside the FMU's ``fmi2Instantiate`` (a call from C
into the interpreter) leaves the heap corrupted when the process exits; the abort comes in the
C library destructors after Python's finalisation, in about half the runs, with or without
``dlclose``. The fix: the FMU's model module imports the cell kernels with the JIT off in a host
that has not started numba (pure-Python kernels, same equations), and ``hevsim cosim`` starts
the JIT before loading a pythonfmu FMU in process where numba is already imported or the FMU
predates that guard (:func:`hevsim.cosim.participant.jit_first_needed`). Measured without the
fixes: FMPy hosts of FMUs without the guard abort in 7-8 of 20 runs (the first test fails);
``hevsim cosim`` hosts with neither part abort in 5 of 10 (either part alone: 0 of 10, so the
second test fails only with both disabled). pythonfmu3 (FMI 3.0) FMUs are not exported
(``--fmi-version 3`` is native only).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from hevsim.cli import main

ROOT = Path(__file__).resolve().parents[1]
RUNS = 20

FMPY_HOST = """
import sys
from fmpy import simulate_fmu

for path in sys.argv[1:]:
    res = simulate_fmu(path, stop_time=5.0, output_interval=1.0, fmi_type="CoSimulation")
    print(path, len(res), res["voltage_v"][-1])
"""


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    d = tmp_path_factory.mktemp("pyfmu")
    out = []
    for example in ("cell", "module"):
        path = d / f"{example}.fmu"
        toml = ROOT / "examples" / f"{example}.toml"
        assert main(["export-fmu", str(toml), "-o", str(path), "--pythonfmu"]) == 0
        out.append(path)
    return out


def run_hosts(cmd: list[str]) -> list[subprocess.CompletedProcess[str]]:
    """``cmd`` in :data:`RUNS` fresh processes; asserts each exits 0 without an abort."""
    procs = []
    for k in range(RUNS):
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, check=False)
        assert proc.returncode == 0, (k, proc.returncode, proc.stderr[-2000:])
        assert "corrupted" not in proc.stderr and "Abort" not in proc.stderr, proc.stderr[-2000:]
        procs.append(proc)
    return procs


def test_fmpy_hosts_exit_cleanly(fmus: list[Path]) -> None:
    """FMPy's ``simulate_fmu`` (instantiate, step, ``fmi2FreeInstance``, ``dlclose``) runs the
    cell and the module FMU in each of 20 fresh host processes: all exit 0, same results."""
    procs = run_hosts([sys.executable, "-c", FMPY_HOST, *map(str, fmus)])
    assert len({p.stdout for p in procs}) == 1
    lines = procs[0].stdout.splitlines()
    assert len(lines) == 2 and all(line.split()[1] == "6" for line in lines), lines
    volts = [float(line.split()[2]) for line in lines]
    assert 3.0 < volts[0] < 4.3 and 6.0 < volts[1] < 8.6, volts  # one cell, two in series


def test_hevsim_cosim_hosts_exit_cleanly(fmus: list[Path], tmp_path: Path) -> None:
    """``hevsim cosim`` with both FMUs in process, in 20 fresh processes: all exit 0 and write
    the same results, equal to FMPy's run of the same FMUs."""
    from hevsim.cosim.ssd import FMU_TYPE, Component, SystemDescription
    from hevsim.cosim.ssp_write import write_ssd

    comps = [Component(p.stem, FMU_TYPE, p.name) for p in fmus]
    master = {"step_s": 1.0, "fmu_process": "inprocess"}
    desc = SystemDescription("exit", comps, [], stop_time_s=5.0, master=master, base_dir=fmus[0].parent)
    ssd = write_ssd(desc, fmus[0].parent / "exit.ssd")
    out = tmp_path / "out"
    hevsim = str(Path(sys.executable).with_name("hevsim"))
    run_hosts([hevsim, "cosim", str(ssd), "--out", str(out), "--force"])
    import csv

    with open(out / "results.csv", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    ref = subprocess.run([sys.executable, "-c", FMPY_HOST, *map(str, fmus)], capture_output=True, text=True,
                         timeout=300, check=True).stdout.splitlines()  # fmt: skip
    got = [float(rows[-1][f"{p.stem}.voltage_v"]) for p in fmus]
    np.testing.assert_allclose(got, [float(line.split()[2]) for line in ref], rtol=1e-12)

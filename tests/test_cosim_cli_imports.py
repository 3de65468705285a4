"""The start of ``hevsim cosim`` pays only for what a co-simulation uses (issue 13 item 11):
no numba cache digest unless numba is imported, no compiler, solver, table or plotting
package, no progress bar off a terminal, no package metadata lookup, no worker protocol for
FMUs in process, no CSE reader for an SSD."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from hevsim import _numba_cache as nc
from hevsim.cosim.ssd import FMU_TYPE, Component, SystemDescription
from hevsim.cosim.ssp_write import write_ssd
from hevsim.cosim.trivial import build_integrator_fmu

HEAVY = ("numba", "scipy", "pandas", "matplotlib", "pyarrow", "tqdm", "importlib.metadata",
         "hevsim.cosim.worker", "hevsim.cosim.cse")  # fmt: skip


def _env(tmp_path: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    return env


def test_numba_cache_is_set_when_numba_is_imported_not_before(tmp_path: Path) -> None:
    code = (
        "import os, sys, json, hevsim\n"
        "before = [os.environ.get('NUMBA_CACHE_DIR'), 'numba' in sys.modules]\n"
        "import numba\n"
        "from numba.core import config\n"
        "hooks = [type(f).__name__ for f in sys.meta_path if type(f).__name__ == '_BeforeNumba']\n"
        "print(json.dumps([before, os.environ.get('NUMBA_CACHE_DIR'), config.CACHE_DIR, hooks]))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=_env(tmp_path), check=True
    )
    before, env_dir, cache_dir, hooks = json.loads(out.stdout)
    assert before == [None, False]  # import hevsim alone: no digest, no numba
    folder = Path(cache_dir)
    assert env_dir == cache_dir and folder.parent == tmp_path / "cache" / "hevsim" / "numba"
    assert (folder / nc.MARKER).is_file() and hooks == []  # the finder removed itself


def test_cosim_command_imports_only_what_it_uses(tmp_path: Path) -> None:
    fmu = build_integrator_fmu(tmp_path / "i.fmu", name="ImportsInt", y0=1.0)
    desc = SystemDescription(
        "imports", [Component("i", FMU_TYPE, fmu.name)], [], stop_time_s=1.0,
        master={"step_s": 0.1}, base_dir=tmp_path,  # the default path: a pythonfmu FMU runs in process
    )  # fmt: skip
    ssd = write_ssd(desc, tmp_path / "imports.ssd")
    out = tmp_path / "out"
    code = (
        "import sys, json, os\n"
        "from hevsim.cli import main\n"
        f"code = main(['cosim', {str(ssd)!r}, '--out', {str(out)!r}])\n"
        f"print(json.dumps([code, [m for m in {HEAVY!r} if m in sys.modules]]), flush=True)\n"
        "os._exit(0)\n"  # (in-process pythonfmu FMUs: see docs/cosim.md)
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=_env(tmp_path))
    assert run.returncode == 0, run.stderr
    code_, heavy = json.loads(run.stdout.strip().splitlines()[-1])
    assert code_ == 0 and heavy == []
    rows = (out / "results.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 11  # header, t = 0 .. 1 s: the outputs users get are still written
    assert (out / "summary.json").is_file() and (out / "system.ssd").is_file()

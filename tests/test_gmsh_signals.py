"""Meshing with gmsh leaves the process's signal handling as Python set it: SIGPIPE ignored
(a write to a closed pipe raises BrokenPipeError instead of killing the process silently, as
it did to the test suite when a co-simulation worker's pipe closed after a meshing test) and
Ctrl-C raising KeyboardInterrupt."""

from __future__ import annotations

import subprocess
import sys

import pytest
from tests.proc_helpers import sigint_default

PROBE = """
import signal, threading
from hevsim.thermal.geometry import ModuleGeometry, build_module_mesh

def sigpipe_ignored():
    status = open("/proc/self/status").read()
    return bool(int(status.split("SigIgn:")[1].split()[0], 16) >> (signal.SIGPIPE - 1) & 1)

assert sigpipe_ignored()
build_module_mesh(ModuleGeometry())
print(sigpipe_ignored(), signal.getsignal(signal.SIGINT) is signal.default_int_handler)
t = threading.Thread(target=build_module_mesh)
t.start(); t.join()
print(sigpipe_ignored())
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
def test_meshing_keeps_sigpipe_ignored_and_sigint_python() -> None:
    proc = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=600,
                          check=False, preexec_fn=sigint_default)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.split() == ["True", "True", "True"], proc.stdout

"""Shared plumbing of the co-simulation tests: interrupted runs and in-process FMU children."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from typing import Any

import pytest

#: Prelude of a child script: the result goes to the original stdout, FMU log lines (pythonfmu3
#: prints them to stdout) to stderr. The child ends with ``finish(out)``.
CHILD_PRELUDE = """
import json, os, sys
_result_fd = os.dup(1)
os.dup2(2, 1)
def finish(out):
    os.write(_result_fd, json.dumps(out).encode())
    os._exit(0)  # pythonfmu test FMUs can abort the host at exit (hevsim._pythonfmu_exit)
"""


def run_child(script: str, arg: Any, timeout_s: float = 120.0) -> dict[str, Any]:
    """Run ``CHILD_PRELUDE + script`` in a fresh interpreter with ``json.dumps(arg)`` as
    ``sys.argv[1]``; return what it passed to ``finish``."""
    proc = subprocess.run(
        [sys.executable, "-c", CHILD_PRELUDE + script, json.dumps(arg)],
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return dict(json.loads(proc.stdout))


def interrupt_after(run: Callable[..., Any], t_kill: float, **kwargs: Any) -> None:
    """Call ``run(progress=..., **kwargs)`` and kill it (KeyboardInterrupt) after ``t_kill`` [s]."""

    def kill(t: float, stop: float) -> None:
        if t > t_kill:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run(progress=kill, **kwargs)

"""Ctrl-C ends every command with exit 130 and one line saying what was kept and how to go on,
never a traceback (issue 26 item 3). A real SIGINT goes to the child's whole process group, as
a terminal's Ctrl-C does (worker processes included)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from tests.proc_helpers import sigint_default

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"

_CHILD = """
import sys
from hevsim.cli import main
print("hevsim-test: started", file=sys.stderr, flush=True)
sys.exit(main(sys.argv[1:]))
"""


def _interrupt(tmp_path: Path, args: list[str], marker: str, after_s: float) -> tuple[int, str]:
    """Run ``hevsim ARGS`` in a new process group, wait for ``marker`` in its stderr and then
    ``after_s`` seconds, send SIGINT to the group; returns (exit status, stderr)."""
    err_path = tmp_path / "stderr.txt"
    with open(err_path, "wb") as err:
        proc = subprocess.Popen(  # Ctrl-C acts even if this run inherited SIGINT ignored
            [sys.executable, "-c", _CHILD, *args], stdout=subprocess.DEVNULL, stderr=err, cwd=tmp_path,
            preexec_fn=sigint_default, start_new_session=True,
        )  # fmt: skip
        try:
            deadline = time.monotonic() + 300
            while marker not in err_path.read_text(errors="replace"):
                assert proc.poll() is None, err_path.read_text()[-3000:]
                assert time.monotonic() < deadline, err_path.read_text()[-3000:]
                time.sleep(0.05)
            time.sleep(after_s)
            assert proc.poll() is None, "the command ended before the interrupt: make it longer"
            os.killpg(proc.pid, signal.SIGINT)
            proc.wait(timeout=120)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    return proc.returncode, err_path.read_text(errors="replace")


def _last_line(err: str, command: str) -> str:
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err[-4000:]
    line = err.strip().splitlines()[-1]
    assert line.startswith(f"hevsim: {command} interrupted (Ctrl-C); "), err[-2000:]
    return line


def test_optimize_ctrl_c(tmp_path: Path) -> None:
    """Today: a KeyboardInterrupt traceback (exit 1)."""
    out = tmp_path / "opt"
    args = ["optimize", str(EXAMPLES / "series_hev.toml"), "--soc-points", "801", "--out", str(out)]
    code, err = _interrupt(tmp_path, args, "hevsim-test: started", 4.0)
    assert code == 130, err[-3000:]
    line = _last_line(err, "optimize")
    assert "nothing was written" in line  # (to OUT, once the command has checked it)
    assert not out.exists()


def test_thermal_ctrl_c_keeps_the_old_results(tmp_path: Path) -> None:
    """Interrupted in the time loop: exit 130, the results folder of an earlier run unchanged."""
    out = tmp_path / "th"
    out.mkdir()
    (out / ".hevsim-results").write_text('{"files": ["old.txt"]}\n')
    (out / "old.txt").write_text("earlier run\n")
    args = ["thermal", str(EXAMPLES / "module_thermal.toml"), "--out", str(out)]
    code, err = _interrupt(tmp_path, args, "time loop", 0.5)
    assert code == 130, err[-3000:]
    _last_line(err, "thermal")
    assert (out / "old.txt").read_text() == "earlier run\n"


@pytest.mark.parametrize("scheduler", [["--scheduler", "in-process"], ["--workers", "1"]])
def test_study_ctrl_c(tmp_path: Path, scheduler: list[str]) -> None:
    """In process and on a local Dask cluster (whose worker processes get the SIGINT too and
    printed four tracebacks): exit 130, one line naming the kept cases and --resume."""
    study = tmp_path / "study.toml"
    text = (EXAMPLES / "study_series_sizing.toml").read_text()
    study.write_text(
        text.replace('vehicle = "series_hev.toml"', f'vehicle = "{EXAMPLES / "series_hev.toml"}"')
    )
    out = tmp_path / "st"
    code, err = _interrupt(tmp_path, ["study", str(study), "--out", str(out), *scheduler], "cases ...", 1.0)
    assert code == 130, err[-3000:]
    line = _last_line(err, "study")
    assert f"the finished cases are in {out}/results/" in line and "--resume" in line


def test_ctrl_c_inside_a_compiler_callback_is_retried_not_lost() -> None:
    """A SIGINT landing in llvmlite's callback into Python (numba compiling) would be "ignored"
    by ctypes, losing the Ctrl-C (seen: a traceback fragment and exit 0): it is retried shortly
    after by SIGALRM; anywhere else it is KeyboardInterrupt."""
    import types

    from hevsim.cli import _sigint

    code = compile("pass", os.path.join(os.sep, "x", "llvmlite", "binding", "executionengine.py"), "exec")
    frame = types.SimpleNamespace(f_code=code)
    previous = signal.getsignal(signal.SIGALRM)
    try:
        _sigint(signal.SIGINT, frame)  # no exception here
        assert signal.getsignal(signal.SIGALRM) is _sigint
        assert 0.0 < signal.getitimer(signal.ITIMER_REAL)[0] <= 0.05
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)
    with pytest.raises(KeyboardInterrupt):
        _sigint(signal.SIGINT, types.SimpleNamespace(f_code=compile("pass", __file__, "exec")))


def test_ctrl_c_wrapped_by_a_c_callback_is_still_ctrl_c(monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    """A Ctrl-C landing while numba loads a kernel from its cache comes back as ``SystemError:
    <function _numba_unpickle> returned a result with an exception set`` (its cause the
    KeyboardInterrupt; seen once in the fresh-clone CI on test_optimize_ctrl_c): exit 130 and
    the one line, not a traceback. Any other exception still propagates."""
    import hevsim.cli as cli

    def wrapped(args: object) -> int:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError("<function _numba_unpickle> returned a result with an exception set") from exc

    def other(args: object) -> int:
        raise SystemError("not an interrupt")

    parser = cli.build_parser()
    real = parser.parse_args

    def parse(argv: object = None) -> object:
        ns = real(["cycles"])
        ns.func = state["func"]
        return ns

    state = {"func": wrapped}
    monkeypatch.setattr(parser, "parse_args", parse)
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    assert cli.main(["cycles"]) == 130
    assert "interrupted (Ctrl-C)" in capsys.readouterr().err
    state["func"] = other
    with pytest.raises(SystemError, match="not an interrupt"):
        cli.main(["cycles"])

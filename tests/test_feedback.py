"""Keeping a person informed, and fast: line thinning for plots, the thread policy, progress
lines and the refusals before heavy work (issue 10.5, issue 15.8-9)."""

from __future__ import annotations

import io
from collections.abc import Callable

import numpy as np
import pytest

from hevsim.errors import ConfigError, HevsimError
from hevsim.progress import Task, cache_is_cold, compile_notice, format_duration, stage, task
from hevsim.report.plots import MAX_LINE_POINTS, thin_line
from hevsim.threads import SERIAL_BELOW_WORK, THREADS_ENV, choose_threads, free_cores, parse_threads

# --------------------------------------------------------------------------- thin_line


def test_thin_line_keeps_short_lines_and_every_peak() -> None:
    x = np.arange(1000.0)
    y = np.sin(x)
    xs, ys = thin_line(x, y)
    assert xs is x and ys is y

    n = 200_003
    x = np.linspace(0.0, 100.0, n)
    y = np.sin(x)
    spikes = {12_345: 7.0, 150_000: -9.0, n - 1: 5.0}
    for i, v in spikes.items():
        y[i] = v
    xs, ys = thin_line(x, y)
    assert ys.size <= MAX_LINE_POINTS
    assert np.all(np.diff(xs) > 0)  # original order, no duplicates
    for i, v in spikes.items():  # every spike survives at its own time
        assert v in ys
        assert xs[np.flatnonzero(ys == v)[0]] == x[i]
    # each bin keeps its min and max: the envelope of the thinned line is the original's
    edges = np.linspace(0, n, MAX_LINE_POINTS // 2 + 1).astype(int)
    for a, b in zip(edges[:-1:97], edges[1::97], strict=True):
        sel = (xs >= x[a]) & (xs <= x[b - 1])
        assert ys[sel].max() == y[a:b].max() and ys[sel].min() == y[a:b].min()


def test_thin_line_nan_never_hides_values() -> None:
    n = 10_000
    x = np.arange(float(n))
    y = np.cos(x / 100.0)
    y[:3000] = np.nan  # bins of only NaN keep a NaN (a gap), mixed bins keep numbers
    y[5000] = np.nan
    y[5001] = 3.0
    _, ys = thin_line(x, y, max_points=100)
    assert ys.size <= 100
    assert np.isnan(ys[0])
    assert 3.0 in ys
    assert np.nanmin(ys) == np.nanmin(y)


# --------------------------------------------------------------------------- thread policy


def _load(value: float) -> Callable[[], tuple[float, float, float]]:
    return lambda: (value, value, value)


def test_threads_option_and_env_win() -> None:
    assert choose_threads("2", env={}, cpu_count=4, loadavg=_load(3.9)).threads == 2
    env = {THREADS_ENV: "3"}
    c = choose_threads(None, env=env, cpu_count=4, loadavg=_load(0.0))
    assert (c.threads, c.reason) == (3, "HEVSIM_THREADS=3")
    # the option beats the environment
    assert choose_threads("1", env=env, cpu_count=4, loadavg=_load(0.0)).threads == 1
    # 'auto' asks for the load-based choice
    assert choose_threads("auto", env=env, cpu_count=4, loadavg=_load(1.2)).threads == 3


@pytest.mark.parametrize("bad", ["0", "-1", "two", "1.5", "", "99"])
def test_threads_validation(bad: str) -> None:
    with pytest.raises(ConfigError, match=r"--threads = .*expected a whole number of threads from 1 to 4"):
        choose_threads(bad, env={}, cpu_count=4, loadavg=_load(0.0))
    with pytest.raises(ConfigError, match=r"HEVSIM_THREADS = .*from 1 to 4"):
        parse_threads(bad, "HEVSIM_THREADS", 4)


def test_threads_follow_the_load() -> None:
    cases = {0.0: 2, 0.4: 2, 0.6: 1, 1.0: 1, 2.0: 1, 7.5: 1}
    for load, want in cases.items():
        assert choose_threads(env={}, cpu_count=2, loadavg=_load(load)).threads == want, load
    assert free_cores(8, _load(2.3)) == (6, 2.3)

    def broken() -> tuple[float, float, float]:
        raise OSError("no load average here")

    assert free_cores(4, broken) == (4, 0.0)
    # below the work threshold: serial whatever the cores
    small = choose_threads(env={}, work=SERIAL_BELOW_WORK / 2, cpu_count=8, loadavg=_load(0.0))
    assert small.threads == 1 and "small problem" in small.reason
    big = choose_threads(env={}, work=SERIAL_BELOW_WORK * 2, cpu_count=8, loadavg=_load(0.0))
    assert big.threads == 8


# --------------------------------------------------------------------------- progress


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_lines_not_on_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    out = io.StringIO()
    stage("meshing ...", out)
    clock = iter([0.0, 40.0, 40.0, 50.0, 200.0, 1000.0])
    monkeypatch.setattr("hevsim.progress.time.perf_counter", lambda: next(clock))
    with task("time loop", 100, stream=out) as t:
        t.update(10)  # 40 s: first progress line, ETA from the rate so far
        t.update(10)  # 50 s: < LOG_EVERY_S since the last line: silent
        t.update(80)  # 200 s: the end, no progress line
    lines = out.getvalue().splitlines()
    assert lines[0] == "hevsim: meshing ..."
    assert lines[1] == "hevsim: time loop: 100 steps ..."
    assert lines[2] == "hevsim: time loop: 10/100 steps (10 %), about 6 min 00 s left"
    assert lines[3].startswith("hevsim: time loop: done, 100 steps in ")
    assert len(lines) == 4


def test_progress_bar_on_a_terminal_and_silence(monkeypatch: pytest.MonkeyPatch) -> None:
    tty = _Tty()
    t = Task("DP table", 50, "stage", tty, None)
    assert t._bar is not None
    for _ in range(50):
        t.update()
    t.close()
    assert "DP table" in tty.getvalue() and "done, 50 stages" in tty.getvalue()
    monkeypatch.setenv("HEVSIM_PROGRESS", "0")
    quiet = io.StringIO()
    with task("x", 3, stream=quiet) as t2:
        t2.update(3)
    stage("nothing", quiet)
    assert quiet.getvalue() == ""
    assert format_duration(5) == "5.0 s" and format_duration(3725) == "1 h 02 min"


def test_compile_notice_only_for_a_cold_cache() -> None:
    class Cold:
        class _cache:
            class _cache_file:
                @staticmethod
                def _load_index() -> dict[str, str]:
                    return {}

    class Warm:
        class _cache:
            class _cache_file:
                @staticmethod
                def _load_index() -> dict[str, str]:
                    return {"sig": "file"}

    assert cache_is_cold([Warm, Cold]) and not cache_is_cold([Warm, object()])
    out = io.StringIO()
    assert not compile_notice("test-warm", [Warm], stream=out)
    assert compile_notice("test-cold", [Cold], stream=out)
    assert not compile_notice("test-cold", [Cold], stream=out)  # once per process
    assert out.getvalue() == (
        "hevsim: compiling test-cold kernels, once: about 20 s (later runs load them from the cache)\n"
    )


def test_real_kernels_have_a_cache_state() -> None:
    from hevsim.progress import module_dispatchers
    from hevsim.sim import kernel

    found = module_dispatchers(kernel, ["run_series"])
    assert len(found) == 1
    assert isinstance(cache_is_cold(found), bool)
    assert issubclass(ConfigError, HevsimError)

"""Keeping a person informed, and fast: line thinning for plots, the thread policy, progress
lines and the refusals before heavy work (issue 10.5, issue 15.8-9)."""

from __future__ import annotations

import io
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from hevsim.errors import ConfigError, HevsimError
from hevsim.guards import check_memory, mem_available_bytes
from hevsim.progress import Task, cache_is_cold, compile_notice, format_duration, stage, task
from hevsim.report.plots import MAX_LINE_POINTS, thin_line
from hevsim.threads import SERIAL_BELOW_WORK, THREADS_ENV, choose_threads, free_cores, own_load, parse_threads

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"

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
    assert choose_threads("auto", env=env, cpu_count=4, loadavg=_load(1.2), own=0.0).threads == 3


@pytest.mark.parametrize("bad", ["0", "-1", "two", "1.5", "", "99"])
def test_threads_validation(bad: str) -> None:
    with pytest.raises(ConfigError, match=r"--threads = .*expected a whole number of threads from 1 to 4"):
        choose_threads(bad, env={}, cpu_count=4, loadavg=_load(0.0))
    with pytest.raises(ConfigError, match=r"HEVSIM_THREADS = .*from 1 to 4"):
        parse_threads(bad, "HEVSIM_THREADS", 4)


def test_threads_follow_the_load() -> None:
    cases = {0.0: 2, 0.4: 2, 0.6: 1, 1.0: 1, 2.0: 1, 7.5: 1}
    for load, want in cases.items():
        assert choose_threads(env={}, cpu_count=2, loadavg=_load(load), own=0.0).threads == want, load
    assert free_cores(8, _load(2.3), own=0.0) == (6, 2.3)
    # this process's own load is not "another process": busy alone on one core -> 2 free
    assert free_cores(2, _load(1.0), own=1.0) == (2, 0.0)
    assert 0.0 <= own_load() <= 1.0 + 1e-9  # a test process: at most one core busy

    def broken() -> tuple[float, float, float]:
        raise OSError("no load average here")

    assert free_cores(4, broken, own=0.0) == (4, 0.0)
    # below the work threshold: serial whatever the cores
    small = choose_threads(env={}, work=SERIAL_BELOW_WORK / 2, cpu_count=8, loadavg=_load(0.0), own=0.0)
    assert small.threads == 1 and "small problem" in small.reason
    big = choose_threads(env={}, work=SERIAL_BELOW_WORK * 2, cpu_count=8, loadavg=_load(0.0), own=0.0)
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


def _dispatcher(index_path: Path, overloads: dict[str, str]) -> object:
    """A stand-in with numba's cache layout: an index file path and what loading it gives."""

    class CacheFile:
        _index_path = str(index_path)

        @staticmethod
        def _load_index() -> dict[str, str]:
            return overloads if index_path.exists() else {}

    class Cache:
        _cache_file = CacheFile

    class Dispatcher:
        _cache = Cache

    return Dispatcher


def test_a_never_compiled_helper_does_not_make_the_cache_cold(tmp_path: Path) -> None:
    (tmp_path / "warm.nbi").write_text("index")
    (tmp_path / "stale.nbi").write_text("index")
    warm = _dispatcher(tmp_path / "warm.nbi", {"sig": "file"})
    inlined = _dispatcher(tmp_path / "inlined.nbi", {})  # no index file: never compiled alone
    stale = _dispatcher(tmp_path / "stale.nbi", {})  # an index for another source version
    assert not cache_is_cold([warm, inlined])
    assert cache_is_cold([warm, inlined, stale])
    assert cache_is_cold([inlined])  # nothing compiled yet: a fresh install


def test_dp_kernels_are_warm_after_a_solve() -> None:
    """After a solve the kernels it ran are warm, and the DP modules' inlined helpers (which
    never get an index of their own) do not make them look cold: the notice stays silent."""
    from hevsim.optimal import _hull, _kernels, optimize
    from hevsim.progress import module_dispatchers

    optimize(EXAMPLES / "parallel_hev.toml", "fu505", soc_grid_points=21, input_grid_points=11)
    ran = module_dispatchers(_hull, ["hull_inputs", "bellman_1d_hull"])
    inlined = module_dispatchers(_kernels, ["_band_value", "_lerp_inf", "_locate"])
    assert len(ran) == 2 and len(inlined) == 3
    assert not cache_is_cold(ran + inlined)


def test_real_kernels_have_a_cache_state() -> None:
    from hevsim.progress import module_dispatchers
    from hevsim.sim import _compiled_series

    found = module_dispatchers(_compiled_series, ["series_drive"])
    assert len(found) == 1
    assert isinstance(cache_is_cold(found), bool)
    assert issubclass(ConfigError, HevsimError)


# --------------------------------------------------------------------------- refusals before heavy work


def test_mem_available_parsing(tmp_path: Path) -> None:
    f = tmp_path / "meminfo"
    f.write_text("MemTotal:       24684328 kB\nMemFree:        1 kB\nMemAvailable:   2048 kB\n")
    assert mem_available_bytes(f) == 2048 * 1024
    f.write_text("MemTotal: 1 kB\n")
    assert mem_available_bytes(f) is None
    assert mem_available_bytes(tmp_path / "missing") is None
    check_memory(
        1e9, "x", "y", ConfigError, available_bytes=None, meminfo=tmp_path / "missing"
    )  # unknown: ok
    with pytest.raises(ConfigError, match=r"^job needs about 2,000 MB \(a 2000.0 MB\), more than the 900 MB"):
        check_memory(2e9, "job", "do less.", ConfigError, {"a": 2e9}, available_bytes=1_000_000_000)


def test_thermal_mesh_refused_before_meshing(monkeypatch: pytest.MonkeyPatch) -> None:
    import dataclasses

    import hevsim.thermal.geometry as geometry
    from hevsim.thermal.mesh import estimate_mesh
    from hevsim.thermal.run import load_thermal_config, run_thermal

    def no_mesh(*args: object, **kwargs: object) -> None:
        raise AssertionError("meshed before the memory check")

    monkeypatch.setattr(geometry, "build_module_mesh", no_mesh)
    cfg = load_thermal_config(EXAMPLES / "module_thermal.toml")
    est = estimate_mesh(cfg.geometry)
    assert 8_000 < est.nodes < 12_000  # 8 863 nodes measured at the example's 5 mm
    fine = dataclasses.replace(cfg, geometry=dataclasses.replace(cfg.geometry, mesh_size_m=2e-4))
    want = (
        r"module_thermal: the thermal mesh at geometry.mesh_size_m = 0.0002 m"
        r" \([\d,]+ nodes estimated\) needs about [\d,]+ MB.*MemAvailable.*larger geometry.mesh_size_m"
    )
    with pytest.raises(ConfigError, match=want):
        run_thermal(fine, None)
    monkeypatch.setattr("hevsim.guards.mem_available_bytes", lambda *a: 100_000_000)
    with pytest.raises(
        ConfigError, match=r"mesh_size_m = 0.005 m .* more than the 90 MB this machine has free"
    ):
        run_thermal(cfg, None)


def test_dp_refused_before_the_stage_table(monkeypatch: pytest.MonkeyPatch) -> None:
    from hevsim.errors import DPSetupError
    from hevsim.optimal import _hev_common
    from hevsim.optimal.hev import optimize

    def no_table(self: object, *args: object, **kwargs: object) -> None:
        raise AssertionError("stage table built before the memory check")

    monkeypatch.setattr(_hev_common.HEVFormulation, "build_table", no_table)
    monkeypatch.setattr(_hev_common.HEVFormulation, "check_followable", no_table)
    with pytest.raises(
        DPSetupError, match=r"the DP solution needs about [\d,]+ MB \(cost_to_go .*solver's limit"
    ):
        optimize(EXAMPLES / "parallel_hev.toml", "udds", soc_grid_points=500_000, input_grid_points=3)
    monkeypatch.setattr("hevsim.guards.mem_available_bytes", lambda *a: 1_000_000)
    with pytest.raises(DPSetupError, match=r"on udds: the DP needs about .* MB this machine has free"):
        optimize(EXAMPLES / "parallel_hev.toml", "udds")


def test_compare_validates_every_input_before_solving(monkeypatch: pytest.MonkeyPatch) -> None:
    import hevsim.optimal.hev as hev
    from hevsim.errors import DPSetupError
    from hevsim.optimal.compare import compare

    def no_solve(*args: object, **kwargs: object) -> None:
        raise AssertionError("solved before every input was checked")

    monkeypatch.setattr(hev, "optimize", no_solve)
    with pytest.raises(HevsimError, match="no_such_cycle"):
        compare([EXAMPLES / "series_hev.toml"], ["udds", "no_such_cycle"])
    with pytest.raises(HevsimError, match=r"missing\.toml"):
        compare([EXAMPLES / "series_hev.toml", EXAMPLES / "missing.toml"], ["udds"])
    with pytest.raises(DPSetupError, match="on hwfet: the DP solution needs at least"):
        compare([EXAMPLES / "series_hev.toml"], ["hwfet"], soc_grid_points=2_000_000)
    with pytest.raises(ConfigError, match="--threads = 'lots'"):
        compare([EXAMPLES / "series_hev.toml"], ["udds"], threads="lots")


def test_cli_threads_option_is_validated(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from hevsim.cli import main

    code = main(
        ["optimize", str(EXAMPLES / "parallel_hev.toml"), "--threads", "0", "--out", str(tmp_path / "o")]
    )
    assert code == 2
    assert "--threads = '0': expected a whole number of threads from 1 to" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_simulation_refused_before_running(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import hevsim.sim.simulator as simulator
    from hevsim.cli import main
    from hevsim.errors import SimulationError
    from hevsim.guards import check_simulation

    need, seconds = check_simulation(10_000_000, "car on cycle", available_bytes=64 * 10**9)
    assert need == pytest.approx(1e10) and seconds == pytest.approx(300.0)
    with pytest.raises(
        SimulationError, match=r"^car on cycle: a simulation of 10,000,000 steps needs about 10,000 MB"
    ):
        check_simulation(10_000_000, "car on cycle", available_bytes=8 * 10**9)

    def no_run(*args: object, **kwargs: object) -> None:
        raise AssertionError("simulated before the memory check")

    monkeypatch.setattr(simulator, "simulate", no_run)
    monkeypatch.setattr("hevsim.guards.mem_available_bytes", lambda *a: 1_000_000)
    code = main(
        ["simulate", str(EXAMPLES / "series_hev.toml"), "--cycle", "udds", "--out", str(tmp_path / "s")]
    )
    err = capsys.readouterr().err
    assert code == 2, err
    assert "on udds: a simulation of 2,739 steps needs about 3 MB" in err and "--dt" in err
    assert not (tmp_path / "s").exists()


def test_dp_runs_the_serial_kernels_with_one_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    """The thread policy reaches the DP: one thread -> serial Bellman kernels, same optimum."""
    import numba

    from hevsim.optimal import _kernels
    from hevsim.optimal.dp import DPProblem, solve_dp

    def model(states, inputs, k, data):
        x, u = states[0], inputs[0]
        return (x + 0.01 * u - 0.004 * x,), (u - 0.3 * x) ** 2 + 0.1 * u, None  # state-dependent: no hull

    problem = DPProblem(model, [np.linspace(0.0, 1.0, 201)], [np.linspace(0.0, 1.0, 201)], 6)  # S*M = 40 401
    calls: dict[str, int] = {"par": 0, "ser": 0}
    for kind in ("par", "ser"):
        real = getattr(_kernels, f"bellman_1d_{kind}")

        def counted(*args: object, _real: object = real, _kind: str = kind) -> object:
            calls[_kind] += 1
            return _real(*args)  # type: ignore[operator]

        monkeypatch.setattr(_kernels, f"bellman_1d_{kind}", counted)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = solve_dp(problem, [0.5])
        assert calls["par"] == 0 and calls["ser"] > 0
        if numba.config.NUMBA_NUM_THREADS >= 2:  # type: ignore[attr-defined]
            numba.set_num_threads(2)
            calls.update(par=0, ser=0)
            two = solve_dp(problem, [0.5])
            assert calls["par"] > 0
            assert two.total_cost == one.total_cost
    finally:
        numba.set_num_threads(before)


def test_dp_notice_comes_before_the_kernels_compile(tmp_path: Path) -> None:
    """The DP's first-compile notice is decided without importing the DP kernels (importing
    ``optimal._kernels`` compiles them at once, so a notice after it would come too late) and
    states the ``dp`` group's measured compile time (hevsim.warmup), not a fixed guess."""
    import ast
    import subprocess
    import sys

    code = f"""
import sys
import hevsim.optimal._feedback as fb
import hevsim.progress as progress
import hevsim.warmup as warmup
seen = []
real = progress.compile_notice
def spy(what, dispatchers, seconds=20.0, stream=None, **kw):
    seen.append(("hevsim.optimal._kernels" in sys.modules, what, seconds))
    return real(what, dispatchers, seconds, stream, **kw)
progress.compile_notice = spy
progress.cache_is_cold = lambda dispatchers: True
warmup.KernelGroup.is_cold = lambda self: self.name == "dp"
fb.STAGE_LINES_MIN_PAIRS = 0
from hevsim.optimal import optimize
optimize({str(EXAMPLES / "parallel_hev.toml")!r}, "fu505", soc_grid_points=21, input_grid_points=11)
print(repr(seen))
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path
    )
    seen = ast.literal_eval(out.stdout.strip().splitlines()[-1])
    from hevsim.warmup import group

    assert seen == [(False, group("dp").label(), group("dp").cold_compile_s)]
    assert "compiling dynamic-programming" in out.stderr

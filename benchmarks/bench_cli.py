"""End-to-end timings of the ``hevsim`` command a person waits for (issue 10.5).

Run from anywhere (paths resolve from this file)::

    .venv/bin/python benchmarks/bench_cli.py [--repeats 5] [--threads-repeats 3]

What is measured (wall time of whole processes, ``time.perf_counter``; the first run of each
command is a warm-up and is not counted, so the numba cache and the OS file cache are warm):

(a) ``hevsim simulate examples/series_hev.toml --cycle udds --out DIR`` with all plots and
    the report. **Target: <= 3 s.**
(b) the same with ``--no-plots``. **Target: <= 1 s.**
(c) baseline, the floor of any ``hevsim simulate``: a process that only imports what the
    command imports (``hevsim.cli``, ``hevsim.sim.simulator``). Ratios (a)/(c) and (b)/(c)
    say how much of the wait is work rather than start-up.
(d) the seven plots in one process: today's figures (fixed margins, major grid, thinned
    lines) against the previous style measured in the same run (constrained layout and a
    minor grid, which the old ``report.plots`` used), median of ``--repeats``.
(e) with ``--dp``: ``hevsim optimize examples/parallel_hev.toml --no-plots`` with
    ``--threads 1`` and ``--threads 2``, then the same while two busy-loop processes run
    (started and killed by this script), median of ``--threads-repeats``.

Load: the 1-minute load average before and after, and the cores other processes used
(:class:`_machine.OtherLoad`). The script reports and never asserts: it always exits 0.
"""

from __future__ import annotations

import argparse
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import OtherLoad

ROOT = Path(__file__).resolve().parents[1]
HEVSIM = [sys.executable, "-m", "hevsim.cli"]
CONFIG = ROOT / "examples" / "series_hev.toml"
DP_CONFIG = ROOT / "examples" / "parallel_hev.toml"
TARGET_PLOTS_S = 3.0
TARGET_NO_PLOTS_S = 1.0


def _run(cmd: Sequence[str]) -> float:
    t0 = time.perf_counter()
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr[-2000:]}")
    return dt


def _median(fn: Callable[[], float], repeats: int, warmup: int = 1) -> tuple[float, float]:
    for _ in range(warmup):
        fn()
    times = [fn() for _ in range(repeats)]
    return statistics.median(times), min(times)


def _load() -> str:
    try:
        return "load average {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())
    except OSError:
        return "load average n/a"


def _plots_in_process(repeats: int, tmp: Path) -> tuple[float, float]:
    """(today's style, previous style) median seconds for the seven simulate plots."""
    from hevsim.config import load_config
    from hevsim.cycles import load_cycle
    from hevsim.report import plots as P
    from hevsim.sim.simulator import simulate

    cfg = load_config(CONFIG)
    result = simulate(cfg, load_cycle("udds"))
    result = pickle.loads(pickle.dumps(result))

    fast_figure, fast_grid = P.figure, P.grid  # (hevsim.figures' helpers, as report.plots calls them)

    def old_figure(nrows: int = 1, ncols: int = 1, margins_in: object = None, **kw: object) -> object:
        kw.pop("wspace", None)
        kw.pop("hspace", None)
        return fast_figure(nrows, ncols, None, **kw)  # constrained layout

    def old_grid(ax: object) -> None:
        ax.grid(True, which="major", alpha=0.4)  # type: ignore[attr-defined]
        ax.minorticks_on()  # type: ignore[attr-defined]
        ax.grid(True, which="minor", alpha=0.12)  # type: ignore[attr-defined]

    def new() -> float:
        t0 = time.perf_counter()
        P.plot_all(result, tmp / "new")
        return time.perf_counter() - t0

    def old() -> float:
        P.figure, P.grid = old_figure, old_grid  # type: ignore[assignment]
        try:
            t0 = time.perf_counter()
            P.plot_all(result, tmp / "old")
            return time.perf_counter() - t0
        finally:
            P.figure, P.grid = fast_figure, fast_grid

    new()
    old()
    t_new, t_old = [], []
    for _ in range(repeats):  # interleaved, so load changes hit both alike
        t_new.append(new())
        t_old.append(old())
    return statistics.median(t_new), statistics.median(t_old)


def _dp(threads: int, repeats: int, tmp: Path) -> float:
    cmd = [*HEVSIM, "optimize", str(DP_CONFIG), "--no-plots", "--threads", str(threads), "--force",
           "--out", str(tmp / f"dp{threads}")]  # fmt: skip
    return _median(lambda: _run(cmd), repeats)[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads-repeats", type=int, default=3)
    ap.add_argument("--dp", action="store_true", help="also time the DP with 1 and 2 threads, idle and busy")
    args = ap.parse_args()
    print(f"hevsim CLI timings, {os.cpu_count()} cores, Python {sys.version.split()[0]}; {_load()}")
    with tempfile.TemporaryDirectory(prefix="hevsim-bench-cli-") as d, OtherLoad() as load:
        tmp = Path(d)
        sim = [*HEVSIM, "simulate", str(CONFIG), "--cycle", "udds", "--force", "--out"]
        a = _median(lambda: _run([*sim, str(tmp / "a")]), args.repeats)
        b = _median(lambda: _run([*sim, str(tmp / "b"), "--no-plots"]), args.repeats)
        c = _median(
            lambda: _run([sys.executable, "-c", "import hevsim.cli, hevsim.sim.simulator"]), args.repeats
        )
        p_new, p_old = _plots_in_process(args.repeats, tmp)
        rows = [
            ("(a) simulate, all plots", a, TARGET_PLOTS_S),
            ("(b) simulate --no-plots", b, TARGET_NO_PLOTS_S),
            ("(c) baseline: imports only", c, None),
        ]
        print(f"\n{'':34}{'median s':>10}{'min s':>8}{'/ (c)':>8}  target")
        for label, (med, mn), target in rows:
            verdict = "" if target is None else f"<= {target:g} s: {'met' if med <= target else 'NOT met'}"
            print(f"{label:34}{med:>10.2f}{mn:>8.2f}{med / c[0]:>8.2f}  {verdict}")
        print(f"\n(d) seven plots in-process: {p_new:.2f} s now vs {p_old:.2f} s in the previous style "
              f"(ratio {p_new / p_old:.2f})")  # fmt: skip
        if args.dp:
            print("\n(e) hevsim optimize examples/parallel_hev.toml --no-plots (median s)")
            idle = {n: _dp(n, args.threads_repeats, tmp) for n in (1, 2)}
            ratio = idle[2] / idle[1]
            print(
                f"    as found: 1 thread {idle[1]:.2f}, 2 threads {idle[2]:.2f} (2/1 {ratio:.2f}); {_load()}"
            )
            hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
            try:
                time.sleep(2.0)
                busy = {n: _dp(n, args.threads_repeats, tmp) for n in (1, 2)}
            finally:
                for h in hogs:
                    h.kill()
                    h.wait()
            print(f"    with 2 busy loops: 1 thread {busy[1]:.2f}, 2 threads {busy[2]:.2f} "
                  f"(2/1 = {busy[2] / busy[1]:.2f}); {_load()}")  # fmt: skip
    print(f"\n{load.text()}; {_load()}")


if __name__ == "__main__":
    main()

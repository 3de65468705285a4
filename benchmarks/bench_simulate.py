"""Time hevsim against FASTSim 3 on one UDDS run, and hevsim's batch throughput.

Run from the repository root (or anywhere; paths are resolved from this file)::

    .venv/bin/python benchmarks/bench_simulate.py [--repeats 50] [--variants 1000]

What is timed (``time.perf_counter``, loading always excluded):

(a) ``hevsim.sim.simulator.simulate(hev, cyc)`` end to end: cycle resampling, the compiled
    kernel and assembly of the pandas result (time series, events, metrics);
(a') ``simulate("examples/series_hev.toml", "udds")`` from the path, as a user calls it, with
    the parsed-file cache (:func:`hevsim.io.cached_by_content`) warm and cleared before each
    call (every file parsed again: the time before the cache);
(b) the compiled run alone (the series plug-in of the one loop,
    ``hevsim.sim._compiled_series.run_compiled``; ``run_series`` in a tree before it), called
    exactly as ``simulate`` calls it (recording the time series);
(c) FASTSim 3's bundled 2016 Toyota Prius on its bundled UDDS: a fresh ``SimDrive`` per
    repetition, timing ``run()`` (``walk()`` in older 3.x); ``run_once()`` is shown too;
(d) ``simulate_batch`` with N mass variants and N driver-gain variants.

Issue 24's goals, as ratios to FASTSim's ``run_once()`` in the same run: (a) <= 0.1, (a')
with the cache warm <= 0.2. ``--baseline-src DIR`` also times (a), (a') and (b) for the
hevsim source tree in ``DIR`` (e.g. a copy of ``src`` before a change) in a child process
right after this tree's, so the before and after figures come from the same run.

Single-run numbers are medians of ``--repeats`` runs after warm-up; the first call in this
process (numba cache load, or compilation when the cache is cold) is reported separately.
The script only reports: it always exits 0.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from _machine import OtherLoad

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / "examples" / "series_hev.toml"
TARGET_RATIO = 0.2  # hevsim single run at most 1/5 of FASTSim's time
GOAL_MODEL = 0.1  # issue 24: simulate(built model, loaded cycle) <= 0.1x FASTSim run_once()
GOAL_PATH = 0.2  # issue 24: simulate("examples/x.toml", "udds"), cache warm, <= 0.2x run_once()
TARGET_RATE = 1000.0  # variant-cycles per second
FASTSIM_VEHICLE = "2016_TOYOTA_Prius_Two.yaml"
FASTSIM_CYCLE = "udds.csv"


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:9.3f}"


def _median(xs: list[float]) -> float:
    return statistics.median(xs) if xs else float("nan")


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _loadavg() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def _cache_state(dispatcher: Any) -> str:
    """'loaded from disk cache' / 'compiled' from a numba dispatcher's compile stats."""
    stats = getattr(dispatcher, "stats", None)
    if stats is None:
        return "unknown"
    hits, misses = sum(stats.cache_hits.values()), sum(stats.cache_misses.values())
    if hits and not misses:
        return "loaded from disk cache"
    if misses and not hits:
        return "compiled (disk cache was cold)"
    return f"cache hits {hits}, misses {misses}"


def machine_info() -> None:
    import numba
    import pandas as pd

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print("Machine")
    print(f"  cpu            : {_cpu_model()}")
    print(f"  cores          : {cores} usable ({os.cpu_count()} logical)")
    print(f"  os             : {platform.platform()}")
    print(f"  python         : {platform.python_version()} ({sys.executable})")
    print(f"  numpy          : {np.__version__}")
    print(f"  pandas         : {pd.__version__}")
    print(f"  numba          : {numba.__version__} (threads: {numba.get_num_threads()})")
    print(f"  load average   : {_loadavg()} (1, 5, 15 min; other jobs skew timings)")
    print()


# --------------------------------------------------------------------------- hevsim single run
def _series_kernel() -> tuple[Any, Any, Any]:
    """(the series run ``simulate`` calls with ``kernel_inputs``' arguments, the dispatcher
    whose cache tells whether it is compiled, the batch's): the series plug-in of the one loop
    (issue 24 item 2), or, in a baseline tree before it, its own loop ``run_series``."""
    try:
        from hevsim.sim._compiled_series import _batch, run_compiled
        from hevsim.sim._loop import run_loop

        return run_compiled, run_loop, _batch
    except ImportError:
        from hevsim.sim import kernel as K

        return K.run_series, K.run_series, K.run_series_batch


def bench_hevsim(repeats: int) -> dict[str, Any]:
    t0 = time.perf_counter()
    from hevsim.config import load_config
    from hevsim.cycles import load_cycle
    from hevsim.sim.model import build_series_hev
    from hevsim.sim.simulator import kernel_inputs, simulate

    run_kernel, probe, _ = _series_kernel()

    t_import = time.perf_counter() - t0

    # Loading (excluded from all timings below).
    hev = build_series_hev(load_config(CONFIG))
    cyc = load_cycle("udds")

    # First call in this process: loads the compiled kernel from numba's disk cache.
    t0 = time.perf_counter()
    res = simulate(hev, cyc)
    first = time.perf_counter() - t0
    first_kernel = float(res.metadata["kernel_time_s"])
    cache = _cache_state(probe)
    for _ in range(3):
        simulate(hev, cyc)

    # (a) end to end, split into prepare / kernel / assemble using simulate()'s own stamps.
    wall, kern, prep, asm = [], [], [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = simulate(hev, cyc)
        dt = time.perf_counter() - t0
        wall.append(dt)
        kern.append(float(res.metadata["kernel_time_s"]))
        prep.append(float(res.metadata["total_time_s"]) - kern[-1])
        asm.append(dt - float(res.metadata["total_time_s"]))

    # (a') from the vehicle file's path, as a user calls it: the parsed-file cache
    # (hevsim.io.cached_by_content) warm, and cleared before each call (every file parsed
    # again, as before the cache)
    from hevsim.io import clear_content_cache

    path_warm, path_cold = [], []
    simulate(CONFIG, "udds")
    for _ in range(repeats):
        t0 = time.perf_counter()
        simulate(CONFIG, "udds")
        path_warm.append(time.perf_counter() - t0)
    for _ in range(max(3, repeats // 5)):
        clear_content_cache()
        t0 = time.perf_counter()
        simulate(CONFIG, "udds")
        path_cold.append(time.perf_counter() - t0)

    # (b) kernel alone, called as simulate() calls it (same arrays, so same cached signature).
    _hev, _cyc, _dt, args = kernel_inputs(hev, cyc)
    out, energy, summary = args[-3], args[-2], args[-1]
    for _ in range(3):
        run_kernel(*args)
    kernel_alone = []
    for _ in range(repeats):
        out.fill(0.0)
        energy.fill(0.0)
        summary.fill(0.0)
        t0 = time.perf_counter()
        run_kernel(*args)
        kernel_alone.append(time.perf_counter() - t0)

    return {
        "import_s": t_import,
        "first_s": first,
        "first_kernel_s": first_kernel,
        "cache": cache,
        "steps": len(args[6]) - 1,
        "dt_s": _dt,
        "e2e": wall,
        "e2e_kernel": kern,
        "e2e_prepare": prep,
        "e2e_assemble": asm,
        "kernel": kernel_alone,
        "path_warm": path_warm,
        "path_cold": path_cold,
        "mpg": res.value("mpg"),
        "hev": hev,
        "cyc": cyc,
    }


def bench_baseline(src: str, repeats: int) -> dict[str, Any] | None:
    """(a), (a'), (b) medians [s] of the hevsim in source tree ``src``, timed in a child
    process (this script with ``--child-json``); None when it fails."""
    import json
    import subprocess

    env = {**os.environ, "PYTHONPATH": str(Path(src).resolve())}
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child-json", "--repeats", str(repeats)]
    try:
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=1800, check=True)
        return dict(json.loads(done.stdout.strip().splitlines()[-1]))
    except (subprocess.SubprocessError, ValueError, IndexError) as exc:
        print(f"baseline {src}: failed ({type(exc).__name__}: {exc})", file=sys.stderr)
        return None


def child_json(repeats: int) -> None:
    """Print one JSON line of this process's hevsim medians (for :func:`bench_baseline`)."""
    import json

    import hevsim

    h = bench_hevsim(repeats)
    keys = ("e2e", "path_warm", "path_cold", "kernel")
    mins = {f"{k}_min": min(h[k]) for k in keys}
    print(json.dumps({"src": str(Path(hevsim.__file__).parent), **{k: _median(h[k]) for k in keys}, **mins}))


# --------------------------------------------------------------------------- FASTSim
def bench_fastsim(repeats: int) -> dict[str, Any] | None:
    t0 = time.perf_counter()
    try:
        import fastsim as fsim
    except ImportError:
        return None
    t_import = time.perf_counter() - t0

    # Loading (excluded).
    veh = fsim.Vehicle.from_resource(FASTSIM_VEHICLE)
    cyc = fsim.Cycle.from_resource(FASTSIM_CYCLE)

    # FASTSim 3.1 renamed walk() to run() (walk() is a deprecated alias); 3.0 has only walk().
    def full(sd: Any) -> None:
        (sd.run if hasattr(sd, "run") else sd.walk)()

    def once(sd: Any) -> None:
        (sd.run_once if hasattr(sd, "run_once") else sd.walk_once)()

    def timed(step: Callable[[Any], None]) -> tuple[float, list[float]]:
        sd = fsim.SimDrive(veh, cyc)
        t0 = time.perf_counter()
        step(sd)
        first = time.perf_counter() - t0
        for _ in range(3):
            step(fsim.SimDrive(veh, cyc))
        times = []
        for _ in range(repeats):
            sd = fsim.SimDrive(veh, cyc)  # fresh state each repetition (construction untimed)
            t0 = time.perf_counter()
            step(sd)
            times.append(time.perf_counter() - t0)
        return first, times

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        first, run_times = timed(full)
        _, once_times = timed(once)
        sd = fsim.SimDrive(veh, cyc)
        t0 = time.perf_counter()
        for _ in range(repeats):
            fsim.SimDrive(veh, cyc)
        ctor = (time.perf_counter() - t0) / max(repeats, 1)
        full(sd)
        d = sd.to_dict()

    steps = int(d["veh"]["state"]["i"])
    soc_iters = None
    pt = d["veh"].get("pt_type", {})
    if isinstance(pt, dict) and isinstance(pt.get("HEV"), dict):
        soc_iters = pt["HEV"].get("soc_bal_iters")
    return {
        "version": getattr(fsim, "__version__", "?"),
        "import_s": t_import,
        "first_s": first,
        "run": run_times,
        "run_once": once_times,
        "ctor_s": ctor,
        "steps": steps,
        "soc_bal_iters": soc_iters,
        "dist_m": float(d["veh"]["state"]["dist_meters"]),
    }


# --------------------------------------------------------------------------- batch
def bench_batch(hev: Any, cyc: Any, variants: int, repeats: int) -> list[dict[str, Any]]:
    from hevsim.sim.simulator import simulate_batch

    batch_probe = _series_kernel()[2]

    cases = [
        ("mass_kg", np.linspace(1000.0, 2000.0, variants), "1000..2000 kg"),
        ("driver_gain_per_mps", np.linspace(0.5, 2.0, variants), "0.5..2 /(m/s)"),
    ]
    rows = []
    first_done = False
    for name, values, span in cases:
        t0 = time.perf_counter()
        simulate_batch(hev, {name: values}, cyc)  # warm-up (first: loads the parallel kernel)
        warm = time.perf_counter() - t0
        row: dict[str, Any] = {"name": name, "span": span, "n": variants}
        if not first_done:
            row["first_s"] = warm
            row["cache"] = _cache_state(batch_probe)
            first_done = True
        wall, kern = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            b = simulate_batch(hev, {name: values}, cyc)
            wall.append(time.perf_counter() - t0)
            kern.append(b.elapsed_s)
        row["wall_s"] = _median(wall)
        row["kernel_s"] = _median(kern)
        row["rate_wall"] = variants / row["wall_s"]
        row["rate_kernel"] = variants / row["kernel_s"]
        row["rate_wall_best"] = variants / min(wall)
        rows.append(row)
    return rows


# --------------------------------------------------------------------------- report
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=50, help="single-run repetitions (median)")
    ap.add_argument("--variants", type=int, default=1000, help="variants per batch")
    ap.add_argument("--batch-repeats", type=int, default=5, help="timed batches per case")
    ap.add_argument("--no-fastsim", action="store_true", help="skip FASTSim even if installed")
    ap.add_argument(
        "--baseline-src", help="also time (a), (a'), (b) of the hevsim source tree in this folder"
    )
    ap.add_argument("--child-json", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    repeats = max(1, a.repeats)
    if a.child_json:
        child_json(repeats)
        return 0

    t_start = time.perf_counter()
    print(f"hevsim benchmark: one UDDS run, {repeats} repetitions (median), loading excluded\n")
    machine_info()

    with OtherLoad() as single_load:
        h = bench_hevsim(repeats)
        base = bench_baseline(a.baseline_src, repeats) if a.baseline_src else None
        f = None if a.no_fastsim else bench_fastsim(repeats)

    print("First call in this process")
    print(f"  import hevsim          : {_ms(h['import_s'])} ms")
    print(
        f"  hevsim simulate()      : {_ms(h['first_s'])} ms "
        f"(kernel {h['first_kernel_s'] * 1e3:.1f} ms; numba kernel {h['cache']})"
    )
    if f is not None:
        print(f"  import fastsim         : {_ms(f['import_s'])} ms")
        print(f"  FASTSim run()          : {_ms(f['first_s'])} ms")
    print()

    e2e, kern = _median(h["e2e"]), _median(h["kernel"])
    print(
        f"Single UDDS run (hevsim: default series HEV, dt {h['dt_s']:g} s, {h['steps']} steps, "
        f"{h['mpg']:.1f} mpg)"
    )
    hdr = f"  {'':50s} {'median ms':>9s} {'min ms':>9s}"
    if f is not None:
        hdr += f" {'/FASTSim':>9s} {'/run_once':>9s}"
    print(hdr)

    def line(label: str, xs: list[float], ratio: bool = False) -> None:
        s = f"  {label:50s} {_ms(_median(xs))} {_ms(min(xs))}"
        if f is not None and ratio:
            s += f" {_median(xs) / _median(f['run']):9.3f} {_median(xs) / _median(f['run_once']):9.3f}"
        print(s)

    line("(a) hevsim simulate() end to end", h["e2e"], ratio=True)
    line("      prepare (resample cycle, params, tables)", h["e2e_prepare"])
    line("      compiled run (inside simulate)", h["e2e_kernel"])
    line("      assemble result (pandas, events, metrics)", h["e2e_assemble"])
    line("(a') simulate(path, 'udds'), parsed files cached", h["path_warm"], ratio=True)
    line("     the same, cache cleared before each call", h["path_cold"], ratio=True)
    line("(b) hevsim compiled run alone", h["kernel"], ratio=True)
    if f is not None:
        soc = f" ({f['soc_bal_iters']} SOC-balance passes)" if f["soc_bal_iters"] else ""
        line(f"(c) FASTSim {f['version']} Prius UDDS run() = walk()", f["run"])
        print(f"      {f['steps']} steps of 1 s, {f['dist_m'] / 1e3:.2f} km{soc}")
        line("    FASTSim run_once() (one pass, no SOC balance)", f["run_once"])
        print(f"      SimDrive(veh, cyc) construction (untimed above): {f['ctor_s'] * 1e3:.3f} ms")
    if base is not None:
        import hevsim

        print(f"  baseline {base['src']} (this tree: {Path(hevsim.__file__).parent}):")
        rows = (
            ("(a) end to end", "e2e"),
            ("(a') from the path, cache warm", "path_warm"),
            ("(a') from the path, cache cleared", "path_cold"),
            ("(b) kernel alone", "kernel"),
        )
        for label, key in rows:
            now = _median(h[key])
            s = f"    {label:36s} {base[key] * 1e3:8.3f} ms -> {now * 1e3:8.3f} ms ({now / base[key]:.2f}x)"
            if f is not None:
                ro, ro_min = _median(f["run_once"]), min(f["run_once"])
                s += f"; /run_once {base[key] / ro:.3f} -> {now / ro:.3f}"
                s += f" (minima: {base[key + '_min'] / ro_min:.3f} -> {min(h[key]) / ro_min:.3f})"
            print(s)
    print()
    print(f"  {single_load.text()}")
    asm_share = _median(h["e2e_assemble"]) / e2e
    print(f"  result assembly is {asm_share:.0%} of hevsim's end-to-end time")
    if f is not None:
        ref = _median(f["run"])
        for label, x in (("(a) end to end", e2e), ("(b) kernel alone", kern)):
            ok = "MET" if x / ref <= TARGET_RATIO else "NOT met"
            print(
                f"  target hevsim <= 1/5 of FASTSim run(), {label:17s}: {ok} "
                f"(ratio {x / ref:.3f}, {ref / x:.1f}x faster)"
            )
        ro, ro_min = _median(f["run_once"]), min(f["run_once"])
        for label, key, goal in (
            ("(a) built model", "e2e", GOAL_MODEL),
            ("(a') path, cache warm", "path_warm", GOAL_PATH),
        ):
            x, x_min = _median(h[key]), min(h[key])
            ok = "MET" if x / ro <= goal else "NOT met"
            print(
                f"  issue 24 goal {label:22s} <= {goal:g}x FASTSim run_once(): {ok} (ratio of medians "
                f"{x / ro:.3f}; of minima {x_min / ro_min:.3f}, less hit by other load)"
            )
    else:
        print(
            "  FASTSim: skipped (package 'fastsim' not importable). Install it with\n"
            "    .venv/bin/pip install -e '.[bench]'    (or: pip install 'fastsim>=3')"
        )
    print()

    with OtherLoad() as batch_load:
        rows = bench_batch(h["hev"], h["cyc"], max(1, a.variants), max(1, a.batch_repeats))
    print(
        f"Batch: simulate_batch() with {a.variants} variants on UDDS "
        f"(median of {max(1, a.batch_repeats)} after one warm-up batch)"
    )
    r0 = rows[0]
    print(f"  first batch in this process: {r0['first_s']:.3f} s (parallel kernel {r0['cache']})")
    print(
        f"  {'variant':22s} {'range':15s} {'call s':>8s} {'kernel s':>9s} "
        f"{'rate/s (call)':>14s} {'rate/s (kernel)':>16s} {'best/s (call)':>14s}"
    )
    for r in rows:
        print(
            f"  {r['name']:22s} {r['span']:15s} {r['wall_s']:8.3f} {r['kernel_s']:9.3f} "
            f"{r['rate_wall']:14.0f} {r['rate_kernel']:16.0f} {r['rate_wall_best']:14.0f}"
        )
    for r in rows:
        ok = "MET" if r["rate_wall"] >= TARGET_RATE else "NOT met"
        print(
            f"  target >= {TARGET_RATE:.0f} variant-cycles/s ({r['name']}, whole call): {ok} "
            f"(median {r['rate_wall']:.0f}/s)"
        )
    print(f"  {batch_load.text()}")
    print()
    print(f"load average now: {_loadavg()}; benchmark took {time.perf_counter() - t_start:.1f} s")
    return 0


if __name__ == "__main__":
    try:
        main()
    except Exception as exc:  # report, never fail the caller
        print(f"benchmark error: {type(exc).__name__}: {exc}", file=sys.stderr)
    sys.exit(0)

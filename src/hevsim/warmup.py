"""Which numba kernels a run compiles, how long that takes, and compiling them ahead of use.

numba compiles a kernel the first time a process calls it and keeps the machine code in its
on-disk cache (:mod:`hevsim._numba_cache`: one folder per version of hevsim's compiled code),
so only the first run after an install or an update pays the compilation. :data:`GROUPS` is
the registry of the kernel groups (:mod:`hevsim.kernel_groups`, re-exported here): the kernels
one kind of run compiles together, the kernels called from Python whose cache index tells
whether the group is compiled (``entries``), the runs that need it (``serves``), the measured
compile time on an empty cache (``cold_compile_s``, from ``benchmarks/bench_compile.py``);
:data:`WARM` holds the smallest real run that compiles each (a shipped example over the first
:data:`WARMUP_CYCLE_S` of UDDS).

* :func:`run_groups` names the groups a forward run of a configuration uses, and
  :func:`compile_notice_for` prints ``compiling ..., once: about ...`` before such a run
  only when one of them is cold (``hevsim simulate``).
* :func:`compile_groups` (``hevsim compile``) runs the warm-up of every group (or those
  named) in ``jobs`` processes at once (numba compiles on one thread), one line per group.

The warm-up runs use the repository's ``examples/`` (a clone or a development install);
:func:`examples_dir` finds them, ``--examples DIR`` points elsewhere.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hevsim.errors import ConfigError
from hevsim.guards import MB, SIM_TALK_STEPS, check_simulation
from hevsim.kernel_groups import (  # re-exported: the registry of groups lives in the ground layer
    GROUPS,
    KernelGroup,
    cache_probe,
    compile_notice_for,
    format_groups,
    group,
    run_groups,
    specialisation_probe,
)

__all__ = [
    "GROUPS", "WARM", "WARMUP_CYCLE_S", "Compiled", "KernelGroup", "cache_probe", "compile_groups",
    "compile_notice_for", "default_jobs", "examples_dir", "format_groups", "group", "run_groups",
    "simulation_preflight", "specialisation_probe", "warm_group",
]  # fmt: skip

WARMUP_CYCLE_S = 60.0
"""Length of the UDDS start the warm-up runs drive [s] (long enough to leave standstill: the
compiled code does not depend on it, the run time does)."""

EXAMPLES_ENV = "HEVSIM_EXAMPLES"
"""Environment variable: the folder of the example configurations the warm-up runs use."""


def examples_dir(explicit: str | Path | None = None) -> Path:
    """The folder of the example vehicle files: ``explicit``, else ``$HEVSIM_EXAMPLES``, else
    ``examples/`` of the repository holding this package (``src/hevsim/../../examples``).
    Raises :class:`~hevsim.errors.ConfigError` naming where it looked."""
    chosen = explicit or os.environ.get(EXAMPLES_ENV)
    folder = Path(chosen) if chosen else Path(__file__).resolve().parents[2] / "examples"
    if not (folder / "series_hev.toml").is_file():
        how = "--examples" if explicit else (EXAMPLES_ENV if chosen else "the repository's examples/")
        raise ConfigError(
            f"{how}: {folder} holds no series_hev.toml; expected the hevsim repository's examples/ "
            "folder (the warm-up runs drive its vehicles); give it with --examples DIR."
        )
    return folder


def _cycle() -> Any:
    from hevsim.cycles import DriveCycle, load_cycle

    udds = load_cycle("udds")
    keep = udds.time_s <= udds.time_s[0] + WARMUP_CYCLE_S
    return DriveCycle(
        "udds_start",
        udds.time_s[keep],
        udds.speed_mps[keep],
        udds.grade[keep],
        f"first {WARMUP_CYCLE_S:g} s of UDDS (kernel warm-up)",
        udds.source,
    )


def _forward(examples: Path, *files: str, compiled: bool = True) -> None:
    from hevsim.architectures import architecture
    from hevsim.config import load_vehicle_config

    for f in files:
        cfg = load_vehicle_config(examples / f)
        architecture(cfg.architecture).simulate(cfg, _cycle(), **({} if compiled else {"compiled": False}))


def _warm_series(examples: Path) -> None:
    _forward(examples, "series_hev.toml")


def _warm_parallel(examples: Path) -> None:
    _forward(examples, "parallel_hev.toml")


def _warm_power_split(examples: Path) -> None:
    _forward(examples, "prius_like_power_split.toml")


def _warm_conventional(examples: Path) -> None:
    _forward(examples, "conventional_sedan.toml")


def _warm_bev(examples: Path) -> None:
    _forward(examples, "bev.toml")


def _warm_fcev(examples: Path) -> None:
    _forward(examples, "fcev.toml")


def _warm_power_flow(examples: Path) -> None:
    names = ("parallel_hev.toml", "prius_like_power_split.toml", "conventional_sedan.toml", "bev.toml")
    _forward(examples, *names, compiled=False)


def _warm_pack(examples: Path) -> None:
    from hevsim.sim.pack_vehicle import simulate_pack_vehicle

    for f in ("series_hev_pack.toml", "parallel_hev_pack.toml"):
        simulate_pack_vehicle(examples / f, _cycle())


def _warm_batch(examples: Path) -> None:
    import numpy as np

    from hevsim.config import load_vehicle_config
    from hevsim.sim.simulator import simulate_batch

    simulate_batch(
        load_vehicle_config(examples / "series_hev.toml"), {"mass_kg": np.array([1500.0, 1600.0])}, _cycle()
    )
    for f in ("conventional_sedan.toml", "parallel_hev.toml"):
        simulate_batch(
            load_vehicle_config(examples / f), {"body.mass_kg": np.array([1400.0, 1500.0])}, _cycle()
        )


def _warm_dp(examples: Path) -> None:
    from hevsim.optimal.hev import optimize

    for f in ("parallel_hev.toml", "series_hev.toml"):
        optimize(examples / f, _cycle(), soc_grid_points=21, progress=False, threads=1)


WARM: dict[str, Callable[[Path], None]] = {
    "series": _warm_series,
    "parallel": _warm_parallel,
    "power_split": _warm_power_split,
    "conventional": _warm_conventional,
    "bev": _warm_bev,
    "fcev": _warm_fcev,
    "power_flow": _warm_power_flow,
    "pack": _warm_pack,
    "batch": _warm_batch,
    "dp": _warm_dp,
}
"""The warm-up of each group of :data:`~hevsim.kernel_groups.GROUPS`: the smallest real run
that compiles it, given the examples folder (a shipped example over the first
:data:`WARMUP_CYCLE_S` of UDDS)."""


@dataclass(frozen=True)
class Compiled:
    """Outcome of one group's warm-up: ``was_cold`` before it, wall and CPU time [s], and the
    error message when it failed (empty otherwise)."""

    name: str
    was_cold: bool
    wall_s: float
    cpu_s: float
    error: str = ""


def warm_group(name: str, examples: str) -> Compiled:
    """Run the warm-up of group ``name`` in this process (a worker of :func:`compile_groups`)."""
    g = group(name)
    was_cold = g.is_cold()
    t0, c0 = time.perf_counter(), time.process_time()
    error = ""
    try:
        WARM[g.name](Path(examples))
    except Exception as exc:  # reported by the parent with the group's name
        error = f"{type(exc).__name__}: {exc}"
    return Compiled(name, was_cold, time.perf_counter() - t0, time.process_time() - c0, error)


def default_jobs() -> int:
    """Processes of ``hevsim compile``: the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def compile_groups(
    names: Sequence[str] | None = None, jobs: int | None = None, examples: str | Path | None = None
) -> list[Compiled]:
    """Compile (fill the numba cache of) the groups ``names`` (default: all) in ``jobs``
    processes (default :func:`default_jobs`), the longest first; one progress line per group
    as it ends. Returns the outcomes in the order they ended."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    from hevsim.progress import format_duration, stage

    chosen = [group(n) for n in names] if names else list(GROUPS)
    folder = str(examples_dir(examples))
    n_jobs = default_jobs() if jobs is None else int(jobs)
    if n_jobs < 1:
        raise ConfigError(f"--jobs = {n_jobs}; expected a number of processes >= 1.")
    chosen.sort(key=lambda g: -g.cold_compile_s)
    n_jobs = min(n_jobs, len(chosen))
    listed = ", ".join(g.name for g in chosen)
    stage(f"compiling {len(chosen)} kernel group(s) in {n_jobs} process(es): {listed}")
    t0 = time.perf_counter()
    done: list[Compiled] = []
    ctx = multiprocessing.get_context("spawn")  # a fresh interpreter: no numba state inherited
    with ProcessPoolExecutor(max_workers=n_jobs, mp_context=ctx) as pool:
        futures = [pool.submit(warm_group, g.name, folder) for g in chosen]
        for fut in as_completed(futures):
            r = fut.result()
            done.append(r)
            how = "compiled" if r.was_cold else "loaded from the cache"
            tail = f"FAILED: {r.error}" if r.error else f"{how} in {format_duration(r.wall_s)}"
            stage(
                f"[{len(done)}/{len(chosen)}] {r.name}: {tail} (CPU {format_duration(r.cpu_s)}, "
                f"{format_duration(time.perf_counter() - t0)} elapsed)"
            )
    return done


def simulation_preflight(cfg: object, cycle: object, dt_s: float | None) -> None:
    """Before ``hevsim simulate``: refuse a run that would not fit in memory
    (:func:`check_simulation`), say what a long run will take, and warn before numba compiles
    the kernels this run uses (:func:`run_groups`) on a cold cache."""
    from hevsim.progress import format_duration, stage

    c: object = cycle
    t = getattr(c, "time_s", None)
    dt = float(dt_s if dt_s is not None else getattr(getattr(cfg, "simulation", None), "dt_s", 0.0) or 0.0)
    if t is None or dt <= 0.0 or len(t) < 2:
        return
    n_steps = int((float(t[-1]) - float(t[0])) / dt) + 1
    label = f"{getattr(cfg, 'name', 'vehicle')} on {getattr(c, 'name', 'cycle')}"
    need, seconds = check_simulation(n_steps, label)
    if n_steps >= SIM_TALK_STEPS:
        stage(
            f"simulating {label}: {n_steps:,} steps, about {format_duration(seconds)} and {need / MB:,.0f} MB"
        )
    from hevsim.config import SERIES_ONLINE_CONTROLLERS
    from hevsim.sim.forward import use_compiled

    kind = getattr(getattr(cfg, "controller", None), "kind", None)
    compile_notice_for(
        run_groups(cfg, python_loop=not use_compiled(None), series_online=kind in SERIES_ONLINE_CONTROLLERS)
    )

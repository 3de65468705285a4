"""Which numba kernels a run compiles, how long that takes, and compiling them ahead of use.

numba compiles a kernel the first time a process calls it and keeps the machine code in its
on-disk cache (:mod:`hevsim._numba_cache`: one folder per version of hevsim's compiled code),
so only the first run after an install or an update pays the compilation. :data:`GROUPS` is
the registry of the kernel groups: the kernels one kind of run compiles together, the kernels
called from Python whose cache index tells whether the group is compiled (``entries``), the
runs that need it (``serves``), the measured compile time on an empty cache
(``cold_compile_s``, from ``benchmarks/bench_compile.py``) and the smallest real run that
compiles it (``warm``: a shipped example over the first :data:`WARMUP_CYCLE_S` of UDDS).

* :func:`run_groups` names the groups a forward run of a configuration uses, and
  :func:`compile_notice_for` prints ``compiling ..., once: about ...`` before such a run
  only when one of them is cold (``hevsim simulate``).
* :func:`compile_groups` (``hevsim compile``) runs the warm-up of every group (or those
  named) in ``jobs`` processes at once (numba compiles on one thread), one line per group.

The warm-up runs use the repository's ``examples/`` (a clone or a development install);
:func:`examples_dir` finds them, ``--examples DIR`` points elsewhere.
"""

from __future__ import annotations

import importlib
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from hevsim.errors import ConfigError

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
    from hevsim.config import load_vehicle_config
    from hevsim.sim.forward import simulate_architecture
    from hevsim.sim.simulator import simulate

    for f in files:
        cfg = load_vehicle_config(examples / f)
        if cfg.architecture == "series":
            simulate(cfg, _cycle())
        else:
            simulate_architecture(cfg.architecture, cfg, _cycle(), compiled=compiled)


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


def cache_probe(module: str, name: str) -> Any:
    """A stand-in for the numba dispatcher ``module.name`` (``cache=True``) holding the same
    on-disk cache object (``_cache``), made without importing ``module``: numba's cache is
    located from the source file and the first line of the function (its first decorator)."""
    import ast
    import importlib.util
    import types

    from numba.core.caching import FunctionCache

    spec = importlib.util.find_spec(module)
    if spec is None or not spec.origin:
        raise ModuleNotFoundError(module)
    source = Path(spec.origin)
    tree = ast.parse(source.read_text())
    found = [n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == name]
    if not found:
        raise AttributeError(f"{module} has no function {name!r}")
    node = found[0]
    first_line = min([node.lineno, *(d.lineno for d in node.decorator_list)])
    code = compile("\n" * (first_line - 1) + "def f(): pass", str(source), "exec").co_consts[0]
    func = types.FunctionType(code, {})
    func.__qualname__ = func.__name__ = name
    func.__module__ = module
    return types.SimpleNamespace(_cache=FunctionCache(func))


def specialisation_probe(dispatcher: Any, none_arg: int) -> Any:
    """A stand-in for ``dispatcher`` whose cache index holds only the compiled versions whose
    argument ``none_arg`` is None (numba's index keys start with the signature)."""
    import types

    cache_file = dispatcher._cache._cache_file

    def load_index() -> dict[Any, Any]:
        out = {}
        for key, value in cache_file._load_index().items():
            sig = key[0] if isinstance(key, tuple) and key else ()
            if isinstance(sig, tuple) and len(sig) > none_arg and str(sig[none_arg]) == "none":
                out[key] = value
        return out

    index = types.SimpleNamespace(_index_path=cache_file._index_path, _load_index=load_index)
    return types.SimpleNamespace(_cache=types.SimpleNamespace(_cache_file=index))


@dataclass(frozen=True)
class KernelGroup:
    """Kernels compiled together by one kind of run.

    Attributes:
        name: short name (``hevsim compile --group NAME``).
        description: what they compute (a noun phrase: "compiling <description> kernels").
        entries: ``"module:function"`` of the kernels called from Python; their cache index
            says whether the group is compiled.
        serves: the runs needing the group: architecture names (a compiled forward run),
            ``"python_loop"`` (a forward run through the Python loop), ``"pack"``
            (``[battery] model = "pack"``), ``"batch"``, ``"dp"``.
        cold_compile_s: compile time of the group on an empty cache [s] (CPU time of the
            warm-up run in a fresh process, ``benchmarks/bench_compile.py``).
        warm: runs the smallest real work that compiles the group, given the examples folder.
        none_arg: position of an argument of the entries that is None in this group's
            specialisation (a kernel compiled once per architecture, the other
            architecture's tables None); only those entries of the cache index count. -1:
            every entry counts.
    """

    name: str
    description: str
    entries: tuple[str, ...]
    serves: tuple[str, ...]
    cold_compile_s: float
    warm: Callable[[Path], None]
    none_arg: int = -1

    def dispatchers(self) -> list[Any]:
        """The numba dispatchers of :attr:`entries` (their modules imported)."""
        out = []
        for ref in self.entries:
            module, _, name = ref.partition(":")
            out.append(getattr(importlib.import_module(module), name))
        return out

    def probes(self) -> list[Any]:
        """What :func:`hevsim.progress.cache_is_cold` reads of :attr:`entries`: the dispatcher
        where its module is imported already, else :func:`cache_probe` (importing a module
        whose kernels compile eagerly, as the DP's, would compile them before any notice)."""
        out = []
        for ref in self.entries:
            module, _, name = ref.partition(":")
            loaded = sys.modules.get(module)
            probe = getattr(loaded, name) if loaded is not None else cache_probe(module, name)
            out.append(probe if self.none_arg < 0 else specialisation_probe(probe, self.none_arg))
        return out

    def is_cold(self) -> bool:
        """Whether the next run needing the group compiles it (:func:`hevsim.progress.cache_is_cold`)."""
        from hevsim.progress import cache_is_cold

        return cache_is_cold(self.probes())

    def label(self) -> str:
        """``"series HEV forward loop (run_series)"``."""
        return f"{self.description} ({', '.join(e.partition(':')[2] for e in self.entries)})"


# cold_compile_s: benchmarks/bench_compile.py on 2026-12-02, 2 cores, other processes 1.7-1.8
# cores: CPU time of the warm-up on an empty cache (series 19.6 s, parallel 33.1 s and power
# split 27.2 s after helper A's compile-time work, conventional 9.3 s, bev 15.1 s, power_flow
# 14.8 s, dp 50.4 s); pack 77.6 s - 48.5 s warm and batch
# 82.5 s - 29.4 s warm (CPU time of the same run on the filled cache: building the pack,
# running the variants).
GROUPS: tuple[KernelGroup, ...] = (
    KernelGroup(
        "series",
        "series HEV forward loop",
        ("hevsim.sim.kernel:run_series",),
        ("series",),
        20.0,
        _warm_series,
    ),
    KernelGroup(
        "parallel",
        "parallel HEV forward loop",
        ("hevsim.sim._compiled_hev:run_hev",),
        ("parallel",),
        33.0,
        _warm_parallel,
        none_arg=1,  # run_hev(dpar, dps = None, ...)
    ),
    KernelGroup(
        "power_split",
        "power-split HEV forward loop",
        ("hevsim.sim._compiled_hev:run_hev",),
        ("power_split",),
        27.0,
        _warm_power_split,
        none_arg=0,  # run_hev(dpar = None, dps, ...)
    ),
    KernelGroup(
        "conventional",
        "conventional vehicle forward loop",
        ("hevsim.sim._compiled_conventional:_run_variant",),
        ("conventional",),
        10.0,
        _warm_conventional,
    ),
    KernelGroup(
        "bev",
        "battery-electric vehicle forward loop",
        ("hevsim.sim._compiled_bev:run_bev",),
        ("bev",),
        15.0,
        _warm_bev,
    ),
    KernelGroup(
        "power_flow",
        "vectorised power-flow (Python loop, ECMS grid)",
        (
            "hevsim.architectures.parallel:_mechanical_many",
            "hevsim.architectures.power_split:_mechanical_many",
            "hevsim.architectures.conventional:_points_many",
            "hevsim.architectures.bev:_wheel_many",
        ),
        ("python_loop",),
        15.0,
        _warm_power_flow,
    ),
    KernelGroup(
        "pack",
        "battery pack step",
        ("hevsim.battery.pack_run:pack_begin", "hevsim.battery.pack_run:pack_finish"),
        ("pack",),
        30.0,
        _warm_pack,
    ),
    KernelGroup(
        "batch",
        "batch-of-variants",
        ("hevsim.sim.kernel:run_series_batch", "hevsim.sim._compiled_conventional:_run_batch"),
        ("batch",),
        55.0,
        _warm_batch,
    ),
    KernelGroup(
        "dp",
        "dynamic-programming stage",
        ("hevsim.optimal._kernels:_row_1d", "hevsim.optimal._hull:bellman_1d_hull"),
        ("dp",),
        50.0,
        _warm_dp,
    ),
)
"""Every kernel group, in the order ``hevsim compile`` lists them."""


def group(name: str) -> KernelGroup:
    """The group called ``name``; :class:`~hevsim.errors.ConfigError` listing the names otherwise."""
    for g in GROUPS:
        if g.name == name:
            return g
    raise ConfigError(
        f"kernel group {name!r} is unknown; expected one of: {', '.join(g.name for g in GROUPS)}."
    )


def run_groups(cfg: Any, python_loop: bool = False) -> list[KernelGroup]:
    """The groups a forward run of the vehicle configuration ``cfg`` compiles: its
    architecture's compiled loop, or the power flows of the Python loop (``python_loop``, or
    a pack battery outside the series HEV), plus the pack step for ``[battery] model =
    "pack"``."""
    arch = str(getattr(cfg, "architecture", "series"))
    pack = getattr(getattr(cfg, "battery", None), "model", None) == "pack"
    wanted = {"pack"} if pack else set()
    wanted.add("python_loop" if arch != "series" and (python_loop or pack) else arch)
    return [g for g in GROUPS if wanted.intersection(g.serves)]


def compile_notice_for(groups: Sequence[KernelGroup], stream: IO[str] | None = None) -> bool:
    """Print ``compiling <the cold groups>, once: about <their cold_compile_s>`` when any of
    ``groups`` is cold (once per process and set); return whether it printed."""
    from hevsim.progress import compile_notice

    cold = [g for g in groups if g.is_cold()]
    if not cold:
        return False
    what = " and ".join(g.label() for g in cold)
    return compile_notice(
        what,
        [d for g in cold for d in g.probes()],
        sum(g.cold_compile_s for g in cold),
        stream,
        hint="; the time is CPU time: longer on a busy machine; `hevsim compile` compiles every kernel ahead",
    )


def format_groups(groups: Sequence[KernelGroup]) -> str:
    """A table of ``groups``: name, cold or compiled in this cache, compile time on an empty
    cache, the runs needing it and the kernels probed."""
    from hevsim.progress import format_duration

    lines = [f"{'group':<13}{'state':<10}{'cold compile':>13}  {'needed by':<28}kernels"]
    for g in groups:
        state = "cold" if g.is_cold() else "compiled"
        lines.append(
            f"{g.name:<13}{state:<10}{format_duration(g.cold_compile_s):>13}  "
            f"{', '.join(g.serves):<28}{', '.join(g.entries)}"
        )
    return "\n".join(lines)


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
        g.warm(Path(examples))
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

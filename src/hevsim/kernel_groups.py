"""The numba kernel groups: which kernels one kind of run compiles together and how long that
takes on an empty cache (the registry :data:`GROUPS`), and the cold-cache notice before a run.

numba compiles a kernel the first time a process calls it and keeps the machine code in its
on-disk cache (:mod:`hevsim._numba_cache`), so only the first run after an install or an update
pays the compilation. Each group names the kernels called from Python whose cache index tells
whether the group is compiled (``entries``), the runs that need it (``serves``) and the measured
compile time on an empty cache (``cold_compile_s``, from ``benchmarks/bench_compile.py``).
Kernels are named by ``"module:function"`` and only probed (their cache index read), never
imported here, so this module sits in the ground layer and the simulator and the DP can print
the notice; the warm-up runs that fill the cache (``hevsim compile``) drive whole vehicles and
live above them, in :mod:`hevsim.warmup` (issue 24).

* :func:`run_groups` names the groups a forward run of a configuration uses, and
  :func:`compile_notice_for` prints ``compiling ..., once: about ...`` before such a run
  only when one of them is cold (``hevsim simulate``).
"""

from __future__ import annotations

import dataclasses
import importlib
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from hevsim.errors import ConfigError


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


def specialisation_probe(dispatcher: Any, first_arg: str = "", last_arg: str = "") -> Any:
    """A stand-in for ``dispatcher`` whose cache index holds only the compiled versions whose
    first argument's type name starts with ``first_arg`` (``""``: any; the one forward loop's
    plug-in, ``"ParallelPlug"``: the architecture) and whose last argument's type name starts
    with ``last_arg`` (``""``: any; ``"none"``, ``"PackArrays"``, ``"CellBusTables"``: the
    battery of a forward loop) (numba's index keys start with the signature)."""
    import types

    cache_file = dispatcher._cache._cache_file

    def wanted(sig: Any) -> bool:
        if not isinstance(sig, tuple):
            return False
        if first_arg and (len(sig) == 0 or not str(sig[0]).startswith(first_arg)):
            return False
        return not last_arg or (len(sig) > 0 and str(sig[-1]).startswith(last_arg))

    def load_index() -> dict[Any, Any]:
        out = {}
        for key, value in cache_file._load_index().items():
            if wanted(key[0] if isinstance(key, tuple) and key else ()):
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
        first_arg: type-name prefix of the entries' first argument that counts ("": any): the
            one forward loop (:func:`hevsim.sim._loop.run_loop`) is compiled once per
            architecture, its plug-in (``"ParallelPlug"``, ``"BEVPlug"``) first.
        battery_arg: whether the entries' last argument is the forward loop's battery step
            (None for a table battery, a pack's ``PackArrays``, a cell's ``CellBusTables``:
            each compiles the loop again); :func:`run_groups` then narrows the probe to the
            run's battery with ``last_arg``.
        last_arg: type-name prefix of the entries' last argument that counts ("": any).
    """

    name: str
    description: str
    entries: tuple[str, ...]
    serves: tuple[str, ...]
    cold_compile_s: float
    first_arg: str = ""
    battery_arg: bool = False
    last_arg: str = ""

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
            narrow = self.first_arg or self.last_arg
            out.append(specialisation_probe(probe, self.first_arg, self.last_arg) if narrow else probe)
        return out

    def is_cold(self) -> bool:
        """Whether the next run needing the group compiles it (:func:`hevsim.progress.cache_is_cold`)."""
        from hevsim.progress import cache_is_cold

        return cache_is_cold(self.probes())

    def label(self) -> str:
        """``"series HEV forward loop (run_loop)"``."""
        return f"{self.description} ({', '.join(e.partition(':')[2] for e in self.entries)})"


# cold_compile_s: benchmarks/bench_compile.py on 2026-12-02, 2 cores, other processes 1.7-1.8
# cores: CPU time of the warm-up on an empty cache (series 19.6 s, parallel 33.1 s and power
# split 27.2 s after helper A's compile-time work, conventional 9.3 s, bev 15.1 s, power_flow
# 14.8 s, dp 50.4 s); pack 77.6 s - 48.5 s warm and batch
# 82.5 s - 29.4 s warm (CPU time of the same run on the filled cache: building the pack,
# running the variants). The one compiled loop (issue 24 item 2, 2026-12-06, other processes
# 0.1-1.9 cores; the same run of the tree before it in brackets): parallel 20.9 s (19.3 s),
# power split 18.7 s (16.1 s), bev 39.5 s (8.1 s: the loop inlines the BEV's whole power flow at
# its four calls of the controller), fcev 22.1 s (new), conventional 16.5 s (6.2 s), batch
# 52.2 s (44.9 s). The series HEV in the one loop (its plug-in, 2026-12-06, other processes 0.6-1.0
# cores): series 15.3 s (11.0 s with its own loop run_series), batch 52.6 s (51.9 s).
GROUPS: tuple[KernelGroup, ...] = (
    KernelGroup(
        "series",
        "series HEV forward loop",
        ("hevsim.sim._loop:run_loop",),
        ("series",),
        20.0,
        first_arg="SeriesPlug",  # run_loop(plug, ..., pk): the loop's battery step, as every architecture's
        battery_arg=True,
    ),
    KernelGroup(
        "parallel",
        "parallel HEV forward loop",
        ("hevsim.sim._loop:run_loop",),
        ("parallel",),
        33.0,
        first_arg="ParallelPlug",  # run_loop(plug, ..., pk)
        battery_arg=True,
    ),
    KernelGroup(
        "power_split",
        "power-split HEV forward loop",
        ("hevsim.sim._loop:run_loop",),
        ("power_split",),
        27.0,
        first_arg="PowerSplitPlug",
        battery_arg=True,
    ),
    KernelGroup(
        "conventional",
        "conventional vehicle forward loop",
        ("hevsim.sim._compiled_conventional:_run_variant",),
        ("conventional",),
        17.0,
    ),
    KernelGroup(
        "bev",
        "battery-electric vehicle forward loop",
        ("hevsim.sim._loop:run_loop",),
        ("bev",),
        40.0,
        first_arg="BEVPlug",
        battery_arg=True,
    ),
    KernelGroup(
        "fcev",
        "fuel-cell vehicle forward loop",
        ("hevsim.sim._loop:run_loop",),
        ("fcev",),
        22.0,
        first_arg="FCEVPlug",
        battery_arg=True,
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
    ),
    KernelGroup(
        "pack",
        "battery pack step",
        ("hevsim.battery.pack_run:pack_begin", "hevsim.battery.pack_run:pack_finish"),
        ("pack",),
        30.0,
    ),
    KernelGroup(
        "batch",
        "batch-of-variants",
        ("hevsim.sim._compiled_series:_batch", "hevsim.sim._compiled_conventional:_run_batch"),
        ("batch",),
        55.0,
    ),
    KernelGroup(
        "dp",
        "dynamic-programming stage",
        ("hevsim.optimal._kernels:_row_1d", "hevsim.optimal._hull:bellman_1d_hull"),
        ("dp",),
        50.0,
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


BATTERY_STEPS: dict[str, tuple[str, str]] = {
    "pack": ("PackArrays", "with a battery pack"),
    "cell": ("CellBusTables", "with a cell battery"),
}
"""``[battery] model`` -> (type name of the compiled loops' battery argument, what the notice
adds to the loop's description); every other model runs the loop with None there."""


def run_groups(cfg: Any, python_loop: bool = False, series_online: bool = False) -> list[KernelGroup]:
    """The groups a forward run of the vehicle configuration ``cfg`` compiles: its
    architecture's compiled loop (for a loop taking the battery step, :attr:`KernelGroup.battery_arg`,
    its version for this battery model: a pack or a cell battery compiles the loop once more),
    or the power flows of the Python loop (``python_loop``, or ``series_online``: a series HEV
    with an online controller, which runs its quasi-static power flow in the Python loop),
    plus the pack step for ``[battery] model = "pack"``."""
    arch = str(getattr(cfg, "architecture", "series"))
    model = str(getattr(getattr(cfg, "battery", None), "model", ""))
    wanted = {"pack"} if model == "pack" else set()
    loop = series_online if arch == "series" else python_loop
    wanted.add("python_loop" if loop else arch)
    last_arg, what = BATTERY_STEPS.get(model, ("none", ""))
    out = []
    for g in GROUPS:
        if not wanted.intersection(g.serves):
            continue
        if g.battery_arg:
            description = f"{g.description} {what}" if what else g.description
            g = dataclasses.replace(g, last_arg=last_arg, description=description)
        out.append(g)
    return out


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

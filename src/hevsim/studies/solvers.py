"""Solvers a study can run per case, looked up by name in :data:`SOLVERS`.

A solver states the architectures it supports, checks its options, names the metrics it can
keep, prepares a picklable context once per study (in the client process), groups cases that
can share one task, and runs a batch of cases on a worker, returning one :class:`Outcome` per
case. A case that fails (invalid combination of values, infeasible cycle, solver error) gets
``status = "failed"`` and the error message; it never stops the study.

Registered here:

- ``simulate``: forward simulation of any architecture through
  :func:`hevsim.sim.simulator.simulate_batch`: the cases of a task run as parameter variants
  in one compiled call (series HEV: kernel parameters of one built model; other architectures:
  dotted configuration keys, :func:`hevsim.sim.forward.simulate_batch_architecture`).
  Options: ``controller`` (:func:`controller_choices`: ``"rule_based"`` = the architecture's
  rule-based controller, any ``[controller] kind`` it admits such as ``"ecms"`` or
  ``"aecms"``, and ``"ecms_dp"``: ECMS with the equivalence factor of the same case's DP,
  which needs an ``optimize`` solver in the study and uses its grids), ``dt_s``.
- ``optimize``: fuel-optimal energy management by dynamic programming
  (:func:`hevsim.optimal.optimize`). Options: ``soc_grid_points``, ``input_grid_points``,
  ``final_constraint``.
- ``performance``: the performance tests of :func:`hevsim.sim.performance.performance`
  (0-60 mph, 0-100 km/h, quarter mile, 50-80 mph, top speed, gradeability), one run per
  vehicle whatever the cycle (the rows of every cycle carry the same values). Options:
  ``dt_s``, ``soc``, ``grade_speed_mph``.

:func:`register_solver` adds a solver.
"""

from __future__ import annotations

import dataclasses
import pickle
import time
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hevsim.errors import ConfigError, HevsimError

OK, FAILED = "ok", "failed"
"""Values of the ``status`` column."""


@dataclass(frozen=True)
class Outcome:
    """Result of one case: status, error message ("" when ok), kept metrics, wall time [s]."""

    status: str
    error: str
    metrics: dict[str, float]
    wall_time_s: float


@dataclass(frozen=True)
class Solver:
    """A registered study solver (see the module docstring for the roles of the callables).

    Attributes:
        name: registry key (``name`` of a ``[[solvers]]`` table).
        architectures: architectures it supports: a tuple of names, or a callable returning
            them from the registry on every call (an architecture registered later is found).
        check_options: ``(vehicle config, options, where) -> resolved options``.
        metric_names: ``(vehicle config) -> names`` of the metrics a case can keep.
        prepare: ``(study, solver case) -> context`` (runs once, in the client).
        group: ``(context, values row) -> key``; cases with equal keys may share one task.
        run: ``(context, cycle, keys, values (m, d), metrics, threads) -> [Outcome] * m``.
        default_batch: cases per task when the study does not say (0: automatic).
        cycle_free: its results do not depend on the cycle: a task holds the cases of every
            cycle of its vehicles and runs each vehicle once.
        link: ``(options, every solver of the study, where) -> options``, run once the study's
            solvers are known (e.g. to take another solver's options); None: nothing to link.
    """

    name: str
    architectures: tuple[str, ...] | Callable[[], tuple[str, ...]]
    check_options: Callable[[Any, dict[str, Any], str], dict[str, Any]]
    metric_names: Callable[[Any], tuple[str, ...]]
    prepare: Callable[[Any, Any], Any]
    group: Callable[[Any, np.ndarray], Hashable]
    run: Callable[..., list[Outcome]]
    default_batch: int = 0
    description: str = ""
    cycle_free: bool = False
    link: Callable[[dict[str, Any], tuple[Any, ...], str], dict[str, Any]] | None = None

    def supported(self) -> tuple[str, ...]:
        """The architectures it supports (``architectures``, called when it is a callable)."""
        a = self.architectures
        return tuple(a() if callable(a) else a)

    def check_architecture(self, cfg: Any, where: str) -> None:
        """Raise ConfigError if the solver does not support ``cfg``'s architecture."""
        if cfg.architecture not in self.supported():
            raise ConfigError(
                f"{where}: solver '{self.name}' supports the {', '.join(self.supported())} "
                f"architecture(s); the vehicle is {cfg.architecture!r}."
            )

    def check(self, cfg: Any, options: dict[str, Any], where: str) -> dict[str, Any]:
        """Validated options of this solver for ``cfg``."""
        return self.check_options(cfg, options, where)


SOLVERS: dict[str, Solver] = {}
"""Registered study solvers by name."""


def register_solver(solver: Solver) -> None:
    """Add (or replace) a solver in :data:`SOLVERS`."""
    SOLVERS[solver.name] = solver


def solver_spec(name: Any, where: str) -> Solver:
    """The registered solver ``name``; ConfigError listing the valid names otherwise."""
    if not isinstance(name, str) or name not in SOLVERS:
        raise ConfigError(
            f"{where}: solver {name!r} is not known; expected one of {', '.join(sorted(SOLVERS))}."
        )
    return SOLVERS[name]


def _unknown_options(options: dict[str, Any], valid: tuple[str, ...], name: str, where: str) -> None:
    bad = [k for k in options if k not in valid]
    if bad:
        raise ConfigError(
            f"{where}: option '{bad[0]}' is not known for solver '{name}'; valid options are: "
            f"{', '.join(valid) or '(none)'}."
        )


def _message(exc: Exception) -> str:
    """A user error's message as it is; any other exception with its type (a solver error)."""
    return str(exc) if isinstance(exc, HevsimError) else f"{type(exc).__name__}: {exc}"


def _fail(message: str, wall: float = 0.0) -> Outcome:
    return Outcome(FAILED, message, {}, wall)


# ------------------------------------------------------------------------------------------
# Worker-side cache of built vehicle models (component data read once per worker)
# ------------------------------------------------------------------------------------------
_MODELS: OrderedDict[Hashable, Any] = OrderedDict()
MODEL_CACHE_SIZE = 32
"""Vehicle models a worker keeps built (least recently used dropped) [-]."""


def cached_model(key: Hashable, build: Callable[[], Any]) -> Any:
    """The model cached under ``key`` in this process, built on first use."""
    if key in _MODELS:
        _MODELS.move_to_end(key)
        return _MODELS[key]
    model = build()
    _MODELS[key] = model
    while len(_MODELS) > MODEL_CACHE_SIZE:
        _MODELS.popitem(last=False)
    return model


def _overrides(keys: tuple[str, ...], row: np.ndarray, integer: tuple[bool, ...]) -> dict[str, Any]:
    return {k: (int(v) if i else float(v)) for k, v, i in zip(keys, row, integer, strict=True)}


# ------------------------------------------------------------------------------------------
# simulate: forward simulation through simulate_batch
# ------------------------------------------------------------------------------------------
RULE_BASED = "rule_based"
"""``controller`` value of the ``simulate`` solver: the architecture's rule-based controller
(the first kind it admits, :attr:`hevsim.architectures.Architecture.controllers`)."""
ECMS_FROM_DP = "ecms_dp"
"""``controller`` value of the ``simulate`` solver: ECMS whose equivalence factor is the median
``-costate x LHV / (Q OCV)`` of the same case's DP (:func:`hevsim.control.parallel.ecms_from_dp`)."""
DP_OPTIONS = "dp_options"
"""Option the ``simulate`` solver receives from the study's ``optimize`` solver (``ecms_dp``)."""


def controller_choices(cfg: Any) -> tuple[str, ...]:
    """The ``controller`` values the ``simulate`` solver admits for ``cfg``'s architecture."""
    from hevsim.architectures import architecture

    arch = architecture(cfg.architecture, cfg.name)
    dp = (ECMS_FROM_DP,) if ("ecms" in arch.controllers and arch.dp_formulation) else ()
    return (RULE_BASED, *arch.controllers, *dp)


def controller_kind(cfg: Any, name: str) -> str:
    """The ``[controller] kind`` a ``controller`` value of the ``simulate`` solver runs."""
    from hevsim.architectures import architecture

    if name == RULE_BASED:
        return architecture(cfg.architecture, cfg.name).controllers[0]
    return "ecms" if name == ECMS_FROM_DP else name


def _simulate_options(cfg: Any, options: dict[str, Any], where: str) -> dict[str, Any]:
    from hevsim import schema

    _unknown_options(options, ("controller", "dt_s"), "simulate", where)
    out: dict[str, Any] = {}
    if "controller" in options:
        valid = controller_choices(cfg)
        if options["controller"] not in valid:
            raise ConfigError(
                f"{where}: key 'controller' = {options['controller']!r} is not admitted by the "
                f"{cfg.architecture} architecture; expected one of {', '.join(valid)}."
            )
        from hevsim.config import with_overrides

        kind = controller_kind(cfg, options["controller"])
        with_overrides(cfg, {"controller.kind": kind}, where)  # the architecture's rules
        out["controller"] = options["controller"]
    if "dt_s" in options:
        out["dt_s"] = schema.check_option(f"{where}: dt_s", options["dt_s"], type(cfg.simulation), "dt_s")
    return out


def _simulate_link(options: dict[str, Any], solvers: tuple[Any, ...], where: str) -> dict[str, Any]:
    """``ecms_dp`` takes the grids of the study's ``optimize`` solver (ConfigError without one)."""
    if options.get("controller") != ECMS_FROM_DP:
        return options
    dp = [s for s in solvers if s.name == "optimize"]
    if not dp:
        raise ConfigError(
            f"{where}: key 'controller' = {ECMS_FROM_DP!r} tunes ECMS from the same case's DP; expected "
            'an [[solvers]] table with name = "optimize" in the study (its grids are used).'
        )
    return {**options, DP_OPTIONS: dp[0].options}


def _simulate_metrics(cfg: Any) -> tuple[str, ...]:
    from hevsim.sim import kernel as K
    from hevsim.sim.metrics import compute_metrics, energy_audit

    ones = (np.ones(len(K.SUMMARY)), energy_audit(np.ones(len(K.ENERGY_TERMS))))
    with np.errstate(all="ignore"):
        if cfg.architecture == "series":
            m = compute_metrics(*ones, 0.5, 1.0, 1.0, 1.0, 1.0, 1.0, 0.5)
        else:
            from hevsim.architectures import architecture
            from hevsim.sim.forward import run_metrics

            m = run_metrics(architecture(cfg.architecture).build(cfg), *ones, 1.0, 0.5)
    return tuple(m)


@dataclass(frozen=True)
class KernelKey:
    """A varied key that changes only kernel parameters: ``column = a + b * value`` for each
    column (``b`` 1 and ``a`` 0 exactly: the value is copied)."""

    axis: int
    columns: tuple[str, ...]
    a: tuple[float, ...]
    b: tuple[float, ...]


@dataclass(frozen=True, eq=False)
class SimulateContext:
    """Client-prepared context of the ``simulate`` solver."""

    base: Any
    keys: tuple[str, ...]
    integer: tuple[bool, ...]
    dt_s: float | None
    kernel: tuple[KernelKey, ...]
    structural: tuple[int, ...]
    token: str
    notes: tuple[str, ...] = field(default_factory=tuple)
    dp_options: tuple[tuple[str, Any], ...] | None = None
    study_token: str = ""


def _model_fingerprint(hev: Any) -> bytes:
    """Everything :func:`~hevsim.sim.simulator.simulate_batch` reads from a model besides its
    kernel parameter vector: kernel tables, pack capacity and OCV, fuel, run settings."""
    from hevsim.fuels import config_fuel

    c = hev.config
    return pickle.dumps((
        hev.kernel_tables(), hev.battery.capacity_ah, np.asarray(hev.battery.ocv(np.linspace(0, 1, 101))),
        config_fuel(c, hev.engine), c.metrics, c.controller.kind, c.controller.schedule, c.driver.kind,
        c.simulation, hev.cell is None,
    ))  # fmt: skip


def _probe_model(base: Any, key: str, value: float, integer: bool) -> tuple[bytes, np.ndarray] | None:
    from hevsim.architectures import build_vehicle
    from hevsim.config import with_overrides

    try:
        hev = build_vehicle(with_overrides(base, {key: int(value) if integer else float(value)}))
    except HevsimError:
        return None
    return _model_fingerprint(hev), hev.param_vector()


def _exact_scale(p: np.ndarray, v: np.ndarray) -> float | None:
    """The factor ``c`` with ``c * v == p`` exactly at every probe (a pure scale), or None."""
    cands: list[float] = []
    for pk, vk in zip(p.tolist(), v.tolist(), strict=True):
        if vk != 0.0:
            r = pk / vk
            cands += [r, float(np.nextafter(r, np.inf)), float(np.nextafter(r, -np.inf)), float(f"{r:.12g}")]
    for c in cands:
        if np.all(c * v == p):
            return c
    return None


def classify_keys(base: Any, keys: tuple[str, ...], integer: tuple[bool, ...], values: np.ndarray) -> tuple[
    tuple[KernelKey, ...], tuple[int, ...], tuple[str, ...]
]:  # fmt: skip
    """Split the varied keys of a series-HEV study into kernel keys (batched as parameter
    variants of one model) and structural keys (a model per distinct combination).

    Each key is probed at up to five of its sampled values (smallest, quartiles, largest). It
    is a kernel key when the model's fingerprint does not change, every kernel parameter it
    changes is a copy of the value or an exact multiple of it (``c * value`` reproducing every
    probe bit for bit, so rows equal single runs exactly) or else affine to 1e-12, and no other
    varied key changes the same parameters. Returns (kernel keys, structural axis indices,
    notes saying why a key was structural).
    """
    from hevsim.sim import kernel as K

    changed: dict[int, set[int]] = {}
    candidates: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    notes: list[str] = []
    for j, key in enumerate(keys):
        uniq = np.unique(values[:, j])
        if uniq.size < 2:
            notes.append(f"{key}: one value")
            continue
        at = np.unique(uniq[np.rint(np.linspace(0, uniq.size - 1, min(5, uniq.size))).astype(int)])
        probes = [_probe_model(base, key, float(v), integer[j]) for v in at]
        if any(p is None for p in probes):
            notes.append(f"{key}: a probe value is invalid with the base vehicle")
            continue
        prints = [p[0] for p in probes if p is not None]
        pv = np.array([p[1] for p in probes if p is not None])  # (probes, params)
        cols = np.flatnonzero(np.any(pv != pv[0], axis=0))
        changed[j] = set(cols.tolist())
        if any(f != prints[0] for f in prints):
            notes.append(f"{key}: changes component data or run settings")
            continue
        lo, hi = float(at[0]), float(at[-1])
        b = (pv[-1] - pv[0]) / (hi - lo)
        a = pv[0] - b * lo
        for c in cols.tolist():
            scale = _exact_scale(pv[:, c], at.astype(np.float64))
            if scale is not None:
                a[c], b[c] = 0.0, scale
        pred = a[None, :] + b[None, :] * at[:, None]
        if cols.size == 0 or not np.allclose(pred[:, cols], pv[:, cols], rtol=1e-12, atol=0.0):
            notes.append(f"{key}: not an affine change of the kernel parameters")
            continue
        candidates[j] = (cols, a, b)
    kernel: list[KernelKey] = []
    for j, (cols, a, b) in candidates.items():
        others = set().union(*(c for i, c in changed.items() if i != j)) if len(changed) > 1 else set()
        if others & set(cols.tolist()):
            notes.append(f"{keys[j]}: shares kernel parameters with another varied key")
            continue
        names = tuple(K.PARAMS[c] for c in cols)
        kernel.append(KernelKey(j, names, tuple(float(a[c]) for c in cols), tuple(float(b[c]) for c in cols)))
    kernel_axes = {k.axis for k in kernel}
    structural = tuple(j for j in range(len(keys)) if j not in kernel_axes)
    return tuple(kernel), structural, tuple(notes)


def _simulate_prepare(study: Any, solver: Any) -> SimulateContext:
    base = study.vehicle
    if solver.option("controller"):
        kind = controller_kind(base, solver.option("controller"))
        base = dataclasses.replace(base, controller=dataclasses.replace(base.controller, kind=kind))
    integer = tuple(a.integer for a in study.parameters)
    fingerprint = study.fingerprint()
    token = f"{fingerprint}:{solver.label}"
    dp = solver.option(DP_OPTIONS)
    if _forward_keys(base):  # configuration keys, validated per variant by the batch
        return SimulateContext(base, study.keys, integer, solver.option("dt_s"), (), (), token, (), dp,
                               fingerprint)  # fmt: skip
    kernel, structural, notes = classify_keys(base, study.keys, integer, study.values)
    return SimulateContext(base, study.keys, integer, solver.option("dt_s"), kernel, structural, token, notes,
                           dp, fingerprint)  # fmt: skip


def _forward_keys(base: Any) -> bool:
    """Whether the ``simulate`` solver varies configuration keys of ``base`` (every
    architecture but the series HEV, and the series HEV with an online controller, which runs
    in :mod:`hevsim.sim.forward`) rather than the series kernel's parameters."""
    from hevsim.config import SERIES_ONLINE_CONTROLLERS

    return bool(base.architecture != "series" or base.controller.kind in SERIES_ONLINE_CONTROLLERS)


def _simulate_group(ctx: SimulateContext, row: np.ndarray) -> Hashable:
    return tuple(float(row[j]) for j in ctx.structural)


def _variants(ctx: SimulateContext, rows: np.ndarray) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for k in ctx.kernel:
        v = rows[:, k.axis].astype(np.float64)
        for name, a, b in zip(k.columns, k.a, k.b, strict=True):
            out[name] = v.copy() if (a == 0.0 and b == 1.0) else (b * v if a == 0.0 else a + b * v)
    return out


def _simulate_run(
    ctx: SimulateContext, cycle: Any, values: np.ndarray, metrics: tuple[str, ...], threads: int | None
) -> list[Outcome]:
    from hevsim.architectures import build_vehicle
    from hevsim.config import with_overrides
    from hevsim.sim import kernel as K
    from hevsim.sim.simulator import simulate_batch

    if _forward_keys(ctx.base):
        return _architecture_run(ctx, cycle, values, metrics, threads)
    t0 = time.perf_counter()
    m = values.shape[0]
    outcomes: list[Outcome | None] = [None] * m
    group_keys = [ctx.keys[j] for j in ctx.structural]
    g_int = tuple(ctx.integer[j] for j in ctx.structural)
    row0 = values[0]
    try:
        group_over = _overrides(tuple(group_keys), row0[list(ctx.structural)], g_int)
        hev = cached_model((ctx.token, _simulate_group(ctx, row0)),
                           lambda: build_vehicle(with_overrides(ctx.base, group_over)))  # fmt: skip
    except HevsimError as exc:
        wall = (time.perf_counter() - t0) / m
        return [_fail(str(exc), wall)] * m
    good: list[int] = []
    for i in range(m):  # cross-key checks of each case (e.g. soc_low < soc_high)
        try:
            with_overrides(hev.config, _overrides(ctx.keys, values[i], ctx.integer))
            good.append(i)
        except HevsimError as exc:
            outcomes[i] = _fail(str(exc))
    if threads:
        import numba

        numba.set_num_threads(threads)

    def run(idx: list[int]) -> list[Outcome]:
        variants = _variants(ctx, values[idx])
        if not variants:  # every key structural: the cases of a group are one vehicle
            variants = {"mass_kg": np.full(len(idx), hev.param_vector()[K.P["mass_kg"]])}
        table = simulate_batch(hev, variants, cycle=cycle, dt_s=ctx.dt_s).table
        return [Outcome(OK, "", {k: float(table[k].iloc[r]) for k in metrics}, 0.0) for r in range(len(idx))]

    return _finish(outcomes, good, run, t0)


def _finish(outcomes: list[Outcome | None], good: list[int], run: Callable[[list[int]], list[Outcome]],
            t0: float) -> list[Outcome]:  # fmt: skip
    """Run the cases ``good`` as one batch (each alone when the batch fails, to know which
    fails), fill ``outcomes`` and give every case the batch's mean wall time."""
    if good:
        try:
            done = run(good)
        except Exception:  # one bad variant fails the batch: run each alone to know which
            done = []
            for i in good:
                try:
                    done.extend(run([i]))
                except Exception as exc:  # recorded for the case; the study goes on
                    done.append(_fail(_message(exc)))
        for i, o in zip(good, done, strict=True):
            outcomes[i] = o
    wall = (time.perf_counter() - t0) / max(1, len(outcomes))
    return [dataclasses.replace(o, wall_time_s=wall) for o in outcomes if o is not None]


_DP_FACTORS: OrderedDict[Hashable, float] = OrderedDict()
DP_FACTOR_CACHE_SIZE = 100_000
"""DP equivalence factors a worker remembers (so ``ecms_dp`` reuses an ``optimize`` case run
in the same process) [-]."""


def _dp_key(study_token: str, cycle: Any, row: np.ndarray, options: Any) -> Hashable:
    return (study_token, getattr(cycle, "name", ""), np.asarray(row, np.float64).tobytes(), tuple(options))


def _remember_factor(key: Hashable, s: float) -> None:
    _DP_FACTORS[key] = s
    while len(_DP_FACTORS) > DP_FACTOR_CACHE_SIZE:
        _DP_FACTORS.popitem(last=False)


def _dp_factor(ctx: SimulateContext, cfg: Any, cycle: Any, row: np.ndarray, threads: int | None) -> float:
    """The ECMS equivalence factor of the case's DP (run here unless this process has it)."""
    from hevsim.control.parallel import ecms_from_dp
    from hevsim.optimal import optimize

    opts = ctx.dp_options or ()
    key = _dp_key(ctx.study_token, cycle, row, opts)
    if key not in _DP_FACTORS:
        res = optimize(cfg, cycle, progress=False, threads=threads, **dict(opts))
        _remember_factor(key, ecms_from_dp(res)["equivalence_factor"])
    return _DP_FACTORS[key]


def _architecture_run(
    ctx: SimulateContext, cycle: Any, values: np.ndarray, metrics: tuple[str, ...], threads: int | None
) -> list[Outcome]:
    """``simulate`` for the architectures other than the series HEV (and the series HEV with an
    online controller): the batch's cases as configuration-key variants of one
    :func:`~hevsim.sim.simulator.simulate_batch` call."""
    from hevsim.architectures import architecture
    from hevsim.config import with_overrides
    from hevsim.sim.simulator import simulate_batch

    t0 = time.perf_counter()
    m = values.shape[0]
    outcomes: list[Outcome | None] = [None] * m
    if threads:
        import numba

        numba.set_num_threads(threads)
    model = cached_model((ctx.token,), lambda: architecture(ctx.base.architecture).build(ctx.base))
    good: list[int] = []
    factor = np.full(m, np.nan)
    for i in range(m):  # each case's values checked alone first (a bad one fails only itself)
        try:
            cfg = with_overrides(ctx.base, _overrides(ctx.keys, values[i], ctx.integer))
            if ctx.dp_options is not None:
                factor[i] = _dp_factor(ctx, cfg, cycle, values[i], threads)
            good.append(i)
        except Exception as exc:  # recorded for the case; the study goes on
            outcomes[i] = _fail(_message(exc))

    def run(idx: list[int]) -> list[Outcome]:
        variants: dict[str, np.ndarray] = {
            k: values[idx, j].astype(np.int64 if integer else np.float64)
            for j, (k, integer) in enumerate(zip(ctx.keys, ctx.integer, strict=True))
        }
        if ctx.dp_options is not None:
            variants["controller.equivalence_factor"] = factor[idx]
        table = simulate_batch(model, variants, cycle=cycle, dt_s=ctx.dt_s).table
        return [Outcome(OK, "", {k: float(table[k].iloc[r]) for k in metrics}, 0.0) for r in range(len(idx))]

    return _finish(outcomes, good, run, t0)


# ------------------------------------------------------------------------------------------
# optimize: dynamic programming
# ------------------------------------------------------------------------------------------
OPTIMIZE_OPTIONS = ("soc_grid_points", "input_grid_points", "final_constraint")
NONDETERMINISTIC_METRICS = ("compute_time_s",)
"""Metrics that are timings (they differ from run to run); not offered (see ``wall_time_s``)."""


def _optimize_options(cfg: Any, options: dict[str, Any], where: str) -> dict[str, Any]:
    from hevsim.optimal import FINAL_CONSTRAINTS

    _unknown_options(options, OPTIMIZE_OPTIONS, "optimize", where)
    out: dict[str, Any] = {}
    for k in ("soc_grid_points", "input_grid_points"):
        if k in options:
            v = options[k]
            if isinstance(v, bool) or not isinstance(v, int) or v < 2:
                raise ConfigError(f"{where}: {k} = {v!r}: expected an integer >= 2.")
            out[k] = v
    if "final_constraint" in options:
        if options["final_constraint"] not in FINAL_CONSTRAINTS:
            raise ConfigError(
                f"{where}: final_constraint = {options['final_constraint']!r} is not known; expected one "
                f"of {', '.join(FINAL_CONSTRAINTS)}."
            )
        out["final_constraint"] = options["final_constraint"]
    return out


def _optimize_metrics(cfg: Any) -> tuple[str, ...]:
    from hevsim.architectures import build_vehicle
    from hevsim.architectures._common import fuel_converter
    from hevsim.optimal._hev_common import hev_metrics

    hev = build_vehicle(cfg)
    engine = fuel_converter(hev)  # an engine, or a fuel-cell vehicle's fuel cell
    if engine is None:  # pragma: no cover - every DP architecture has a fuel converter
        return ()
    with np.errstate(all="ignore"):
        m = hev_metrics(fuel_kg=1.0, distance_m=1.0, duration_s=1.0, soc_initial=0.5, soc_final=0.5,
                        battery=hev.battery, engine=engine, conversion_efficiency=0.5, engine_on_time_s=0.0,
                        compute_time_s=0.0, dp_total_cost=0.0)  # fmt: skip
    return tuple(k for k in m if k not in NONDETERMINISTIC_METRICS)


@dataclass(frozen=True, eq=False)
class OptimizeContext:
    """Client-prepared context of the ``optimize`` solver."""

    base: Any
    keys: tuple[str, ...]
    integer: tuple[bool, ...]
    options: tuple[tuple[str, Any], ...]
    study_token: str = ""


def _optimize_prepare(study: Any, solver: Any) -> OptimizeContext:
    return OptimizeContext(
        study.vehicle,
        study.keys,
        tuple(a.integer for a in study.parameters),
        solver.options,
        study.fingerprint(),
    )


def _optimize_run(
    ctx: OptimizeContext, cycle: Any, values: np.ndarray, metrics: tuple[str, ...], threads: int | None
) -> list[Outcome]:
    from hevsim.config import with_overrides
    from hevsim.optimal import optimize

    out: list[Outcome] = []
    for row in values:
        t0 = time.perf_counter()
        try:
            cfg = with_overrides(ctx.base, _overrides(ctx.keys, row, ctx.integer))
            res = optimize(cfg, cycle, progress=False, threads=threads, **dict(ctx.options))
            s = float(res.metrics.get("equivalence_factor_median", {}).get("value", np.nan))
            if np.isfinite(s) and s >= 0:  # for an ecms_dp case of the same sample in this process
                _remember_factor(_dp_key(ctx.study_token, cycle, row, ctx.options), s)
            out.append(Outcome(OK, "", {k: float(res.metrics[k]["value"]) for k in metrics},
                               time.perf_counter() - t0))  # fmt: skip
        except Exception as exc:  # recorded for the case; the study goes on
            out.append(_fail(_message(exc), time.perf_counter() - t0))
    return out


# ------------------------------------------------------------------------------------------
# performance: acceleration, top speed, gradeability
# ------------------------------------------------------------------------------------------
PERFORMANCE_METRICS: dict[str, tuple[str, str]] = {
    "0-60 mph": ("time_0_60_mph_s", "s"),
    "0-100 km/h": ("time_0_100_kmh_s", "s"),
    "quarter mile": ("quarter_mile_s", "s"),
    "quarter mile trap speed": ("quarter_mile_trap_speed_mph", "mph"),
    "50-80 mph": ("time_50_80_mph_s", "s"),
    "top speed": ("top_speed_mph", "mph"),
    "gradeability": ("gradeability_pct", "%"),
}
"""Test of :func:`hevsim.sim.performance.performance` (the gradeability test's name starts
with ``gradeability``) -> (study metric, its unit)."""
PERFORMANCE_OPTIONS = ("dt_s", "soc", "grade_speed_mph")


def _performance_options(cfg: Any, options: dict[str, Any], where: str) -> dict[str, Any]:
    from hevsim.architectures import architecture

    _unknown_options(options, PERFORMANCE_OPTIONS, "performance", where)
    if not hasattr(architecture(cfg.architecture, cfg.name).power_module(), "capability_controls"):
        raise ConfigError(
            f"{where}: solver 'performance' needs the architecture's capability controls; the "
            f"{cfg.architecture} architecture has none."
        )
    bounds = {"dt_s": (0.0, 10.0), "soc": (0.0, 1.0), "grade_speed_mph": (0.0, 200.0)}  # (lo, hi]
    out: dict[str, Any] = {}
    for k, v in options.items():
        lo, hi = bounds[k]
        number = isinstance(v, int | float) and not isinstance(v, bool)
        if not number or not lo < v <= hi:
            raise ConfigError(f"{where}: {k} = {v!r}: expected a number in ({lo:g}, {hi:g}].")
        out[k] = float(v)
    return out


def _performance_metrics(cfg: Any) -> tuple[str, ...]:
    return tuple(name for name, _ in PERFORMANCE_METRICS.values())


def performance_metrics(result: Any) -> dict[str, float]:
    """The study metrics of a :class:`~hevsim.sim.performance.PerformanceResult` (units as in
    :data:`PERFORMANCE_METRICS`; RuntimeError if a test or a unit is not the expected one)."""
    out: dict[str, float] = {}
    for test, value, unit in result.table[["test", "value", "unit"]].itertuples(index=False):
        key = "gradeability" if str(test).startswith("gradeability") else str(test)
        if key not in PERFORMANCE_METRICS or PERFORMANCE_METRICS[key][1] != unit:
            raise RuntimeError(f"performance test {test!r} [{unit}]: expected {list(PERFORMANCE_METRICS)}")
        out[PERFORMANCE_METRICS[key][0]] = float(value)
    return out


def _performance_run(
    ctx: OptimizeContext, cycle: Any, values: np.ndarray, metrics: tuple[str, ...], threads: int | None
) -> list[Outcome]:
    from hevsim.config import with_overrides
    from hevsim.sim.performance import performance
    from hevsim.units import MPS_PER_MPH

    opts = dict(ctx.options)
    kwargs: dict[str, Any] = {k: opts[k] for k in ("dt_s", "soc") if k in opts}
    if "grade_speed_mph" in opts:
        kwargs["grade_speed_mps"] = opts["grade_speed_mph"] * MPS_PER_MPH
    done: dict[bytes, Outcome] = {}  # a task holds a vehicle's cases of every cycle: run it once
    out: list[Outcome] = []
    for row in values:
        key = np.asarray(row, np.float64).tobytes()
        if key not in done:
            t0 = time.perf_counter()
            try:
                cfg = with_overrides(ctx.base, _overrides(ctx.keys, row, ctx.integer))
                got = performance_metrics(performance(cfg, **kwargs))
                done[key] = Outcome(OK, "", {k: got[k] for k in metrics}, time.perf_counter() - t0)
            except Exception as exc:  # recorded for the case; the study goes on
                done[key] = _fail(_message(exc), time.perf_counter() - t0)
        out.append(done[key])
    return out


def _every_architecture() -> tuple[str, ...]:
    """Every architecture of the registry (each has a forward simulation and its controllers)."""
    from hevsim.architectures import ARCHITECTURES

    return tuple(ARCHITECTURES)


def _dp_architectures() -> tuple[str, ...]:
    """The architectures of the registry with a DP formulation."""
    from hevsim.architectures import ARCHITECTURES

    return tuple(n for n, a in ARCHITECTURES.items() if a.dp_formulation)


def _performance_architectures() -> tuple[str, ...]:
    """The architectures whose module has a performance envelope (``capability_controls``)."""
    from hevsim.architectures import ARCHITECTURES

    return tuple(n for n, a in ARCHITECTURES.items() if hasattr(a.power_module(), "capability_controls"))


register_solver(Solver(
    "simulate", _every_architecture, _simulate_options,
    _simulate_metrics, _simulate_prepare, _simulate_group, _simulate_run, default_batch=0,
    description="forward simulation (a named controller) via simulate_batch", link=_simulate_link,
))  # fmt: skip
register_solver(Solver(
    "optimize", _dp_architectures, _optimize_options, _optimize_metrics,
    _optimize_prepare, lambda ctx, row: (), _optimize_run, default_batch=1,
    description="fuel-optimal energy management by dynamic programming",
))  # fmt: skip
register_solver(Solver(
    "performance", _performance_architectures, _performance_options,
    _performance_metrics, _optimize_prepare, lambda ctx, row: (), _performance_run, default_batch=1,
    description="0-60 mph, 0-100 km/h, quarter mile, 50-80 mph, top speed, gradeability", cycle_free=True,
))  # fmt: skip

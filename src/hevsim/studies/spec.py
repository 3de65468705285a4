"""The study file (``study.toml``): schema, validation and the resolved, sampled study.

A study names a base vehicle configuration (any registered architecture), the parameters to
vary (any numeric key path ``section.field`` of that vehicle's configuration, checked against
the configuration's section dataclasses, so renamed sections are reported, not guessed), how
to sample them, the cycles, the solvers (:mod:`hevsim.studies.solvers`), the metrics to keep
and the Pareto fronts to report. See ``docs/studies.md`` for the file format.

Every error names the study file, the key, the value and what was expected, and is raised
before anything is computed or written.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hevsim import schema
from hevsim.config import with_overrides as with_overrides  # re-exported: studies import it from here
from hevsim.errors import ConfigError, HevsimError
from hevsim.studies import sampling
from hevsim.studies.sampling import Axis

TOP_KEYS = ("name", "description", "vehicle", "cycles", "metrics", "batch_size", "sampling",
            "parameters", "solvers", "pareto")  # fmt: skip
"""Valid top-level keys of a study file."""
SAMPLING_KEYS = ("method", "samples", "seed")
RANGE_KEYS = ("min", "max", "num", "step")
PARETO_KEYS = ("name", "minimize", "maximize")
MAX_CASES = 10_000_000
"""Largest number of cases a study may plan [-] (a guard against a typo in a grid)."""


class StudyError(ConfigError):
    """A study file (or a study folder) is malformed; the message names file, key and value."""


@dataclass(frozen=True)
class SolverCase:
    """One solver of the study and its validated options (``name`` is a registry key)."""

    name: str
    options: tuple[tuple[str, Any], ...] = ()

    @property
    def label(self) -> str:
        """The solver's label in results: its name, plus options that distinguish it."""
        opts = ",".join(f"{k}={v}" for k, v in self.options if k == "controller")
        return f"{self.name}[{opts}]" if opts else self.name

    def kept_metrics(self, metrics: tuple[str, ...], vehicle: Any) -> tuple[str, ...]:
        """The study's ``metrics`` this solver gives (the others are NaN in its rows)."""
        from hevsim.studies.solvers import solver_spec

        offered = solver_spec(self.name, "study").metric_names(vehicle)
        return tuple(m for m in metrics if m in offered)

    def option(self, key: str, default: Any = None) -> Any:
        """Option ``key`` (or ``default``)."""
        return dict(self.options).get(key, default)


@dataclass(frozen=True)
class Pareto:
    """A Pareto front to report: columns (metrics or parameters) to minimize / maximize."""

    name: str
    minimize: tuple[str, ...] = ()
    maximize: tuple[str, ...] = ()

    @property
    def objectives(self) -> tuple[str, ...]:
        """Every objective column."""
        return self.minimize + self.maximize


@dataclass(frozen=True, eq=False)
class Study:
    """A validated, sampled study (picklable; it is shipped to every worker once).

    ``values`` holds one row per sample (``n_samples x len(parameters)``); cases are every
    (sample, cycle, solver) in that nesting order: ``case_id = (sample * n_cycles + cycle) *
    n_solvers + solver``.
    """

    name: str
    source: str
    vehicle: Any
    vehicle_source: str
    cycles: tuple[str, ...]
    cycle_objects: tuple[Any, ...]
    parameters: tuple[Axis, ...]
    method: str
    samples: int
    seed: int
    solvers: tuple[SolverCase, ...]
    metrics: tuple[str, ...]
    pareto: tuple[Pareto, ...] = ()
    batch_size: int = 0
    description: str = ""
    values: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def keys(self) -> tuple[str, ...]:
        """The varied key paths, in file order."""
        return tuple(a.key for a in self.parameters)

    @property
    def n_samples(self) -> int:
        """Rows of :attr:`values`."""
        return int(self.values.shape[0])

    @property
    def n_cases(self) -> int:
        """Samples x cycles x solvers."""
        return self.n_samples * len(self.cycles) * len(self.solvers)

    def case_index(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(sample, cycle, solver) index of every case id, in case-id order."""
        nc, ns = len(self.cycles), len(self.solvers)
        ids = np.arange(self.n_cases)
        return ids // (nc * ns), (ids // ns) % nc, ids % ns

    def plan(self) -> Any:
        """The case table: ``case_id``, ``sample_id``, ``cycle``, ``solver`` and every varied
        parameter (a pandas DataFrame)."""
        import pandas as pd

        s, c, v = self.case_index()
        cols: dict[str, Any] = {
            "case_id": np.arange(self.n_cases, dtype=np.int64),
            "sample_id": s.astype(np.int64),
            "cycle": np.asarray(self.cycles, dtype=object)[c] if self.n_cases else [],
            "solver": np.asarray([sv.label for sv in self.solvers], dtype=object)[v] if self.n_cases else [],
        }
        for j, a in enumerate(self.parameters):
            col = self.values[s, j]
            cols[a.key] = col.astype(np.int64) if a.integer else col
        return pd.DataFrame(cols)

    def describe(self) -> dict[str, Any]:
        """A plain description (written to ``study.json``; its hash identifies the study)."""
        return {
            "name": self.name,
            "description": self.description,
            "source": self.source,
            "vehicle": self.vehicle_source,
            "architecture": self.vehicle.architecture,
            "vehicle_config": self.vehicle.to_dict(),
            "cycles": list(self.cycles),
            "parameters": [dataclasses.asdict(a) for a in self.parameters],
            "method": self.method,
            "samples": self.samples,
            "seed": self.seed,
            "solvers": [{"name": s.name, "label": s.label, **dict(s.options)} for s in self.solvers],
            "metrics": list(self.metrics),
            "pareto": [dataclasses.asdict(p) for p in self.pareto],
            "n_samples": self.n_samples,
            "n_cases": self.n_cases,
        }

    def fingerprint(self) -> str:
        """SHA-256 of everything that determines the rows (not the file's location)."""
        d = self.describe()
        d.pop("source", None)
        d.pop("description", None)
        d.pop("pareto", None)
        h = hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode())
        h.update(np.ascontiguousarray(self.values).tobytes())
        return h.hexdigest()


# ------------------------------------------------------------------------------------------
# Key paths of a vehicle configuration
# ------------------------------------------------------------------------------------------
def numeric_keys(cfg: Any) -> list[str]:
    """Every numeric (int or float) ``section.field`` key path of configuration ``cfg``."""
    out: list[str] = []
    for f in dataclasses.fields(cfg):
        sec = getattr(cfg, f.name)
        if dataclasses.is_dataclass(sec):
            hints = typing.get_type_hints(type(sec))
            out.extend(f"{f.name}.{g.name}" for g in dataclasses.fields(sec) if hints[g.name] in (int, float))
    return out


def resolve_key(cfg: Any, key: str, where: str) -> tuple[type, dict[str, Any]]:
    """(int or float, field metadata) of the numeric key path ``key`` of ``cfg``.

    Raises StudyError naming the valid sections or the valid numeric keys of the section.
    """
    sections = {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg)}
    sections = {k: v for k, v in sections.items() if dataclasses.is_dataclass(v)}
    sec, _, name = key.partition(".")
    if sec not in sections or not name or "." in name:
        raise StudyError(
            f"{where}: parameter '{key}' is not a key path of the {cfg.architecture} vehicle; expected "
            f"'section.field' with a section among: {', '.join(sections)}."
        )
    valid = [k.partition(".")[2] for k in numeric_keys(cfg) if k.startswith(sec + ".")]
    if name not in valid:
        raise StudyError(
            f"{where}: parameter '{key}' is not a numeric key of [{sec}]; valid numeric keys of "
            f"[{sec}] are: {', '.join(valid) or '(none)'}."
        )
    tp, meta = schema.field_of(type(sections[sec]), name)
    return tp, dict(meta)


# ------------------------------------------------------------------------------------------
# Parsing
# ------------------------------------------------------------------------------------------
def _is_spec(v: Any) -> bool:
    return isinstance(v, list) or (isinstance(v, dict) and any(k in v for k in RANGE_KEYS))


def _flatten(params: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in params.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and not _is_spec(v):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _number(v: Any, tp: type, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise StudyError(f"{where} = {v!r}: expected a finite number.")
    if tp is int and float(v) != int(v):
        raise StudyError(f"{where} = {v!r}: this key is an integer; expected a whole number.")
    return float(v)


def _check_bounds(v: float, tp: type, meta: dict[str, Any], where: str) -> None:
    schema.check_value(int(v) if tp is int else float(v), tp, "", "", {}, {}, meta, where=where)


def _axis(cfg: Any, key: str, spec: Any, method: str, src: str) -> Axis:
    where = f"{src}: [parameters] '{key}'"
    tp, meta = resolve_key(cfg, key, src)
    integer = tp is int
    if isinstance(spec, list):
        if method in sampling.CONTINUOUS:
            raise StudyError(
                f"{where} = {spec!r}: method '{method}' samples a range; expected {{min = .., max = ..}}."
            )
        if not spec:
            raise StudyError(f"{where} = []: expected at least one value.")
        vals = tuple(_number(v, tp, f"{where}[{i}]") for i, v in enumerate(spec))
        for i, v in enumerate(vals):
            _check_bounds(v, tp, meta, f"{where}[{i}]")
        return Axis(key, values=vals, integer=integer)
    if not isinstance(spec, dict):
        raise StudyError(f"{where} = {spec!r}: expected a list of values or a range {{min, max, ...}}.")
    _reject_unknown(spec, RANGE_KEYS, where)
    for k in ("min", "max"):
        if k not in spec:
            raise StudyError(f"{where}: the range has no '{k}'; expected {{min = .., max = ..}}.")
    lo, hi = _number(spec["min"], tp, f"{where}.min"), _number(spec["max"], tp, f"{where}.max")
    if lo > hi:
        raise StudyError(
            f"{where}: min = {spec['min']!r} is above max = {spec['max']!r}; expected min <= max."
        )
    _check_bounds(lo, tp, meta, f"{where}.min")
    _check_bounds(hi, tp, meta, f"{where}.max")
    if method in sampling.CONTINUOUS:
        if "num" in spec or "step" in spec:
            raise StudyError(
                f"{where}: 'num'/'step' make a grid; method '{method}' samples the range {{min, max}} only."
            )
        return Axis(key, low=lo, high=hi, integer=integer)
    if method == "list":
        raise StudyError(f"{where}: method 'list' zips lists; expected a list of values, got a range.")
    if ("num" in spec) == ("step" in spec):
        raise StudyError(f"{where}: a grid range needs exactly one of 'num' (points) or 'step'.")
    if "num" in spec:
        num = spec["num"]
        if isinstance(num, bool) or not isinstance(num, int) or num < 1:
            raise StudyError(f"{where}.num = {num!r}: expected an integer >= 1.")
        if num == 1 and lo != hi:
            raise StudyError(f"{where}.num = 1 with min < max: expected num >= 2 (or min = max).")
        vals_arr = np.asarray(np.linspace(lo, hi, num), dtype=np.float64)
    else:
        step = _number(spec["step"], float, f"{where}.step")
        if step <= 0:
            raise StudyError(f"{where}.step = {spec['step']!r}: expected a step > 0.")
        count = math.floor((hi - lo) / step + 1e-9) + 1
        vals_arr = np.asarray(lo + step * np.arange(count), dtype=np.float64)
    if integer:
        if not np.allclose(vals_arr, np.rint(vals_arr)):
            raise StudyError(f"{where}: this key is an integer; the range gives non-integer values.")
        vals_arr = np.rint(vals_arr)
    return Axis(key, values=tuple(float(v) for v in vals_arr), integer=integer)


def _str_list(v: Any, where: str, allow_empty: bool = False) -> tuple[str, ...]:
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not all(isinstance(x, str) for x in v) or (not v and not allow_empty):
        raise StudyError(f"{where} = {v!r}: expected a {'' if allow_empty else 'non-empty '}list of strings.")
    if len(set(v)) != len(v):
        raise StudyError(f"{where} = {v!r}: names repeat; expected each once.")
    return tuple(v)


SAMPLE_BYTES_PER_VALUE = 4 * 8
"""Memory a sampler needs per sampled value [B]: the float64 result plus about three arrays of
its size while it runs (scipy's Latin hypercube: the integer permutations, the uniform draws
and the scaled copy; measured peak 29.8 GiB for 1e9 rows x 4 parameters = 32 B per value)."""


def _sample_rows(axes: tuple[Axis, ...], method: str, n: int) -> int:
    """Rows the sampler would make (before making them)."""
    if method == "grid":
        return math.prod(len(a.values) for a in axes)
    if method == "list":
        return max(len(a.values) for a in axes)
    return n * (len(axes) + 2) if method == "saltelli" else n


def _check_sample_size(axes: tuple[Axis, ...], method: str, n: int, src: str) -> None:
    """Refuse, before allocating anything, a sample of more than :data:`MAX_CASES` rows or
    more than the machine's free memory holds (:func:`hevsim.guards.check_memory`)."""
    from hevsim.guards import MB, check_memory

    rows = _sample_rows(axes, method, n)
    need = rows * max(len(axes), 1) * SAMPLE_BYTES_PER_VALUE
    what = f"key 'sampling.samples' = {n}" if method in sampling.CONTINUOUS else f"method '{method}'"
    if rows > MAX_CASES:
        raise StudyError(
            f"{src}: {what}: {rows:,} {method} sample rows of {len(axes)} parameters would need about "
            f"{need / MB:,.0f} MB to draw; "
            f"expected at most {MAX_CASES:,} rows (lower the sample size or the grid)."
        )
    check_memory(
        need, f"{src}: {rows:,} {method} sample rows of {len(axes)} parameters",
        "lower 'sampling.samples' (or the grid), or run on a machine with more memory.", StudyError,
    )  # fmt: skip


def _sample(axes: tuple[Axis, ...], method: str, n: int, seed: int, src: str) -> np.ndarray:
    if not axes:
        return np.zeros((1, 0))
    _check_sample_size(axes, method, n, src)
    if method == "grid":
        total = math.prod(len(a.values) for a in axes)
        if total > MAX_CASES:
            raise StudyError(f"{src}: the grid has {total} points; expected at most {MAX_CASES}.")
        return sampling.full_factorial(axes)
    if method == "list":
        lens = {a.key: len(a.values) for a in axes}
        if len(set(lens.values())) != 1:
            raise StudyError(f"{src}: method 'list' zips the lists; expected equal lengths, got {lens}.")
        return sampling.zipped(axes)
    if method == "lhs":
        return sampling.latin_hypercube(axes, n, seed)
    if method == "sobol":
        return sampling.sobol_points(axes, n, seed)
    return sampling.saltelli(axes, n, seed)


def _load_cycles(names: tuple[str, ...], base: Path, src: str) -> tuple[tuple[str, ...], tuple[Any, ...]]:
    from hevsim.cycles import load_cycle

    labels: list[str] = []
    objs: list[Any] = []
    for i, name in enumerate(names):
        path = base / name
        target: str | Path = path if name.lower().endswith(".csv") and path.is_file() else name
        try:
            cyc = load_cycle(target)
        except HevsimError as exc:
            raise StudyError(f"{src}: cycles[{i}] = {name!r}: {exc}") from exc
        labels.append(name if isinstance(target, str) else cyc.name)
        objs.append(cyc)
    if len(set(labels)) != len(labels):
        raise StudyError(
            f"{src}: cycles = {list(names)}: two cycles share the name; expected distinct cycles."
        )
    return tuple(labels), tuple(objs)


def _reject_unknown(
    table: dict[str, Any], valid: tuple[str, ...], where: str, prefix: str = "", label: str = "keys"
) -> None:
    """Raise :class:`StudyError` naming the first key of ``table`` that is not in ``valid``."""
    unknown = [k for k in table if k not in valid]
    if unknown:
        raise StudyError(
            f"{where}: key '{prefix}{unknown[0]}' is not known; valid {label} are: {', '.join(valid)}."
        )


def study_from_dict(data: dict[str, Any], source: str = "<study>", base_dir: Path | None = None) -> Study:
    """Validate a parsed study mapping into a sampled :class:`Study` (see module docstring)."""
    from hevsim.config import load_vehicle_config
    from hevsim.studies.solvers import solver_spec

    src = source
    base = base_dir or Path(".")
    _reject_unknown(data, TOP_KEYS, src, label="top-level keys")
    for key in ("vehicle", "cycles", "parameters", "solvers", "metrics"):
        if key not in data:
            raise StudyError(f"{src}: key '{key}' is missing; expected it (see docs/studies.md).")
    name = data.get("name", Path(source).stem)
    if not isinstance(name, str) or not name:
        raise StudyError(f"{src}: key 'name' = {name!r}: expected a non-empty string.")
    veh = data["vehicle"]
    if not isinstance(veh, str):
        raise StudyError(f"{src}: key 'vehicle' = {veh!r}: expected the path of a vehicle TOML file.")
    veh_path = (base / veh) if not Path(veh).is_absolute() else Path(veh)
    if not veh_path.is_file():
        raise StudyError(f"{src}: key 'vehicle' = {veh!r}: no file {veh_path}; expected a vehicle TOML file.")
    vehicle = load_vehicle_config(veh_path)

    smp = data.get("sampling", {})
    if not isinstance(smp, dict):
        raise StudyError(f"{src}: [sampling] = {smp!r}: expected a table.")
    _reject_unknown(smp, SAMPLING_KEYS, src, prefix="sampling.")
    method = smp.get("method", "grid")
    if method not in sampling.METHODS:
        raise StudyError(
            f"{src}: key 'sampling.method' = {method!r} is not known; expected one of "
            f"{', '.join(sampling.METHODS)}."
        )
    seed = smp.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise StudyError(f"{src}: key 'sampling.seed' = {seed!r}: expected an integer >= 0.")
    n = smp.get("samples", 0)
    if method in sampling.CONTINUOUS:
        if "samples" not in smp:
            raise StudyError(f"{src}: method '{method}' needs 'sampling.samples' (the sample size).")
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise StudyError(f"{src}: key 'sampling.samples' = {n!r}: expected an integer >= 1.")
        if method in ("sobol", "saltelli") and not sampling.is_power_of_two(n):
            raise StudyError(
                f"{src}: key 'sampling.samples' = {n}: method '{method}' needs a power of 2 "
                f"(e.g. {1 << max(0, n.bit_length() - 1)} or {1 << n.bit_length()})."
            )
    elif "samples" in smp:
        raise StudyError(
            f"{src}: key 'sampling.samples' applies to lhs, sobol and saltelli; method is '{method}'."
        )

    params = data["parameters"]
    if not isinstance(params, dict) or not params:
        raise StudyError(f"{src}: [parameters] = {params!r}: expected a table of at least one key path.")
    axes = tuple(_axis(vehicle, k, v, method, src) for k, v in _flatten(params).items())
    if method in sampling.CONTINUOUS and all(a.low == a.high for a in axes):
        raise StudyError(f"{src}: every range of [parameters] has min = max; nothing to sample.")
    values = _sample(axes, method, int(n), int(seed), src)
    if values.shape[0] * 1 > MAX_CASES:
        raise StudyError(f"{src}: {values.shape[0]} samples; expected at most {MAX_CASES}.")

    cycles, cycle_objs = _load_cycles(_str_list(data["cycles"], f"{src}: key 'cycles'"), base, src)

    raw_solvers = data["solvers"]
    if isinstance(raw_solvers, dict):
        raw_solvers = [raw_solvers]
    if not isinstance(raw_solvers, list) or not raw_solvers:
        raise StudyError(
            f"{src}: key 'solvers' = {raw_solvers!r}: expected [[solvers]] tables with a 'name'."
        )
    solvers: list[SolverCase] = []
    for i, s in enumerate(raw_solvers):
        where = f"{src}: solvers[{i}]"
        if isinstance(s, str):
            s = {"name": s}
        if not isinstance(s, dict) or "name" not in s:
            raise StudyError(f"{where} = {s!r}: expected a table with a 'name'.")
        spec = solver_spec(s["name"], where)
        spec.check_architecture(vehicle, where)
        opts = {k: v for k, v in s.items() if k != "name"}
        solvers.append(SolverCase(spec.name, tuple(sorted(spec.check(vehicle, opts, where).items()))))
    for i, sc in enumerate(solvers):  # options a solver takes from the others (e.g. ecms_dp's grids)
        link = solver_spec(sc.name, src).link
        if link is not None:
            solvers[i] = SolverCase(sc.name, tuple(sorted(link(dict(sc.options), tuple(solvers),
                                                               f"{src}: solvers[{i}]").items())))  # fmt: skip
    labels = [s.label for s in solvers]
    if len(set(labels)) != len(labels):
        raise StudyError(f"{src}: solvers {labels}: two solvers are the same; expected distinct solvers.")

    metrics = _str_list(data["metrics"], f"{src}: key 'metrics'")
    offered = {s.name: solver_spec(s.name, src).metric_names(vehicle) for s in solvers}
    for m in metrics:  # a metric one solver does not give is NaN in its rows
        if not any(m in names for names in offered.values()):
            valid = sorted(set().union(*offered.values()))
            raise StudyError(
                f"{src}: key 'metrics': {m!r} is not a metric of solver(s) {', '.join(offered)}; valid "
                f"metrics are: {', '.join(valid)}."
            )

    pareto: list[Pareto] = []
    raw_p = data.get("pareto", [])
    if isinstance(raw_p, dict):
        raw_p = [raw_p]
    if not isinstance(raw_p, list):
        raise StudyError(f"{src}: key 'pareto' = {raw_p!r}: expected [[pareto]] tables.")
    columns = set(metrics) | {a.key for a in axes}
    for i, p in enumerate(raw_p):
        where = f"{src}: pareto[{i}]"
        if not isinstance(p, dict):
            raise StudyError(f"{where} = {p!r}: expected a table with minimize/maximize lists.")
        _reject_unknown(p, PARETO_KEYS, where)
        mn = _str_list(p.get("minimize", []), f"{where}.minimize", allow_empty=True)
        mx = _str_list(p.get("maximize", []), f"{where}.maximize", allow_empty=True)
        if len(mn) + len(mx) < 2:
            raise StudyError(f"{where}: a Pareto front needs at least two objectives (minimize + maximize).")
        for col in mn + mx:
            if col not in columns:
                raise StudyError(
                    f"{where}: objective {col!r} is neither a kept metric nor a varied parameter; expected "
                    f"one of {', '.join(sorted(columns))}."
                )
        pname = p.get("name", f"front_{i + 1}")
        if not isinstance(pname, str) or not pname.replace("_", "").replace("-", "").isalnum():
            raise StudyError(f"{where}.name = {pname!r}: expected letters, digits, '_' or '-'.")
        pareto.append(Pareto(pname, mn, mx))

    batch = data.get("batch_size", 0)
    if isinstance(batch, bool) or not isinstance(batch, int) or batch < 0:
        raise StudyError(f"{src}: key 'batch_size' = {batch!r}: expected an integer >= 0 (0 = automatic).")
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise StudyError(f"{src}: key 'description' = {desc!r}: expected a string.")
    study = Study(
        name=name, source=source, vehicle=vehicle, vehicle_source=str(veh_path), cycles=cycles,
        cycle_objects=cycle_objs, parameters=axes, method=method, samples=int(n), seed=int(seed),
        solvers=tuple(solvers), metrics=metrics, pareto=tuple(pareto), batch_size=batch,
        description=desc, values=values,
    )  # fmt: skip
    if study.n_cases > MAX_CASES:
        raise StudyError(f"{src}: {study.n_cases} cases; expected at most {MAX_CASES}.")
    return study


def load_study(path: str | Path) -> Study:
    """Read, validate and sample a study TOML file."""
    p = Path(path)
    if not p.is_file():
        raise StudyError(f"{p}: study file not found; expected a TOML file.")
    try:
        data = schema.read_toml(p)  # parses; ``name`` defaults to the file's stem
    except ConfigError as exc:  # not valid TOML: the same message, as a StudyError
        raise StudyError(str(exc)) from exc.__cause__
    return study_from_dict(data, source=str(p), base_dir=p.resolve().parent)

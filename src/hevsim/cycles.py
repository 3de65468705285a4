"""Drive cycles: the speed (and grade) a vehicle is asked to follow over time.

A :class:`DriveCycle` holds sampled ``time_s`` [s], ``speed_mps`` [m/s] and ``grade``
[rise/run fraction]; between samples the cycle is linear, so distance is the trapezoidal
integral of speed. Standard cycles ship with the package (``hevsim/data/cycles``, see
``PROVENANCE.md`` there) and are looked up by name through :func:`load_cycle`; user cycles
are read from CSV files with :func:`load_cycle_csv`.

Example::

    from hevsim.cycles import load_cycle
    udds = load_cycle("udds")
    udds.summary()["distance_mi"]  # 7.45
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property
from importlib.resources import as_file, files
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from hevsim.errors import InputError
from hevsim.io import read_csv_rows
from hevsim.units import M_PER_MILE, MPS_PER_MPH

if TYPE_CHECKING:
    from hevsim.tables import Table1D

FloatArray = npt.NDArray[np.float64]

MPS_PER_KMH = 1000.0 / 3600.0
"""Metres per second in one kilometre per hour [m/s / (km/h)] (exact)."""

TIME_COLUMN = "time_s"
"""Name of the time column of a cycle CSV file [s]."""
SPEED_COLUMNS: dict[str, float] = {
    "speed_mps": 1.0,
    "speed_m_per_s": 1.0,
    "speed_mph": MPS_PER_MPH,
    "speed_kmh": MPS_PER_KMH,
}
"""Accepted speed columns of a cycle CSV file, in order of preference, with the factor that
converts each to [m/s]."""
GRADE_COLUMN = "grade"
"""Name of the optional road grade column of a cycle CSV file [rise/run fraction]."""
MAX_SPEED_MPS = 150.0
"""Highest speed a drive cycle may ask for [m/s] (540 km/h, 336 mph). The fastest road cars
reach about 135 m/s (490 km/h); a cycle beyond 150 m/s is a unit or data error (m/s read as
km/h, or a corrupted row), not a drive a road vehicle can be asked to follow."""

_DATA_PACKAGE = "hevsim"
_CYCLES_TOML = "cycles/cycles.toml"


_NO_GRADE: FloatArray = np.zeros(0)
"""Sentinel default of :attr:`DriveCycle.grade`: replaced by zeros of the right length."""
_NO_GRADE.setflags(write=False)


def _no_grade() -> FloatArray:
    return _NO_GRADE


def _readonly(values: npt.ArrayLike) -> FloatArray:
    arr = np.array(values, dtype=np.float64, copy=True)
    arr.setflags(write=False)
    return arr


def _check_samples(
    time_s: FloatArray,
    speed: FloatArray,
    grade: FloatArray,
    where: str,
    locate: Callable[[int], str],
    columns: tuple[str, str, str] = (TIME_COLUMN, "speed_mps", GRADE_COLUMN),
    to_mps: float = 1.0,
) -> None:
    """Raise :class:`InputError` at the first bad sample.

    Args:
        time_s, speed, grade: equal-length 1-D arrays (speed in the unit of its column)
            [s], [-], [-].
        where: the cycle or file named in the message.
        locate: turns a sample index into "line 7" or "index 5" for the message.
        columns: names of the time, speed and grade columns for the message.
        to_mps: factor converting ``speed`` to [m/s] (for the :data:`MAX_SPEED_MPS` check).
    """
    for values, column in zip((time_s, speed, grade), columns, strict=True):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            i = int(bad[0])
            raise InputError(
                f"{where}: {locate(i)}, column '{column}': value {float(values[i]):g} is not "
                "a finite number; expected a finite number."
            )
    if time_s[0] < 0.0:
        raise InputError(
            f"{where}: {locate(0)}, column '{columns[0]}': value {float(time_s[0]):g} is "
            "negative; expected the cycle to start at a time >= 0 [s]."
        )
    bad = np.flatnonzero(np.diff(time_s) <= 0.0)
    if bad.size:
        i = int(bad[0]) + 1
        raise InputError(
            f"{where}: {locate(i)}, column '{columns[0]}': value {float(time_s[i]):g} does not "
            f"increase on the previous sample {float(time_s[i - 1]):g}; expected strictly "
            "increasing times [s]."
        )
    bad = np.flatnonzero(speed < 0.0)
    if bad.size:
        i = int(bad[0])
        raise InputError(
            f"{where}: {locate(i)}, column '{columns[1]}': value {float(speed[i]):g} is "
            "negative; expected a speed >= 0."
        )
    bad = np.flatnonzero(speed * to_mps > MAX_SPEED_MPS)
    if bad.size:
        i = int(bad[0])
        raise InputError(
            f"{where}: {locate(i)}, column '{columns[1]}': value {float(speed[i]):g} is "
            f"{float(speed[i]) * to_mps:g} m/s; expected a speed <= {MAX_SPEED_MPS:g} m/s "
            f"({MAX_SPEED_MPS / to_mps:g} in this column's unit; check the unit of the column)."
        )


@dataclass(frozen=True, eq=False, repr=False)
class DriveCycle:
    """A sampled drive cycle, linear between samples.

    Arrays are copied to read-only float64 arrays on construction and validated: at least two
    samples, equal lengths, finite values, times strictly increasing and >= 0, speeds >= 0.

    Attributes:
        name: short name, e.g. ``"udds"``.
        time_s: sample times, strictly increasing, starting anywhere >= 0 [s].
        speed_mps: vehicle speed at each sample, >= 0 [m/s].
        grade: road grade at each sample [rise/run fraction]; zeros when not given.
        description: one-line human description.
        source: where the data came from (file, repository and commit, or derivation).
    """

    name: str
    time_s: FloatArray
    speed_mps: FloatArray
    grade: FloatArray = field(default_factory=_no_grade)
    description: str = ""
    source: str = ""

    def __post_init__(self) -> None:
        where = f"drive cycle '{self.name}'" + (f" ({self.source})" if self.source else "")
        time_s = _readonly(self.time_s)
        speed = _readonly(self.speed_mps)
        grade = np.zeros_like(time_s) if self.grade is _NO_GRADE else self.grade
        grade = _readonly(grade)
        for values, column in ((time_s, "time_s"), (speed, "speed_mps"), (grade, "grade")):
            if values.ndim != 1:
                raise InputError(f"{where}: '{column}' has shape {values.shape}; expected a 1-D array.")
        if time_s.size < 2:
            raise InputError(f"{where}: has {time_s.size} sample(s); expected at least 2 samples.")
        if speed.size != time_s.size or grade.size != time_s.size:
            raise InputError(
                f"{where}: length mismatch: time_s has {time_s.size} samples, speed_mps "
                f"{speed.size}, grade {grade.size}; expected equal lengths."
            )
        _check_samples(time_s, speed, grade, where, lambda i: f"index {i}")
        object.__setattr__(self, "time_s", time_s)
        object.__setattr__(self, "speed_mps", speed)
        object.__setattr__(self, "grade", grade)

    def __repr__(self) -> str:
        return (
            f"DriveCycle(name={self.name!r}, n_samples={self.n_samples}, "
            f"t={self.time_s[0]:g}..{self.time_s[-1]:g} s, "
            f"distance={self.distance_m / M_PER_MILE:.3f} mi)"
        )

    # ------------------------------------------------------------------ statistics
    @property
    def n_samples(self) -> int:
        """Number of samples [-]."""
        return int(self.time_s.size)

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample [s]."""
        return float(self.time_s[-1] - self.time_s[0])

    @property
    def distance_m(self) -> float:
        """Distance driven: trapezoidal integral of speed over time [m]."""
        mean_speed = 0.5 * (self.speed_mps[1:] + self.speed_mps[:-1])
        return float(np.sum(mean_speed * np.diff(self.time_s)))

    @property
    def max_speed_mps(self) -> float:
        """Highest sampled speed [m/s]."""
        return float(self.speed_mps.max())

    @property
    def mean_speed_mps(self) -> float:
        """Time-averaged speed, distance / duration, stops included [m/s]."""
        return self.distance_m / self.duration_s

    def summary(self) -> dict[str, float | int]:
        """Key figures: duration_s [s], distance_m [m], distance_mi [mi], max_speed_mps [m/s],
        max_speed_mph [mph], n_samples [-]."""
        return {
            "duration_s": self.duration_s,
            "distance_m": self.distance_m,
            "distance_mi": self.distance_m / M_PER_MILE,
            "max_speed_mps": self.max_speed_mps,
            "max_speed_mph": self.max_speed_mps / MPS_PER_MPH,
            "n_samples": self.n_samples,
        }

    # ------------------------------------------------------------------ interpolation
    @cached_property
    def _speed_table(self) -> Table1D:
        from hevsim.tables import Table1D

        return Table1D(
            np.array(self.time_s),
            np.array(self.speed_mps),
            "clamp",
            "time_s",
            "speed_mps",
            self.name,
        )

    @cached_property
    def _grade_table(self) -> Table1D:
        from hevsim.tables import Table1D

        return Table1D(np.array(self.time_s), np.array(self.grade), "clamp", "time_s", "grade", self.name)

    def speed_at(self, t_s: npt.ArrayLike) -> FloatArray:
        """Speed at times ``t_s`` of any shape, linear between samples [m/s].

        Outside the cycle the first / last speed is held (the ``"clamp"`` policy of
        :mod:`hevsim.tables`). Returns an array of the shape of ``t_s`` [m/s].
        """
        return self._speed_table(t_s)

    def grade_at(self, t_s: npt.ArrayLike) -> FloatArray:
        """Grade at times ``t_s`` [s] of any shape, linear between samples [fraction]."""
        return self._grade_table(t_s)

    # ------------------------------------------------------------------ derived cycles
    def resampled(self, dt_s: float) -> DriveCycle:
        """The cycle sampled every ``dt_s`` [s] from ``time_s[0]`` to ``time_s[-1]``.

        The end point is always included; when the duration is not a whole number of steps
        the last step is shorter than ``dt_s``. Speed and grade are interpolated linearly, so
        the distance is preserved exactly when the new grid contains the old samples.
        """
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise InputError(
                f"drive cycle '{self.name}': resampling step dt_s={dt_s:g}; expected a finite step > 0 [s]."
            )
        t0 = float(self.time_s[0])
        t1 = float(self.time_s[-1])
        n_steps = math.floor(self.duration_s / dt_s * (1.0 + 1e-12))
        grid = t0 + dt_s * np.arange(n_steps + 1, dtype=np.float64)
        if t1 - grid[-1] > 1e-9 * max(dt_s, 1.0):
            grid = np.append(grid, t1)
        else:
            grid[-1] = t1
        return replace(
            self,
            time_s=grid,
            speed_mps=self.speed_at(grid),
            grade=self.grade_at(grid),
            description=f"{self.description} (resampled every {dt_s:g} s)".lstrip(),
        )

    def repeated(self, n: int) -> DriveCycle:
        """The cycle driven ``n`` times end to end, time continuing.

        When the last sample equals the first (same speed and grade, e.g. both stopped) the
        joining sample is shared, so each repeat adds exactly :attr:`duration_s` [s] and
        :attr:`distance_m` [m]. Otherwise each repeat starts one first-sample interval
        (``time_s[1] - time_s[0]``) after the previous end, with a linear ramp between.
        """
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
            raise InputError(f"drive cycle '{self.name}': repeat count {n!r}; expected an integer >= 1.")
        n = int(n)
        joins = bool(self.speed_mps[-1] == self.speed_mps[0] and self.grade[-1] == self.grade[0])
        start = 1 if joins else 0
        period = self.duration_s + (0.0 if joins else float(self.time_s[1] - self.time_s[0]))
        offsets = period * np.arange(1, n, dtype=np.float64)
        time_s = np.concatenate([self.time_s, *(self.time_s[start:] + k for k in offsets)])
        speed = np.concatenate([self.speed_mps, *([self.speed_mps[start:]] * (n - 1))])
        grade = np.concatenate([self.grade, *([self.grade[start:]] * (n - 1))])
        return replace(
            self,
            time_s=time_s,
            speed_mps=speed,
            grade=grade,
            description=f"{self.description} (repeated {n} times)".lstrip(),
        )

    def truncated(self, t_end_s: float) -> DriveCycle:
        """The cycle up to time ``t_end_s`` [s] inclusive.

        Samples after ``t_end_s`` are dropped; if ``t_end_s`` falls between samples an
        interpolated end sample is added. ``t_end_s`` at or past the end returns the cycle
        unchanged.
        """
        t0 = float(self.time_s[0])
        if not (math.isfinite(t_end_s) and t_end_s > t0):
            raise InputError(
                f"drive cycle '{self.name}': truncation time t_end_s={t_end_s:g}; expected a "
                f"time after the first sample {t0:g} s [s]."
            )
        if t_end_s >= self.time_s[-1]:
            return self
        keep = int(np.searchsorted(self.time_s, t_end_s, side="right"))
        time_s = self.time_s[:keep]
        speed = self.speed_mps[:keep]
        grade = self.grade[:keep]
        if time_s[-1] != t_end_s:
            time_s = np.append(time_s, t_end_s)
            speed = np.append(speed, self.speed_at(t_end_s))
            grade = np.append(grade, self.grade_at(t_end_s))
        return replace(
            self,
            time_s=time_s,
            speed_mps=speed,
            grade=grade,
            description=f"{self.description} (truncated at {t_end_s:g} s)".lstrip(),
        )


# ---------------------------------------------------------------------- CSV files
def _read_csv_rows(path: Path) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """Header names and data rows with their 1-based physical line numbers
    (:func:`hevsim.io.read_csv_rows`: blank lines and ``#`` lines skipped, fields stripped)."""
    if path.is_dir():
        raise InputError(
            f"{path} is a directory; expected a CSV file or a shipped cycle name ({', '.join(CYCLE_NAMES)})."
        )
    return read_csv_rows(path, f"a CSV file with columns '{TIME_COLUMN}' and one of {list(SPEED_COLUMNS)}")


def _parse_column(path: Path, rows: list[tuple[int, list[str]]], index: int, column: str) -> FloatArray:
    out = np.empty(len(rows), dtype=np.float64)
    for k, (line, fields) in enumerate(rows):
        text = fields[index]
        try:
            out[k] = float(text)
        except ValueError:
            raise InputError(
                f"{path}: line {line}, column '{column}': value {text!r} is not a number; "
                "expected a finite number."
            ) from None
    return out


def load_cycle_csv(path: str | Path, name: str | None = None) -> DriveCycle:
    """Read a drive cycle from a CSV file.

    The file has a header line and columns ``time_s`` [s], one speed column (the first
    present of ``speed_mps``, ``speed_m_per_s`` [m/s], ``speed_mph`` [mph], ``speed_kmh``
    [km/h]; converted to [m/s]) and optionally ``grade`` [rise/run fraction]; other columns
    are ignored. Blank lines and lines starting with ``#`` are skipped. Errors name the file,
    the line (the header being line 1 when it is the first line), the column and the value.

    Args:
        path: the CSV file.
        name: cycle name; defaults to the file name without extension.

    Returns:
        The cycle, with ``source`` set to the file path. Parsed once per file content
        (:func:`hevsim.io.cached_by_content`; a cycle is immutable: read-only arrays).
    """
    from hevsim.io import cached_by_content

    p = Path(path)
    if not p.is_file():
        return _parse_cycle_csv(p, name)  # its errors name the file
    cycle: DriveCycle = cached_by_content(p, _parse_cycle_csv, name)
    return cycle


def _parse_cycle_csv(p: Path, name: str | None) -> DriveCycle:
    """:func:`load_cycle_csv`'s parser."""
    header, rows = _read_csv_rows(p)
    lowered = [h.lower() for h in header]
    if TIME_COLUMN not in lowered:
        raise InputError(
            f"{p}: missing time column; found columns {header}, expected a column '{TIME_COLUMN}' [s]."
        )
    speed_column = next((c for c in SPEED_COLUMNS if c in lowered), None)
    if speed_column is None:
        raise InputError(
            f"{p}: missing speed column; found columns {header}, expected one of "
            f"{list(SPEED_COLUMNS)} (m/s, m/s, mph, km/h)."
        )
    if len(rows) < 2:
        raise InputError(f"{p}: has {len(rows)} data line(s); expected at least 2 samples.")
    for line, fields in rows:
        if len(fields) != len(header):
            raise InputError(
                f"{p}: line {line}: has {len(fields)} field(s) {fields}; expected "
                f"{len(header)} fields as in the header {header}."
            )
    time_s = _parse_column(p, rows, lowered.index(TIME_COLUMN), TIME_COLUMN)
    speed_raw = _parse_column(p, rows, lowered.index(speed_column), speed_column)
    if GRADE_COLUMN in lowered:
        grade = _parse_column(p, rows, lowered.index(GRADE_COLUMN), GRADE_COLUMN)
    else:
        grade = np.zeros_like(time_s)
    lines = [line for line, _ in rows]
    _check_samples(
        time_s,
        speed_raw,
        grade,
        str(p),
        lambda i: f"line {lines[i]}",
        (TIME_COLUMN, speed_column, GRADE_COLUMN),
        SPEED_COLUMNS[speed_column],
    )
    return DriveCycle(
        name=name if name is not None else p.stem,
        time_s=time_s,
        speed_mps=speed_raw * SPEED_COLUMNS[speed_column],
        grade=grade,
        description=f"user cycle from {p.name}",
        source=str(p),
    )


# ---------------------------------------------------------------------- registry
def _cycles_metadata() -> dict[str, Any]:
    """The parsed ``data/cycles/cycles.toml`` (parsed once per file content: a deep copy)."""
    import copy

    from hevsim.io import cached_by_content

    resource = files(_DATA_PACKAGE) / "data" / _CYCLES_TOML
    with as_file(resource) as path:
        return copy.deepcopy(cached_by_content(path, _parse_toml_file))


def _parse_toml_file(path: Path) -> dict[str, Any]:
    with path.open("rb") as stream:
        return tomllib.load(stream)


def _source_text(meta: dict[str, Any]) -> str:
    src = meta.get("source", {})
    parts = [
        src.get("upstream", ""),
        f"{src.get('repository', '')} {src.get('path', '')}".strip(),
        f"commit {src['commit_head']}" if "commit_head" in src else "",
    ]
    text = "; ".join(p for p in parts if p)
    return f"{text} (see hevsim/data/PROVENANCE.md)" if text else "hevsim/data/PROVENANCE.md"


@dataclass(frozen=True)
class _ShippedCycle:
    """A cycle read from a CSV file shipped in ``hevsim/data``, described in cycles.toml."""

    key: str
    """Table name in ``cycles.toml``."""

    def load(self, name: str) -> DriveCycle:
        meta = _cycles_metadata()[self.key]
        description = str(meta["description"])
        if "quality_warning" in meta:
            description = f"{description}. Quality warning: {meta['quality_warning']}"
        resource = files(_DATA_PACKAGE) / "data" / str(meta["file"])
        with as_file(resource) as path:
            cycle = load_cycle_csv(path, name=name)
        return replace(cycle, description=description, source=_source_text(meta))


@dataclass(frozen=True)
class _DerivedCycle:
    """A cycle built in code from another registered cycle."""

    base: str
    build: Callable[[DriveCycle], DriveCycle]
    description: str

    def load(self, name: str) -> DriveCycle:
        base = load_cycle(self.base)
        cycle = self.build(base)
        return replace(
            cycle,
            name=name,
            description=self.description,
            source=f"derived from '{self.base}' ({base.source})",
        )


FU505_END_S = 505.0
"""End of the fu505 cycle: the first 505 s of the UDDS, which end at a stop [s]."""
FU505X10_REPEATS = 10
"""Number of fu505 repeats in fu505x10 [-]."""

_REGISTRY: dict[str, _ShippedCycle | _DerivedCycle] = {
    "udds": _ShippedCycle("udds"),
    "ftp75": _ShippedCycle("ftp75"),
    "hwfet": _ShippedCycle("hwfet"),
    "us06": _ShippedCycle("us06"),
    "sc03": _ShippedCycle("sc03"),
    "nycc": _ShippedCycle("nycc"),
    "la92": _ShippedCycle("la92"),
    "wltc3b": _ShippedCycle("wltc_class3b"),
    "wltc3a": _ShippedCycle("wltc_class3a"),
    "nedc": _ShippedCycle("nedc_approx"),
    "manhattan_bus": _ShippedCycle("manhattan_bus"),
    "hotlap_0_200": _ShippedCycle("hotlap_0_200"),
    "fu505": _DerivedCycle(
        "udds",
        lambda udds: udds.truncated(FU505_END_S),
        "First 505 s of the UDDS (t = 0..505 s inclusive, ends at a stop)",
    ),
    "fu505x10": _DerivedCycle(
        "fu505",
        lambda fu505: fu505.repeated(FU505X10_REPEATS),
        "fu505 driven 10 times end to end (joining stops shared), 5050 s",
    ),
}

CYCLE_NAMES: tuple[str, ...] = tuple(_REGISTRY)
"""Names accepted by :func:`load_cycle`."""


def load_cycle(name_or_path: str | Path) -> DriveCycle:
    """Load a registered cycle by name (see :data:`CYCLE_NAMES`) or a user CSV file by path.

    A string is looked up as a name first (case-insensitive), then as a file path; a
    :class:`~pathlib.Path` is always a file. Raises :class:`InputError` naming the valid
    cycle names when neither matches.
    """
    if isinstance(name_or_path, str):
        spec = _REGISTRY.get(name_or_path.strip().lower())
        if spec is not None:
            return spec.load(name_or_path.strip().lower())
        if not Path(name_or_path).exists():
            raise InputError(
                f"unknown drive cycle {name_or_path!r} (not a registered name and no such "
                f"file); expected one of {', '.join(CYCLE_NAMES)} or the path of a CSV file "
                f"with columns '{TIME_COLUMN}' and one of {list(SPEED_COLUMNS)}."
            )
    return load_cycle_csv(name_or_path)


def list_cycles() -> list[dict[str, str | float]]:
    """One row per registered cycle: name, description, duration_s [s], distance_mi [mi],
    max_speed_mph [mph] (for the ``hevsim cycles`` table)."""
    rows: list[dict[str, str | float]] = []
    for name in CYCLE_NAMES:
        cycle = load_cycle(name)
        stats = cycle.summary()
        rows.append(
            {
                "name": name,
                "description": cycle.description,
                "duration_s": stats["duration_s"],
                "distance_mi": stats["distance_mi"],
                "max_speed_mph": stats["max_speed_mph"],
            }
        )
    return rows

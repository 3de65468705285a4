"""1-D and 2-D lookup tables with one interpolation and extrapolation policy.

Interpolation is always linear. Outside the axis range a table either *clamps* to the edge
value or extrapolates *linearly* from the two edge points; the choice is made per table
(``extrapolation="clamp"`` or ``"linear"``). Tables are validated on construction: axes must be
strictly increasing, free of NaN, and their sizes must match the data.

The scalar kernels :func:`interp1` and :func:`interp2` are numba-compiled so that compiled
simulation loops call exactly the same code as the vectorised ``Table1D.__call__`` and
``Table2D.__call__`` used by the quasi-static (DP) models: one interpolation, every solver.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from numba import njit

from hevsim.errors import InputError

Extrapolation = Literal["clamp", "linear"]
_EXTRAPOLATIONS: tuple[str, ...] = ("clamp", "linear")
FloatArray = npt.NDArray[np.float64]


BORROWS: dict[str, Any] = {"_nrt": False}
"""numba options of the interpolation kernels: no reference counting (they allocate nothing and
only borrow the caller's tables; the forward loops call them tens of thousands of times a run)."""


@njit(cache=True, inline="always")
def _segment(xp: FloatArray, x: float) -> int:
    """Index i of the segment [xp[i], xp[i+1]] holding x (edge segments outside the range)."""
    n = xp.shape[0]
    if x <= xp[0]:
        return 0
    if x >= xp[n - 1]:
        return n - 2
    lo = 0
    hi = n - 1
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if xp[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True, **BORROWS)
def interp1(xp: FloatArray, fp: FloatArray, x: float, linear: bool) -> float:
    """Linear interpolation of ``fp(xp)`` at scalar ``x``.

    Outside ``[xp[0], xp[-1]]`` the edge value is returned (``linear=False``) or the edge
    segment is extended (``linear=True``). ``xp`` must hold at least one point.
    """
    n = xp.shape[0]
    if n == 1:
        return fp[0]
    if not linear:
        if x <= xp[0]:
            return fp[0]
        if x >= xp[n - 1]:
            return fp[n - 1]
    i = _segment(xp, x)
    w = (x - xp[i]) / (xp[i + 1] - xp[i])
    return fp[i] + w * (fp[i + 1] - fp[i])


@njit(cache=True, **BORROWS)
def interp2(xp: FloatArray, yp: FloatArray, fp: FloatArray, x: float, y: float, linear: bool) -> float:
    """Bilinear interpolation of ``fp[i, j] = f(xp[i], yp[j])`` at scalar ``(x, y)``."""
    nx = xp.shape[0]
    ny = yp.shape[0]
    if not linear:
        x = min(max(x, xp[0]), xp[nx - 1])
        y = min(max(y, yp[0]), yp[ny - 1])
    if nx == 1:
        return interp1(yp, fp[0, :], y, linear)
    if ny == 1:
        return interp1(xp, fp[:, 0], x, linear)
    i, j, wx, wy = _bracket2(xp, yp, x, y)
    return _blend2(fp, i, j, wx, wy)


@njit(cache=True, inline="always")
def _bracket2(xp: FloatArray, yp: FloatArray, x: float, y: float) -> tuple[int, int, float, float]:
    """The cell ``(i, j)`` of the grid ``xp`` x ``yp`` holding ``(x, y)`` and the point's weights
    in it (:func:`interp2`, :func:`interp2_three`)."""
    i = _segment(xp, x)
    j = _segment(yp, y)
    return i, j, (x - xp[i]) / (xp[i + 1] - xp[i]), (y - yp[j]) / (yp[j + 1] - yp[j])


@njit(cache=True, inline="always")
def _blend2(fp: FloatArray, i: int, j: int, wx: float, wy: float) -> float:
    """The bilinear value of ``fp`` in the cell ``(i, j)`` at the weights ``wx``, ``wy``."""
    f0 = fp[i, j] + wy * (fp[i, j + 1] - fp[i, j])
    f1 = fp[i + 1, j] + wy * (fp[i + 1, j + 1] - fp[i + 1, j])
    return f0 + wx * (f1 - f0)


@njit(cache=True, inline="always")
def interp2_three(
    xp: FloatArray,
    yp: FloatArray,
    fa: FloatArray,
    fb: FloatArray,
    fc: FloatArray,
    x: float,
    y: float,
    linear: bool,
) -> tuple[float, float, float]:
    """:func:`interp2` of three tables on the same axes at one ``(x, y)``, bit for bit, with
    one bracketing of the point: inlined into the caller, without the three calls (each
    passing both axes and its table on the stack)."""
    nx = xp.shape[0]
    ny = yp.shape[0]
    if nx == 1 or ny == 1:
        return (interp2(xp, yp, fa, x, y, linear), interp2(xp, yp, fb, x, y, linear),
                interp2(xp, yp, fc, x, y, linear))  # fmt: skip
    if not linear:
        x = min(max(x, xp[0]), xp[nx - 1])
        y = min(max(y, yp[0]), yp[ny - 1])
    i, j, wx, wy = _bracket2(xp, yp, x, y)
    return _blend2(fa, i, j, wx, wy), _blend2(fb, i, j, wx, wy), _blend2(fc, i, j, wx, wy)


@njit(cache=True)
def _interp1_many(xp: FloatArray, fp: FloatArray, x: FloatArray, linear: bool) -> FloatArray:
    out = np.empty(x.shape[0])
    for k in range(x.shape[0]):
        out[k] = interp1(xp, fp, x[k], linear)
    return out


@njit(cache=True)
def _interp2_many(
    xp: FloatArray, yp: FloatArray, fp: FloatArray, x: FloatArray, y: FloatArray, linear: bool
) -> FloatArray:
    out = np.empty(x.shape[0])
    for k in range(x.shape[0]):
        out[k] = interp2(xp, yp, fp, x[k], y[k], linear)
    return out


def _check_axis(axis: FloatArray, name: str, source: str) -> None:
    if axis.ndim != 1 or axis.size == 0:
        raise InputError(
            f"{source}: axis '{name}' must be a non-empty 1-D list of numbers, got shape {axis.shape}."
        )
    bad = np.flatnonzero(~np.isfinite(axis))
    if bad.size:
        raise InputError(
            f"{source}: axis '{name}' has a non-finite value {float(axis[bad[0]]):g} at position "
            f"{bad[0]}; expected finite numbers."
        )
    steps = np.diff(axis)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0])
        raise InputError(
            f"{source}: axis '{name}' is not strictly increasing: value {float(axis[i + 1]):g} at "
            f"position {i + 1} follows {float(axis[i]):g}; expected sorted, distinct breakpoints."
        )


def _check_values(values: FloatArray, name: str, source: str) -> None:
    bad = np.argwhere(~np.isfinite(values))
    if bad.size:
        idx = tuple(int(i) for i in bad[0])
        raise InputError(
            f"{source}: table '{name}' has a non-finite value {float(values[idx]):g} at index {idx}; "
            "expected finite numbers everywhere (fill gaps in the source data)."
        )


def _check_extrapolation(extrapolation: str, source: str) -> None:
    if extrapolation not in _EXTRAPOLATIONS:
        raise InputError(
            f"{source}: extrapolation {extrapolation!r} is not known; expected one of "
            f"{', '.join(_EXTRAPOLATIONS)}."
        )


@dataclass(frozen=True, eq=False)
class Table1D:
    """y = f(x) by linear interpolation; see the module docstring for the policy.

    Attributes:
        x: breakpoints, strictly increasing [unit of ``x_name``].
        y: values at the breakpoints [unit of ``y_name``].
        extrapolation: ``"clamp"`` or ``"linear"``.
        x_name, y_name: names with units, used in error messages and plots.
        source: where the data came from (file path or citation).
    """

    x: FloatArray
    y: FloatArray
    extrapolation: Extrapolation = "clamp"
    x_name: str = "x"
    y_name: str = "y"
    source: str = "table"

    def __post_init__(self) -> None:
        x = np.ascontiguousarray(self.x, dtype=np.float64)
        y = np.ascontiguousarray(self.y, dtype=np.float64)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "y", y)
        _check_extrapolation(self.extrapolation, self.source)
        _check_axis(x, self.x_name, self.source)
        if y.shape != x.shape:
            raise InputError(
                f"{self.source}: table '{self.y_name}' has {y.size} values but axis "
                f"'{self.x_name}' has {x.size} breakpoints; expected equal sizes."
            )
        _check_values(y, self.y_name, self.source)

    @property
    def linear(self) -> bool:
        """True when the table extrapolates linearly."""
        return self.extrapolation == "linear"

    def __call__(self, x: npt.ArrayLike) -> FloatArray:
        """Evaluate at ``x`` of any shape; returns an array of the same shape."""
        xa = np.asarray(x, dtype=np.float64)
        flat = _interp1_many(self.x, self.y, np.ascontiguousarray(xa.ravel()), self.linear)
        return flat.reshape(xa.shape)

    @classmethod
    def from_csv(
        cls,
        path: str | Path,
        x_col: str,
        y_col: str,
        extrapolation: Extrapolation = "clamp",
        scale: float = 1.0,
    ) -> Table1D:
        """Load two columns of a CSV file; ``scale`` multiplies the values."""
        frame = read_csv_columns(path, [x_col, y_col])
        return cls(
            frame[x_col],
            frame[y_col] * scale,
            extrapolation,
            x_name=x_col,
            y_name=y_col,
            source=str(path),
        )


@dataclass(frozen=True, eq=False)
class Table2D:
    """z = f(x, y) by bilinear interpolation on a rectangular grid, ``z[i, j] = f(x[i], y[j])``."""

    x: FloatArray
    y: FloatArray
    z: FloatArray
    extrapolation: Extrapolation = "clamp"
    x_name: str = "x"
    y_name: str = "y"
    z_name: str = "z"
    source: str = "table"
    meta: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        x = np.ascontiguousarray(self.x, dtype=np.float64)
        y = np.ascontiguousarray(self.y, dtype=np.float64)
        z = np.ascontiguousarray(self.z, dtype=np.float64)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "y", y)
        object.__setattr__(self, "z", z)
        _check_extrapolation(self.extrapolation, self.source)
        _check_axis(x, self.x_name, self.source)
        _check_axis(y, self.y_name, self.source)
        if z.shape != (x.size, y.size):
            raise InputError(
                f"{self.source}: table '{self.z_name}' has shape {z.shape} but the axes "
                f"'{self.x_name}' x '{self.y_name}' need ({x.size}, {y.size})."
            )
        _check_values(z, self.z_name, self.source)

    @property
    def linear(self) -> bool:
        """True when the table extrapolates linearly."""
        return self.extrapolation == "linear"

    def __call__(self, x: npt.ArrayLike, y: npt.ArrayLike) -> FloatArray:
        """Evaluate at broadcast ``(x, y)`` of any shapes; returns the broadcast shape."""
        xa, ya = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
        flat = _interp2_many(
            self.x,
            self.y,
            self.z,
            np.ascontiguousarray(xa.ravel()),
            np.ascontiguousarray(ya.ravel()),
            self.linear,
        )
        return flat.reshape(xa.shape)

    @classmethod
    def from_long_csv(
        cls,
        path: str | Path,
        x_col: str,
        y_col: str,
        z_col: str,
        extrapolation: Extrapolation = "clamp",
        scale: float = 1.0,
    ) -> Table2D:
        """Load a long-format CSV (one row per grid point ``x, y, z``) into a full grid.

        Every (x, y) combination must appear exactly once.
        """
        frame = read_csv_columns(path, [x_col, y_col, z_col])
        xs = np.unique(frame[x_col])
        ys = np.unique(frame[y_col])
        if xs.size * ys.size != frame[x_col].size:
            raise InputError(
                f"{path}: columns '{x_col}', '{y_col}' do not form a full rectangular grid "
                f"({xs.size} x {ys.size} distinct values but {frame[x_col].size} rows); "
                "expected every combination exactly once."
            )
        z = np.full((xs.size, ys.size), np.nan)
        i = np.searchsorted(xs, frame[x_col])
        j = np.searchsorted(ys, frame[y_col])
        z[i, j] = frame[z_col] * scale
        return cls(xs, ys, z, extrapolation, x_name=x_col, y_name=y_col, z_name=z_col, source=str(path))


def read_csv_columns(path: str | Path, columns: list[str]) -> dict[str, FloatArray]:
    """Read numeric ``columns`` of a CSV file with clear errors (file, column, line, value).

    Parsed once per file content (:func:`hevsim.io.cached_by_content`); the arrays returned
    are the caller's own copies."""
    from hevsim.io import cached_by_content

    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: file not found; expected a CSV file with columns {columns}.")
    parsed: dict[str, FloatArray] = cached_by_content(p, _parse_csv_columns, tuple(columns))
    return {c: v.copy() for c, v in parsed.items()}


def _parse_csv_columns(p: Path, columns: tuple[str, ...]) -> dict[str, FloatArray]:
    """:func:`read_csv_columns`'s parser (its arrays are made read-only: they are cached)."""
    import pandas as pd

    columns = list(columns)  # type: ignore[assignment]
    try:
        frame = pd.read_csv(p, comment="#", skipinitialspace=True)
    except Exception as exc:  # pandas raises several parser error types
        raise InputError(f"{p}: cannot be read as CSV ({exc}).") from exc
    frame.columns = [str(c).strip() for c in frame.columns]
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise InputError(
            f"{p}: missing column(s) {missing}; found {list(frame.columns)}, expected {columns}."
        )
    out: dict[str, FloatArray] = {}
    for c in columns:
        values = pd.to_numeric(frame[c], errors="coerce").to_numpy(dtype=np.float64)
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            row = int(bad[0])
            raise InputError(
                f"{p}: line {row + 2}, column '{c}': value {str(frame[c].iloc[row])!r} is not a "
                "finite number; expected a number."
            )
        values.setflags(write=False)
        out[c] = values
    return out


def read_meta(folder: str | Path, what: str) -> dict[str, Any]:
    """Parse ``folder/meta.toml`` of a component-data folder, with a clear error if absent
    (parsed once per file content: the dictionary returned is the caller's own copy)."""
    import copy

    from hevsim.io import cached_by_content

    path = Path(folder) / "meta.toml"
    if not path.is_file():
        raise InputError(f"{path}: {what} metadata file not found; expected a meta.toml file.")
    return copy.deepcopy(cached_by_content(path, _parse_meta))


def _parse_meta(path: Path) -> dict[str, Any]:
    """:func:`read_meta`'s parser (cached per file content: callers get deep copies)."""
    import tomllib

    from hevsim.io import read_text_utf8

    try:
        return tomllib.loads(read_text_utf8(path, error=InputError))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML ({exc}).") from exc

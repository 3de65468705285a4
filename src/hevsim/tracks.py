"""Race tracks: a closed centreline with its curvature, elevation and banking along distance.

A :class:`Track` holds samples at a uniform distance step around a closed loop (sample ``i``
at ``distance_m[i] = i * step_m``, the last sample's successor is the first):
signed curvature [1/m] (> 0 turns left), elevation [m], banking [rad] (> 0 tilts the road
down towards the left, i.e. into a left-hand corner) and the track widths to the right and
left [m] where the source gives them.

A track comes from

* a CSV of the centreline, ``x_m, y_m`` [m] with optional ``w_tr_right_m, w_tr_left_m`` [m]
  (the layout of the TUM racetrack database, whose header line starts with ``#``) and
  optional ``elevation_m`` [m] / ``banking_deg`` [deg]. The points are interpolated by a
  periodic cubic spline in chord length (:func:`scipy.interpolate.splprep`, ``per=1``),
  resampled at equal arc length; the curvature is the spline's,
  ``kappa = (x' y'' - y' x'') / (x'^2 + y'^2)^(3/2)``, smoothed by a periodic Gaussian filter
  along distance (:data:`CURVATURE_SMOOTHING_M`). (FITPACK's smoothing splines, ``s > 0``,
  smooth by dropping knots and make the curvature of a sampled circle wander by 10 %);
* a CSV of ``distance_m, curvature_1pm`` [m, 1/m] (optional ``elevation_m``,
  ``banking_deg``), interpolated linearly onto the step; the centreline is the integral of
  the heading (``theta' = kappa``, ``x' = cos theta``, ``y' = sin theta``) and must close;
* or a shipped name (:data:`TRACK_NAMES`): three tracks built from stated geometry of
  straights and constant-radius arcs (:func:`skidpad`, :func:`oval`, :func:`handling_circuit`)
  and one real circuit, ``monza`` (TUM racetrack database, LGPL-3.0; see
  ``hevsim/data/PROVENANCE.md``).

Bad input raises :class:`~hevsim.errors.InputError` naming the file, the column or the
place along the track (distance from the first point [m]): a centreline that does not close
(gap between the last and the first point larger than :data:`CLOSURE_GAP_FACTOR` times the
median point spacing, or a distance-curvature track whose end misses its start by more than
:data:`CLOSURE_TOLERANCE_M`), one that crosses itself, and (:meth:`Track.check_radius`) a
curvature spike beyond a vehicle's minimum turning radius.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from hevsim.errors import InputError
from hevsim.io import read_csv_rows

FloatArray = npt.NDArray[np.floating[Any]]

DEFAULT_STEP_M = 1.0
"""Default distance step of a resampled track [m]."""
CURVATURE_SMOOTHING_M = 5.0
"""Standard deviation [m] of the periodic Gaussian filter applied along distance to the
curvature of an x-y centreline (about a car's length: the curvature a car follows is averaged
over its wheelbase). The interpolating spline through GPS-derived points has corner-entry
spikes (smallest radius 8.8 m on the shipped Monza centreline; 11.6 m after the filter,
17.6 m with 10 m); a circle keeps its curvature exactly."""
CLOSURE_GAP_FACTOR = 4.0
"""An x-y centreline closes if its last point lies within this many median point spacings of
its first [-]."""
CLOSURE_TOLERANCE_M = 1.0
"""Largest miss [m] of the end of a distance-curvature track on its start (position)."""
HEADING_TOLERANCE_RAD = 0.02
"""Largest miss [rad] of a distance-curvature track's total turning on +-2 pi."""
INTERSECTION_POINTS = 1500
"""Largest number of points of the self-intersection test (:func:`_check_simple`) [-]."""
ELEVATION_TOLERANCE_M = 0.5
"""Largest difference [m] between the elevation at the end and at the start of a lap."""
XY_COLUMNS = ("x_m", "y_m")
CURVATURE_COLUMNS = ("distance_m", "curvature_1pm")
OPTIONAL_COLUMNS = ("w_tr_right_m", "w_tr_left_m", "elevation_m", "banking_deg")


@dataclass(frozen=True)
class Track:
    """A closed track sampled at a uniform step (see the module docstring).

    Attributes: name, step_m [m], distance_m [m] (n samples from 0), curvature_1pm [1/m],
    x_m, y_m [m] (centreline), elevation_m [m], banking_rad [rad], width_right_m,
    width_left_m [m] (nan where unknown), source (file or geometry).
    """

    name: str
    step_m: float
    distance_m: FloatArray
    curvature_1pm: FloatArray
    x_m: FloatArray
    y_m: FloatArray
    elevation_m: FloatArray
    banking_rad: FloatArray
    width_right_m: FloatArray
    width_left_m: FloatArray
    source: str = ""
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def length_m(self) -> float:
        """Lap length [m]."""
        return float(self.step_m * self.distance_m.size)

    @property
    def grade(self) -> FloatArray:
        """Road grade (rise / run) [-] at each sample: periodic central difference of the
        elevation."""
        z = self.elevation_m
        return (np.roll(z, -1) - np.roll(z, 1)) / (2.0 * self.step_m)

    def resampled(self, step_m: float) -> Track:
        """The same track at another distance step [m] (linear interpolation of every
        channel around the loop; the step is adjusted so that a whole number fits the lap)."""
        n = _samples(self.length_m, step_m, self.name)
        s = np.arange(n) * (self.length_m / n)
        sp = np.append(self.distance_m, self.length_m)

        def per(a: FloatArray) -> FloatArray:
            return np.interp(s, sp, np.append(a, a[0]))

        return Track(
            self.name,
            self.length_m / n,
            s,
            per(self.curvature_1pm),
            per(self.x_m),
            per(self.y_m),
            per(self.elevation_m),
            per(self.banking_rad),
            per(self.width_right_m),
            per(self.width_left_m),
            self.source,
            dict(self.metadata),
        )

    def check_radius(self, min_radius_m: float, who: str = "the vehicle") -> None:
        """Raise InputError at the first sample whose curvature radius is below
        ``min_radius_m`` [m] (a corner ``who`` cannot turn)."""
        bad = np.flatnonzero(np.abs(self.curvature_1pm) * min_radius_m > 1.0)
        if bad.size:
            i = int(bad[0])
            k = float(self.curvature_1pm[i])
            raise InputError(
                f"track '{self.name}' ({self.source}): curvature {k:.4g} 1/m at distance "
                f"{self.distance_m[i]:.1f} m (x = {self.x_m[i]:.1f} m, y = {self.y_m[i]:.1f} m) is a radius "
                f"of {1.0 / abs(k):.3g} m, below the minimum turning radius {min_radius_m:g} m of {who} "
                f"('body.min_turning_radius_m'); {bad.size} samples are affected. Expected a smooth "
                "centreline (check the points there)."
            )

    def to_frame(self) -> Any:
        """The samples as a table (pandas DataFrame) with unit-named columns."""
        import pandas as pd

        return pd.DataFrame(
            {
                "distance_m": self.distance_m,
                "x_m": self.x_m,
                "y_m": self.y_m,
                "curvature_1pm": self.curvature_1pm,
                "elevation_m": self.elevation_m,
                "banking_deg": np.degrees(self.banking_rad),
                "w_tr_right_m": self.width_right_m,
                "w_tr_left_m": self.width_left_m,
            }
        )

    def plot(self, path: str | Path) -> Path:
        """Centreline coloured by curvature and curvature against distance (PNG)."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from hevsim.io import save_png

        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 5), gridspec_kw={"width_ratios": [1, 1.3]})
        lim = float(np.percentile(np.abs(self.curvature_1pm), 99)) or 1e-3
        sc = ax1.scatter(self.x_m, self.y_m, c=self.curvature_1pm, s=2, cmap="coolwarm", vmin=-lim, vmax=lim)
        ax1.plot(self.x_m[0], self.y_m[0], "k>", ms=8)
        ax1.set_aspect("equal")
        ax1.set_xlabel("x [m]")
        ax1.set_ylabel("y [m]")
        ax1.set_title(f"{self.name}: {self.length_m:.0f} m")
        fig.colorbar(sc, ax=ax1, label="curvature [1/m]")
        ax2.plot(self.distance_m, self.curvature_1pm, lw=0.8)
        ax2.set_xlabel("distance [m]")
        ax2.set_ylabel("curvature [1/m] (> 0 left)")
        ax2.grid(True)
        fig.tight_layout()
        save_png(fig, path, 100)
        plt.close(fig)
        return Path(path)


def _samples(length_m: float, step_m: float, name: str) -> int:
    if not (math.isfinite(step_m) and step_m > 0.0):
        raise InputError(f"track '{name}': distance step {step_m!r} m; expected a finite step > 0 m.")
    n = round(length_m / step_m)
    if n < 8:
        raise InputError(
            f"track '{name}': distance step {step_m:g} m leaves {n} samples on a {length_m:.1f} m lap; "
            "expected a step below 1/8 of the lap."
        )
    return n


def _self_intersection(x: FloatArray, y: FloatArray) -> int | None:
    """Index of the first segment ``i`` (from point ``i`` to ``i+1``, closed loop) that
    crosses a later, non-adjacent segment; None if the loop is simple."""
    n = x.size
    x2, y2 = np.roll(x, -1), np.roll(y, -1)
    block = 512
    for i0 in range(0, n, block):
        i = np.arange(i0, min(i0 + block, n))[:, None]
        j = np.arange(n)[None, :]
        ax, ay, bx, by = x[i], y[i], x2[i], y2[i]
        cx, cy, dx, dy = x[j], y[j], x2[j], y2[j]

        def orient(px: Any, py: Any, qx: Any, qy: Any, rx: Any, ry: Any) -> Any:
            return (qx - px) * (ry - py) - (qy - py) * (rx - px)

        o1 = orient(ax, ay, bx, by, cx, cy)
        o2 = orient(ax, ay, bx, by, dx, dy)
        o3 = orient(cx, cy, dx, dy, ax, ay)
        o4 = orient(cx, cy, dx, dy, bx, by)
        cross = (o1 * o2 < 0.0) & (o3 * o4 < 0.0)
        adjacent = (np.abs(i - j) <= 1) | (np.abs(i - j) >= n - 1)
        hit = np.argwhere(cross & ~adjacent & (j > i))
        if hit.size:
            return int(hit[0, 0] + i0)
    return None


def _check_simple(name: str, where: str, x: FloatArray, y: FloatArray, s: FloatArray) -> None:
    """Refuse a loop that crosses itself. The test is O(n^2): a loop of more than
    :data:`INTERSECTION_POINTS` points is tested on every k-th point (a crossing at an angle
    stays a crossing; two branches that cross at a grazing angle within k steps may pass)."""
    stride = max(1, -(-x.size // INTERSECTION_POINTS))
    x, y, s = x[::stride], y[::stride], s[::stride]
    k = _self_intersection(x, y)
    if k is not None:
        raise InputError(
            f"track '{name}' ({where}): the centreline crosses itself at distance {s[k]:.1f} m "
            f"(x = {x[k]:.1f} m, y = {y[k]:.1f} m); expected a simple closed loop."
        )


def from_curvature(
    name: str,
    distance_m: npt.ArrayLike,
    curvature_1pm: npt.ArrayLike,
    *,
    step_m: float = DEFAULT_STEP_M,
    elevation_m: npt.ArrayLike | None = None,
    banking_deg: npt.ArrayLike | None = None,
    length_m: float | None = None,
    source: str = "",
    step_curvature: bool = False,
) -> Track:
    """A track from curvature [1/m] at increasing distances [m] (first at 0), closed at
    ``length_m`` [m] (default the last distance). ``step_curvature``: the curvature of each
    row holds up to the next row (straights and arcs), else it is interpolated linearly.
    The centreline integrates the heading (midpoint rule on the step) and must close."""
    s_in = np.asarray(distance_m, np.float64)
    k_in = np.asarray(curvature_1pm, np.float64)
    where = source or "distance-curvature"
    if k_in.shape != s_in.shape:
        s_in = np.full(1, np.nan)
    if (
        s_in.ndim != 1
        or s_in.size < (1 if length_m is not None else 2)
        or s_in[0] != 0.0
        or np.any(np.diff(s_in) <= 0.0)
    ):
        raise InputError(
            f"track '{name}' ({where}): column 'distance_m' must start at 0 and increase strictly "
            "(at least two rows), as long as column 'curvature_1pm'."
        )
    total = float(length_m if length_m is not None else s_in[-1])
    if total <= s_in[-1] - 1e-9 and length_m is not None:
        raise InputError(f"track '{name}' ({where}): lap length {total:g} m is below the last distance.")
    n = _samples(total, step_m, name)
    h = total / n
    s = np.arange(n) * h

    def at(values: FloatArray, pts: FloatArray) -> FloatArray:
        if step_curvature:
            idx = np.searchsorted(s_in, pts, side="right") - 1
            return values[np.clip(idx, 0, values.size - 1)]
        return np.interp(pts, s_in, values)

    kappa = at(k_in, s)
    # exact heading theta(s) = integral of the curvature (piecewise linear or constant)
    if total > s_in[-1]:  # the last row holds (step) or ramps back to the first row's value
        ends = np.append(s_in, total)
        k_next = k_in if step_curvature else np.append(k_in[1:], k_in[0])
    else:  # rows up to the lap's end: the intervals between rows
        ends, k_in = s_in, k_in[:-1]
        k_next = k_in if step_curvature else np.asarray(curvature_1pm, np.float64)[1:]
    slope = (k_next - k_in) / np.diff(ends)
    h_rows = np.concatenate([[0.0], np.cumsum(k_in * np.diff(ends) + 0.5 * slope * np.diff(ends) ** 2)])

    def heading(pts: FloatArray) -> FloatArray:
        j = np.clip(np.searchsorted(ends, pts, side="right") - 1, 0, k_in.size - 1)
        d = pts - ends[j]
        return h_rows[j] + k_in[j] * d + 0.5 * slope[j] * d * d

    heading_mid = np.append(heading(s), h_rows[-1])
    # centreline: heading at the middle of each step (midpoint rule, O(h^2))
    th = heading(s + 0.5 * h)
    x = np.concatenate([[0.0], np.cumsum(np.cos(th) * h)])
    y = np.concatenate([[0.0], np.cumsum(np.sin(th) * h)])
    turn = float(heading_mid[-1])
    miss = math.hypot(x[-1], y[-1])
    if abs(abs(turn) - 2.0 * math.pi) > HEADING_TOLERANCE_RAD or miss > CLOSURE_TOLERANCE_M:
        raise InputError(
            f"track '{name}' ({where}): the track does not close: at distance {total:.1f} m (the end) the "
            f"centreline is {miss:.2f} m from its start and has turned {math.degrees(turn):.2f} deg; "
            "expected "
            f"to return within {CLOSURE_TOLERANCE_M:g} m and +-360 deg (within "
            f"{math.degrees(HEADING_TOLERANCE_RAD):.1f} deg)."
        )
    x, y = x[:-1], y[:-1]
    _check_simple(name, where, x, y, s)
    z = np.zeros(n) if elevation_m is None else np.interp(s, s_in, np.asarray(elevation_m, np.float64))
    if elevation_m is not None:
        z_end = float(np.asarray(elevation_m, np.float64)[-1])
        if length_m is None and abs(z_end - z[0]) > ELEVATION_TOLERANCE_M:
            raise InputError(
                f"track '{name}' ({where}): column 'elevation_m': the track does not close in height: "
                f"{z_end:g} m at the end (distance {total:.1f} m), {z[0]:g} m at the start; expected a "
                f"difference below {ELEVATION_TOLERANCE_M:g} m."
            )
    bank = np.zeros(n) if banking_deg is None else np.radians(np.interp(s, s_in, np.asarray(banking_deg)))
    nan = np.full(n, np.nan)
    return Track(name, h, s, kappa, x, y, z, bank, nan, nan.copy(), where)


def from_xy(
    name: str,
    x_m: npt.ArrayLike,
    y_m: npt.ArrayLike,
    *,
    step_m: float = DEFAULT_STEP_M,
    width_right_m: npt.ArrayLike | None = None,
    width_left_m: npt.ArrayLike | None = None,
    elevation_m: npt.ArrayLike | None = None,
    banking_deg: npt.ArrayLike | None = None,
    source: str = "",
    smoothing_m: float = CURVATURE_SMOOTHING_M,
) -> Track:
    """A track from centreline points [m] (a closed loop; the first point is not repeated at
    the end, or repeated exactly): periodic cubic spline, curvature smoothed over
    ``smoothing_m`` [m] (module docstring)."""
    from scipy.interpolate import splev, splprep
    from scipy.ndimage import gaussian_filter1d

    x = np.asarray(x_m, np.float64)
    y = np.asarray(y_m, np.float64)
    where = source or "x-y points"
    extra = {
        k: (None if v is None else np.asarray(v, np.float64))
        for k, v in (
            ("w_tr_right_m", width_right_m),
            ("w_tr_left_m", width_left_m),
            ("elevation_m", elevation_m),
            ("banking_deg", banking_deg),
        )
    }
    if x.size >= 2 and x[-1] == x[0] and y[-1] == y[0]:
        x, y = x[:-1], y[:-1]
        extra = {k: (None if v is None else v[:-1]) for k, v in extra.items()}
    if x.size < 8:
        raise InputError(f"track '{name}' ({where}): {x.size} points; expected at least 8.")
    seg = np.hypot(np.diff(x), np.diff(y))
    s_pts = np.concatenate([[0.0], np.cumsum(seg)])
    dup = np.flatnonzero(seg <= 0.0)
    if dup.size:
        k = int(dup[0])
        raise InputError(
            f"track '{name}' ({where}): points {k + 1} and {k + 2} coincide (distance {s_pts[k]:.1f} m); "
            "expected distinct consecutive points."
        )
    gap = math.hypot(x[0] - x[-1], y[0] - y[-1])
    spacing = float(np.median(seg))
    if gap > CLOSURE_GAP_FACTOR * spacing:
        raise InputError(
            f"track '{name}' ({where}): the track does not close: the last point (distance "
            f"{s_pts[-1]:.1f} m, x = {x[-1]:.1f} m, y = {y[-1]:.1f} m) is {gap:.1f} m from the first; "
            "expected "
            f"a closed loop (gap within {CLOSURE_GAP_FACTOR:g} x the median point spacing {spacing:.2f} m)."
        )
    _check_simple(name, where, x, y, s_pts)
    xc, yc = np.append(x, x[0]), np.append(y, y[0])
    u = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(xc), np.diff(yc)))])
    tck, _ = splprep([xc, yc], u=u, s=0.0, per=1, k=3)
    # arc length of the spline on a dense grid, then equal arc-length samples
    dense = np.linspace(0.0, u[-1], 20 * x.size + 1)
    dx, dy = splev(dense, tck, der=1)
    speed = np.hypot(dx, dy)
    arc = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(dense))])
    total = float(arc[-1])
    n = _samples(total, step_m, name)
    s = np.arange(n) * (total / n)
    uu = np.interp(s, arc, dense)
    px, py = splev(uu, tck)
    d1x, d1y = splev(uu, tck, der=1)
    d2x, d2y = splev(uu, tck, der=2)
    kappa = (d1x * d2y - d1y * d2x) / np.hypot(d1x, d1y) ** 3
    if smoothing_m > 0.0:
        kappa = gaussian_filter1d(kappa, smoothing_m / (total / n), mode="wrap")
    px, py = np.asarray(px), np.asarray(py)
    s_of_pts = np.interp(u, dense, arc)

    def chan(key: str, default: float) -> FloatArray:
        v = extra[key]
        if v is None:
            return np.full(n, default)
        return np.interp(s, s_of_pts, np.append(v, v[0]))

    if extra["elevation_m"] is not None:
        ez = extra["elevation_m"]
        if abs(ez[-1] - ez[0]) > ELEVATION_TOLERANCE_M + abs(float(np.max(np.abs(np.diff(ez))))):
            raise InputError(
                f"track '{name}' ({where}): column 'elevation_m': the track does not close in height: "
                f"{ez[-1]:g} m at the last point, {ez[0]:g} m at the first."
            )
    return Track(
        name,
        total / n,
        s,
        np.asarray(kappa),
        px,
        py,
        chan("elevation_m", 0.0),
        np.radians(chan("banking_deg", 0.0)),
        chan("w_tr_right_m", np.nan),
        chan("w_tr_left_m", np.nan),
        where,
        {"points": int(x.size), "curvature_smoothing_m": smoothing_m},
    )


def _read_columns(path: Path) -> dict[str, FloatArray]:
    """Columns of a track CSV by header name. The header is the first line; it may start
    with ``#`` (the TUM racetrack database). Other ``#`` lines are comments."""
    expected = (
        "a track CSV (columns x_m, y_m or distance_m, curvature_1pm) "
        f"or a shipped track name ({', '.join(TRACK_NAMES)})"
    )
    header, rows = read_csv_rows(path, expected, hash_header=(*XY_COLUMNS, *CURVATURE_COLUMNS))
    if not rows:
        raise InputError(f"{path}: no data rows; expected {expected}.")
    out: dict[str, FloatArray] = {}
    for c, name in enumerate(header):
        if name not in (*XY_COLUMNS, *CURVATURE_COLUMNS, *OPTIONAL_COLUMNS):
            continue
        col = np.empty(len(rows))
        for k, (line, fields) in enumerate(rows):
            text = fields[c] if c < len(fields) else ""
            try:
                col[k] = float(text)
            except ValueError:
                col[k] = np.nan
            if not math.isfinite(col[k]):
                raise InputError(
                    f"{path}: line {line}, column '{name}': value {text!r} is not a finite number; "
                    "expected a finite number."
                )
        out[name] = col
    return out


def load_track_csv(path: str | Path, *, step_m: float = DEFAULT_STEP_M, name: str | None = None) -> Track:
    """Read a track CSV (x-y centreline or distance-curvature; see the module docstring)."""
    p = Path(path)
    cols = _read_columns(p)
    nm = name or p.stem
    if all(c in cols for c in XY_COLUMNS):
        return from_xy(
            nm,
            cols["x_m"],
            cols["y_m"],
            step_m=step_m,
            width_right_m=cols.get("w_tr_right_m"),
            width_left_m=cols.get("w_tr_left_m"),
            elevation_m=cols.get("elevation_m"),
            banking_deg=cols.get("banking_deg"),
            source=str(p),
        )
    if all(c in cols for c in CURVATURE_COLUMNS):
        return from_curvature(
            nm,
            cols["distance_m"],
            cols["curvature_1pm"],
            step_m=step_m,
            elevation_m=cols.get("elevation_m"),
            banking_deg=cols.get("banking_deg"),
            source=str(p),
        )
    raise InputError(
        f"{p}: columns {sorted(cols)} found; expected 'x_m', 'y_m' (optional 'w_tr_right_m', 'w_tr_left_m', "
        "'elevation_m', 'banking_deg') or 'distance_m', 'curvature_1pm' (optional 'elevation_m', "
        "'banking_deg')."
    )


# ------------------------------------------------------------------------------------------
# Tracks from stated geometry
# ------------------------------------------------------------------------------------------
def from_segments(
    name: str, segments: list[tuple[float, float]], *, step_m: float = DEFAULT_STEP_M, source: str = ""
) -> Track:
    """A track of straights and constant-radius arcs: ``segments`` is a list of
    ``(length_m, radius_m)`` with radius ``inf`` for a straight, > 0 for a left-hand arc and
    < 0 for a right-hand one [m]. The loop must close (checked)."""
    lengths = np.array([seg[0] for seg in segments], np.float64)
    kappa = np.array([0.0 if math.isinf(seg[1]) else 1.0 / seg[1] for seg in segments])
    starts = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
    return from_curvature(
        name,
        starts,
        kappa,
        step_m=step_m,
        length_m=float(lengths.sum()),
        source=source or "segments",
        step_curvature=True,
    )


def segment_rows(segments: list[tuple[float, float]]) -> tuple[FloatArray, FloatArray]:
    """(distance [m], curvature [1/m]) rows of a distance-curvature CSV that reproduce
    ``segments`` (as :func:`from_segments`) under linear interpolation: each piece's start
    and a row :data:`SEGMENT_EDGE_M` before its end, and the lap's end."""
    lengths = np.array([seg[0] for seg in segments], np.float64)
    kappa = np.array([0.0 if math.isinf(seg[1]) else 1.0 / seg[1] for seg in segments])
    starts = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
    d = np.ravel(np.column_stack([starts, starts + lengths - SEGMENT_EDGE_M]))
    k = np.repeat(kappa, 2)
    return np.append(d, lengths.sum()), np.append(k, kappa[0])


SEGMENT_EDGE_M = 1e-6
"""Length [m] of the ramp between two pieces in :func:`segment_rows`."""


SKIDPAD_RADIUS_M = 30.48
"""Radius of the skidpad circle [m]: 200 ft diameter, the circle of the road tests of US
magazines' lateral-g figures."""


def skidpad(radius_m: float = SKIDPAD_RADIUS_M, *, step_m: float = DEFAULT_STEP_M) -> Track:
    """A circle of ``radius_m`` [m] driven anticlockwise (constant curvature 1/R)."""
    return from_segments(
        "skidpad",
        [(2.0 * math.pi * radius_m, radius_m)],
        step_m=step_m,
        source=f"geometry: circle R = {radius_m:g} m",
    )


def oval(straight_m: float = 800.0, radius_m: float = 200.0, *, step_m: float = DEFAULT_STEP_M) -> Track:
    """Two straights of ``straight_m`` [m] joined by two 180-degree left-hand arcs of
    ``radius_m`` [m] (default: 2 x 800 m + 2 x 628.3 m = 2856.6 m)."""
    half = math.pi * radius_m
    return from_segments(
        "oval",
        [(straight_m, math.inf), (half, radius_m), (straight_m, math.inf), (half, radius_m)],
        step_m=step_m,
        source=f"geometry: 2 straights {straight_m:g} m, 2 half circles R = {radius_m:g} m",
    )


def handling_circuit(*, step_m: float = DEFAULT_STEP_M) -> Track:
    """A 2.5 km handling circuit of straights and constant-radius corners, anticlockwise,
    starting east on the main straight (radius > 0 left, < 0 right; lengths [m]):

    * S1 straight 700 m (heading east); T1 90 deg left, R 60 m (north);
    * S2 straight 200 m; T2 90 deg left, R 30 m (west);
    * S3 straight 150 m; T3 90 deg right, R 40 m (north);
    * S4 straight 100 m; T4 90 deg left, R 40 m (west);
    * S5 straight (closes x); T5 90 deg left, R 50 m (south);
    * S6 straight (closes y); T6 90 deg left, R 80 m (east).

    S5 and S6 are computed so that the loop closes: east +700 +60 -30 -150 -40 -40 - S5 - 50
    + 80 = 0 gives S5 = 530 m; north +60 +200 +30 +40 +100 +40 - 50 - S6 - 80 = 0 gives
    S6 = 340 m (total 2491.2 m; slowest corner T2).
    """
    segs = _handling_segments()
    return from_segments("handling", segs, step_m=step_m, source="geometry: hevsim.tracks.handling_circuit")


def _handling_segments() -> list[tuple[float, float]]:
    q = 0.5 * math.pi
    s5 = 700.0 + 60.0 - 30.0 - 150.0 - 40.0 - 40.0 - 50.0 + 80.0
    s6 = 60.0 + 200.0 + 30.0 + 40.0 + 100.0 + 40.0 - 50.0 - 80.0
    return [
        (700.0, math.inf),
        (q * 60.0, 60.0),
        (200.0, math.inf),
        (q * 30.0, 30.0),
        (150.0, math.inf),
        (q * 40.0, -40.0),
        (100.0, math.inf),
        (q * 40.0, 40.0),
        (s5, math.inf),
        (q * 50.0, 50.0),
        (s6, math.inf),
        (q * 80.0, 80.0),
    ]


def geometry(name: str) -> list[tuple[float, float]]:
    """The ``(length_m, radius_m)`` pieces of a track built from stated geometry
    (``skidpad``, ``oval``, ``handling``; see :func:`from_segments`)."""
    return list(_GEOMETRY[name]())


_GEOMETRY = {
    "skidpad": lambda: [(2.0 * math.pi * SKIDPAD_RADIUS_M, SKIDPAD_RADIUS_M)],
    "oval": lambda: [
        (800.0, math.inf),
        (math.pi * 200.0, 200.0),
        (800.0, math.inf),
        (math.pi * 200.0, 200.0),
    ],
    "handling": _handling_segments,
}

TRACK_NAMES = ("skidpad", "oval", "handling", "monza")
"""Shipped tracks."""


def _shipped_csv(name: str) -> Path:
    return Path(str(resources.files("hevsim") / "data" / "tracks" / f"{name}.csv"))


def load_track(name_or_path: str | Path, *, step_m: float = DEFAULT_STEP_M) -> Track:
    """A shipped track by name (:data:`TRACK_NAMES`) or a track CSV file."""
    key = str(name_or_path)
    if key == "skidpad":
        return skidpad(step_m=step_m)
    if key == "oval":
        return oval(step_m=step_m)
    if key == "handling":
        return handling_circuit(step_m=step_m)
    if key in TRACK_NAMES:
        return load_track_csv(_shipped_csv(key), step_m=step_m, name=key)
    return load_track_csv(key, step_m=step_m)

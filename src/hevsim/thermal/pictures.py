"""Pictures of a module temperature field (pyplot-free; used by ``run_thermal`` and the co-simulation).

Every function takes the mesh (:func:`hevsim.thermal.geometry.build_module_mesh`), its split
discretisation (:func:`hevsim.thermal.solver.discretise`: ``points_m``, ``tets``, ``node_part``),
the :class:`~hevsim.thermal.geometry.ModuleGeometry`, one temperature [°C] per node of the
discretisation and the time [s], and writes one PNG:

* :func:`plot_cells_top` - top view, each cell coloured by its mean temperature, hottest outlined;
* :func:`plot_plate` - cooling-plate top face with the channel (thesis fig 4.30);
* :func:`plot_cells_section` - vertical x-z sections through each row of cells (thesis fig 4.32);
* :func:`plot_fields` - all three.

matplotlib is imported only inside the drawing functions.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import InputError

#: Colour map of the temperature fields (rainbow, as the thesis's Abaqus pictures).
FIELD_CMAP = "turbo"
#: Smallest span [K] of the cell top view's colour scale.
MIN_CELL_SPAN_K = 0.5
_DPI = 120
_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])


def check_field(mesh: Any, disc: Any, temp_c: Any, where: str = "temperature field") -> np.ndarray:
    """``temp_c`` as a float array of one finite temperature [°C] per discretisation node."""
    n = int(disc.points_m.shape[0])
    t = np.asarray(temp_c, dtype=float)
    if t.shape != (n,):
        raise InputError(
            f"{where}: temp_c has shape {t.shape}; expected shape ({n},), one temperature [°C] per "
            "node of the discretisation (disc.points_m), not of the unsplit mesh."
        )
    if not np.all(np.isfinite(t)):
        raise InputError(f"{where}: temp_c contains NaN or infinity at {int(np.sum(~np.isfinite(t)))} nodes.")
    if disc.tets.shape[0] != mesh.cell_of_tet.shape[0]:
        raise InputError(
            f"{where}: the discretisation has {disc.tets.shape[0]} tetrahedra but the mesh "
            f"{mesh.cell_of_tet.shape[0]}; expected the discretisation of this mesh."
        )
    return t


def cell_temperatures_c(mesh: Any, disc: Any, temp_c: Any) -> tuple[np.ndarray, np.ndarray]:
    """Volume-weighted mean and maximum temperature [°C] of every battery cell, ``(mean, max)``.

    A cell's nodes are those of the tetrahedra with ``mesh.cell_of_tet == cell``; nodal weights
    are a quarter of the volume of each tetrahedron touching the node (as in ``run_thermal``).
    """
    from hevsim.thermal.solver import cell_nodes

    t = check_field(mesh, disc, temp_c, "cell temperatures")
    node_vol, nodes_of_cell = cell_nodes(mesh, disc)
    mean, peak = np.full(len(nodes_of_cell), np.nan), np.full(len(nodes_of_cell), np.nan)
    for c, nodes in enumerate(nodes_of_cell):
        if nodes.size:
            mean[c] = np.average(t[nodes], weights=node_vol[nodes])
            peak[c] = t[nodes].max()
    return mean, peak


@dataclass(frozen=True)
class Section:
    """Cut of the tetrahedra by the plane ``y = y_m``: triangles in the x-z plane.

    ``x_m``, ``z_m``, ``temp_c`` per section vertex (vertices are not shared between
    tetrahedra, so jumps across part interfaces stay visible); ``triangles`` (T, 3) into them;
    ``part`` part index per vertex; ``outline`` (E, 2, 2) [m] x-z segments on part boundaries.
    """

    y_m: float
    x_m: np.ndarray
    z_m: np.ndarray
    temp_c: np.ndarray
    part: np.ndarray
    triangles: np.ndarray
    outline: np.ndarray


def section_y(mesh: Any, disc: Any, temp_c: Any, y_m: float) -> Section:
    """Exact cut of the P1 field by the vertical plane ``y = y_m`` (linear along tetrahedron edges).

    The plane is moved by 1e-9 of the mesh size so that nodes lying on it do not give
    degenerate pieces.
    """
    t = check_field(mesh, disc, temp_c, "section")
    p = disc.points_m
    span = float(np.ptp(p, axis=0).max()) or 1.0
    y0 = float(y_m) + 1e-9 * span
    d = p[:, 1] - y0
    dt = d[disc.tets]
    cut = np.flatnonzero((dt.min(axis=1) < 0) & (dt.max(axis=1) > 0))
    tets = disc.tets[cut]
    a, b = tets[:, _EDGES[:, 0]], tets[:, _EDGES[:, 1]]
    pa, pb = p[a], p[b]
    # canonical edge direction (lexicographic on coordinates) so that neighbouring tetrahedra,
    # and the split copies of a node, give bit-identical intersection points
    swap = (pa[..., 0] > pb[..., 0]) | (
        (pa[..., 0] == pb[..., 0])
        & ((pa[..., 1] > pb[..., 1]) | ((pa[..., 1] == pb[..., 1]) & (pa[..., 2] > pb[..., 2])))
    )
    a, b = np.where(swap, b, a), np.where(swap, a, b)
    da, db = d[a], d[b]
    hit = (da < 0) != (db < 0)
    s = np.where(hit, da / np.where(hit, da - db, 1.0), 0.0)
    xz = p[a][..., [0, 2]] + s[..., None] * (p[b][..., [0, 2]] - p[a][..., [0, 2]])
    tv = t[a] + s * (t[b] - t[a])
    nhit = hit.sum(axis=1)
    part_of_tet = np.asarray(mesh.part_of_tet)[cut]
    xs, ts, parts, tris, segs, seg_part = [], [], [], [], [], []
    start = 0
    for k, tri_local in ((3, [[0, 1, 2]]), (4, [[0, 1, 2], [0, 2, 3]])):
        sel = np.flatnonzero(nhit == k)
        if sel.size == 0:
            continue
        order = np.argsort(~hit[sel], axis=1, kind="stable")[:, :k]
        pts = np.take_along_axis(xz[sel], order[..., None], axis=1)  # (S, k, 2)
        tk = np.take_along_axis(tv[sel], order, axis=1)
        centre = pts.mean(axis=1, keepdims=True)
        ang = np.arctan2(pts[..., 1] - centre[..., 1], pts[..., 0] - centre[..., 0])
        ring = np.argsort(ang, axis=1)
        pts = np.take_along_axis(pts, ring[..., None], axis=1)
        tk = np.take_along_axis(tk, ring, axis=1)
        base = start + k * np.arange(sel.size)[:, None, None]
        tris.append((base + np.asarray(tri_local)[None]).reshape(-1, 3))
        xs.append(pts.reshape(-1, 2))
        ts.append(tk.ravel())
        parts.append(np.repeat(part_of_tet[sel], k))
        segs.append(np.stack([pts, np.roll(pts, -1, axis=1)], axis=2).reshape(-1, 2, 2))
        seg_part.append(np.repeat(part_of_tet[sel], k))
        start += k * sel.size
    if not xs:
        empty = np.zeros(0)
        return Section(
            float(y_m), empty, empty, empty, np.zeros(0, int), np.zeros((0, 3), int), np.zeros((0, 2, 2))
        )
    v = np.concatenate(xs)
    seg = np.concatenate(segs)
    sp = np.concatenate(seg_part)
    # part boundaries: segments seen once (outer boundary, channel) or by two different parts
    first = (seg[:, 0, 0] < seg[:, 1, 0]) | ((seg[:, 0, 0] == seg[:, 1, 0]) & (seg[:, 0, 1] <= seg[:, 1, 1]))
    canon = np.where(first[:, None, None], seg, seg[:, ::-1])
    key = np.round(canon.reshape(-1, 4) / (1e-9 * span)).astype(np.int64)
    _, inv, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    lo = np.full(count.size, np.iinfo(np.int64).max)
    hi = np.full(count.size, -1)
    np.minimum.at(lo, inv, sp)
    np.maximum.at(hi, inv, sp)
    boundary = (count[inv] == 1) | (lo[inv] != hi[inv])
    length = np.linalg.norm(canon[:, 1] - canon[:, 0], axis=1)
    keep = boundary & (length > 0)
    _, uniq = np.unique(inv[keep], return_index=True)
    outline = canon[keep][uniq]
    return Section(
        float(y_m), v[:, 0], v[:, 1], np.concatenate(ts), np.concatenate(parts), np.concatenate(tris), outline
    )


def row_y_m(geometry: Any) -> list[float]:
    """y [m] of the centre line of every row of cells."""
    return [float(geometry.cell_centre_xy_m(r, 0)[1]) for r in range(geometry.rows)]


def section_hot_points(
    mesh: Any, disc: Any, geometry: Any, temp_c: Any, part: str | None = "cells"
) -> list[dict[str, Any]]:
    """Hottest point of each row section (the one :func:`plot_cells_section` marks).

    One dict per row: ``row`` (1-based), ``x_m``, ``y_m``, ``z_m``, ``temp_c``, ``part``; only
    points of ``part`` count (``None``: any part). The field is linear in each tetrahedron, so
    the maximum over the section lies on a section vertex.
    """
    names = list(mesh.part_names)
    if part is not None and part not in names:
        raise InputError(f"section hot points: part '{part}' is not in the mesh; parts are {names}.")
    out = []
    for r, y in enumerate(row_y_m(geometry)):
        sec = section_y(mesh, disc, temp_c, y)
        ok = np.ones(sec.temp_c.size, bool) if part is None else sec.part == names.index(part)
        if not ok.any():
            continue
        i = int(np.flatnonzero(ok)[np.argmax(sec.temp_c[ok])])
        out.append(
            {
                "row": r + 1,
                "x_m": float(sec.x_m[i]),
                "y_m": y,
                "z_m": float(sec.z_m[i]),
                "temp_c": float(sec.temp_c[i]),
                "part": str(names[int(sec.part[i])]),
            }
        )
    return out


def raster_triangles(
    corners: np.ndarray, values: np.ndarray, extent: tuple[float, float, float, float], shape: tuple[int, int]
) -> np.ndarray:
    """Sample a piecewise-linear field on a regular grid of pixel centres; NaN outside.

    ``corners`` (T, 3, 2) triangle corners, ``values`` (T, 3) corner values, ``extent``
    ``(x0, x1, y0, y1)``, ``shape`` ``(ny, nx)``. Values are interpolated (not colours, as
    Gouraud shading does), so a colour map with many hues stays correct inside big triangles.
    """
    ny, nx = shape
    x0, x1, y0, y1 = extent
    dx, dy = (x1 - x0) / nx, (y1 - y0) / ny
    img = np.full(shape, np.nan)
    if corners.shape[0] == 0:
        return img
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    i0 = np.clip(np.ceil((lo[:, 0] - x0) / dx - 0.5), 0, nx).astype(np.int64)
    i1 = np.clip(np.floor((hi[:, 0] - x0) / dx - 0.5), -1, nx - 1).astype(np.int64)
    j0 = np.clip(np.ceil((lo[:, 1] - y0) / dy - 0.5), 0, ny).astype(np.int64)
    j1 = np.clip(np.floor((hi[:, 1] - y0) / dy - 0.5), -1, ny - 1).astype(np.int64)
    wi, wj = np.maximum(i1 - i0 + 1, 0), np.maximum(j1 - j0 + 1, 0)
    count = wi * wj
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    ok = (count > 0) & (np.abs(det) > 1e-30)
    tri = np.repeat(np.flatnonzero(ok), count[ok])
    if tri.size == 0:
        return img
    local = np.arange(tri.size) - np.repeat(np.cumsum(count[ok]) - count[ok], count[ok])
    ii = i0[tri] + local % wi[tri]
    jj = j0[tri] + local // wi[tri]
    px, py = x0 + (ii + 0.5) * dx, y0 + (jj + 0.5) * dy
    ax_, ay_ = a[tri, 0], a[tri, 1]
    l1 = ((px - ax_) * (c[tri, 1] - ay_) - (c[tri, 0] - ax_) * (py - ay_)) / det[tri]
    l2 = ((b[tri, 0] - ax_) * (py - ay_) - (px - ax_) * (b[tri, 1] - ay_)) / det[tri]
    l0 = 1.0 - l1 - l2
    eps = -1e-9
    inside = (l0 >= eps) & (l1 >= eps) & (l2 >= eps)
    v = values[tri]
    img[jj[inside], ii[inside]] = (l0 * v[:, 0] + l1 * v[:, 1] + l2 * v[:, 2])[inside]
    return img


def _save(fig: Any, path: str | Path) -> Path:
    """Write ``fig`` to ``path`` (PNG, tight bounding box) through the package's one atomic save."""
    from hevsim.io import save_png

    return save_png(fig, path, _DPI, bbox_inches="tight")


def _module_outline(ax: Any, geometry: Any) -> None:
    from matplotlib.patches import Rectangle

    ax.add_patch(
        Rectangle((0, 0), geometry.length_x_m * 1e3, geometry.length_y_m * 1e3, fill=False, lw=1, ec="0.3")
    )


def plot_cells_top(mesh: Any, disc: Any, geometry: Any, temp_c: Any, time_s: float, path: str | Path) -> Path:
    """Top view of the cells, each filled with its mean temperature and labelled mean / max [°C].

    The colour scale spans at least :data:`MIN_CELL_SPAN_K` so that differences of hundredths of
    a kelvin do not look like hot and cold cells. The cell with the highest mean temperature is
    outlined. Returns ``path``.
    """
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle

    g = geometry
    mean, peak = cell_temperatures_c(mesh, disc, temp_c)
    ncell = mean.size
    if ncell != g.rows * g.columns:
        raise InputError(
            f"cells top view: the mesh has {ncell} cells; expected rows x columns = {g.rows * g.columns}."
        )
    lo, hi = float(np.nanmin(mean)), float(np.nanmax(mean))
    pad = max(0.0, MIN_CELL_SPAN_K - (hi - lo)) / 2
    norm, cmap = Normalize(lo - pad, hi + pad), colormaps[FIELD_CMAP]
    lx, ly = g.length_x_m * 1e3, g.length_y_m * 1e3
    fig = Figure(
        figsize=(max(6.0, 1.25 * g.columns + 2.0), max(3.4, 1.25 * g.rows + 1.9)), layout="constrained"
    )
    ax = fig.add_subplot()
    _module_outline(ax, g)
    hot = int(np.nanargmax(mean))
    rad_mm = g.cell_diameter_m * 500
    font = float(np.clip(7.0 * g.cell_diameter_m / 0.018 * min(1.0, 8.0 / max(g.columns, g.rows)), 4.5, 8.0))
    for c in range(ncell):
        r, col = divmod(c, g.columns)
        x, y = (v * 1e3 for v in g.cell_centre_xy_m(r, col))
        level = float(norm(mean[c]))
        ax.add_patch(Circle((x, y), rad_mm, fc=cmap(level), ec="0.25", lw=0.6))
        ax.text(
            x,
            y,
            f"#{c + 1}\n{mean[c]:.2f}\nmax {peak[c]:.2f}",
            ha="center",
            va="center",
            fontsize=font,
            color="white" if level < 0.2 or level > 0.85 else "black",
        )
    hx, hy = (v * 1e3 for v in g.cell_centre_xy_m(*divmod(hot, g.columns)))
    ax.add_patch(Circle((hx, hy), rad_mm * 1.1, fill=False, ec="black", lw=2.2))
    marker = Line2D([], [], ls="", marker="o", mfc="none", mec="black", mew=2, ms=11)
    fig.legend(
        [marker],
        [f"hottest cell: #{hot + 1}, mean {mean[hot]:.2f} °C (cells numbered along x, row 1 nearest y = 0)"],
        loc="outside lower center",
        fontsize=8,
        frameon=False,
    )
    ax.set_xlim(-0.02 * lx, 1.02 * lx)
    ax.set_ylim(-0.04 * ly, 1.04 * ly)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(f"Battery cells at t = {time_s:g} s, top view (label: cell, mean, max [°C])", fontsize=10)
    fig.colorbar(ScalarMappable(norm, cmap), ax=ax, label="cell mean temperature [°C]", shrink=0.9)
    return _save(fig, path)


@dataclass(frozen=True)
class PlateFace:
    """Temperature of the cooling plate's top face: ``xy_m`` (N, 2) [m] node coordinates,
    ``temp_c`` (N,) [°C], ``triangles`` (T, 3) a triangulation of the nodes, the plate's
    ``length_x_m``, ``length_y_m`` [m] and ``channel_path_m`` (P, 3) [m] (the channel centre
    line, or None). Plain arrays: it pickles, so a worker process can return it."""

    xy_m: np.ndarray
    temp_c: np.ndarray
    triangles: np.ndarray
    length_x_m: float
    length_y_m: float
    channel_path_m: np.ndarray | None

    @property
    def spread_k(self) -> float:
        """Hottest minus coldest top-face node [K]."""
        return float(self.temp_c.max() - self.temp_c.min())


def plate_top_face(
    mesh: Any, disc: Any, geometry: Any, temp_c: Any, where: str = "plate picture"
) -> PlateFace:
    """The plate's top face (``z = plate_thickness_m``) of a module temperature field [°C]."""
    from matplotlib.tri import Triangulation

    g = geometry
    t = check_field(mesh, disc, temp_c, where)
    names = list(mesh.part_names)
    if "plate" not in names:
        raise InputError(f"{where}: the mesh has no part 'plate'; parts are {names}.")
    tol = 1e-6 * g.plate_thickness_m + 1e-9
    top = np.flatnonzero(
        (disc.node_part == names.index("plate")) & (np.abs(disc.points_m[:, 2] - g.plate_thickness_m) < tol)
    )
    if top.size < 3:
        raise InputError(
            f"{where}: {top.size} plate nodes at z = plate_thickness_m = {g.plate_thickness_m} m; "
            "expected the plate's top face (is the geometry the mesh's?)."
        )
    xy = np.asarray(disc.points_m[top, :2], dtype=float)
    path = None if mesh.channel_path_m is None else np.asarray(mesh.channel_path_m, dtype=float)
    tri = Triangulation(xy[:, 0], xy[:, 1]).triangles
    return PlateFace(xy, t[top], np.asarray(tri), float(g.length_x_m), float(g.length_y_m), path)


def _face_image(face: PlateFace, width_px: int = 640) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The face rasterised [°C] on a pixel grid over the plate, and its extent [mm]."""
    lx, ly = face.length_x_m * 1e3, face.length_y_m * 1e3
    extent = (0.0, lx, 0.0, ly)
    xy = face.xy_m * 1e3
    shape = (max(8, round(width_px * ly / lx)), width_px)
    return raster_triangles(xy[face.triangles], face.temp_c[face.triangles], extent, shape), extent


def plot_plate(mesh: Any, disc: Any, geometry: Any, temp_c: Any, time_s: float, path: str | Path) -> Path:
    """Temperature of the cooling plate's top face (thesis fig 4.30) with the channel path.

    The hottest and coldest top-face nodes are marked and labelled. Returns ``path``.
    """
    from matplotlib import patheffects
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure
    from matplotlib.tri import Triangulation

    g = geometry
    face = plate_top_face(mesh, disc, geometry, temp_c)
    xy, tt = face.xy_m * 1e3, face.temp_c
    lx, ly = g.length_x_m * 1e3, g.length_y_m * 1e3
    tri = Triangulation(xy[:, 0], xy[:, 1], face.triangles)
    t_lo, t_hi = float(tt.min()), max(float(tt.max()), float(tt.min()) + 1e-6)
    norm = Normalize(t_lo, t_hi)
    img, extent = _face_image(face)
    fig = Figure(figsize=(9.5, 1.6 + 7.0 * ly / lx), layout="constrained")
    ax = fig.add_subplot()
    pc = ax.imshow(img, origin="lower", extent=extent, cmap=FIELD_CMAP, norm=norm, interpolation="nearest")
    cs = ax.tricontour(
        tri, tt, levels=np.linspace(t_lo, t_hi, 10)[1:-1], colors="k", linewidths=0.4, alpha=0.5
    )
    ax.clabel(cs, fontsize=6, fmt="%.2f")
    fig.colorbar(pc, ax=ax, label="temperature [°C]", shrink=0.9)
    glow = [patheffects.withStroke(linewidth=2.6, foreground="black")]
    if mesh.channel_path_m is not None:
        path_mm = np.asarray(mesh.channel_path_m) * 1e3
        ax.plot(
            path_mm[:, 0],
            path_mm[:, 1],
            color="white",
            ls="--",
            lw=1.2,
            path_effects=glow,
            label=f"coolant channel centreline (z = {path_mm[0, 2]:g} mm)",
        )
        inlet, outlet = (
            (float(path_mm[0, 0]), float(path_mm[0, 1])),
            (float(path_mm[-1, 0]), float(path_mm[-1, 1])),
        )
        ax.annotate(
            "inlet →", inlet, xytext=(-3, 0), textcoords="offset points", ha="right", va="center", fontsize=8
        )
        right = outlet[0] > lx / 2
        ax.annotate(
            "→ outlet" if right else "outlet ←",
            outlet,
            xytext=(3 if right else -3, 0),
            textcoords="offset points",
            ha="left" if right else "right",
            va="center",
            fontsize=8,
        )
    for i, style, what in ((int(np.argmax(tt)), "r^", "hottest"), (int(np.argmin(tt)), "bv", "coldest")):
        ax.plot(
            xy[i, 0],
            xy[i, 1],
            style,
            ms=9,
            mec="black",
            clip_on=False,
            zorder=5,
            label=f"{what} point: {tt[i]:.2f} °C",
        )
        inside_x = -34 if xy[i, 0] > 0.8 * lx else 6
        inside_y = -14 if xy[i, 1] > 0.8 * ly else 6
        ax.annotate(
            f"{tt[i]:.2f} °C",
            xy[i],
            xytext=(inside_x, inside_y),
            textcoords="offset points",
            fontsize=8,
            zorder=6,
            bbox={"boxstyle": "round,pad=0.2", "fc": "white", "alpha": 0.85, "lw": 0.5},
        )
    fig.legend(loc="outside lower center", ncol=3, fontsize=8, frameon=False)
    ax.set_xlim(-0.1 * lx, 1.1 * lx)
    ax.set_ylim(-0.04 * ly, 1.04 * ly)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(
        f"Cooling plate, top face (z = {g.plate_thickness_m * 1e3:g} mm) at t = {time_s:g} s", fontsize=10
    )
    return _save(fig, path)


def plot_cells_section(
    mesh: Any, disc: Any, geometry: Any, temp_c: Any, time_s: float, path: str | Path
) -> Path:
    """Vertical x-z sections through the centre line of each row of cells (thesis fig 4.32).

    One panel per row with the exact cut of the field (cells, holder, plate with the channel,
    connector, cover, BMS, housing; white where there is no solid), part boundaries and
    isotherms drawn, a shared colour scale and the hottest cell point of the row
    (:func:`section_hot_points`) marked. Returns ``path``.
    """
    from matplotlib.collections import LineCollection
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    g = geometry
    check_field(mesh, disc, temp_c, "section picture")
    ys = row_y_m(g)
    sections = [section_y(mesh, disc, temp_c, y) for y in ys]
    hot = {h["row"]: h for h in section_hot_points(mesh, disc, g, temp_c)}
    vals = np.concatenate([s.temp_c for s in sections if s.temp_c.size] or [np.zeros(1)])
    t_lo, t_hi = float(vals.min()), max(float(vals.max()), float(vals.min()) + 1e-6)
    norm = Normalize(t_lo, t_hi)
    ncol = 1 if g.rows == 1 else 2
    nrow = math.ceil(g.rows / ncol)
    zmax = max((float(s.z_m.max()) for s in sections if s.z_m.size), default=g.plate_thickness_m)
    aspect = zmax / g.length_x_m
    extent = (0.0, g.length_x_m * 1e3, 0.0, zmax * 1e3)
    shape = (max(8, round(640 * aspect)), 640)
    levels = np.linspace(t_lo, t_hi, 12)[1:-1]
    xs = np.linspace(extent[0], extent[1], shape[1] + 1)
    zs = np.linspace(extent[2], extent[3], shape[0] + 1)
    xc, zc = 0.5 * (xs[1:] + xs[:-1]), 0.5 * (zs[1:] + zs[:-1])
    fig = Figure(figsize=(6.0 * ncol + 1.2, (6.0 * aspect + 1.0) * nrow + 0.9), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrow, ncol, squeeze=False).ravel())
    pc = None
    for r, (ax, sec) in enumerate(zip(axes, sections, strict=False)):
        if sec.triangles.size:
            corners = np.stack([sec.x_m, sec.z_m], axis=1)[sec.triangles] * 1e3
            img = raster_triangles(corners, sec.temp_c[sec.triangles], extent, shape)
            pc = ax.imshow(
                img,
                origin="lower",
                extent=extent,
                cmap=FIELD_CMAP,
                norm=norm,
                interpolation="nearest",
                aspect="equal",
            )
            cs = ax.contour(xc, zc, img, levels=levels, colors="black", linewidths=0.4, alpha=0.45)
            ax.clabel(cs, levels[::2], fontsize=6, fmt="%.1f", inline_spacing=1)
            ax.add_collection(
                LineCollection(list(sec.outline * 1e3), colors="0.15", linewidths=0.5, alpha=0.8)
            )
        h = hot.get(r + 1)
        if h is not None:
            hx, hz = h["x_m"] * 1e3, h["z_m"] * 1e3
            ax.plot(hx, hz, "*", ms=13, mfc="white", mec="black", mew=1.0, zorder=5)
            ax.annotate(
                f"{h['temp_c']:.2f} °C\nz = {hz:.0f} mm",
                (hx, hz),
                xytext=(-8 if hx > 0.75 * extent[1] else 8, -6),
                textcoords="offset points",
                ha="right" if hx > 0.75 * extent[1] else "left",
                va="top",
                fontsize=7,
                zorder=6,
                bbox={"boxstyle": "round,pad=0.2", "fc": "white", "alpha": 0.85, "lw": 0.5},
            )
        ax.set_xlim(0, extent[1])
        ax.set_ylim(0, extent[3])
        ax.set_aspect("equal")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("z [mm]")
        ax.set_title(f"row {r + 1}: section y = {sec.y_m * 1e3:.1f} mm", fontsize=10)
    for ax in axes[len(sections) :]:
        ax.set_visible(False)
    if pc is not None:
        fig.colorbar(pc, ax=list(axes[: len(sections)]), label="temperature [°C]", shrink=0.85)
    star = Line2D([], [], ls="", marker="*", ms=12, mfc="white", mec="black")
    edge = Line2D([], [], color="0.15", lw=0.5)
    iso = Line2D([], [], color="black", lw=0.4, alpha=0.45)
    fig.legend(
        [star, edge, iso],
        [
            "hottest point in the cells of the row",
            "part boundary (white: no solid, e.g. coolant channel)",
            f"isotherms every {levels[1] - levels[0] if levels.size > 1 else 0:.2f} K",
        ],
        loc="outside lower center",
        ncol=3,
        fontsize=8,
        frameon=False,
    )
    fig.suptitle(f"Temperature in vertical sections through the cell rows at t = {time_s:g} s", fontsize=11)
    return _save(fig, path)


def plot_fields(
    mesh: Any, disc: Any, geometry: Any, temp_c: Any, time_s: float, out_dir: str | Path, prefix: str = ""
) -> list[Path]:
    """Write ``{prefix}cells_temperature.png``, ``{prefix}plate_temperature.png`` and
    ``{prefix}cells_section.png`` into ``out_dir`` (created if missing); returns the paths."""
    out = Path(out_dir)
    check_field(mesh, disc, temp_c, "field pictures")
    return [
        plot_cells_top(mesh, disc, geometry, temp_c, time_s, out / f"{prefix}cells_temperature.png"),
        plot_plate(mesh, disc, geometry, temp_c, time_s, out / f"{prefix}plate_temperature.png"),
        plot_cells_section(mesh, disc, geometry, temp_c, time_s, out / f"{prefix}cells_section.png"),
    ]


def plot_plate_comparison(
    faces: Sequence[PlateFace], titles: Sequence[str], path: str | Path, suptitle: str = ""
) -> Path:
    """Top faces of several cooling plates, one panel each (stacked), on one colour scale [°C],
    with their channel centre lines and the hottest and coldest points; for comparing plate
    layouts side by side (``examples/plate_comparison``). Returns ``path``."""
    from matplotlib import patheffects
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    if not faces or len(faces) != len(titles):
        raise InputError(
            f"plate comparison: {len(faces)} plate faces and {len(titles)} titles; expected one title per "
            "face and at least one face."
        )
    t_lo = min(float(f.temp_c.min()) for f in faces)
    t_hi = max(max(float(f.temp_c.max()) for f in faces), t_lo + 1e-6)
    norm = Normalize(t_lo, t_hi)
    lx = max(f.length_x_m for f in faces) * 1e3
    ly = max(f.length_y_m for f in faces) * 1e3
    fig = Figure(figsize=(8.0, len(faces) * (0.9 + 6.0 * ly / lx) + 0.6), layout="constrained")
    axes = fig.subplots(len(faces), 1, squeeze=False)[:, 0]
    glow = [patheffects.withStroke(linewidth=2.2, foreground="black")]
    pc: Any = None
    for ax, face, title in zip(axes, faces, titles, strict=True):
        img, extent = _face_image(face)
        pc = ax.imshow(
            img, origin="lower", extent=extent, cmap=FIELD_CMAP, norm=norm, interpolation="nearest"
        )
        if face.channel_path_m is not None:
            cp = face.channel_path_m * 1e3
            ax.plot(cp[:, 0], cp[:, 1], color="white", ls="--", lw=1.0, path_effects=glow)
            ax.annotate("in", (cp[0, 0], cp[0, 1]), xytext=(-3, 0), textcoords="offset points", ha="right",
                        va="center", fontsize=7)  # fmt: skip
            ax.annotate("out", (cp[-1, 0], cp[-1, 1]), xytext=(3 if cp[-1, 0] > lx / 2 else -3, 0),
                        textcoords="offset points", ha="left" if cp[-1, 0] > lx / 2 else "right",
                        va="center", fontsize=7)  # fmt: skip
        xy = face.xy_m * 1e3
        for i, style in ((int(np.argmax(face.temp_c)), "r^"), (int(np.argmin(face.temp_c)), "bv")):
            ax.plot(xy[i, 0], xy[i, 1], style, ms=7, mec="black", clip_on=False, zorder=5)
        ax.set_xlim(-0.08 * lx, 1.08 * lx)
        ax.set_ylim(-0.04 * ly, 1.04 * ly)
        ax.set_aspect("equal")
        ax.set_ylabel("y [mm]")
        ax.set_title(
            f"{title}: {face.temp_c.min():.2f} (▼) .. {face.temp_c.max():.2f} °C (▲), spread "
            f"{face.spread_k:.2f} K",
            fontsize=9,
        )
    axes[-1].set_xlabel("x [mm]")
    fig.colorbar(pc, ax=list(axes), label="plate top-face temperature [°C]", shrink=0.9)
    if suptitle:
        fig.suptitle(suptitle, fontsize=10)
    return _save(fig, path)


def coolant_midplane_c(
    res: Any, spacing_m: float = 5e-4
) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """Coolant temperature [°C] of a heat-transfer run (:class:`hevsim.thermal.cht.ChtResult`)
    in the channel's mid-height plane, sampled on a pixel grid of ``spacing_m`` [m] (NaN
    outside the channel), and its extent ``(x0, x1, y0, y1)`` [mm]. The P2 field is evaluated
    exactly at the pixel centres."""
    from hevsim.units import KELVIN_OFFSET

    model = res.model
    boxes = np.asarray(model.channel.boxes, dtype=float)
    x0, x1 = float(boxes[:, 0].min()), float(boxes[:, 1].max())
    y0, y1 = float(boxes[:, 2].min()), float(boxes[:, 3].max())
    z = 0.5 * float(boxes[0, 4] + boxes[0, 5])
    nx, ny = max(2, round((x1 - x0) / spacing_m)), max(2, round((y1 - y0) / spacing_m))
    xc = x0 + (np.arange(nx) + 0.5) * (x1 - x0) / nx
    yc = y0 + (np.arange(ny) + 0.5) * (y1 - y0) / ny
    gx, gy = np.meshgrid(xc, yc)
    inside = np.zeros(gx.shape, dtype=bool)
    for bx0, bx1, by0, by1, *_ in boxes:
        inside |= (gx > bx0) & (gx < bx1) & (gy > by0) & (gy < by1)
    img = np.full(gx.shape, np.nan)
    pts = np.vstack([gx[inside], gy[inside], np.full(int(inside.sum()), z)])
    img[inside] = model.basis.probes(pts) @ np.asarray(res.temp_k) - KELVIN_OFFSET
    return img, (x0 * 1e3, x1 * 1e3, y0 * 1e3, y1 * 1e3)


def bulk_temperature_1d_k(res: Any) -> np.ndarray:
    """Bulk coolant temperature [K] at the segment ends (inlet first) of the 1-D channel model
    for the wall temperatures of a heat-transfer run: each segment relaxes the bulk towards its
    wall temperature by ``exp(-h A / (m_dot c_p))`` with the 1-D model's film ``h``
    (:meth:`hevsim.thermal.coolant.ChannelModel.fluid_temperature_k`) and the run's wall area."""
    m, seg = res.metrics, res.segments
    ntu = seg["film_1d_w_m2k"] * seg["wall_area_m2"] / res.model.capacity_rate_w_k
    out = [float(m["inlet_temp_k"])]
    for decay in np.exp(-ntu):
        out.append(m["wall_temp_k"] + (out[-1] - m["wall_temp_k"]) * decay)
    return np.array(out)


def plot_coolant(res: Any, path: str | Path) -> Path:
    """Pictures of a coolant heat-transfer run (``hevsim flow --thermal``,
    :class:`hevsim.thermal.cht.ChtResult`), the coolant side of the thesis's figs 4.30-4.31:
    top, the coolant temperature in the channel's mid-height plane (top view); bottom, the bulk
    (mixing-cup) temperature along the channel from the 3-D field and from the 1-D channel
    model, with the wall and the outlet temperatures. Returns ``path``."""
    from matplotlib.figure import Figure

    from hevsim.units import KELVIN_OFFSET as c0

    img, extent = coolant_midplane_c(res)
    m, seg = res.metrics, res.segments
    lx, ly = extent[1] - extent[0], extent[3] - extent[2]
    fig = Figure(figsize=(8.0, 3.2 + 6.0 * ly / lx), layout="constrained")
    top, bottom = fig.subplots(2, 1, height_ratios=[6.0 * ly / lx + 0.6, 2.8])
    pc = top.imshow(img, origin="lower", extent=extent, cmap=FIELD_CMAP, interpolation="nearest")
    axis = np.asarray(res.model.path_m) * 1e3
    top.plot(axis[:, 0], axis[:, 1], color="white", ls=":", lw=0.8)
    top.annotate("inlet", (axis[0, 0], axis[0, 1]), xytext=(4, 4), textcoords="offset points", ha="left",
                 va="bottom", fontsize=7, bbox={"boxstyle": "round,pad=0.15", "fc": "white", "alpha": 0.8,
                 "lw": 0})  # fmt: skip
    top.set_aspect("equal")
    top.set_xlabel("x [mm]")
    top.set_ylabel("y [mm]")
    top.set_title(
        f"Coolant temperature at mid-height (z = {0.5 * sum(res.model.channel.boxes[0][4:6]) * 1e3:g} mm), "
        f"wall {m['wall_temp_k'] - c0:g} °C, inlet {m['inlet_temp_k'] - c0:g} °C",
        fontsize=9,
    )
    fig.colorbar(pc, ax=top, label="temperature [°C]", shrink=0.9)
    length_mm = float(np.sum(np.linalg.norm(np.diff(axis, axis=0), axis=1)))
    s_mm = np.linspace(0.0, length_mm, seg["heat_w"].size + 1)
    bulk_3d = np.concatenate(([m["inlet_temp_k"]], seg["bulk_temp_k"]))
    bottom.plot(s_mm, bulk_3d - c0, "o-", ms=3, label=f"3-D (outlet {m['outlet_temp_k'] - c0:.2f} °C)")
    one_d = f"1-D channel, Nu {m['nusselt_1d']:.2f} (outlet {m['outlet_temp_1d_k'] - c0:.2f} °C)"
    bottom.plot(s_mm, bulk_temperature_1d_k(res) - c0, "--", label=one_d)
    bottom.axhline(m["wall_temp_k"] - c0, color="k", lw=0.8, ls=":", label="wall")
    bottom.set_xlabel("distance along the channel [mm]")
    bottom.set_ylabel("bulk temperature [°C]")
    bottom.legend(fontsize=8)
    bottom.set_title("Coolant bulk temperature along the channel", fontsize=9)
    return _save(fig, path)


def add_coolant_pictures(res: Any, out_dir: str | Path) -> list[Path]:
    """Add ``coolant_temperature.png`` (:func:`plot_coolant`) to the results folder ``out_dir``
    of a coolant heat-transfer run (``hevsim flow --thermal``, written by
    :func:`hevsim.thermal.flow.run_flow`). The folder is rewritten through
    :func:`hevsim.io.atomic_directory` with its files and the picture, so it is never seen
    with a partial set and stays a hevsim results folder. Returns the pictures' paths."""
    import shutil

    from hevsim.io import MARKER, atomic_directory

    out = Path(out_dir)
    with atomic_directory(out) as tmp:
        for f in out.iterdir():
            if f.name == MARKER:
                continue
            if f.is_dir():
                shutil.copytree(f, tmp / f.name)
            else:
                shutil.copy2(f, tmp / f.name)
        made = [plot_coolant(res, tmp / "coolant_temperature.png")]
    return [out / m.name for m in made]


__all__ = [
    "FIELD_CMAP",
    "PlateFace",
    "Section",
    "add_coolant_pictures",
    "bulk_temperature_1d_k",
    "cell_temperatures_c",
    "check_field",
    "coolant_midplane_c",
    "plate_top_face",
    "plot_cells_section",
    "plot_cells_top",
    "plot_coolant",
    "plot_fields",
    "plot_plate",
    "plot_plate_comparison",
    "raster_triangles",
    "row_y_m",
    "section_hot_points",
    "section_y",
]

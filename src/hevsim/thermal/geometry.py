"""Parametric battery module (cells, holder, cooling plate with channel, connectors, cover, BMS) in gmsh.

Layout (z up): an aluminium cooling plate with a rectangular serpentine channel at mid
thickness, a plastic cell holder on the plate with ``rows x columns`` cylindrical cells
standing in it, copper connecting plates on top of each row of cells, a plastic cover on the
connectors and a silicon BMS board on the cover. All volumes are fragmented into one conformal
mesh; the solver then splits it at part interfaces for gap conductance. gmsh runs with one
thread so the same inputs give the same mesh.
"""

from __future__ import annotations

import ctypes
import itertools
import math
import signal
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from hevsim.errors import ConfigError, InputError
from hevsim.thermal.mesh import CELL_SURFACE, CHANNEL_WALL, EXTERNAL, ThermalMesh, tet_volumes_m3

PART_ORDER = ("plate", "holder", "cells", "connector", "cover", "bms", "housing")


@dataclass(frozen=True)
class ModuleGeometry:
    """Module dimensions [m]; defaults give a 2 x 6 module of 18650-size cells (thesis fig 4.6)."""

    rows: int = 2
    columns: int = 6
    cell_diameter_m: float = 0.018
    cell_height_m: float = 0.065
    cell_pitch_m: float = 0.020
    margin_m: float = 0.004
    plate_thickness_m: float = 0.008
    channel_width_m: float = 0.008
    channel_height_m: float = 0.004
    channel_passes: int = 3
    holder_height_m: float = 0.012
    connector_thickness_m: float = 0.0015
    connector_width_m: float = 0.010
    cover_thickness_m: float = 0.003
    bms_thickness_m: float = 0.002
    housing_thickness_m: float = 0.002
    mesh_size_m: float = 0.005
    #: elements per 2 pi along curved surfaces (gmsh Mesh.MeshSizeFromCurvature): the cells'
    #: facet count, independent of ``mesh_size_m``; 12 holds ~97 % of a cylinder's volume
    curvature_elements: int = 12

    def check(self, where: str = "geometry") -> ModuleGeometry:
        for key, value in self.__dict__.items():
            if isinstance(value, int) and value < 1:
                raise ConfigError(f"{where}: key '{key}' = {value}; expected an integer >= 1.")
            if isinstance(value, float) and not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f"{where}: key '{key}' = {value!r}; expected a finite positive length [m].")
        if self.curvature_elements < 6:
            raise ConfigError(
                f"{where}: key 'curvature_elements' = {self.curvature_elements}; expected at least 6 "
                "elements per 2 pi (a cylinder meshed coarser is not round)."
            )
        if self.cell_diameter_m >= self.cell_pitch_m:
            raise ConfigError(
                f"{where}: cell_diameter_m {self.cell_diameter_m} must be below "
                f"cell_pitch_m {self.cell_pitch_m}."
            )
        if self.channel_height_m >= 0.8 * self.plate_thickness_m:
            raise ConfigError(
                f"{where}: channel_height_m {self.channel_height_m} leaves no plate wall; "
                "expected < 0.8 * plate_thickness_m."
            )
        if self.housing_thickness_m >= self.margin_m:
            raise ConfigError(
                f"{where}: housing_thickness_m {self.housing_thickness_m} must be below margin_m "
                f"{self.margin_m} (the housing walls stand in the margin around the cells)."
            )
        ly = self.rows * self.cell_pitch_m + 2 * self.margin_m
        if self.channel_passes * self.channel_width_m * 1.5 > ly:
            raise ConfigError(
                f"{where}: {self.channel_passes} channel passes of width {self.channel_width_m} m "
                f"do not fit in {ly:.4f} m."
            )
        return self

    @property
    def length_x_m(self) -> float:
        return self.columns * self.cell_pitch_m + 2 * self.margin_m

    @property
    def length_y_m(self) -> float:
        return self.rows * self.cell_pitch_m + 2 * self.margin_m

    def cell_centre_xy_m(self, row: int, column: int) -> tuple[float, float]:
        return (
            self.margin_m + (column + 0.5) * self.cell_pitch_m,
            self.margin_m + (row + 0.5) * self.cell_pitch_m,
        )

    def channel_path_m(self) -> np.ndarray:
        """Channel centreline from the inlet (x = 0) to the outlet, (P, 3) [m]."""
        lx, ly, w = self.length_x_m, self.length_y_m, self.channel_width_m
        z = self.plate_thickness_m / 2
        ys = np.linspace(
            ly / (self.channel_passes + 1),
            ly * self.channel_passes / (self.channel_passes + 1),
            self.channel_passes,
        )
        x_turn = (1.5 * w, lx - 1.5 * w)
        pts = [(0.0, ys[0], z)]
        for i, y in enumerate(ys):
            x_end = x_turn[1] if i % 2 == 0 else x_turn[0]
            if i == len(ys) - 1:
                x_end = lx if i % 2 == 0 else 0.0
            pts.append((pts[-1][0], y, z))
            pts.append((x_end, y, z))
        out = np.array(pts)
        keep = np.concatenate(([True], np.linalg.norm(np.diff(out, axis=0), axis=1) > 1e-12))
        return out[keep]

    def channel_boxes_m(self) -> list[tuple[float, float, float, float, float, float]]:
        """The channel as boxes along :meth:`channel_path_m`, one per straight leg, each
        ``(x0, x1, y0, y1, z0, z1)`` [m]: what the plate loses and the coolant fills."""
        w, hc, lx = self.channel_width_m, self.channel_height_m, self.length_x_m
        z0 = self.plate_thickness_m / 2 - hc / 2
        path = self.channel_path_m()
        boxes = []
        for a, b in itertools.pairwise(path):
            x0, x1 = min(a[0], b[0]) - (0 if a[0] == b[0] == 0 else w / 2), max(a[0], b[0]) + w / 2
            y0, y1 = min(a[1], b[1]) - w / 2, max(a[1], b[1]) + w / 2
            boxes.append((float(max(x0, 0.0)), float(min(x1, lx)), float(y0), float(y1), z0, z0 + hc))
        return boxes


def initialize_gmsh(gmsh: Any) -> None:
    """``gmsh.initialize`` without its process-wide side effects.

    gmsh's library resets SIGPIPE to the default action when it starts, so a later write to a
    closed pipe (a co-simulation worker's pipe, ``hevsim ... | head``) kills the whole process
    without a message instead of raising ``BrokenPipeError``; its Python API also replaces the
    SIGINT handler and, in gmsh 4.x, never restores it (Ctrl-C would no longer raise
    ``KeyboardInterrupt``, which long runs catch to checkpoint). This starts gmsh with
    ``interruptible=False`` and puts SIGPIPE back to Python's own setting (ignored)."""
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    if not hasattr(signal, "SIGPIPE"):
        return
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)
    else:  # signal.signal works in the main thread only; the C library's call anywhere
        libc = ctypes.CDLL(None)
        libc.signal.restype = ctypes.c_void_p
        libc.signal(int(signal.SIGPIPE), ctypes.c_void_p(1))  # 1 = SIG_IGN


def build_module_mesh(geom: ModuleGeometry | None = None, *, source: str = "module geometry") -> ThermalMesh:
    """Build and mesh the module with gmsh (one thread); returns a :class:`ThermalMesh`."""
    import gmsh

    g = (geom or ModuleGeometry()).check(source)
    started_here = not gmsh.isInitialized()
    if started_here:
        initialize_gmsh(gmsh)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.Verbosity", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("hevsim_module")
        return _build(gmsh, g, source)
    finally:
        gmsh.clear()
        if started_here:
            gmsh.finalize()


def _build(gmsh: object, g: ModuleGeometry, source: str) -> ThermalMesh:
    import gmsh as gm

    occ = gm.model.occ
    lx, ly, tp = g.length_x_m, g.length_y_m, g.plate_thickness_m
    # cooling plate minus channel
    plate = occ.addBox(0, 0, 0, lx, ly, tp)
    path = g.channel_path_m()
    hc = g.channel_height_m
    z0 = tp / 2 - hc / 2
    boxes = [
        (3, occ.addBox(x0, y0, z0, x1 - x0, y1 - y0, hc)) for x0, x1, y0, y1, _, _ in g.channel_boxes_m()
    ]
    plate_cut, _ = occ.cut([(3, plate)], boxes)
    # cells and holder
    cells = []
    for r in range(g.rows):
        for c in range(g.columns):
            x, y = g.cell_centre_xy_m(r, c)
            cells.append((3, occ.addCylinder(x, y, tp, 0, 0, g.cell_height_m, g.cell_diameter_m / 2)))
    holder_box = occ.addBox(0, 0, tp, lx, ly, g.holder_height_m)
    holder, _ = occ.cut([(3, holder_box)], cells, removeObject=True, removeTool=False)
    top = tp + g.cell_height_m
    connectors = []
    for r in range(g.rows):
        _, y = g.cell_centre_xy_m(r, 0)
        connectors.append(
            (
                3,
                occ.addBox(
                    g.margin_m,
                    y - g.connector_width_m / 2,
                    top,
                    lx - 2 * g.margin_m,
                    g.connector_width_m,
                    g.connector_thickness_m,
                ),
            )
        )
    ztop = top + g.connector_thickness_m
    cover = [(3, occ.addBox(0, 0, ztop, lx, ly, g.cover_thickness_m))]
    zbms = ztop + g.cover_thickness_m
    bms = [(3, occ.addBox(lx / 4, ly / 4, zbms, lx / 2, ly / 2, g.bms_thickness_m))]
    # housing: side walls on the holder rim, up to the cover (a frame of thickness th)
    th, zh = g.housing_thickness_m, tp + g.holder_height_m
    outer_box = occ.addBox(0, 0, zh, lx, ly, ztop - zh)
    inner_box = occ.addBox(th, th, zh, lx - 2 * th, ly - 2 * th, ztop - zh)
    housing, _ = occ.cut([(3, outer_box)], [(3, inner_box)])
    groups = [plate_cut, holder, *[[c] for c in cells], connectors, cover, bms, housing]
    flat = [dt for grp in groups for dt in grp]
    _, out_map = occ.fragment(flat, [])
    occ.synchronize()
    # volumes of each input after fragmentation
    children = [sorted({t for _, t in out_map[i]}) for i in range(len(flat))]
    k = 0
    part_vols: dict[str, list[int]] = {p: [] for p in PART_ORDER}
    cell_vols: list[list[int]] = []
    for gi, grp in enumerate(groups):
        name = (
            "plate"
            if gi == 0
            else "holder"
            if gi == 1
            else "cells"
            if gi < 2 + len(cells)
            else ("connector", "cover", "bms", "housing")[gi - 2 - len(cells)]
        )
        for _ in grp:
            part_vols[name].extend(children[k])
            if name == "cells":
                cell_vols.append(children[k])
            k += 1
    # channel wall: boundary faces of the plate lying within the channel's z range
    tol = 1e-5 * g.plate_thickness_m + 1e-6
    bnd = gm.model.getBoundary([(3, t) for t in part_vols["plate"]], combined=False, oriented=False)
    outer = {
        t
        for _, t in gm.model.getBoundary(
            [(3, t) for v in part_vols.values() for t in v], combined=True, oriented=False
        )
    }
    wall = []
    for _, s in bnd:
        bb = gm.model.getBoundingBox(2, abs(s))
        if abs(s) in outer and bb[2] > z0 - tol and bb[5] < z0 + hc + tol:
            wall.append(abs(s))
    nominal = {name: float(sum(occ.getMass(3, v) for v in vols)) for name, vols in part_vols.items()}
    for name, vols in part_vols.items():
        gm.model.addPhysicalGroup(3, vols, name=name)
    cell_surf = sorted({abs(t) for _, t in gm.model.getBoundary([(3, t) for t in part_vols["cells"]],
                                                              combined=False, oriented=False)})  # fmt: skip
    external = sorted(outer - set(wall))
    surfaces = {CHANNEL_WALL: wall, CELL_SURFACE: cell_surf, EXTERNAL: external}
    for name, tags in surfaces.items():
        gm.model.addPhysicalGroup(2, tags, name=name)
    gm.option.setNumber("Mesh.MeshSizeMax", g.mesh_size_m)
    gm.option.setNumber("Mesh.MeshSizeMin", g.mesh_size_m / 8)
    gm.option.setNumber("Mesh.MeshSizeFromCurvature", g.curvature_elements)
    gm.option.setNumber("Mesh.Algorithm3D", 1)
    gm.option.setNumber("Mesh.RandomSeed", 1)
    gm.model.mesh.generate(3)

    tags, coords, _ = gm.model.mesh.getNodes()
    xyz = coords.reshape(-1, 3)
    lookup = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
    lookup[tags.astype(np.int64)] = np.arange(tags.size)

    def elements(dim: int, tag: int, etype: int, nn: int) -> np.ndarray:
        _, nodes = gm.model.mesh.getElementsByType(etype, tag)
        return lookup[np.asarray(nodes, dtype=np.int64)].reshape(-1, nn)

    tets, part, cell = [], [], []
    cell_of_vol = {v: i for i, vs in enumerate(cell_vols) for v in vs}
    for pi, name in enumerate(PART_ORDER):
        for v in part_vols[name]:
            t = elements(3, v, 4, 4)
            tets.append(t)
            part.append(np.full(len(t), pi))
            cell.append(np.full(len(t), cell_of_vol.get(v, -1)))
    t_all = np.vstack(tets)
    tris = {
        name: np.vstack([elements(2, s, 2, 3) for s in tags]) if tags else np.zeros((0, 3), dtype=np.int64)
        for name, tags in surfaces.items()
    }
    used, inv = np.unique(
        np.concatenate([t_all.ravel(), *(t.ravel() for t in tris.values())]), return_inverse=True
    )
    surf_groups: dict[str, np.ndarray] = {}
    start = t_all.size
    t_all = inv[:start].reshape(-1, 4)
    for name, t in tris.items():
        surf_groups[name] = inv[start : start + t.size].reshape(-1, 3)
        start += t.size
    pts = xyz[used]
    vol = tet_volumes_m3(pts, t_all)
    t_all[vol < 0] = t_all[vol < 0][:, [1, 0, 2, 3]]  # gmsh orientation convention -> right-handed
    if not wall:
        raise InputError(f"{source}: the cooling plate has no channel wall surface ('{CHANNEL_WALL}').")
    return ThermalMesh(
        pts,
        t_all,
        np.concatenate(part),
        PART_ORDER,
        np.concatenate(cell),
        surf_groups,
        path,
        source,
        nominal,
    ).validate()


def check_channel_connected(
    elements: np.ndarray, inlet_elements: np.ndarray, outlet_elements: np.ndarray, where: str
) -> None:
    """Refuse (:class:`~hevsim.errors.ConfigError`, exit 2) a coolant channel whose volume does
    not connect the inlet to the outlet.

    ``elements``: (4, E) vertex indices of the channel's tetrahedra; two are neighbours when
    they share a face (a shared edge or corner is no passage for the flow).
    ``inlet_elements``, ``outlet_elements``: indices of the elements next to the inlet and the
    outlet planes. A flood fill over the neighbours from the inlet elements must reach an
    outlet element; ``where`` names the file and keys (or the mesh) in the message, which also
    says how many separate pieces the channel has."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    t = np.asarray(elements)
    n_el = t.shape[1]
    if np.size(inlet_elements) == 0 or np.size(outlet_elements) == 0:
        raise ConfigError(
            f"{where}: the channel has no {'inlet' if np.size(inlet_elements) == 0 else 'outlet'} face."
        )
    nv = t.shape[0]
    faces = np.concatenate(
        [np.sort(np.delete(t, i, axis=0), axis=0) for i in range(nv)], axis=1
    )  # (nv-1, nv E)
    owner = np.tile(np.arange(n_el), nv)
    _, key = np.unique(faces.T, axis=0, return_inverse=True)
    key = key.ravel()
    order = np.argsort(key, kind="stable")
    k, o = key[order], owner[order]
    same = k[1:] == k[:-1]
    a, b = o[:-1][same], o[1:][same]
    graph = coo_matrix((np.ones(a.size), (a, b)), shape=(n_el, n_el))
    n_parts, label = connected_components(graph, directed=False)
    reached = np.unique(label[np.asarray(inlet_elements)])
    if not np.isin(label[np.asarray(outlet_elements)], reached).any():
        raise ConfigError(
            f"{where}: the coolant channel does not connect the inlet to the outlet (its volume falls into "
            f"{n_parts} separate pieces; the inlet's is not the outlet's); expected one continuous channel "
            "from the inlet to the outlet. Check the channel's geometry (passes, width and the plate's size)."
        )

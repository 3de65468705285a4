"""The tetrahedral mesh the heat solver works on, with parts, cells and named surfaces."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hevsim.errors import InputError

#: Name of the channel-wall surface towards the coolant (thesis: INTERFACE).
CHANNEL_WALL = "INTERFACE"
#: Name of the cell surfaces towards the electro-thermal model (thesis: INTERFACE2).
CELL_SURFACE = "INTERFACE2"
#: Name of the external surfaces (film convection to the ambient).
EXTERNAL = "EXTERNAL"
#: Relative volume below which a tetrahedron counts as degenerate.
DEGENERATE_RELATIVE_VOLUME = 1e-10

_FACES = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])


def tet_volumes_m3(points_m: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes [m^3] of tetrahedra ``tets`` (M, 4) on ``points_m`` (N, 3)."""
    p = points_m[tets]
    a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    return np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0


def triangle_areas_m2(points_m: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Areas [m^2] of triangles ``tris`` (K, 3)."""
    p = points_m[tris]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


@dataclass(frozen=True)
class Faces:
    """Unique triangular faces of a tet mesh and the (one or two) tetrahedra owning each."""

    nodes: np.ndarray  # (F, 3) sorted node indices
    owner: np.ndarray  # (F,) first owning tet
    other: np.ndarray  # (F,) second owning tet or -1 on the boundary


def mesh_faces(tets: np.ndarray) -> Faces:
    """Unique faces of ``tets`` with their owning tetrahedra."""
    m = tets.shape[0]
    f = np.sort(tets[:, _FACES].reshape(-1, 3), axis=1)
    tet_of = np.repeat(np.arange(m), 4)
    uniq, inv, counts = np.unique(f, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    if counts.max(initial=0) > 2:
        raise InputError(
            "mesh: a triangular face is shared by more than two tetrahedra; not a manifold mesh."
        )
    order = np.argsort(inv, kind="stable")
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    owner = tet_of[order[starts]]
    other = np.where(counts == 2, tet_of[order[np.minimum(starts + 1, len(order) - 1)]], -1)
    return Faces(uniq, owner, other)


@dataclass(frozen=True)
class ThermalMesh:
    """Linear-tetrahedron mesh of a module.

    ``points_m`` (N, 3) [m]; ``tets`` (M, 4) node indices; ``part_of_tet`` (M,) index into
    ``part_names``; ``cell_of_tet`` (M,) battery-cell number 0..n_cells-1 or -1; ``facet_groups``
    named boundary triangles (K, 3) such as the channel wall ``INTERFACE``; ``channel_path_m``
    (P, 3) the coolant channel centreline from inlet to outlet (or ``None``).
    """

    points_m: np.ndarray
    tets: np.ndarray
    part_of_tet: np.ndarray
    part_names: tuple[str, ...]
    cell_of_tet: np.ndarray
    facet_groups: dict[str, np.ndarray] = field(default_factory=dict)
    channel_path_m: np.ndarray | None = None
    source: str = "mesh"
    #: exact (CAD) volume of every part [m^3] where known (a faceted mesh holds less)
    nominal_volume_m3: dict[str, float] = field(default_factory=dict)

    @property
    def n_cells(self) -> int:
        """Number of battery cells."""
        return int(self.cell_of_tet.max(initial=-1)) + 1

    def validate(self) -> ThermalMesh:
        """Raise :class:`InputError` on bad indices, non-finite, inverted or degenerate elements."""
        src = self.source
        p, t = self.points_m, self.tets
        if p.ndim != 2 or p.shape[1] != 3 or t.ndim != 2 or t.shape[1] != 4 or t.shape[0] == 0:
            raise InputError(
                f"{src}: expected points (N, 3) and tetrahedra (M, 4); got {p.shape}, {t.shape}."
            )
        if not np.all(np.isfinite(p)):
            raise InputError(f"{src}: node coordinates contain NaN or infinity; expected finite values.")
        if t.min() < 0 or t.max() >= p.shape[0]:
            raise InputError(f"{src}: element node index out of range 0..{p.shape[0] - 1}.")
        if self.part_of_tet.shape != (t.shape[0],) or self.cell_of_tet.shape != (t.shape[0],):
            raise InputError(f"{src}: part_of_tet and cell_of_tet must have one entry per tetrahedron.")
        if self.part_of_tet.min() < 0 or self.part_of_tet.max() >= len(self.part_names):
            raise InputError(f"{src}: part index out of range; parts are {list(self.part_names)}.")
        vol = tet_volumes_m3(p, t)
        scale = float(np.mean(np.abs(vol))) if vol.size else 0.0
        degenerate = np.flatnonzero(np.abs(vol) <= DEGENERATE_RELATIVE_VOLUME * max(scale, 1e-300))
        if degenerate.size:
            raise InputError(
                f"{src}: {degenerate.size} degenerate (zero-volume) tetrahedra, first is element "
                f"{int(degenerate[0])} with nodes {t[degenerate[0]].tolist()}; expected positive volumes."
            )
        inverted = np.flatnonzero(vol < 0.0)
        if inverted.size:
            raise InputError(
                f"{src}: {inverted.size} inverted tetrahedra (negative volume), first is element "
                f"{int(inverted[0])} with nodes {t[inverted[0]].tolist()}; expected right-handed "
                "node order (positive volume)."
            )
        for name, tris in self.facet_groups.items():
            if tris.ndim != 2 or tris.shape[1] != 3 or (tris.size and tris.max() >= p.shape[0]):
                raise InputError(f"{src}: surface '{name}' is not a (K, 3) array of valid node indices.")
        return self


# --------------------------------------------------------------------------- estimates
#: Nodes per mesh-size cube of meshed volume [-]; with :data:`NODES_PER_CELL`, fitted to
#: ``examples/module_thermal.toml`` at mesh_size_m 5, 3.5 and 2.5 mm (8 863, 17 508 and
#: 36 468 nodes; the formula gives 10 350, 17 500 and 36 470).
NODES_PER_H3 = 1.34
#: Nodes the small features of one cell add whatever the mesh size (channel, holder,
#: connector and housing walls thinner than the mesh size) [-].
NODES_PER_CELL = 550.0
#: Memory of a run per mesh node (mesh, sparse matrices, factorisation, pictures) [B];
#: measured peak RSS 193, 298 and 629 MB at the three sizes above, and about 8 GB at 1 mm.
BYTES_PER_NODE = 16_000.0
#: Memory of a run before meshing (Python, numpy, scipy, gmsh) [B].
BYTES_BASE = 80e6
#: Meshing, assembly and factorisation time per node on the 2-core reference machine
#: under load (0.8-1.1 ms measured; 560 s at 1 mm) [s].
SECONDS_PER_NODE = 1.1e-3
#: Time-loop cost per node and step [s] (5.4 µs measured at 36 k nodes).
SECONDS_PER_NODE_STEP = 5.4e-6


@dataclass(frozen=True)
class MeshEstimate:
    """Size and cost of a module mesh, predicted before meshing."""

    nodes: int
    memory_bytes: float
    prepare_s: float
    seconds_per_step: float

    def describe(self, steps: int) -> str:
        """``"about 36 000 nodes, 660 MB, 40 s to mesh and assemble + 2 s for 300 steps"``."""
        return (
            f"about {self.nodes:,} nodes, {self.memory_bytes / 1e6:,.0f} MB, "
            f"{self.prepare_s:,.0f} s to mesh and assemble + {self.seconds_per_step * steps:,.0f} s "
            f"for {steps} steps"
        )


def meshed_volume_m3(geom: object) -> float:
    """Volume the module mesh fills [m³]: plate, holder, cover (full footprint), the cells
    above the holder, connectors, BMS board and housing walls (:class:`ModuleGeometry`)."""
    g: Any = geom
    lx, ly = g.length_x_m, g.length_y_m
    n_cells = g.rows * g.columns
    base = lx * ly * (g.plate_thickness_m + g.holder_height_m + g.cover_thickness_m)
    cells = n_cells * np.pi * (g.cell_diameter_m / 2) ** 2 * max(g.cell_height_m - g.holder_height_m, 0.0)
    connectors = g.rows * (lx - 2 * g.margin_m) * g.connector_width_m * g.connector_thickness_m
    wall_h = max(g.cell_height_m + g.connector_thickness_m - g.holder_height_m, 0.0)
    housing = 2 * (lx + ly) * g.housing_thickness_m * wall_h
    bms = lx * ly / 4 * g.bms_thickness_m
    return float(base + cells + connectors + housing + bms)


def estimate_mesh(geom: object) -> MeshEstimate:
    """Nodes, memory and time of meshing and solving ``geom`` (a :class:`ModuleGeometry`),
    from the calibration constants above (within about 20 % on the reference module)."""
    g: Any = geom
    h = float(g.mesh_size_m)
    nodes = int(NODES_PER_H3 * meshed_volume_m3(g) / h**3 + NODES_PER_CELL * g.rows * g.columns)
    return MeshEstimate(
        nodes=nodes,
        memory_bytes=BYTES_BASE + BYTES_PER_NODE * nodes,
        prepare_s=SECONDS_PER_NODE * nodes,
        seconds_per_step=SECONDS_PER_NODE_STEP * nodes,
    )

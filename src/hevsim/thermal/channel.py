"""The coolant channel shared by the flow solvers and the coolant heat transfer: the channel's
boxes and ports (:class:`Channel`), its tetrahedral mesh (:func:`channel_mesh`) and graded
hexahedral grid (:func:`channel_grid`), the ``[flow]`` section (:class:`FlowSection`), a flow
solution (:class:`FlowResult`) and the figures every solution reports
(:func:`hydraulic_metrics`).

The modules above it: :mod:`hevsim.thermal.rans` (k-omega SST with OpenFOAM),
:mod:`hevsim.thermal.cht` (heat transfer on a frozen flow) and :mod:`hevsim.thermal.flow` (the
laminar solver, the model choice and the config runner), which re-exports these names.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hevsim.thermal.geometry import ModuleGeometry

#: Litres per minute -> m^3/s.
L_MIN_TO_M3_S = 1e-3 / 60.0


#: Inlet profiles :class:`FlowSection` accepts.
INLET_PROFILES = ("developed", "uniform")
#: Channels :class:`FlowSection` accepts: the plate's serpentine or a straight duct.
CHANNEL_KINDS = ("plate", "duct")
#: Flow models :class:`FlowSection` accepts (``auto``: laminar up to RE_LAMINAR_MAX, else RANS).
FLOW_MODELS = ("auto", "laminar", "rans")
#: Coolant wall treatments on a turbulent flow (``flow.thermal_wall``): ``auto`` (the thermal
#: wall function when the FEM wall cells are thicker than twice the conduction sublayer, else
#: resolved), ``resolved`` (the interpolated eddy diffusivity down to the wall; refused on such
#: cells) or ``wall_function`` (:mod:`hevsim.thermal.wall_function`).
THERMAL_WALL_MODES = ("auto", "resolved", "wall_function")


@dataclass(frozen=True)
class FlowSection:
    """``[flow]``: operating point, channel, mesh and solver of the laminar flow solve.

    ``flow_l_min`` [L/min] (absent = take ``[coolant] flow_l_min``; zero is refused),
    ``outlet_pressure_pa`` [Pa] (static gauge pressure at the outlet),
    ``inlet_profile`` (``developed`` or ``uniform``),
    ``channel`` (``plate``: the geometry's serpentine; ``duct``: a straight duct of the
    channel's cross-section and length ``duct_length_m`` [m]), mesh resolution
    (``cells_across_width``, ``cells_across_height``, ``cell_length_m`` [m] along the
    channel), Newton ``tolerance`` (relative velocity update) and ``max_iterations``;
    ``wall_temp_c`` [°C]: the uniform wall temperature of the coolant heat-transfer run
    (``hevsim flow --thermal``, :func:`hevsim.thermal.cht.run_cht`); ``grad_div`` [-]:
    grad-div stabilisation ``gamma int div u div v`` with ``gamma = grad_div (mu + rho U D_h)``
    (0 = none), which improves the local mass conservation the coolant heat balance needs.
    ``streamline_diffusion`` [-]: streamline-upwind stabilisation of the momentum equation,
    ``int tau rho ((u . grad) u) . ((u . grad) v)`` with the SUPG ``tau = s h'/(2 |u|) (coth Pe_h -
    1/Pe_h)`` scaled by this factor ``s`` (0 = none; 1 = the standard tau;
    :data:`~hevsim.thermal.flow.STREAMLINE_ORDER` sets ``h'``), Newton-linearised with tau frozen; it lets the
    serpentine converge up to the laminar limit on coarse meshes (docs/flow.md). It adds
    numerical diffusion along the streamlines only (no pressure or viscous part of the
    residual): it vanishes for developed flow and is of order ``h`` where the flow develops.
    ``wall_cell_m`` [m]: first cell height at the channel walls of this (FEM) mesh, growing by
    ``growth`` [-] away from them up to the sizes above (0 = uniform cells, the default).

    ``model``: ``auto`` (default), ``laminar`` or ``rans`` (module docstring). RANS keys
    (:mod:`hevsim.thermal.rans`): ``turbulence_intensity`` [-] (0.05) and
    ``turbulence_length_m`` [m] (0 = 0.07 D_h) of the inflow, ``prandtl_turbulent`` [-]
    (0.85) for the coolant's eddy diffusivity nu_t / Pr_t, the OpenFOAM grid
    (``rans_cells_across_width``, ``rans_cells_across_height``, ``rans_cell_length_m`` [m],
    first cell height ``rans_wall_cell_m`` [m] at the walls, ``growth``), at most
    ``rans_iterations`` SIMPLE iterations down to initial residuals ``rans_tolerance`` [-], on
    ``rans_processes`` MPI processes. ``thermal_wall``: the coolant heat transfer's wall
    treatment on a turbulent flow, :data:`THERMAL_WALL_MODES` (default ``auto``).
    """

    flow_l_min: float = 0.0
    outlet_pressure_pa: float = 0.0
    inlet_profile: str = "developed"
    channel: str = "plate"
    duct_length_m: float = 0.05
    cells_across_width: int = 4
    cells_across_height: int = 2
    cell_length_m: float = 0.002
    picard_iterations: int = 3
    max_iterations: int = 30
    tolerance: float = 1e-9
    wall_temp_c: float = 25.0
    grad_div: float = 0.0
    streamline_diffusion: float = 0.0
    wall_cell_m: float = 0.0
    growth: float = 1.3
    model: str = "auto"
    turbulence_intensity: float = 0.05
    turbulence_length_m: float = 0.0
    prandtl_turbulent: float = 0.85
    rans_cells_across_width: int = 8
    rans_cells_across_height: int = 4
    rans_cell_length_m: float = 0.002
    rans_wall_cell_m: float = 3e-4
    rans_iterations: int = 500
    rans_tolerance: float = 1e-4
    rans_processes: int = 1
    thermal_wall: str = "auto"


# --------------------------------------------------------------------------- channel and mesh
@dataclass(frozen=True)
class Channel:
    """Axis-aligned boxes (x0, x1, y0, y1, z0, z1) [m] whose union is the channel volume, and
    the inlet/outlet planes x = const with the y range and flow direction (+1/-1 along x)."""

    boxes: tuple[tuple[float, float, float, float, float, float], ...]
    inlet: tuple[float, float, float, int]  # x, y0, y1, direction
    outlet: tuple[float, float, float, int]

    @property
    def width_m(self) -> float:
        return self.inlet[2] - self.inlet[1]

    @property
    def height_m(self) -> float:
        return self.boxes[0][5] - self.boxes[0][4]


def plate_channel(g: ModuleGeometry) -> Channel:
    """The serpentine channel of the plate: the boxes :func:`~hevsim.thermal.geometry.build_module_mesh`
    cuts out of the plate (:meth:`ModuleGeometry.channel_boxes_m`)."""
    path = g.channel_path_m()
    w = g.channel_width_m
    boxes = g.channel_boxes_m()
    first, last = path[0], path[-1]
    out_dir = 1 if last[0] > path[-2][0] else -1
    return Channel(
        tuple(boxes),
        (0.0, first[1] - w / 2, first[1] + w / 2, 1),
        (float(last[0]), last[1] - w / 2, last[1] + w / 2, out_dir),
    )


def duct_channel(length_m: float, width_m: float, height_m: float) -> Channel:
    """A straight duct x in [0, L], y in [0, width], z in [0, height] [m]."""
    return Channel(
        ((0.0, length_m, 0.0, width_m, 0.0, height_m),), (0.0, 0.0, width_m, 1), (length_m, 0.0, width_m, 1)
    )


def _axis_nodes(breaks: list[float], spacing: float) -> np.ndarray:
    pts = sorted(set(np.round(breaks, 12)))
    out = [pts[0]]
    for a, b in itertools.pairwise(pts):
        n = max(1, math.ceil((b - a) / spacing - 1e-9))
        out.extend(np.linspace(a, b, n + 1)[1:])
    return np.array(out)


def channel_mesh(
    ch: Channel,
    cells_across_width: int,
    cells_across_height: int,
    cell_length_m: float,
    wall_cell_m: float = 0.0,
    growth: float = 1.3,
) -> Any:
    """Structured tetrahedral mesh (scikit-fem ``MeshTet``) of the channel's box union;
    ``wall_cell_m`` > 0 [m]: cells graded geometrically (``growth`` [-]) from that height at the
    walls (:func:`channel_grid`)."""
    from skfem import MeshTet

    w, h = ch.width_m, ch.height_m
    if wall_cell_m > 0.0:
        xs, ys, zs = channel_grid(
            ch, cells_across_width, cells_across_height, cell_length_m, wall_cell_m, growth
        ).nodes
    else:
        xs = _axis_nodes([v for b in ch.boxes for v in b[:2]], cell_length_m)
        ys = _axis_nodes([v for b in ch.boxes for v in b[2:4]], min(w / cells_across_width, cell_length_m))
        zs = _axis_nodes([v for b in ch.boxes for v in b[4:]], h / cells_across_height)
    m = MeshTet.init_tensor(xs, ys, zs)
    c = m.p[:, m.t].mean(axis=1)
    inside = np.zeros(c.shape[1], dtype=bool)
    for x0, x1, y0, y1, z0, z1 in ch.boxes:
        inside |= (c[0] > x0) & (c[0] < x1) & (c[1] > y0) & (c[1] < y1) & (c[2] > z0) & (c[2] < z1)
    return m.restrict(np.nonzero(inside)[0])


def port_facets(mesh: Any, channel: Channel) -> tuple[np.ndarray, np.ndarray]:
    """Boundary facets of ``mesh`` on the channel's inlet and on its outlet plane."""
    tol = 1e-9 * max(max(b[1] for b in channel.boxes), channel.width_m, channel.height_m)
    mid = mesh.p[:, mesh.facets].mean(axis=1)
    bnd = mesh.boundary_facets()

    def plane(spec: tuple[float, float, float, int]) -> np.ndarray:
        x, y0, y1, _ = spec
        on = (np.abs(mid[0, bnd] - x) < tol) & (mid[1, bnd] > y0 - tol) & (mid[1, bnd] < y1 + tol)
        return bnd[on]

    return plane(channel.inlet), plane(channel.outlet)


def check_channel_mesh(mesh: Any, channel: Channel, where: str) -> None:
    """Refuse (ConfigError, exit 2) a channel mesh without an inlet or outlet face or whose
    volume does not connect them (:func:`hevsim.thermal.geometry.check_channel_connected`)."""
    from hevsim.thermal.geometry import check_channel_connected

    f_in, f_out = port_facets(mesh, channel)
    f2t = mesh.f2t
    check_channel_connected(mesh.t, f2t[0, f_in], f2t[0, f_out], where)


@dataclass
class FlowResult:
    """Flow solution and its figures (SI units; names carry the unit)."""

    metrics: dict[str, float]
    mesh: Any
    velocity: np.ndarray  # P2 velocity dofs
    pressure: np.ndarray  # P1 pressure dofs (= vertex values)
    basis_u: Any
    basis_p: Any
    history: list[float]
    metadata: dict[str, Any] = field(default_factory=dict)
    cht: Any = None  # hevsim.thermal.cht.ChtResult of a thermal run (run_flow(thermal=True))
    #: turbulent (eddy) diffusivity nu_t / Pr_t at the mesh vertices [m^2/s] (RANS only)
    eddy_diffusivity_m2_s: np.ndarray | None = None
    rans: Any = None  # hevsim.thermal.rans.RansResult of a RANS solve

    def vertex_velocity_mps(self) -> np.ndarray:
        """Velocity at the mesh vertices, (N, 3) [m/s]."""
        return np.asarray(self.velocity[self.basis_u.nodal_dofs].T)


def hydraulic_metrics(
    flow_m3_s: float, q_in: float, q_out: float, reynolds: float, u_mean: float, dh: float, p_in: float,
    p_out: float,
) -> dict[str, float]:  # fmt: skip
    """The figures every flow solution reports (laminar and RANS): configured, inlet and outlet
    flow [m^3/s] and the mass imbalance [-], Reynolds number [-], mean velocity [m/s],
    hydraulic diameter [m], inlet and outlet pressure [Pa], pressure drop [Pa] and pump power
    (pressure drop x flow) [W]."""
    dp = p_in - p_out
    return {
        "flow_m3_s": flow_m3_s,
        "flow_l_min": flow_m3_s / L_MIN_TO_M3_S,
        "inlet_flow_m3_s": q_in,
        "outlet_flow_m3_s": q_out,
        "mass_imbalance_rel": abs(q_in - q_out) / flow_m3_s,
        "reynolds": reynolds,
        "mean_velocity_mps": u_mean,
        "hydraulic_diameter_m": dh,
        "inlet_pressure_pa": p_in,
        "outlet_pressure_pa": p_out,
        "pressure_drop_pa": dp,
        "pump_power_w": dp * flow_m3_s,
    }


def config_channel(cfg: Any) -> Channel:
    """The channel a :class:`~hevsim.thermal.flow.FlowConfig` names (``plate`` or ``duct``)."""
    g = cfg.geometry
    if cfg.flow.channel == "duct":
        return duct_channel(cfg.flow.duct_length_m, g.channel_width_m, g.channel_height_m)
    return plate_channel(g)


# --------------------------------------------------------------------------- graded grid
def graded_axis(
    breaks: Sequence[float], walls: Sequence[bool], max_cell_m: float, wall_cell_m: float, growth: float
) -> np.ndarray:
    """Grid nodes [m] along one axis through every value of ``breaks`` (sorted): cells no
    larger than ``max_cell_m`` [m], and from each break flagged in ``walls`` a geometric
    progression starting at ``wall_cell_m`` [m] growing by ``growth`` [-] (``wall_cell_m`` = 0:
    uniform cells)."""
    out = [float(breaks[0])]
    for i in range(len(breaks) - 1):
        a, b = float(breaks[i]), float(breaks[i + 1])
        length = b - a
        ends = [walls[i], walls[i + 1]] if wall_cell_m > 0 else [False, False]
        sides: list[list[float]] = [[], []]
        for s in (0, 1):
            if not ends[s]:
                continue
            size = wall_cell_m
            while size < max_cell_m and sum(sides[s]) + size <= length / (2 if ends[1 - s] else 1):
                sides[s].append(size)
                size *= growth
        middle = length - sum(sides[0]) - sum(sides[1])
        n_mid = max(0, math.ceil(middle / max_cell_m - 1e-9))
        if n_mid == 0 and not (sides[0] or sides[1]):
            n_mid = 1
        sizes = (
            np.array(sides[0] + [middle / n_mid] * n_mid + sides[1][::-1])
            if n_mid
            else np.array(sides[0] + sides[1][::-1])
        )
        sizes *= length / sizes.sum()
        out.extend((a + np.cumsum(sizes))[:-1])
        out.append(b)
    return np.array(out)


@dataclass
class ChannelGrid:
    """A tensor grid of hexahedra restricted to a channel's boxes.

    ``nodes``: the three axes' grid nodes [m]; ``inside``: (nx, ny, nz) cell mask;
    ``cell_id``: (nx, ny, nz) OpenFOAM cell index (-1 outside)."""

    nodes: tuple[np.ndarray, np.ndarray, np.ndarray]
    inside: np.ndarray
    cell_id: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.cell_id = np.full(self.inside.shape, -1, dtype=np.int64)
        self.cell_id[self.inside] = np.arange(int(self.inside.sum()))

    @property
    def n_cells(self) -> int:
        return int(self.inside.sum())

    def centres(self) -> np.ndarray:
        """Cell centres (n_cells, 3) [m] in cell-index order."""
        mids = [(n[1:] + n[:-1]) / 2 for n in self.nodes]
        i, j, k = np.nonzero(self.inside)
        return np.column_stack([mids[0][i], mids[1][j], mids[2][k]])


def _box_mask(channel: Any, nodes: Sequence[np.ndarray]) -> np.ndarray:
    mids = [(n[1:] + n[:-1]) / 2 for n in nodes]
    cx, cy, cz = np.meshgrid(*mids, indexing="ij")
    inside = np.zeros(cx.shape, dtype=bool)
    for x0, x1, y0, y1, z0, z1 in channel.boxes:
        inside |= (cx > x0) & (cx < x1) & (cy > y0) & (cy < y1) & (cz > z0) & (cz < z1)
    return inside


def _on_port(channel: Any, x: float, y: np.ndarray) -> np.ndarray:
    """True where the points (x, y) lie on the inlet or outlet plane's span."""
    hit = np.zeros(np.shape(y), dtype=bool)
    for px, y0, y1, _ in (channel.inlet, channel.outlet):
        tol = 1e-9 * max(abs(y1 - y0), 1e-3)
        hit |= (abs(x - px) < tol) & (y > y0 - tol) & (y < y1 + tol)
    return hit


def wall_planes(channel: Any) -> list[list[bool]]:
    """For each axis, whether each break (box face coordinate) carries channel wall somewhere
    (inlet and outlet planes do not count)."""
    breaks = [sorted({round(v, 12) for b in channel.boxes for v in b[2 * a : 2 * a + 2]}) for a in range(3)]
    nodes = [np.array(b) for b in breaks]
    mask = np.pad(_box_mask(channel, nodes), 1)  # padded with outside
    mids = [(n[1:] + n[:-1]) / 2 for n in nodes]
    flags: list[list[bool]] = []
    for a in range(3):
        m = np.moveaxis(mask, a, 0)
        boundary = m[1:] != m[:-1]  # (n_breaks, ., .) faces on each plane
        f = []
        for p in range(len(breaks[a])):
            faces = boundary[p][1:-1, 1:-1]
            if a == 0 and faces.any():  # discount the inlet/outlet spans on x planes
                jj = np.nonzero(faces)[0]
                faces_wall = ~_on_port(channel, breaks[0][p], mids[1][jj])
                f.append(bool(faces_wall.any()))
            else:
                f.append(bool(faces.any()))
        flags.append(f)
    return flags


def channel_grid(
    channel: Any,
    cells_across_width: int,
    cells_across_height: int,
    cell_length_m: float,
    wall_cell_m: float = 0.0,
    growth: float = 1.2,
) -> ChannelGrid:
    """The graded tensor grid of ``channel`` (see the module docstring): cells at most
    width / ``cells_across_width``, height / ``cells_across_height`` and ``cell_length_m`` [m]
    long, first cell ``wall_cell_m`` [m] at every wall plane (0 = uniform), ``growth`` [-]."""
    w, h = channel.width_m, channel.height_m
    walls = wall_planes(channel)
    breaks = [sorted({round(v, 12) for b in channel.boxes for v in b[2 * a : 2 * a + 2]}) for a in range(3)]
    sizes = (cell_length_m, min(w / cells_across_width, cell_length_m), h / cells_across_height)
    nodes = tuple(graded_axis(breaks[a], walls[a], sizes[a], wall_cell_m, growth) for a in range(3))
    return ChannelGrid((nodes[0], nodes[1], nodes[2]), _box_mask(channel, nodes))

"""Transient heat conduction on linear tetrahedra (scikit-fem) with contact, films and coolant.

Equation, per part ``p`` with conductivity k_p and heat capacity rho_p c_p:

    rho c dT/dt = div(k grad T) + q_cell          in every part
    -k dT/dn = h_film (T - T_amb)                 on the external surfaces
    -k dT/dn = h_wall (T - T_fluid)               on the channel wall (INTERFACE)
    q_contact = h_gap (T_a - T_b)                 across every interface between two parts

Contact really resists: every node on a face shared by two parts is duplicated (one copy per
part) and the two copies are tied by the interface conductance h_gap integrated with the
consistent P1 surface mass matrix. Volume terms use a scikit-fem cell basis; the surface terms
(films, channel wall, contact) use scikit-fem facet bases on the boundary facets of the split
mesh (an interface face is a boundary facet of each of its two parts): ``int w u v`` for a
film, and ``int h (u_a - u_b)(v_a - v_b)`` with one facet basis per side for a contact, the
two sides' facets listed in the same order with the same vertex order, so that their
quadrature points coincide. The theta-method matrix ``C/dt + theta K`` is factorised
once with ``scipy.sparse.linalg.splu`` and reused while the step, materials, conductances and
coolant heat-transfer coefficients stay fixed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from hevsim.errors import ConfigError, InputError, SimulationError
from hevsim.thermal.materials import FILM_COEFFICIENT_W_M2K, GAP_CONDUCTANCE_W_M2K, Material
from hevsim.thermal.mesh import CHANNEL_WALL, ThermalMesh, mesh_faces, tet_volumes_m3, triangle_areas_m2

#: heat capacity matrix kinds of :class:`HeatModel` (``lumped_capacity`` true / false)
CAPACITY_KINDS = ("lumped", "consistent")
#: plate-coolant coupling of :class:`HeatModel`: "implicit" (the fluid of the end-of-step wall,
#: exact for a coolant with ``fluid_sensitivity``) or "staggered" (the fluid of the wall at the
#: start of the step, ``coupling_iterations`` fixed-point passes)
COUPLING_KINDS = ("implicit", "staggered")


class WallCoolant(Protocol):
    """What the solver needs from a coolant model coupled at the channel wall.

    The wall is cut into ``n_segments`` pieces (a 1-D channel model uses segments along the
    path; a 3D fluid model could use one segment per wall facet). Each step the solver passes
    the mean wall temperature and wall area of every segment and receives the fluid
    temperature [K] that drives the film ``h (T_wall - T_fluid)`` on that segment.
    """

    n_segments: int

    def heat_transfer_coefficient_w_m2k(self) -> np.ndarray:
        """Film coefficient [W/(m^2 K)] per segment, shape (n_segments,)."""
        ...

    def fluid_temperature_k(self, wall_temp_k: np.ndarray, wall_area_m2: np.ndarray) -> np.ndarray:
        """Fluid temperature [K] per segment for the given wall temperatures [K] and areas [m^2]."""
        ...


def _facet_index(skm: Any, tris: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Facets of the scikit-fem mesh ``skm`` that are the triangles ``tris`` (K, 3) (node
    indices of ``skm``) of tetrahedra ``tets`` (K,)."""
    cand = skm.t2f[:, tets]  # (4, K) the facets of each tetrahedron
    nodes = np.sort(skm.facets[:, cand], axis=0)  # (3, 4, K)
    hit = np.all(nodes == np.sort(tris, axis=1).T[:, None, :], axis=0)  # (4, K)
    if not np.all(hit.sum(axis=0) == 1):
        raise SimulationError("thermal mesh: a surface triangle is not a face of its tetrahedron.")
    return cand[np.argmax(hit, axis=0), np.arange(tets.size)]


def _facet_basis(skm: Any, facets: np.ndarray) -> Any:
    """P1 basis on the facets ``facets`` of ``skm`` (exact for products of two P1 functions)."""
    from skfem import ElementTetP1, FacetBasis

    return FacetBasis(skm, ElementTetP1(), facets=facets, intorder=2)


def _per_facet(basis: Any, value: np.ndarray) -> np.ndarray:
    """A value per facet of ``basis`` at every quadrature point, shape (facets, points)."""
    return np.repeat(np.asarray(value, dtype=float)[:, None], basis.X.shape[-1], axis=1)


def _mass_form() -> Any:
    """The bilinear form ``int w u v`` (``w``: the keyword argument ``weight``)."""
    from skfem import BilinearForm

    @BilinearForm
    def mass(u: Any, v: Any, w: Any) -> Any:
        return w.weight * u * v

    return mass


@dataclass(frozen=True)
class FacetMass:
    """The P1 surface mass matrices ``int phi_i phi_j`` of a set of facets, one per facet (the
    element matrices of a scikit-fem facet basis), to be weighted per facet: entry ``k`` is
    ``data[k]`` [m^2] at (``rows[k]``, ``cols[k]``) of facet ``facet[k]``."""

    rows: np.ndarray
    cols: np.ndarray
    facet: np.ndarray
    data: np.ndarray
    n_facets: int
    n_nodes: int

    @classmethod
    def assemble(cls, skm: Any, facets: np.ndarray) -> FacetMass:
        """The facet matrices of ``facets`` (indices into the facets of ``skm``)."""
        if facets.size == 0:
            e = np.zeros(0, dtype=np.int64)
            return cls(e, e, e, np.zeros(0), 0, skm.nvertices)
        fb = _facet_basis(skm, facets)
        el = _mass_form().elemental(fb, weight=_per_facet(fb, np.ones(facets.size)))
        rows, cols = el.indices
        facet = np.tile(np.arange(facets.size), el.data.size // facets.size)
        keep = el.data != 0.0  # the function of the vertex off the facet vanishes on it
        return cls(rows[keep], cols[keep], facet[keep], el.data[keep], facets.size, skm.nvertices)

    def subset(self, which: np.ndarray) -> FacetMass:
        """The facets ``which`` (indices into this set), numbered 0.. in that order."""
        new = np.full(self.n_facets, -1)
        new[which] = np.arange(which.size)
        k = np.flatnonzero(new[self.facet] >= 0)
        return FacetMass(
            self.rows[k], self.cols[k], new[self.facet[k]], self.data[k], which.size, self.n_nodes
        )

    def matrix(self, weight: np.ndarray) -> sp.csr_matrix:
        """``sum_f weight_f int_f u v`` (``weight`` per facet)."""
        w = self.data * np.asarray(weight, dtype=float)[self.facet]
        return sp.csr_matrix((w, (self.rows, self.cols)), shape=(self.n_nodes, self.n_nodes))

    def load(self, weight: np.ndarray) -> np.ndarray:
        """``sum_f weight_f int_f v`` (``weight`` per facet): the row sums of :meth:`matrix`,
        as the P1 functions sum to one."""
        w = self.data * np.asarray(weight, dtype=float)[self.facet]
        return np.bincount(self.rows, weights=w, minlength=self.n_nodes)

    def group_loads(self, group: np.ndarray, n_groups: int) -> sp.csr_matrix:
        """``int v`` over the facets of each group (``group`` per facet), shape (nodes, groups)."""
        shape = (self.n_nodes, max(n_groups, 1))
        return sp.csr_matrix((self.data, (self.rows, np.asarray(group)[self.facet])), shape=shape)


def _contact(skm: Any, facets_a: np.ndarray, facets_b: np.ndarray, h: np.ndarray) -> sp.csr_matrix:
    """Contact conductance ``int h (u_a - u_b)(v_a - v_b)`` between the facets ``facets_a`` and
    ``facets_b`` (the two copies of the same faces, listed in the same order, their vertices
    in the same order), with ``h`` constant per face."""
    from skfem import asm

    n = skm.nvertices
    if facets_a.size == 0:
        return sp.csr_matrix((n, n))
    mass = _mass_form()
    fa, fb = _facet_basis(skm, facets_a), _facet_basis(skm, facets_b)
    xa, xb = (np.asarray(basis.global_coordinates()) for basis in (fa, fb))
    if not np.allclose(xa, xb, rtol=0.0, atol=1e-12):  # [m]
        raise SimulationError("thermal mesh: the two sides of a contact interface do not coincide.")
    w = _per_facet(fa, h)
    cross = asm(mass, fb, fa, weight=w).tocsr()  # rows side a (test), columns side b (trial)
    k = asm(mass, fa, weight=w) + asm(mass, fb, weight=w) - cross - cross.T
    # The facet bases carry all four functions of each side's tetrahedron; the one of the vertex
    # off the face is zero there up to rounding (~1e-19 relative), which would add entries
    # between the two tetrahedra to the sparsity pattern: keep only those between face nodes.
    nodes = np.vstack([skm.facets[:, facets_a], skm.facets[:, facets_b]])  # (6, K)
    rows, cols = np.repeat(nodes[:, None, :], 6, axis=1), np.repeat(nodes[None, :, :], 6, axis=0)
    on_face = sp.csr_matrix((np.ones(rows.size), (rows.ravel(), cols.ravel())), shape=(n, n))
    on_face.data[:] = 1.0
    return sp.csr_matrix(k.multiply(on_face))


def interface_name(a: str, b: str) -> str:
    """Canonical name of the contact interface between parts ``a`` and ``b``: ``"a|b"`` sorted."""
    return "|".join(sorted((a, b)))


@dataclass(frozen=True)
class Discretisation:
    """The split (per-part duplicated) mesh and the assembled operators (SI units)."""

    points_m: np.ndarray  # (N, 3) split nodes
    tets: np.ndarray  # (M, 4)
    node_part: np.ndarray  # (N,)
    original_node: np.ndarray  # (N,) node of the input mesh
    stiffness: sp.csr_matrix  # conduction + contact + film [W/K]
    capacity: sp.csr_matrix  # consistent heat capacity [J/K]
    film_load_w: np.ndarray  # h_film T_amb int phi over the external surfaces [W]
    film_area: np.ndarray  # int phi over external surfaces [m^2]
    film_w_m2k: float
    ambient_k: float
    cell_load: sp.csr_matrix  # (N, n_cells): nodal share of 1 W in each cell [-]
    wall_tris: np.ndarray  # (K, 3) channel-wall triangles on split nodes
    wall_segment: np.ndarray  # (K,) segment of each wall triangle
    wall_weights: sp.csr_matrix  # (N, n_seg): int phi over each wall segment [m^2]
    wall_mass: FacetMass  # of the wall triangles: film h (T - T_fluid) per segment
    wall_area_m2: np.ndarray  # (n_seg,)
    interfaces: dict[str, float]  # contact interface name -> area [m^2]
    cell_volume_m3: np.ndarray  # (n_cells,)
    tet_volume_m3: np.ndarray  # (M,)
    #: ``surface_films`` as assembled: group -> (h [W/(m^2 K)], T_inf [K]) ...
    surface_films: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: ... and the facet matrices of the faces each group's film is on (a face in two groups
    #: belongs to the last), for :meth:`HeatModel.set_surface_film`
    surface_film_mass: dict[str, FacetMass] = field(default_factory=dict)
    #: the material of every part (name -> Material) the operators were assembled with
    materials: dict[str, Material] = field(default_factory=dict)


def discretise(
    mesh: ThermalMesh,
    materials: Mapping[str, Material],
    *,
    gap_conductance_w_m2k: float = GAP_CONDUCTANCE_W_M2K,
    interface_conductance_w_m2k: Mapping[str, float] | None = None,
    film_w_m2k: float = FILM_COEFFICIENT_W_M2K,
    ambient_k: float = 303.15,
    surface_films: Mapping[str, tuple[float, float]] | None = None,
    wall_segment_of_facet: np.ndarray | None = None,
    wall_h_w_m2k: np.ndarray | None = None,
) -> Discretisation:
    """Split the mesh at part interfaces and assemble conduction, capacity, contact and films.

    ``materials`` maps every part name to its :class:`Material`; ``interface_conductance_w_m2k``
    overrides ``gap_conductance_w_m2k`` for named interfaces (``"partA|partB"``);
    ``surface_films`` maps a facet group name to ``(h [W/(m^2 K)], T_inf [K])`` (these faces
    then get no ambient film); ``wall_segment_of_facet`` assigns each ``INTERFACE`` facet
    to a coolant segment and ``wall_h_w_m2k`` gives the coolant film per segment.
    """
    from skfem import Basis, BilinearForm, ElementTetP1, MeshTet, asm
    from skfem.helpers import dot, grad

    mesh.validate()
    src = mesh.source
    nparts = len(mesh.part_names)
    for name in mesh.part_names:
        if name not in materials:
            raise ConfigError(
                f"{src}: part '{name}' has no material properties; expected one of the materials "
                f"given for parts {sorted(materials)}."
            )
        materials[name].check(f"{src}: part '{name}'")
    for label, v in (
        ("gap_conductance_w_m2k", gap_conductance_w_m2k),
        ("film_w_m2k", film_w_m2k),
        ("ambient_k", ambient_k),
    ):
        if not (np.isfinite(v) and v >= 0.0) or (label == "ambient_k" and v <= 0.0):
            raise ConfigError(f"{src}: '{label}' = {v!r} is not physical; expected a finite value >= 0.")

    # ---- split nodes: one copy per (node, part) -------------------------------------------
    part = mesh.part_of_tet.astype(np.int64)
    keys = mesh.tets.astype(np.int64) * nparts + part[:, None]
    uniq, inv = np.unique(keys.ravel(), return_inverse=True)
    tets = inv.reshape(-1, 4).astype(np.int64)
    original_node = uniq // nparts
    node_part = uniq % nparts
    points = mesh.points_m[original_node]
    n = points.shape[0]

    def side(nodes: np.ndarray, parts: np.ndarray) -> np.ndarray:
        return np.searchsorted(uniq, nodes.astype(np.int64) * nparts + parts[:, None])

    # ---- faces of the input mesh: boundary and part interfaces --------------------------
    faces = mesh_faces(mesh.tets)
    inner = faces.other >= 0
    pa, pb = part[faces.owner], np.where(inner, part[np.maximum(faces.other, 0)], -1)
    iface = np.flatnonzero(inner & (pa != pb))
    bnd = np.flatnonzero(~inner)

    # Named facet groups (matched by their sorted node triples) on the boundary.
    bnd_keys = {tuple(r): i for i, r in enumerate(faces.nodes[bnd].tolist())}
    group_of_bnd = np.full(bnd.size, -1)
    group_names = list(mesh.facet_groups)
    group_rows: dict[str, np.ndarray] = {}
    for gi, gname in enumerate(group_names):
        rows = []
        for tri in np.sort(mesh.facet_groups[gname], axis=1).tolist():
            j = bnd_keys.get(tuple(tri))
            if j is not None:
                rows.append(j)
                group_of_bnd[j] = gi
        group_rows[gname] = np.asarray(rows, dtype=np.int64)
        if mesh.facet_groups[gname].shape[0] and not rows and gname == CHANNEL_WALL:
            raise InputError(f"{src}: surface '{gname}' has no facet on the mesh boundary.")
    surface_films = dict(surface_films or {})
    for gname in surface_films:
        if gname not in mesh.facet_groups:
            raise ConfigError(
                f"{src}: film surface '{gname}' is not a named surface of the mesh; "
                f"expected one of {sorted(mesh.facet_groups)}."
            )

    # ---- conduction and capacity with scikit-fem ----------------------------------------
    kmat = np.array([materials[nm].conductivity_w_mk for nm in mesh.part_names])
    cmat = np.array([materials[nm].volumetric_heat_capacity_j_m3k for nm in mesh.part_names])
    skm = MeshTet(points.T.copy(), tets.T.copy())
    basis = Basis(skm, ElementTetP1())
    nqp = basis.X.shape[1]

    @BilinearForm
    def conduction(u: Any, v: Any, w: Any) -> Any:
        return w.k * dot(grad(u), grad(v))

    @BilinearForm
    def capacity_form(u: Any, v: Any, w: Any) -> Any:
        return w.c * u * v

    ones = np.ones((1, nqp))
    stiffness = asm(conduction, basis, k=kmat[part][:, None] * ones).tocsr()
    capacity = asm(capacity_form, basis, c=cmat[part][:, None] * ones).tocsr()

    # ---- contact interfaces ----------------------------------------------------------------
    overrides = dict(interface_conductance_w_m2k or {})
    iface_names = np.array(
        [
            interface_name(mesh.part_names[a], mesh.part_names[b])
            for a, b in zip(pa[iface], pb[iface], strict=True)
        ],
        dtype=object,
    )
    present = sorted(set(iface_names.tolist()))
    for name, h in overrides.items():
        if name not in present:
            raise ConfigError(
                f"{src}: contact interface '{name}' does not exist in the mesh; expected one of "
                f"{present or '(none: the mesh has a single part)'}."
            )
        if not (np.isfinite(h) and h > 0.0):
            raise ConfigError(f"{src}: contact '{name}' conductance {h!r} is not physical; expected > 0.")
    h_if = np.array([overrides.get(nm, gap_conductance_w_m2k) for nm in iface_names.tolist()])
    tri = faces.nodes[iface]
    # Split node numbers keep the order of the input nodes within a part, so both copies of a
    # face have their vertices in the same order: their facet quadrature points coincide.
    side_a, side_b = side(tri, pa[iface]), side(tri, pb[iface])
    area_if = triangle_areas_m2(mesh.points_m, tri)
    interfaces = {nm: float(area_if[iface_names == nm].sum()) for nm in present}
    facets_a = _facet_index(skm, side_a, faces.owner[iface])
    facets_b = _facet_index(skm, side_b, faces.other[iface])
    stiffness = stiffness + _contact(skm, facets_a, facets_b, h_if)

    # ---- boundary films ---------------------------------------------------------------------
    bnd_side = side(faces.nodes[bnd], pa[bnd])
    bnd_facets = _facet_index(skm, bnd_side, faces.owner[bnd])
    film_w = np.zeros(bnd.size)
    film_t = np.zeros(bnd.size)
    is_ambient = np.ones(bnd.size, dtype=bool)
    if CHANNEL_WALL in group_rows:
        is_ambient[group_rows[CHANNEL_WALL]] = False
    film_owner = np.full(bnd.size, -1)
    for gi, (gname, (h, t_inf)) in enumerate(surface_films.items()):
        film_w[group_rows[gname]] = h
        film_t[group_rows[gname]] = t_inf
        is_ambient[group_rows[gname]] = False
        film_owner[group_rows[gname]] = gi
    film_w[is_ambient] = film_w_m2k
    film_t[is_ambient] = ambient_k
    bnd_mass = FacetMass.assemble(skm, bnd_facets)
    stiffness = stiffness + bnd_mass.matrix(film_w)
    film_load = bnd_mass.load(film_w * film_t)
    film_area = bnd_mass.load(is_ambient.astype(float))
    film_mass = {
        gname: bnd_mass.subset(np.flatnonzero(film_owner == gi)) for gi, gname in enumerate(surface_films)
    }

    # ---- channel wall (coolant film per segment) ------------------------------------------
    wall_rows = group_rows.get(CHANNEL_WALL, np.zeros(0, dtype=np.int64))
    wall_tris = bnd_side[wall_rows]
    if wall_segment_of_facet is None:
        wall_segment = np.zeros(wall_rows.size, dtype=np.int64)
    else:
        wall_segment = np.asarray(wall_segment_of_facet, dtype=np.int64)
        if wall_segment.shape != (wall_rows.size,):
            raise InputError(
                f"{src}: wall segment map has {wall_segment.size} entries; expected {wall_rows.size}."
            )
    n_seg = int(wall_segment.max(initial=-1)) + 1
    wall_area = np.bincount(wall_segment, weights=triangle_areas_m2(points, wall_tris), minlength=n_seg)
    wall_mass = bnd_mass.subset(wall_rows)
    wall_weights = wall_mass.group_loads(wall_segment, n_seg)
    if wall_h_w_m2k is not None and wall_rows.size:
        hw = np.asarray(wall_h_w_m2k, dtype=float)
        stiffness = stiffness + wall_mass.matrix(hw[wall_segment])

    # ---- per-cell heat load (body heat flux, uniform in each cell) ------------------------
    vol = np.abs(tet_volumes_m3(points, tets))
    ncell = mesh.n_cells
    cell_vol = np.bincount(
        mesh.cell_of_tet[mesh.cell_of_tet >= 0], weights=vol[mesh.cell_of_tet >= 0], minlength=ncell
    )
    in_cell = np.flatnonzero(mesh.cell_of_tet >= 0)
    cid = mesh.cell_of_tet[in_cell]
    share = np.repeat(vol[in_cell] / 4.0 / cell_vol[cid], 4)
    cell_load = sp.csr_matrix((share, (tets[in_cell].ravel(), np.repeat(cid, 4))), shape=(n, max(ncell, 1)))

    return Discretisation(
        points,
        tets,
        node_part,
        original_node,
        stiffness.tocsr(),
        capacity,
        film_load,
        film_area,
        film_w_m2k,
        ambient_k,
        cell_load,
        wall_tris,
        wall_segment,
        wall_weights.tocsr(),
        wall_mass,
        wall_area,
        interfaces,
        cell_vol,
        vol,
        {k: (float(h), float(t)) for k, (h, t) in surface_films.items()},
        film_mass,
        {nm: materials[nm] for nm in mesh.part_names},
    )


def cell_nodes(mesh: ThermalMesh, disc: Discretisation) -> tuple[np.ndarray, list[np.ndarray]]:
    """Nodal volume [m^3] (a quarter of every tetrahedron touching the node) and the nodes of
    every battery cell (those of the tetrahedra with ``mesh.cell_of_tet == cell``)."""
    n = disc.points_m.shape[0]
    node_vol = np.bincount(disc.tets.ravel(), weights=np.repeat(disc.tet_volume_m3 / 4, 4), minlength=n)
    in_cell = mesh.cell_of_tet >= 0
    cell_of_node = np.full(n, -1)
    cell_of_node[disc.tets[in_cell].ravel()] = np.repeat(mesh.cell_of_tet[in_cell], 4)
    return node_vol, [np.flatnonzero(cell_of_node == c) for c in range(mesh.n_cells)]


@dataclass(frozen=True)
class StepReport:
    """Heat flows at the end of one step [W] (positive = into the module for heat_in)."""

    time_s: float
    heat_in_w: float
    film_w: float  # to the ambient through the external films
    wall_w: float  # to the coolant through the channel wall
    stored_energy_j: float


class HeatModel:
    """Theta-method time stepper: implicit Euler (theta = 1, default) or Crank-Nicolson (0.5).

    ``(C/dt + theta K) T1 = (C/dt - (1 - theta) K) T0 + theta f1 + (1 - theta) f0``. The left
    matrix is factorised once and reused while ``dt_s`` and the operators stay fixed.
    ``C`` is the row-sum lumped heat capacity by default (``lumped_capacity``): with implicit
    Euler it keeps temperatures within their bounds next to steep fronts (the consistent
    matrix overshoots there: spurious hot spots a few tenths of a kelvin above the true
    maximum near a cooled wall); both have the same total heat capacity and the same
    second-order spatial convergence.
    Temperatures are in kelvin; heat inputs per cell in watts (``set_cell_heat_w``).
    On the channel wall, segment j loses ``h_j (T - T_fluid,j) + q_j`` per unit area: the film
    ``wall_h`` (:meth:`set_wall_film`) towards ``fluid_k`` plus :attr:`wall_flux_w_m2`, a
    prescribed heat flux [W/m^2] (zero unless an external coolant model gives flux only).
    The films of the discretisation's ``surface_films`` can be changed between steps with
    :meth:`set_surface_film` (a sink temperature or film coefficient varying in time).
    """

    def __init__(
        self,
        disc: Discretisation,
        *,
        dt_s: float,
        theta: float = 1.0,
        initial_temp_k: float | np.ndarray = 303.15,
        coolant: WallCoolant | None = None,
        coupling_iterations: int = 1,
        lumped_capacity: bool = True,
        coupling: str = "implicit",
    ) -> None:
        if not (np.isfinite(dt_s) and dt_s > 0.0):
            raise ConfigError(f"heat model: dt_s = {dt_s!r} is not valid; expected a positive step [s].")
        if not 0.5 <= theta <= 1.0:
            raise ConfigError(
                f"heat model: theta = {theta!r}; expected 0.5 (Crank-Nicolson) to 1 (implicit Euler)."
            )
        self._check_materials(disc)
        self.disc = disc
        # row-sum lumping: same total heat capacity (energy), no over/undershoot at fronts
        row_sums = np.asarray(disc.capacity.sum(axis=1)).ravel()
        self.capacity = sp.diags(row_sums).tocsr() if lumped_capacity else disc.capacity
        self.dt_s = float(dt_s)
        self.theta = float(theta)
        self.coolant = coolant
        self.coupling_iterations = max(1, int(coupling_iterations))
        if coupling not in COUPLING_KINDS:
            raise ConfigError(
                f"heat model: coupling = {coupling!r}; expected one of {', '.join(COUPLING_KINDS)}."
            )
        self.coupling = coupling
        #: (Y = LU^-1 W diag(h), P Y) of the implicit coupling, per factorisation
        self._wall_response: tuple[np.ndarray, np.ndarray] | None = None
        # conduction, contact and external films [W/K] and the films' load [W]; they differ from
        # the discretisation's only after set_surface_film
        self._stiffness: sp.csr_matrix = disc.stiffness
        self._film_load_w: np.ndarray = disc.film_load_w
        #: current (h [W/(m^2 K)], T_inf [K]) of every surface film of the discretisation
        self.surface_films: dict[str, tuple[float, float]] = dict(disc.surface_films)
        n = disc.points_m.shape[0]
        t0 = np.broadcast_to(np.asarray(initial_temp_k, dtype=float), (n,)).copy()
        if not np.all(np.isfinite(t0)) or t0.min() <= 0.0:
            raise ConfigError("heat model: initial temperature must be finite and > 0 K.")
        self.temp_k = t0
        self.time_s = 0.0
        self.cell_heat_w = np.zeros(disc.cell_load.shape[1])
        self.factorisations = 0
        n_seg = disc.wall_area_m2.size
        self.wall_h = np.zeros(n_seg)
        self.fluid_k = np.zeros(n_seg)
        self.wall_flux_w_m2 = np.zeros(n_seg)
        if coolant is not None:
            if n_seg == 0:
                raise InputError("heat model: a coolant is coupled but the mesh has no 'INTERFACE' wall.")
            if coolant.n_segments != n_seg:
                raise ConfigError(
                    f"heat model: coolant has {coolant.n_segments} segments; the wall has {n_seg}."
                )
            self.wall_h = np.asarray(coolant.heat_transfer_coefficient_w_m2k(), dtype=float)
            self.fluid_k = coolant.fluid_temperature_k(self.wall_temp_k(), disc.wall_area_m2)
        self._factorise()
        self._f_old = self._load()

    def _check_materials(self, disc: Discretisation) -> None:
        """The linear stepper refuses temperature-dependent materials (it would use the first
        row of their tables)."""
        for part, mat in disc.materials.items():
            if mat.temperature_dependent:
                raise ConfigError(
                    f"heat model: part '{part}' material '{mat.name}' depends on temperature; the linear "
                    "HeatModel (used by the thermal run, the ROM build, the FEM co-simulation "
                    "participant and CHT) needs constant properties: expected constant properties, or "
                    "NonlinearHeatModel for a deck."
                )

    def _factorise(self) -> None:
        """Assemble ``K`` (with the wall film ``wall_h``) and factorise ``C/dt + theta K``."""
        d = self.disc
        k = self._stiffness
        if np.any(self.wall_h):
            k = k + d.wall_mass.matrix(self.wall_h[d.wall_segment])
        self.k = k.tocsr()
        self._rhs_matrix = (self.capacity / self.dt_s - (1.0 - self.theta) * self.k).tocsr()
        # symmetric positive-definite matrix: minimum degree on A^T + A, diagonal pivots
        self._lu = splu(
            (self.capacity / self.dt_s + self.theta * self.k).tocsc(),
            permc_spec="MMD_AT_PLUS_A",
            options={"SymmetricMode": True},
        )
        self.factorisations += 1
        self._wall_response = None

    def set_dt(self, dt_s: float) -> None:
        """Step size [s] of the next steps; refactorises only when it changes."""
        if not (np.isfinite(dt_s) and dt_s > 0.0):
            raise ConfigError(f"heat model: dt_s = {dt_s!r} is not valid; expected a positive step [s].")
        if float(dt_s) != self.dt_s:
            self.dt_s = float(dt_s)
            self._factorise()

    def set_wall_film(self, h_w_m2k: np.ndarray) -> None:
        """Film coefficient [W/(m^2 K)] per wall segment; refactorises only when it changes."""
        h = np.asarray(h_w_m2k, dtype=float)
        if h.shape != self.wall_h.shape or not np.all(np.isfinite(h)) or h.min(initial=0.0) < 0.0:
            raise SimulationError(
                f"heat model: wall film {h.tolist()} is not valid; expected {self.wall_h.size} "
                "finite values >= 0 W/(m^2 K), one per wall segment."
            )
        if not np.array_equal(h, self.wall_h):
            self.wall_h = h.copy()
            self._factorise()

    def set_surface_film(self, name: str, h_w_m2k: float, sink_k: float) -> None:
        """Film coefficient [W/(m^2 K)] and sink temperature [K] of the surface film ``name``
        (a group of the discretisation's ``surface_films``) from the end of the next step on:
        the sink changes the load only, a new coefficient refactorises. With theta < 1 the new
        coefficient applies to the whole step (as :meth:`set_wall_film`)."""
        d = self.disc
        if name not in d.surface_film_mass:
            raise ConfigError(
                f"heat model: surface film '{name}' is not one of the discretisation's films "
                f"{sorted(d.surface_film_mass) or '(none)'}."
            )
        h, t = float(h_w_m2k), float(sink_k)
        if not (np.isfinite(h) and h >= 0.0 and np.isfinite(t) and t > 0.0):
            raise SimulationError(
                f"heat model: surface film '{name}' h = {h!r} W/(m^2 K), sink = {t!r} K; expected "
                "finite h >= 0 and a sink temperature > 0 K."
            )
        old_h = self.surface_films[name][0]
        self.surface_films[name] = (h, t)
        load = d.film_load_w
        stiffness = d.stiffness
        for g, (hg, tg) in self.surface_films.items():
            h0, t0 = d.surface_films[g]
            mass = d.surface_film_mass[g]
            if (hg, tg) != (h0, t0):
                load = load + mass.load(np.full(mass.n_facets, hg * tg - h0 * t0))
            if hg != h0:
                stiffness = stiffness + mass.matrix(np.full(mass.n_facets, hg - h0))
        self._film_load_w = load
        if h != old_h:
            self._stiffness = stiffness.tocsr()
            self._factorise()

    # -- inputs -------------------------------------------------------------------------------
    def set_cell_heat_w(
        self, heat_w: float | Sequence[float] | np.ndarray, *, from_now: bool = False
    ) -> None:
        """Heat generated in every cell [W] (body heat flux, uniform over each cell's volume).

        It is the load at the end of the next step; with ``from_now`` it is also the load now
        (a step change at the current time: with theta < 1 the next step otherwise ramps from
        the previous heat)."""
        q = np.broadcast_to(np.asarray(heat_w, dtype=float), self.cell_heat_w.shape)
        if not np.all(np.isfinite(q)):
            raise SimulationError(f"heat model: cell heat {q.tolist()} is not finite.")
        self.cell_heat_w = q.copy()
        if from_now:
            self._f_old = self._load()

    # -- observations --------------------------------------------------------------------------
    def wall_temp_k(self, temp_k: np.ndarray | None = None) -> np.ndarray:
        """Mean channel-wall temperature per coolant segment [K]."""
        t = self.temp_k if temp_k is None else temp_k
        area = np.where(self.disc.wall_area_m2 > 0, self.disc.wall_area_m2, 1.0)
        return np.asarray(self.disc.wall_weights.T @ t)[: area.size] / area

    def report(self) -> StepReport:
        """Heat flows at the current state."""
        d, t = self.disc, self.temp_k
        film_total = float(t @ (self._stiffness @ np.ones_like(t))) - float(self._film_load_w.sum())
        wall = float(
            np.sum(d.wall_area_m2 * (self.wall_h * (self.wall_temp_k() - self.fluid_k) + self.wall_flux_w_m2))
        )
        return StepReport(
            self.time_s, float(self.cell_heat_w.sum()), film_total, wall, float(np.sum(self.capacity @ t))
        )

    # -- stepping --------------------------------------------------------------------------------
    def _load(self) -> np.ndarray:
        d = self.disc
        f = self._film_load_w + d.cell_load @ self.cell_heat_w
        if self.coolant is not None:
            w = d.wall_weights[:, : self.fluid_k.size]
            f = f + w @ (self.wall_h * self.fluid_k - self.wall_flux_w_m2)
        return np.asarray(f)

    def _implicit_wall(self, predicted: np.ndarray, wall0_k: np.ndarray, sens: np.ndarray) -> np.ndarray:
        """The step's temperatures with the fluid at the end-of-step wall (implicit coupling).

        The coolant's segment-mean fluid temperature is affine in the segment-mean wall
        temperatures, ``T_f = T_f0 + M (w - w0)`` (``M`` = ``sens``), and the wall film enters
        the load as ``W h T_f``; so the step is ``T = T_p + theta Y M e`` with the predictor
        ``T_p`` (fluid from the wall ``w0`` at the start of the step), ``Y = LU^-1 W h`` and the
        wall change ``e = w(T) - w0`` from the small system ``(I - theta P Y M) e = w(T_p) - w0``
        (``P``: the wall means), a low-rank update of the factorised step (no iteration)."""
        d = self.disc
        n = self.fluid_k.size
        area = np.where(d.wall_area_m2 > 0, d.wall_area_m2, 1.0)[:n]
        if self._wall_response is None:
            w = d.wall_weights[:, :n].toarray() if sp.issparse(d.wall_weights) else d.wall_weights[:, :n]
            y = np.asarray(self._lu.solve(np.asarray(w, dtype=float) * self.wall_h[None, :n]))
            self._wall_response = (y, np.asarray(d.wall_weights.T @ y)[:n] / area[:, None])
        y, py = self._wall_response
        e = np.linalg.solve(np.eye(n) - self.theta * py @ sens, self.wall_temp_k(predicted) - wall0_k)
        return predicted + self.theta * (y @ (sens @ e))

    def step(self) -> np.ndarray:
        """Advance one step of ``dt_s``; returns the new nodal temperatures [K]."""
        base = self._rhs_matrix @ self.temp_k + (1.0 - self.theta) * self._f_old
        new = self.temp_k
        f_new: np.ndarray | None = None
        sens_of = getattr(self.coolant, "fluid_sensitivity", None)
        if self.coupling == "implicit" and self.coolant is not None and sens_of is not None:
            area = self.disc.wall_area_m2
            wall0 = self.wall_temp_k(new)
            self.fluid_k = self.coolant.fluid_temperature_k(wall0, area)
            predicted = self._lu.solve(base + self.theta * self._load())
            new = self._implicit_wall(predicted, wall0, np.asarray(sens_of(area), dtype=float))
            self.fluid_k = self.coolant.fluid_temperature_k(self.wall_temp_k(new), area)
            f_new = self._load()
        for _ in range(self.coupling_iterations if f_new is None else 0):
            if self.coolant is not None:
                self.fluid_k = self.coolant.fluid_temperature_k(self.wall_temp_k(new), self.disc.wall_area_m2)
            f_new = self._load()
            new = self._lu.solve(base + self.theta * f_new)
        if not np.all(np.isfinite(new)):
            raise SimulationError(
                f"heat model: temperature became non-finite at t = {self.time_s + self.dt_s} s."
            )
        assert f_new is not None  # coupling_iterations >= 1
        self.temp_k = new
        self._f_old = f_new
        self.time_s += self.dt_s
        return new

    def steady(self) -> np.ndarray:
        """Steady state for the current inputs (without coolant iteration) [K]."""
        from scipy.sparse.linalg import spsolve

        self.temp_k = np.asarray(spsolve(self.k.tocsc(), self._load()))
        return self.temp_k


def _unit_conduction(points_m: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Element conduction matrices for k = 1, ``V grad(phi_i) . grad(phi_j)`` [m], shape (M, 4, 4)."""
    x = points_m[tets]  # (M, 4, 3)
    jac = (x[:, 1:, :] - x[:, :1, :]).transpose(0, 2, 1)  # columns x1 - x0, x2 - x0, x3 - x0
    inv = np.linalg.inv(jac)  # rows: gradients of phi_1..phi_3
    grads = np.concatenate([-inv.sum(axis=1, keepdims=True), inv], axis=1)  # (M, 4, 3)
    vol = np.abs(np.linalg.det(jac)) / 6.0
    return vol[:, None, None] * np.einsum("mik,mjk->mij", grads, grads)


class NonlinearHeatModel(HeatModel):
    """Implicit Euler with temperature-dependent properties (materials with tables).

    Per step it solves ``V_i (h(T_i) - h(T_i^n)) / dt + (K(T) T)_i = f_i`` for the new nodal
    temperatures: ``h`` the volumetric enthalpy of the node's part (:meth:`Material.enthalpy_j_m3`,
    the integral of rho c_p), ``V_i`` the node's lumped volume (the row sums of the P1 mass
    matrix, as the linear solver's lumped capacity), ``K(T)`` the conduction with every
    element's conductivity at its mean (centroid) temperature plus the contact and film terms
    (linear). Newton on the capacity term and Picard on the conductivity: the update solves
    ``(diag(V rho c(T^m)) / dt + K(T^m)) dT = -R(T^m)`` until the largest update is below
    ``tolerance_k`` [K]. The stored heat is the enthalpy change, so heat in - stored - to the
    films closes to the residual left (conduction's rows sum to zero for any conductivity).
    Lumped capacity and implicit Euler only; no coolant (films and cell heat as
    :class:`HeatModel`, :meth:`set_surface_film` included). With constant properties it solves
    the same equations as :class:`HeatModel` (to rounding).
    """

    def __init__(
        self,
        disc: Discretisation,
        *,
        dt_s: float,
        initial_temp_k: float | np.ndarray = 303.15,
        tolerance_k: float = 1e-10,
        max_iterations: int = 50,
    ) -> None:
        super().__init__(disc, dt_s=dt_s, initial_temp_k=initial_temp_k)
        n = disc.points_m.shape[0]
        self.node_volume_m3 = np.bincount(
            disc.tets.ravel(), weights=np.repeat(disc.tet_volume_m3 / 4.0, 4), minlength=n
        )
        names = list(disc.materials)
        self._mats = [disc.materials[nm] for nm in names]
        self._node_part = disc.node_part
        tet_part = disc.node_part[disc.tets[:, 0]]
        # conduction of the temperature-dependent parts: K(T) = K(disc) + sum_e (k_e(T) - k_p) K1_e
        self._var_tets = np.flatnonzero(
            [
                bool(self._mats[p].conductivity_table) and len(self._mats[p].conductivity_table) > 1
                for p in tet_part
            ]
        )
        self._tet_part = tet_part[self._var_tets]
        self._k1 = _unit_conduction(disc.points_m, disc.tets[self._var_tets])
        tv = disc.tets[self._var_tets]
        self._rows = np.repeat(tv, 4, axis=1).ravel()
        self._cols = np.tile(tv, (1, 4)).ravel()
        self.tolerance_k = float(tolerance_k)
        self.max_iterations = int(max_iterations)
        self.iterations = 0  # Newton-Picard iterations of the last step

    def _check_materials(self, disc: Discretisation) -> None:
        for part, mat in disc.materials.items():
            mat.check(f"nonlinear heat model: part '{part}'")

    def _factorise(self) -> None:
        """No fixed factorisation: each iteration factorises its own matrix."""
        self.k = self._stiffness

    def _per_node(self, what: str, temp_k: np.ndarray) -> np.ndarray:
        out = np.empty_like(temp_k)
        for p, mat in enumerate(self._mats):
            sel = self._node_part == p
            out[sel] = getattr(mat, what)(temp_k[sel])
        return out

    def enthalpy_j(self, temp_k: np.ndarray | None = None) -> float:
        """Stored heat [J]: the sum of the nodal enthalpies ``V_i h(T_i)``."""
        t = self.temp_k if temp_k is None else temp_k
        return float(np.sum(self.node_volume_m3 * self._per_node("enthalpy_j_m3", t)))

    def conduction(self, temp_k: np.ndarray) -> sp.csr_matrix:
        """``K(T)`` [W/K]: films, contact and conduction at the elements' mean temperatures."""
        if self._var_tets.size == 0:
            return self._stiffness
        tbar = temp_k[self.disc.tets[self._var_tets]].mean(axis=1)
        dk = np.empty(self._var_tets.size)
        for p in np.unique(self._tet_part):
            sel = self._tet_part == p
            mat = self._mats[int(p)]
            dk[sel] = mat.conductivity_at(tbar[sel]) - mat.conductivity_w_mk
        n = temp_k.size
        delta = sp.csr_matrix(
            ((dk[:, None, None] * self._k1).ravel(), (self._rows, self._cols)), shape=(n, n)
        )
        return (self._stiffness + delta).tocsr()

    def residual_w(self, temp_k: np.ndarray) -> np.ndarray:
        """Implicit-Euler residual [W] of the next step at ``temp_k``."""
        h0 = self._per_node("enthalpy_j_m3", self.temp_k)
        h1 = self._per_node("enthalpy_j_m3", temp_k)
        return self.node_volume_m3 * (h1 - h0) / self.dt_s + self.conduction(temp_k) @ temp_k - self._load()

    def step(self) -> np.ndarray:
        """Advance one step of ``dt_s``; returns the new nodal temperatures [K]."""
        new = self.temp_k.copy()
        for it in range(1, self.max_iterations + 1):
            k = self.conduction(new)
            cap = self.node_volume_m3 * self._per_node("heat_capacity_at", new) / self.dt_s
            r = self.residual_w(new)
            lu = splu((sp.diags(cap) + k).tocsc(), permc_spec="MMD_AT_PLUS_A")
            self.factorisations += 1
            dt = lu.solve(-r)
            new = new + dt
            if not np.all(np.isfinite(new)):
                break
            if np.abs(dt).max() <= self.tolerance_k:
                self.iterations = it
                break
        else:
            raise SimulationError(
                f"nonlinear heat model: no convergence in {self.max_iterations} iterations at "
                f"t = {self.time_s + self.dt_s} s (last update {np.abs(dt).max():.3g} K > "
                f"{self.tolerance_k:g} K); expected a smaller dt_s."
            )
        if not np.all(np.isfinite(new)):
            raise SimulationError(
                f"nonlinear heat model: temperature became non-finite at t = {self.time_s + self.dt_s} s."
            )
        self.temp_k = new
        self.k = self.conduction(new)
        self.time_s += self.dt_s
        return new

    def report(self) -> StepReport:
        """Heat flows at the current state; ``stored_energy_j`` is the enthalpy."""
        rep = super().report()
        return StepReport(rep.time_s, rep.heat_in_w, rep.film_w, rep.wall_w, self.enthalpy_j())

    def steady(self) -> np.ndarray:
        """Steady state for the current inputs [K]: Picard on ``K(T) T = f``."""
        from scipy.sparse.linalg import spsolve

        t = self.temp_k.copy()
        for _ in range(self.max_iterations):
            new = np.asarray(spsolve(self.conduction(t).tocsc(), self._load()))
            if np.abs(new - t).max() <= self.tolerance_k:
                self.temp_k = new
                return new
            t = new
        raise SimulationError(
            f"nonlinear heat model: steady state not converged in {self.max_iterations} iterations."
        )

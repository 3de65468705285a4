"""Monolithic reference for the conjugate heat transfer (CHT) of a straight channel in a plate
slab, and the partitioned (co-simulation) solution of the same case to compare with it.

Case: the plate of a :class:`~hevsim.thermal.geometry.ModuleGeometry` with one straight
channel pass (``channel_passes = 1``): a slab ``[0, L_x] x [0, L_y] x [0, t]`` [m] of the plate
material with the channel box cut along x. The top face is held at ``top_temp_k`` [K] (the cells'
side), the other outer faces are adiabatic; coolant enters at ``inlet_temp_k`` [K] with the
laminar flow of :func:`hevsim.thermal.flow.solve_flow`, frozen. Everything starts at
``initial_temp_k`` [K].

**Monolithic** (:class:`MonolithicCHT`): one P2 temperature on a structured tetrahedral mesh of
the whole slab whose channel part is, element by element, the coolant's own mesh (the flow
mesh); the plate's conduction (``int k grad T . grad v``, capacity ``rho c``) on the solid
elements and the coolant's assembled advection-diffusion operator
(:class:`hevsim.thermal.cht.CoolantThermal`, SUPG, divergence correction, weak inflow) on the
channel elements form one sparse system. The wall nodes are shared: temperature and heat flux
are continuous across the wall with no exchange model at all. Steady, or implicit Euler.

**Partitioned** (:func:`run_partitioned`): the same plate discretisation as a co-simulation
participant (:class:`PlateSlabParticipant`) with the module FEM participant's coupling
(:mod:`hevsim.cosim.fem`, ``coolant = "external"``): it sends the mean wall temperature and the
area per wall segment and applies, per segment, the coolant's heat flux linearised with its
film, ``q(T) = q* + h (T - T*)``; the coolant is
:class:`hevsim.cosim.coolant_cht.CoolantCHTParticipant`. Gauss-Seidel (plate, then coolant)
through :class:`hevsim.cosim.master.Master` at a coupling step ``step_s``, the module
co-simulation's scheme. Its differences from the monolithic solution are the coupling-step
(splitting) error, which vanishes with the step, and the exchange per segment (one wall
temperature and one film per segment instead of continuity node by node), which shrinks with
more segments.

Both solutions share the coolant operator, its wall heat (the consistent residual of the wall
rows, gathered per segment) and its mixing-cup outlet temperature, so they compare one to one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from hevsim.cosim.participant import Participant, store_inputs
from hevsim.errors import ConfigError
from hevsim.thermal.cht import CoolantThermal
from hevsim.thermal.coolant import segments_along_path
from hevsim.thermal.geometry import ModuleGeometry
from hevsim.thermal.materials import TABLE_4_3, Material

#: Cells of the slab mesh in the plate on each side of the channel (across y) [-] ...
PLATE_CELLS_ACROSS_Y = 3
#: ... and below and above it (across z) [-].
PLATE_CELLS_ACROSS_Z = 2
#: Relative distance [-] under which a P2 node of the coolant mesh is the slab mesh's node.
NODE_MATCH_TOLERANCE = 1e-9


@dataclass
class Slab:
    """The plate slab around the coolant's channel: mesh, P2 basis, the solid elements, the
    coolant's dofs in the slab numbering, the wall facets per segment and the top face."""

    model: CoolantThermal
    geometry: ModuleGeometry
    mesh: Any
    basis: Any
    solid: np.ndarray  # element indices of the plate
    coolant_dofs: np.ndarray  # slab dof of each coolant dof
    wall_facets: np.ndarray  # facets between plate and channel
    wall_segment: np.ndarray  # segment of each wall facet
    top_dofs: np.ndarray  # dofs on the top face (z = plate thickness)


def build_slab(model: CoolantThermal, geometry: ModuleGeometry) -> Slab:
    """The slab of ``geometry``'s plate around ``model``'s (straight, one-pass) channel, meshed
    so that its channel elements are the coolant mesh's; raises :class:`ConfigError` when the
    channel is not one straight pass or the meshes do not conform."""
    from scipy.spatial import cKDTree
    from skfem import Basis, ElementTetP2, MeshTet

    g = geometry
    where = f"{model.where}: monolithic CHT reference"
    boxes = model.channel.boxes
    if len(boxes) != 1 or g.channel_passes != 1:
        raise ConfigError(f"{where}: needs one straight channel pass (channel_passes = 1); got {len(boxes)}.")
    if model.wall_function is not None:
        raise ConfigError(
            f"{where}: shares the wall nodes of coolant and plate, so it needs the wall resolved; the "
            "coolant uses the thermal wall function (a film at the wall): use flow.thermal_wall = 'resolved'."
        )
    cm = model.flow.mesh
    xs, ys, zs = (np.unique(np.round(cm.p[i], 12)) for i in range(3))
    lx, ly, t = g.length_x_m, g.length_y_m, g.plate_thickness_m
    if not (math.isclose(xs[0], 0.0, abs_tol=1e-12) and math.isclose(xs[-1], lx, rel_tol=1e-9)):
        raise ConfigError(f"{where}: the channel must run through the plate, x = 0 .. {lx} m.")
    ny, nz = PLATE_CELLS_ACROSS_Y, PLATE_CELLS_ACROSS_Z
    ys = np.concatenate((np.linspace(0.0, ys[0], ny + 1)[:-1], ys, np.linspace(ys[-1], ly, ny + 1)[1:]))
    zs = np.concatenate((np.linspace(0.0, zs[0], nz + 1)[:-1], zs, np.linspace(zs[-1], t, nz + 1)[1:]))
    mesh = MeshTet.init_tensor(xs, ys, zs)
    x0, x1, y0, y1, z0, z1 = boxes[0]
    c = mesh.p[:, mesh.t].mean(axis=1)
    fluid = (c[0] > x0) & (c[0] < x1) & (c[1] > y0) & (c[1] < y1) & (c[2] > z0) & (c[2] < z1)
    basis = Basis(mesh, ElementTetP2(), intorder=4)
    size = max(lx, ly, t)
    dist, idx = cKDTree(basis.doflocs.T).query(model.basis.doflocs.T)
    if fluid.sum() != cm.t.shape[1] or np.max(dist) > NODE_MATCH_TOLERANCE * size:
        raise ConfigError(f"{where}: the slab mesh does not contain the coolant mesh node for node.")
    # wall facets: one neighbour in the plate, the other in the channel
    f2t = mesh.f2t
    inner = f2t[1] >= 0
    wall = np.nonzero(inner & (fluid[f2t[0]] != fluid[np.where(inner, f2t[1], 0)]))[0]
    mid = mesh.p[:, mesh.facets[:, wall]].mean(axis=1)
    seg = segments_along_path(mid.T, model.path_m, model.n_segments)
    top = mesh.facets_satisfying(
        lambda x: np.abs(x[2] - t) < NODE_MATCH_TOLERANCE * size, boundaries_only=True
    )
    return Slab(model, g, mesh, basis, np.nonzero(~fluid)[0], idx, wall, seg, basis.get_dofs(top).all())


def _plate_matrices(slab: Slab, plate: Material) -> tuple[Any, Any]:
    """Conduction [W/K] and capacity [J/K] matrices of the plate elements (slab numbering)."""
    from skfem import Basis, BilinearForm, ElementTetP2
    from skfem.helpers import dot, grad

    if plate.temperature_dependent:
        raise ConfigError(
            f"CHT reference: plate material '{plate.name}' depends on temperature; the conjugate "
            "heat-transfer model is linear: expected constant properties."
        )
    k, rc = plate.conductivity_w_mk, plate.volumetric_heat_capacity_j_m3k
    b = Basis(slab.mesh, ElementTetP2(), intorder=4, elements=slab.solid)

    @BilinearForm
    def conduction(t: Any, v: Any, _: Any) -> Any:
        return k * dot(grad(t), grad(v))

    @BilinearForm
    def capacity(t: Any, v: Any, _: Any) -> Any:
        return rc * t * v

    return conduction.assemble(b).tocsr(), capacity.assemble(b).tocsr()


def _coolant_to_slab(slab: Slab) -> Any:
    """Sparse (coolant dofs, slab dofs) selection [-]: ``S @ T_slab`` = the coolant's dofs."""
    from scipy.sparse import coo_matrix

    n_c = slab.model.basis.N
    return coo_matrix((np.ones(n_c), (np.arange(n_c), slab.coolant_dofs)), shape=(n_c, slab.basis.N)).tocsr()


class MonolithicCHT:
    """Plate conduction and coolant advection-diffusion in one sparse system (module
    docstring). ``plate``: the slab's material (default aluminium, thesis Table 4.3);
    ``coolant_capacity``: False leaves out the coolant's heat capacity (the quasi-steady coolant
    of the module co-simulation's default participant)."""

    def __init__(
        self,
        slab: Slab,
        top_temp_k: float,
        inlet_temp_k: float,
        plate: Material | None = None,
        coolant_capacity: bool = True,
    ):
        from scipy.sparse.linalg import splu

        self.slab, self.model = slab, slab.model
        self.coolant_capacity = bool(coolant_capacity)
        self.plate = (plate or TABLE_4_3["aluminium"]).check(f"{self.model.where}: plate")
        k_s, c_s = _plate_matrices(slab, self.plate)
        self.select = s = _coolant_to_slab(slab)
        self.stiffness = (k_s + s.T @ self.model.stiffness @ s).tocsr()
        self.capacity = (c_s + s.T @ self.model.capacity @ s).tocsr() if coolant_capacity else c_s
        self.top_temp_k, self.inlet_temp_k = float(top_temp_k), float(inlet_temp_k)
        self.free = np.setdiff1d(np.arange(slab.basis.N), slab.top_dofs)
        self._splu = splu
        self._lu: dict[float, Any] = {}

    def solve(self, *, dt_s: float = math.inf, previous_k: np.ndarray | None = None) -> np.ndarray:
        """Slab temperature dofs [K]: steady (``dt_s`` = inf) or one implicit Euler step of
        ``dt_s`` [s] from ``previous_k`` [K]."""
        key = float(dt_s)
        a = self.stiffness if not math.isfinite(key) else self.stiffness + self.capacity / key
        if key not in self._lu:
            self._lu[key] = self._splu(a[self.free][:, self.free].tocsc())
        rhs = self.select.T @ (self.model.inflow * self.inlet_temp_k)
        if math.isfinite(key):
            if previous_k is None:
                raise ConfigError(f"{self.model.where}: a transient step needs the previous temperature.")
            rhs = rhs + self.capacity @ previous_k / key
        t = np.zeros(self.slab.basis.N)
        t[self.slab.top_dofs] = self.top_temp_k
        r = rhs - a @ t
        t[self.free] = self._lu[key].solve(r[self.free])
        return t

    def coolant_heat_w(
        self, t_k: np.ndarray, *, dt_s: float = math.inf, previous_k: np.ndarray | None = None
    ) -> np.ndarray:
        """Heat into the coolant per wall segment [W] of the slab field ``t_k`` [K] (the
        coolant's wall residual, as :meth:`CoolantThermal.solve` gives it)."""
        m, s = self.model, self.select
        tc = s @ t_k
        r = m.stiffness @ tc - m.inflow * self.inlet_temp_k
        if math.isfinite(dt_s) and self.coolant_capacity:
            if previous_k is None:
                raise ConfigError(f"{m.where}: a transient step needs the previous temperature.")
            r = r + m.capacity @ (tc - s @ previous_k) / dt_s
        return np.asarray(m.wall_weights.T @ r[m.wall_dofs])

    def outlet_temp_k(self, t_k: np.ndarray) -> float:
        """Mixing-cup outlet temperature [K] of the slab field ``t_k`` [K]."""
        return self.model.outlet_temp_k(self.select @ t_k)

    def run(self, initial_temp_k: float, dt_s: float, stop_s: float) -> dict[str, np.ndarray]:
        """Implicit Euler from a uniform ``initial_temp_k`` [K] to ``stop_s`` [s] in steps of
        ``dt_s`` [s]: time [s], wall heat [W] and outlet temperature [K] after each step."""
        n = round(stop_s / dt_s)
        if n < 1 or not math.isclose(n * dt_s, stop_s, rel_tol=1e-9):
            raise ConfigError(f"{self.model.where}: stop time {stop_s} s is not a multiple of dt {dt_s} s.")
        t = np.full(self.slab.basis.N, float(initial_temp_k))
        heat, outlet = np.empty(n), np.empty(n)
        for i in range(n):
            prev, t = t, self.solve(dt_s=dt_s, previous_k=t)
            heat[i] = self.coolant_heat_w(t, dt_s=dt_s, previous_k=prev).sum()
            outlet[i] = self.outlet_temp_k(t)
        return {"time_s": dt_s * np.arange(1, n + 1), "heat_w": heat, "outlet_temp_k": outlet}


class PlateSlabParticipant(Participant):
    """The slab's plate as a co-simulation participant with the module FEM participant's
    coolant exchange (:mod:`hevsim.cosim.fem`, ``coolant = "external"``): outputs
    ``wall<j>_temp_k`` [K] (area-mean wall temperature of segment j) and ``wall<j>_area_m2``
    [m^2]; inputs ``wall<j>_heat_flux_w_m2`` [W/m^2, into the coolant],
    ``wall<j>_film_w_m2k`` [W/(m^2 K)] and optionally ``wall<j>_fluid_temp_k`` [K] (a film to
    it instead of the linearised flux). Implicit Euler in sub-steps of at most ``dt_s`` [s]."""

    def __init__(
        self,
        name: str,
        slab: Slab,
        top_temp_k: float,
        initial_temp_k: float,
        dt_s: float,
        plate: Material | None = None,
    ):
        from skfem import BilinearForm, ElementTetP2, FacetBasis, LinearForm

        self.name, self.slab = name, slab
        self.plate = (plate or TABLE_4_3["aluminium"]).check(f"participant {name!r}: plate")
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise ConfigError(f"participant {name!r}: dt_s = {dt_s!r}; expected a positive time step [s].")
        self.dt_s = float(dt_s)
        n = self.n_segments = slab.model.n_segments
        self.inputs = {f"wall{j}_heat_flux_w_m2": "W/m2" for j in range(n)}
        self.inputs.update({f"wall{j}_film_w_m2k": "W/(m2.K)" for j in range(n)})
        self.inputs.update({f"wall{j}_fluid_temp_k": "K" for j in range(n)})
        self.outputs = {f"wall{j}_temp_k": "K" for j in range(n)}
        self.outputs.update({f"wall{j}_area_m2": "m2" for j in range(n)})
        self.stiffness, self.capacity = _plate_matrices(slab, self.plate)
        used = np.unique(slab.basis.element_dofs[:, slab.solid])
        self.free = np.setdiff1d(used, slab.top_dofs)
        self.top_temp_k = float(top_temp_k)

        @BilinearForm
        def wall_mass(t: Any, v: Any, _: Any) -> Any:
            return t * v

        @LinearForm
        def wall_load(v: Any, _: Any) -> Any:
            return v

        self._mass, self._load = [], []
        for j in range(n):
            fb = FacetBasis(slab.mesh, ElementTetP2(), facets=slab.wall_facets[slab.wall_segment == j])
            self._mass.append(wall_mass.assemble(fb).tocsr())
            self._load.append(wall_load.assemble(fb))
        self.area_m2 = np.array([float(b.sum()) for b in self._load])
        if np.any(self.area_m2 <= 0.0):
            raise ConfigError(f"participant {name!r}: a wall segment has no facet of the slab mesh.")
        self.temp_k = np.full(slab.basis.N, float(initial_temp_k))
        self.temp_k[slab.top_dofs] = self.top_temp_k
        self.u = dict.fromkeys(self.inputs, 0.0)
        self._lu: dict[tuple[float, ...], Any] = {}
        for j in range(n):
            self.u[f"wall{j}_fluid_temp_k"] = math.nan

    def wall_temp_k(self) -> np.ndarray:
        """Area-mean wall temperature per segment [K]."""
        return np.array([b @ self.temp_k for b in self._load]) / self.area_m2

    def set_inputs(self, values: Mapping[str, float]) -> None:
        store_inputs(self, self.u, values)

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        from scipy.sparse.linalg import splu

        n = self.n_segments
        flux, film, fluid = (
            np.array([self.u[f"wall{j}_{q}"] for j in range(n)])
            for q in ("heat_flux_w_m2", "film_w_m2k", "fluid_temp_k")
        )
        if not (np.all(np.isfinite(flux)) and np.all(np.isfinite(film)) and film.min() >= 0.0):
            raise ConfigError(f"participant {self.name!r}: wall flux {flux} / film {film} are not valid.")
        wall = self.wall_temp_k()
        has = film > 0.0
        sink = np.where(np.isfinite(fluid), fluid, wall - flux / np.where(has, film, 1.0))
        robin = sum(film[j] * self._mass[j] for j in range(n))
        # heat into the plate per unit test function: film to the sink, or the pure flux
        load = sum((film[j] * sink[j] if has[j] else -flux[j]) * self._load[j] for j in range(n))
        steps = max(1, math.ceil(h / self.dt_s - 1e-9))
        dt = h / steps
        key = (dt, *film.tolist())  # the coolant's film is constant at a fixed step: factor once
        if key not in self._lu:
            a = (self.stiffness + robin + self.capacity / dt).tocsr()
            self._lu = {key: (a, splu(a[self.free][:, self.free].tocsc()))}
        a, lu = self._lu[key]
        for _ in range(steps):
            rhs = load + self.capacity @ self.temp_k / dt
            top = np.zeros_like(self.temp_k)
            top[self.slab.top_dofs] = self.top_temp_k
            r = rhs - a @ top
            self.temp_k[self.free] = lu.solve(r[self.free])
        return True, None

    def get_outputs(self) -> dict[str, float]:
        wall = self.wall_temp_k()
        out = {f"wall{j}_temp_k": float(wall[j]) for j in range(self.n_segments)}
        out.update({f"wall{j}_area_m2": float(self.area_m2[j]) for j in range(self.n_segments)})
        return out

    def get_state(self) -> Any:
        return {"u": dict(self.u), "temp_k": self.temp_k.copy()}

    def set_state(self, state: Any) -> None:
        self.u, self.temp_k = dict(state["u"]), state["temp_k"].copy()


def run_partitioned(
    coolant: Any,
    slab: Slab,
    top_temp_k: float,
    initial_temp_k: float,
    step_s: float,
    stop_s: float,
    dt_s: float,
    *,
    fluid_temperature: bool = False,
) -> dict[str, np.ndarray]:
    """The staggered co-simulation of the slab: :class:`PlateSlabParticipant` (sub-steps of
    ``dt_s`` [s]) and ``coolant`` (a :class:`~hevsim.cosim.coolant_cht.CoolantCHTParticipant`
    on the slab's coolant model) through the master, Gauss-Seidel plate then coolant, exchange
    every ``step_s`` [s] to ``stop_s`` [s]; the exchange is the module case's (flux and film),
    or with ``fluid_temperature`` a film to the coolant's fluid temperature. Returns time [s],
    wall heat [W] and outlet temperature [K] at each exchange."""
    from hevsim.cosim.master import Connection, Master, Options

    plate = PlateSlabParticipant("plate", slab, top_temp_k, initial_temp_k, dt_s)
    kinds = ("heat_flux_w_m2", "film_w_m2k") + (("fluid_temp_k",) if fluid_temperature else ())
    conns = []
    for j in range(plate.n_segments):
        conns += [
            Connection("plate", f"wall{j}_{q}", coolant.name, f"wall{j}_{q}") for q in ("temp_k", "area_m2")
        ]
        conns += [Connection(coolant.name, f"wall{j}_{q}", "plate", f"wall{j}_{q}") for q in kinds]
    opts = Options(stop_time_s=stop_s, step_s=step_s, algorithm="gauss-seidel", order=["plate", coolant.name])
    res = Master([plate, coolant], conns, opts).run()
    t = np.asarray(res.time_s)
    keep = t > 0.0
    return {
        "time_s": t[keep],
        "heat_w": np.asarray(res[f"{coolant.name}.cooling_power_w"])[keep],
        "outlet_temp_k": np.asarray(res[f"{coolant.name}.outlet_temp_k"])[keep],
    }

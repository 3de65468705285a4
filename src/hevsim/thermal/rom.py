"""Thermal reduced-order model (ROM) of a module, projected from the 3D FEM.

The FEM of :mod:`hevsim.thermal.solver` is the linear time-invariant system

    C dT/dt + (K_s + h M_w) T = B_q q + h W T_f + b_a T_amb + f_0

with ``C`` the (lumped) heat capacity, ``K_s`` conduction + contact + external films,
``M_w`` the channel-wall film matrix for h = 1 W/(m^2 K), ``W`` (N x n_seg) the integral of the
shape functions over each wall segment, ``B_q`` the per-cell heat distribution, ``b_a`` the
ambient film load per kelvin and ``f_0`` what the fixed ``[[boundary]]`` films and fluxes add.
The inputs are the per-cell heat ``q`` [W], the fluid temperature per channel segment ``T_f``
[K] and the ambient temperature ``T_amb`` [K]; the wall film ``h`` [W/(m^2 K)] (one value for the
whole wall, set by the coolant flow) is a parameter.

**Projection.** ``T ~ V z`` with a basis ``V`` orthonormal in the ``C`` inner product
(``V^T C V = I``) and a Galerkin projection: ``dz/dt + (K_s,r + h M_w,r) z = B_r(h) u``. The
reduced matrix is symmetric positive definite for every ``h >= 0``, so the ROM is stable, and
the constant field is in ``span V`` so the ROM conserves energy exactly (heat in = heat
stored + heat to the coolant + heat to the ambient, for the reconstructed field). ``V`` is a
rational block Krylov basis: the columns ``(s C + K(h))^-1 B(h)`` at ``s = 0`` for the lowest
and highest wall film (so steady states are exact: moment matching at ``s = 0``) and then,
greedily, at the test point ``(s, h)`` where the estimated output error is largest. The error
estimate compares the full and reduced transfer functions of the temperature outputs at all test
points (``s`` from 0 to ``2/dt``, the range the implicit-Euler step sees, for the two wall
films), each input at its design amplitude (``heat_scale_w`` per cell,
``temp_scale_k`` per fluid segment and for the ambient) and summed in absolute value over the
inputs (a worst case over in-phase inputs); the order is the smallest one whose estimate is
below ``tol_k``. Then ``V`` and the reduced matrices are stored; the field ``V z`` is
reconstructed on demand.

The order is the smallest whose estimate is below ``estimate_margin`` (0.6) x ``tol_k``: the
test points are real, and loads that oscillate or move the hot spot between them err up to
about 1.5 times the estimate (:func:`validation_loads`), so the margin keeps them within
``tol_k``.

**Outputs.** Per-cell mean temperature (nodal-volume weighted, as ``hevsim thermal``), per-cell
hot spot = the maximum of the reconstructed field over every node of the cell (its rows are
outputs of the error estimate, so :attr:`ThermalRom.hot_spot_error_k` is the hot spot's error
estimate; ``candidates`` > 0 instead takes only the hottest nodes of the cell in the full
model's design steady state and responses, which misses a hot spot that moves inside the cell),
mean wall temperature and wall heat per segment, heat to the ambient, and the stored heat
``sum C T``.

**Time discretisation.** The ROM is stepped with implicit Euler, as the FEM (theta = 1):
``(I/dt + A_r) z_1 = z_0/dt + B_r u_1``; this is the Galerkin projection of the FEM's
implicit-Euler step, so ROM and FEM differ only by the projection.

Stored as ``.npz`` with the hash of the mesh (:func:`mesh_hash`) and the model's provenance.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import ConfigError, InputError

#: format tag of the stored ROM
ROM_FORMAT = "hevsim-thermal-rom-1"
#: default tolerance of the error estimate on every temperature output [K]
ROM_TOL_K = 0.05
#: default design amplitude of the per-cell heat [W] (the estimate's input scale)
ROM_HEAT_SCALE_W = 5.0
#: default design amplitude of the fluid and ambient temperatures [K]
ROM_TEMP_SCALE_K = 20.0
#: design amplitude of the linear fluid-temperature variation along the channel [K] (the
#: quadratic one gets half)
ROM_GRADIENT_SCALE_K = 5.0
#: lowest wall film of the parameter range, as a fraction of the configured one [-]
ROM_LOW_FILM_FRACTION = 0.05
#: candidate hot-spot nodes per cell taken from each field [-]; 0: every node of the cell (the
#: hot spot of the reconstructed field, covered by the error estimate)
ROM_CANDIDATES = 0
#: the build drives its error estimate below this fraction of ``tol_k`` [-]: the estimate compares
#: transfer functions at real test points, and oscillating or moving loads between them err up
#: to about 1.5 times it (the validation loads of :func:`validation_loads`, docs/rom.md)
ROM_ESTIMATE_MARGIN = 0.6
#: lowest positive test point of the error estimate [1/dt] (slower modes are matched by s = 0)
ROM_S_MIN = 1e-4
#: largest order the greedy build may reach
ROM_MAX_ORDER = 400
#: relative deflation tolerance of the block orthonormalisation
_DEFLATION = 1e-9


def mesh_hash(mesh: Any) -> str:
    """SHA-256 of a :class:`~hevsim.thermal.mesh.ThermalMesh` (nodes, tetrahedra, parts,
    cells, named surfaces, channel path): a ROM is valid for this mesh only."""
    h = hashlib.sha256()
    for arr in (mesh.points_m, mesh.tets, mesh.part_of_tet, mesh.cell_of_tet):
        a = np.ascontiguousarray(arr)
        h.update(str(a.dtype).encode() + str(a.shape).encode())
        h.update(a.tobytes())
    h.update(json.dumps(list(mesh.part_names)).encode())
    for name in sorted(mesh.facet_groups):
        h.update(name.encode())
        h.update(np.ascontiguousarray(np.sort(mesh.facet_groups[name], axis=1)).astype(np.int64).tobytes())
    if mesh.channel_path_m is not None:
        h.update(np.ascontiguousarray(mesh.channel_path_m).tobytes())
    return h.hexdigest()


@dataclass(frozen=True)
class FullModel:
    """The full FEM operators a ROM is projected from (SI units; see the module docstring)."""

    capacity: Any  # (N, N) sparse [J/K]
    k_solid: Any  # (N, N) sparse [W/K]
    m_wall: Any  # (N, N) sparse, wall film matrix for h = 1 [m^2]
    b_heat: Any  # (N, n_cells) sparse [-]
    w_wall: Any  # (N, n_seg) sparse [m^2]
    b_amb: np.ndarray  # (N,) [W/K]
    f_const: np.ndarray  # (N,) [W]
    wall_area_m2: np.ndarray  # (n_seg,)
    node_vol: np.ndarray  # (N,)
    cell_nodes: list[np.ndarray]
    wall_h_w_m2k: float  # configured wall film
    ambient_k: float
    initial_k: float
    fluid_k: float  # configured inlet temperature
    design_heat_w: np.ndarray  # (n_cells,)
    dt_s: float

    @property
    def n_nodes(self) -> int:
        return int(self.capacity.shape[0])

    def stiffness(self, h: float) -> Any:
        return (self.k_solid + h * self.m_wall).tocsc()

    def inputs(self, h: float) -> Any:
        """``B(h)`` (N, n_cells + n_seg + 2): heat, fluid per segment, ambient, constant load."""
        import scipy.sparse as sp

        return sp.hstack(
            [
                self.b_heat,
                h * self.w_wall,
                sp.csr_matrix(self.b_amb[:, None]),
                sp.csr_matrix(self.f_const[:, None]),
            ]
        ).tocsc()


def full_model(cfg: Any, mesh: Any) -> tuple[FullModel, Any, Any]:
    """The FEM operators of a module case (``hevsim.thermal.run.module_model`` with its
    configured coolant film); returns ``(full, disc, channel)``."""
    from hevsim.thermal.run import KELVIN, module_model
    from hevsim.thermal.solver import cell_nodes

    sim = cfg.simulation
    if sim.stiffness != "galerkin" or sim.theta != 1.0:
        raise ConfigError(
            f'{cfg.name}: a ROM needs simulation.stiffness = "galerkin" and theta = 1 (implicit Euler); '
            f"got stiffness = {sim.stiffness!r}, theta = {sim.theta:g}."
        )
    disc, channel, model = module_model(cfg, mesh)
    h = np.asarray(channel.heat_transfer_coefficient_w_m2k(), dtype=float)
    if h.size == 0 or not np.allclose(h, h[0]):
        raise ConfigError(f"{cfg.name}: a ROM needs one wall film for the whole channel; got {h.tolist()}.")
    if np.any(model.wall_flux_w_m2):
        raise ConfigError(f"{cfg.name}: a ROM does not take a heat-flux [[boundary]] on INTERFACE.")
    b_amb = disc.film_w_m2k * disc.film_area
    f_const = disc.film_load_w - b_amb * disc.ambient_k
    node_vol, cells = cell_nodes(mesh, disc)
    n_cells = mesh.n_cells
    heat = np.broadcast_to(np.asarray(sim.cell_heat_w, dtype=float), (n_cells,)).copy()
    full = FullModel(
        capacity=model.capacity.tocsr(),
        k_solid=disc.stiffness.tocsr(),
        m_wall=disc.wall_mass.matrix(np.ones(disc.wall_segment.size)).tocsr(),
        b_heat=disc.cell_load.tocsc(),
        w_wall=disc.wall_weights.tocsc(),
        b_amb=np.asarray(b_amb, dtype=float),
        f_const=np.asarray(f_const, dtype=float),
        wall_area_m2=np.asarray(disc.wall_area_m2, dtype=float),
        node_vol=node_vol,
        cell_nodes=cells,
        wall_h_w_m2k=float(h[0]),
        ambient_k=float(disc.ambient_k),
        initial_k=sim.initial_temp_c + KELVIN,
        fluid_k=float(getattr(channel, "inlet_temp_k", cfg.coolant.inlet_temp_c + KELVIN)),
        design_heat_w=heat,
        dt_s=sim.dt_s,
    )
    return full, disc, channel


def _c_orth(c: Any, v: np.ndarray | None, x: np.ndarray, scale: float) -> np.ndarray:
    """Columns of ``x`` made C-orthonormal to ``v`` and among themselves, deflated (columns
    whose remaining C-norm is below ``_DEFLATION * scale`` are dropped)."""
    for _ in range(2):
        if v is not None and v.shape[1]:
            x = x - v @ (v.T @ (c @ x))
    g = x.T @ (c @ x)
    g = 0.5 * (g + g.T)
    lam, u = np.linalg.eigh(g)
    keep = lam > (_DEFLATION * scale) ** 2
    if not np.any(keep):
        return np.zeros((x.shape[0], 0))
    q = x @ (u[:, keep] / np.sqrt(lam[keep]))
    if v is not None and v.shape[1]:  # one more pass for rounding
        q = q - v @ (v.T @ (c @ q))
        g = q.T @ (c @ q)
        lam, u = np.linalg.eigh(0.5 * (g + g.T))
        q = q @ (u / np.sqrt(lam))
    return q


@dataclass
class ThermalRom:
    """A module's thermal ROM (see the module docstring); arrays in SI units."""

    basis: np.ndarray  # (N, r) V, C-orthonormal
    k_solid: np.ndarray  # (r, r)
    k_wall: np.ndarray  # (r, r) per unit h
    b_heat: np.ndarray  # (r, n_cells)
    b_wall: np.ndarray  # (r, n_seg) per unit h
    b_amb: np.ndarray  # (r,)
    b_const: np.ndarray  # (r,)
    out_mean: np.ndarray  # (n_cells, r)
    out_candidates: np.ndarray  # (n_cells * n_cand, r)
    candidate_nodes: np.ndarray  # (n_cells, n_cand)
    out_wall: np.ndarray  # (n_seg, r) W^T V (int T over each segment) [m^2 K per unit z]
    wall_area_m2: np.ndarray  # (n_seg,)
    energy: np.ndarray  # (r,) 1^T C V
    film_row: np.ndarray  # (r,) 1^T K_s V: film heat = film_row z - sum(b_amb) T_amb - sum(f_const)
    b_amb_total: float
    f_const_total: float
    unit_state: np.ndarray  # (r,) coordinates of the constant field 1 K
    wall_h_range_w_m2k: tuple[float, float]
    mesh_hash: str
    metadata: dict[str, Any] = field(default_factory=dict)
    _transposed: dict[str, np.ndarray] = field(default_factory=dict, init=False, repr=False, compare=False)

    def _rows_t(self, name: str) -> np.ndarray:
        """The output rows ``name`` transposed and contiguous (fast products with (m, r) states)."""
        if name not in self._transposed:
            self._transposed[name] = np.ascontiguousarray(getattr(self, name).T)
        return self._transposed[name]

    @property
    def order(self) -> int:
        return int(self.basis.shape[1])

    @property
    def n_cells(self) -> int:
        return int(self.b_heat.shape[1])

    @property
    def hot_spot_error_k(self) -> float:
        """Error estimate of the hot-spot outputs :meth:`cell_max_k` [K] (the build's estimate over
        every node of the cells: inputs at their design amplitudes; NaN for a file without it or
        built with a candidate set, ``BuildOptions.candidates`` > 0)."""
        value = self.metadata.get("hot_spot_error_estimate_k")
        return float("nan") if value is None else float(value)

    @property
    def n_segments(self) -> int:
        return int(self.b_wall.shape[1])

    # -- reduced operators ------------------------------------------------------------------
    def check_wall_h(self, h: float, where: str = "thermal ROM") -> float:
        lo, hi = self.wall_h_range_w_m2k
        if not (np.isfinite(h) and lo * (1 - 1e-9) <= h <= hi * (1 + 1e-9)):
            raise ConfigError(
                f"{where}: wall film {h!r} W/(m^2 K) is outside the range the ROM was built and "
                f"validated for ({lo:.6g} to {hi:.6g} W/(m^2 K)); rebuild it for this coolant flow."
            )
        return float(h)

    def stiffness(self, h: float) -> np.ndarray:
        return self.k_solid + h * self.k_wall

    def inputs(self, h: float) -> np.ndarray:
        """Reduced ``B(h)``: columns heat (n_cells), fluid (n_seg), ambient, constant load."""
        return np.column_stack([self.b_heat, h * self.b_wall, self.b_amb, self.b_const])

    def transfer(self, s: float, h: float) -> np.ndarray:
        """``(s I + A_r)^-1 B_r`` (r, m) at the real Laplace variable ``s`` [1/s]."""
        return np.linalg.solve(s * np.eye(self.order) + self.stiffness(h), self.inputs(h))

    def state_of_uniform(self, temp_k: float) -> np.ndarray:
        """Reduced state of the uniform field ``temp_k`` (exact: the constant is in span V)."""
        return self.unit_state * float(temp_k)

    def field_k(self, z: np.ndarray) -> np.ndarray:
        """Full nodal temperature field [K] of the reduced state ``z`` (r,) or (..., r)."""
        return np.asarray(z) @ self.basis.T

    # -- outputs (z may be (r,) or (n_modules, r)) ----------------------------------------------
    def cell_mean_k(self, z: np.ndarray) -> np.ndarray:
        return np.asarray(z) @ self._rows_t("out_mean")

    def cell_max_k(self, z: np.ndarray) -> np.ndarray:
        y = np.asarray(z) @ self._rows_t("out_candidates")
        return y.reshape(*y.shape[:-1], self.n_cells, -1).max(axis=-1)

    def wall_temp_k(self, z: np.ndarray) -> np.ndarray:
        return (np.asarray(z) @ self._rows_t("out_wall")) / self.wall_area_m2

    def wall_heat_w(self, z: np.ndarray, fluid_k: np.ndarray, h: float) -> np.ndarray:
        """Heat through each wall segment into the coolant [W]."""
        return h * (np.asarray(z) @ self._rows_t("out_wall") - self.wall_area_m2 * np.asarray(fluid_k))

    def ambient_heat_w(self, z: np.ndarray, ambient_k: float | np.ndarray) -> np.ndarray:
        """Heat to the ambient (and the fixed [[boundary]] films) [W]."""
        return np.asarray(z) @ self.film_row - self.b_amb_total * np.asarray(ambient_k) - self.f_const_total

    def stored_j(self, z: np.ndarray) -> np.ndarray:
        """``sum C T`` of the reconstructed field [J] (relative to 0 K)."""
        return np.asarray(z) @ self.energy

    # -- storage -------------------------------------------------------------------------------
    _ARRAYS = (
        "basis", "k_solid", "k_wall", "b_heat", "b_wall", "b_amb", "b_const", "out_mean",
        "out_candidates", "candidate_nodes", "out_wall", "wall_area_m2", "energy", "film_row",
        "unit_state",
    )  # fmt: skip

    def save(self, path: str | Path) -> Path:
        """Write the ROM atomically as ``.npz`` (arrays + JSON header)."""
        from hevsim.io import atomic_file

        header = {
            "format": ROM_FORMAT,
            "mesh_hash": self.mesh_hash,
            "wall_h_range_w_m2k": list(self.wall_h_range_w_m2k),
            "b_amb_total": self.b_amb_total,
            "f_const_total": self.f_const_total,
            "metadata": self.metadata,
        }
        arrays = {k: getattr(self, k) for k in self._ARRAYS}
        with atomic_file(path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, header=np.array(json.dumps(header)), **arrays)
        return Path(path)


def load_rom(
    path: str | Path, *, expected_mesh_hash: str | None = None, where: str | None = None
) -> ThermalRom:
    """Read a ROM written by :meth:`ThermalRom.save`; with ``expected_mesh_hash`` refuse one
    built on another mesh (:class:`~hevsim.errors.ConfigError`)."""
    p = Path(path)
    label = where or str(p)
    if not p.is_file():
        raise InputError(
            f"{label}: ROM file {p} not found; build one with `hevsim rom build CONFIG -o FILE`."
        )
    try:
        with np.load(p, allow_pickle=False) as data:
            header = json.loads(str(data["header"]))
            arrays = {k: np.asarray(data[k]) for k in ThermalRom._ARRAYS}
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(f"{label}: {p} is not a hevsim thermal ROM file ({exc}).") from exc
    fmt = header.get("format") if isinstance(header, dict) else None
    if fmt != ROM_FORMAT:
        raise InputError(f"{label}: {p} has format {fmt!r}; expected {ROM_FORMAT!r}.")
    try:
        rom = ThermalRom(
            **arrays,
            wall_h_range_w_m2k=(
                float(header["wall_h_range_w_m2k"][0]),
                float(header["wall_h_range_w_m2k"][1]),
            ),
            b_amb_total=float(header["b_amb_total"]),
            f_const_total=float(header["f_const_total"]),
            mesh_hash=str(header["mesh_hash"]),
            metadata=dict(header.get("metadata", {})),
        )
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        raise InputError(f"{label}: {p}: the ROM header lacks or mangles {exc}; rebuild the file.") from exc
    r = rom.order
    if rom.k_solid.shape != (r, r) or rom.b_heat.shape[0] != r or rom.out_mean.shape[1] != r:
        raise InputError(f"{label}: {p}: inconsistent ROM arrays (order {r}); rebuild the file.")
    if expected_mesh_hash is not None and rom.mesh_hash != expected_mesh_hash:
        raise ConfigError(
            f"{label}: ROM {p} was built on mesh {rom.mesh_hash[:16]}... "
            f"({rom.metadata.get('config', '?')}); the module's mesh is {expected_mesh_hash[:16]}...; "
            "expected the same geometry and mesh: rebuild it with `hevsim rom build`."
        )
    return rom


@dataclass(frozen=True)
class BuildOptions:
    """ROM build settings (see the module docstring for their use)."""

    tol_k: float = ROM_TOL_K
    heat_scale_w: float = ROM_HEAT_SCALE_W
    temp_scale_k: float = ROM_TEMP_SCALE_K
    gradient_scale_k: float = ROM_GRADIENT_SCALE_K
    low_film_fraction: float = ROM_LOW_FILM_FRACTION
    candidates: int = ROM_CANDIDATES
    test_points: int = 8
    refinements: int = 1
    max_order: int = ROM_MAX_ORDER
    estimate_margin: float = ROM_ESTIMATE_MARGIN


def _candidates(fields: list[np.ndarray], cells: list[np.ndarray], k: int) -> np.ndarray:
    """Per cell, the union of the ``k`` hottest nodes of each field (padded by repetition)."""
    rows = []
    for nodes in cells:
        chosen: list[int] = []
        for f in fields:
            order = nodes[np.argsort(-f[nodes], kind="stable")]
            for i in order[:k]:
                if int(i) not in chosen:
                    chosen.append(int(i))
        rows.append(chosen)
    width = max(len(r) for r in rows)
    return np.array([r + [r[-1]] * (width - len(r)) for r in rows], dtype=np.int64)


def _all_cell_nodes(cells: list[np.ndarray]) -> np.ndarray:
    """Per cell, every node of the cell (padded by repetition): the hot spot of the
    reconstructed field."""
    width = max(len(nodes) for nodes in cells)
    return np.array(
        [[int(i) for i in nodes] + [int(nodes[-1])] * (width - len(nodes)) for nodes in cells], dtype=np.int64
    )


def build_rom(full: FullModel, mesh_digest: str, options: BuildOptions | None = None,
              provenance: dict[str, Any] | None = None) -> ThermalRom:  # fmt: skip
    """Project ``full`` onto a greedy rational block Krylov basis (module docstring)."""
    from scipy.sparse.linalg import splu

    opt = options or BuildOptions()
    t_start = time.perf_counter()
    c = full.capacity
    n_cells, n_seg = full.b_heat.shape[1], full.w_wall.shape[1]
    h_hi = full.wall_h_w_m2k
    h_lo = h_hi * opt.low_film_fraction
    films = (h_hi, h_lo)
    # input directions at their design amplitudes: heat per cell, the fluid temperature along the
    # channel as Legendre modes (uniform, linear, quadratic), ambient, constant load
    x = np.linspace(-1.0, 1.0, n_seg)
    modes = np.column_stack([np.ones(n_seg), x, 1.5 * x**2 - 0.5])[:, : max(1, min(3, n_seg))]
    mode_scale = np.array([opt.temp_scale_k, opt.gradient_scale_k, opt.gradient_scale_k / 2])[
        : modes.shape[1]
    ]
    has_const = bool(np.any(full.f_const))
    n_dir = n_cells + modes.shape[1] + 1 + int(has_const)
    directions = np.zeros((n_cells + n_seg + 2, n_dir))
    directions[:n_cells, :n_cells] = np.eye(n_cells) * opt.heat_scale_w
    directions[n_cells : n_cells + n_seg, n_cells : n_cells + modes.shape[1]] = modes * mode_scale
    directions[n_cells + n_seg, n_cells + modes.shape[1]] = opt.temp_scale_k
    if has_const:
        directions[-1, -1] = 1.0

    def inputs_dir(h: float) -> np.ndarray:
        return np.asarray(full.inputs(h) @ directions)

    # temperature outputs of the error estimate: cell means, candidate nodes, wall means
    import scipy.sparse as sp

    mean_rows = sp.lil_matrix((n_cells, full.n_nodes))
    for i, nodes in enumerate(full.cell_nodes):
        w = full.node_vol[nodes]
        mean_rows[i, nodes] = w / w.sum()
    mean_rows = mean_rows.tocsr()
    wall_rows = (full.w_wall.T.multiply(1.0 / full.wall_area_m2[:, None])).tocsr()

    s_max = 2.0 / full.dt_s
    grid = [0.0, *np.geomspace(ROM_S_MIN / full.dt_s, s_max, opt.test_points).tolist()]
    responses: dict[tuple[float, int], np.ndarray] = {}
    b_dir = {hi_: inputs_dir(h) for hi_, h in enumerate(films)}

    def factor(s: float, hi_: int) -> Any:
        a = (s * c + full.stiffness(films[hi_])).tocsc()
        return splu(a, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})

    def respond(key: tuple[float, int]) -> np.ndarray:
        if key not in responses:
            responses[key] = factor(*key).solve(b_dir[key[1]])
        return responses[key]

    # test points: the grid at the configured film, every other point at the lowest film
    test = [(s, 0) for s in grid] + [(s, 1) for s in grid[::2]]
    for key in test:
        respond(key)
    t_full = time.perf_counter() - t_start

    # hot-spot candidates: the design steady state and the responses to all cells' heat
    x0 = responses[(0.0, 0)]
    design = x0[:, :n_cells] @ (full.design_heat_w / opt.heat_scale_w)
    design = design + x0[:, n_cells] * (full.fluid_k / opt.temp_scale_k)
    design = design + x0[:, n_cells + modes.shape[1]] * (full.ambient_k / opt.temp_scale_k)
    fields = [design] + [responses[(s, 0)][:, :n_cells].sum(axis=1) for s in grid[::3]]
    fields += [-responses[(s, 0)][:, n_cells] for s in (grid[1], grid[len(grid) // 2])]
    # and the transients of the design case (uniform start, design heat and inlet) at every test
    # point and both films: the field at time ~1/s of the step response
    step_in = full.fluid_k - full.initial_k
    for key, x in responses.items():
        if key[0] > 0:
            fields.append(
                x[:, :n_cells] @ (full.design_heat_w / opt.heat_scale_w)
                + x[:, n_cells] * (step_in / opt.temp_scale_k)
            )
    cand = (
        _candidates(fields, full.cell_nodes, opt.candidates)
        if opt.candidates > 0
        else _all_cell_nodes(full.cell_nodes)
    )
    cand_rows = sp.csr_matrix(
        (np.ones(cand.size), (np.arange(cand.size), cand.ravel())), shape=(cand.size, full.n_nodes)
    )
    outputs = sp.vstack([mean_rows, cand_rows, wall_rows]).tocsr()
    y_full: dict[tuple[float, int], np.ndarray] = {}

    cap_scale = float(np.sqrt(c.diagonal().sum()))
    v = _c_orth(c, None, np.ones((full.n_nodes, 1)), 1e-300)
    used: set[tuple[float, int]] = set()
    history: list[dict[str, float]] = []

    def add(x: np.ndarray) -> None:
        nonlocal v
        norms = np.sqrt(np.einsum("ij,ij->j", x, c @ x))
        q = _c_orth(c, v, x, float(norms.max(initial=0.0)) or cap_scale)
        v = np.hstack([v, q])

    for key in ((0.0, 0), (0.0, 1)):
        add(respond(key))
        used.add(key)

    hot_rows = slice(n_cells, n_cells + cand.size)
    hot_err: dict[tuple[float, int], float] = {}

    def errors() -> dict[tuple[float, int], float]:
        ov = outputs @ v
        out: dict[tuple[float, int], float] = {}
        reduced = {hi_: (v.T @ (full.stiffness(h) @ v), v.T @ b_dir[hi_]) for hi_, h in enumerate(films)}
        for key in test:
            if key not in y_full:
                y_full[key] = outputs @ respond(key)
            kr, br = reduced[key[1]]
            yr = ov @ np.linalg.solve(key[0] * np.eye(v.shape[1]) + kr, br)
            per_row = np.abs(y_full[key] - yr).sum(axis=1)
            out[key] = float(per_row.max())
            hot_err[key] = float(per_row[hot_rows].max())
        return out

    moments: dict[tuple[float, int], np.ndarray] = {}
    refinements = 0
    target_k = opt.tol_k * opt.estimate_margin
    while True:
        err = errors()
        worst = max(err, key=lambda key: err[key])
        history.append({"order": int(v.shape[1]), "error_k": err[worst], "test_points": len(test)})
        if v.shape[1] >= opt.max_order:
            break
        if err[worst] <= target_k:
            if refinements >= opt.refinements:
                break
            # converged on the test points: check between them (geometric midpoints)
            refinements += 1
            pos = sorted({s for s, hi_ in test if s > 0 and hi_ == 0})
            test += [(float(np.sqrt(a * b)), 0) for a, b in itertools.pairwise(pos)]
            continue
        if worst not in used:
            add(respond(worst))
            used.add(worst)
        else:  # next moment at that point: (sC + K)^-1 C X
            nxt = factor(*worst).solve(c @ moments.get(worst, responses[worst]))
            moments[worst] = nxt
            add(nxt)
    if err[worst] > target_k:
        raise ConfigError(
            f"thermal ROM: the error estimate {err[worst]:.3g} K is above {opt.estimate_margin:g} x tol_k = "
            f"{target_k:.3g} K at the largest order {opt.max_order}; expected a larger tol_k or max_order."
        )

    kdense = lambda m: np.asarray(v.T @ (m @ v))  # noqa: E731
    ones = np.ones(full.n_nodes)
    k_solid = kdense(full.k_solid)
    k_wall = kdense(full.m_wall)
    unit_state = v.T @ (c @ ones)
    build_s = time.perf_counter() - t_start
    meta = {
        **(provenance or {}),
        "built": datetime.now(UTC).isoformat(timespec="seconds"),
        "method": "Galerkin projection on a greedy rational block Krylov basis (moments at s = 0 for "
        "both wall films, then the test point of largest estimated output error)",
        "order": int(v.shape[1]),
        "nodes": full.n_nodes,
        "error_estimate_k": err[worst],
        "error_history": history,
        "test_points_1_s": sorted({key[0] for key in test}),
        "wall_h_w_m2k": [h_lo, h_hi],
        "options": {k: getattr(opt, k) for k in BuildOptions.__dataclass_fields__},
        "hot_spot": (
            "max over every node of the cell (the reconstructed field)"
            if opt.candidates <= 0
            else "max over candidate nodes per cell: the hottest nodes of the design steady state and "
            "of the full model's responses to cell heat and to the fluid temperature"
        ),
        "candidates_per_cell": int(cand.shape[1]),
        # over every node of the cells; a candidate set has no estimate of the missed nodes
        "hot_spot_error_estimate_k": max(hot_err.values()) if opt.candidates <= 0 else None,
        "time_discretisation": "implicit Euler (as the FEM with theta = 1)",
        "build_s": build_s,
        "full_solves_s": t_full,
        "dt_s": full.dt_s,
        "initial_temp_k": full.initial_k,
        "ambient_k": full.ambient_k,
        "inlet_temp_k": full.fluid_k,
    }
    return ThermalRom(
        basis=v,
        k_solid=0.5 * (k_solid + k_solid.T),
        k_wall=0.5 * (k_wall + k_wall.T),
        b_heat=np.asarray(v.T @ full.b_heat.toarray()),
        b_wall=np.asarray(v.T @ full.w_wall.toarray()),
        b_amb=v.T @ full.b_amb,
        b_const=v.T @ full.f_const,
        out_mean=np.asarray(mean_rows @ v),
        out_candidates=np.asarray(cand_rows @ v),
        candidate_nodes=cand,
        out_wall=np.asarray(full.w_wall.T @ v),
        wall_area_m2=full.wall_area_m2.copy(),
        energy=unit_state.copy(),
        film_row=np.asarray(full.k_solid.T @ ones) @ v,
        b_amb_total=float(full.b_amb.sum()),
        f_const_total=float(full.f_const.sum()),
        unit_state=unit_state,
        wall_h_range_w_m2k=(h_lo, h_hi),
        mesh_hash=mesh_digest,
        metadata=meta,
    )


def build_rom_from_config(
    config: str | Path | Any, options: BuildOptions | None = None
) -> tuple[ThermalRom, Any]:
    """Mesh a module case, assemble its FEM and build its ROM; returns ``(rom, mesh)``."""
    from hevsim import __version__
    from hevsim.schema import to_dict
    from hevsim.thermal.geometry import build_module_mesh
    from hevsim.thermal.run import load_thermal_config

    if isinstance(config, str | Path):
        cfg = load_thermal_config(config)
        src = str(config)
        sha = hashlib.sha256(Path(config).read_bytes()).hexdigest()
    else:
        cfg, src, sha = config, config.name, ""
    t0 = time.perf_counter()
    mesh = build_module_mesh(cfg.geometry, source=f"{cfg.name}: geometry")
    mesh_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    full, _, _ = full_model(cfg, mesh)
    assemble_s = time.perf_counter() - t0
    import dataclasses

    prov = {
        "config": src,
        "config_sha256": sha,
        "hevsim_version": __version__,
        "mesh_s": mesh_s,
        "assemble_s": assemble_s,
        "geometry": to_dict(cfg.geometry) if dataclasses.is_dataclass(cfg.geometry) else {},
        "n_cells": int(mesh.n_cells),
    }
    rom = build_rom(full, mesh_hash(mesh), options, prov)
    return rom, mesh


class RomStepper:
    """Implicit-Euler stepping of one ROM for ``n_modules`` modules at once (states (m, r)).

    ``step(cell_heat_w (m, n_cells), fluid_k (m, n_seg), ambient_k (m,))`` advances ``dt_s``
    with the inputs at the end of the step (as the FEM's implicit Euler). The step is one
    matrix product ``[z, u] @ [A_d; B_d]^T`` (the step matrices cached per wall film ``h``).
    :attr:`z` is a view of the state, overwritten by the next step.
    """

    def __init__(self, rom: ThermalRom, dt_s: float, wall_h_w_m2k: float, initial_temp_k: float | np.ndarray,
                 n_modules: int = 1) -> None:  # fmt: skip
        if not (np.isfinite(dt_s) and dt_s > 0):
            raise ConfigError(f"thermal ROM: dt_s = {dt_s!r}; expected a positive step [s].")
        self.rom = rom
        self.dt_s = float(dt_s)
        r, nc, ns = rom.order, rom.n_cells, rom.n_segments
        t0 = np.broadcast_to(np.asarray(initial_temp_k, dtype=float), (n_modules,))
        self._zu = np.zeros((n_modules, r + nc + ns + 2))  # [z | heat | fluid | ambient | 1]
        self._zu[:, :r] = t0[:, None] * rom.unit_state[None, :]
        self._zu[:, -1] = 1.0
        self._heat = slice(r, r + nc)
        self._fluid = slice(r + nc, r + nc + ns)
        self._cache: dict[float, np.ndarray] = {}
        self.set_wall_h(wall_h_w_m2k)

    @property
    def z(self) -> np.ndarray:
        """Reduced states (n_modules, r) (a view)."""
        return self._zu[:, : self.rom.order]

    @property
    def step_matrix(self) -> np.ndarray:
        """The step matrix ``[A_d; B_d]^T = [inv/dt | inv B(h)]^T`` for the current wall film,
        shape ``(r + n_cells + n_segments + 2, r)``, with ``inv = (I/dt + K(h))^-1``: one step is
        ``z_1 = [z_0, cell heat [W], fluid [K], ambient [K], 1] @ step_matrix`` (a read-only view
        of the cached matrix)."""
        view = self._step_t.view()
        view.flags.writeable = False
        return view

    def set_wall_h(self, h: float) -> None:
        h = self.rom.check_wall_h(float(h))
        self.h = h
        if h not in self._cache:
            r = self.rom.order
            inv = np.linalg.inv(np.eye(r) / self.dt_s + self.rom.stiffness(h))
            self._cache[h] = np.ascontiguousarray(
                np.vstack([(inv / self.dt_s).T, (inv @ self.rom.inputs(h)).T])
            )
        self._step_t = self._cache[h]

    def step(self, cell_heat_w: np.ndarray, fluid_k: np.ndarray, ambient_k: float | np.ndarray) -> np.ndarray:
        zu = self._zu
        zu[:, self._heat] = cell_heat_w
        zu[:, self._fluid] = fluid_k
        zu[:, -2] = ambient_k
        r = self.rom.order
        if zu.shape[0] == 1:
            zu[0, :r] = zu[0] @ self._step_t
        else:
            zu[:, :r] = zu @ self._step_t
        return zu[:, :r]


def write_rom_fields(rom: ThermalRom, config: str | Path | Any, states: list[tuple[float, np.ndarray]],
                     out_dir: str | Path) -> Path:  # fmt: skip
    """Rebuild the module mesh of ``config`` (checked against the ROM's hash) and write the
    full temperature fields ``V z`` [°C] of ``states`` = ``[(time_s, z), ...]`` as VTU files and a
    ParaView collection under ``out_dir`` (atomically); returns the ``.pvd`` path."""
    from hevsim.io import atomic_directory
    from hevsim.thermal.geometry import build_module_mesh
    from hevsim.thermal.run import KELVIN, load_thermal_config, module_model, write_field_series

    cfg = load_thermal_config(config) if isinstance(config, str | Path) else config
    mesh = build_module_mesh(cfg.geometry, source=f"{cfg.name}: geometry")
    digest = mesh_hash(mesh)
    if digest != rom.mesh_hash:
        raise ConfigError(
            f"{cfg.name}: the ROM was built on mesh {rom.mesh_hash[:16]}...; this configuration meshes to "
            f"{digest[:16]}...; expected the same geometry."
        )
    disc, _, _ = module_model(cfg, mesh)
    series = [(t, rom.field_k(z) - KELVIN) for t, z in states]
    with atomic_directory(out_dir) as tmp:
        write_field_series(tmp, disc, mesh, series, prefix="rom_")
    return Path(out_dir) / "rom_temperature.pvd"


__all__ = [
    "BuildOptions",
    "FullModel",
    "RomStepper",
    "ThermalRom",
    "build_rom",
    "build_rom_from_config",
    "compare_with_fem",
    "format_rom",
    "full_model",
    "load_rom",
    "mesh_hash",
    "validation_loads",
    "write_rom_fields",
]


@dataclass
class RomComparison:
    """ROM vs full FEM on one load: per-step per-cell mean and hot-spot temperatures [K]."""

    time_s: np.ndarray
    fem_mean_k: np.ndarray  # (steps + 1, n_cells)
    fem_max_k: np.ndarray
    rom_mean_k: np.ndarray
    rom_max_k: np.ndarray
    fem_wall_heat_w: np.ndarray  # (steps + 1,)
    rom_wall_heat_w: np.ndarray
    fem_step_s: float
    rom_step_s: float
    rom_z: np.ndarray | None = None  # (steps + 1, r) the ROM's reduced states

    @property
    def mean_error_k(self) -> float:
        return float(np.abs(self.rom_mean_k - self.fem_mean_k).max())

    @property
    def max_error_k(self) -> float:
        return float(np.abs(self.rom_max_k - self.fem_max_k).max())


def compare_with_fem(
    cfg: Any, mesh: Any, rom: ThermalRom, heat_w: Any, inlet_k: Any, steps: int
) -> RomComparison:
    """Run the full FEM (``module_model``: implicit Euler, the configured 1-D coolant channel)
    and the ROM (with its own copy of that channel, fed by the ROM's wall temperatures) on the
    same load: ``heat_w(t_s) -> (n_cells,)`` [W] and ``inlet_k(t_s)`` [K] at the end of each step."""
    import copy
    import dataclasses

    from hevsim.thermal.run import KELVIN, module_model
    from hevsim.thermal.solver import cell_nodes

    if rom.mesh_hash != mesh_hash(mesh):
        raise ConfigError(f"{cfg.name}: the ROM was built on another mesh; expected {rom.mesh_hash[:16]}...")
    # the FEM with the ROM's coupling (fluid from the wall at the start of the step), so that the
    # two differ by the projection only
    staggered = dataclasses.replace(cfg.simulation, coupling="staggered", coupling_iterations=1)
    disc, channel, model = module_model(dataclasses.replace(cfg, simulation=staggered), mesh)
    rom_channel = copy.deepcopy(channel)
    node_vol, cells = cell_nodes(mesh, disc)
    h = float(np.asarray(channel.heat_transfer_coefficient_w_m2k())[0])
    stepper = RomStepper(rom, cfg.simulation.dt_s, h, cfg.simulation.initial_temp_c + KELVIN)
    amb = disc.ambient_k

    def fem_obs() -> tuple[np.ndarray, np.ndarray]:
        t = model.temp_k
        return (
            np.array([np.average(t[c], weights=node_vol[c]) for c in cells]),
            np.array([t[c].max() for c in cells]),
        )

    dt = cfg.simulation.dt_s
    times = np.arange(steps + 1) * dt
    rows: dict[str, list[Any]] = {k: [] for k in ("fm", "fx", "rm", "rx", "fw", "rw")}
    states: list[np.ndarray] = []

    def record(wall_fem_w: float, wall_rom_w: float) -> None:
        m, x = fem_obs()
        z = stepper.z[0]
        states.append(z.copy())
        for key, value in zip(
            rows, (m, x, rom.cell_mean_k(z), rom.cell_max_k(z), wall_fem_w, wall_rom_w), strict=True
        ):
            rows[key].append(value)

    record(0.0, 0.0)
    fem_s = rom_s = 0.0
    for k in range(1, steps + 1):
        q = np.asarray(heat_w(times[k]), dtype=float)
        t_in = float(inlet_k(times[k]))
        t0 = time.perf_counter()
        channel.inlet_temp_k = t_in
        model.set_cell_heat_w(q)
        model.step()
        fem_s += time.perf_counter() - t0
        t0 = time.perf_counter()
        rom_channel.inlet_temp_k = t_in
        rom_fluid = rom_channel.fluid_temperature_k(rom.wall_temp_k(stepper.z[0]), rom.wall_area_m2)
        stepper.step(q[None, :], rom_fluid[None, :], amb)
        rom_s += time.perf_counter() - t0
        record(model.report().wall_w, float(rom.wall_heat_w(stepper.z[0], rom_fluid, h).sum()))
    arr = {k: np.array(v) for k, v in rows.items()}
    return RomComparison(
        times, arr["fm"], arr["fx"], arr["rm"], arr["rx"], arr["fw"], arr["rw"],
        fem_s / max(steps, 1), rom_s / max(steps, 1), np.array(states),
    )  # fmt: skip


#: inlet temperature of the validation loads [K] (15 degC, as the build's design case)
_VALIDATION_INLET_K = 288.15


def validation_loads(
    n_cells: int, heat_scale_w: float = ROM_HEAT_SCALE_W, seed: int = 0
) -> dict[str, tuple[Any, Any, int]]:
    """Load families the ROM is not built or tuned with, each ``name -> (heat_w(t_s) (n_cells,)
    [W], inlet_k(t_s) [K], steps)`` for :func:`compare_with_fem` (1 s steps), every per-cell heat
    within +-``heat_scale_w`` (the build's design amplitude) and of both signs, so that the hot
    spot moves inside the cells:

    * ``multisine``: per cell a random multi-sine (6 frequencies from 1/600 to 1/4 Hz, random
      amplitudes and phases, peak ``heat_scale_w``), 600 s;
    * ``checkerboard``: odd and even cells swap +-``heat_scale_w`` every 20 s, 300 s;
    * ``random_steps``: per cell a random level in +-``heat_scale_w`` held 15 s, 600 s;
    * ``travelling``: a heat wave travelling along the cells (period 60 s, one wavelength over
      the module), 300 s;
    * ``inlet_sine``: random constant cell heats in +-``heat_scale_w`` with the coolant inlet
      swinging +-10 K (period 120 s), 600 s;
    * ``chirp``: per cell a sine of amplitude ``heat_scale_w`` whose frequency sweeps from
      1/300 to 1/2 Hz over the run, a random phase per cell (held out: added after the build's
      ``estimate_margin`` was set), 600 s.
    """
    rng = np.random.default_rng(seed)
    q = float(heat_scale_w)
    cells = np.arange(n_cells)
    freqs = np.geomspace(1.0 / 600.0, 1.0 / 4.0, 6)
    amp = rng.uniform(0.0, 1.0, (n_cells, freqs.size))
    amp *= q / amp.sum(axis=1, keepdims=True)
    phase = rng.uniform(0.0, 2.0 * np.pi, (n_cells, freqs.size))
    levels = rng.uniform(-q, q, (41, n_cells))
    fixed = rng.uniform(-q, q, n_cells)
    sign = np.where(cells % 2 == 0, 1.0, -1.0)
    chirp_phase = rng.uniform(0.0, 2.0 * np.pi, n_cells)
    f0, f1, t_end = 1.0 / 300.0, 1.0 / 2.0, 600.0

    def inlet(t: float) -> float:
        return _VALIDATION_INLET_K

    return {
        "multisine": (lambda t: (amp * np.sin(2.0 * np.pi * freqs * t + phase)).sum(axis=1), inlet, 600),
        "checkerboard": (lambda t: q * sign * (1.0 if (t // 20.0) % 2 == 0 else -1.0), inlet, 300),
        "random_steps": (lambda t: levels[min(int(t // 15.0), len(levels) - 1)], inlet, 600),
        "travelling": (lambda t: q * np.sin(2.0 * np.pi * (t / 60.0 - cells / n_cells)), inlet, 300),
        "inlet_sine": (
            lambda t: fixed,
            lambda t: _VALIDATION_INLET_K + 10.0 * np.sin(2.0 * np.pi * t / 120.0),
            600,
        ),
        "chirp": (
            lambda t: q * np.sin(2.0 * np.pi * (f0 * t + 0.5 * (f1 - f0) * t * t / t_end) + chirp_phase),
            inlet,
            600,
        ),
    }


def format_rom(rom: ThermalRom) -> str:
    """A few lines for the terminal: order, error estimate, timings and provenance."""
    m = rom.metadata
    lo, hi = rom.wall_h_range_w_m2k

    def nan(key: str) -> float:
        return float(m.get(key, float("nan")))

    lines = [
        f"thermal ROM of {m.get('config', '?')}: order {rom.order} from {m.get('nodes', '?')} FEM nodes, "
        f"{rom.n_cells} cells, {rom.n_segments} wall segments",
        f"  error estimate {m.get('error_estimate_k', float('nan')):.4f} K (tolerance "
        f"{m.get('options', {}).get('tol_k', float('nan')):g} K) on cell means, hot-spot candidates and wall "
        "temperatures",
        f"  wall film range {lo:.1f} to {hi:.1f} W/(m^2 K); hot spot = max over "
        f"{m.get('candidates_per_cell', '?')} "
        + (
            "nodes (every node of the cell)"
            if m.get("options", {}).get("candidates", 1) <= 0
            else "candidate nodes"
        )
        + f" per cell, error estimate {rom.hot_spot_error_k:.4f} K",
        f"  build {nan('build_s'):.1f} s (full solves {nan('full_solves_s'):.1f} s) after meshing "
        f"{nan('mesh_s'):.1f} s and assembly {nan('assemble_s'):.1f} s",
        f"  mesh sha256 {rom.mesh_hash}",
    ]
    return "\n".join(lines)

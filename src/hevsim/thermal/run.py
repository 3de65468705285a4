"""One call for a module case: configuration -> mesh -> coupled transient -> results folder.

``run_thermal(config_path, out_dir)`` is what ``hevsim thermal CONFIG --out DIR`` runs.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import ConfigError, SimulationError
from hevsim.schema import build_config, check_value, read_toml, to_dict
from hevsim.thermal.geometry import PART_ORDER, ModuleGeometry
from hevsim.thermal.materials import (
    DEFAULT_PART_MATERIALS,
    FILM_COEFFICIENT_W_M2K,
    GAP_CONDUCTANCE_W_M2K,
    TABLE_4_3,
    Material,
)
from hevsim.thermal.solver import CAPACITY_KINDS, COUPLING_KINDS
from hevsim.thermal.solver import cell_nodes as cell_node_sets
from hevsim.units import KELVIN_OFFSET

KELVIN = KELVIN_OFFSET  # [K] at 0 degC
LITRE_PER_MIN_M3_S = 1.0 / 60000.0


@dataclass(frozen=True)
class SimulationSection:
    """Transient run: duration and step [s], theta, temperatures [°C], films [W/(m^2 K)], heat [W]."""

    duration_s: float = 300.0
    dt_s: float = 1.0
    theta: float = 1.0
    initial_temp_c: float = 30.0
    ambient_temp_c: float = 30.0
    film_w_m2k: float = FILM_COEFFICIENT_W_M2K
    gap_conductance_w_m2k: float = GAP_CONDUCTANCE_W_M2K
    cell_heat_w: tuple[float, ...] = (1.0,)
    coupling_iterations: int = 1
    coupling: str = "implicit"  # or "staggered" (see hevsim.thermal.solver.HeatModel)
    capacity: str = "lumped"  # or "consistent" (see hevsim.thermal.solver.HeatModel)
    stiffness: str = "galerkin"  # or "afc": algebraic flux correction (AFCHeatModel)


@dataclass(frozen=True)
class CoolantSection:
    """Coolant: inlet [°C], flow [L/min], channel segments, properties (Table 4.4 defaults).

    ``properties = "meg50_table"`` replaces the four constants by the temperature-dependent
    MEG 50 table (:data:`hevsim.thermal.coolant.MEG50_TABLE`) evaluated at the inlet temperature.
    """

    properties: str = "table_4_4"
    inlet_temp_c: float = 15.0
    flow_l_min: float = 10.0
    segments: int = 30
    conductivity_w_mk: float = 0.43
    density_kg_m3: float = 1056.0
    viscosity_pa_s: float = 0.0085
    specific_heat_j_kgk: float = 3300.0


@dataclass(frozen=True)
class OutputSection:
    """What to write: field snapshots every ``field_every_s`` [s], hot spots, pictures (0/1)."""

    field_every_s: float = 60.0
    hot_spots: int = 10
    pictures: int = 1


#: ``[simulation] stiffness``: the Galerkin matrices, or "afc": algebraic flux correction
#: (:class:`AFCHeatModel`), which keeps the discrete maximum principle.
STIFFNESS_KINDS = ("galerkin", "afc")
#: Overshoot above which the summary suggests ``stiffness = "afc"`` or a better mesh [K].
OVERSHOOT_WARN_K = 0.05
#: the summary warns when the estimated capacity (mass-lumping) error of the removed heat is above
#: this fraction of it [-] or that of a temperature above CAPACITY_WARN_K [K]
CAPACITY_WARN_FRACTION = 0.01
CAPACITY_WARN_K = 0.5
#: A source-free node counts as above its physical bound beyond this margin [K] (rounding).
OVERSHOOT_TOL_K = 1e-7


def dmp_diffusion(k: Any) -> Any:
    """Symmetric artificial diffusion ``D`` that removes the positive off-diagonal couplings of
    ``k`` [W/K] (obtuse tetrahedra, consistent contact and film surface matrices):
    ``D = sum over pairs max(0, k_ij) (e_i - e_j)(e_i - e_j)^T``. ``k + D`` has non-positive
    off-diagonal entries and the same row sums (no heat is created: the energy balance is
    unchanged) and stays symmetric positive definite; with the lumped capacity and implicit
    Euler its solution obeys the discrete maximum principle. This is the low-order operator of
    algebraic flux correction for diffusion (D. Kuzmin, M. J. Shashkov, D. Svyatskiy, J. Comput.
    Phys. 228 (2009) 3448-3463); alone it is far too diffusive on an unstructured mesh (42 % more
    heat to the coolant in 20 s on the example mesh), so :class:`AFCHeatModel` adds back the
    limited antidiffusion."""
    import scipy.sparse as sp

    ks = sp.coo_matrix((k + k.T) * 0.5)
    off = (ks.row != ks.col) & (ks.data > 0.0)
    r, c, v = ks.row[off], ks.col[off], ks.data[off]
    n = k.shape[0]
    return sp.csr_matrix(
        (np.concatenate([-v, v]), (np.concatenate([r, r]), np.concatenate([c, r]))), shape=(n, n)
    )


class AFCHeatModel:
    """Implicit-Euler heat model with algebraic flux correction (``[simulation] stiffness =
    "afc"``): the low-order operator ``L = K + D`` (:func:`dmp_diffusion`) is factorised once and
    the antidiffusive fluxes ``f_ij = d_ij (T_i - T_j)`` (``D T`` = their sum) are added back,
    each limited by Zalesak's limiter so that no node leaves the range of its neighbours and its
    previous value (Kuzmin, Shashkov, Svyatskiy 2009). The nonlinear step is solved by defect
    correction with the same factorisation, the limited fluxes under-relaxed by ``relaxation``
    (at most ``max_iterations``, to ``tol_k``; about 100 solves a step). Where the
    limiter does not act the result is the Galerkin one; the fluxes are antisymmetric, so no
    heat is created. Wraps a :class:`~hevsim.thermal.solver.HeatModel` built on ``L``."""

    def __init__(
        self,
        model: Any,
        diffusion: Any,
        *,
        max_iterations: int = 1000,
        tol_k: float = 1e-8,
        relaxation: float = 0.5,
    ) -> None:
        import scipy.sparse as sp

        lumped = sp.issparse(model.capacity) and model.capacity.nnz == model.capacity.shape[0]
        if model.theta != 1.0 or not lumped:
            raise ConfigError(
                'heat model: stiffness = "afc" needs theta = 1 and capacity = "lumped"; '
                f"got theta = {model.theta} and {'a lumped' if lumped else 'a consistent'} capacity."
            )
        self.model = model
        upper = sp.triu(diffusion, k=1).tocoo()
        self.i, self.j, self.d = upper.row, upper.col, -upper.data  # d_ij > 0
        low = model.k.tocsr()
        self.indices, self.starts = low.indices, low.indptr[:-1]
        off = np.abs(low - sp.diags(low.diagonal())).sum(axis=1)
        self.q = model.capacity.diagonal() / model.dt_s + np.asarray(off).ravel()
        self.film_sum = np.asarray(low.sum(axis=1)).ravel()  # conduction and contact rows sum to 0
        self.film = self.film_sum > 1e-9 * np.abs(low.diagonal())
        self.max_iterations = max_iterations
        self.tol_k = tol_k
        self.relaxation = relaxation
        self.iterations = 0  # most defect-correction iterations of a step so far

    def __getattr__(self, name: str) -> Any:
        return getattr(self.model, name)

    def _film_temp_k(self) -> np.ndarray:
        """The temperature every film node is drawn to (the film-weighted fluid / ambient / set
        temperature; NaN where there is no film): a film node may legitimately go there."""
        m = self.model
        d = m.disc
        f = d.film_load_w.copy()
        if m.coolant is not None:
            f += np.asarray(d.wall_weights[:, : m.fluid_k.size] @ (m.wall_h * m.fluid_k)).ravel()
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.film, f / np.where(self.film, self.film_sum, 1.0), np.nan)

    def _limited(self, u: np.ndarray, u_old: np.ndarray, film_k: np.ndarray) -> np.ndarray:
        n = u.size
        near = u[self.indices]
        umax = np.fmax(np.maximum(np.maximum.reduceat(near, self.starts), u_old), film_k)
        umin = np.fmin(np.minimum(np.minimum.reduceat(near, self.starts), u_old), film_k)
        f = self.d * (u[self.i] - u[self.j])  # into i, out of j
        fp, fm = np.maximum(f, 0.0), np.minimum(f, 0.0)
        p_plus = np.bincount(self.i, fp, n) - np.bincount(self.j, fm, n)
        p_minus = np.bincount(self.i, fm, n) - np.bincount(self.j, fp, n)
        q_plus, q_minus = self.q * (umax - u), self.q * (umin - u)
        r_plus = np.where(p_plus > 0.0, np.minimum(1.0, q_plus / np.where(p_plus > 0.0, p_plus, 1.0)), 1.0)
        r_minus = np.where(
            p_minus < 0.0, np.minimum(1.0, q_minus / np.where(p_minus < 0.0, p_minus, -1.0)), 1.0
        )
        alpha = np.where(
            f > 0.0, np.minimum(r_plus[self.i], r_minus[self.j]), np.minimum(r_minus[self.i], r_plus[self.j])
        )
        g = alpha * f
        return np.bincount(self.i, g, n) - np.bincount(self.j, g, n)

    def step(self) -> np.ndarray:
        """Advance one step of ``dt_s``; returns the new nodal temperatures [K]."""
        m = self.model
        old = m.temp_k
        base = m._rhs_matrix @ old
        new = old
        for _ in range(m.coupling_iterations):
            if m.coolant is not None:
                m.fluid_k = m.coolant.fluid_temperature_k(m.wall_temp_k(new), m.disc.wall_area_m2)
            rhs = base + m._load()
            film_k = self._film_temp_k()
            new = m._lu.solve(rhs)  # low-order solution
            flux = np.zeros_like(new)
            change, used = np.inf, 0
            while used < self.max_iterations:
                used += 1
                # under-relaxed: the plain fixed point oscillates (0.2 K on the example mesh)
                flux = (1.0 - self.relaxation) * flux + self.relaxation * self._limited(new, old, film_k)
                nxt = m._lu.solve(rhs + flux)
                change = float(np.abs(nxt - new).max())
                new = nxt
                if change <= self.tol_k:
                    break
            if change > self.tol_k:
                raise SimulationError(
                    f"heat model: the flux-corrected step at t = {m.time_s + m.dt_s} s did not converge in "
                    f"{self.max_iterations} iterations (last change {change:.2e} K); expected <= "
                    f'{self.tol_k:g} K: use stiffness = "galerkin" or a smaller dt_s.'
                )
            self.iterations = max(self.iterations, used)
        if not np.all(np.isfinite(new)):
            raise SimulationError(f"heat model: temperature became non-finite at t = {m.time_s + m.dt_s} s.")
        m.temp_k = new
        m._f_old = rhs - base
        m.time_s += m.dt_s
        return new


class CapacityEstimate:
    """First-order estimate of the capacity discretisation error of a run: how much the field and
    the removed heat would change with the other capacity matrix (consistent for a lumped run,
    lumped for a consistent one).

    With ``C`` the run's capacity and ``C'`` the other, ``T' = T + d`` solves
    ``C' dT'/dt + K T' = f``, so ``C d'/dt + K d = -(C' - C) dT/dt`` to first order in ``d``; it is
    stepped with the run's own factorised step (one more back-substitution per step, the fluid
    held): ``d_1 = LU^-1 (R d_0 - (C' - C)(T_1 - T_0) / dt)``. ``max_k`` is the largest ``|d|``
    over nodes and steps, ``removed_j`` the change of the heat through the channel wall,
    ``sum dt h (W^T d)``. Lumped and consistent forms differ by O(h^2) in space, so both shrink
    with the mesh size."""

    def __init__(self, model: Any, disc: Any) -> None:
        import scipy.sparse as sp

        lumped = sp.diags(np.asarray(disc.capacity.sum(axis=1)).ravel()).tocsr()
        own_is_lumped = model.capacity.nnz == model.capacity.shape[0]
        other = disc.capacity if own_is_lumped else lumped
        self.other = "consistent" if own_is_lumped else "lumped"
        self.model = model
        self.diff = (other - model.capacity).tocsr()
        self.delta = np.zeros(model.capacity.shape[0])
        self.max_k = 0.0
        self.removed_j = 0.0

    def update(self, old_k: np.ndarray, new_k: np.ndarray) -> None:
        m = self.model
        r = self.diff @ (new_k - old_k) / m.dt_s
        self.delta = np.asarray(m._lu.solve(m._rhs_matrix @ self.delta - r))
        self.max_k = max(self.max_k, float(np.abs(self.delta).max()))
        n = m.wall_h.size
        wall = np.asarray(m.disc.wall_weights.T @ self.delta)[:n]
        self.removed_j += m.dt_s * float(np.sum(m.wall_h * wall))


class OvershootMonitor:
    """Nodes above their physical bound: a node without heat source (no cell heat, no heat
    flux) cannot get hotter than its own previous temperature, every node it is coupled to
    and, when it has a film, the hottest fluid / ambient / set temperature (the parabolic
    maximum principle). Updated after every step from the coupling pattern of the matrix."""

    def __init__(self, k: Any, source_free: np.ndarray) -> None:
        k = k.tocsr()
        rows = np.repeat(np.arange(k.shape[0]), np.diff(k.indptr))
        self.indices = k.indices
        self.starts = k.indptr[:-1]
        self.off = k.indices != rows
        row_sum = np.asarray(k.sum(axis=1)).ravel()
        self.film = row_sum > 1e-9 * np.abs(k.diagonal())
        self.source_free = source_free
        self.max_k = 0.0
        self.nodes = 0
        self.ever = np.zeros(k.shape[0], dtype=bool)

    def update(self, old_k: np.ndarray, new_k: np.ndarray, hottest_fluid_k: float) -> None:
        vals = np.where(self.off, new_k[self.indices], -np.inf)
        bound = np.maximum(np.maximum.reduceat(vals, self.starts), old_k)
        bound = np.where(self.film, np.maximum(bound, hottest_fluid_k), bound)
        excess = np.where(self.source_free, new_k - bound, 0.0)
        flagged = excess > OVERSHOOT_TOL_K
        self.max_k = max(self.max_k, float(excess.max(initial=0.0)))
        self.nodes = max(self.nodes, int(flagged.sum()))
        self.ever |= flagged


#: Kinds of ``[[boundary]]`` condition and the values each one takes.
BOUNDARY_KINDS: dict[str, tuple[str, ...]] = {
    "film": ("film_w_m2k", "temp_c"),
    "temperature": ("temp_c",),
    "heat_flux": ("heat_flux_w_m2",),
}
#: Surfaces of the module geometry a ``[[boundary]]`` can name: the channel wall (replaces the
#: 1-D coolant) and the external surfaces (replaces the ambient film).
BOUNDARY_SURFACES = ("INTERFACE", "EXTERNAL")
_BOUNDARY_BOUNDS = {"film_w_m2k": (0.0, 1e9), "temp_c": (-200.0, 2000.0), "heat_flux_w_m2": (-1e9, 1e9)}
#: A fixed temperature is held by a stiff film of Biot number ``h * mesh_size / k_max`` = this
#: value: on the example wall 15 K below the module the surface stays within 2e-5 K of the set
#: value (1.4e-6 of the difference) and the energy balance still closes to 1e-9 (a stiffer film
#: amplifies the linear solver's rounding: 1e6 gives 2e-7 K but an 8e-8 balance).
FIXED_TEMPERATURE_BIOT = 1e4


@dataclass(frozen=True)
class BoundaryCondition:
    """A fixed condition on a named surface: ``film`` (h [W/(m^2 K)] towards ``temp_c`` [°C]),
    ``temperature`` (``temp_c``) or ``heat_flux`` (``heat_flux_w_m2`` [W/m^2] into the solid)."""

    surface: str
    kind: str
    film_w_m2k: float = 0.0
    temp_c: float = 0.0
    heat_flux_w_m2: float = 0.0


def boundary_conditions(raw: Any, source: str) -> tuple[BoundaryCondition, ...]:
    """Validate ``[[boundary]]`` tables (``surface``, ``kind`` and that kind's values)."""
    if not isinstance(raw, list) or not all(isinstance(b, dict) for b in raw):
        raise ConfigError(
            f"{source}: [[boundary]]: expected an array of tables with surface, kind and values; got {raw!r}."
        )
    out: list[BoundaryCondition] = []
    for i, spec in enumerate(raw, start=1):
        where = f"boundary[{i}]"
        surface = spec.get("surface")
        if surface not in BOUNDARY_SURFACES:
            raise ConfigError(
                f"{source}: key '{where}.surface' = {surface!r}; expected one of "
                f"{', '.join(BOUNDARY_SURFACES)}."
            )
        kind = spec.get("kind")
        if kind not in BOUNDARY_KINDS:
            raise ConfigError(
                f"{source}: key '{where}.kind' = {kind!r}; expected one of {', '.join(BOUNDARY_KINDS)}."
            )
        need = BOUNDARY_KINDS[kind]
        for key in spec:
            if key not in ("surface", "kind", *need):
                raise ConfigError(
                    f"{source}: key '{where}.{key}' is not known for kind '{kind}'; valid keys are: "
                    f"surface, kind, {', '.join(need)}."
                )
        missing = [k for k in need if k not in spec]
        if missing:
            raise ConfigError(
                f"{source}: [[boundary]] {i} ({surface}, {kind}) has no {', '.join(missing)}; "
                f"expected {', '.join(need)}."
            )
        values = {
            k: check_value(spec[k], float, source, f"{where}.{k}", {}, {f"{where}.{k}": _BOUNDARY_BOUNDS[k]})
            for k in need
        }
        if any(b.surface == surface for b in out):
            raise ConfigError(
                f"{source}: key '{where}.surface': '{surface}' has a second [[boundary]]; expected one."
            )
        out.append(BoundaryCondition(surface, kind, **values))
    return tuple(out)


def boundary_from_option(text: str) -> dict[str, Any]:
    """``SURFACE:KIND:key=value,key=value`` (the ``--boundary`` option) as a [[boundary]] table."""
    parts = text.split(":")
    if len(parts) != 3:
        raise ConfigError(
            f"--boundary {text!r}: expected SURFACE:KIND:key=value[,key=value], e.g. "
            "INTERFACE:film:film_w_m2k=4600,temp_c=15."
        )
    table: dict[str, Any] = {"surface": parts[0], "kind": parts[1]}
    for item in filter(None, parts[2].split(",")):
        key, eq, value = item.partition("=")
        try:
            table[key.strip()] = float(value)
        except ValueError:
            raise ConfigError(f"--boundary {text!r}: '{item}' is not key=number.") from None
        if not eq:
            raise ConfigError(f"--boundary {text!r}: '{item}' is not key=number.")
    return table


@dataclass(frozen=True)
class ThermalConfig:
    """A validated module thermal case (see ``examples/module_thermal.toml``)."""

    name: str = "module_thermal"
    base_dir: str = "."
    geometry: ModuleGeometry = field(default_factory=ModuleGeometry)
    simulation: SimulationSection = field(default_factory=SimulationSection)
    coolant: CoolantSection = field(default_factory=CoolantSection)
    output: OutputSection = field(default_factory=OutputSection)
    materials: dict[str, Material] = field(default_factory=dict)
    contact: dict[str, float] = field(default_factory=dict)
    boundary: tuple[BoundaryCondition, ...] = ()


_BOUNDS: dict[str, tuple[float, float]] = {
    "simulation.duration_s": (0.0, 1e7),
    "simulation.dt_s": (1e-6, 1e5),
    "simulation.theta": (0.5, 1.0),
    "simulation.initial_temp_c": (-60.0, 300.0),
    "simulation.ambient_temp_c": (-60.0, 300.0),
    "simulation.film_w_m2k": (0.0, 1e6),
    "simulation.gap_conductance_w_m2k": (1e-9, 1e9),
    "simulation.cell_heat_w": (-1e4, 1e4),
    "simulation.coupling_iterations": (1, 20),
    "coolant.inlet_temp_c": (-40.0, 150.0),
    "coolant.flow_l_min": (1e-6, 1e4),
    "coolant.segments": (1, 10000),
    "coolant.conductivity_w_mk": (1e-6, 1e3),
    "coolant.density_kg_m3": (1e-3, 1e5),
    "coolant.viscosity_pa_s": (1e-9, 1e3),
    "coolant.specific_heat_j_kgk": (1.0, 1e6),
    "output.field_every_s": (0.0, 1e9),
    "output.hot_spots": (0, 1000),
    "output.pictures": (0, 1),
    "geometry.rows": (1, 20),
    "geometry.columns": (1, 40),
    "geometry.channel_passes": (1, 40),
    "geometry.mesh_size_m": (2e-4, 0.1),
    "geometry.curvature_elements": (6, 360),
    **{
        f"geometry.{f.name}": (1e-5, 2.0)
        for f in dataclasses.fields(ModuleGeometry)
        if f.name.endswith("_m") and f.name != "mesh_size_m"
    },
}
_MATERIAL_KEYS = ("material", "conductivity_w_mk", "density_kg_m3", "specific_heat_j_kgk")


def thermal_config_from_dict(
    data: dict[str, Any], source: str = "<dict>", base_dir: Path | None = None
) -> ThermalConfig:
    """Validate a parsed TOML mapping into a :class:`ThermalConfig`."""
    data = dict(data)
    raw_mat = data.pop("materials", {})
    raw_contact = data.pop("contact", {})
    boundary = boundary_conditions(data.pop("boundary", []), source)
    choices = {
        "coolant.properties": ("table_4_4", "meg50_table"),
        "simulation.capacity": CAPACITY_KINDS,
        "simulation.coupling": COUPLING_KINDS,
        "simulation.stiffness": STIFFNESS_KINDS,
    }
    cfg = build_config(ThermalConfig, data, source, base_dir, choices, _BOUNDS)
    if not isinstance(raw_mat, dict):
        raise ConfigError(f"{source}: [materials]: expected tables [materials.<part>], got {raw_mat!r}.")
    materials = {p: TABLE_4_3[DEFAULT_PART_MATERIALS[p]] for p in PART_ORDER}
    for part, spec in raw_mat.items():
        if part not in PART_ORDER:
            raise ConfigError(
                f"{source}: key 'materials.{part}' is not a part; valid parts are: {', '.join(PART_ORDER)}."
            )
        if not isinstance(spec, dict):
            raise ConfigError(f"{source}: key 'materials.{part}': expected a table, got {spec!r}.")
        base = materials[part]
        for key, value in spec.items():
            full = f"materials.{part}.{key}"
            if key not in _MATERIAL_KEYS:
                raise ConfigError(
                    f"{source}: key '{full}' is not known; valid keys are: {', '.join(_MATERIAL_KEYS)}."
                )
            if key == "material":
                check_value(value, str, source, full, {full: tuple(TABLE_4_3)}, {})
                base = dataclasses.replace(TABLE_4_3[value])
        props = {
            k: check_value(v, float, source, f"materials.{part}.{k}", {}, {})
            for k, v in spec.items()
            if k != "material"
        }
        materials[part] = dataclasses.replace(base, **props).check(f"{source}: key 'materials.{part}'")
    if not isinstance(raw_contact, dict):
        raise ConfigError(f"{source}: [contact]: expected 'partA|partB' = conductance [W/(m^2 K)].")
    contact = {
        str(k): check_value(v, float, source, f"contact.{k}", {}, {f"contact.{k}": (1e-9, 1e9)})
        for k, v in raw_contact.items()
    }
    cfg.geometry.check(f"{source}: [geometry]")
    if cfg.simulation.stiffness == "afc" and (
        cfg.simulation.theta != 1.0 or cfg.simulation.capacity != "lumped"
    ):
        raise ConfigError(
            f'{source}: key \'simulation.stiffness\' = "afc" needs theta = 1 and capacity = "lumped"; '
            f'got theta = {cfg.simulation.theta:g}, capacity = "{cfg.simulation.capacity}".'
        )
    if cfg.coolant.properties == "meg50_table":
        from hevsim.thermal.coolant import meg50_coolant

        try:
            meg50_coolant(cfg.coolant.inlet_temp_c)
        except ConfigError as exc:
            raise ConfigError(f"{source}: key 'coolant.inlet_temp_c': {exc}") from exc
    return dataclasses.replace(cfg, materials=materials, contact=contact, boundary=boundary)


def coolant_from_section(cool: CoolantSection) -> Any:
    """The :class:`~hevsim.thermal.coolant.Coolant` of a ``[coolant]`` section.

    ``table_4_4``: the section's constants (thesis Table 4.4 by default). ``meg50_table``: the
    MEG 50 table at the inlet temperature; the film coefficient then stays fixed during the run
    (the coolant warms by well under 1 K across the plate at 10 L/min), so the matrix is still
    factorised once.
    """
    from hevsim.thermal.coolant import Coolant, meg50_coolant

    if cool.properties == "meg50_table":
        return meg50_coolant(cool.inlet_temp_c)
    return Coolant(cool.conductivity_w_mk, cool.density_kg_m3, cool.viscosity_pa_s, cool.specific_heat_j_kgk)


def load_thermal_config(path: str | Path) -> ThermalConfig:
    """Read and validate a thermal TOML file."""
    p = Path(path)
    return thermal_config_from_dict(read_toml(p), str(p), p.parent)


@dataclass
class ThermalResult:
    """Time series (SI and °C columns), per-part / per-cell statistics, hot spots and metadata."""

    timeseries: dict[str, np.ndarray]
    part_stats: dict[str, dict[str, float]]
    cell_stats: list[dict[str, float]]
    hot_spots: list[dict[str, Any]]
    metrics: dict[str, dict[str, Any]]
    metadata: dict[str, Any]
    out_dir: Path | None = None


def hot_spots(
    points_m: np.ndarray, temp_c: np.ndarray, part_names: list[str], count: int, min_separation_m: float
) -> list[dict[str, Any]]:
    """The ``count`` hottest nodes at least ``min_separation_m`` apart (greedy, hottest first)."""
    order = np.argsort(-temp_c, kind="stable")
    chosen: list[int] = []
    for i in order[: max(20000, count)]:
        if len(chosen) >= count:
            break
        if chosen and np.min(np.linalg.norm(points_m[chosen] - points_m[i], axis=1)) < min_separation_m:
            continue
        chosen.append(int(i))
    return [
        {
            "rank": r + 1,
            "x_m": float(points_m[i, 0]),
            "y_m": float(points_m[i, 1]),
            "z_m": float(points_m[i, 2]),
            "part": part_names[i],
            "temp_c": float(temp_c[i]),
        }
        for r, i in enumerate(chosen)
    ]


def run_thermal(
    config_path: str | Path | ThermalConfig, out_dir: str | Path | None, *, progress: bool = False
) -> ThermalResult:
    """Run a module case end to end; writes the results folder atomically when ``out_dir`` is given.

    Before meshing, the mesh size, memory and time are estimated
    (:func:`hevsim.thermal.mesh.estimate_mesh`) and a mesh that would not fit in the free
    memory is refused (:class:`~hevsim.errors.ConfigError`). ``progress`` prints a line per
    stage on stderr (meshing, assembly, the time loop with its ETA; a bar on a terminal).
    """
    from hevsim.guards import check_memory
    from hevsim.progress import stage, task
    from hevsim.thermal.geometry import build_module_mesh
    from hevsim.thermal.mesh import estimate_mesh, mesh_faces, triangle_areas_m2

    cfg = config_path if isinstance(config_path, ThermalConfig) else load_thermal_config(config_path)
    sim = cfg.simulation
    est = estimate_mesh(cfg.geometry.check(f"{cfg.name}: geometry"))
    n_steps = round(sim.duration_s / sim.dt_s)
    check_memory(
        est.memory_bytes,
        f"{cfg.name}: the thermal mesh at geometry.mesh_size_m = {cfg.geometry.mesh_size_m:g} m "
        f"({est.nodes:,} nodes estimated)",
        "use a larger geometry.mesh_size_m (memory grows as 1/mesh_size^3).",
        ConfigError,
    )
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    if progress:
        stage(f"meshing {cfg.name}: {est.describe(n_steps)} ...")
    mesh = build_module_mesh(cfg.geometry, source=f"{cfg.name}: geometry")
    timings["mesh_s"] = time.perf_counter() - t0
    if progress:
        n_nodes, n_tets = mesh.points_m.shape[0], mesh.tets.shape[0]
        stage(f"meshed: {n_nodes:,} nodes, {n_tets:,} tetrahedra in {timings['mesh_s']:.1f} s")
    ncell = mesh.n_cells
    heat = np.asarray(sim.cell_heat_w, dtype=float)
    if heat.size not in (1, ncell):
        raise ConfigError(
            f"{cfg.name}: key 'simulation.cell_heat_w' has {heat.size} values; expected 1 or {ncell}."
        )

    t0 = time.perf_counter()
    if progress:
        stage("assembling and factorising the FEM matrices ...")
    disc, channel, model = module_model(cfg, mesh)
    model.set_cell_heat_w(heat, from_now=True)  # the heat is on from t = 0
    timings["assemble_factorise_s"] = time.perf_counter() - t0
    if progress:
        stage(f"assembled and factorised in {timings['assemble_factorise_s']:.1f} s")

    # observation operators
    n = disc.points_m.shape[0]
    node_vol, cell_nodes = cell_node_sets(mesh, disc)
    faces = mesh_faces(disc.tets)
    surf = (faces.other < 0) & (mesh.cell_of_tet[faces.owner] >= 0)
    tri = faces.nodes[surf]
    a3 = np.repeat(triangle_areas_m2(disc.points_m, tri) / 3, 3)
    cid = np.repeat(mesh.cell_of_tet[faces.owner[surf]], 3)
    surf_w = np.zeros((ncell, n))
    np.add.at(surf_w, (cid, tri.ravel()), a3)
    surf_w /= surf_w.sum(axis=1, keepdims=True)

    steps = round(sim.duration_s / sim.dt_s)
    every = max(1, round(cfg.output.field_every_s / sim.dt_s)) if cfg.output.field_every_s > 0 else 0
    rows: dict[str, list[float]] = {
        k: []
        for k in (
            "time_s",
            "heat_in_w",
            "cooling_power_w",
            "wall_heat_w",
            "film_heat_w",
            "outlet_temp_c",
            "cell_max_temp_c",
            "cell_mean_temp_c",
            "module_max_temp_c",
        )
    }
    cell_surface: list[np.ndarray] = []
    snapshots: list[tuple[float, np.ndarray]] = []

    def record() -> None:
        tc = model.temp_k - KELVIN
        rep = model.report()
        rows["time_s"].append(model.time_s)
        rows["heat_in_w"].append(rep.heat_in_w)
        rows["cooling_power_w"].append(getattr(channel, "heat_w", rep.wall_w))
        rows["wall_heat_w"].append(rep.wall_w)
        rows["film_heat_w"].append(rep.film_w)
        rows["outlet_temp_c"].append(getattr(channel, "outlet_temp_k", np.nan) - KELVIN)
        rows["cell_max_temp_c"].append(max(float(tc[c].max()) for c in cell_nodes))
        cell_mean = np.array([np.average(tc[c], weights=node_vol[c]) for c in cell_nodes])
        rows["cell_mean_temp_c"].append(float(cell_mean.mean()))
        rows["module_max_temp_c"].append(float(tc.max()))
        cell_surface.append(surf_w @ tc)

    channel.fluid_temperature_k(model.wall_temp_k(), disc.wall_area_m2)
    initial_temp_k = model.temp_k.copy()
    source_free = np.asarray(disc.cell_load.sum(axis=1)).ravel() == 0.0
    for b in cfg.boundary:  # a heat flux into the solid is a source too
        if b.kind == "heat_flux" and b.heat_flux_w_m2 > 0.0:
            flux_nodes = (
                np.unique(disc.wall_tris)
                if b.surface == "INTERFACE"
                else surface_nodes_and_load(mesh, disc, b.surface)[0]
            )
            source_free[flux_nodes] = False
    monitor = OvershootMonitor(model.k, source_free)
    capacity_estimate = CapacityEstimate(model, disc) if sim.stiffness == "galerkin" else None
    set_temps_k = [b.temp_c + KELVIN for b in cfg.boundary if b.kind != "heat_flux"]
    record()
    if every:
        snapshots.append((0.0, model.temp_k - KELVIN))
    t0 = time.perf_counter()
    with task("time loop", steps, show=progress) as bar:
        for k in range(1, steps + 1):
            old_k = model.temp_k
            model.step()
            fluids = np.asarray(model.fluid_k, dtype=float)[model.wall_h > 0]
            hottest = max([disc.ambient_k, *set_temps_k, *fluids.tolist()])
            monitor.update(old_k, model.temp_k, hottest)
            if capacity_estimate is not None:
                capacity_estimate.update(old_k, model.temp_k)
            record()
            if every and (k % every == 0 or k == steps):
                snapshots.append((model.time_s, model.temp_k - KELVIN))
            bar.update()
    timings["solve_s"] = time.perf_counter() - t0

    tc = model.temp_k - KELVIN
    part_of_node = [mesh.part_names[i] for i in disc.node_part]
    part_stats = {}
    meshed = np.bincount(mesh.part_of_tet, weights=disc.tet_volume_m3, minlength=len(mesh.part_names))
    for pi, name in enumerate(mesh.part_names):
        sel = disc.node_part == pi
        if sel.any():
            part_stats[name] = {
                "min_temp_c": float(tc[sel].min()),
                "mean_temp_c": float(np.average(tc[sel], weights=node_vol[sel])),
                "max_temp_c": float(tc[sel].max()),
                "meshed_volume_m3": float(meshed[pi]),
            }
            if name in mesh.nominal_volume_m3:
                nominal = mesh.nominal_volume_m3[name]
                part_stats[name]["nominal_volume_m3"] = nominal
                part_stats[name]["volume_ratio"] = float(meshed[pi] / nominal) if nominal > 0 else 1.0
    cell_stats = []
    for c, nodes in enumerate(cell_nodes):
        r, col = divmod(c, cfg.geometry.columns)
        cell_stats.append(
            {
                "cell": c + 1,
                "row": r + 1,
                "column": col + 1,
                "min_temp_c": float(tc[nodes].min()),
                "mean_temp_c": float(np.average(tc[nodes], weights=node_vol[nodes])),
                "max_temp_c": float(tc[nodes].max()),
                "surface_temp_c": float(cell_surface[-1][c]),
            }
        )
    spots = hot_spots(disc.points_m, tc, part_of_node, cfg.output.hot_spots, cfg.geometry.cell_pitch_m / 2)
    ts = {k: np.asarray(v) for k, v in rows.items()}
    surf_arr = np.asarray(cell_surface)
    for c in range(ncell):
        ts[f"cell{c + 1}_surface_temp_c"] = surf_arr[:, c]
    rel_balance = (ts["heat_in_w"][-1] - ts["wall_heat_w"][-1] - ts["film_heat_w"][-1]) if steps else 0.0
    energy = energy_balance(ts, sim.theta, sim.dt_s, model.capacity, model.temp_k - initial_temp_k)
    metrics = {
        "cell_max_temp_c": {"value": float(ts["cell_max_temp_c"][-1]), "unit": "degC"},
        "module_max_temp_c": {"value": float(ts["module_max_temp_c"][-1]), "unit": "degC"},
        "outlet_temp_c": {"value": float(ts["outlet_temp_c"][-1]), "unit": "degC"},
        "cooling_power_w": {"value": float(ts["cooling_power_w"][-1]), "unit": "W"},
        **energy,
        "heat_rate_residual_w": {
            "value": float(rel_balance),
            "unit": "W",
            "note": "heat in - wall - film at the end; the difference is being stored",
        },
        **_channel_metrics(channel),
        **_boundary_metrics(cfg, mesh, disc, tc),
        "overshoot_nodes": {
            "value": monitor.nodes,
            "unit": "-",
            "note": "most source-free nodes above their physical bound (local maximum in space and "
            "time above every coupled node and fluid) at one step",
        },
        "overshoot_max_k": {"value": monitor.max_k, "unit": "K", "note": "largest such excess"},
        **_capacity_metrics(capacity_estimate, energy["heat_removed_j"]["value"]),
        "nodes": {"value": int(mesh.points_m.shape[0]), "unit": "-"},
        "nodes_split": {"value": int(n), "unit": "-"},
        "tetrahedra": {"value": int(mesh.tets.shape[0]), "unit": "-"},
    }
    metadata = {
        "config": to_dict(dataclasses.replace(cfg, materials={}, contact={}, boundary=())),
        "boundary": [dataclasses.asdict(b) for b in cfg.boundary],
        "materials": {  # without the (empty) temperature tables of constant materials
            k: {f: x for f, x in dataclasses.asdict(v).items() if x != ()} for k, v in cfg.materials.items()
        },
        "contact_w_m2k": cfg.contact,
        "interfaces_m2": disc.interfaces,
        "timings_s": timings,
        "factorisations": model.factorisations,
        "afc_max_iterations": getattr(model, "iterations", None),
    }
    result = ThermalResult(ts, part_stats, cell_stats, spots, metrics, metadata)
    if out_dir is not None:
        _write(result, Path(out_dir), disc, mesh, snapshots, cfg, tc)
    return result


def energy_balance(
    ts: dict[str, np.ndarray], theta: float, dt_s: float, capacity: Any, delta_temp_k: np.ndarray
) -> dict[str, dict[str, Any]]:
    """Energy metrics [J] of a run from the heat flows recorded at every step end.

    The theta method applies in step k the flows ``theta * P_k + (1 - theta) * P_(k-1)``
    (``P_k``: the flow at the end of step k, at the fluid temperature used in that step), so
    these sums are exactly what the solid gained and lost: ``heat_removed_j`` is the wall heat
    applied to the solid, ``heat_to_ambient_j`` the external films, ``heat_stored_j`` the change
    of ``sum C T`` and ``energy_balance_residual_j`` = in - stored - removed - to ambient (zero
    up to the linear solver's rounding). ``coolant_heat_j`` is what the 1-D coolant took
    (``m c_p (T_out - T_in)`` per step): under the staggered coupling it is computed from the
    wall temperature at the start of the step, so it lags the wall heat;
    ``coupling_lag_j`` = coolant - removed.
    """

    def applied_j(key: str) -> float:
        p = np.asarray(ts[key], dtype=float)
        return float(np.sum(dt_s * (theta * p[1:] + (1.0 - theta) * p[:-1])))

    heat_in = applied_j("heat_in_w")
    removed = applied_j("wall_heat_w")
    ambient = applied_j("film_heat_w")
    stored = float(np.sum(capacity @ delta_temp_k))
    coolant = float(np.sum(dt_s * np.asarray(ts["cooling_power_w"], dtype=float)[1:]))
    residual = heat_in - stored - removed - ambient
    scale = max(abs(heat_in), abs(stored), abs(removed), abs(ambient), 1e-300)
    return {
        "heat_in_j": {"value": heat_in, "unit": "J", "note": "cell heat applied to the solid"},
        "heat_stored_j": {"value": stored, "unit": "J", "note": "sum C (T_end - T_start)"},
        "heat_removed_j": {
            "value": removed,
            "unit": "J",
            "note": "heat through the channel wall into the coolant, as applied to the solid",
        },
        "heat_to_ambient_j": {"value": ambient, "unit": "J", "note": "external films"},
        "energy_balance_residual_j": {
            "value": residual,
            "unit": "J",
            "note": "heat in - stored - removed - to ambient",
        },
        "energy_balance_relative": {
            "value": residual / scale,
            "unit": "-",
            "note": "residual / the largest of the four terms",
        },
        "coolant_heat_j": {
            "value": coolant,
            "unit": "J",
            "note": "m c_p (T_out - T_in) summed over the steps; lags the wall heat by one step",
        },
        "coupling_lag_j": {
            "value": coolant - removed,
            "unit": "J",
            "note": "coolant_heat_j - heat_removed_j",
        },
    }


def _capacity_metrics(est: CapacityEstimate | None, removed_j: float) -> dict[str, dict[str, Any]]:
    """The capacity discretisation error estimate (:class:`CapacityEstimate`) as metrics."""
    if est is None:
        return {}
    note = f"first-order estimate of the change with the {est.other} capacity (the mass-lumping error)"
    return {
        "capacity_error_k": {
            "value": est.max_k,
            "unit": "K",
            "note": f"largest nodal temperature change over the run: {note}",
        },
        "capacity_error_removed_j": {"value": est.removed_j, "unit": "J", "note": f"heat removed: {note}"},
        "capacity_error_removed_relative": {
            "value": est.removed_j / removed_j if removed_j else 0.0,
            "unit": "-",
            "note": "capacity_error_removed_j / heat_removed_j",
            "other_capacity": est.other,
        },
    }


def _channel_metrics(channel: Any) -> dict[str, dict[str, Any]]:
    """Flow metrics of the 1-D coolant channel (none when a [[boundary]] replaces it)."""
    if not hasattr(channel, "reynolds"):
        return {}
    return {
        "reynolds": {"value": channel.reynolds, "unit": "-"},
        "nusselt": {"value": channel.nusselt, "unit": "-"},
        "wall_h_w_m2k": {"value": channel.h_w_m2k, "unit": "W/(m^2 K)"},
        "coolant_viscosity_pa_s": {"value": channel.coolant.viscosity_pa_s, "unit": "Pa s"},
    }


def surface_nodes_and_load(mesh: Any, disc: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Split nodes of the boundary triangles of surface ``name`` and ``int phi`` over them
    [m^2] per split node (the load of a unit heat flux, exact for P1)."""
    from hevsim.thermal.mesh import mesh_faces, triangle_areas_m2

    tris = np.sort(mesh.facet_groups[name], axis=1)
    faces = mesh_faces(mesh.tets)
    bnd = faces.other < 0
    index = {
        tuple(f): int(o) for f, o in zip(faces.nodes[bnd].tolist(), faces.owner[bnd].tolist(), strict=True)
    }
    owner = np.array([index.get(tuple(t), -1) for t in tris.tolist()], dtype=np.int64)
    tris = tris[owner >= 0]
    owner = owner[owner >= 0]
    nparts = len(mesh.part_names)
    keys = disc.original_node.astype(np.int64) * nparts + disc.node_part
    split = np.searchsorted(keys, tris * nparts + mesh.part_of_tet[owner][:, None])
    load = np.zeros(disc.points_m.shape[0])
    np.add.at(load, split.ravel(), np.repeat(triangle_areas_m2(mesh.points_m, tris) / 3.0, 3))
    return np.unique(split), load


def _boundary_metrics(
    cfg: ThermalConfig, mesh: Any, disc: Any, temp_c: np.ndarray
) -> dict[str, dict[str, Any]]:
    """For every fixed-temperature [[boundary]]: the largest deviation of its nodes from the set value."""
    out: dict[str, dict[str, Any]] = {}
    for b in cfg.boundary:
        if b.kind == "temperature":
            nodes, _ = surface_nodes_and_load(mesh, disc, b.surface)
            out[f"boundary_{b.surface}_max_deviation_k"] = {
                "value": float(np.abs(temp_c[nodes] - b.temp_c).max()),
                "unit": "K",
                "note": f"largest |T - {b.temp_c:g} degC| on {b.surface} (held by a stiff film)",
            }
    return out


def format_summary(result: ThermalResult) -> str:
    """A few lines for the terminal: metrics and the hottest spots."""
    m = result.metrics
    lines = [f"{result.metadata['config'].get('name', 'module')}: {m['nodes']['value']} nodes, "
             f"{m['tetrahedra']['value']} tetrahedra"]  # fmt: skip
    keys = ("cell_max_temp_c", "module_max_temp_c", "outlet_temp_c", "cooling_power_w", "heat_in_j",
            "heat_stored_j", "heat_removed_j", "heat_to_ambient_j", "coupling_lag_j")  # fmt: skip
    for key in (k for k in keys if k in m):
        lines.append(f"  {key:<26}{m[key]['value']:>12.4f} {m[key]['unit']}")
    ratios = {k: v["volume_ratio"] for k, v in result.part_stats.items() if "volume_ratio" in v}
    if ratios:
        lines.append("  meshed/nominal volume: " + ", ".join(f"{k} {v:.4f}" for k, v in ratios.items()))
    if "overshoot_max_k" in m:
        over, count = m["overshoot_max_k"]["value"], m["overshoot_nodes"]["value"]
        lines.append(f"  {'overshoot (nodes, max)':<26}{count:>12d} {over:.4f} K")
        if over > OVERSHOOT_WARN_K:
            lines.append(
                f"  note: source-free nodes overshoot their physical bound by up to {over:.3f} K "
                f"(> {OVERSHOOT_WARN_K} K: obtuse tetrahedra or consistent surface matrices); "
                '[simulation] stiffness = "afc" removes it (algebraic flux correction)'
            )
    if "capacity_error_k" in m:
        cap_k, cap_rel = m["capacity_error_k"]["value"], m["capacity_error_removed_relative"]["value"]
        lines.append(
            f"  {'capacity error (est.)':<26}{cap_k:>12.4f} K, {100 * cap_rel:+.2f} % of heat removed"
        )
        if abs(cap_rel) > CAPACITY_WARN_FRACTION or cap_k > CAPACITY_WARN_K:
            other = m["capacity_error_removed_relative"]["other_capacity"]
            lines.append(
                f"  warning: the {other} heat capacity would change a temperature by up to {cap_k:.2f} K and "
                f"the heat removed by {100 * cap_rel:+.1f} % (estimated; above {CAPACITY_WARN_K} K or "
                f"{100 * CAPACITY_WARN_FRACTION:g} %): the mesh is too coarse for this transient; refine "
                "geometry.mesh_size_m"
                + (
                    ', or run [simulation] capacity = "consistent" (closer to CalculiX on fast transients) '
                    "and check its overshoot_max_k"
                    if other == "consistent"
                    else ""
                )
            )
    if "energy_balance_relative" in m:
        lines.append(f"  {'energy_balance_relative':<26}{m['energy_balance_relative']['value']:>12.2e} -")
    lines.append("  hot spots (part, x y z [mm], °C):")
    for h in result.hot_spots[:5]:
        lines.append(
            f"    {h['rank']:>2} {h['part']:<10}{1e3 * h['x_m']:7.1f}{1e3 * h['y_m']:7.1f}"
            f"{1e3 * h['z_m']:7.1f}{h['temp_c']:9.3f}"
        )
    if result.out_dir is not None:
        lines.append(
            f"results written to {result.out_dir}/ (summary.json, timeseries.csv, temperature.pvd, PNGs)"
        )
    return "\n".join(lines)


def _write(
    result: ThermalResult,
    out: Path,
    disc: Any,
    mesh: Any,
    snapshots: list[tuple[float, np.ndarray]],
    cfg: ThermalConfig,
    final_c: np.ndarray,
) -> None:
    import csv

    from hevsim.io import atomic_directory, write_json

    with atomic_directory(out) as tmp:
        keys = list(result.timeseries)
        with open(tmp / "timeseries.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(keys)
            for row in zip(*(result.timeseries[k] for k in keys), strict=True):
                w.writerow([f"{v:.10g}" for v in row])
        write_json(
            tmp / "summary.json",
            {
                "name": cfg.name,
                "metrics": result.metrics,
                "parts": result.part_stats,
                "cells": result.cell_stats,
                "hot_spots": result.hot_spots,
                "metadata": result.metadata,
            },
        )
        write_field_series(tmp, disc, mesh, snapshots)
        if cfg.output.pictures:
            _pictures(tmp, result, disc, mesh, cfg, final_c)
    result.out_dir = out


def write_field_series(
    out_dir: Path, disc: Any, mesh: Any, series: list[tuple[float, np.ndarray]], prefix: str = ""
) -> Path:
    """Write nodal temperature fields [°C] ``series`` = ``[(time_s, temp_c), ...]`` as
    ``out_dir/fields/{prefix}temperature_NNNN.vtu`` (split mesh, cell data ``part`` and ``cell``)
    and the ParaView collection ``out_dir/{prefix}temperature.pvd``; returns the .pvd path."""
    import meshio

    out = Path(out_dir)
    fields = out / "fields"
    fields.mkdir(parents=True, exist_ok=True)
    cells = [("tetra", disc.tets)]
    cell_data = {"part": [mesh.part_of_tet.astype(np.int32)], "cell": [mesh.cell_of_tet.astype(np.int32)]}
    entries = []
    for i, (t, temp) in enumerate(series):
        name = f"{prefix}temperature_{i:04d}.vtu"
        meshio.write(
            fields / name,
            meshio.Mesh(disc.points_m, cells, point_data={"temperature_c": temp}, cell_data=cell_data),
            binary=True,
        )
        entries.append(f'    <DataSet timestep="{t:g}" part="0" file="fields/{name}"/>')
    pvd = out / f"{prefix}temperature.pvd"
    pvd.write_text(
        '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
        + "\n".join(entries)
        + "\n  </Collection>\n</VTKFile>\n"
    )
    return pvd


def _pictures(
    tmp: Path, result: ThermalResult, disc: Any, mesh: Any, cfg: ThermalConfig, tc: np.ndarray
) -> None:
    """cells_temperature.png, plate_temperature.png, cells_section.png (final field) and timeseries.png."""
    from matplotlib.figure import Figure

    from hevsim.io import save_png
    from hevsim.thermal.pictures import plot_fields

    ts = result.timeseries
    plot_fields(mesh, disc, cfg.geometry, tc, float(ts["time_s"][-1]), tmp)
    # time series
    fig = Figure(figsize=(8, 6), dpi=100)
    a1, a2 = fig.subplots(2, 1, sharex=True)
    a1.plot(ts["time_s"], ts["cell_max_temp_c"], label="cell max")
    a1.plot(ts["time_s"], ts["cell_mean_temp_c"], label="cell mean")
    a1.plot(ts["time_s"], ts["outlet_temp_c"], label="coolant outlet")
    a1.set_ylabel("°C")
    a1.legend()
    a2.plot(ts["time_s"], ts["cooling_power_w"], label="coolant (m c ΔT)")
    a2.plot(ts["time_s"], ts["heat_in_w"], label="cell heat input")
    a2.set_ylabel("W")
    a2.set_xlabel("time [s]")
    a2.legend()
    save_png(fig, tmp / "timeseries.png", 100)


__all__ = [
    "ThermalConfig",
    "ThermalResult",
    "format_summary",
    "load_thermal_config",
    "run_thermal",
    "thermal_config_from_dict",
    "write_field_series",
]


def module_model(cfg: ThermalConfig, mesh: Any, external_coolant: bool = False) -> tuple[Any, Any, Any]:
    """Discretisation, coolant and heat model of a module case (shared by :func:`run_thermal`
    and the co-simulation's FEM participant): ``(disc, coolant, model)``.

    The coolant is the configured 1-D channel (:class:`~hevsim.thermal.coolant.ChannelModel`),
    or with ``external_coolant`` a :class:`~hevsim.thermal.coolant.PrescribedWallCoolant`
    whose film and fluid temperature are set from outside. Its ``configured_segments`` gives
    the configured channel segment (0 .. segments-1) of each wall segment of ``disc``."""
    from hevsim.thermal.coolant import ChannelModel, PrescribedWallCoolant, channel_segments
    from hevsim.thermal.mesh import CHANNEL_WALL
    from hevsim.thermal.solver import HeatModel, discretise

    for part, mat in cfg.materials.items():
        if mat.temperature_dependent:  # only through the API: TOML [materials] have no tables
            raise ConfigError(
                f"{cfg.name}: part '{part}' material '{mat.name}' depends on temperature; the module "
                "model (thermal run, ROM build, FEM co-simulation participant, CHT) is linear: expected "
                "constant properties (NonlinearHeatModel runs a deck with temperature tables)."
            )
    sim, cool = cfg.simulation, cfg.coolant
    bcs = {b.surface: b for b in cfg.boundary}
    k_max = max(m.conductivity_w_mk for m in cfg.materials.values()) if cfg.materials else 1.0
    h_fixed = FIXED_TEMPERATURE_BIOT * k_max / cfg.geometry.mesh_size_m  # [W/(m^2 K)]
    films: dict[str, tuple[float, float]] = {}
    for b in bcs.values():
        if b.surface == CHANNEL_WALL:
            continue
        if b.kind == "film":
            films[b.surface] = (b.film_w_m2k, b.temp_c + KELVIN)
        elif b.kind == "temperature":
            films[b.surface] = (h_fixed, b.temp_c + KELVIN)
        else:  # heat flux: no film there; the flux is a load below
            films[b.surface] = (0.0, KELVIN)
    wall = mesh.facet_groups[CHANNEL_WALL]
    assert mesh.channel_path_m is not None
    seg, used = channel_segments(mesh.points_m[wall].mean(axis=1), mesh.channel_path_m, cool.segments)
    disc = discretise(
        mesh,
        cfg.materials,
        gap_conductance_w_m2k=sim.gap_conductance_w_m2k,
        interface_conductance_w_m2k=cfg.contact,
        film_w_m2k=sim.film_w_m2k,
        ambient_k=sim.ambient_temp_c + KELVIN,
        wall_segment_of_facet=seg,
        surface_films=films,
    )
    for b in bcs.values():
        if b.kind == "heat_flux" and b.surface != CHANNEL_WALL:
            _, unit_load = surface_nodes_and_load(mesh, disc, b.surface)
            disc = dataclasses.replace(disc, film_load_w=disc.film_load_w + b.heat_flux_w_m2 * unit_load)
    wall_bc = bcs.get(CHANNEL_WALL)
    if wall_bc is not None and external_coolant:
        raise ConfigError(
            f"{cfg.name}: [[boundary]] on {CHANNEL_WALL} and an external coolant; expected one of the two."
        )
    coolant: Any
    if wall_bc is not None:  # a fixed condition on the channel wall replaces the 1-D coolant
        coolant = PrescribedWallCoolant(used.size)
        if wall_bc.kind == "film":
            coolant.h_w_m2k[:], coolant.fluid_k[:] = wall_bc.film_w_m2k, wall_bc.temp_c + KELVIN
        elif wall_bc.kind == "temperature":
            coolant.h_w_m2k[:], coolant.fluid_k[:] = h_fixed, wall_bc.temp_c + KELVIN
    elif external_coolant:
        coolant = PrescribedWallCoolant(used.size)
    else:
        coolant = ChannelModel(
            used.size,
            inlet_temp_k=cool.inlet_temp_c + KELVIN,
            flow_m3_s=cool.flow_l_min * LITRE_PER_MIN_M3_S,
            width_m=cfg.geometry.channel_width_m,
            height_m=cfg.geometry.channel_height_m,
            coolant=coolant_from_section(cool),
        )
    coolant.configured_segments = used
    diffusion = None
    if sim.stiffness == "afc":  # low-order operator of conduction, contact and films
        k_total = disc.stiffness
        h_wall = np.asarray(coolant.heat_transfer_coefficient_w_m2k(), dtype=float)
        if np.any(h_wall):
            k_total = k_total + disc.wall_mass.matrix(h_wall[disc.wall_segment])
        diffusion = dmp_diffusion(k_total)
        disc = dataclasses.replace(disc, stiffness=(disc.stiffness + diffusion).tocsr())
    model: Any = HeatModel(
        disc,
        dt_s=sim.dt_s,
        theta=sim.theta,
        initial_temp_k=sim.initial_temp_c + KELVIN,
        coolant=coolant,
        coupling_iterations=sim.coupling_iterations,
        lumped_capacity=sim.capacity == "lumped",
        coupling=sim.coupling,
    )
    if wall_bc is not None and wall_bc.kind == "heat_flux":
        model.wall_flux_w_m2[:] = -wall_bc.heat_flux_w_m2  # the wall loses -q
        model.set_cell_heat_w(model.cell_heat_w, from_now=True)  # the load now includes it
    if diffusion is not None:
        model = AFCHeatModel(model, diffusion)
    return disc, coolant, model

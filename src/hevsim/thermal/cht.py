"""Heat transfer in the coolant with a frozen laminar flow field: the coolant side of the
conjugate heat-transfer (CHT) problem of the cooling plate.

Equation (constant properties: density rho [kg/m^3], specific heat c_p [J/(kg K)],
conductivity k [W/(m K)]) on the channel volume, velocity u [m/s] from
:func:`hevsim.thermal.flow.solve_flow` (solved once per operating point and frozen)::

    rho c_p (dT/dt + u . grad T) - k lap T = 0

Discretisation: P2 temperature on the flow's tetrahedral mesh, convective term in advective
form ``int rho c_p v u . grad T`` with streamline-upwind Petrov-Galerkin stabilisation
``int tau (u . grad v) rho c_p (dT/dt + u . grad T)`` (``tau = h'/(2 |u|) (coth Pe_h - 1/Pe_h)``
with the nodal spacing ``h' = h/2`` and ``Pe_h = |u| h' / (2 alpha)``; the diffusive part of the
element residual, zero for P1 and small for P2 at the cell Peclet numbers where tau matters, is
left out). Boundaries: the wall (all channel faces but inlet and outlet) takes the plate's
wall temperature (Dirichlet: one value per coolant segment along the channel path,
interpolated linearly between the segment centres so that the wall temperature is
continuous, :func:`segment_weights`); the inlet takes the inflow enthalpy weakly
(``int rho c_p |u . n| (T - T_in) v``, a Danckwerts condition); the outlet has no diffusive
flux. Steady or implicit Euler.

The heat through the wall is the consistent residual of the Dirichlet rows (the heat each wall
degree of freedom must supply). Summed over the wall (the test function ``v = 1``) it equals the
coolant's enthalpy rise ``m_dot c_p (T_out - T_in)`` (mixing-cup outlet temperature) up to
``int rho c_p T div u``, which vanishes for a divergence-free velocity but not for the Taylor-Hood
flow, whose divergence is zero only against the P1 pressure space: on the serpentine's default
mesh the plain advective form left 28 %, 6.8 % and 0.55 % of the heat unbalanced with
``flow.grad_div`` 0, 1 and 10 (the bends are where the coarse mesh conserves mass worst). The
convective term therefore carries the correction ``int rho c_p (T - I_1 T) v div u``, with
``I_1 T`` the P1 interpolant of T at the vertices (:func:`vertex_interpolation`). Since
``int I_1 T div u = 0`` for the Taylor-Hood velocity, the balance closes to round-off (measured
1e-9 on the serpentine, :func:`run_cht`'s ``energy_imbalance_rel``); the term is zero for a
uniform temperature (no heat without a temperature difference, unlike the conservative form,
which turns the discrete divergence times the absolute temperature into about +-150 W of
spurious wall heat per bend segment) and for a divergence-free velocity, and it is consistent
(of order ``h^2 |T|_2 |div u_h|``). ``divergence_correction=False`` gives the plain advective
form.

On a turbulent (RANS) flow the eddy diffusivity ``nu_t / Pr_t`` adds to ``alpha``; where the
FEM wall cells are too thick for the conduction sublayer, the thermal wall function
(:mod:`hevsim.thermal.wall_function`, ``flow.thermal_wall``) bridges the wall layer: the
wall temperature then enters through a film ``int h (T_w - T) v`` on the wall facets (from the
law of the wall) instead of the Dirichlet rows, and the wall heat is that film's heat.

The coupling to conduction in the plate is partitioned: the plate's FEM gives the wall
temperature per segment, the coolant returns the heat per segment
(:class:`hevsim.cosim.coolant_cht.CoolantCHTParticipant`).

Local heat-transfer coefficient per segment, defined like the 1-D channel model's
(:class:`hevsim.thermal.coolant.ChannelModel`) so the two compare directly: with the bulk
(mixing-cup) temperature ``T_b`` from the cumulative wall heat,
``h_i = m_dot c_p / A_i ln((T_w,i - T_b,i-1) / (T_w,i - T_b,i))``, ``Nu_i = h_i D_h / k``.

References: A. N. Brooks and T. J. R. Hughes, Comput. Methods Appl. Mech. Engrg. 32 (1982)
199-259 (SUPG); R. K. Shah and A. L. London, *Laminar Flow Forced Convection in Ducts*,
Academic Press (1978), ch. VII (rectangular ducts: Nu_T of thermally developed flow).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from hevsim.errors import ConfigError
from hevsim.thermal.channel import THERMAL_WALL_MODES, Channel, FlowResult, config_channel, port_facets
from hevsim.thermal.coolant import Coolant, segments_along_path

#: Cells of the mesh wanted across the thermal boundary layer [-]: 0.5 = one node spacing of
#: the P2 temperature (two per cell); fewer gives the coarse-mesh warning
#: (:class:`ThermalMeshWarning`).
CELLS_PER_BOUNDARY_LAYER = 0.5


#: Bins per segment that locate a point along the channel path (1e-6 of a segment) [-].
SUBDIVISIONS = 1_000_000


#: Polynomial order p of the temperature element: the SUPG length is h/p (the element's
#: nodal spacing), the usual choice for quadratic elements [-].
TAU_ORDER = 2.0


class ThermalMeshWarning(UserWarning):
    """The coolant mesh is too coarse for the thermal boundary layer it has to resolve."""


class WallFunctionWarning(ThermalMeshWarning):
    """Coolant wall elements lie outside the thermal wall function's range (beyond the log layer)."""


def shah_london_nu_t(aspect: float) -> float:
    """Thermally developed Nusselt number of a rectangular duct, constant wall temperature on
    all four walls [-], for the aspect ratio ``aspect`` = short / long side in (0, 1].

    Shah & London (1978), ch. VII, the polynomial fit ``7.541 (1 - 2.610 a + 4.970 a^2 - 5.119
    a^3 + 2.702 a^4 - 0.548 a^5)`` of their tabulated values (2.976 square, 3.391 at 1/2,
    4.439 at 1/4, 7.541 parallel plates), within 0.1 % of them.
    """
    a = min(aspect, 1.0 / aspect) if aspect > 0 else 0.0
    return 7.541 * (1 - 2.610 * a + 4.970 * a**2 - 5.119 * a**3 + 2.702 * a**4 - 0.548 * a**5)


def thermal_boundary_layer_m(x_m: float, hydraulic_diameter_m: float, peclet: float) -> float:
    """Thermal entry boundary-layer thickness [m] a distance ``x_m`` [m] from the inlet,
    ``D_h (x / (D_h Pe))^(1/3)`` (Leveque scaling), capped at half the diameter (developed)."""
    return min(
        hydraulic_diameter_m * (x_m / (hydraulic_diameter_m * peclet)) ** (1.0 / 3.0),
        hydraulic_diameter_m / 2,
    )


def segment_weights(points_m: np.ndarray, path_m: np.ndarray, n_segments: int) -> Any:
    """Sparse (points, n_segments) weights [-] of the continuous, piecewise-linear profile along
    ``path_m`` through one value per segment at the segment centres (constant before the first
    centre and after the last). Rows sum to 1: a value per segment becomes a continuous wall
    temperature, and the transpose gathers heat per point into heat per segment, conserving
    the total."""
    from scipy.sparse import coo_matrix

    fine = segments_along_path(points_m, path_m, n_segments * SUBDIVISIONS)
    pos = np.clip((fine + 0.5) / SUBDIVISIONS - 0.5, 0.0, n_segments - 1.0)  # in segment centres
    left = np.minimum(np.floor(pos).astype(np.int64), n_segments - 1)
    right = np.minimum(left + 1, n_segments - 1)
    w = 1.0 - (pos - left)
    rows = np.arange(len(pos))
    return coo_matrix(
        (np.concatenate((w, 1 - w)), (np.concatenate((rows, rows)), np.concatenate((left, right)))),
        shape=(len(pos), n_segments),
    ).tocsr()


@dataclass
class CoolantThermal:
    """Assembled coolant heat-transfer problem on a frozen flow; see the module docstring.

    Args:
        flow: the flow solution (mesh and P2 velocity).
        channel: its channel (inlet/outlet planes).
        coolant: properties (k, rho, c_p).
        path_m: polyline (P, 3) [m] along which the wall is cut into ``n_segments`` segments.
        n_segments: number of wall segments (one wall temperature each).
        where: prefix of error messages.
        divergence_correction: add the term that closes the energy balance on a flow that
            is divergence-free only weakly (module docstring); False = plain advective form.
        thermal_wall: wall treatment on a RANS flow, ``auto``, ``resolved`` or
            ``wall_function`` (:meth:`_wall_treatment`, :mod:`hevsim.thermal.wall_function`:
            the wall temperature then enters through a film instead of the wall rows).
    """

    flow: FlowResult
    channel: Channel
    coolant: Coolant
    path_m: np.ndarray
    n_segments: int
    where: str = "cht"
    divergence_correction: bool = True
    thermal_wall: str = "auto"

    def __post_init__(self) -> None:
        from skfem import BilinearForm, ElementTetP1, ElementTetP2, FacetBasis, LinearForm
        from skfem.helpers import dot, grad

        if self.n_segments < 1:
            raise ConfigError(f"{self.where}: n_segments = {self.n_segments}; expected at least 1.")
        c = self.coolant.check(f"{self.where}: coolant")
        rc, k = c.density_kg_m3 * c.specific_heat_j_kgk, c.conductivity_w_mk
        alpha = k / rc
        fl = self.flow
        mesh = fl.mesh
        self.basis = fl.basis_u.with_element(ElementTetP2())
        u_q = fl.basis_u.interpolate(fl.velocity)
        # RANS flow: the eddy diffusivity nu_t / Pr_t [m^2/s] adds to alpha (k -> k + rc a_t)
        eddy = fl.eddy_diffusivity_m2_s if fl.eddy_diffusivity_m2_s is not None else np.zeros(mesh.p.shape[1])
        a_t = fl.basis_u.with_element(ElementTetP1()).interpolate(eddy)
        use_wall_function = self._wall_treatment()
        mid = mesh.p[:, mesh.facets].mean(axis=1)
        bnd = mesh.boundary_facets()
        f_in, f_out = port_facets(mesh, self.channel)
        f_wall = np.setdiff1d(bnd, np.union1d(f_in, f_out))
        self.wall_dofs = self.basis.get_dofs(f_wall).all()
        # total diffusivity alpha + nu_t / Pr_t [m^2/s] at the quadrature points; with the wall
        # function, the wall elements' own effective value (hevsim.thermal.wall_function)
        self.wall_function: Any = None
        if use_wall_function:  # the eddy diffusivity lifted at the wall: the film carries the layer
            from hevsim.thermal.wall_function import lift_wall_values

            wall_vertices = np.unique(mesh.facets[:, f_wall])
            a_t = fl.basis_u.with_element(ElementTetP1()).interpolate(
                lift_wall_values(mesh, wall_vertices, eddy)
            )
        a_tot = alpha + np.asarray(a_t)

        @BilinearForm
        def advection_diffusion(t: Any, v: Any, w: Any) -> Any:
            ugv = dot(w["u"], grad(v))
            speed = np.sqrt(dot(w["u"], w["u"])) + 1e-300
            hp = w.h / TAU_ORDER
            pe = np.maximum(speed * hp / (2 * w["a"]), 1e-12)
            tau = hp / (2 * speed) * (1 / np.tanh(pe) - 1 / pe)
            ugt = dot(w["u"], grad(t))
            return rc * v * ugt + rc * w["a"] * dot(grad(t), grad(v)) + tau * ugv * rc * ugt

        @BilinearForm
        def capacity(t: Any, v: Any, w: Any) -> Any:
            speed = np.sqrt(dot(w["u"], w["u"])) + 1e-300
            hp = w.h / TAU_ORDER
            pe = np.maximum(speed * hp / (2 * w["a"]), 1e-12)
            tau = hp / (2 * speed) * (1 / np.tanh(pe) - 1 / pe)
            return rc * t * (v + tau * dot(w["u"], grad(v)))

        @BilinearForm
        def inflow_exchange(t: Any, v: Any, w: Any) -> Any:  # rho c_p |u . n| T v on the inlet
            return -rc * dot(w["u"], w.n) * t * v

        @LinearForm
        def boundary_inflow(v: Any, w: Any) -> Any:  # -rho c_p (u . n) v per kelvin of T_in
            return -rc * dot(w["u"], w.n) * v

        fb_in = FacetBasis(mesh, self.basis.elem, facets=f_in, intorder=4)
        fb_out = FacetBasis(mesh, self.basis.elem, facets=f_out, intorder=4)
        fu_in = FacetBasis(mesh, fl.basis_u.elem, facets=f_in, intorder=4)
        fu_out = FacetBasis(mesh, fl.basis_u.elem, facets=f_out, intorder=4)
        self.stiffness = (
            advection_diffusion.assemble(self.basis, u=u_q, a=a_tot)
            + inflow_exchange.assemble(fb_in, u=fu_in.interpolate(fl.velocity))
        ).tocsr()
        if self.divergence_correction:
            self.stiffness = (self.stiffness + _divergence_correction(self.basis, u_q, rc)).tocsr()
        self.capacity = capacity.assemble(self.basis, u=u_q, a=a_tot).tocsr()
        self.inflow = boundary_inflow.assemble(fb_in, u=fu_in.interpolate(fl.velocity))  # [W/K]
        self._fb_out, self._u_out = fb_out, fu_out.interpolate(fl.velocity)
        self.flow_m3_s = float(fl.metrics["flow_m3_s"])
        self.capacity_rate_w_k = rc * self.flow_m3_s
        # wall dofs' segments; wall facet areas per segment
        self.wall_weights = segment_weights(
            self.basis.doflocs[:, self.wall_dofs].T, self.path_m, self.n_segments
        )
        p = mesh.p[:, mesh.facets[:, f_wall]]
        area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], axis=0), axis=0)
        fseg = segments_along_path(mid[:, f_wall].T, self.path_m, self.n_segments)
        self.wall_area_m2 = np.bincount(fseg, weights=area, minlength=self.n_segments)
        if np.any(self.wall_weights.sum(axis=0) == 0.0):
            raise ConfigError(
                f"{self.where}: {self.n_segments} wall segments but some have no mesh node on the wall; "
                "use fewer segments or a finer flow mesh (flow.cell_length_m)."
            )
        n = self.basis.N
        self._robin: tuple[Any, Any, np.ndarray] | None = None
        if use_wall_function:  # the wall temperature enters through the film
            self._robin = self._wall_film(f_wall, rc, a_tot)
            self.stiffness = (self.stiffness + self._robin[0]).tocsr()
            self.wall_dofs = np.zeros(0, dtype=np.int64)
        self.free = np.setdiff1d(np.arange(n), self.wall_dofs)
        self._lu: dict[float, Any] = {}
        self.dh_m = float(fl.metrics["hydraulic_diameter_m"])
        self.peclet = float(fl.metrics["reynolds"]) * c.prandtl
        self._response: dict[float, np.ndarray] = {}

    def _wall_treatment(self) -> bool:
        """Whether the wall elements take the thermal wall function (``thermal_wall``:
        ``auto``, ``resolved`` or ``wall_function``; see :data:`~hevsim.thermal.flow.THERMAL_WALL_MODES`).
        ``auto`` on a RANS flow: the wall function when the FEM wall cells are thicker than
        twice the conduction sublayer, else resolved. ``resolved`` on such a mesh is refused
        (:func:`~hevsim.thermal.rans.check_thermal_wall_mesh`); ``wall_function`` on a laminar
        flow too (the law of the wall is a turbulent one)."""
        mode = self.thermal_wall
        if mode not in THERMAL_WALL_MODES:
            raise ConfigError(
                f"{self.where}: flow.thermal_wall = {mode!r}; expected one of "
                f"{', '.join(THERMAL_WALL_MODES)}."
            )
        fl = self.flow
        if fl.rans is None:
            if mode == "wall_function":
                raise ConfigError(
                    f"{self.where}: flow.thermal_wall = 'wall_function' needs a turbulent (RANS) flow, but "
                    f"the flow at Re {fl.metrics['reynolds']:.0f} was solved laminar; use 'auto' or "
                    "'resolved'."
                )
            return False
        if mode == "auto":
            from hevsim.thermal.rans import wall_cells_resolve_sublayer

            return not wall_cells_resolve_sublayer(fl.metrics)
        if mode == "resolved":  # the FEM wall cells must resolve the conduction sublayer
            from hevsim.thermal.rans import check_thermal_wall_mesh

            check_thermal_wall_mesh(fl, self.where)
            return False
        return True

    def _wall_film(self, f_wall: np.ndarray, rc: float, a_tot: np.ndarray) -> tuple[Any, Any, np.ndarray]:
        """The thermal wall function's film on the wall facets (module
        :mod:`hevsim.thermal.wall_function`): facet film matrix ``M`` [W/K] of
        ``int h T v``, the (N, n_segments) matrix ``R`` [W/K] of ``int h T_w v`` per kelvin of
        each segment's wall temperature and the (n_segments, n_segments) ``W`` [W/K] of
        ``int h T_w w_s``, so the heat per segment is ``W T_w - R^T T``."""
        from scipy.sparse import csr_matrix, diags
        from skfem import BilinearForm, FacetBasis, LinearForm

        from hevsim.thermal.wall_function import wall_function

        fl, c = self.flow, self.coolant
        mesh = fl.mesh
        wf = wall_function(
            mesh,
            f_wall,
            lambda x: fl.rans.u_field.at(x),
            a_tot.mean(axis=1),
            c.viscosity_pa_s / c.density_kg_m3,
            c.prandtl,
        )
        self.wall_function = wf
        self._check_wall_function_range(wf)
        fb = FacetBasis(mesh, self.basis.elem, facets=f_wall, intorder=4)
        film = wf.film_w_m2k(rc)  # [W/(m^2 K)] per wall facet
        nqp = fb.dx.shape[1]
        h_q = np.repeat(film[:, None], nqp, axis=1)

        @BilinearForm
        def film_mass(t: Any, v: Any, w: Any) -> Any:
            return w["h"] * t * v

        @LinearForm
        def film_load(v: Any, w: Any) -> Any:
            return w["h"] * w["g"] * v

        xq = np.asarray(fb.global_coordinates()).reshape(3, -1).T
        wq = segment_weights(xq, self.path_m, self.n_segments).tocsc()  # (facets * nqp, segments)
        cols = []
        for j in range(self.n_segments):
            g = wq[:, j].toarray().reshape(h_q.shape)
            cols.append(film_load.assemble(fb, h=h_q, g=g))
        r = csr_matrix(np.column_stack(cols))
        w_ss = (wq.T @ diags((h_q * fb.dx).ravel()) @ wq).toarray()
        return film_mass.assemble(fb, h=h_q).tocsr(), r, w_ss

    def _check_wall_function_range(self, wf: Any) -> None:
        """Warn (:class:`WallFunctionWarning`) when wall facets have their point P beyond the
        log layer (y+ or distance from the wall; :mod:`hevsim.thermal.wall_function`)."""
        from hevsim.thermal.wall_function import OUTER_FRACTION_MAX, YPLUS_LOG_MAX

        outer_m = OUTER_FRACTION_MAX * float(self.flow.metrics["hydraulic_diameter_m"]) / 2
        above = (wf.y_plus > YPLUS_LOG_MAX) | (wf.y_m > outer_m)
        if above.any():
            warnings.warn(
                f"{self.where}: {int(above.sum())} of {above.size} coolant wall facets have their "
                "wall-function point beyond the log layer (y+ up to "
                f"{float(wf.y_plus.max()):.0f}, limit {YPLUS_LOG_MAX:g}; wall cells up to "
                f"{float(wf.y_m.max()) * 1e3:.3g} mm, limit {outer_m * 1e3:.3g} mm, a quarter of the "
                "hydraulic diameter): there the law of the wall does not hold and the wall heat comes "
                "out too high (+35 % on the validation duct with the node at the centre line). Use thinner "
                "wall cells: flow.wall_cell_m (graded) or more flow.cells_across_height / "
                "cells_across_width.",
                WallFunctionWarning,
                stacklevel=3,
            )

    def wall_metrics(self) -> dict[str, float]:
        """The wall treatment's figures: with the thermal wall function the y+ range of the
        wall elements' nodes and more (:meth:`~hevsim.thermal.wall_function.WallFunction.metrics`),
        else ``wall_function`` = 0."""
        from hevsim.thermal.wall_function import OUTER_FRACTION_MAX

        if self.wall_function is None:
            return {"wall_function": 0.0}
        return self.wall_function.metrics(OUTER_FRACTION_MAX * self.dh_m / 2)

    # ------------------------------------------------------------------ solves
    def _factor(self, dt_s: float) -> Any:
        from scipy.sparse.linalg import splu

        key = float(dt_s)
        if key not in self._lu:
            a = self.stiffness if not math.isfinite(key) else self.stiffness + self.capacity / key
            self._lu[key] = (a, splu(a[self.free][:, self.free].tocsc()))
        return self._lu[key]

    def wall_values_k(self, wall_temp_k: np.ndarray) -> np.ndarray:
        """Dirichlet values at the wall dofs [K] from one wall temperature per segment [K]."""
        t = np.asarray(wall_temp_k, dtype=float)
        if t.shape != (self.n_segments,):
            raise ConfigError(f"{self.where}: {t.size} wall temperatures; expected {self.n_segments}.")
        return self.wall_weights @ t

    def solve(
        self,
        wall_temp_k: np.ndarray,
        inlet_temp_k: float,
        *,
        dt_s: float = math.inf,
        previous_k: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Temperature dofs [K] and heat per wall segment into the coolant [W].

        Steady with ``dt_s = inf``; otherwise one implicit Euler step of ``dt_s`` [s] from the
        dofs ``previous_k`` [K] (the heat then includes the coolant's storage term)."""
        a, lu = self._factor(dt_s)
        rhs = self.inflow * inlet_temp_k
        if math.isfinite(dt_s):
            if previous_k is None:
                raise ConfigError(f"{self.where}: a transient step needs the previous temperature.")
            rhs = rhs + self.capacity @ previous_k / dt_s
        if self._robin is not None:  # wall function: the wall temperature through the film
            tw = np.asarray(wall_temp_k, dtype=float)
            if tw.shape != (self.n_segments,):
                raise ConfigError(f"{self.where}: {tw.size} wall temperatures; expected {self.n_segments}.")
            _, r_film, w_film = self._robin
            t = lu.solve(rhs + r_film @ tw)
            return t, w_film @ tw - r_film.T @ t
        t = np.zeros(self.basis.N)
        t[self.wall_dofs] = self.wall_values_k(wall_temp_k)
        r = rhs - a @ t
        t[self.free] = lu.solve(r[self.free])
        residual = a @ t - rhs  # heat into the coolant at each wall dof [W]
        heat = self.wall_weights.T @ residual[self.wall_dofs]
        return t, heat

    def response(self, dt_s: float = math.inf) -> np.ndarray:
        """Matrix G (n_segments, n_segments + 1) [W/K]: heat per segment = G @ [T_wall..., T_in]
        in steady state (``dt_s`` = inf) or, for an implicit Euler step of ``dt_s`` [s], the
        part of the step's heat that depends on them (the rest comes from the previous field)."""
        key = float(dt_s)
        if key not in self._response:
            g = np.empty((self.n_segments, self.n_segments + 1))
            zero = np.zeros(self.basis.N)
            for j in range(self.n_segments + 1):
                e = np.zeros(self.n_segments + 1)
                e[j] = 1.0
                g[:, j] = self.solve(e[:-1], float(e[-1]), dt_s=key, previous_k=zero)[1]
            self._response[key] = g
        return self._response[key]

    def outlet_temp_k(self, t: np.ndarray) -> float:
        """Mixing-cup outlet temperature [K] of the temperature dofs ``t`` [K]."""
        from skfem import Functional
        from skfem.helpers import dot

        @Functional
        def enthalpy(w: Any) -> Any:
            return dot(w["u"], w.n) * w["t"]

        flux = float(enthalpy.assemble(self._fb_out, u=self._u_out, t=self._fb_out.interpolate(t)))
        return flux / self.flow_m3_s

    def local_film(
        self, wall_temp_k: np.ndarray, inlet_temp_k: float, heat_w: np.ndarray
    ) -> dict[str, np.ndarray]:
        """Bulk temperature at the segment ends [K], local film [W/(m^2 K)] and Nusselt number [-]
        per segment, defined as in the module docstring (needs T_w on the same side of T_b)."""
        tb = inlet_temp_k + np.concatenate(([0.0], np.cumsum(heat_w))) / self.capacity_rate_w_k
        tw = np.asarray(wall_temp_k, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            h = self.capacity_rate_w_k / self.wall_area_m2 * np.log((tw - tb[:-1]) / (tw - tb[1:]))
        return {"bulk_temp_k": tb, "film_w_m2k": h, "nusselt": h * self.dh_m / self.coolant.conductivity_w_mk}

    def check_resolution(self, length_m: float) -> dict[str, float]:
        """Warn (:class:`ThermalMeshWarning`) when the cells across the channel height do not
        resolve the (laminar) thermal boundary layer one segment (``length_m`` [m]) from the
        inlet; not on a RANS flow, whose wall treatment checks its own mesh."""
        sec_h = self.channel.height_m
        cells_h = float(self.flow.metrics["cells_across_height"])
        cell = sec_h / cells_h
        delta = thermal_boundary_layer_m(length_m, self.dh_m, self.peclet)
        need = math.ceil(CELLS_PER_BOUNDARY_LAYER * sec_h / delta)
        # a laminar (Leveque) boundary layer: on a RANS flow the wall treatment checks the mesh
        if delta < CELLS_PER_BOUNDARY_LAYER * cell and self.flow.rans is None:
            warnings.warn(
                f"{self.where}: the coolant mesh has {cells_h:.0f} cells across the channel height "
                f"({cell * 1e3:.3g} mm each) but the thermal boundary layer is {delta * 1e3:.3g} mm thick "
                f"{length_m * 1e3:.3g} mm from the inlet (Peclet {self.peclet:.0f}); the wall heat there is "
                f"under-resolved. Use flow.cells_across_height >= {need} "
                f"(and cells_across_width in proportion) for a converged local Nusselt number.",
                ThermalMeshWarning,
                stacklevel=2,
            )
        return {"boundary_layer_m": delta, "cells_across_height": cells_h, "cells_needed": float(need)}


def vertex_interpolation(basis: Any) -> Any:
    """Sparse (N, N) map [-] of P2 dofs to the P2 dofs of their P1 vertex interpolant: vertex
    dofs are kept, an edge's midpoint dof becomes the mean of its two vertex dofs."""
    from scipy.sparse import coo_matrix

    nodal, edge = basis.nodal_dofs[0], basis.edge_dofs[0]
    ends = nodal[basis.mesh.edges]  # (2, edges): the vertex dofs at each edge's ends
    rows = np.concatenate((nodal, edge, edge))
    cols = np.concatenate((nodal, ends[0], ends[1]))
    vals = np.concatenate((np.ones(nodal.size), np.full(2 * edge.size, 0.5)))
    return coo_matrix((vals, (rows, cols)), shape=(basis.N, basis.N)).tocsr()


def _divergence_correction(basis: Any, u_q: Any, rc: float) -> Any:
    """Matrix [W/K] of ``int rho c_p (T - I_1 T) v div u`` (``I_1``: :func:`vertex_interpolation`),
    the term that makes the discrete energy balance exact on a Taylor-Hood velocity; see
    :class:`CoolantThermal`."""
    from scipy.sparse import identity
    from skfem import BilinearForm
    from skfem.helpers import div

    @BilinearForm
    def divergence_mass(t: Any, v: Any, w: Any) -> Any:
        return rc * div(w["u"]) * t * v

    d = divergence_mass.assemble(basis, u=u_q).tocsr()
    return d @ (identity(basis.N, format="csr") - vertex_interpolation(basis))


def write_cht_vtu(model: CoolantThermal, temp_k: np.ndarray, path: Any) -> None:
    """Coolant temperature [K], velocity [m/s] and pressure [Pa] at the mesh vertices to a
    VTU file (meshio)."""
    import meshio

    fl = model.flow
    meshio.write(
        str(path),
        meshio.Mesh(
            fl.mesh.p.T,
            [("tetra", fl.mesh.t.T)],
            point_data={
                "temperature_k": np.asarray(temp_k)[model.basis.nodal_dofs[0]],
                "velocity_mps": fl.vertex_velocity_mps(),
                "pressure_pa": fl.pressure,
            },
        ),
    )


@dataclass
class ChtResult:
    """A coolant heat-transfer run at a uniform wall temperature: scalar figures (SI, names
    carry units), per-segment table (arc length [m], area [m^2], heat [W], bulk temperature
    [K], film [W/(m^2 K)], Nusselt [-], the 1-D model's film and Nusselt) and the fields."""

    metrics: dict[str, float]
    segments: dict[str, np.ndarray]
    model: CoolantThermal
    temp_k: np.ndarray


def channel_axis_m(cfg: Any) -> np.ndarray:
    """The polyline along which the wall is cut into segments: the plate's serpentine centre
    line, or the duct's axis, (P, 3) [m]."""
    g = cfg.geometry
    if cfg.flow.channel == "duct":
        w, h = g.channel_width_m, g.channel_height_m
        return np.array([[0.0, w / 2, h / 2], [cfg.flow.duct_length_m, w / 2, h / 2]])
    return np.asarray(g.channel_path_m())


def run_cht(cfg: Any, flow: FlowResult) -> ChtResult:
    """Coolant heat transfer of a :class:`~hevsim.thermal.flow.FlowConfig` (``[flow]``) with the
    whole wall at ``flow.wall_temp_c`` and the inlet at ``coolant.inlet_temp_c``; compares the
    local film and Nusselt number with the 1-D channel model's correlation
    (:class:`~hevsim.thermal.coolant.ChannelModel`), which also gives its outlet temperature.
    ``flow``: the solved flow of the same config (:func:`hevsim.thermal.flow.run_flow` with
    ``thermal=True`` solves both)."""
    from hevsim.thermal.coolant import ChannelModel
    from hevsim.units import KELVIN_OFFSET

    channel = config_channel(cfg)
    axis = channel_axis_m(cfg)
    n = int(cfg.segments)
    model = CoolantThermal(flow, channel, cfg.coolant, axis, n, cfg.name, thermal_wall=cfg.flow.thermal_wall)
    length_m = float(np.linalg.norm(np.diff(axis, axis=0), axis=1).sum())
    res = model.check_resolution(length_m / n)
    t_in, t_w = cfg.inlet_temp_c + KELVIN_OFFSET, cfg.flow.wall_temp_c + KELVIN_OFFSET
    wall = np.full(n, t_w)
    temp, heat = model.solve(wall, t_in)
    local = model.local_film(wall, t_in, heat)
    one_d = ChannelModel(
        n,
        inlet_temp_k=t_in,
        flow_m3_s=cfg.flow_m3_s,
        width_m=channel.width_m,
        height_m=channel.height_m,
        coolant=cfg.coolant,
    )
    one_d.fluid_temperature_k(wall, model.wall_area_m2)
    t_out = model.outlet_temp_k(temp)
    rise = model.capacity_rate_w_k * (t_out - t_in)
    k = cfg.coolant.conductivity_w_mk
    metrics = {
        "inlet_temp_k": t_in,
        "wall_temp_k": t_w,
        "outlet_temp_k": t_out,
        "heat_w": float(heat.sum()),
        "enthalpy_rise_w": rise,
        "energy_imbalance_rel": abs(float(heat.sum()) - rise) / max(abs(rise), 1e-300),
        "outlet_temp_1d_k": one_d.outlet_temp_k,
        "heat_1d_w": one_d.heat_w,
        "film_1d_w_m2k": one_d.h_w_m2k,
        "nusselt_1d": one_d.nusselt,
        "nusselt_developed_shah_london": shah_london_nu_t(channel.height_m / channel.width_m),
        "mean_film_w_m2k": float(heat.sum() / (model.wall_area_m2.sum() * _lmtd_k(t_w, t_in, t_out))),
        "peclet": model.peclet,
        "thermal_boundary_layer_m": res["boundary_layer_m"],
        "temperature_dofs": float(model.basis.N),
        **model.wall_metrics(),
    }
    metrics["mean_nusselt"] = metrics["mean_film_w_m2k"] * model.dh_m / k
    s_end = np.arange(1, n + 1) * length_m / n
    segs = {
        "arc_length_m": s_end - length_m / (2 * n),
        "wall_area_m2": model.wall_area_m2,
        "heat_w": heat,
        "bulk_temp_k": local["bulk_temp_k"][1:],
        "film_w_m2k": local["film_w_m2k"],
        "nusselt": local["nusselt"],
        "film_1d_w_m2k": one_d.heat_transfer_coefficient_w_m2k(),
        "nusselt_1d": np.full(n, one_d.nusselt),
    }
    return ChtResult(metrics, segs, model, temp)


def _lmtd_k(t_w: float, t_in: float, t_out: float) -> float:
    """Log-mean temperature difference [K] of a channel at uniform wall temperature."""
    a, b = t_w - t_in, t_w - t_out
    return (a - b) / math.log(a / b) if abs(a - b) > 1e-12 * abs(a) else a


def plot_nusselt(res: ChtResult, path: Any) -> None:
    """Local Nusselt number along the channel: 3-D (laminar or RANS) vs the 1-D model's
    correlation and, laminar, the Shah & London developed value, as a PNG (Agg canvas, no
    pyplot)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from hevsim.io import save_png

    fig = Figure(figsize=(7, 4))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    s = res.segments["arc_length_m"] * 1e3
    kind = _flow_kind(res)
    ax.plot(s, res.segments["nusselt"], "o-", ms=3, label=f"3-D {kind} (CHT), local")
    ax.plot(s, res.segments["nusselt_1d"], "--", label="1-D model correlation")
    if res.model.flow.rans is None:  # the laminar developed value
        ax.axhline(res.metrics["nusselt_developed_shah_london"], color="k", lw=0.8, ls=":",
                   label="developed, Shah & London")  # fmt: skip
    ax.set_xlabel("distance along the channel [mm]")
    ax.set_ylabel("Nusselt number [-]")
    ax.set_yscale("log")
    ax.legend()
    ax.set_title(f"wall {res.metrics['wall_temp_k'] - 273.15:g} degC, Pe {res.metrics['peclet']:.0f}")
    save_png(fig, path, 100)


def _flow_kind(res: ChtResult) -> str:
    """How the coolant's flow and wall were modelled, for labels."""
    if res.model.flow.rans is None:
        return "laminar"
    return "RANS, wall function" if res.metrics.get("wall_function") else "RANS, resolved wall"


def write_cht(res: ChtResult, out_dir: Any) -> None:
    """``cht_summary.json``, ``cht_segments.csv``, ``nusselt.png`` and ``temperature.vtu``
    into the (temporary) results folder ``out_dir``."""
    from pathlib import Path

    from hevsim.io import write_json

    out = Path(out_dir)
    write_json(out / "cht_summary.json", {"metrics": res.metrics})
    keys = list(res.segments)
    rows = np.column_stack([res.segments[k] for k in keys])
    np.savetxt(out / "cht_segments.csv", rows, delimiter=",", header=",".join(keys), comments="", fmt="%.10g")
    plot_nusselt(res, out / "nusselt.png")
    write_cht_vtu(res.model, res.temp_k, out / "temperature.vtu")


def format_cht(res: ChtResult) -> str:
    """A short text summary of a coolant heat-transfer run."""
    m = res.metrics
    from hevsim.units import KELVIN_OFFSET as c

    return "\n".join(
        [
            f"coolant heat transfer (wall {m['wall_temp_k'] - c:.4g} degC, inlet {m['inlet_temp_k'] - c:.4g} "
            f"degC, Pe {m['peclet']:.0f}): outlet {m['outlet_temp_k'] - c:.4f} degC (1-D model "
            f"{m['outlet_temp_1d_k'] - c:.4f} degC), heat {m['heat_w']:.5g} W (1-D {m['heat_1d_w']:.5g} W)",
            f"energy balance: wall heat {m['heat_w']:.10g} W, m_dot c_p dT {m['enthalpy_rise_w']:.10g} W "
            f"(relative {m['energy_imbalance_rel']:.1e})",
            f"mean Nusselt {m['mean_nusselt']:.4g} (1-D correlation {m['nusselt_1d']:.4g}, developed "
            f"Shah & London {m['nusselt_developed_shah_london']:.4g}); local "
            f"{np.nanmin(res.segments['nusselt']):.4g} .. {np.nanmax(res.segments['nusselt']):.4g}",
        ]
        + (
            [
                f"thermal wall function: y+ of the wall cells {m['wall_yplus_min']:.3g} .. "
                f"{m['wall_yplus_max']:.3g} (mean {m['wall_yplus_mean']:.3g}), "
                f"{100 * m['wall_beyond_log_layer_fraction']:.3g} % of the wall beyond the log layer, "
                f"mean friction velocity {m['friction_velocity_mean_mps']:.3g} m/s"
            ]
            if m.get("wall_function")
            else []
        )
    )

"""Heat transfer in the coolant with a frozen laminar flow field: the coolant side of the
conjugate heat-transfer (CHT) problem of the cooling plate.

Equation (constant properties: density rho [kg/m^3], specific heat c_p [J/(kg K)],
conductivity k [W/(m K)]) on the channel volume, velocity u [m/s] from
:func:`hevsim.thermal.flow.solve_flow` (solved once per operating point and frozen)::

    rho c_p (dT/dt + u . grad T) - k lap T = 0

Discretisation: P2 temperature on the flow's tetrahedral mesh, convective term in
conservative weak form ``-int rho c_p T u . grad v`` with streamline-upwind Petrov-Galerkin
stabilisation ``int tau (u . grad v) rho c_p (dT/dt + u . grad T)`` (tau = h'/(2|u|) (coth Pe_h
- 1/Pe_h) with the nodal spacing h' = h/2 and Pe_h = |u| h' / (2 alpha); the diffusive part of the
element residual, zero for P1 and small for P2 at the cell Peclet numbers where tau matters, is
left out). Boundaries: the wall (all channel faces but inlet and outlet) takes the plate's
wall temperature (Dirichlet, one value per coolant segment along the channel path); the
inlet takes the inflow enthalpy weakly (``int rho c_p (u . n) (T - T_in) v``, a Danckwerts
condition); the outlet carries its enthalpy out (no diffusive flux). Steady or implicit Euler.

The heat through the wall is the consistent residual of the Dirichlet rows (the heat each wall
degree of freedom must supply), so summed over the wall it equals the coolant's enthalpy rise
``m_dot c_p (T_out - T_in)`` (mixing-cup outlet temperature) to solver precision: the
discrete statement of the energy balance (the flow's discrete mass balance closes to ~1e-12).
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
from hevsim.thermal.coolant import Coolant, segments_along_path
from hevsim.thermal.flow import Channel, FlowResult

#: Cells of the mesh wanted across the thermal boundary layer [-]: 0.5 = one node spacing of
#: the P2 temperature (two per cell); fewer gives the coarse-mesh warning
#: (:class:`ThermalMeshWarning`).
CELLS_PER_BOUNDARY_LAYER = 0.5


#: Bins per segment in which a point counts as on a segment boundary (1e-6 of its length).
SUBDIVISIONS = 1_000_000


#: Polynomial order p of the temperature element: the SUPG length is h/p (the element's
#: nodal spacing), the usual choice for quadratic elements [-].
TAU_ORDER = 2.0


class ThermalMeshWarning(UserWarning):
    """The coolant mesh is too coarse for the thermal boundary layer it has to resolve."""


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
    """Sparse (points, n_segments) weights [-]: 1 for the segment along ``path_m`` a point lies
    in, 1/2 and 1/2 for a point on the boundary of two segments (within 1e-6 of a segment's
    length). Rows sum to 1, so heat summed over the segments is the total heat."""
    from scipy.sparse import coo_matrix

    fine = segments_along_path(points_m, path_m, n_segments * SUBDIVISIONS)
    seg, pos = np.divmod(fine, SUBDIVISIONS)
    low = (pos == 0) & (seg > 0)  # just after a boundary: share with the segment before
    high = (pos == SUBDIVISIONS - 1) & (seg < n_segments - 1)  # just before one: share with the next
    other = np.where(low, seg - 1, np.where(high, seg + 1, seg))
    w = np.where(low | high, 0.5, 1.0)
    rows = np.arange(len(seg))
    return coo_matrix(
        (np.concatenate((w, 1 - w)), (np.concatenate((rows, rows)), np.concatenate((seg, other)))),
        shape=(len(seg), n_segments),
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
    """

    flow: FlowResult
    channel: Channel
    coolant: Coolant
    path_m: np.ndarray
    n_segments: int
    where: str = "cht"

    def __post_init__(self) -> None:
        from skfem import BilinearForm, ElementTetP2, FacetBasis, LinearForm
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
        tol = 1e-9 * max(max(b[1] for b in self.channel.boxes), self.channel.width_m)
        mid = mesh.p[:, mesh.facets].mean(axis=1)
        bnd = mesh.boundary_facets()

        def plane(spec: tuple[float, float, float, int]) -> np.ndarray:
            x, y0, y1, _ = spec
            on = (np.abs(mid[0, bnd] - x) < tol) & (mid[1, bnd] > y0 - tol) & (mid[1, bnd] < y1 + tol)
            return bnd[on]

        f_in, f_out = plane(self.channel.inlet), plane(self.channel.outlet)
        f_wall = np.setdiff1d(bnd, np.union1d(f_in, f_out))

        @BilinearForm
        def advection_diffusion(t: Any, v: Any, w: Any) -> Any:
            ugv = dot(w["u"], grad(v))
            speed = np.sqrt(dot(w["u"], w["u"])) + 1e-300
            hp = w.h / TAU_ORDER
            pe = np.maximum(speed * hp / (2 * alpha), 1e-12)
            tau = hp / (2 * speed) * (1 / np.tanh(pe) - 1 / pe)
            return -rc * t * ugv + k * dot(grad(t), grad(v)) + tau * ugv * rc * dot(w["u"], grad(t))

        @BilinearForm
        def capacity(t: Any, v: Any, w: Any) -> Any:
            speed = np.sqrt(dot(w["u"], w["u"])) + 1e-300
            hp = w.h / TAU_ORDER
            pe = np.maximum(speed * hp / (2 * alpha), 1e-12)
            tau = hp / (2 * speed) * (1 / np.tanh(pe) - 1 / pe)
            return rc * t * (v + tau * dot(w["u"], grad(v)))

        @BilinearForm
        def boundary_flux(t: Any, v: Any, w: Any) -> Any:  # rho c_p (u . n) T v
            return rc * dot(w["u"], w.n) * t * v

        @LinearForm
        def boundary_inflow(v: Any, w: Any) -> Any:  # -rho c_p (u . n) v per kelvin of T_in
            return -rc * dot(w["u"], w.n) * v

        fb_in = FacetBasis(mesh, self.basis.elem, facets=f_in, intorder=4)
        fb_out = FacetBasis(mesh, self.basis.elem, facets=f_out, intorder=4)
        fu_in = FacetBasis(mesh, fl.basis_u.elem, facets=f_in, intorder=4)
        fu_out = FacetBasis(mesh, fl.basis_u.elem, facets=f_out, intorder=4)
        self.stiffness = (
            advection_diffusion.assemble(self.basis, u=u_q)
            + boundary_flux.assemble(fb_out, u=fu_out.interpolate(fl.velocity))
        ).tocsr()
        self.capacity = capacity.assemble(self.basis, u=u_q).tocsr()
        self.inflow = boundary_inflow.assemble(fb_in, u=fu_in.interpolate(fl.velocity))  # [W/K]
        self._fb_out, self._u_out = fb_out, fu_out.interpolate(fl.velocity)
        self.flow_m3_s = float(fl.metrics["flow_m3_s"])
        self.capacity_rate_w_k = rc * self.flow_m3_s
        # wall dofs, their segments; wall facet areas per segment
        self.wall_dofs = self.basis.get_dofs(f_wall).all()
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
        self.free = np.setdiff1d(np.arange(n), self.wall_dofs)
        self._lu: dict[float, Any] = {}
        self.dh_m = float(fl.metrics["hydraulic_diameter_m"])
        self.peclet = float(fl.metrics["reynolds"]) * c.prandtl
        self._response: dict[float, np.ndarray] = {}

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
        resolve the thermal boundary layer one segment (``length_m`` [m]) from the inlet."""
        sec_h = self.channel.height_m
        cells_h = float(self.flow.metrics["cells_across_height"])
        cell = sec_h / cells_h
        delta = thermal_boundary_layer_m(length_m, self.dh_m, self.peclet)
        need = math.ceil(CELLS_PER_BOUNDARY_LAYER * sec_h / delta)
        if delta < CELLS_PER_BOUNDARY_LAYER * cell:
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

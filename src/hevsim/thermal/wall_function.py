"""Thermal wall function for the coolant heat transfer on a turbulent (RANS) flow.

On the shipped plate at 10 L/min (Re about 3450, 50/50 glycol with Pr about 65) the
conduction sublayer at the channel wall is about 27 um thick; the coolant's FEM cells there
are millimetres thick. Resolving the sublayer needs graded wall cells of ~50 um over the whole
serpentine (several hundred thousand P2 tetrahedra), so the coolant heat transfer instead
bridges the wall cells with the law of the wall for temperature, the standard answer of CFD
codes (e.g. OpenFOAM's ``alphatJayatillekeWallFunction``).

**Model.** The wall temperature enters through a film on the wall facets instead of being
imposed on the wall nodes: the heat from the wall into the coolant is ``int h (T_w - T) dA``,
with the film per facet taken from the law of the wall for temperature::

    q_w = rho c_p u_tau (T_w - T_P) / T+(y+_P, Pr)

between the wall and the point P a wall element's height ``y_P`` [m] into the flow along the
facet's normal; ``y+_P = y_P u_tau / nu`` and ``T+`` is Kader's law of the wall
(:func:`kader_t_plus`), which blends the conduction sublayer ``T+ = Pr y+`` into the
logarithmic layer for any Prandtl number. The friction velocity ``u_tau`` [m/s] comes from the
RANS velocity at P through Spalding's law of the wall (:func:`spalding_friction_velocity`,
the law OpenFOAM's ``nutUSpaldingWallFunction`` uses for the flow), so it is local (lower in
the bends' recirculation, higher where the flow is pushed onto a wall) and valid from the
viscous sublayer to the log layer. The wall elements conduct with the eddy diffusivity of the
flow next to them (``nu_t / Pr_t`` at the wall vertices lifted to its value at their first
neighbours in the flow, :func:`lift_wall_values`): their temperature is the turbulent core's,
nearly uniform, as in a finite-volume wall cell, so the mixing-cup temperature is not biased
towards the wall. The film's resistance is the law's from the wall to P less the wall
element's own conduction resistance over ``y_P`` (:meth:`WallFunction.film_w_m2k`), so the
wall-to-P resistance adds up to the law's.

Below y+ about 5 (the viscous sublayer) Kader's law tends to ``T+ = Pr y+``: the law's
resistance becomes molecular conduction across ``y_P``, the element's own conduction is then
all of it, the film tends to infinity (floored at :data:`FILM_RESISTANCE_FLOOR`) and the wall
temperature is imposed as in the resolved model; a fine wall mesh so gives the resolved
answer (``tests/test_rans.py``). The law holds in the viscous, buffer and log layers,
up to y+ about 300 (:data:`YPLUS_LOG_MAX`) and a node no farther from the wall than about a
quarter of the hydraulic diameter (:data:`OUTER_FRACTION_MAX` of ``D_h / 2``): beyond, P lies
in the channel's core, where the velocity and temperature depart from the log laws (the
friction velocity from the centreline speed comes out too high and the core temperature is
taken for the bulk one); the coolant model warns with the fraction of such facets. The law is
that of developed, attached flow along a wall: in separated regions (behind the bends) and in
the thermal entry it is an approximation, as in every CFD code using it. The divergence-
corrected advection is unchanged, so the discrete energy balance of
:class:`hevsim.thermal.cht.CoolantThermal` stays exact (the film's heat is the wall heat).

References: B. A. Kader, Int. J. Heat Mass Transfer 24 (1981) 1541-1544 (temperature law of
the wall, all Pr); D. B. Spalding, J. Appl. Mech. 28 (1961) 455-458 (velocity law of the wall,
all y+); kappa = 0.41 and E = 9.8 as OpenFOAM's defaults.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

#: von Karman constant [-] and the log-law constant E [-] (B = ln(E) / kappa = 5.57), OpenFOAM's
#: defaults for its wall functions.
KAPPA = 0.41
LOG_LAW_E = 9.8
#: Wall-cell y+ above which the node is beyond the logarithmic layer (the wall function's range)
#: [-]; the CHT run warns above it.
YPLUS_LOG_MAX = 300.0
#: Newton iterations of the Spalding inversion (monotone from above; 1e-12 reached in < 30) [-].
SPALDING_ITERATIONS = 60
#: Largest u+ [-] of the Newton start (exp(kappa u+) stays finite; u+ = 100 is y+ ~ 1e17).
UPLUS_START_MAX = 100.0
#: Kader's conduction-to-log blending constants [-] (Kader 1981, eq. 9).
KADER_GAMMA_A = 0.01
KADER_GAMMA_B = 5.0
#: Smallest wall-film resistance, as a fraction of the law of the wall's from the wall to the
#: node [-]: in the viscous sublayer the element's own conduction is the whole law, and the
#: film tends to an imposed wall temperature (the resolved model).
FILM_RESISTANCE_FLOOR = 1e-3
#: Farthest node P from the wall for the law of the wall, as a fraction of half the hydraulic
#: diameter [-] (0.5: a quarter of D_h, the log layer's outer edge in duct flow is about
#: 0.2-0.3 of the half-height); the coolant model warns beyond it.
OUTER_FRACTION_MAX = 0.5
#: Edge of the viscous sublayer in wall units [-] (reported, not a switch: Kader's law blends).
VISCOUS_SUBLAYER_YPLUS = 5.0
#: Kader's log-layer slope Pr_t / kappa [-] (Kader 1981).
KADER_SLOPE = 2.12


def kader_t_plus(y_plus: Any, prandtl: float) -> np.ndarray:
    """Dimensionless temperature T+ = (T_w - T) rho c_p u_tau / q_w [-] at ``y_plus`` [-] for the
    molecular Prandtl number ``prandtl`` [-] (Kader 1981, without the outer-region term)::

        T+ = Pr y+ exp(-G) + (2.12 ln(1 + y+) + beta(Pr)) exp(-1/G)
        G = 0.01 (Pr y+)^4 / (1 + 5 Pr^3 y+),  beta = (3.85 Pr^(1/3) - 1.3)^2 + 2.12 ln Pr
    """
    yp = np.asarray(y_plus, dtype=float)
    pr = float(prandtl)
    beta = (3.85 * pr ** (1.0 / 3.0) - 1.3) ** 2 + KADER_SLOPE * math.log(pr)
    gamma = KADER_GAMMA_A * (pr * yp) ** 4 / (1.0 + KADER_GAMMA_B * pr**3 * yp)
    with np.errstate(divide="ignore", over="ignore"):
        blend = np.where(gamma > 0.0, np.exp(-1.0 / np.maximum(gamma, 1e-300)), 0.0)
    return np.asarray(pr * yp * np.exp(-gamma) + (KADER_SLOPE * np.log1p(yp) + beta) * blend)


def spalding_friction_velocity(speed_mps: Any, y_m: Any, nu_m2_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Friction velocity u_tau [m/s] and y+ [-] from the speed ``speed_mps`` [m/s] at the wall
    distance ``y_m`` [m] (arrays of one shape) and the kinematic viscosity ``nu_m2_s`` [m^2/s],
    by Spalding's law ``y+ = u+ + (1/E) (exp(k u+) - 1 - k u+ - (k u+)^2/2 - (k u+)^3/6)``.

    Solved for u+ from ``u+ y+ = U y / nu`` by Newton's method, which converges monotonically
    from the start sqrt(U y / nu) (the left side is convex and increasing in u+). Zero speed or
    distance gives u_tau = y+ = 0."""
    u = np.abs(np.asarray(speed_mps, dtype=float))
    y = np.asarray(y_m, dtype=float)
    re_y = u * y / nu_m2_s
    up = np.minimum(np.sqrt(re_y), UPLUS_START_MAX)
    for _ in range(SPALDING_ITERATIONS):
        ku = KAPPA * up
        ex = np.exp(ku)
        f = up + (ex - 1 - ku - ku**2 / 2 - ku**3 / 6) / LOG_LAW_E  # y+ of u+
        df = 1 + KAPPA * (ex - 1 - ku - ku**2 / 2) / LOG_LAW_E
        g = up * f - re_y
        dg = f + up * df
        step = np.where(dg > 0.0, g / np.where(dg > 0.0, dg, 1.0), 0.0)
        up = np.maximum(up - step, 0.0)
        if np.all(np.abs(step) <= 1e-13 * np.maximum(up, 1e-300)):
            break
    ok = up > 0.0
    u_tau = np.where(ok, u / np.where(ok, up, 1.0), 0.0)
    return u_tau, np.where(ok, re_y / np.where(ok, up, 1.0), 0.0)


@dataclass
class WallFunction:
    """The thermal wall function on the coolant's wall facets (module docstring).

    Per wall facet: ``y_m`` [m], the height of its element over it (the distance of the node
    in the flow, P); ``y_plus`` [-] and ``u_tau_mps`` [m/s] there; ``alpha_eff_m2_s``
    [m^2/s], the diffusivity that carries the law of the wall's flux across ``y_m``;
    ``element_alpha_m2_s`` [m^2/s], the mean diffusivity the element conducts with."""

    y_m: np.ndarray
    y_plus: np.ndarray
    u_tau_mps: np.ndarray
    alpha_eff_m2_s: np.ndarray
    element_alpha_m2_s: np.ndarray

    def film_w_m2k(self, rho_cp_j_m3k: float) -> np.ndarray:
        """Film [W/(m^2 K)] per wall facet between the wall temperature and the facet, for the
        volumetric heat capacity ``rho_cp_j_m3k`` [J/(m^3 K)]: the law of the wall's resistance
        from the wall to P, ``y_P / (rho c_p alpha_eff)``, less the element's own conduction
        resistance ``y_P / (rho c_p alpha_element)`` (so that wall to P adds up to the law), at
        least :data:`FILM_RESISTANCE_FLOOR` of the law's."""
        law = self.y_m / (rho_cp_j_m3k * self.alpha_eff_m2_s)
        own = self.y_m / (rho_cp_j_m3k * self.element_alpha_m2_s)
        return np.asarray(1.0 / np.maximum(law - own, FILM_RESISTANCE_FLOOR * law))

    def metrics(self, outer_m: float = math.inf) -> dict[str, float]:
        """Figures for a run's metrics: the y+ range of P over the wall facets and the fractions
        beyond the log layer (y+ above :data:`YPLUS_LOG_MAX` or P farther from the wall than
        ``outer_m`` [m]) and in the viscous sublayer (y+ < 5) [-], the largest wall cell [m]
        and the mean friction velocity [m/s]."""
        yp = self.y_plus
        return {
            "wall_function": 1.0,
            "wall_function_facets": float(yp.size),
            "wall_yplus_min": float(yp.min()),
            "wall_yplus_mean": float(yp.mean()),
            "wall_yplus_max": float(yp.max()),
            "wall_beyond_log_layer_fraction": float(np.mean((yp > YPLUS_LOG_MAX) | (self.y_m > outer_m))),
            "wall_yplus_in_viscous_sublayer_fraction": float(np.mean(yp < VISCOUS_SUBLAYER_YPLUS)),
            "wall_cell_max_m": float(self.y_m.max()),
            "friction_velocity_mean_mps": float(self.u_tau_mps.mean()),
        }


def lift_wall_values(mesh: Any, wall_vertices: np.ndarray, values: np.ndarray, passes: int = 3) -> np.ndarray:
    """``values`` at the mesh vertices with those on the wall (``wall_vertices``, indices)
    replaced by the largest value among their edge neighbours off the wall (repeated
    ``passes`` times for vertices whose neighbours all lie on the wall, as in corners): the
    eddy diffusivity, zero at the wall, lifted to its value at the first nodes in the flow so
    that the wall elements conduct like the flow next to them (the law of the wall carries
    the wall layer itself)."""
    out = np.array(values, dtype=float)
    todo = np.zeros(out.size, dtype=bool)
    todo[wall_vertices] = True
    a, b = mesh.edges
    for _ in range(passes):
        src = np.where(todo, -np.inf, out)
        best = np.full(out.size, -np.inf)
        np.maximum.at(best, a, src[b])
        np.maximum.at(best, b, src[a])
        fill = todo & np.isfinite(best)
        out[fill] = best[fill]
        todo &= ~fill
    return out


def wall_function(
    mesh: Any,
    wall_facets: np.ndarray,
    velocity_at: Any,
    element_alpha_m2_s: np.ndarray,
    nu_m2_s: float,
    prandtl: float,
) -> WallFunction:
    """The :class:`WallFunction` of the tetrahedral ``mesh``'s ``wall_facets``:
    ``velocity_at`` maps points (N, 3) [m] to velocities (N, 3) [m/s] (the flow at P, the
    point a facet's element height into the flow along its normal); ``element_alpha_m2_s``
    [m^2/s] the mean diffusivity of every element; coolant ``nu_m2_s`` [m^2/s] and
    ``prandtl`` [-]."""
    facets = mesh.facets[:, wall_facets]
    owner = mesh.f2t[0, wall_facets]
    p0, p1, p2 = (mesh.p[:, facets[i]] for i in range(3))
    normal = np.cross(p1 - p0, p2 - p0, axis=0)
    normal /= np.linalg.norm(normal, axis=0)
    centroid = (p0 + p1 + p2) / 3
    element_mid = mesh.p[:, mesh.t[:, owner]].mean(axis=1)
    normal *= np.sign(np.einsum("ij,ij->j", normal, element_mid - centroid))  # into the flow
    # height of the element over the facet: its vertex off the facet's plane
    heights = np.abs(np.einsum("ij,ikj->kj", normal, mesh.p[:, mesh.t[:, owner]] - centroid[:, None, :]))
    y = heights.max(axis=0)
    speed = np.linalg.norm(velocity_at((centroid + y * normal).T), axis=1)
    u_tau, y_plus = spalding_friction_velocity(speed, y, nu_m2_s)
    t_plus = kader_t_plus(y_plus, prandtl)
    alpha = nu_m2_s / prandtl
    ok = t_plus > 0.0
    alpha_eff = np.where(ok, u_tau * y / np.where(ok, t_plus, 1.0), alpha)
    return WallFunction(y, y_plus, u_tau, np.maximum(alpha_eff, alpha), element_alpha_m2_s[owner])

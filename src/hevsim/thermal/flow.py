"""Laminar coolant flow in the cooling plate's channel: steady incompressible Navier-Stokes.

Equations (constant density rho [kg/m^3] and viscosity mu [Pa s]) on the channel volume::

    rho (u . grad) u - mu lap u + grad p = 0,   div u = 0

with Taylor-Hood elements (P2 velocity, P1 pressure) on tetrahedra, solved by Picard
(Oseen) iterations followed by Newton iterations, each a sparse direct solve. Boundaries: the
inlet gets the prescribed velocity (the fully developed rectangular-duct profile, or a uniform
one) scaled so that its discrete flux equals the configured flow rate exactly; the walls are
no-slip; the outlet is a do-nothing (traction) boundary ``mu du/dn - p n = -p_out n``, which
sets the outlet's static pressure and is exact for developed flow.

The channel is the shipped plate's serpentine (:meth:`ModuleGeometry.channel_path_m`), or a
straight rectangular duct for verification, meshed as a structured tensor grid of tetrahedra
restricted to the union of the channel's axis-aligned boxes (the same boxes the module mesh
cuts out of the plate). ``flow.model`` chooses the solver: ``laminar`` (this module; a Reynolds
number above :data:`~hevsim.thermal.coolant.RE_LAMINAR_MAX` is refused with a message),
``rans`` (k-omega SST with OpenFOAM, :mod:`hevsim.thermal.rans`, read back onto this module's
mesh) or ``auto`` (the default: laminar up to ``RE_LAMINAR_MAX``, RANS above; the shipped
10 L/min case, Re about 3450 with the Table 4.4 properties, is transitional/turbulent).
Coolant properties are constant, so the field is solved once per operating point (flow rate,
temperature) and can be frozen for a thermal run.

Verification (``tests/test_thermal_flow.py``) uses the series solution for Poiseuille flow in
a rectangular duct: F. M. White, *Viscous Fluid Flow*, 3rd ed., McGraw-Hill (2006), eqs.
(3-48) (velocity) and (3-49) (flow rate), and the friction factors of R. K. Shah and A. L.
London, *Laminar Flow Forced Convection in Ducts*, Academic Press (1978), Table 44 / eq. (341).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import ConfigError, SimulationError
from hevsim.thermal.channel import (  # the shared base, re-exported where users import it
    CHANNEL_KINDS,
    FLOW_MODELS,
    INLET_PROFILES,
    L_MIN_TO_M3_S,
    THERMAL_WALL_MODES,
    Channel,
    FlowResult,
    FlowSection,
    channel_mesh,
    check_channel_mesh,
    config_channel,
    hydraulic_metrics,
)
from hevsim.thermal.channel import (
    duct_channel as duct_channel,
)
from hevsim.thermal.channel import (
    plate_channel as plate_channel,
)
from hevsim.thermal.channel import (
    port_facets as port_facets,
)
from hevsim.thermal.coolant import RE_LAMINAR_MAX, Coolant
from hevsim.thermal.geometry import ModuleGeometry

#: Terms of the rectangular-duct series (odd indices 1, 3, ..., 2 N - 1); the terms fall as
#: i^-3 (velocity) and i^-5 (flow rate), so 200 terms give ~1e-8 relative accuracy.
SERIES_TERMS = 200
#: Continuation in Reynolds number: the first level's Re is at most this [-] ...
CONTINUATION_START_RE = 50.0
#: ... and each level multiplies Re by this factor [-] up to the case's Re.
CONTINUATION_FACTOR = 3.0
#: Polynomial order of the velocity: the streamline-diffusion length is h / this (the P2
#: nodal spacing), as in the coolant's SUPG (:data:`hevsim.thermal.cht.TAU_ORDER`) [-].
STREAMLINE_ORDER = 2.0
#: Relative velocity update at which an intermediate continuation level counts as converged [-].
CONTINUATION_TOLERANCE = 1e-4


# --------------------------------------------------------------------------- closed forms
def duct_velocity_mps(
    y_m: np.ndarray, z_m: np.ndarray, width_m: float, height_m: float, gradient_pa_m: float, mu_pa_s: float
) -> np.ndarray:
    """Fully developed axial velocity [m/s] in a rectangular duct (White 2006, eq. 3-48).

    ``y_m`` in [-width/2, width/2], ``z_m`` in [-height/2, height/2] (duct centre at 0);
    ``gradient_pa_m`` = -dp/dx > 0 [Pa/m]; ``mu_pa_s`` the dynamic viscosity [Pa s]. The series
    runs over the shorter side's half-width ``a`` so it converges fast everywhere.
    """
    y, z = np.asarray(y_m, dtype=float), np.asarray(z_m, dtype=float)
    if width_m < height_m:  # a along the shorter side
        y, z = z, y
        width_m, height_m = height_m, width_m
    a, b = height_m / 2, width_m / 2  # z in [-a, a], y in [-b, b], a <= b
    u = np.zeros(np.broadcast(y, z).shape)
    for k in range(SERIES_TERMS):
        i = 2 * k + 1
        c = i * math.pi / (2 * a)
        # cosh(c y)/cosh(c b) written with exponentials of non-positive arguments (no overflow)
        ratio = np.exp(c * (np.abs(y) - b)) * (1 + np.exp(-2 * c * np.abs(y))) / (1 + math.exp(-2 * c * b))
        u += (-1) ** k * (1 - ratio) * np.cos(c * z) / i**3
    return 16 * a**2 * gradient_pa_m / (mu_pa_s * math.pi**3) * u


def duct_flow_m3_s(width_m: float, height_m: float, gradient_pa_m: float, mu_pa_s: float) -> float:
    """Volume flow [m^3/s] of developed laminar flow in a rectangular duct (White 2006, eq. 3-49)."""
    a, b = min(width_m, height_m) / 2, max(width_m, height_m) / 2
    s = sum(math.tanh((2 * k + 1) * math.pi * b / (2 * a)) / (2 * k + 1) ** 5 for k in range(SERIES_TERMS))
    return 4 * b * a**3 * gradient_pa_m / (3 * mu_pa_s) * (1 - 192 * a / (math.pi**5 * b) * s)


def duct_fanning_re(width_m: float, height_m: float) -> float:
    """Fanning friction factor times Reynolds number (Re on the hydraulic diameter) [-].

    From :func:`duct_flow_m3_s`: ``f Re = (-dp/dx) D_h^2 / (2 mu u_mean)``; Shah & London
    (1978) tabulate 14.227 (square), 15.548 (aspect 1/2), 18.233 (1/4), 24 (parallel plates).
    """
    area, dh = width_m * height_m, 2 * width_m * height_m / (width_m + height_m)
    u_mean = duct_flow_m3_s(width_m, height_m, 1.0, 1.0) / area
    return dh**2 / (2 * u_mean)


# --------------------------------------------------------------------------- configuration


_FLOW_BOUNDS: dict[str, tuple[float, float]] = {
    "flow.flow_l_min": (0.0, 1e4),
    "flow.outlet_pressure_pa": (-1e8, 1e8),
    "flow.duct_length_m": (1e-5, 10.0),
    "flow.cells_across_width": (2, 200),
    "flow.cells_across_height": (2, 200),
    "flow.cell_length_m": (1e-6, 1.0),
    "flow.picard_iterations": (0, 100),
    "flow.max_iterations": (1, 200),
    "flow.tolerance": (1e-14, 1e-2),
    "flow.wall_temp_c": (-50.0, 150.0),
    "flow.grad_div": (0.0, 1e6),
    "flow.streamline_diffusion": (0.0, 10.0),
    "flow.wall_cell_m": (0.0, 1.0),
    "flow.growth": (1.0, 3.0),
    "flow.turbulence_intensity": (1e-4, 0.5),
    "flow.turbulence_length_m": (0.0, 1.0),
    "flow.prandtl_turbulent": (0.1, 10.0),
    "flow.rans_cells_across_width": (2, 400),
    "flow.rans_cells_across_height": (2, 400),
    "flow.rans_cell_length_m": (1e-6, 1.0),
    "flow.rans_wall_cell_m": (0.0, 1.0),
    "flow.rans_iterations": (1, 100000),
    "flow.rans_tolerance": (1e-12, 1e-1),
    "flow.rans_processes": (1, 256),
}


@dataclass(frozen=True)
class FlowConfig:
    """A validated flow case: the module's geometry and coolant plus its ``[flow]`` section;
    the coolant's inlet temperature [°C] and wall segments (``[coolant]``) for the thermal run."""

    name: str = "flow"
    geometry: ModuleGeometry = field(default_factory=ModuleGeometry)
    coolant: Coolant = field(default_factory=Coolant)
    flow_m3_s: float = 10.0 * L_MIN_TO_M3_S
    flow: FlowSection = field(default_factory=FlowSection)
    inlet_temp_c: float = 15.0
    segments: int = 30


def flow_config_from_dict(
    data: dict[str, Any], source: str = "<dict>", base_dir: Path | None = None
) -> FlowConfig:
    """Validate a module TOML mapping with a ``[flow]`` section into a :class:`FlowConfig`.

    The other sections are validated as by ``hevsim thermal`` (one file describes the module);
    geometry and coolant properties come from ``[geometry]`` and ``[coolant]``.
    """
    from hevsim.schema import build_section
    from hevsim.thermal.run import coolant_from_section, thermal_config_from_dict

    data = dict(data)
    raw = data.pop("flow", {})
    thermal = thermal_config_from_dict(data, source, base_dir)
    choices = {
        "flow.inlet_profile": INLET_PROFILES,
        "flow.channel": CHANNEL_KINDS,
        "flow.model": FLOW_MODELS,
        "flow.thermal_wall": THERMAL_WALL_MODES,
    }
    sec = build_section(FlowSection, raw, source, "flow", choices, _FLOW_BOUNDS)
    if "flow_l_min" in raw and not sec.flow_l_min > 0.0:
        raise ConfigError(
            f"{source}: key 'flow.flow_l_min' = {sec.flow_l_min!r}; expected a positive inlet flow rate "
            "[L/min] (leave the key out to take coolant.flow_l_min)."
        )
    flow_l_min = sec.flow_l_min or thermal.coolant.flow_l_min
    if not flow_l_min > 0.0:
        raise ConfigError(
            f"{source}: key 'flow.flow_l_min' = {sec.flow_l_min!r} and coolant.flow_l_min = "
            f"{thermal.coolant.flow_l_min!r}; expected a positive inlet flow rate [L/min]."
        )
    coolant = coolant_from_section(thermal.coolant).check(f"{source}: [coolant]")
    cfg = FlowConfig(
        thermal.name,
        thermal.geometry,
        coolant,
        flow_l_min * L_MIN_TO_M3_S,
        sec,
        thermal.coolant.inlet_temp_c,
        thermal.coolant.segments,
    )
    _check_config_channel(cfg, source)
    return cfg


def _check_config_channel(cfg: FlowConfig, source: str) -> None:
    """Fail early (ConfigError naming the file and the geometry keys) when the config's channel
    does not connect the inlet to the outlet. The tensor mesh puts a node plane on every box
    face whatever its resolution, so the coarsest one (one cell across, boxes' own lengths)
    has the connectivity of the boxes' union."""
    g = cfg.geometry
    if cfg.flow.channel == "duct":
        keys = f"flow.duct_length_m = {cfg.flow.duct_length_m!r}"
    else:
        keys = (
            f"[geometry] channel_passes = {g.channel_passes}, channel_width_m = {g.channel_width_m!r}, "
            f"rows = {g.rows}, columns = {g.columns}, cell_pitch_m = {g.cell_pitch_m!r}, "
            f"margin_m = {g.margin_m!r}"
        )
    ch = config_channel(cfg)
    coarse = max(max(b[1] - b[0] for b in ch.boxes), ch.width_m)
    check_channel_mesh(channel_mesh(ch, 1, 1, coarse), ch, f"{source}: {keys}")


def load_flow_config(path: str | Path) -> FlowConfig:
    """Read and validate a module TOML file with a ``[flow]`` section."""
    from hevsim.schema import read_toml

    p = Path(path)
    return flow_config_from_dict(read_toml(p), str(p), p.parent)


# --------------------------------------------------------------------------- solver


def solve_flow(
    channel: Channel,
    coolant: Coolant,
    flow_m3_s: float,
    *,
    section: FlowSection | None = None,
    where: str = "flow",
    progress: bool = False,
    case_dir: str | Path | None = None,
) -> FlowResult:
    """Steady flow through ``channel`` at ``flow_m3_s`` [m^3/s]; see the module docstring.

    ``flow.model`` ``rans`` (or ``auto`` above the laminar limit) hands over to
    :func:`hevsim.thermal.rans.solve_rans` (``progress``: OpenFOAM's iterations on the
    terminal; ``case_dir``: keep its case there).

    Raises:
        ConfigError: the flow rate is not positive, or the Reynolds number is above the laminar
            limit with ``flow.model = "laminar"``; OpenFOAM is missing for a RANS solve.
        SimulationError: the nonlinear iterations do not converge.
    """
    from scipy.sparse import bmat
    from scipy.sparse.linalg import splu
    from skfem import Basis, BilinearForm, ElementTetP1, ElementTetP2, ElementVector, FacetBasis, LinearForm
    from skfem.helpers import ddot, div, dot, grad

    sec = section or FlowSection()
    coolant.check(f"{where}: coolant")
    if not (math.isfinite(flow_m3_s) and flow_m3_s > 0.0):
        raise ConfigError(f"{where}: flow rate {flow_m3_s!r} m^3/s; expected a finite positive flow rate.")
    rho, mu = coolant.density_kg_m3, coolant.viscosity_pa_s
    rho_eff = [rho]  # density in the convective term (continuation)
    w, h = channel.width_m, channel.height_m
    area, dh = w * h, 2 * w * h / (w + h)
    u_mean = flow_m3_s / area
    re = rho * u_mean * dh / mu
    if sec.model == "rans" or (sec.model == "auto" and re > RE_LAMINAR_MAX):
        from hevsim.thermal.rans import solve_rans

        return solve_rans(
            channel, coolant, flow_m3_s, section=sec, where=where, case_dir=case_dir, progress=progress
        )
    if re > RE_LAMINAR_MAX:
        raise ConfigError(
            f"{where}: flow rate {flow_m3_s / L_MIN_TO_M3_S:.4g} L/min gives Re = {re:.0f} in the "
            f"{w * 1e3:g} x {h * 1e3:g} mm channel (D_h = {dh * 1e3:.3g} mm, nu = {mu / rho:.3g} m^2/s); "
            f'the laminar solver needs Re <= {RE_LAMINAR_MAX:g} (flow.model = "rans" or "auto" '
            f"solves it with OpenFOAM's k-omega SST). Or use flow.flow_l_min <= "
            f"{RE_LAMINAR_MAX * mu * area / (rho * dh) / L_MIN_TO_M3_S:.3g}."
        )
    cell_m = max(sec.cell_length_m, w / sec.cells_across_width, h / sec.cells_across_height)
    cell_re = rho * u_mean * cell_m / mu
    t0 = time.perf_counter()
    mesh = channel_mesh(channel, sec.cells_across_width, sec.cells_across_height, sec.cell_length_m)
    e_u = ElementVector(ElementTetP2())
    basis_u = Basis(mesh, e_u, intorder=4)
    basis_p = basis_u.with_element(ElementTetP1())
    tol = 1e-9 * max(channel.boxes[0][1], w, h)

    def plane(spec: tuple[float, float, float, int]) -> np.ndarray:
        x, y0, y1, _ = spec
        mid = mesh.p[:, mesh.facets].mean(axis=1)
        on = (np.abs(mid[0] - x) < tol) & (mid[1] > y0 - tol) & (mid[1] < y1 + tol)
        return np.intersect1d(mesh.boundary_facets(), np.nonzero(on)[0])

    f_in, f_out = plane(channel.inlet), plane(channel.outlet)
    if f_in.size == 0 or f_out.size == 0:
        raise ConfigError(f"{where}: the channel mesh has no inlet or outlet face; check the geometry.")
    check_channel_mesh(mesh, channel, where)
    fb_in = FacetBasis(mesh, e_u, facets=f_in, intorder=4)
    fb_out = FacetBasis(mesh, e_u, facets=f_out, intorder=4)

    @BilinearForm
    def viscous(u: Any, v: Any, _: Any) -> Any:
        return mu * ddot(grad(u), grad(v))

    @BilinearForm
    def divergence(u: Any, q: Any, _: Any) -> Any:
        return div(u) * q

    @BilinearForm
    def oseen(u: Any, v: Any, wf: Any) -> Any:  # rho (w . grad) u . v
        return rho_eff[0] * dot(np.einsum("j...,ij...->i...", wf["w"], grad(u)), v)

    @BilinearForm
    def newton_extra(u: Any, v: Any, wf: Any) -> Any:  # rho (u . grad) w . v
        return rho_eff[0] * dot(np.einsum("ij...,j...->i...", grad(wf["w"]), u), v)

    @LinearForm
    def newton_rhs(v: Any, wf: Any) -> Any:  # rho (w . grad) w . v
        return rho_eff[0] * dot(np.einsum("j...,ij...->i...", wf["w"], grad(wf["w"])), v)

    @LinearForm
    def outlet_traction(v: Any, wf: Any) -> Any:
        return -sec.outlet_pressure_pa * dot(v, wf.n)

    @LinearForm
    def flux(v: Any, wf: Any) -> Any:
        return dot(v, wf.n)

    def streamline_tau(wf: Any) -> Any:  # SUPG tau [s] of the iterate wf["w"]
        speed = np.sqrt(dot(wf["w"], wf["w"])) + 1e-300
        hp = wf.h / STREAMLINE_ORDER
        pe = np.maximum(speed * hp * rho_eff[0] / (2 * mu), 1e-12)
        return sec.streamline_diffusion * hp / (2 * speed) * (1 / np.tanh(pe) - 1 / pe)

    def along(a: Any, g: Any) -> Any:  # (a . grad) of the field with gradient g
        return np.einsum("j...,ij...->i...", a, g)

    @BilinearForm
    def streamline_picard(u: Any, v: Any, wf: Any) -> Any:
        return rho_eff[0] * streamline_tau(wf) * dot(along(wf["w"], grad(u)), along(wf["w"], grad(v)))

    @BilinearForm
    def streamline_newton(u: Any, v: Any, wf: Any) -> Any:  # d/du of tau rho (u.grad u).(u.grad v)
        w_, gw = wf["w"], grad(wf["w"])
        du = along(w_, grad(u)) + along(u, gw)
        return (
            rho_eff[0]
            * streamline_tau(wf)
            * (dot(du, along(w_, grad(v))) + dot(along(w_, gw), along(u, grad(v))))
        )

    @LinearForm
    def streamline_rhs(v: Any, wf: Any) -> Any:  # J(w) w - T(w) = 2 T(w) (T cubic in w, tau frozen)
        w_ = wf["w"]
        return 2 * rho_eff[0] * streamline_tau(wf) * dot(along(w_, grad(w_)), along(w_, grad(v)))

    @BilinearForm
    def grad_div(u: Any, v: Any, _: Any) -> Any:
        return div(u) * div(v)

    a_visc = viscous.assemble(basis_u)
    if sec.grad_div > 0.0:
        a_visc = a_visc + sec.grad_div * (mu + rho * u_mean * dh) * grad_div.assemble(basis_u)
    b_div = divergence.assemble(basis_u, basis_p)
    f_u = outlet_traction.assemble(fb_out)
    n_u, n_p = basis_u.N, basis_p.N
    # Dirichlet data: walls 0, inlet profile scaled to the exact discrete flux
    d_all = basis_u.get_dofs(np.setdiff1d(mesh.boundary_facets(), f_out)).all()
    in_x = basis_u.get_dofs(f_in).all("u^1")
    x_d = np.zeros(n_u)
    y_loc, z_loc = basis_u.doflocs[1, in_x], basis_u.doflocs[2, in_x]
    _, y0, y1, direction = channel.inlet
    z0 = channel.boxes[0][4]
    on_wall = np.isin(
        in_x, basis_u.get_dofs(np.setdiff1d(mesh.boundary_facets(), np.union1d(f_in, f_out))).all()
    )
    if sec.inlet_profile == "developed":
        prof = duct_velocity_mps(y_loc - (y0 + y1) / 2, z_loc - (z0 + h / 2), w, h, 1.0, 1.0)
    else:
        prof = np.ones(in_x.size)
    prof[on_wall] = 0.0
    x_d[in_x] = direction * prof
    phi_in = flux.assemble(fb_in)  # outward normal: inflow is negative
    x_d *= -flow_m3_s / float(phi_in @ x_d)
    free = np.setdiff1d(np.arange(n_u + n_p), d_all)

    def solve(a_uu: Any, rhs_u: np.ndarray) -> np.ndarray:
        k = bmat([[a_uu, -b_div.T], [-b_div, None]], format="csc")
        rhs = np.concatenate([rhs_u, np.zeros(n_p)])
        x = np.concatenate([x_d, np.zeros(n_p)])
        rhs = rhs - k @ x
        x[free] = splu(k[free][:, free].tocsc()).solve(rhs[free])
        return x

    x = solve(a_visc, f_u)  # Stokes start
    history: list[float] = []
    # continuation in the convective term: Newton at Re levels rising by CONTINUATION_FACTOR
    # from at most CONTINUATION_START_RE to Re (Picard iterations first, at the lowest level)
    n_levels = max(
        1, math.ceil(math.log(max(re / CONTINUATION_START_RE, 1.0)) / math.log(CONTINUATION_FACTOR)) + 1
    )
    scales = [CONTINUATION_FACTOR ** (k - n_levels + 1) for k in range(n_levels)]
    converged = False
    iterations = 0
    for level, scale in enumerate(scales):
        rho_eff[0] = rho * scale
        target = sec.tolerance if level == n_levels - 1 else max(sec.tolerance, CONTINUATION_TOLERANCE)
        converged = False
        for it in range(sec.max_iterations):
            iterations += 1
            u_k = basis_u.interpolate(x[:n_u])
            a_conv = oseen.assemble(basis_u, w=u_k)
            picard = level == 0 and it < sec.picard_iterations
            sd = sec.streamline_diffusion > 0.0
            if picard:
                a_k, f_k = a_visc + a_conv, f_u
                if sd:
                    a_k = a_k + streamline_picard.assemble(basis_u, w=u_k)
            else:
                a_k = a_visc + a_conv + newton_extra.assemble(basis_u, w=u_k)
                f_k = f_u + newton_rhs.assemble(basis_u, w=u_k)
                if sd:
                    a_k = a_k + streamline_newton.assemble(basis_u, w=u_k)
                    f_k = f_k + streamline_rhs.assemble(basis_u, w=u_k)
            x_new = solve(a_k, f_k)
            size = max(float(np.linalg.norm(x_new[:n_u])), 1e-300)
            change = float(np.linalg.norm(x_new[:n_u] - x[:n_u])) / size
            history.append(change)
            x = x_new
            if not math.isfinite(change):
                break
            if change < target:
                converged = True
                break
        if not converged:
            raise SimulationError(
                f"{where}: Navier-Stokes iterations did not converge in {sec.max_iterations} iterations at "
                f"Re = {re * scale:.0f} (continuation level {level + 1} of {n_levels} towards "
                f"Re = {re:.0f}; last relative update {history[-1]:.3g}). The mesh has "
                f"{sec.cells_across_width} x {sec.cells_across_height} cells across the channel and a cell "
                f"Reynolds number of {cell_re:.0f} (mean velocity x largest cell size / nu); the Galerkin "
                "solver needs it well below 100 (flow.streamline_diffusion = "
                f"{sec.streamline_diffusion:g}; 1 stabilises it): refine flow.cells_across_width, "
                "flow.cells_across_height and flow.cell_length_m, set flow.streamline_diffusion = 1, or "
                "lower the flow rate."
            )
    vel, prs = x[:n_u], x[n_u:]
    q_in = -float(phi_in @ vel)
    q_out = float(flux.assemble(fb_out) @ vel)
    p_in = _face_mean(mesh, basis_p, prs, f_in)
    metrics = {
        **hydraulic_metrics(flow_m3_s, q_in, q_out, re, u_mean, dh, p_in, sec.outlet_pressure_pa),
        "max_velocity_mps": float(np.max(np.linalg.norm(vel[basis_u.nodal_dofs], axis=0))),
        "channel_volume_m3": _volume_m3(mesh),
        "iterations": float(iterations),
        "continuation_levels": float(n_levels),
        "velocity_dofs": float(n_u),
        "pressure_dofs": float(n_p),
        "elements": float(mesh.t.shape[1]),
        "cell_reynolds": cell_re,
        "cells_across_width": float(sec.cells_across_width),
        "cells_across_height": float(sec.cells_across_height),
        "solve_time_s": time.perf_counter() - t0,
    }
    return FlowResult(metrics, mesh, vel, prs, basis_u, basis_p, history)


def _volume_m3(mesh: Any) -> float:
    """Sum of the tetrahedra's volumes [m^3]."""
    e = mesh.p[:, mesh.t[1:]] - mesh.p[:, mesh.t[0]][:, None, :]
    return float(np.abs(np.einsum("ij,ij->j", e[:, 0], np.cross(e[:, 1], e[:, 2], axis=0))).sum() / 6.0)


def _face_mean(mesh: Any, basis_p: Any, p: np.ndarray, facets: np.ndarray) -> float:
    """Area-weighted mean of the P1 field ``p`` over boundary ``facets`` [same unit as p]."""
    from skfem import ElementTetP1, FacetBasis, Functional

    fb = FacetBasis(mesh, ElementTetP1(), facets=facets, intorder=2)

    @Functional
    def one(_: Any) -> Any:
        return 1.0 + 0.0 * _.x[0]

    @Functional
    def value(wf: Any) -> Any:
        return wf["p"]

    return float(value.assemble(fb, p=fb.interpolate(p)) / one.assemble(fb))


def run_flow(
    config: FlowConfig | str | Path,
    out_dir: str | Path | None = None,
    thermal: bool = False,
    progress: bool = False,
) -> FlowResult:
    """Solve the flow of a config; write ``summary.json`` and ``flow.vtu`` to ``out_dir``.

    ``thermal``: also the coolant heat transfer on the frozen flow (:func:`hevsim.thermal.cht.run_cht`,
    in ``res.cht``; files ``cht_summary.json``, ``cht_segments.csv``, ``nusselt.png``,
    ``temperature.vtu``). A RANS solve also leaves its OpenFOAM case in ``openfoam/``. The
    results folder appears atomically (:func:`hevsim.io.atomic_directory`). ``progress``: the
    RANS iterations on the terminal.
    """
    import tempfile

    cfg = config if isinstance(config, FlowConfig) else load_flow_config(config)
    with tempfile.TemporaryDirectory(prefix="hevsim-flow-") as work:
        case = Path(work) / "openfoam" if out_dir is not None else None
        res = solve_flow(
            config_channel(cfg), cfg.coolant, cfg.flow_m3_s, section=cfg.flow, where=cfg.name,
            progress=progress, case_dir=case,
        )  # fmt: skip
        _finish_flow(cfg, res, out_dir, thermal, case if res.rans is not None else None)
    return res


def _finish_flow(
    cfg: FlowConfig, res: FlowResult, out_dir: str | Path | None, thermal: bool, case: Path | None
) -> None:
    """The thermal run, metadata and result files of :func:`run_flow`."""
    if thermal:
        from hevsim.thermal.cht import run_cht

        res.cht = run_cht(cfg, res)
    res.metadata = {
        "name": cfg.name,
        "model": "rans" if res.rans is not None else "laminar",
        "channel": cfg.flow.channel,
        "flow": dataclasses.asdict(cfg.flow),
        "coolant": dataclasses.asdict(cfg.coolant),
        "history": res.history,
    }
    if out_dir is not None:
        from hevsim.io import atomic_directory, write_json

        with atomic_directory(out_dir) as tmp:
            write_json(tmp / "summary.json", {"metrics": res.metrics, "metadata": res.metadata})
            write_vtu(res, tmp / "flow.vtu")
            if res.cht is not None:
                from hevsim.thermal.cht import write_cht

                write_cht(res.cht, tmp)
            if case is not None:
                import shutil

                shutil.copytree(case, tmp / "openfoam", ignore=shutil.ignore_patterns("processor*"))


def write_vtu(res: FlowResult, path: str | Path) -> None:
    """Velocity [m/s] and pressure [Pa] at the vertices to a VTU file (meshio)."""
    import meshio

    meshio.write(
        str(path),
        meshio.Mesh(
            res.mesh.p.T,
            [("tetra", res.mesh.t.T)],
            point_data={
                "velocity_mps": res.vertex_velocity_mps(),
                "pressure_pa": res.pressure,
                **(
                    {}
                    if res.eddy_diffusivity_m2_s is None
                    else {"eddy_diffusivity_m2_s": res.eddy_diffusivity_m2_s}
                ),
            },
        ),
    )


def format_flow(res: FlowResult) -> str:
    """A short text summary of a flow result."""
    m = res.metrics
    rans = res.rans is not None
    kind = "turbulent flow (RANS k-omega SST, OpenFOAM)" if rans else "laminar flow"
    lines = [
        f"{kind}: {m['flow_l_min']:.4g} L/min, Re = {m['reynolds']:.0f}, mean velocity "
        f"{m['mean_velocity_mps']:.4g} m/s, max {m['max_velocity_mps']:.4g} m/s",
        f"pressure drop {m['pressure_drop_pa']:.6g} Pa, pump power {m['pump_power_w']:.6g} W",
        f"mass balance: inlet {m['inlet_flow_m3_s']:.6e} m^3/s, outlet {m['outlet_flow_m3_s']:.6e} m^3/s "
        f"(relative imbalance {m['mass_imbalance_rel']:.1e})",
    ]
    if rans:
        lines += [
            f"wall y+ {m['yplus_min']:.3g} .. {m['yplus_max']:.3g} (mean {m['yplus_mean']:.3g}); max nu_t/nu "
            f"{m['max_eddy_viscosity_ratio']:.3g}; pressure drop changed {m['pressure_drop_change_rel']:.1e} "
            "(relative) over the last tenth of the iterations",
            f"OpenFOAM: {m['rans_cells']:.0f} hexahedra, {m['iterations']:.0f} SIMPLE iterations "
            f"({'converged' if m['converged'] else 'NOT converged'}), {m['solve_time_s']:.2f} s; "
            f"read back onto {m['elements']:.0f} tetrahedra",
        ]
    else:
        lines.append(
            f"mesh: {m['elements']:.0f} tetrahedra, {m['velocity_dofs']:.0f} + {m['pressure_dofs']:.0f} "
            f"dofs, {m['iterations']:.0f} iterations, {m['solve_time_s']:.2f} s"
        )
    return "\n".join(lines)

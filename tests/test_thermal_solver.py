"""Validation of the FEM heat solver against analytic solutions (issue 5, item 6)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

pytest.importorskip("skfem")

from hevsim.thermal.materials import Material
from hevsim.thermal.mesh import ThermalMesh
from hevsim.thermal.solver import HeatModel, discretise

STEEL = Material("steel", 15.0, 8000.0, 500.0)


def box_mesh(
    nx: int, lengths=(0.02, 0.004, 0.004), ny: int = 1, parts_at: float | None = None
) -> ThermalMesh:
    """Box [0,Lx]x[0,Ly]x[0,Lz]; faces LEFT (x=0) and RIGHT (x=Lx); two parts split at x=parts_at."""
    from skfem import MeshTet

    lx, ly, lz = lengths
    m = MeshTet.init_tensor(
        np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1), np.linspace(0, lz, ny + 1)
    )
    p, t = m.p.T.copy(), m.t.T.copy()
    # orient right-handed
    v = np.einsum(
        "ij,ij->i", p[t[:, 1]] - p[t[:, 0]], np.cross(p[t[:, 2]] - p[t[:, 0]], p[t[:, 3]] - p[t[:, 0]])
    )
    t[v < 0] = t[v < 0][:, [1, 0, 2, 3]]
    tol = 1e-9
    left = m.facets[:, m.facets_satisfying(lambda x: x[0] < tol)].T
    right = m.facets[:, m.facets_satisfying(lambda x: x[0] > lx - tol)].T
    xc = p[t].mean(axis=1)[:, 0]
    if parts_at is None:
        part, names = np.zeros(len(t), dtype=int), ("a",)
    else:
        part, names = (xc > parts_at).astype(int), ("a", "b")
    return ThermalMesh(p, t, part, names, np.zeros(len(t), dtype=int), {"LEFT": left, "RIGHT": right})


def slab_series(x_over_a: np.ndarray, fo: float, bi: float, terms: int = 60) -> np.ndarray:
    """Analytic theta/theta0 of a plane wall of half-thickness a cooled on both faces."""
    out = np.zeros_like(x_over_a)
    for n in range(terms):
        lam = brentq(lambda z: z * np.tan(z) - bi, n * np.pi + 1e-12, n * np.pi + np.pi / 2 - 1e-12)
        c = 4.0 * np.sin(lam) / (2.0 * lam + np.sin(2.0 * lam))
        out += c * np.exp(-(lam**2) * fo) * np.cos(lam * x_over_a)
    return out


def slab_error(
    nx: int, theta: float = 0.5, steps: int = 400, dt: float = 0.05, start_s: float = 0.0
) -> float:
    """Max nodal error [K] after ``steps`` steps; starts from the exact field at ``start_s``."""
    lx, h, t0, tinf = 0.02, 3000.0, 350.0, 300.0
    mesh = box_mesh(nx, lengths=(lx, lx / nx, lx / nx))
    disc = discretise(
        mesh, {"a": STEEL}, film_w_m2k=0.0, surface_films={"LEFT": (h, tinf), "RIGHT": (h, tinf)}
    )
    a = lx / 2
    alpha = STEEL.conductivity_w_mk / STEEL.volumetric_heat_capacity_j_m3k
    x = disc.points_m[:, 0]

    def exact(t: float) -> np.ndarray:
        if t == 0.0:
            return np.full_like(x, t0)
        return tinf + (t0 - tinf) * slab_series(
            (x - a) / a, alpha * t / a**2, h * a / STEEL.conductivity_w_mk
        )

    model = HeatModel(disc, dt_s=dt, theta=theta, initial_temp_k=exact(start_s))
    for _ in range(steps):
        model.step()
    return float(np.max(np.abs(model.temp_k - exact(start_s + model.time_s))))


def test_slab_converges_at_second_order_in_space() -> None:
    errors = [slab_error(n) for n in (4, 8, 16)]
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert errors[-1] < 0.05  # K, out of a 50 K transient
    assert np.all(rates > 1.7), (errors, rates)


def test_time_order_implicit_euler_and_crank_nicolson() -> None:
    """Temporal error against a fine-step run on the same mesh: order 1 (IE) and 2 (CN)."""
    mesh = box_mesh(16, lengths=(0.02, 0.02 / 16, 0.02 / 16))
    disc = discretise(
        mesh, {"a": STEEL}, film_w_m2k=0.0, surface_films={"LEFT": (3000.0, 300.0), "RIGHT": (3000.0, 300.0)}
    )
    x = disc.points_m[:, 0]
    start = 300.0 + 50.0 * np.cos(np.pi * (x - 0.01) / 0.02)  # smooth start: no CN ringing

    def run(theta: float, dt: float) -> np.ndarray:
        model = HeatModel(disc, dt_s=dt, theta=theta, initial_temp_k=start)
        for _ in range(round(16.0 / dt)):
            model.step()
        return model.temp_k

    ref = run(0.5, 0.02)
    ie = [float(np.max(np.abs(run(1.0, dt) - ref))) for dt in (0.8, 0.4)]
    cn = [float(np.max(np.abs(run(0.5, dt) - ref))) for dt in (0.8, 0.4)]
    assert 0.85 < np.log2(ie[0] / ie[1]) < 1.3, ie
    assert np.log2(cn[0] / cn[1]) > 1.8, cn


def test_high_conductivity_limit_matches_lumped_ode() -> None:
    mat = Material("al", 1.0e6, 2700.0, 900.0)
    mesh = box_mesh(4, lengths=(0.03, 0.02, 0.01), ny=2)
    h, tinf, t0, power = 50.0, 300.0, 320.0, 5.0
    disc = discretise(mesh, {"a": mat}, film_w_m2k=h, ambient_k=tinf)
    model = HeatModel(disc, dt_s=1.0, theta=0.5, initial_temp_k=t0)
    model.set_cell_heat_w(power)
    area = 2 * (0.03 * 0.02 + 0.03 * 0.01 + 0.02 * 0.01)
    cap = 2700.0 * 900.0 * 0.03 * 0.02 * 0.01
    tau = cap / (h * area)
    for _ in range(600):
        model.step()
    exact = tinf + power / (h * area) + (t0 - tinf - power / (h * area)) * np.exp(-model.time_s / tau)
    assert np.ptp(model.temp_k) < 1e-3
    assert abs(model.temp_k.mean() - exact) < 2e-3 * abs(t0 - tinf)


@pytest.mark.parametrize("h_gap", [200.0, 5000.0])
def test_contact_resistance_matches_series_resistance(h_gap: float) -> None:
    mesh = box_mesh(6, lengths=(0.012, 0.005, 0.005), parts_at=0.006)
    k_a, k_b = Material("a", 5.0, 1000.0, 1000.0), Material("b", 50.0, 1000.0, 1000.0)
    h_l, h_r, t_l, t_r = 400.0, 900.0, 350.0, 290.0
    disc = discretise(
        mesh,
        {"a": k_a, "b": k_b},
        film_w_m2k=0.0,
        interface_conductance_w_m2k={"a|b": h_gap},
        surface_films={"LEFT": (h_l, t_l), "RIGHT": (h_r, t_r)},
    )
    model = HeatModel(disc, dt_s=1.0)
    temp = model.steady()
    area = 0.005 * 0.005
    r = (1 / h_l + 0.006 / 5.0 + 1 / h_gap + 0.006 / 50.0 + 1 / h_r) / area
    q = (t_l - t_r) / r
    x = disc.points_m[:, 0]
    on_a = (np.abs(x - 0.006) < 1e-9) & (disc.node_part == 0)
    on_b = (np.abs(x - 0.006) < 1e-9) & (disc.node_part == 1)
    jump = temp[on_a].mean() - temp[on_b].mean()
    assert jump == pytest.approx(q / (h_gap * area), rel=1e-6)
    left = temp[np.abs(x) < 1e-9].mean()
    assert t_l - left == pytest.approx(q / (h_l * area), rel=1e-6)
    assert disc.interfaces == {"a|b": pytest.approx(area)}


def test_steady_energy_balance_films_only() -> None:
    mesh = box_mesh(5, lengths=(0.02, 0.01, 0.01), ny=2)
    disc = discretise(mesh, {"a": STEEL}, film_w_m2k=20.0, ambient_k=295.0)
    model = HeatModel(disc, dt_s=1.0)
    model.set_cell_heat_w(3.0)
    model.steady()
    rep = model.report()
    assert rep.film_w == pytest.approx(3.0, rel=1e-9)


def test_lumped_capacity_keeps_the_maximum_principle() -> None:
    """No heat sources, a 30 degC module on a 15 degC coolant: no node should rise above
    30 degC. The consistent capacity matrix overshoots by kelvins next to the cooling front
    (spurious hot spots); the lumped one (default) stays within a few tenths of a kelvin (what
    is left comes from obtuse tetrahedra: positive off-diagonal conduction entries), and both
    hold the same total heat capacity."""
    from dataclasses import replace
    from pathlib import Path

    from hevsim.thermal.geometry import build_module_mesh
    from hevsim.thermal.run import load_thermal_config, module_model

    cfg = load_thermal_config(Path(__file__).resolve().parents[1] / "examples" / "module_thermal.toml")
    cfg = replace(cfg, geometry=replace(cfg.geometry, mesh_size_m=0.008))
    mesh = build_module_mesh(cfg.geometry)
    peaks = {}
    for kind in ("lumped", "consistent"):
        c = replace(cfg, simulation=replace(cfg.simulation, capacity=kind))
        _, _, model = module_model(c, mesh)
        model.set_cell_heat_w(0.0)
        peak = 0.0
        for _ in range(20):
            peak = max(peak, float(model.step().max()))
        peaks[kind] = peak - 303.15
        assert float(np.sum(model.capacity)) == pytest.approx(float(np.sum(model.disc.capacity)), rel=1e-12)
    assert 0.0 < peaks["lumped"] < 0.25, peaks
    assert peaks["consistent"] > 20 * peaks["lumped"], peaks  # the artefact lumping removes

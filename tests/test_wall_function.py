"""The laws of the wall behind the coolant's thermal wall function (hevsim.thermal.wall_function)
against closed forms and a peer correlation.

References: D. B. Spalding, J. Appl. Mech. 28 (1961) 455-458 (y+ as an explicit function of
u+; u+ = y+ in the viscous sublayer, u+ = ln(E y+) / kappa in the log layer); B. A. Kader,
Int. J. Heat Mass Transfer 24 (1981) 1541-1544; the peer: the thermal law of C. L. V.
Jayatilleke, Prog. Heat Mass Transfer 1 (1969) 193-329, as OpenFOAM's
``alphatJayatillekeWallFunction`` uses it: T+ = Pr_t (u+ + P), P = 9.24 ((Pr/Pr_t)^0.75 - 1)
(1 + 0.28 exp(-0.007 Pr/Pr_t)), Pr_t = 0.85.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hevsim.thermal import wall_function as wfn

NU = 8.0e-6  # the shipped glycol's kinematic viscosity [m^2/s]


def _spalding_y_plus(u_plus: np.ndarray) -> np.ndarray:
    """Spalding's law written out here (y+ explicit in u+), the test's own copy."""
    k, e = 0.41, 9.8
    ku = k * u_plus
    return u_plus + (np.exp(ku) - 1 - ku - ku**2 / 2 - ku**3 / 6) / e


def test_spalding_inversion_recovers_the_friction_velocity() -> None:
    u_tau = 0.3
    u_plus = np.array([0.2, 1.0, 5.0, 10.0, 15.0, 20.0, 25.0])
    y_plus = _spalding_y_plus(u_plus)
    y = y_plus * NU / u_tau
    got, yp = wfn.spalding_friction_velocity(u_plus * u_tau, y, NU)
    assert np.allclose(got, u_tau, rtol=1e-10) and np.allclose(yp, y_plus, rtol=1e-10)


def test_spalding_limits_are_the_viscous_and_log_laws() -> None:
    u_tau = 0.2
    # viscous sublayer: u+ = y+
    y = 0.5 * NU / u_tau
    speed = 0.5 * u_tau
    assert wfn.spalding_friction_velocity(np.array([speed]), np.array([y]), NU)[0][0] == pytest.approx(
        u_tau, rel=1e-3
    )
    # log layer: u+ = ln(E y+) / kappa
    y_plus = 2000.0
    speed = u_tau * math.log(9.8 * y_plus) / 0.41
    got = wfn.spalding_friction_velocity(np.array([speed]), np.array([y_plus * NU / u_tau]), NU)[0][0]
    assert got == pytest.approx(u_tau, rel=5e-3)
    # no flow: no friction velocity (and no NaN)
    u0, yp0 = wfn.spalding_friction_velocity(np.zeros(2), np.array([1e-3, 0.0]), NU)
    assert np.all(u0 == 0.0) and np.all(yp0 == 0.0)


@pytest.mark.parametrize("prandtl", [0.71, 3.56, 65.0])
def test_kader_conduction_sublayer_is_pr_y_plus(prandtl: float) -> None:
    y_plus = np.array([1e-3, 1e-2, 0.05])
    assert np.allclose(wfn.kader_t_plus(y_plus, prandtl), prandtl * y_plus, rtol=1e-4)


@pytest.mark.parametrize("prandtl", [0.71, 3.56, 65.0])
def test_kader_log_layer_against_jayatilleke(prandtl: float) -> None:
    pr_t = 0.85
    p = 9.24 * ((prandtl / pr_t) ** 0.75 - 1) * (1 + 0.28 * math.exp(-0.007 * prandtl / pr_t))
    for y_plus in (30.0, 100.0, 300.0):
        jayatilleke = pr_t * (math.log(9.8 * y_plus) / 0.41 + p)
        assert float(wfn.kader_t_plus(y_plus, prandtl)) == pytest.approx(jayatilleke, rel=0.12)


def test_film_is_the_law_less_the_element_and_tends_to_an_imposed_wall_temperature() -> None:
    rc = 3.4e6  # rho c_p [J/(m^3 K)]
    pr, y = 65.0, 1e-3
    alpha = NU / pr
    # log layer: the law's resistance less the element's own
    u_tau = 0.35
    yp = y * u_tau / NU
    a_eff = u_tau * y / float(wfn.kader_t_plus(yp, pr))
    a_el = 50 * a_eff
    wf = wfn.WallFunction(
        np.array([y]), np.array([yp]), np.array([u_tau]), np.array([a_eff]), np.array([a_el])
    )
    expect = 1.0 / (y / (rc * a_eff) - y / (rc * a_el))
    assert wf.film_w_m2k(rc)[0] == pytest.approx(expect, rel=1e-12)
    assert wf.film_w_m2k(rc)[0] > rc * u_tau / float(wfn.kader_t_plus(yp, pr))
    # viscous sublayer: law = conduction across y = the element's own -> floor (near-Dirichlet)
    fine = wfn.WallFunction(
        np.array([y]), np.array([0.01]), np.array([1e-3]), np.array([alpha]), np.array([alpha])
    )
    assert fine.film_w_m2k(rc)[0] == pytest.approx(rc * alpha / y / wfn.FILM_RESISTANCE_FLOOR)


def test_lift_wall_values_takes_the_first_neighbour_in_the_flow() -> None:
    from skfem import MeshTet

    m = MeshTet.init_tensor(np.linspace(0, 1, 3), np.linspace(0, 1, 4), np.linspace(0, 1, 4))
    z = m.p[2]
    values = z * (1 - z)  # zero on both z walls, 2/9 at the interior planes
    wall = np.nonzero((z == 0) | (z == 1))[0]
    lifted = wfn.lift_wall_values(m, wall, values)
    assert np.allclose(lifted, 2 / 9)
    off = np.setdiff1d(np.arange(m.p.shape[1]), wall)
    assert np.array_equal(lifted[off], values[off])

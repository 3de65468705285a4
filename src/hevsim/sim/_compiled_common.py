"""Pieces shared by the compiled forward loops (:mod:`hevsim.sim._compiled_conventional`,
:mod:`hevsim.sim._compiled_bev`): the road side of the energy audit."""

from __future__ import annotations

from numba import njit

from hevsim.components.body import grade_force, rolling_force

AUDIT_ROAD = ("aero", "rolling", "grade", "kinetic_vehicle")
"""Audit terms :func:`add_road_audit` fills, at indices 3-6 of a loop's audit array (after
``fuel``, ``genset_source``, ``battery_chemical``), as in :func:`hevsim.sim.forward._run`."""


@njit(cache=True, inline="always")
def add_road_audit(audit, v0, v1, v_mid, a, g, f, mass_kg, m_eff, crr, dt):
    """Add one step's road energies [J] to ``audit[3:7]`` (:data:`AUDIT_ROAD`): speeds at the
    start, end and middle of the step [m/s], acceleration [m/s²], grade [-], wheel force [N],
    mass and effective (rotating) mass [kg], rolling coefficient [-], step [s]. Aero is the
    rest of the road load of eq (32); nothing is added at a standstill."""
    if v_mid > 0.0:
        f_grade = grade_force(mass_kg, g)
        f_roll = rolling_force(mass_kg, g, crr)
        f_aero = f - m_eff * a - f_roll - f_grade
        audit[3] += f_aero * v_mid * dt
        audit[4] += f_roll * v_mid * dt
        audit[5] += f_grade * v_mid * dt
        audit[6] += 0.5 * m_eff * (v1 * v1 - v0 * v0)

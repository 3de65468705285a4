"""Pieces shared by the forward loops (the Python loop of :mod:`hevsim.sim.forward` and the
compiled ones of :mod:`hevsim.sim._compiled_conventional`, :mod:`hevsim.sim._compiled_bev`,
:mod:`hevsim.sim._compiled_hev`): the road side of the energy audit and the trace-following
bookkeeping of the run summary."""

from __future__ import annotations

import numpy as np
from numba import njit

from hevsim.components.body import grade_force, rolling_force
from hevsim.sim import kernel as K

AUDIT_ROAD = ("aero", "rolling", "grade", "kinetic_vehicle")
"""Audit terms :func:`add_road_audit` fills, at indices 3-6 of a loop's audit array (after
``fuel``, ``genset_source``, ``battery_chemical``), as in :func:`hevsim.sim.forward._run`."""


@njit(cache=True, inline="always")
def add_road_audit(audit, v0, v1, v_mid, a, g, f, mass_kg, m_eff, crr, crr_v, dt):
    """Add one step's road energies [J] to ``audit[3:7]`` (:data:`AUDIT_ROAD`): speeds at the
    start, end and middle of the step [m/s], acceleration [m/s²], grade [-], wheel force [N],
    mass and effective (rotating) mass [kg], rolling coefficients [-] and [s/m], step [s]. Aero is the
    rest of the road load of eq (32); nothing is added at a standstill."""
    if v_mid > 0.0:
        f_grade = grade_force(mass_kg, g)
        f_roll = rolling_force(mass_kg, g, crr, crr_v, v_mid)
        f_aero = f - m_eff * a - f_roll - f_grade
        audit[3] += f_aero * v_mid * dt
        audit[4] += f_roll * v_mid * dt
        audit[5] += f_grade * v_mid * dt
        audit[6] += 0.5 * m_eff * (v1 * v1 - v0 * v0)


@njit(cache=True, inline="always")
def track_step(err, v_mid, dt, limited, err_sq, err_max, dist, lim_s):
    """One step of the trace-following bookkeeping: speed error at the step's start
    ``err`` [m/s], mid-step speed [m/s], step [s], ``limited`` (1.0 when the car fell behind
    the trace, else 0.0). Returns the updated (sum of squared errors [m²/s²], largest error
    [m/s], distance [m], time limited [s])."""
    return err_sq + err * err, max(err_max, abs(err)), dist + v_mid * dt, lim_s + limited * dt


@njit(cache=True, inline="always")
def write_summary(summary, err_end, err_sq, err_max, n, dist, fuel, soc, eon, starts, lim_s, duration):
    """Fill ``summary`` (:data:`hevsim.sim.kernel.SUMMARY`) at the end of a run of ``n`` steps:
    the end error ``err_end`` [m/s] joins the RMS (over the ``n + 1`` samples) and the largest
    error; distance [m], fuel [kg], final SOC [-], engine-on time [s], engine starts, time
    limited [s], duration [s]."""
    err_sq += err_end * err_end
    err_max = max(err_max, abs(err_end))
    summary[K.S_DIST], summary[K.S_FUEL], summary[K.S_SOCF] = dist, fuel, soc
    summary[K.S_RMS], summary[K.S_MAXERR], summary[K.S_EON] = np.sqrt(err_sq / (n + 1)), err_max, eon
    summary[K.S_STARTS], summary[K.S_BLIM], summary[K.S_DUR] = starts, lim_s, duration

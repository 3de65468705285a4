"""Compiled electro-thermal cell kernel (thesis section 4.1.1, eqs 33-41).

Sign convention: current ``i`` [A] is positive on discharge (as in :mod:`hevsim.components.battery`),
so the removed charge ``Q = ∫ i dt`` (eq 33) grows on discharge and ``SOC = SOC_ini - Q / C``
(eq 37).

One step holds the current constant over ``dt`` and advances every state exactly for that
current: RC voltages and the lumped temperature by their exact exponentials (stable at any
step), charge by exact integration. Parameters that depend on temperature, SOC or Q_abs
(capacity eq 35, series resistance eq 36, OCV) are evaluated at the start of the step.

Two RC sets (discharge and charge), one connected at a time by the thesis's switch. The
connected set carries the current and appears in the terminal voltage; the disconnected set
is bypassed and relaxes through its own resistor (its stored energy becomes heat). The switch
(and the choice of the charge or discharge OCV and R_s table) follows the current direction
with a dead band: the direction changes only when the current leaves
``[-switch_band_a, +switch_band_a]``, and is kept otherwise (including at zero current), so a
current dithering around zero cannot make the model chatter between sets.

Energy bookkeeping per step (all exact for the piecewise-constant current):
``electrical out = -Δ(chemical) - Δ(RC capacitor energy) - heat``, with the chemical energy
change ``-OCV_k i dt`` (stored chemical energy is ``-∫ OCV dQ``) and heat ``R_s i² dt`` plus the
exact RC resistor losses ``∫ v²/R dt``.

Model options (parameter vector entries; all off by default, which is the thesis's model above,
bit for bit — see ``docs/battery.md``, "Cell model options"):

* ``rc_persistent`` = 1: one RC set carries the polarisation through current reversals. Its
  states are the first ``n_rc`` RC voltages; the element parameters are those of the current
  direction's set (``rc_discharge`` / ``rc_charge``; give both the same values for the
  symmetric set of linear diffusion). The set is always connected, so a reversal neither drops
  nor resets the slow polarisation. Energy closes exactly when both sets are equal (a switch
  between unequal sets keeps the voltage and changes the capacitance).
* ``ocv_in_step`` = 1: the OCV is consistent within the step: the end-of-step voltage uses the
  OCV at the end-of-step SOC, the step-average voltage and the chemical energy the exact mean
  of the (piecewise-linear) OCV over the step's linear SOC path, and R_s the mid-step SOC, so
  the terminal voltage is second order in the step (the thesis's start-of-step OCV leaves an
  error ``dOCV/dSOC · i dt / C``).
* ``ct_i0_a`` > 0: a Butler-Volmer (symmetric, alpha = 1/2) charge-transfer overpotential
  ``eta = m (2 R T / F) asinh(i / (2 i0))`` in series with R_s (``m`` = ``ct_scale``, ``i0`` =
  ``ct_i0_a / r_scale`` times an Arrhenius factor with ``ct_ea_j_per_mol``): its resistance
  falls with current. Its heat is ``eta i``.
* ``hyst_max_v`` > 0: one-state hysteresis voltage ``h`` added to the terminal voltage,
  relaxing toward ``-M sign(i)`` with charge throughput:
  ``dh/dt = -gamma |i| / C (h + M sign(i))`` (Plett's one-state model), exact for the step;
  its work ``-h i`` counts as heat.

Temperature laws (issue 27; all off by default, which keeps the model above bit for bit):
every law is evaluated at the start-of-step cell temperature ``T`` [K] with the reference
``T_ref`` = ``t_ref_k``, as the Arrhenius factor ``A(Ea, T) = exp(Ea / R_gas (1/T - 1/T_ref))``
(> 1 below ``T_ref`` for ``Ea`` > 0; :func:`arrhenius`).

* OCV(SOC, T), R_s(SOC, T) and the capacity factor (T) are tables (clamped outside their
  temperature axis); ``rs_ea_j_per_mol`` multiplies R_s by ``A(Ea_Rs, T)`` on top of eq (36).
* RC elements: an RC set with four columns ``(R, tau, Ea_R, Ea_tau)`` has
  ``R_i(T) = R_i A(Ea_R, T)`` and ``tau_i(T) = tau_i A(Ea_tau, T)`` (two columns: constant).
* ``hyst_ea_j_per_mol``: hysteresis amplitude ``M(T) = M A(Ea_M, T)``.
* ``entropic_heat`` = 1: reversible (entropic) heat ``-i T dU/dT`` [W] (discharge > 0) adds to
  the heat, with ``dU/dT`` the temperature slope of the OCV table of the step's direction at the
  step's SOC (start of step; mid-step with ``ocv_in_step``) and ``T``; zero outside the table's
  temperature axis, where the OCV is clamped, and where the OCV is clamped to the voltage
  limits. The chemical energy of the step is then the enthalpy ``-(OCV - T dU/dT) i dt``, so
  the energy balance still closes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit, prange

from hevsim.tables import _segment, interp1, interp2

# --- parameter vector layout (one row per cell) ---------------------------------------------
PARAMS = (
    "c0_c",
    "k_cqabs",
    "alpha_c_per_k",
    "t_ref_k",
    "alpha_rs_per_k",
    "c_heat_j_per_k",
    "r_skin_k_per_w",
    "v_min_v",
    "v_max_v",
    "soc_initial",
    "r_scale",
    "n_rc",
    "switch_band_a",
    # model options (module docstring); zeros give the thesis's model
    "rc_persistent",
    "ocv_in_step",
    "ct_i0_a",
    "ct_scale",
    "ct_ea_j_per_mol",
    "hyst_max_v",
    "hyst_gamma",
    # temperature laws (issue 27; module docstring, "Temperature laws"); zeros: none
    "rs_ea_j_per_mol",
    "hyst_ea_j_per_mol",
    "entropic_heat",
)
C0, KCQ, ALPHAC, TREF, ALPHARS, CHEAT, RSKIN, VMIN, VMAX, SOCINI, RSCALE, NRC, IBAND = range(13)
RCPERS, OCVSTEP, CTI0, CTM, CTEA, HMAX, HGAMMA, EARS, HEA, ENTROPIC = range(13, len(PARAMS))

MODEL_SCALARS = {
    "ct_i0_a": CTI0,
    "ct_scale": CTM,
    "ct_ea_j_per_mol": CTEA,
    "hyst_max_v": HMAX,
    "hyst_gamma": HGAMMA,
    "rs_ea_j_per_mol": EARS,
    "hyst_ea_j_per_mol": HEA,
}
"""Scalar parameters of the model options that calibration fits: name -> index in the vector."""

R_GAS_J_PER_MOL_K = 8.314462618  # molar gas constant [J/(mol K)], CODATA 2018 (exact)
FARADAY_C_PER_MOL = 96485.33212  # Faraday constant [C/mol], CODATA 2018 (exact)


@njit(cache=True, inline="always")
def arrhenius(ea_j_per_mol, temp_k, t_ref_k):
    """Arrhenius factor ``exp(Ea / R_gas (1/T - 1/T_ref))`` [-] of a resistance-like quantity
    (activation energy [J/mol], temperatures [K]): 1 at ``T_ref``, > 1 below it for Ea > 0."""
    return math.exp(ea_j_per_mol / R_GAS_J_PER_MOL_K * (1.0 / temp_k - 1.0 / t_ref_k))


@njit(cache=True, inline="always")
def rc_values(rc, jj, temp_k, t_ref_k):
    """(R [ohm, before r_scale], tau [s]) of RC element row ``jj`` of the set ``rc`` at
    ``temp_k`` [K]: the table's values, times their Arrhenius factors when the set has the
    activation-energy columns ``(R, tau, Ea_R, Ea_tau)`` (module docstring)."""
    r = rc[jj, 0]
    tau = rc[jj, 1]
    if rc.shape[1] > 2:
        if rc[jj, 2] != 0.0:
            r *= arrhenius(rc[jj, 2], temp_k, t_ref_k)
        if rc[jj, 3] != 0.0:
            tau *= arrhenius(rc[jj, 3], temp_k, t_ref_k)
    return r, tau


TUNABLE_SCALARS = {
    "c0_c": C0,
    "alpha_c_per_k": ALPHAC,
    "alpha_rs_per_k": ALPHARS,
    "c_heat_j_per_k": CHEAT,
    "r_skin_k_per_w": RSKIN,
    "r_scale": RSCALE,
}
"""Scalar parameters that calibration fits and FMUs expose: name -> index in the vector."""

# --- state vector layout: then n_rc discharge RC voltages, then n_rc charge RC voltages [V] ---
STATES = ("q_c", "qabs_c", "temp_k", "direction", "cycles", "current_a", "hyst_v")
SQ, SQABS, STEMP, SDIR, SCYC, SILAST, SHYST = range(len(STATES))
N_FIXED_STATES = len(STATES)

# --- per-step record (what one step reports) -----------------------------------------------
RECORD = (
    "voltage_v",
    "voltage_avg_v",
    "ocv_v",
    "soc",
    "temp_k",
    "heat_w",
    "port_heat_w",
    "capacity_c",
    "rs_ohm",
    "e_elec_j",
    "e_chem_j",
    "e_heat_j",
    "e_port_j",
)
RV, RVAVG, ROCV, RSOC, RTEMP, RHEAT, RPORT, RCAP, RRS, REEL, RECH, REHEAT, REPORT = range(len(RECORD))


@njit(cache=True, inline="always")
def capacity_c(c0_c, k_cqabs, alpha_c_per_k, t_ref_k, qabs_c, temp_k, factor):
    """Capacity C [C] per eq (35) from the cell's parameters (C0 [C], k [-], alpha [1/K],
    T_ref [K]), its throughput ``qabs_c`` [C] and temperature [K], times the capacity factor
    [-] of the capacity-vs-temperature table at ``temp_k``."""
    return (c0_c + k_cqabs * qabs_c) * (1.0 + alpha_c_per_k * (temp_k - t_ref_k)) * factor


@njit(cache=True)
def cell_capacity(prm, t_ax, capf, qabs, temp_k):
    """Capacity C [C] per eq (35), times the optional capacity-vs-temperature factor table."""
    return capacity_c(
        prm[C0], prm[KCQ], prm[ALPHAC], prm[TREF], qabs, temp_k, interp1(t_ax, capf, temp_k, False)
    )


@njit(cache=True)
def cell_ocv_rs(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, soc, temp_k, direction):
    """OCV [V] (clamped to the voltage limits) and R_s [ohm] (eq 36) for a direction (+1 discharge)."""
    if direction >= 0.0:
        ocv = interp2(soc_ax, t_ax, ocv_d, soc, temp_k, False)
        r = interp2(soc_ax, t_ax, rs_d, soc, temp_k, False)
    else:
        ocv = interp2(soc_ax, t_ax, ocv_c, soc, temp_k, False)
        r = interp2(soc_ax, t_ax, rs_c, soc, temp_k, False)
    ocv = min(max(ocv, prm[VMIN]), prm[VMAX])
    if prm[EARS] != 0.0:
        r *= arrhenius(prm[EARS], temp_k, prm[TREF])
    return ocv, series_resistance(r, prm[RSCALE], prm[ALPHARS], temp_k, prm[TREF])


@njit(cache=True)
def series_resistance(rs_table_ohm, r_scale, alpha_rs_per_k, temp_k, t_ref_k):
    """Series resistance R_s [ohm], eq (36): the table value times the ageing scale [-] and
    ``1 + alpha_Rs (T - T_ref)`` (temperatures [K]); scalars or arrays."""
    return rs_table_ohm * r_scale * (1.0 + alpha_rs_per_k * (temp_k - t_ref_k))


@njit(cache=True)
def step_direction(i_a, last_direction, band_a):
    """+1 discharge, -1 charge; inside the dead band ``|i| <= band_a`` the last direction is kept."""
    if i_a > band_a:
        return 1.0
    if i_a < -band_a:
        return -1.0
    return last_direction


@njit(cache=True)
def cell_ocv(prm, soc_ax, t_ax, ocv_c, ocv_d, soc, temp_k, direction):
    """OCV [V] of a direction (+1 discharge) at ``soc`` [-], ``temp_k`` [K], clamped to the limits."""
    if direction >= 0.0:
        ocv = interp2(soc_ax, t_ax, ocv_d, soc, temp_k, False)
    else:
        ocv = interp2(soc_ax, t_ax, ocv_c, soc, temp_k, False)
    return min(max(ocv, prm[VMIN]), prm[VMAX])


@njit(cache=True)
def ocv_dudt(prm, soc_ax, t_ax, ocv_c, ocv_d, soc, temp_k, direction):
    """Entropic coefficient dU/dT [V/K] of a direction's OCV table at ``soc`` [-], ``temp_k``
    [K]: the temperature slope of the bilinear table (the segment above a breakpoint at a
    breakpoint); 0 with one temperature column, outside the temperature axis (clamped) and
    where the OCV is clamped to the voltage limits."""
    nt = t_ax.shape[0]
    if nt < 2 or temp_k < t_ax[0] or temp_k >= t_ax[nt - 1]:
        return 0.0
    raw = interp2(soc_ax, t_ax, ocv_d if direction >= 0.0 else ocv_c, soc, temp_k, False)
    if not prm[VMIN] < raw < prm[VMAX]:
        return 0.0
    j = _segment(t_ax, temp_k)
    s = min(max(soc, soc_ax[0]), soc_ax[soc_ax.shape[0] - 1])
    tab = ocv_d if direction >= 0.0 else ocv_c
    lo = interp1(soc_ax, tab[:, j], s, False)
    hi = interp1(soc_ax, tab[:, j + 1], s, False)
    return (hi - lo) / (t_ax[j + 1] - t_ax[j])


@njit(cache=True)
def ocv_step_mean(prm, soc_ax, t_ax, ocv_c, ocv_d, soc0, soc1, f0, f1, temp_k, direction):
    """Mean OCV [V] over a linear SOC path ``soc0 -> soc1`` at ``temp_k`` [K], given the OCVs
    ``f0``, ``f1`` [V] at its ends: exact for the piecewise-linear table (trapezoids between
    the SOC breakpoints inside the path)."""
    if soc1 == soc0:
        return f0
    lo, f_prev, hi, f = (soc0, f0, soc1, f1) if soc0 < soc1 else (soc1, f1, soc0, f0)
    f_hi = f
    acc = 0.0
    s_prev = lo
    for k in range(soc_ax.shape[0]):
        s = soc_ax[k]
        if lo < s < hi:
            f = cell_ocv(prm, soc_ax, t_ax, ocv_c, ocv_d, s, temp_k, direction)
            acc += 0.5 * (f + f_prev) * (s - s_prev)
            s_prev = s
            f_prev = f
    acc += 0.5 * (f_hi + f_prev) * (hi - s_prev)
    return acc / (hi - lo)


@njit(cache=True)
def ct_overpotential(prm, i_a, temp_k):
    """Charge-transfer overpotential [V] and its slope d eta / d i [ohm] at ``i_a`` [A] and
    ``temp_k`` [K] (module docstring); (0, 0) when the term is off (``ct_i0_a`` = 0)."""
    if prm[CTI0] <= 0.0:
        return 0.0, 0.0
    i0 = prm[CTI0] / prm[RSCALE]
    if prm[CTEA] != 0.0:
        i0 *= math.exp(-prm[CTEA] / R_GAS_J_PER_MOL_K * (1.0 / temp_k - 1.0 / prm[TREF]))
    b = prm[CTM] * 2.0 * R_GAS_J_PER_MOL_K * temp_k / FARADAY_C_PER_MOL
    u = i_a / (2.0 * i0)
    return b * math.asinh(u), b / (2.0 * i0 * math.sqrt(1.0 + u * u))


@njit(cache=True)
def hysteresis_step(prm, h0, i_a, dt, cap, temp_k):
    """One-state hysteresis over a step at constant ``i_a`` [A] at ``temp_k`` [K]: (end value
    [V], step mean [V])."""
    if prm[HMAX] <= 0.0 or i_a == 0.0:
        return h0, h0
    m = prm[HMAX]
    if prm[HEA] != 0.0:
        m *= arrhenius(prm[HEA], temp_k, prm[TREF])
    target = -m if i_a > 0.0 else m
    k = prm[HGAMMA] * abs(i_a) / cap  # decay rate [1/s]
    if k <= 0.0:
        return h0, h0
    e1 = math.exp(-k * dt)
    d = h0 - target
    return target + d * e1, target + d * (1.0 - e1) / (k * dt)


@njit(cache=True, inline="always")
def rc_element(j, n, persistent, direction, rc_d, rc_c):
    """RC state ``j`` (of ``n`` RC elements per set, ``persistent`` = ``rc_persistent`` on):
    ``(rc, jj, active)`` — its element is row ``jj`` of the set ``rc`` (``rc_d`` or ``rc_c``),
    connected (``active``) if that set is the one of the current ``direction``."""
    if persistent:
        return rc_d if direction > 0.0 else rc_c, j, True
    if j < n:
        return rc_d, j, direction > 0.0
    return rc_c, j - n, direction < 0.0


@njit(cache=True)
def branch_affine(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, dt, direction):
    """Step-average terminal voltage as ``E - Z i`` for a current of the given direction.

    Returns ``(E [V], Z [ohm])``: the cell's step-averaged voltage is exactly ``E - Z i`` for
    any constant current ``i`` of that direction over ``dt`` (used to share current between
    parallel cells). With the nonlinear model options (charge transfer, in-step OCV,
    hysteresis) it is the linearisation at the last step's current (:func:`branch_affine_at`).
    """
    i_lin = x[SILAST] if x[SILAST] * direction > 0.0 else 0.0
    return branch_affine_at(
        prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, dt, direction, i_lin
    )


@njit(cache=True)
def branch_affine_at(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, dt, direction, i_lin):
    """:func:`branch_affine` linearised at current ``i_lin`` [A]: ``E - Z i_lin`` is the exact
    step-average voltage at ``i_lin``; ``Z`` is exact for the affine parts and the charge
    transfer term, approximate (quasi-Newton) for the in-step OCV and hysteresis."""
    n = int(prm[NRC])
    temp = x[STEMP]
    cap = cell_capacity(prm, t_ax, capf, x[SQABS], temp)
    soc = prm[SOCINI] - x[SQ] / cap
    if prm[OCVSTEP] > 0.0:
        soc1 = soc - i_lin * dt / cap
        f0 = cell_ocv(prm, soc_ax, t_ax, ocv_c, ocv_d, soc, temp, direction)
        f1 = cell_ocv(prm, soc_ax, t_ax, ocv_c, ocv_d, soc1, temp, direction)
        ocv_avg = ocv_step_mean(prm, soc_ax, t_ax, ocv_c, ocv_d, soc, soc1, f0, f1, temp, direction)
        _, rs = cell_ocv_rs(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, 0.5 * (soc + soc1), temp, direction)
        if abs(soc1 - soc) > 1e-9:
            z_ocv = dt / cap * (f1 - ocv_avg) / (soc1 - soc)
        else:  # half the local slope on the side the SOC moves to
            ds = -1e-6 * direction
            f1 = cell_ocv(prm, soc_ax, t_ax, ocv_c, ocv_d, soc + ds, temp, direction)
            z_ocv = 0.5 * dt / cap * (f1 - ocv_avg) / ds
        e = ocv_avg + z_ocv * i_lin
        z = rs + z_ocv
    else:
        ocv, rs = cell_ocv_rs(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, soc, temp, direction)
        e = ocv
        z = rs
    persistent = prm[RCPERS] > 0.0
    for j in range(n if persistent else 2 * n):
        rc, jj, active = rc_element(j, n, persistent, direction, rc_d, rc_c)
        r_el, tau = rc_values(rc, jj, temp, prm[TREF])
        g = tau * (1.0 - math.exp(-dt / tau)) / dt  # mean of exp(-t/tau) over the step
        if active:
            e -= x[N_FIXED_STATES + j] * g
            z += r_el * prm[RSCALE] * (1.0 - g)
    if prm[CTI0] > 0.0:
        eta, d_eta = ct_overpotential(prm, i_lin, temp)
        e -= eta - d_eta * i_lin
        z += d_eta
    if prm[HMAX] > 0.0:
        _, h_avg = hysteresis_step(prm, x[SHYST], i_lin, dt, cap, temp)
        e += h_avg
    return e, z


@njit(cache=True)
def cell_step(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, i_a, dt, t_port, rec):
    """Advance one cell state ``x`` (in place) by ``dt`` [s] at constant current ``i_a`` [A].

    ``t_port`` [K]: heat-port temperature. Fills ``rec`` (:data:`RECORD`) for the step.
    """
    n = int(prm[NRC])
    direction = step_direction(i_a, x[SDIR], prm[IBAND])
    temp0 = x[STEMP]
    cap = cell_capacity(prm, t_ax, capf, x[SQABS], temp0)
    soc = prm[SOCINI] - x[SQ] / cap
    if prm[OCVSTEP] > 0.0:  # OCV consistent within the step (module docstring)
        soc1 = soc - i_a * dt / cap
        f0 = cell_ocv(prm, soc_ax, t_ax, ocv_c, ocv_d, soc, temp0, direction)
        ocv = cell_ocv(prm, soc_ax, t_ax, ocv_c, ocv_d, soc1, temp0, direction)
        ocv_avg = ocv_step_mean(prm, soc_ax, t_ax, ocv_c, ocv_d, soc, soc1, f0, ocv, temp0, direction)
        _, rs = cell_ocv_rs(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, 0.5 * (soc + soc1), temp0, direction)
    else:
        ocv, rs = cell_ocv_rs(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, soc, temp0, direction)
        ocv_avg = ocv
    # RC elements: exact exponential, exact step integrals of v and v^2/R
    v_sum_end = 0.0
    v_sum_avg = 0.0
    rc_heat_j = 0.0
    persistent = prm[RCPERS] > 0.0
    for j in range(n if persistent else 2 * n):
        rc, jj, active = rc_element(j, n, persistent, direction, rc_d, rc_c)
        r_el, tau = rc_values(rc, jj, temp0, prm[TREF])
        r_j = r_el * prm[RSCALE]
        a = r_j * i_a if active else 0.0
        v0 = x[N_FIXED_STATES + j]
        e1 = math.exp(-dt / tau)
        d = v0 - a
        v1 = a + d * e1
        int_v = a * dt + d * tau * (1.0 - e1)
        int_v2 = a * a * dt + 2.0 * a * d * tau * (1.0 - e1) + d * d * 0.5 * tau * (1.0 - e1 * e1)
        rc_heat_j += int_v2 / r_j
        if active:
            v_sum_end += v1
            v_sum_avg += int_v / dt
        x[N_FIXED_STATES + j] = v1
    eta, _ = ct_overpotential(prm, i_a, temp0)
    h1, h_avg = hysteresis_step(prm, x[SHYST], i_a, dt, cap, temp0)
    heat_j = rs * i_a * i_a * dt + rc_heat_j
    if prm[CTI0] > 0.0 or prm[HMAX] > 0.0:
        heat_j += (eta - h_avg) * i_a * dt
    t_dudt = 0.0  # T dU/dT [V] (entropic heat, module docstring)
    if prm[ENTROPIC] > 0.0:
        s_rev = soc - 0.5 * i_a * dt / cap if prm[OCVSTEP] > 0.0 else soc
        t_dudt = temp0 * ocv_dudt(prm, soc_ax, t_ax, ocv_c, ocv_d, s_rev, temp0, direction)
        heat_j -= i_a * t_dudt * dt
    q_heat = heat_j / dt
    # lumped temperature, eq (41) with a skin resistance to the port: exact exponential
    tau_th = prm[CHEAT] * prm[RSKIN]
    t_inf = t_port + q_heat * prm[RSKIN]
    temp1 = t_inf + (temp0 - t_inf) * math.exp(-dt / tau_th)
    port_j = heat_j - prm[CHEAT] * (temp1 - temp0)
    # charge, eqs (33), (34), (38)
    x[SQ] += i_a * dt
    x[SQABS] += abs(i_a) * dt
    x[SCYC] += abs(i_a) * dt / (2.0 * cap)
    x[STEMP] = temp1
    x[SDIR] = direction
    x[SILAST] = i_a
    x[SHYST] = h1
    v_avg = ocv_avg - rs * i_a - v_sum_avg
    v_end = ocv - rs * i_a - v_sum_end
    if prm[CTI0] > 0.0 or prm[HMAX] > 0.0:
        v_avg += h_avg - eta
        v_end += h1 - eta
    rec[RV] = v_end
    rec[RVAVG] = v_avg
    rec[ROCV] = ocv
    rec[RSOC] = prm[SOCINI] - x[SQ] / cap  # end of step (capacity of the step)
    rec[RTEMP] = temp1
    rec[RHEAT] = q_heat
    rec[RPORT] = port_j / dt
    rec[RCAP] = cap
    rec[RRS] = rs
    rec[REEL] = v_avg * i_a * dt
    rec[RECH] = -(ocv_avg - t_dudt) * i_a * dt if prm[ENTROPIC] > 0.0 else -ocv_avg * i_a * dt
    rec[REHEAT] = heat_j
    rec[REPORT] = port_j


@njit(cache=True)
def rc_energy(prm, rc_d, rc_c, x):
    """Energy stored in the RC capacitors [J] (C = tau / R; with ``rc_persistent`` the set of
    the last direction)."""
    n = int(prm[NRC])
    e = 0.0
    persistent = prm[RCPERS] > 0.0
    for j in range(n if persistent else 2 * n):
        rc, jj, _ = rc_element(j, n, persistent, x[SDIR], rc_d, rc_c)
        r_el, tau = rc_values(rc, jj, x[STEMP], prm[TREF])
        c = tau / (r_el * prm[RSCALE])
        v = x[N_FIXED_STATES + j]
        e += 0.5 * c * v * v
    return e


@njit(cache=True, nogil=True)
def run_cell(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, current, dt, t_port, out):
    """Simulate one cell over ``current[k]`` [A] (step ``dt`` [s]); ``out[k]`` gets the record.

    ``t_port[k]`` [K] is the heat-port temperature of step k. ``x`` ends at the final state.
    """
    for k in range(current.shape[0]):
        cell_step(
            prm,
            soc_ax,
            t_ax,
            ocv_c,
            ocv_d,
            rs_c,
            rs_d,
            capf,
            rc_d,
            rc_c,
            x,
            current[k],
            dt,
            t_port[k],
            out[k],
        )


@njit(cache=True, parallel=True)
def run_batch(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, current, dt, t_port, summary):
    """Many independent cells in parallel: ``prm[c]``, ``x[c]``, ``current[c, k]``, ``t_port[c, k]``.

    ``summary[c]`` receives (min voltage [V], max voltage [V], max temperature [K],
    electrical energy [J], heat [J], final voltage [V]).
    """
    for c in prange(prm.shape[0]):
        rec = np.empty(len(RECORD))
        vmin = np.inf
        vmax = -np.inf
        tmax = x[c, STEMP]
        e_el = 0.0
        e_h = 0.0
        for k in range(current.shape[1]):
            cell_step(
                prm[c],
                soc_ax,
                t_ax,
                ocv_c,
                ocv_d,
                rs_c,
                rs_d,
                capf,
                rc_d,
                rc_c,
                x[c],
                current[c, k],
                dt,
                t_port[c, k],
                rec,
            )
            vmin = min(vmin, rec[RV])
            vmax = max(vmax, rec[RV])
            tmax = max(tmax, rec[RTEMP])
            e_el += rec[REEL]
            e_h += rec[REHEAT]
        summary[c, 0] = vmin
        summary[c, 1] = vmax
        summary[c, 2] = tmax
        summary[c, 3] = e_el
        summary[c, 4] = e_h
        summary[c, 5] = rec[RV] if current.shape[1] > 0 else np.nan


@njit(cache=True)
def share_current(
    prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, cells, i_total, dt, i_out
):
    """Branch currents [A] of parallel cells ``cells`` carrying ``i_total`` [A] together.

    Every branch's step-average voltage is affine in its current for a fixed direction
    (:func:`branch_affine`), so equal voltages and ``Σ i = i_total`` are solved exactly; a
    branch whose current comes out against its assumed direction is flipped and the system
    solved again (at most ``len(cells) + 2`` times; the direction rule is the cells' own,
    :func:`step_direction`, so the solved currents are the ones the cells then step with).
    With the nonlinear model options the branches are relinearised at the solved currents
    (:func:`branch_affine_at`) until the currents change by less than ``1e-9 (1 + |i_total|)`` A.
    Returns the shared step-average voltage [V].
    """
    m = cells.shape[0]
    dirs = np.empty(m)
    e = np.empty(m)
    z = np.empty(m)
    nonlinear = False
    for b in range(m):
        c = cells[b]
        dirs[b] = step_direction(i_total, x[c, SDIR], prm[c, IBAND])
        i_out[b] = i_total / m
        if prm[c, OCVSTEP] > 0.0 or prm[c, CTI0] > 0.0 or prm[c, HMAX] > 0.0:
            nonlinear = True
    v = 0.0
    for _it in range(m + 2 + (50 if nonlinear else 0)):
        s_g = 0.0
        s_eg = 0.0
        for b in range(m):
            c = cells[b]
            e[b], z[b] = branch_affine_at(
                prm[c], soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x[c], dt, dirs[b], i_out[b]
            )
            s_g += 1.0 / z[b]
            s_eg += e[b] / z[b]
        v = (s_eg - i_total) / s_g
        flipped = False
        change = 0.0
        for b in range(m):
            c = cells[b]
            i_new = (e[b] - v) / z[b]
            change = max(change, abs(i_new - i_out[b]))
            i_out[b] = i_new
            d_new = step_direction(i_out[b], x[c, SDIR], prm[c, IBAND])
            if d_new != dirs[b]:
                dirs[b] = d_new
                flipped = True
        if not flipped and (not nonlinear or change < 1e-9 * (1.0 + abs(i_total))):
            break
    return v


@njit(cache=True)
def run_module(
    prm,
    soc_ax,
    t_ax,
    ocv_c,
    ocv_d,
    rs_c,
    rs_d,
    capf,
    rc_d,
    rc_c,
    x,
    n_s,
    n_p,
    current,
    dt,
    t_port,
    out_module,
    out_cells,
):
    """n_s groups in series of n_p parallel cells (cell c = s * n_p + b).

    ``out_module[k]`` = (voltage end [V], voltage average [V], heat [W], port heat [W]);
    ``out_cells[k, c]`` = (current [A], SOC [-], temperature [K], heat [W]).
    """
    rec = np.empty(len(RECORD))
    i_b = np.empty(n_p)
    cells = np.empty(n_p, dtype=np.int64)
    for k in range(current.shape[0]):
        v_end = 0.0
        v_avg = 0.0
        heat = 0.0
        port = 0.0
        for s in range(n_s):
            for b in range(n_p):
                cells[b] = s * n_p + b
            share_current(
                prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, cells, current[k], dt, i_b
            )
            v_group = 0.0
            v_group_avg = 0.0
            for b in range(n_p):
                c = cells[b]
                cell_step(
                    prm[c],
                    soc_ax,
                    t_ax,
                    ocv_c,
                    ocv_d,
                    rs_c,
                    rs_d,
                    capf,
                    rc_d,
                    rc_c,
                    x[c],
                    i_b[b],
                    dt,
                    t_port[k, c],
                    rec,
                )
                v_group += rec[RV] / n_p
                v_group_avg += rec[RVAVG] / n_p
                heat += rec[RHEAT]
                port += rec[RPORT]
                out_cells[k, c, 0] = i_b[b]
                out_cells[k, c, 1] = rec[RSOC]
                out_cells[k, c, 2] = rec[RTEMP]
                out_cells[k, c, 3] = rec[RHEAT]
            v_end += v_group
            v_avg += v_group_avg
        out_module[k, 0] = v_end
        out_module[k, 1] = v_avg
        out_module[k, 2] = heat
        out_module[k, 3] = port


# --- forward sensitivities for identification (issue 14) ------------------------------------
# Columns of the sensitivity arrays of :func:`run_cell_sensitivity` for ``n_soc`` SOC
# breakpoints and ``n_rc`` RC pairs: OCV table, R_s table, RC resistances, RC time constants,
# then the four scalars below (offsets from ``2 n_soc + 2 n_rc``).
SENS_I0, SENS_SCALE, SENS_CHEAT, SENS_RSKIN = range(4)


def sensitivity_columns(n_soc: int, n_rc: int) -> dict[str, Any]:
    """Column of each parameter group in :func:`run_cell_sensitivity`'s arrays:
    ``ocv``, ``rs`` (slices over the SOC breakpoints), ``rc_r``, ``rc_tau`` (slices over the
    RC pairs), ``ct_i0_a``, ``ct_scale``, ``c_heat_j_per_k``, ``r_skin_k_per_w`` (indices)."""
    k = 2 * n_soc + 2 * n_rc
    return {
        "ocv": slice(0, n_soc),
        "rs": slice(n_soc, 2 * n_soc),
        "rc_r": slice(2 * n_soc, 2 * n_soc + n_rc),
        "rc_tau": slice(2 * n_soc + n_rc, k),
        "ct_i0_a": k + SENS_I0,
        "ct_scale": k + SENS_SCALE,
        "c_heat_j_per_k": k + SENS_CHEAT,
        "r_skin_k_per_w": k + SENS_RSKIN,
        "n": k + 4,
    }


@njit(cache=True, inline="always")
def _hat_weights(soc_ax, s, scale, w):
    """Add ``scale`` times the weights of the piecewise-linear (edge-clamped) interpolation at
    ``s`` of a table on ``soc_ax`` to ``w[i]``."""
    n = soc_ax.shape[0]
    if n == 1 or s <= soc_ax[0]:
        w[0] += scale
        return
    if s >= soc_ax[n - 1]:
        w[n - 1] += scale
        return
    i = 0
    while soc_ax[i + 1] <= s:
        i += 1
    a = (s - soc_ax[i]) / (soc_ax[i + 1] - soc_ax[i])
    w[i] += scale * (1.0 - a)
    w[i + 1] += scale * a


@njit(cache=True)
def _ocv_weight(prm, soc_ax, ocv, s, scale, w):
    """``scale`` times d OCV(s) / d table (zero where the OCV is clamped to the limits) into ``w``."""
    raw = interp1(soc_ax, ocv, s, False)
    if prm[VMIN] < raw < prm[VMAX]:
        _hat_weights(soc_ax, s, scale, w)


@njit(cache=True)
def _sensitivity_step(prm, soc_ax, ocv, rc, x0, i_a, dt, t_port, rec, s_rc, s_t, w_heat, dv, dt_out):
    """Sensitivities of one step of :func:`cell_step` (pre-step state ``x0``, its record
    ``rec``; ``w_heat`` is work space); updates the RC sensitivities ``s_rc``
    (``[j, 0]`` d v_j / d R_j, ``[j, 1]`` d v_j / d tau_j) and the temperature's ``s_t`` in
    place and writes d v_end / d p into ``dv`` and d T_end / d p into ``dt_out``."""
    n_soc = soc_ax.shape[0]
    n = int(prm[NRC])
    k0 = 2 * n_soc + 2 * n
    temp0 = x0[STEMP]
    cap = rec[RCAP]  # independent of the parameters (alpha_c = 0, one temperature column)
    soc = prm[SOCINI] - x0[SQ] / cap
    q_heat = rec[RHEAT]
    w_heat[:] = 0.0  # d heat_j / d p, before the temperature term
    dv[:] = 0.0
    if prm[OCVSTEP] > 0.0:
        soc1 = soc - i_a * dt / cap
        _ocv_weight(prm, soc_ax, ocv, soc1, 1.0, dv)
        s_r = 0.5 * (soc + soc1)
    else:
        _ocv_weight(prm, soc_ax, ocv, soc, 1.0, dv)
        s_r = soc
    _hat_weights(soc_ax, s_r, prm[RSCALE] * i_a * i_a * dt, w_heat[n_soc : 2 * n_soc])
    _hat_weights(soc_ax, s_r, -prm[RSCALE] * i_a, dv[n_soc : 2 * n_soc])
    for j in range(n):
        r_j = rc[j, 0] * prm[RSCALE]
        tau = rc[j, 1]
        e1 = math.exp(-dt / tau)
        de1 = e1 * dt / (tau * tau)  # d e1 / d tau
        a = r_j * i_a
        v0 = x0[N_FIXED_STATES + j]
        d = v0 - a
        g1 = tau * (1.0 - e1)
        g2 = 0.5 * tau * (1.0 - e1 * e1)
        int_v2 = a * a * dt + 2.0 * a * d * g1 + d * d * g2
        # d / d R_j (table value; r_j = R_j r_scale)
        da = prm[RSCALE] * i_a
        dd = s_rc[j, 0] - da
        d_int = 2.0 * a * da * dt + 2.0 * (da * d + a * dd) * g1 + 2.0 * d * dd * g2
        w_heat[2 * n_soc + j] += d_int / r_j - int_v2 / (r_j * rc[j, 0])
        s_new_r = da * (1.0 - e1) + s_rc[j, 0] * e1
        # d / d tau_j
        dd = s_rc[j, 1]
        dg1 = (1.0 - e1) - tau * de1
        dg2 = 0.5 * (1.0 - e1 * e1) - tau * e1 * de1
        d_int = 2.0 * a * dd * g1 + 2.0 * a * d * dg1 + 2.0 * d * dd * g2 + d * d * dg2
        w_heat[2 * n_soc + n + j] += d_int / r_j
        s_new_t = s_rc[j, 1] * e1 + d * de1
        s_rc[j, 0] = s_new_r
        s_rc[j, 1] = s_new_t
        dv[2 * n_soc + j] -= s_new_r
        dv[2 * n_soc + n + j] -= s_new_t
    if prm[CTI0] > 0.0:
        eta, _ = ct_overpotential(prm, i_a, temp0)
        i0 = prm[CTI0] / prm[RSCALE]
        if prm[CTEA] != 0.0:
            i0 *= math.exp(-prm[CTEA] / R_GAS_J_PER_MOL_K * (1.0 / temp0 - 1.0 / prm[TREF]))
        b = prm[CTM] * 2.0 * R_GAS_J_PER_MOL_K * temp0 / FARADAY_C_PER_MOL
        u = i_a / (2.0 * i0)
        bu = b * u / math.sqrt(1.0 + u * u)
        d_i0 = -bu / prm[CTI0]
        d_m = eta / prm[CTM]
        d_temp = eta / temp0 - bu * prm[CTEA] / (R_GAS_J_PER_MOL_K * temp0 * temp0)
        dv[k0 + SENS_I0] -= d_i0
        dv[k0 + SENS_SCALE] -= d_m
        w_heat[k0 + SENS_I0] += d_i0 * i_a * dt
        w_heat[k0 + SENS_SCALE] += d_m * i_a * dt
        for m in range(dv.shape[0]):  # the temperature path (dense)
            dv[m] -= d_temp * s_t[m]
            w_heat[m] += d_temp * i_a * dt * s_t[m]
    # lumped temperature: temp1 = t_inf + (temp0 - t_inf) E
    c_h = prm[CHEAT]
    r_sk = prm[RSKIN]
    big_e = math.exp(-dt / (c_h * r_sk))
    t_inf = t_port + q_heat * r_sk
    for m in range(dv.shape[0]):
        s_t[m] = (1.0 - big_e) * r_sk * w_heat[m] / dt + big_e * s_t[m]
    s_t[k0 + SENS_CHEAT] += (temp0 - t_inf) * big_e * dt / (c_h * c_h * r_sk)
    s_t[k0 + SENS_RSKIN] += (1.0 - big_e) * q_heat + (temp0 - t_inf) * big_e * dt / (c_h * r_sk * r_sk)
    dt_out[:] = s_t


@njit(cache=True, nogil=True)
def run_cell_sensitivity(prm, soc_ax, t_ax, ocv, rs, capf, rc, x, current, dt, t_port, out, dv, dtemp):
    """:func:`run_cell` and its forward sensitivities in one pass.

    For the structure identification fits (:mod:`hevsim.battery.identify`): one temperature
    column, the same OCV, R_s and RC tables in both directions, ``rc_persistent`` on,
    ``alpha_c = alpha_Rs = 0``, no hysteresis (the caller checks). ``dv[k, p]``
    and ``dtemp[k, p]`` receive d voltage_end / d p [V per unit of p] and d temperature / d p
    [K per unit of p] for the parameters p of :func:`sensitivity_columns`. Exact for the
    discrete model: every step is differentiated as it is computed (the RC and thermal
    exponentials, the OCV and R_s interpolation, the Butler-Volmer term and its temperature
    path, the heat). The values (``out``, ``x``) are :func:`cell_step`'s, bit for bit.
    """
    n = int(prm[NRC])
    s_rc = np.zeros((max(n, 1), 2))
    s_t = np.zeros(dv.shape[1])
    w_heat = np.empty(dv.shape[1])
    x0 = np.empty_like(x)
    for k in range(current.shape[0]):
        x0[:] = x
        cell_step(prm, soc_ax, t_ax, ocv, ocv, rs, rs, capf, rc, rc, x, current[k], dt, t_port[k], out[k])
        _sensitivity_step(
            prm, soc_ax, ocv[:, 0], rc, x0, current[k], dt, t_port[k], out[k], s_rc, s_t, w_heat,
            dv[k], dtemp[k],
        )  # fmt: skip

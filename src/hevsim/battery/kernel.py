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
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from hevsim.tables import interp1, interp2

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
)
C0, KCQ, ALPHAC, TREF, ALPHARS, CHEAT, RSKIN, VMIN, VMAX, SOCINI, RSCALE, NRC, IBAND = range(len(PARAMS))

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
STATES = ("q_c", "qabs_c", "temp_k", "direction", "cycles")
SQ, SQABS, STEMP, SDIR, SCYC = range(len(STATES))
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


@njit(cache=True)
def cell_capacity(prm, t_ax, capf, qabs, temp_k):
    """Capacity C [C] per eq (35), times the optional capacity-vs-temperature factor table."""
    c = (prm[C0] + prm[KCQ] * qabs) * (1.0 + prm[ALPHAC] * (temp_k - prm[TREF]))
    return c * interp1(t_ax, capf, temp_k, False)


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
    r = r * prm[RSCALE] * (1.0 + prm[ALPHARS] * (temp_k - prm[TREF]))
    return ocv, r


@njit(cache=True)
def step_direction(i_a, last_direction, band_a):
    """+1 discharge, -1 charge; inside the dead band ``|i| <= band_a`` the last direction is kept."""
    if i_a > band_a:
        return 1.0
    if i_a < -band_a:
        return -1.0
    return last_direction


@njit(cache=True)
def branch_affine(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, dt, direction):
    """Step-average terminal voltage as ``E - Z i`` for a current of the given direction.

    Returns ``(E [V], Z [ohm])``: the cell's step-averaged voltage is exactly ``E - Z i`` for
    any constant current ``i`` of that direction over ``dt`` (used to share current between
    parallel cells).
    """
    n = int(prm[NRC])
    temp = x[STEMP]
    cap = cell_capacity(prm, t_ax, capf, x[SQABS], temp)
    soc = prm[SOCINI] - x[SQ] / cap
    ocv, rs = cell_ocv_rs(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, soc, temp, direction)
    e = ocv
    z = rs
    for j in range(2 * n):
        rc = rc_d if j < n else rc_c
        jj = j if j < n else j - n
        tau = rc[jj, 1]
        g = tau * (1.0 - math.exp(-dt / tau)) / dt  # mean of exp(-t/tau) over the step
        active = (j < n and direction > 0.0) or (j >= n and direction < 0.0)
        if active:
            e -= x[N_FIXED_STATES + j] * g
            z += rc[jj, 0] * prm[RSCALE] * (1.0 - g)
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
    ocv, rs = cell_ocv_rs(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, soc, temp0, direction)
    # RC elements: exact exponential, exact step integrals of v and v^2/R
    v_sum_end = 0.0
    v_sum_avg = 0.0
    rc_heat_j = 0.0
    for j in range(2 * n):
        rc = rc_d if j < n else rc_c
        jj = j if j < n else j - n
        r_j = rc[jj, 0] * prm[RSCALE]
        tau = rc[jj, 1]
        active = (j < n and direction > 0.0) or (j >= n and direction < 0.0)
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
    heat_j = rs * i_a * i_a * dt + rc_heat_j
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
    v_avg = ocv - rs * i_a - v_sum_avg
    rec[RV] = ocv - rs * i_a - v_sum_end
    rec[RVAVG] = v_avg
    rec[ROCV] = ocv
    rec[RSOC] = prm[SOCINI] - x[SQ] / cap  # end of step (capacity of the step)
    rec[RTEMP] = temp1
    rec[RHEAT] = q_heat
    rec[RPORT] = port_j / dt
    rec[RCAP] = cap
    rec[RRS] = rs
    rec[REEL] = v_avg * i_a * dt
    rec[RECH] = -ocv * i_a * dt
    rec[REHEAT] = heat_j
    rec[REPORT] = port_j


@njit(cache=True)
def rc_energy(prm, rc_d, rc_c, x):
    """Energy stored in the RC capacitors [J] (C = tau / R)."""
    n = int(prm[NRC])
    e = 0.0
    for j in range(2 * n):
        rc = rc_d if j < n else rc_c
        jj = j if j < n else j - n
        c = rc[jj, 1] / (rc[jj, 0] * prm[RSCALE])
        v = x[N_FIXED_STATES + j]
        e += 0.5 * c * v * v
    return e


@njit(cache=True)
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
    Returns the shared step-average voltage [V].
    """
    m = cells.shape[0]
    dirs = np.empty(m)
    e = np.empty(m)
    z = np.empty(m)
    for b in range(m):
        c = cells[b]
        dirs[b] = step_direction(i_total, x[c, SDIR], prm[c, IBAND])
    v = 0.0
    for _it in range(m + 2):
        s_g = 0.0
        s_eg = 0.0
        for b in range(m):
            c = cells[b]
            e[b], z[b] = branch_affine(
                prm[c], soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x[c], dt, dirs[b]
            )
            s_g += 1.0 / z[b]
            s_eg += e[b] / z[b]
        v = (s_eg - i_total) / s_g
        flipped = False
        for b in range(m):
            c = cells[b]
            i_out[b] = (e[b] - v) / z[b]
            d_new = step_direction(i_out[b], x[c, SDIR], prm[c, IBAND])
            if d_new != dirs[b]:
                dirs[b] = d_new
                flipped = True
        if not flipped:
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

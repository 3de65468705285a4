"""The pack's compiled step kernels (moved out of :mod:`hevsim.battery.pack`, which
re-exports the public ones): one cell's record, the Thevenin sums and step of a pack
(:func:`pack_thevenin`, :func:`pack_step`), the one compiled pass per step with the current
shared through affine pairs (:func:`pack_pass`, :func:`pack_pass_linear`, :func:`pack_pairs`) and
the RC constants of a step (:func:`rc_constants`).

They sit below both the pack (:class:`hevsim.battery.pack.Pack`) and the pack's compiled run
(:mod:`hevsim.battery.pack_run`), which imports them; SI units as in
:mod:`hevsim.battery.kernel`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from hevsim.battery.kernel import (
    ALPHAC,
    ALPHARS,
    C0,
    CHEAT,
    CTI0,
    HMAX,
    IBAND,
    KCQ,
    N_FIXED_STATES,
    NRC,
    OCVSTEP,
    RCPERS,
    RECH,
    RECORD,
    REEL,
    REHEAT,
    REPORT,
    RPORT,
    RSCALE,
    RSKIN,
    RSOC,
    RTEMP,
    RV,
    RVAVG,
    SCYC,
    SDIR,
    SILAST,
    SOCINI,
    SQ,
    SQABS,
    STEMP,
    TREF,
    VMAX,
    VMIN,
    branch_affine,
    capacity_c,
    cell_step,
    rc_element,
    series_resistance,
    share_current,
    step_direction,
)
from hevsim.tables import _segment


@njit(cache=True, inline="always")
def _record_cell(c, i_a, rec, out_cells, energy):
    """Store cell ``c``'s step record (current [A], SOC, temperature [K], port temperature
    [K], end voltage [V]) in ``out_cells`` and add its energies [J] (electrical, chemical,
    heat, to the port) to ``energy``."""
    out_cells[c, 0] = i_a
    out_cells[c, 1] = rec[RSOC]
    out_cells[c, 2] = rec[RTEMP]
    out_cells[c, 3] = rec[RPORT]
    out_cells[c, 4] = rec[RV]
    energy[0] += rec[REEL]
    energy[1] += rec[RECH]
    energy[2] += rec[REHEAT]
    energy[3] += rec[REPORT]


@njit(cache=True)
def pack_step(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, n_groups, n_p, i_a, dt,
              t_port, out_cells, energy):  # fmt: skip
    """One step of ``n_groups`` series groups of ``n_p`` parallel cells at pack current ``i_a``
    [A]; ``t_port[c]`` [K] per cell. ``out_cells[c]`` = (current [A], SOC, core temperature [K],
    port heat [W], end voltage [V]); ``energy`` = (electrical out, chemical change, heat, port
    heat) [J] of the step. Returns (end voltage, step-average voltage) [V] of the pack."""
    rec = np.empty(len(RECORD))
    i_b = np.empty(n_p)
    cells = np.empty(n_p, dtype=np.int64)
    energy[:] = 0.0
    v_end = 0.0
    v_avg = 0.0
    for g in range(n_groups):
        for b in range(n_p):
            cells[b] = g * n_p + b
        share_current(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, cells, i_a, dt, i_b)
        for b in range(n_p):
            c = cells[b]
            cell_step(prm[c], soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x[c], i_b[b], dt,
                      t_port[c], rec)  # fmt: skip
            _record_cell(c, i_b[b], rec, out_cells, energy)
            v_end += rec[RV] / n_p
            v_avg += rec[RVAVG] / n_p
    return v_end, v_avg


@njit(cache=True)
def pack_thevenin(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, n_groups, n_p, dt,
                  direction, e_group, z_group):  # fmt: skip
    """The pack's step-average voltage ``E - Z I`` over the next step ``dt`` [s] for a pack
    current of ``direction`` (+1 discharge, -1 charge): each cell's exact affine branch
    (:func:`hevsim.battery.kernel.branch_affine`), the parallel cells of a group as one branch
    (``1/Z_g = sum 1/z``, ``E_g = Z_g sum e/z``: the shared voltage :func:`share_current`
    solves), the groups in series. Exact while every cell carries the pack's direction (the
    thesis cell's linear options). Fills ``e_group``/``z_group`` [V, ohm]; returns (E [V], Z [ohm])."""
    e_tot = 0.0
    z_tot = 0.0
    for g in range(n_groups):
        s_g = 0.0
        s_eg = 0.0
        for b in range(n_p):
            c = g * n_p + b
            e, z = branch_affine(prm[c], soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x[c], dt,
                                 direction)  # fmt: skip
            s_g += 1.0 / z
            s_eg += e / z
        e_group[g] = s_eg / s_g
        z_group[g] = 1.0 / s_g
        e_tot += e_group[g]
        z_tot += z_group[g]
    return e_tot, z_tot


@njit(cache=True)
def _linear_group(prm, x, cells):
    """True when the cells' step-average voltages are exactly affine in their currents (none of
    the nonlinear options: in-step OCV, charge transfer, hysteresis)."""
    for c in cells:
        if prm[c, OCVSTEP] > 0.0 or prm[c, CTI0] > 0.0 or prm[c, HMAX] > 0.0:
            return False
    return True


@njit(cache=True, inline="always")
def _share_affine(prm, x, ez, cells, i_total, i_out, dirs):
    """:func:`hevsim.battery.kernel.share_current` for linear cells from their stored affine pairs
    ``ez[c]`` = (E, Z) discharge then charge [V, ohm], then ``1/Z`` and ``E/Z`` of each
    direction (the same values it would compute, in the same order: the same currents bit for
    bit)."""
    m = cells.shape[0]
    for b in range(m):
        dirs[b] = step_direction(i_total, x[cells[b], SDIR], prm[cells[b], IBAND])
    for _it in range(m + 2):
        inv_z = 0.0
        e_over_z = 0.0
        for b in range(m):
            k = 4 if dirs[b] >= 0.0 else 6
            inv_z += ez[cells[b], k]  # 1/Z and E/Z, stored by _group_pairs
            e_over_z += ez[cells[b], k + 1]
        v = (e_over_z - i_total) / inv_z
        turned = False
        for b in range(m):
            c = cells[b]
            k = 0 if dirs[b] >= 0.0 else 2
            i_out[b] = (ez[c, k] - v) / ez[c, k + 1]
            d_new = step_direction(i_out[b], x[c, SDIR], prm[c, IBAND])
            turned = turned or d_new != dirs[b]
            dirs[b] = d_new
        if not turned:
            break


@njit(cache=True)
def pack_pass(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, n_groups, n_p, i_a, dt,
              t_port, out_cells, energy, ez, ez_valid, pairs, totals):  # fmt: skip
    """One compiled pass over the pack per step: :func:`pack_step` at pack current ``i_a`` [A]
    (same arguments and results), then, from every cell's new state, the next step's affine
    pairs of both directions (:func:`pack_thevenin` for +1 and -1): ``ez[c]`` = the cell's
    (E_dis, Z_dis, E_chg, Z_chg) [V, ohm], ``pairs[g]`` its series group's, ``totals`` the
    pack's. With ``ez_valid`` (``ez`` holds the pairs of the present state) the parallel cells
    of a linear group share the current from ``ez`` (no second evaluation). Returns (end
    voltage, step-average voltage) [V] of the pack."""
    rec = np.empty(len(RECORD))
    i_b = np.empty(n_p)
    cells = np.empty(n_p, dtype=np.int64)
    energy[:] = 0.0
    totals[:] = 0.0
    v_end = 0.0
    v_avg = 0.0
    tabs = (soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c)
    for g in range(n_groups):
        for b in range(n_p):
            cells[b] = g * n_p + b
        if ez_valid and _linear_group(prm, x, cells):
            _share_affine(prm, x, ez, cells, i_a, i_b, np.empty(n_p))
        else:
            share_current(prm, *tabs, x, cells, i_a, dt, i_b)
        for b in range(n_p):
            c = cells[b]
            cell_step(prm[c], *tabs, x[c], i_b[b], dt, t_port[c], rec)
            _record_cell(c, i_b[b], rec, out_cells, energy)
            v_end += rec[RV] / n_p
            v_avg += rec[RVAVG] / n_p
        _group_pairs(prm, tabs, x, dt, g, n_p, ez, ez, np.zeros((2, 1, 5)), False, pairs, totals)
    return v_end, v_avg


@njit(cache=True)
def rc_constants(p, rc_d, rc_c, dt):
    """Per direction (discharge, charge) and RC state of cells with parameters ``p``, at step
    ``dt`` [s]: (connected 0/1, R [ohm] before the cell's scale, tau [s], mean of
    ``exp(-t/tau)`` over the step, ``exp(-dt/tau)``), as :func:`hevsim.battery.kernel.cell_step`
    and :func:`~hevsim.battery.kernel.branch_affine` evaluate them."""
    n = int(p[NRC])
    persistent = p[RCPERS] > 0.0
    slots = n if persistent else 2 * n
    rcc = np.zeros((2, max(slots, 1), 5))
    for d in range(2):
        for j in range(slots):
            table, row, on = rc_element(j, n, persistent, 1.0 - 2.0 * d, rc_d, rc_c)
            tau = table[row, 1]
            rcc[d, j, 0] = 1.0 if on else 0.0
            rcc[d, j, 1] = table[row, 0]
            rcc[d, j, 2] = tau
            rcc[d, j, 3] = tau * (1.0 - math.exp(-dt / tau)) / dt
            rcc[d, j, 4] = math.exp(-dt / tau)
    return rcc[:, :slots]


@njit(cache=True, inline="always")
def _axis_location(ax, v):
    """Where :func:`hevsim.tables.interp1` (``linear=False``) reads a table on the axis ``ax`` at
    ``v``: (k, w); :func:`_axis_value` gives the value (the same bit for bit: the edges
    exactly)."""
    n = ax.shape[0]
    k, w = 0, 0.0
    if n > 1 and v >= ax[n - 1]:
        k = n - 1
    elif n > 1 and v > ax[0]:
        k = _segment(ax, v)
        w = (v - ax[k]) / (ax[k + 1] - ax[k])
    return k, w


@njit(cache=True, inline="always")
def _axis_value(fp, k, w):
    """1-D table ``fp`` at an :func:`_axis_location`."""
    return fp[k] if w == 0.0 else fp[k] + w * (fp[k + 1] - fp[k])


@njit(cache=True, inline="always")
def _table_location(xp, yp, x, y):
    """Where :func:`hevsim.tables.interp2` (``linear=False``) reads a table on the axes ``xp``,
    ``yp`` at ``(x, y)``: (kind, i, j, wx, wy); kind 0 bilinear, 1 along ``x`` only (one ``y``
    point), 2 along ``y`` only (one ``x`` point). :func:`_table_value` evaluates any table on
    those axes there with interp2's operations (the same value bit for bit), so that the four
    tables of a cell share one search."""
    nx = xp.shape[0]
    ny = yp.shape[0]
    x = min(max(x, xp[0]), xp[nx - 1])
    y = min(max(y, yp[0]), yp[ny - 1])
    if nx == 1:  # interp1 (linear=False) along the other axis: edges exactly
        k, w = _axis_location(yp, y)
        return 2, 0, k, 0.0, w
    if ny == 1:
        k, w = _axis_location(xp, x)
        return 1, k, 0, w, 0.0
    i = _segment(xp, x)
    j = _segment(yp, y)
    return 0, i, j, (x - xp[i]) / (xp[i + 1] - xp[i]), (y - yp[j]) / (yp[j + 1] - yp[j])


@njit(cache=True, inline="always")
def _table_value(fp, kind, i, j, wx, wy):
    """Table ``fp`` at a :func:`_table_location` (interp2's arithmetic)."""
    if kind == 1:
        return fp[i, 0] if wx == 0.0 else fp[i, 0] + wx * (fp[i + 1, 0] - fp[i, 0])
    if kind == 2:
        return fp[0, j] if wy == 0.0 else fp[0, j] + wy * (fp[0, j + 1] - fp[0, j])
    f0 = fp[i, j] + wy * (fp[i, j + 1] - fp[i, j])
    f1 = fp[i + 1, j] + wy * (fp[i + 1, j + 1] - fp[i + 1, j])
    return f0 + wx * (f1 - f0)


# The linear pass's cell functions below index the pack's 2-D arrays by cell (``x[c, k]``) and
# take no row views or table arrays chosen at run time: in compiled code each array view or
# non-inlined call with array arguments costs reference-count updates (atomic operations) that
# were most of a cell's step before (bench_pack_vehicle.py).


@njit(cache=True, inline="always")
def _affine_direction(rcc, d, x, c, r_scale, u, r_s, ez, oc):
    """Direction ``d`` (0 discharge, 1 charge) of :func:`_affine_linear` from the cell's OCV
    ``u`` [V] and R_s [ohm]: stores them in ``oc[c]`` and the pair (E, Z) in ``ez[c]``."""
    oc[c, 1 + 2 * d] = u
    oc[c, 2 + 2 * d] = r_s
    for k in range(rcc.shape[1]):
        if rcc[d, k, 0] > 0.0:
            u -= x[c, N_FIXED_STATES + k] * rcc[d, k, 3]
            r_s += rcc[d, k, 1] * r_scale * (1.0 - rcc[d, k, 3])
    ez[c, 2 * d] = u
    ez[c, 2 * d + 1] = r_s


@njit(cache=True, inline="always")
def _affine_linear(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rcc, x, ez, oc, c):
    """:func:`hevsim.battery.kernel.branch_affine` of both directions of linear cell ``c`` (the
    same operations, one capacity and one table location for both; ``rcc`` from
    :func:`rc_constants`): ``ez[c]`` = (E_dis, Z_dis, E_chg, Z_chg) [V, ohm]; ``oc[c]`` =
    (capacity [C], OCV_dis, R_s dis, OCV_chg, R_s chg) [V, ohm] for its next step
    (:func:`_step_linear`)."""
    temp = x[c, STEMP]
    k, w = _axis_location(t_ax, temp)
    cap = capacity_c(prm[c, C0], prm[c, KCQ], prm[c, ALPHAC], prm[c, TREF], x[c, SQABS], temp,
                     _axis_value(capf, k, w))  # fmt: skip
    soc = prm[c, SOCINI] - x[c, SQ] / cap
    oc[c, 0] = cap
    kind, i, j, wx, wy = _table_location(soc_ax, t_ax, soc, temp)
    v_min, v_max, r_scale = prm[c, VMIN], prm[c, VMAX], prm[c, RSCALE]
    alpha, t_ref = prm[c, ALPHARS], prm[c, TREF]
    u = min(max(_table_value(ocv_d, kind, i, j, wx, wy), v_min), v_max)
    r_s = series_resistance(_table_value(rs_d, kind, i, j, wx, wy), r_scale, alpha, temp, t_ref)
    _affine_direction(rcc, 0, x, c, r_scale, u, r_s, ez, oc)
    u = min(max(_table_value(ocv_c, kind, i, j, wx, wy), v_min), v_max)
    r_s = series_resistance(_table_value(rs_c, kind, i, j, wx, wy), r_scale, alpha, temp, t_ref)
    _affine_direction(rcc, 1, x, c, r_scale, u, r_s, ez, oc)


@njit(cache=True, inline="always")
def _step_linear(prm, rcc, x, oc, c, i_a, dt, t_port, out, energy):
    """:func:`hevsim.battery.kernel.cell_step` of linear cell ``c`` from the capacity, OCV and
    R_s :func:`_affine_linear` kept (the same operations); fills ``out[c]`` as :func:`pack_step`
    and adds the step's energies. Returns (end voltage, step-average voltage) [V]."""
    sign = step_direction(i_a, x[c, SDIR], prm[c, IBAND])
    k = 1 if sign >= 0.0 else 3
    d = 0 if sign > 0.0 else 1  # rc_element's test
    cap, ocv, rs = oc[c, 0], oc[c, k], oc[c, k + 1]
    r_scale = prm[c, RSCALE]
    rc_end = 0.0
    rc_avg = 0.0
    rc_heat = 0.0
    for j in range(rcc.shape[1]):
        on = rcc[d, j, 0] > 0.0
        r_el = rcc[d, j, 1] * r_scale
        tau = rcc[d, j, 2]
        decay = rcc[d, j, 4]
        v_inf = r_el * i_a if on else 0.0
        dv = x[c, N_FIXED_STATES + j] - v_inf
        v_new = v_inf + dv * decay
        sq = (
            v_inf * v_inf * dt
            + 2.0 * v_inf * dv * tau * (1.0 - decay)
            + dv * dv * 0.5 * tau * (1.0 - decay * decay)
        )
        rc_heat += sq / r_el
        if on:
            rc_end += v_new
            rc_avg += (v_inf * dt + dv * tau * (1.0 - decay)) / dt
        x[c, N_FIXED_STATES + j] = v_new
    heat_j = rs * i_a * i_a * dt + rc_heat
    q_heat = heat_j / dt
    t_inf = t_port + q_heat * prm[c, RSKIN]
    temp0 = x[c, STEMP]
    temp1 = t_inf + (temp0 - t_inf) * oc[c, 5]  # exp(-dt / (C_heat R_skin)) (pack_pairs)
    port_j = heat_j - prm[c, CHEAT] * (temp1 - temp0)
    x[c, SQ] += i_a * dt
    x[c, SQABS] += abs(i_a) * dt
    x[c, SCYC] += abs(i_a) * dt / (2.0 * cap)
    x[c, STEMP] = temp1
    x[c, SDIR] = sign
    x[c, SILAST] = i_a
    v_avg = ocv - rs * i_a - rc_avg
    v_end = ocv - rs * i_a - rc_end
    out[c, 0] = i_a
    out[c, 1] = prm[c, SOCINI] - x[c, SQ] / cap
    out[c, 2] = temp1
    out[c, 3] = port_j / dt
    out[c, 4] = v_end
    energy[0] += v_avg * i_a * dt
    energy[1] += -ocv * i_a * dt
    energy[2] += heat_j
    energy[3] += port_j
    return v_end, v_avg


#: options of the compiled loops that allocate nothing: no reference counting of arrays
#: (numba's ``_nrt=False``, as numba's own sort and string kernels use it). In a loop over
#: cells every array a helper receives or views otherwise costs a pair of atomic reference
#: updates: they were ~85 % of a cell's step (bench_pack_vehicle.py, before/after rows).
NO_REFCOUNT: dict[str, Any] = {"cache": True, "_nrt": False}


@njit(cache=True)
def pack_pass_linear(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, n_groups, n_p, i_a, dt,
                     t_port, out_cells, energy, ez, oc, rcc, pairs, totals):  # fmt: skip
    """:func:`pack_pass` for a pack of linear cells (none of the nonlinear options), from the
    pairs, capacities, OCVs and resistances :func:`pack_pairs` (or the previous pass) stored in
    ``ez``/``oc``: each cell's tables are read once per direction and step."""
    return _pass_linear(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, x, n_groups, n_p, i_a, dt, t_port,
                        out_cells, energy, ez, oc, rcc, pairs, totals, np.empty(n_p), np.empty(n_p),
                        np.empty(n_p, dtype=np.int64))  # fmt: skip


@njit(**NO_REFCOUNT)
def _pass_linear(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, x, n_groups, n_p, i_a, dt, t_port,
                 out_cells, energy, ez, oc, rcc, pairs, totals, i_b, dirs, cells):  # fmt: skip
    """:func:`pack_pass_linear` with its work arrays ``i_b``, ``dirs``, ``cells`` (n_p,)."""
    energy[:] = 0.0
    totals[:] = 0.0
    v_end = 0.0
    v_avg = 0.0
    for g in range(n_groups):
        for b in range(n_p):
            cells[b] = g * n_p + b
        _share_affine(prm, x, ez, cells, i_a, i_b, dirs)
        for b in range(n_p):
            c = g * n_p + b
            ve, va = _step_linear(prm, rcc, x, oc, c, i_b[b], dt, t_port[c], out_cells, energy)
            v_end += ve / n_p
            v_avg += va / n_p
        for c in range(g * n_p, (g + 1) * n_p):
            _affine_linear(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rcc, x, ez, oc, c)
        _group_sums(ez, g, n_p, pairs, totals)
    return v_end, v_avg


@njit(cache=True, inline="always")
def _group_sums(ez, g, n_p, pairs, totals):
    """From the cells' pairs ``ez[c, :4]`` of group ``g`` (cells ``g n_p`` to ``(g+1) n_p - 1``):
    their ``1/Z`` and ``E/Z`` (``ez[c, 4:]``), the group's pair (parallel branches) in
    ``pairs[g]``, added to ``totals``."""
    for d in range(2):
        inv_z = 0.0
        e_over_z = 0.0
        for c in range(g * n_p, (g + 1) * n_p):
            e, z = ez[c, 2 * d], ez[c, 2 * d + 1]
            ez[c, 4 + 2 * d] = 1.0 / z
            ez[c, 5 + 2 * d] = e / z
            inv_z += ez[c, 4 + 2 * d]
            e_over_z += ez[c, 5 + 2 * d]
        pairs[g, 2 * d] = e_over_z / inv_z
        pairs[g, 2 * d + 1] = 1.0 / inv_z
        totals[2 * d] += pairs[g, 2 * d]
        totals[2 * d + 1] += pairs[g, 2 * d + 1]


@njit(cache=True, inline="always")
def _group_pairs(prm, tabs, x, dt, g, n_p, ez, oc, rcc, linear, pairs, totals):
    """Affine pairs of both directions (:func:`pack_pass`) of group ``g``'s cells (``linear``:
    by :func:`_affine_linear`, which also fills ``oc``); adds the group's to ``totals``."""
    if linear:
        soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf = tabs[:7]
        for c in range(g * n_p, (g + 1) * n_p):
            _affine_linear(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rcc, x, ez, oc, c)
    else:
        for c in range(g * n_p, (g + 1) * n_p):
            for d in range(2):
                ez[c, 2 * d], ez[c, 2 * d + 1] = branch_affine(prm[c], *tabs, x[c], dt, 1.0 - 2.0 * d)  # type: ignore[call-arg]
    _group_sums(ez, g, n_p, pairs, totals)


@njit(cache=True)
def pack_pairs(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, n_groups, n_p, dt, ez, oc,
               rcc, linear, pairs, totals):  # fmt: skip
    """The affine pairs of :func:`pack_pass` (and, ``linear``, the data of
    :func:`pack_pass_linear` in ``oc``, with each cell's thermal decay over a step
    ``exp(-dt / (C_heat R_skin))`` in ``oc[:, 5]``) from the cells' present state, without a step."""
    tabs = (soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c)
    totals[:] = 0.0
    for g in range(n_groups):
        _group_pairs(prm, tabs, x, dt, g, n_p, ez, oc, rcc, linear, pairs, totals)
    if linear:  # the cells' thermal decay over a step (constant: their heat capacity and skin)
        for c in range(x.shape[0]):
            oc[c, 5] = math.exp(-dt / (prm[c, CHEAT] * prm[c, RSKIN]))

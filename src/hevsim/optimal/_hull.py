"""Exact input pruning for one-state problems whose increments do not depend on the state.

When a model returns, for every state node, the same next-state increment ``d_m`` and stage
cost ``g_m`` per input ``m`` (an :class:`~hevsim.optimal.Increment` of shape ``(1, M)``, as in
HEV problems with a SOC-independent battery), and the state grid is regular (spacing
``h``), input ``m`` moves every node by ``t_m = d_m / h = o_m + w_m`` cells: integer offset
``o_m`` and fraction ``w_m`` in [0, 1). For a node ``s`` whose next states all land where the
cost-to-go is the plain linear interpolant of finite node values, the value of input ``m`` is

    g_m + J[s + o_m] + w_m (J[s + o_m + 1] - J[s + o_m]),

linear in ``w_m`` with a slope that depends on ``s`` but not on ``m`` within the offset group.
The minimum over a group is therefore attained on the lower convex hull of the points
``(w_m, g_m)`` of that group, whatever the slope: the other inputs can never be strictly
optimal and are skipped (the convex-hull trick). Nodes near the edges of the admissible
band (boundary lines, state bounds) or next to infinite cost-to-go values are evaluated
with every input by the generic row kernel, so the Bellman step is unchanged up to
round-off. The hull is built once per step; typically it keeps a fifth or less of the
inputs, and the step runs that much faster.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange, types

from hevsim.optimal._consts import ST_FEASIBLE, ST_UNREACHABLE
from hevsim.optimal._kernels import _B2, _BOOL, _F, _F1, _F2, _I, _I1, _OF, _OI, _OS, _row_1d

SIG_HULL = types.void(
    _F1, _F2, _F2, _B2, _BOOL, _F1, _BOOL, _F, _F1, _F1, _I, _F1, _I1, _BOOL, _F1,
    _F1, _F1, _I1, _F, _F, _F, _F, _I1, _BOOL,
    _OF, _OI, _OS, _OF, _OI, _OF, _OF,
)  # fmt: skip


@njit(cache=True)
def hull_inputs(d, g, mask, has_mask, inv_dx):
    """Inputs on the lower convex hulls of ``(w_m, g_m)`` per cell-offset group.

    ``d``, ``g``, ``mask``: increments, costs and mask of one (state-independent) row.
    Returns ``(hull index array, smallest and largest valid increment, number of valid
    inputs, bad)``; ``bad`` is True when an unmasked input has a NaN / -inf cost or a
    non-finite increment (the generic kernel then reports it). The hull is ordered by
    offset, then fraction.
    """
    M = d.shape[0]
    valid = np.empty(M, np.int64)
    nv = 0
    bad = False
    dmin = np.inf
    dmax = -np.inf
    for m in range(M):
        if has_mask and mask[m]:
            continue
        c = g[m]
        x = d[m]
        if not (c < np.inf and c > -np.inf and abs(x) < np.inf):
            if c != c or c == -np.inf or (c < np.inf and not abs(x) < np.inf):
                bad = True
            continue
        valid[nv] = m
        nv += 1
        dmin = min(dmin, x)
        dmax = max(dmax, x)
    valid = valid[:nv]
    if nv == 0 or bad:
        return valid, dmin, dmax, nv, bad
    t = d[valid] * inv_dx
    off = np.floor(t)
    frac = t - off
    cost = g[valid]
    order = np.argsort(cost, kind="mergesort")
    order = order[np.argsort(t[order], kind="mergesort")]  # by (offset, fraction), then cost
    hull = np.empty(nv, np.int64)  # positions in ``valid``
    nh = 0
    start = 0  # first hull slot of the current group
    for r in range(nv):
        p = order[r]
        if nh > start and off[hull[nh - 1]] != off[p]:
            start = nh
        if nh > start and frac[hull[nh - 1]] == frac[p]:
            continue  # same fraction, higher or equal cost (sorted): never strictly better
        while nh - start >= 2:
            a = hull[nh - 2]
            b = hull[nh - 1]
            cross = (frac[b] - frac[a]) * (cost[p] - cost[a]) - (cost[b] - cost[a]) * (frac[p] - frac[a])
            if cross <= 0.0:
                nh -= 1
            else:
                break
        hull[nh] = p
        nh += 1
    return valid[hull[:nh]], dmin, dmax, nv, bad


@njit(SIG_HULL, parallel=True, cache=True)
def bellman_1d_hull(
    xb, xn, g, mask, has_mask, grid, uniform, inv_dx, J, V, mode, band, band_i, use_box, box,
    hd, hg, hidx, dmin, dmax, safe_lo, safe_hi, ninf, track_f,
    out_J, out_arg, out_status, out_V, out_argV, out_fmax, out_fmin,
):  # fmt: skip
    """Bellman step for one state with state-independent rows, parallel over the nodes.

    Arguments as :func:`hevsim.optimal._kernels.bellman_1d_par`, plus the hull inputs
    (``hd`` increments, ``hg`` costs, ``hidx`` input indices), the valid increment range
    ``[dmin, dmax]``, the interval ``[safe_lo, safe_hi]`` where the cost-to-go is the plain
    interpolant, ``ninf`` (``ninf[i]`` = number of infinite values in ``J[:i]``) and
    ``track_f`` (report the largest / smallest next state, boundary-line mode). Nodes whose
    every next state lies in the safe interval on finite cells use the hull only; the others
    run the generic row kernel with every input.
    """
    n = grid.shape[0]
    g0 = grid[0]
    gn = grid[n - 1]
    H = hd.shape[0]
    for s in prange(xb.shape[0]):
        xs = xb[s]
        lo = xs + dmin
        hi = xs + dmax
        safe = lo >= safe_lo and hi <= safe_hi
        if safe:
            ilo = int((min(max(lo, g0), gn) - g0) * inv_dx)
            ihi = int((min(max(hi, g0), gn) - g0) * inv_dx)
            ilo = min(max(ilo, 0), n - 2)
            ihi = min(max(ihi, 0), n - 2)
            safe = ninf[ihi + 2] - ninf[ilo] == 0
        if not safe:
            _row_1d(
                s, xb, xn, g, mask, has_mask, grid, uniform, inv_dx, J, V, mode, band, band_i,
                use_box, box, out_J, out_arg, out_status, out_V, out_argV, out_fmax, out_fmin,
            )  # fmt: skip
            continue
        best = np.inf
        arg = -1
        for h in range(H):
            x = xs + hd[h]
            xc = min(max(x, g0), gn)
            tt = (xc - g0) * inv_dx
            i = int(tt)
            if i > n - 2:
                i = n - 2
            w = tt - i
            ja = J[i]
            tot = hg[h] + (ja + w * (J[i + 1] - ja))
            if tot < best:
                best = tot
                arg = hidx[h]
        out_J[s] = best
        out_arg[s] = arg
        out_status[s] = ST_FEASIBLE if best < np.inf else ST_UNREACHABLE
        out_V[s] = np.inf
        out_argV[s] = -1
        out_fmax[s] = hi if track_f else -np.inf
        out_fmin[s] = lo if track_f else np.inf

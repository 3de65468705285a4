"""Numba kernels of the DP solver: one Bellman step over a (states x inputs) block.

A Bellman step receives the model outputs for every (grid node, input) pair, flattened to a
``(S, M)`` block (``S`` state nodes, ``M`` input combinations), and for every node returns
the minimum over the inputs of ``stage cost + cost-to-go(next state)``, the arg-min and a
status code. The cost-to-go is interpolated (multi)linearly on a rectilinear grid, regular
(index by arithmetic) or irregular (index by bisection).

Infinite cost-to-go values mark infeasible nodes. The interpolation treats them exactly: a
point whose interpolation gives a positive weight to an infinite node is infeasible; a
corner with zero weight (a point on a grid line) is ignored. Weights within ``WSNAP`` of 0
or 1 are snapped, so that rounding in ``(x - x0) / dx`` cannot make an on-node point touch
its infeasible neighbour.

A block in which each state moves on its own (next state ``j`` a function of state ``j`` and
the inputs, cost and mask of the inputs only: ``_problem.Separable``) is not flattened: its
per-state tables of cell index, weight and distance outside the grid (:func:`sep_table`) are
read per pair by :func:`bellman_sep2_par` (two states, finite cost-to-go, cache-ordered loop)
or :func:`bellman_sep_par` (any number of states), with the same floating-point operations in
the same order as :func:`bellman_nd_par`, so with the same result bit for bit.

Modes (how the final-state constraint is enforced, see ``dp.py``):

* ``MODE_PLAIN`` (0): plain cost-to-go (hard wall or linear penalty); at the last step the
  target box can be checked exactly (``use_box``).
* ``MODE_LEVELSET`` (1): a pair is admissible only if the interpolated level-set function of
  the next step is <= ``VTOL`` (the next state lies in the backward reachable set). Nodes
  outside the reachable set keep a finite cost (that of the input that comes closest to the
  set), so nothing infinite is interpolated near the boundary of the set.
* ``MODE_BAND`` (2, one state): the next state must lie in the band between the lower and
  upper boundary lines; in the cells cut by a boundary line the cost-to-go is interpolated
  between the boundary point (with its exact boundary-line cost) and the first grid node
  inside the band.
"""

from __future__ import annotations

from types import FunctionType
from typing import Any

import numpy as np
from numba import njit, prange, types

from hevsim.optimal._consts import (
    BTOL,
    MODE_BAND,
    MODE_LEVELSET,
    MODE_PLAIN,
    ST_BAD,
    ST_BOUNDS,
    ST_FEASIBLE,
    ST_MASKED,
    ST_UNREACHABLE,
    V_CAP,
    VTIE,
    VTOL,
    WSNAP,
)

# One compiled version per kernel: every array is typed "any layout" (read-only inputs
# accept writable, strided and broadcast arrays), so that C-contiguous, broadcast and
# sliced model outputs share the same machine code and the cache stays small.
_F1 = types.Array(types.float64, 1, "A", readonly=True)
_F2 = types.Array(types.float64, 2, "A", readonly=True)
_B2 = types.Array(types.boolean, 2, "A", readonly=True)
_B1 = types.Array(types.boolean, 1, "A", readonly=True)
_I1 = types.Array(types.int64, 1, "A", readonly=True)
_OF = types.Array(types.float64, 1, "A")
_OI = types.Array(types.int64, 1, "A")
_OS = types.Array(types.int8, 1, "A")
_BOOL = types.boolean
_F = types.float64
_I = types.int64
SIG_1D = types.void(
    _F1, _F2, _F2, _B2, _BOOL, _F1, _BOOL, _F, _F1, _F1, _I, _F1, _I1, _BOOL, _F1,
    _OF, _OI, _OS, _OF, _OI, _OF, _OF,
)  # fmt: skip
SIG_ND = types.void(
    _F2, _F2, _F2, _F2, _F2, _I, _F2, _B2, _BOOL, _F1, _I1, _B1, _F1, _I1, _F1, _F1, _I,
    _BOOL, _F1, _F1, _OF, _OI, _OS, _OF, _OI,
)  # fmt: skip


def _par_and_ser(body: Any, sig: Any) -> tuple[Any, Any]:
    """Compile the row loop ``body`` (a ``prange`` loop) twice: parallel and serial.

    The solver runs the serial kernel on blocks below ``PARALLEL_MIN_PAIRS`` (``_solver.py``:
    small grids, the one-row steps of the forward pass, boundary-line and point queries),
    which would otherwise pay the thread launch of a parallel region; with
    ``parallel=False``, ``prange`` is a plain ``range``. Each kernel is compiled from a copy
    of ``body`` under its own name (``bellman_1d_par``, ``bellman_1d_ser``, ...): numba's
    disk cache keys a function by module, qualified name, line and bytecode, not by its
    compile flags, so compiling ``body`` itself twice would make the serial kernel load the
    parallel one from the cache.
    """
    kernels = []
    for parallel, suffix in ((True, "par"), (False, "ser")):
        name = f"{body.__name__.lstrip('_')}_{suffix}"
        f = FunctionType(body.__code__, body.__globals__, name)
        f.__qualname__ = name
        f.__doc__ = body.__doc__
        kernels.append(njit(sig, parallel=parallel, cache=True)(f))
    return kernels[0], kernels[1]


@njit(cache=True, inline="always")
def _store_row(s, bad, n_ok, n_inb, best, arg, cost_v, arg_v, v_out, is_ls, out_J, out_arg, out_status, out_V,
               out_argV):  # fmt: skip
    """Write one state's Bellman result: its status (``ST_*``: bad model output, every input
    masked, every next state out of bounds, no finite cost, feasible), cost-to-go and argmin
    (the closest approach's when infeasible; level-set mode keeps its cost), level value
    ``v_out`` and the closest approach's argmin. Shared by the 1-D, n-D and separable rows."""
    if bad:
        status = ST_BAD
    elif n_ok == 0:
        status = ST_MASKED
    elif n_inb == 0:
        status = ST_BOUNDS
    elif best == np.inf:
        status = ST_UNREACHABLE
    else:
        status = ST_FEASIBLE
    out_status[s] = status
    if status == ST_FEASIBLE:
        out_J[s] = best
        out_arg[s] = arg
    else:
        out_J[s] = cost_v if is_ls else np.inf
        out_arg[s] = arg_v
    out_V[s] = v_out
    out_argV[s] = arg_v


@njit(cache=True, inline="always")
def _locate(grid, uniform, inv_dx, x):
    """Cell index ``i`` and weight ``w`` of ``x`` (inside the grid) on ``grid``."""
    n = grid.shape[0]
    if uniform:
        t = (x - grid[0]) * inv_dx
        i = int(np.floor(t))
        if i < 0:
            i = 0
        elif i > n - 2:
            i = n - 2
        w = t - i
    else:
        if x <= grid[0]:
            return 0, 0.0
        if x >= grid[n - 1]:
            return n - 2, 1.0
        lo = 0
        hi = n - 1
        while hi - lo > 1:
            mid = (lo + hi) >> 1
            if grid[mid] <= x:
                lo = mid
            else:
                hi = mid
        i = lo
        w = (x - grid[lo]) / (grid[lo + 1] - grid[lo])
    if w < WSNAP:
        w = 0.0
    elif w > 1.0 - WSNAP:
        w = 1.0
    return i, w


@njit(cache=True, inline="always")
def _lerp_inf(a, b, w):
    """Linear interpolation that is infinite when it touches an infinite end point."""
    if w < WSNAP:
        return 1.0 * a
    if w > 1.0 - WSNAP:
        return 1.0 * b
    if a == np.inf or b == np.inf:
        return np.inf
    return a + w * (b - a)


@njit(cache=True, inline="always")
def _band_value(grid, uniform, inv_dx, J, band, band_i, x):
    """Cost-to-go at ``x`` inside the band ``[band[0], band[2]]`` (boundary-line method)."""
    lo = band[0]
    lo_j = band[1]
    hi = band[2]
    hi_j = band[3]
    if x <= lo:
        return 1.0 * lo_j
    if x >= hi:
        return 1.0 * hi_j
    ilo = band_i[0]
    ihi = band_i[1]
    if ilo > ihi:
        return _lerp_inf(lo_j, hi_j, (x - lo) / (hi - lo))
    glo = grid[ilo]
    if x < glo:
        return _lerp_inf(lo_j, J[ilo], (x - lo) / (glo - lo))
    ghi = grid[ihi]
    if x > ghi:
        return _lerp_inf(J[ihi], hi_j, (x - ghi) / (hi - ghi))
    i, w = _locate(grid, uniform, inv_dx, x)
    return _lerp_inf(J[i], J[i + 1], w)


@njit(cache=True)
def _interp_clamped(grid, uniform, inv_dx, J, x):
    """Cost-to-go at ``x`` clamped to the grid (closest-approach cost of the level set)."""
    xc = min(max(x, grid[0]), grid[grid.shape[0] - 1])
    i, w = _locate(grid, uniform, inv_dx, xc)
    return _lerp_inf(J[i], J[i + 1], w)


@njit(cache=True)
def _is_bad(x, c):
    """NaN / -inf cost or non-finite next state (for a pair whose cost is not +inf)."""
    return c != c or c == -np.inf or (c < np.inf and not abs(x) < np.inf)


@njit(cache=True)
def _loop_plain(s, xb, xn, g, mask, has_mask, grid, uniform, inv_dx, J):
    """Plain cost-to-go (wall / penalty before the last step): the hot loop."""
    M = xn.shape[1]
    n = grid.shape[0]
    g0 = grid[0]
    gn = grid[n - 1]
    span = gn - g0
    lo_b = g0 - BTOL * span
    hi_b = gn + BTOL * span
    best = np.inf
    arg = -1
    n_ok = 0
    n_inb = 0
    bad = False
    xs = xb[s]
    xrow = xn[s]  # row views: one stride per access instead of two
    grow = g[s]
    mrow = mask[s] if has_mask else mask[0]
    for m in range(M):
        if has_mask and mrow[m]:
            continue
        x = xs + xrow[m]
        c = grow[m]
        if not (x >= lo_b and x <= hi_b and c < np.inf and c > -np.inf):
            if _is_bad(x, c):
                bad = True
            elif c < np.inf:
                n_ok += 1  # admissible but outside the state bounds
            continue
        n_inb += 1
        xc = min(max(x, g0), gn)
        if uniform:
            t = (xc - g0) * inv_dx
            i = int(t)
            if i > n - 2:
                i = n - 2
            w = t - i
        else:
            i, w = _locate(grid, uniform, inv_dx, xc)
        ja = J[i]
        jb = J[i + 1]
        jv = ja + w * (jb - ja)
        if not jv < np.inf:  # an infinite node: exact rule (rarely taken)
            jv = _lerp_inf(ja, jb, w)
        tot = c + jv
        if tot < best:
            best = tot
            arg = m
    return best, arg, np.inf, -1, np.inf, -np.inf, np.inf, n_ok + n_inb, n_inb, bad


@njit(cache=True)
def _loop_interval(
    s, xb, xn, g, mask, has_mask, grid, uniform, inv_dx, J, band, band_i, is_band, is_ls, v_lo, v_hi
):
    """Admissible next states form an interval: the boundary-line band or the target box."""
    M = xn.shape[1]
    n = grid.shape[0]
    g0 = grid[0]
    gn = grid[n - 1]
    span = gn - g0
    inv_span = 1.0 / span
    lo_b = g0 - BTOL * span
    hi_b = gn + BTOL * span
    lo_t = v_lo - VTOL * span  # the interval lies inside the grid, so inside => in bounds
    hi_t = v_hi + VTOL * span
    node_lo = g0  # between these nodes the plain interpolation applies
    node_hi = gn
    if is_band:
        node_lo = np.inf
        node_hi = -np.inf
        if band_i[0] <= band_i[1]:
            node_lo = grid[band_i[0]]
            node_hi = grid[band_i[1]]
    best = np.inf
    arg = -1
    best_v = np.inf
    arg_v = -1
    cost_v = np.inf
    v_in = np.inf  # smallest level value among admissible pairs
    fmax = -np.inf
    fmin = np.inf
    n_ok = 0
    n_inb = 0
    bad = False
    xs = xb[s]
    xrow = xn[s]  # row views: one stride per access instead of two
    grow = g[s]
    mrow = mask[s] if has_mask else mask[0]
    for m in range(M):
        if has_mask and mrow[m]:
            continue
        x = xs + xrow[m]
        c = grow[m]
        if not (c < np.inf and c > -np.inf and abs(x) < np.inf):
            if _is_bad(x, c):
                bad = True
            continue
        n_ok += 1
        fmax = max(fmax, x)
        fmin = min(fmin, x)
        if x >= lo_t and x <= hi_t:  # admissible next state
            n_inb += 1
            xc = min(max(x, g0), gn)
            if uniform:
                t = (xc - g0) * inv_dx
                i = int(t)
                if i > n - 2:
                    i = n - 2
                w = t - i
            else:
                i, w = _locate(grid, uniform, inv_dx, xc)
            if xc >= node_lo and xc <= node_hi:
                ja = J[i]
                jb = J[i + 1]
                jv = ja + w * (jb - ja)
                if not jv < np.inf:  # an infinite node: exact rule (rarely taken)
                    jv = _lerp_inf(ja, jb, w)
            else:
                jv = _band_value(grid, uniform, inv_dx, J, band, band_i, xc)
            tot = c + jv
            if tot < best:
                best = tot
                arg = m
            if is_ls:
                v_in = min(v_in, max(v_lo - x, x - v_hi) * inv_span)
            continue
        if x >= lo_b and x <= hi_b:
            n_inb += 1
        v = max(v_lo - x, x - v_hi) * inv_span
        if v <= best_v + VTIE:  # outside: remember the closest approach (ties: lower cost)
            tot = c + _interp_clamped(grid, uniform, inv_dx, J, x) if is_ls else np.inf
            if v < best_v - VTIE or tot < cost_v:
                best_v = min(best_v, v)
                arg_v = m
                cost_v = tot
    return best, arg, min(best_v, v_in), arg_v, cost_v, fmax, fmin, n_ok, n_inb, bad


@njit(cache=True)
def _loop_levelset(s, xb, xn, g, mask, has_mask, grid, uniform, inv_dx, J, V):
    """Level-set restriction: admissible if the interpolated ``V`` is <= VTOL."""
    M = xn.shape[1]
    n = grid.shape[0]
    g0 = grid[0]
    gn = grid[n - 1]
    span = gn - g0
    inv_span = 1.0 / span
    lo_b = g0 - BTOL * span
    hi_b = gn + BTOL * span
    best = np.inf
    arg = -1
    best_v = np.inf
    arg_v = -1
    cost_v = np.inf
    v_in = np.inf  # smallest level value among admissible pairs
    n_ok = 0
    n_inb = 0
    bad = False
    xs = xb[s]
    xrow = xn[s]  # row views: one stride per access instead of two
    grow = g[s]
    mrow = mask[s] if has_mask else mask[0]
    for m in range(M):
        if has_mask and mrow[m]:
            continue
        x = xs + xrow[m]
        c = grow[m]
        if not (c < np.inf and c > -np.inf and abs(x) < np.inf):
            if _is_bad(x, c):
                bad = True
            continue
        n_ok += 1
        inb = x >= lo_b and x <= hi_b
        xc = min(max(x, g0), gn)
        if uniform:
            t = (xc - g0) * inv_dx
            i = int(t)
            if i > n - 2:
                i = n - 2
            w = t - i
        else:
            i, w = _locate(grid, uniform, inv_dx, xc)
        va = V[i]
        v = va + w * (V[i + 1] - va)
        if inb:
            n_inb += 1
        else:
            v = max(v, 0.0) + ((g0 - x) if x < g0 else (x - gn)) * inv_span
        ja = J[i]
        jb = J[i + 1]
        if v > VTOL:  # outside the reachable set: only remember the closest approach
            if v <= best_v + VTIE:  # closest approach (ties: lower cost)
                tot = c + _lerp_inf(ja, jb, w)
                if v < best_v - VTIE or tot < cost_v:
                    best_v = min(best_v, v)
                    arg_v = m
                    cost_v = tot
            continue
        v_in = min(v_in, v)
        jv = ja + w * (jb - ja)
        if not jv < np.inf:  # an infinite node: exact rule (rarely taken)
            jv = _lerp_inf(ja, jb, w)
        tot = c + jv
        if inb and tot < best:
            best = tot
            arg = m
    return best, arg, min(best_v, v_in), arg_v, cost_v, -np.inf, np.inf, n_ok, n_inb, bad


@njit(cache=True)
def _row_1d(
    s,
    xb,
    xn,
    g,
    mask,
    has_mask,
    grid,
    uniform,
    inv_dx,
    J,
    V,
    mode,
    band,
    band_i,
    use_box,
    box,
    out_J,
    out_arg,
    out_status,
    out_V,
    out_argV,
    out_fmax,
    out_fmin,
):
    """Bellman step of row ``s`` (one state node) for one state variable."""
    is_ls = mode == MODE_LEVELSET
    if mode == MODE_PLAIN and not use_box:
        res = _loop_plain(s, xb, xn, g, mask, has_mask, grid, uniform, inv_dx, J)
    elif mode == MODE_BAND:
        res = _loop_interval(
            s,
            xb,
            xn,
            g,
            mask,
            has_mask,
            grid,
            uniform,
            inv_dx,
            J,
            band,
            band_i,
            True,
            False,
            band[0],
            band[2],
        )
    elif use_box:
        res = _loop_interval(
            s,
            xb,
            xn,
            g,
            mask,
            has_mask,
            grid,
            uniform,
            inv_dx,
            J,
            band,
            band_i,
            False,
            is_ls,
            box[0],
            box[1],
        )
    else:
        res = _loop_levelset(s, xb, xn, g, mask, has_mask, grid, uniform, inv_dx, J, V)
    best, arg, best_v, arg_v, cost_v, fmax, fmin, n_ok, n_inb, bad = res
    v_out = best_v if n_ok > 0 else V_CAP
    _store_row(s, bad, n_ok, n_inb, best, arg, cost_v, arg_v, v_out, is_ls, out_J, out_arg, out_status, out_V,
               out_argV)  # fmt: skip
    out_fmax[s] = fmax
    out_fmin[s] = fmin


def _bellman_1d(
    xb, xn, g, mask, has_mask, grid, uniform, inv_dx, J, V, mode, band, band_i, use_box, box,
    out_J, out_arg, out_status, out_V, out_argV, out_fmax, out_fmin,
):  # fmt: skip
    """One Bellman step for one state variable, over the rows (state nodes).

    ``xn``, ``g``, ``mask``: (S, M) next state, stage cost, infeasibility mask.
    ``J``, ``V``: cost-to-go and level-set function of the next step on ``grid``.
    ``band``: ``[lo, J(lo), hi, J(hi)]`` of the boundary lines at the next step,
    ``band_i``: first and last grid node inside the band. ``box``: ``[lo, hi]`` target.
    Outputs (length S): cost, arg-min input, status, level value, input closest to the
    admissible set, largest and smallest unmasked next state.
    """
    for s in prange(xn.shape[0]):
        _row_1d(
            s, xb, xn, g, mask, has_mask, grid, uniform, inv_dx, J, V, mode, band, band_i, use_box,
            box, out_J, out_arg, out_status, out_V, out_argV, out_fmax, out_fmin,
        )  # fmt: skip


bellman_1d_par, bellman_1d_ser = _par_and_ser(_bellman_1d, SIG_1D)


@njit(cache=True)
def _row_nd(
    s,
    xb,
    x1,
    x2,
    x3,
    x4,
    d,
    g,
    mask,
    has_mask,
    gflat,
    goff,
    guni,
    ginv,
    gstride,
    J,
    V,
    mode,
    use_box,
    box_lo,
    box_hi,
    out_J,
    out_arg,
    out_status,
    out_V,
    out_argV,
):
    """Bellman step of row ``s`` (one state node) for 2 to 4 state variables."""
    M = g.shape[1]
    ncorner = 1 << d
    track = mode != MODE_PLAIN or use_box
    idx = np.empty(4, np.int64)
    w = np.empty(4)
    xv = np.empty(4)
    best = np.inf
    arg = -1
    best_v = np.inf
    arg_v = -1
    cost_v = np.inf
    v_in = np.inf  # smallest level value among admissible pairs
    n_ok = 0
    n_inb = 0
    bad = False
    for m in range(M):
        if has_mask and mask[s, m]:
            continue
        c = g[s, m]
        xv[0] = xb[0, s] + x1[s, m]
        if d > 1:
            xv[1] = xb[1, s] + x2[s, m]
        if d > 2:
            xv[2] = xb[2, s] + x3[s, m]
        if d > 3:
            xv[3] = xb[3, s] + x4[s, m]
        finite = True
        for j in range(d):
            if not np.isfinite(xv[j]):
                finite = False
        if not finite or np.isnan(c) or c == -np.inf:
            bad = True
            continue
        if c == np.inf:
            continue
        n_ok += 1
        inb = True
        dout = 0.0
        vbox = -np.inf  # target level value: max_j d_j (Chebyshev distance, both sides)
        for j in range(d):
            a = goff[j]
            b = goff[j + 1]
            lo = gflat[a]
            hi = gflat[b - 1]
            sp = hi - lo
            x = xv[j]
            if use_box:
                dj = max((box_lo[j] - x) / sp, (x - box_hi[j]) / sp)
                vbox = max(vbox, dj)
            if x < lo - BTOL * sp:
                inb = False
                dout += (lo - x) / sp
                x = lo
            elif x > hi + BTOL * sp:
                inb = False
                dout += (x - hi) / sp
                x = hi
            else:
                x = min(max(x, lo), hi)
            ij, wj = _locate(gflat[a:b], guni[j], ginv[j], x)
            idx[j] = ij
            w[j] = wj
        if not inb and not track:
            continue
        jacc = 0.0
        vacc = 0.0
        jinf = False
        for cidx in range(ncorner):
            wt = 1.0
            flat = 0
            for j in range(d):
                if (cidx >> j) & 1:
                    wt *= w[j]
                    flat += (idx[j] + 1) * gstride[j]
                else:
                    wt *= 1.0 - w[j]
                    flat += idx[j] * gstride[j]
            if wt == 0.0:
                continue
            jc = J[flat]
            if jc == np.inf:
                jinf = True
            else:
                jacc += wt * jc
            if mode == MODE_LEVELSET:
                vacc += wt * V[flat]
        if use_box:
            v = vbox
        elif mode == MODE_LEVELSET:
            v = vacc if inb else max(vacc, 0.0) + dout
        else:
            v = 0.0
        if inb:
            n_inb += 1
        tot = np.inf if jinf else c + jacc
        if v > VTOL or not inb:  # inadmissible: remember the closest approach (cost at the
            # clamped state; equal level values, up to VTIE, are broken by the lower cost)
            if v < best_v - VTIE or (v <= best_v + VTIE and tot < cost_v):
                best_v = min(best_v, v)
                arg_v = m
                cost_v = tot
            continue
        v_in = min(v_in, v)
        if tot < best:
            best = tot
            arg = m
    v_out = min(best_v, v_in) if n_ok > 0 else V_CAP
    _store_row(s, bad, n_ok, n_inb, best, arg, cost_v, arg_v, v_out, mode == MODE_LEVELSET, out_J, out_arg,
               out_status, out_V, out_argV)  # fmt: skip


def _bellman_nd(
    xb, x1, x2, x3, x4, d, g, mask, has_mask, gflat, goff, guni, ginv, gstride, J, V, mode,
    use_box, box_lo, box_hi, out_J, out_arg, out_status, out_V, out_argV,
):  # fmt: skip
    """One Bellman step for 2 to 4 state variables (modes plain and level set).

    ``x1..x4``: (S, M) next-state components (unused ones are dummies); the grid of
    dimension ``j`` is ``gflat[goff[j]:goff[j+1]]`` and its flat-index stride ``gstride[j]``.
    Other arguments as in :func:`_bellman_1d`.
    """
    for s in prange(g.shape[0]):
        _row_nd(
            s, xb, x1, x2, x3, x4, d, g, mask, has_mask, gflat, goff, guni, ginv, gstride, J, V,
            mode, use_box, box_lo, box_hi, out_J, out_arg, out_status, out_V, out_argV,
        )  # fmt: skip


bellman_nd_par, bellman_nd_ser = _par_and_ser(_bellman_nd, SIG_ND)


# ------------------------------------------------------------------ separable blocks
_OI2 = types.Array(types.int64, 2, "A")
_OF2 = types.Array(types.float64, 2, "A")
SIG_TAB = types.void(_F2, _F1, _BOOL, _F, _OI2, _OF2, _OF2)


@njit(SIG_TAB, cache=True)
def sep_table(x, gflat_j, uniform, inv_dx, out_i, out_w, out_d):
    """Interpolation table of one state of a separable block (``_problem.Separable``).

    ``x``: (n_j, M) next values of state ``j``. Outputs, per (node, input): the cell index
    (-1 for a non-finite value), the weight and the span-normalised distance outside the
    grid (0 inside the bounds tolerance), computed exactly as :func:`_row_nd` does per pair.
    """
    n = gflat_j.shape[0]
    lo = gflat_j[0]
    hi = gflat_j[n - 1]
    sp = hi - lo
    for i in range(x.shape[0]):
        for m in range(x.shape[1]):
            xv = x[i, m]
            if not np.isfinite(xv):
                out_i[i, m] = -1
                out_w[i, m] = 0.0
                out_d[i, m] = 0.0
                continue
            dout = 0.0
            if xv < lo - BTOL * sp:
                dout = (lo - xv) / sp
                xv = lo
            elif xv > hi + BTOL * sp:
                dout = (xv - hi) / sp
                xv = hi
            else:
                xv = min(max(xv, lo), hi)
            ij, wj = _locate(gflat_j, uniform, inv_dx, xv)
            out_i[i, m] = ij
            out_w[i, m] = wj
            out_d[i, m] = dout


_I3 = types.Array(types.int64, 3, "A", readonly=True)
_F3 = types.Array(types.float64, 3, "A", readonly=True)
SIG_SEP = types.void(
    _I3, _F3, _F3, _I1, _I, _F1, _B1, _BOOL, _I1, _F1, _F1, _I, _OF, _OI, _OS, _OF, _OI,
)  # fmt: skip


@njit(cache=True)
def _row_sep(s, ti, tw, td, dims, d, g, mask, has_mask, gstride, J, V, mode, out_J, out_arg,
             out_status, out_V, out_argV):  # fmt: skip
    """Bellman step of row ``s`` of a separable block (level-set or plain mode, no target
    box): :func:`_row_nd` with the cell indices, weights and bound distances read from the
    per-state tables of :func:`sep_table` instead of computed per pair; the same
    floating-point operations in the same order, so the same result bit for bit."""
    M = g.shape[0]
    ncorner = 1 << d
    track = mode != MODE_PLAIN
    node = np.empty(4, np.int64)
    rem = s
    for j in range(d - 1, -1, -1):
        node[j] = rem % dims[j]
        rem //= dims[j]
    best = np.inf
    arg = -1
    best_v = np.inf
    arg_v = -1
    cost_v = np.inf
    v_in = np.inf
    n_ok = 0
    n_inb = 0
    bad = False
    for m in range(M):
        if has_mask and mask[m]:
            continue
        c = g[m]
        finite = True
        for j in range(d):
            if ti[j, node[j], m] < 0:
                finite = False
        if not finite or np.isnan(c) or c == -np.inf:
            bad = True
            continue
        if c == np.inf:
            continue
        n_ok += 1
        dout = 0.0
        for j in range(d):
            dout += td[j, node[j], m]
        inb = dout == 0.0
        if not inb and not track:
            continue
        jacc = 0.0
        vacc = 0.0
        jinf = False
        for cidx in range(ncorner):
            wt = 1.0
            flat = 0
            for j in range(d):
                wj = tw[j, node[j], m]
                ij = ti[j, node[j], m]
                if (cidx >> j) & 1:
                    wt *= wj
                    flat += (ij + 1) * gstride[j]
                else:
                    wt *= 1.0 - wj
                    flat += ij * gstride[j]
            if wt == 0.0:
                continue
            jc = J[flat]
            if jc == np.inf:
                jinf = True
            else:
                jacc += wt * jc
            if mode == MODE_LEVELSET:
                vacc += wt * V[flat]
        if mode == MODE_LEVELSET:
            v = vacc if inb else max(vacc, 0.0) + dout
        else:
            v = 0.0
        if inb:
            n_inb += 1
        tot = np.inf if jinf else c + jacc
        if v > VTOL or not inb:
            if v < best_v - VTIE or (v <= best_v + VTIE and tot < cost_v):
                best_v = min(best_v, v)
                arg_v = m
                cost_v = tot
            continue
        v_in = min(v_in, v)
        if tot < best:
            best = tot
            arg = m
    v_out = min(best_v, v_in) if n_ok > 0 else V_CAP
    _store_row(s, bad, n_ok, n_inb, best, arg, cost_v, arg_v, v_out, mode == MODE_LEVELSET, out_J, out_arg,
               out_status, out_V, out_argV)  # fmt: skip


def _bellman_sep(
    ti, tw, td, dims, d, g, mask, has_mask, gstride, J, V, mode, out_J, out_arg, out_status,
    out_V, out_argV,
):  # fmt: skip
    """One Bellman step over the rows of a separable block (see :func:`_row_sep`).

    ``ti``, ``tw``, ``td``: (d, max n_j, M) tables of :func:`sep_table`; ``dims``: nodes
    per state; ``g``, ``mask``: (M,) stage cost and mask. Outputs as :func:`_bellman_nd`.
    """
    S = out_J.shape[0]
    for s in prange(S):
        _row_sep(
            s, ti, tw, td, dims, d, g, mask, has_mask, gstride, J, V, mode, out_J, out_arg,
            out_status, out_V, out_argV,
        )  # fmt: skip


bellman_sep_par, bellman_sep_ser = _par_and_ser(_bellman_sep, SIG_SEP)


_I2 = types.Array(types.int64, 2, "A", readonly=True)
SIG_SEP2 = types.void(
    _I2, _F2, _F2, _I2, _F2, _F2, _F1, _B1, _BOOL, _F1, _F1, _BOOL, _OF, _OI, _OS, _OF, _OI,
)  # fmt: skip


def _bellman_sep2(
    i0t, w0t, d0t, i1t, w1t, d1t, g, mask, has_mask, J, V, is_ls, out_J, out_arg, out_status,
    out_V, out_argV,
):  # fmt: skip
    """:func:`_bellman_sep` for two states and a cost-to-go and level-set function without
    infinite nodes, ordered for the cache: rows of state 1 outermost, then the inputs, then
    the nodes of state 2 (whose table rows ``i1t[m]``, ``w1t[m]``, ``d1t[m]``, (M, n2), are
    contiguous). The same floating-point operations per pair as :func:`_row_nd` (a zero
    corner weight adds an exact zero instead of being skipped, which is the same sum with
    finite values), and the inputs are visited in the same order for every node, so the
    result is the same bit for bit. Tables: ``i0t``, ``w0t``, ``d0t`` (n1, M).
    """
    n0 = i0t.shape[0]
    M = g.shape[0]
    n1 = i1t.shape[1]
    for r in prange(n0):
        best = np.full(n1, np.inf)
        arg = np.full(n1, -1, np.int64)
        best_v = np.full(n1, np.inf)
        arg_v = np.full(n1, -1, np.int64)
        cost_v = np.full(n1, np.inf)
        v_in = np.full(n1, np.inf)
        n_ok = np.zeros(n1, np.int64)
        n_inb = np.zeros(n1, np.int64)
        bad = np.zeros(n1, np.bool_)
        for m in range(M):
            if has_mask and mask[m]:
                continue
            c = g[m]
            ia = i0t[r, m]
            ib_row = i1t[m]
            if ia < 0 or np.isnan(c) or c == -np.inf:
                bad[:] = True
                continue
            if c == np.inf:
                for i1 in range(n1):
                    if ib_row[i1] < 0:
                        bad[i1] = True
                continue
            w0 = w0t[r, m]
            a0 = 1.0 - w0
            d0 = d0t[r, m]
            f0 = ia * n1
            f1 = f0 + n1
            w1_row = w1t[m]
            d1_row = d1t[m]
            for i1 in range(n1):
                ib = ib_row[i1]
                if ib < 0:
                    bad[i1] = True
                    continue
                n_ok[i1] += 1
                dout = 0.0
                dout += d0
                dout += d1_row[i1]
                inb = dout == 0.0
                if not inb and not is_ls:
                    continue
                w1 = w1_row[i1]
                a1 = 1.0 - w1
                wt00 = a0 * a1
                wt10 = w0 * a1
                wt01 = a0 * w1
                wt11 = w0 * w1
                if is_ls:
                    vacc = 0.0
                    vacc += wt00 * V[f0 + ib]
                    vacc += wt10 * V[f1 + ib]
                    vacc += wt01 * V[f0 + ib + 1]
                    vacc += wt11 * V[f1 + ib + 1]
                    v = vacc if inb else max(vacc, 0.0) + dout
                else:
                    v = 0.0
                if inb:
                    n_inb[i1] += 1
                outside = v > VTOL or not inb
                if outside and v > best_v[i1] + VTIE:
                    continue  # cannot be the closest approach: the cost is not needed
                jacc = 0.0
                jacc += wt00 * J[f0 + ib]
                jacc += wt10 * J[f1 + ib]
                jacc += wt01 * J[f0 + ib + 1]
                jacc += wt11 * J[f1 + ib + 1]
                tot = c + jacc
                if outside:
                    if v < best_v[i1] - VTIE or tot < cost_v[i1]:
                        best_v[i1] = min(best_v[i1], v)
                        arg_v[i1] = m
                        cost_v[i1] = tot
                    continue
                v_in[i1] = min(v_in[i1], v)
                if tot < best[i1]:
                    best[i1] = tot
                    arg[i1] = m
        for i1 in range(n1):
            s = r * n1 + i1
            if bad[i1]:
                status = ST_BAD
            elif n_ok[i1] == 0:
                status = ST_MASKED
            elif n_inb[i1] == 0:
                status = ST_BOUNDS
            elif best[i1] == np.inf:
                status = ST_UNREACHABLE
            else:
                status = ST_FEASIBLE
            out_status[s] = status
            if status == ST_FEASIBLE:
                out_J[s] = best[i1]
                out_arg[s] = arg[i1]
            else:
                out_J[s] = cost_v[i1] if is_ls else np.inf
                out_arg[s] = arg_v[i1]
            out_V[s] = min(best_v[i1], v_in[i1]) if n_ok[i1] > 0 else V_CAP
            out_argV[s] = arg_v[i1]


bellman_sep2_par, bellman_sep2_ser = _par_and_ser(_bellman_sep2, SIG_SEP2)

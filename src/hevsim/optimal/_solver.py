"""Backward recursion, forward pass, costate and infeasibility diagnosis of the DP solver."""

from __future__ import annotations

import itertools
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from hevsim.errors import DPInfeasibleError
from hevsim.optimal import _consts as kn
from hevsim.optimal._problem import Block, DPProblem, Evaluator, FloatArray, IntArray

METHODS = ("boundary_line", "levelset", "wall", "penalty")
_MODE = {
    "wall": kn.MODE_PLAIN,
    "penalty": kn.MODE_PLAIN,
    "levelset": kn.MODE_LEVELSET,
    "boundary_line": kn.MODE_BAND,
}
REFINE_POINTS = 17  # states evaluated per boundary-line refinement
LAND_STEPS_PER_STATE = 8  # the landing corrects at most this many final steps per state
POLISH = True  # re-optimise the landed window for cost (SLSQP)
FWD_REFINE = True  # level set, 2+ states: refine the forward pass's grid arg-min input
FWD_REFINE_SUB = 10  # sub-steps tried in the grid cell the admission boundary cuts
PARALLEL_MIN_PAIRS = 20_000  # blocks smaller than this run the serial kernel
_DUMMY_MASK = np.zeros((1, 1), dtype=np.bool_)
_DUMMY_X = np.zeros((1, 1))


USE_HULL = True  # exact convex-hull input pruning for state-independent 1-D blocks (_hull.py)
USE_SEPARABLE = True  # per-state interpolation tables for separable blocks (_problem.Separable)


def _hull() -> Any:
    """The convex-hull kernels (imported, and loaded from numba's cache, on first use)."""
    import hevsim.optimal._hull as hull

    return hull


def _numba_threads() -> int:
    """Threads numba's parallel kernels use now (set by :func:`hevsim.threads.apply_threads`)."""
    import numba

    return int(numba.get_num_threads())


def _kernels() -> Any:
    """The numba kernels, imported (and loaded from numba's cache) on first use only."""
    import hevsim.optimal._kernels as kernels

    return kernels


@dataclass
class StepOut:
    J: FloatArray
    arg: IntArray
    status: npt.NDArray[np.int8]
    V: FloatArray
    arg_v: IntArray
    fmax: FloatArray
    fmin: FloatArray


@dataclass
class Backward:
    """What the backward recursion leaves for the forward pass and the diagnosis."""

    J: np.ndarray | None  # (N+1, S) stored cost-to-go
    V: np.ndarray | None  # (N+1, S) stored level-set function
    policy: npt.NDArray[np.int32] | None  # (N, S) arg-min input (flat index)
    status: npt.NDArray[np.int8] | None  # (N, S) node status
    band: FloatArray | None  # (N+1, 4) [lo, J(lo), hi, J(hi)] (boundary line)
    band_i: IntArray | None  # (N+1, 2)
    n_feasible: IntArray  # (N+1,)
    empty_step: int | None  # largest k at which the admissible set is empty
    J0: FloatArray  # cost-to-go, level set and status at the earliest step computed
    V0: FloatArray
    k0: int


class DPSolver:
    """Runs one DP solution; holds the problem, the method and the storage choices.

    (Named ``DPSolver``, not ``Engine``: :class:`hevsim.components.engine.Engine` is the
    combustion engine.)"""

    def __init__(
        self,
        problem: DPProblem,
        method: str,
        penalty_weight: FloatArray | None,
        cost_dtype: npt.DTypeLike,
    ) -> None:
        self.problem = problem
        self.space = problem.space
        self.ev = Evaluator(problem)
        self.method = method
        self.mode = _MODE[method]
        self.penalty_weight = penalty_weight
        self.cost_dtype = np.dtype(cost_dtype)
        self.N = self.space.n_steps
        sp = self.space
        self.btol = kn.BTOL * sp.span
        self.box = (sp.box_lo, sp.box_hi)  # target box of the recursion being run
        self.last_fractional: dict[int, tuple] = {}  # fractional inputs of the last step

    # ------------------------------------------------------------------ kernels
    def step(
        self,
        blk: Block,
        J: np.ndarray,
        V: np.ndarray | None,
        band: FloatArray,
        band_i: IntArray,
        use_box: bool,
        mode: int | None = None,
    ) -> StepOut:
        """One Bellman step on a flattened block (any number of rows)."""
        sp = self.space
        mode = self.mode if mode is None else mode
        S = int(np.prod(blk.shape[: sp.d]))
        M = int(np.prod(blk.shape[sp.d :]))
        out_J = np.empty(S)
        out_arg = np.empty(S, dtype=np.int64)
        out_status = np.empty(S, dtype=np.int8)
        out_V = np.empty(S)
        out_argv = np.empty(S, dtype=np.int64)
        J = np.asarray(J, dtype=np.float64)  # stored float32 rows are widened
        Vk = J if V is None else np.asarray(V, dtype=np.float64)
        big = S >= 2 and S * M >= PARALLEL_MIN_PAIRS
        # the thread policy (hevsim.threads): one thread -> the serial Bellman kernels
        parallel = big and _numba_threads() > 1
        if (
            USE_SEPARABLE
            and blk.sep is not None
            and not use_box
            and mode in (kn.MODE_PLAIN, kn.MODE_LEVELSET)
        ):
            self._sep_step(blk, J, Vk, mode, parallel, out_J, out_arg, out_status, out_V, out_argv)
            return StepOut(out_J, out_arg, out_status, out_V, out_argv, out_V, out_V)
        if sp.d == 1 and USE_HULL and big and not use_box:
            hull = self._hull_step(blk, J, Vk, band, band_i, mode)
            if hull is not None:
                return hull
        has_mask = blk.mask is not None
        mask = blk.mask if blk.mask is not None else _DUMMY_MASK
        if sp.d == 1:
            fmax = np.empty(S)
            fmin = np.empty(S)
            box = np.array([self.box[0][0], self.box[1][0]])
            kernel_1d = _kernels().bellman_1d_par if parallel else _kernels().bellman_1d_ser
            kernel_1d(
                blk.base[0],
                blk.xn[0],
                blk.g,
                mask,
                has_mask,
                sp.grids[0],
                bool(sp.uniform[0]),
                float(sp.inv_dx[0]),
                J,
                Vk,
                mode,
                band,
                band_i,
                use_box,
                box,
                out_J,
                out_arg,
                out_status,
                out_V,
                out_argv,
                fmax,
                fmin,
            )
        else:
            fmax = fmin = out_V
            xs = [*blk.xn, *([_DUMMY_X] * (4 - sp.d))]
            xb = np.zeros((4, S))
            for j in range(sp.d):
                xb[j] = blk.base[j]
            kernel_nd = _kernels().bellman_nd_par if parallel else _kernels().bellman_nd_ser
            kernel_nd(
                xb,
                xs[0],
                xs[1],
                xs[2],
                xs[3],
                sp.d,
                blk.g,
                mask,
                has_mask,
                sp.gflat,
                sp.goff,
                sp.uniform,
                sp.inv_dx,
                sp.gstride,
                J,
                Vk,
                mode,
                use_box,
                self.box[0],
                self.box[1],
                out_J,
                out_arg,
                out_status,
                out_V,
                out_argv,
            )
        return StepOut(out_J, out_arg, out_status, out_V, out_argv, fmax, fmin)

    def _sep_step(
        self,
        blk: Block,
        J: FloatArray,
        V: FloatArray,
        mode: int,
        parallel: bool,
        *outs: np.ndarray,
    ) -> None:
        """Bellman step of a separable block (:class:`~hevsim.optimal._problem.Separable`):
        per-state interpolation tables, then the row kernel reads them (same result as the
        flattened block, without forming it)."""
        sp = self.space
        sep = blk.sep
        assert sep is not None
        kern = _kernels()
        M = sep.g.shape[0]
        nmax = max(sp.shape)
        ti = np.zeros((sp.d, nmax, M), dtype=np.int64)
        tw = np.zeros((sp.d, nmax, M))
        td = np.zeros((sp.d, nmax, M))
        for j in range(sp.d):
            n = sp.grids[j].size
            kern.sep_table(
                sep.x[j],
                sp.grids[j],
                bool(sp.uniform[j]),
                float(sp.inv_dx[j]),
                ti[j, :n],
                tw[j, :n],
                td[j, :n],
            )
        has_mask = sep.mask is not None
        mask = sep.mask if sep.mask is not None else _DUMMY_MASK[0]
        if sp.d == 2 and np.isfinite(J).all() and (mode != kn.MODE_LEVELSET or np.isfinite(V).all()):
            n0, n1 = sp.shape
            kernel2 = kern.bellman_sep2_par if parallel else kern.bellman_sep2_ser
            kernel2(
                ti[0, :n0], tw[0, :n0], td[0, :n0],
                np.ascontiguousarray(ti[1, :n1].T), np.ascontiguousarray(tw[1, :n1].T),
                np.ascontiguousarray(td[1, :n1].T),
                sep.g, mask, has_mask, J, V, mode == kn.MODE_LEVELSET, *outs,
            )  # fmt: skip
            return
        dims = np.array(sp.shape, dtype=np.int64)
        kernel = kern.bellman_sep_par if parallel else kern.bellman_sep_ser
        kernel(ti, tw, td, dims, sp.d, sep.g, mask, has_mask, sp.gstride, J, V, mode, *outs)

    def _hull_step(
        self, blk: Block, J: FloatArray, V: FloatArray, band: FloatArray, band_i: IntArray, mode: int
    ) -> StepOut | None:
        """Bellman step with exact convex-hull input pruning (see :mod:`hevsim.optimal._hull`),
        or None when it does not apply: one state on a regular grid, plain or boundary-line
        mode, and a block whose increments, costs and mask are the same for every node."""
        sp = self.space
        if mode not in (kn.MODE_PLAIN, kn.MODE_BAND) or not bool(sp.uniform[0]):
            return None
        xn, g, mask = blk.xn[0], blk.g, blk.mask
        if xn.strides[0] != 0 or g.strides[0] != 0 or (mask is not None and mask.strides[0] != 0):
            return None
        grid = sp.grids[0]
        if mode == kn.MODE_BAND:
            if band_i[0] > band_i[1]:
                return None
            safe_lo, safe_hi = float(grid[band_i[0]]), float(grid[band_i[1]])
        else:
            safe_lo, safe_hi = float(grid[0]), float(grid[-1])
        hull_mod = _hull()
        has_mask = mask is not None
        mrow = mask[0] if mask is not None else _DUMMY_MASK[0]
        inv_dx = float(sp.inv_dx[0])
        hidx, dmin, dmax, n_valid, bad = hull_mod.hull_inputs(xn[0], g[0], mrow, has_mask, inv_dx)
        if bad or n_valid == 0:
            return None
        S = g.shape[0]
        out_J = np.empty(S)
        out_arg = np.empty(S, dtype=np.int64)
        out_status = np.empty(S, dtype=np.int8)
        out_V = np.empty(S)
        out_argv = np.empty(S, dtype=np.int64)
        fmax = np.empty(S)
        fmin = np.empty(S)
        ninf = np.concatenate([[0], np.cumsum(np.isinf(J))]).astype(np.int64)
        box = np.array([self.box[0][0], self.box[1][0]])
        hull_mod.bellman_1d_hull(
            blk.base[0], xn, g, mask if mask is not None else _DUMMY_MASK, has_mask, grid, True, inv_dx,
            J, V, mode, band, band_i, False, box,
            np.ascontiguousarray(xn[0][hidx]), np.ascontiguousarray(g[0][hidx]), hidx,
            float(dmin), float(dmax), safe_lo, safe_hi, ninf, mode == kn.MODE_BAND,
            out_J, out_arg, out_status, out_V, out_argv, fmax, fmin,
        )  # fmt: skip
        return StepOut(out_J, out_arg, out_status, out_V, out_argv, fmax, fmin)

    def bellman(
        self,
        blk: Block,
        k: int,
        Jn: np.ndarray,
        Vn: np.ndarray | None,
        band: FloatArray,
        band_i: IntArray,
    ) -> StepOut:
        """Bellman step ``k``; at the last step the terminal cost, the linear penalty and
        the target box are evaluated exactly at the next states instead of interpolated."""
        if k != self.N - 1:
            return self.step(blk, Jn, Vn, band, band_i, False)
        blk = self._fold_terminal(blk, k)
        Jz = np.where(np.isinf(Jn), np.inf, 0.0)
        bz = band.copy()
        bz[1] = bz[3] = 0.0
        out = self.step(blk, Jz, Vn, bz, band_i, self.method in ("wall", "levelset"))
        if self.method != "penalty":
            self.last_fractional = self._fractional_last_step(blk, out, bz)
        return out

    def _fractional_last_step(self, blk: Block, out: StepOut, band: FloatArray) -> dict[int, tuple]:
        """Last step: reach a target narrower than the input grid with a fractional input.

        A node from which no grid input lands in the target box (an equality target
        ``lower == upper``, or a window narrower than the spacing of the next states) is
        still feasible when two neighbouring values of one continuous input land on either
        side of it: the input between them reaches the box (the model is continuous in
        its inputs). The node's cost is the linear interpolation of the two stage costs
        (terminal cost included) at the entry point into the box, the cheaper end of the
        admissible part of the segment. Updates ``out`` in place and returns, per updated
        row, ``(input axis, flat index A, flat index B, theta)`` for the forward pass.
        """
        sp = self.space
        if self.mode == kn.MODE_BAND:
            lo = np.array([band[0]])
            hi = np.array([band[2]])
        else:
            lo, hi = self.box
        rows = np.flatnonzero((out.status == kn.ST_UNREACHABLE) | (out.status == kn.ST_BOUNDS))
        cont = [a for a in range(sp.q) if not sp.discrete[a] and sp.inputs[a].size > 1]
        if rows.size == 0 or not cont:
            return {}
        R = rows.size
        ishape = (R, *blk.shape[sp.d :])
        g = blk.g[rows]
        valid = np.isfinite(g)
        if blk.mask is not None:
            valid &= ~blk.mask[rows]
        xs = []
        for j in range(sp.d):
            x = blk.base[j][rows][:, None] + blk.xn[j][rows]
            valid &= np.isfinite(x)
            xs.append(x.reshape(ishape))
        g = g.reshape(ishape)
        valid = valid.reshape(ishape)
        # only rows whose valid next states reach both sides of every face of the box can
        # hold a segment that meets it (the rest is most of the grid, and costs most)
        near = np.ones(R, dtype=bool)
        with np.errstate(invalid="ignore"):
            for j in range(sp.d):
                tol = kn.VTOL * sp.span[j]
                vx = valid & (xs[j] <= hi[j] + tol)
                near &= vx.reshape(R, -1).any(axis=1)
                vx = valid & (xs[j] >= lo[j] - tol)
                near &= vx.reshape(R, -1).any(axis=1)
        if not near.all():
            rows, g, valid = rows[near], g[near], valid[near]
            xs = [x[near] for x in xs]
            R = rows.size
            ishape = (R, *ishape[1:])
            if R == 0:
                return {}
        flat_idx = np.arange(int(np.prod(ishape[1:]))).reshape(ishape[1:])
        best = np.full(R, np.inf)
        info: dict[int, tuple] = {}
        choice = np.full((R, 4), -1.0)
        for a in cont:
            ax = 1 + a
            sl_a = [slice(None)] * len(ishape)
            sl_b = [slice(None)] * len(ishape)
            sl_a[ax] = slice(0, -1)
            sl_b[ax] = slice(1, None)
            ta, tb = tuple(sl_a), tuple(sl_b)
            ok = valid[ta] & valid[tb]
            t0 = np.zeros(ok.shape)
            t1 = np.ones(ok.shape)
            with np.errstate(divide="ignore", invalid="ignore"):
                for j in range(sp.d):
                    tol = kn.VTOL * sp.span[j]
                    xa, xb = xs[j][ta], xs[j][tb]
                    p = xb - xa
                    flat_seg = p == 0.0
                    ok &= ~flat_seg | ((xa >= lo[j] - tol) & (xa <= hi[j] + tol))
                    ta_lo = (lo[j] - tol - xa) / p  # theta where the segment meets lo
                    ta_hi = (hi[j] + tol - xa) / p
                    enter = np.where(p > 0, ta_lo, ta_hi)
                    leave = np.where(p > 0, ta_hi, ta_lo)
                    t0 = np.where(flat_seg, t0, np.maximum(t0, enter))
                    t1 = np.where(flat_seg, t1, np.minimum(t1, leave))
            ok &= t0 <= t1
            if not ok.any():
                continue
            ga, gb = g[ta], g[tb]
            theta = np.where(gb - ga < 0.0, t1, t0)  # cost is linear in theta
            cost = np.where(ok, ga + theta * (gb - ga), np.inf)
            flat_cost = cost.reshape(R, -1)
            m = np.argmin(flat_cost, axis=1)
            c = flat_cost[np.arange(R), m]
            better = c < best
            if not better.any():
                continue
            seg_idx = np.unravel_index(m, cost.shape[1:])
            ia = flat_idx[ta[1:]][seg_idx]
            ib = flat_idx[tb[1:]][seg_idx]
            th = theta.reshape(R, -1)[np.arange(R), m]
            best = np.where(better, c, best)
            choice[better] = np.stack([np.full(R, a), ia, ib, th], axis=1)[better]
        # level value: minus the margin by which the reachable next states straddle the box
        # (about the distance to the edge of the feasible set), so that it stays linear
        # across that edge instead of being flat zero inside a set without interior
        margin = np.full(R, np.inf)
        for j in range(sp.d):
            xv = np.where(valid, xs[j], np.nan).reshape(R, -1)
            with np.errstate(invalid="ignore"):
                m_j = np.minimum(lo[j] - np.nanmin(xv, axis=1), np.nanmax(xv, axis=1) - hi[j])
            margin = np.minimum(margin, np.maximum(m_j, 0.0) / sp.span[j])
        for r in np.flatnonzero(np.isfinite(best)):
            s = int(rows[r])
            a, ia, ib, th = choice[r]
            out.J[s] = best[r]
            out.status[s] = kn.ST_FEASIBLE
            out.arg[s] = int(ia if th < 0.5 else ib)
            out.V[s] = -float(margin[r]) if np.isfinite(margin[r]) else 0.0
            info[s] = (int(a), int(ia), int(ib), float(th))
        return info

    def _fold_terminal(self, blk: Block, k: int) -> Block:
        """``blk`` with ``terminal_cost(x') (+ penalty(x'))`` added to the stage cost."""
        sp = self.space
        if self.problem.terminal_cost is None and self.method != "penalty":
            return blk
        xn = [blk.next_state(j) for j in range(sp.d)]
        outside = np.zeros(blk.g.shape, dtype=bool)
        for j, x in enumerate(xn):
            outside |= ~((x >= sp.lo[j] - self.btol[j]) & (x <= sp.hi[j] + self.btol[j]))
        ignore = outside if blk.mask is None else outside | blk.mask
        add = np.zeros(blk.g.shape)
        if self.problem.terminal_cost is not None:
            states = tuple(x.reshape(blk.shape) for x in xn)
            add += self.ev.terminal(states, blk.shape, ignore=ignore.reshape(blk.shape)).reshape(blk.g.shape)
        if self.method == "penalty" and self.penalty_weight is not None:
            lo, hi = self.box
            for j, x in enumerate(xn):
                add += self.penalty_weight[j] * np.maximum(np.maximum(lo[j] - x, x - hi[j]), 0.0)
        return blk.with_cost(blk.g + add)

    def point_blocks(self, points: FloatArray, cost: FloatArray | None = None) -> Block:
        """A block whose rows are the given next states (one input each)."""
        P = points.shape[0]
        g = np.zeros((P, 1)) if cost is None else cost.reshape(P, 1)
        xn = [np.ascontiguousarray(points[:, j].reshape(P, 1)) for j in range(self.space.d)]
        base = [np.zeros(P) for _ in range(self.space.d)]
        return Block((P, 1), (), (), parts=(xn, base, g, None))

    # ------------------------------------------------------------------ terminal
    def box_distance(self, box_lo: FloatArray, box_hi: FloatArray) -> FloatArray:
        """Level-set function of the target box at every node (flat).

        With ``d_j`` the signed, span-normalised distance of state ``j`` to its target
        interval, ``max_j d_j`` on both sides of the box (<= 0 inside). Its slope is the
        same on both sides of every face and of the corner diagonals, so propagated
        backward it stays nearly linear across the boundary of the reachable set, where
        the optimal path of a problem with an active final constraint runs; a function
        with a kink there (for instance the sum of the excesses outside) is over-estimated
        by multilinear interpolation in every cell the boundary cuts, which shrinks the
        reachable set by a fraction of a cell per step (the two-tank benchmark of
        Elbert et al. 2013 lost 0.9 % of its cost to this at 51 x 51 nodes).
        """
        sp = self.space
        vmax = np.full(sp.shape, -np.inf)
        for j, grid in enumerate(sp.grids):
            shp = [1] * sp.d
            shp[j] = grid.size
            gj = grid.reshape(shp)
            dj = np.maximum(box_lo[j] - gj, gj - box_hi[j]) / sp.span[j]
            vmax = np.maximum(vmax, dj)
        return vmax.ravel()

    def terminal(self, box_lo: FloatArray, box_hi: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Terminal cost-to-go and level-set function on the nodes (flat, float64)."""
        sp = self.space
        grid_states = tuple(
            g.reshape(tuple(g.size if i == j else 1 for i in range(sp.d))) for j, g in enumerate(sp.grids)
        )
        J = self.ev.terminal(grid_states, sp.shape).ravel()
        V = self.box_distance(box_lo, box_hi)
        if self.method == "penalty" and self.penalty_weight is not None:
            pen = np.zeros(sp.shape)
            for j, grid in enumerate(sp.grids):
                shp = [1] * sp.d
                shp[j] = grid.size
                gj = grid.reshape(shp)
                out = np.maximum(np.maximum(box_lo[j] - gj, gj - box_hi[j]), 0.0)
                pen = pen + self.penalty_weight[j] * out
            J = J + pen.ravel()
        return np.ascontiguousarray(J), np.ascontiguousarray(V)

    def terminal_at(self, x: FloatArray) -> tuple[float, float]:
        """Terminal cost and linear penalty at a continuous final state."""
        sp = self.space
        states = tuple(np.full((1,) * sp.d, x[j]) for j in range(sp.d))
        phi = float(self.ev.terminal(states, (1,) * sp.d).ravel()[0])
        pen = 0.0
        if self.method == "penalty" and self.penalty_weight is not None:
            out = np.maximum(np.maximum(sp.box_lo - x, x - sp.box_hi), 0.0)
            pen = float(np.sum(self.penalty_weight * out))
        return phi, pen

    # ------------------------------------------------------------------ backward
    def backward(
        self,
        box_lo: FloatArray,
        box_hi: FloatArray,
        *,
        store: bool,
        keep_policy: bool,
        bar: Any = None,
        stop_when_empty: bool = True,
    ) -> Backward:
        """Backward recursion towards the target box ``[box_lo, box_hi]``."""
        saved = self.box
        self.box = (box_lo, box_hi)
        try:
            return self._backward(box_lo, box_hi, store, keep_policy, bar, stop_when_empty)
        finally:
            self.box = saved

    def _backward(
        self,
        box_lo: FloatArray,
        box_hi: FloatArray,
        store: bool,
        keep_policy: bool,
        bar: Any,
        stop_when_empty: bool,
    ) -> Backward:
        sp = self.space
        N = self.N
        S = sp.S
        J, V = self.terminal(box_lo, box_hi)
        use_levelset = self.mode == kn.MODE_LEVELSET
        band = band_i = None
        if self.mode == kn.MODE_BAND:
            band = np.full((N + 1, 4), np.nan)
            band_i = np.zeros((N + 1, 2), dtype=np.int64)
            grid = sp.grids[0]
            phi_lo, _ = self.terminal_at(np.array([box_lo[0]]))
            phi_hi, _ = self.terminal_at(np.array([box_hi[0]]))
            band[N] = [box_lo[0], phi_lo, box_hi[0], phi_hi]
            band_i[N] = self._band_index(box_lo[0], box_hi[0])
            outside = (grid < box_lo[0]) | (grid > box_hi[0])
            J = J.copy()
            J[outside] = np.inf
        Jst = np.empty((N + 1, S), dtype=self.cost_dtype) if store else None
        Vst = np.empty((N + 1, S), dtype=self.cost_dtype) if (store and use_levelset) else None
        pol = np.empty((N, S), dtype=np.int32) if keep_policy else None
        stat = np.empty((N, S), dtype=np.int8) if keep_policy else None
        if Jst is not None:
            Jst[N] = J
        if Vst is not None:
            Vst[N] = V
        n_feasible = np.zeros(N + 1, dtype=np.int64)
        n_feasible[N] = int(np.count_nonzero(V <= kn.VTOL))
        empty_step: int | None = None
        k0 = N
        dummy_band = np.zeros(4)
        dummy_band_i = np.zeros(2, dtype=np.int64)
        for k in range(N - 1, -1, -1):
            data_k = self.ev.data_at(k)
            pre = self.ev.pre_at(k, data_k)
            blk = self.ev(sp.states_b, k, data_k, pre)
            bk = band[k + 1] if band is not None else dummy_band
            bik = band_i[k + 1] if band_i is not None else dummy_band_i
            out = self.bellman(blk, k, J, V if use_levelset else None, bk, bik)
            bad = np.flatnonzero(out.status == kn.ST_BAD)
            if bad.size:
                raise self.ev.bad_output_error(k, blk, int(bad[0]))
            empty = False
            if band is not None and band_i is not None:
                empty = not self._update_band(k, out, J, band, band_i, data_k, pre)
            feasible = out.status == kn.ST_FEASIBLE
            n_feasible[k] = int(np.count_nonzero(feasible))
            if band is None and n_feasible[k] == 0:
                empty = True
            J = out.J
            if use_levelset:
                J = self.extend_cost(J, out.status)
            V = out.V
            k0 = k
            if Jst is not None:
                Jst[k] = J
            if Vst is not None:
                Vst[k] = V
            if pol is not None and stat is not None:
                pol[k] = out.arg
                stat[k] = out.status
            if bar is not None:
                bar.update(1)
            if empty and empty_step is None:
                empty_step = k
                if stop_when_empty:
                    break
        return Backward(
            J=Jst,
            V=Vst,
            policy=pol,
            status=stat,
            band=band,
            band_i=band_i,
            n_feasible=n_feasible,
            empty_step=empty_step,
            J0=J,
            V0=V,
            k0=k0,
        )

    def extend_cost(self, J: FloatArray, status: npt.NDArray[np.int8]) -> FloatArray:
        """Level-set method: continue the cost-to-go smoothly across the feasibility boundary.

        A node just outside the backward reachable set has no true cost-to-go; the kernel
        gives it the cost of the input that comes closest to the set, which is about the
        cost on the boundary itself. Inside, the cost-to-go falls away from the boundary,
        so the stored function has a concave kink there, and multilinear interpolation in
        every cell the boundary cuts under-estimates the cost of the states next to the
        boundary, exactly where the optimal path of an active final constraint runs (the
        recursion then compounds it step by step). Each infeasible node with a feasible
        neighbour therefore gets the largest, over the grid directions ``e`` (axes and
        diagonals) in which both nodes are feasible, of ``J(n+e) + |J(n+e) - J(n+2e)|``:
        the linear extrapolation where the cost rises towards the boundary (the usual
        case: less slack costs more), its mirror image where it falls, so that an
        infeasible node never looks cheaper than the feasible neighbour it continues (with
        the plain extrapolation, or a flat continuation, the two-tank benchmark ends 1 % above
        the optimum at 101 x 101 nodes). The largest, not the mean (issue 26): where the
        boundary runs obliquely to the grid (the two-tank's, along ``x1 + x2 = const``),
        the directions along the boundary see a flat cost and the mean pulls the node below
        the rise across it; the under-estimate then grows away from the diagonal, and a
        finer input grid finds the inputs that exploit it (101 x 101 nodes, 21 values per
        input: +1.27 % with the mean against +0.027 % with 11 values; with the largest,
        +0.012 % with both). It is not floored at the closest-approach cost:
        such a floor puts a convex kink into the extended function, interpolation
        over-estimates it, and the error compounds upward step by step (two-tank at
        201 x 201 nodes, one cell per step: +0.66 % with the floor). Only these nodes can be corners
        of an admissible interpolation (an admissible point has an interpolated level
        value <= 0, so a feasible corner); nodes farther out keep their closest-approach
        cost.
        """
        sp = self.space
        feas = (status == kn.ST_FEASIBLE) & np.isfinite(J)
        cand = ~feas & np.isfinite(J)
        if not feas.any() or not cand.any():
            return J
        shape = sp.shape
        near = feas.reshape(shape).copy()
        for ax in range(sp.d):  # Chebyshev dilation by one node
            grown = near.copy()
            lo = [slice(None)] * sp.d
            hi = [slice(None)] * sp.d
            lo[ax] = slice(0, -1)
            hi[ax] = slice(1, None)
            grown[tuple(lo)] |= near[tuple(hi)]
            grown[tuple(hi)] |= near[tuple(lo)]
            near = grown
        nodes = np.flatnonzero(cand & near.ravel())
        if nodes.size == 0:
            return J
        sub = np.array(np.unravel_index(nodes, shape))  # (d, L)
        dims = np.array(shape).reshape(-1, 1)
        stride = sp.gstride.reshape(-1, 1)
        acc = np.full(nodes.size, -np.inf)
        for step in itertools.product((-1, 0, 1), repeat=sp.d):
            if not any(step):
                continue
            e = np.array(step).reshape(-1, 1)
            s2 = sub + 2 * e
            inside = np.all((s2 >= 0) & (s2 < dims), axis=0)
            if not inside.any():
                continue
            i1 = np.where(inside, nodes + int((e * stride).sum()), 0)
            i2 = np.where(inside, nodes + int((2 * e * stride).sum()), 0)
            ok = inside & feas[i1] & feas[i2]
            acc = np.where(ok, np.maximum(acc, J[i1] + np.abs(J[i1] - J[i2])), acc)
        has = np.isfinite(acc)
        out = J.copy()
        out[nodes[has]] = acc[has]
        return out

    # ------------------------------------------------------------ boundary line
    def _band_index(self, lo: float, hi: float) -> IntArray:
        grid = self.space.grids[0]
        ilo = int(np.searchsorted(grid, lo, side="left"))
        ihi = int(np.searchsorted(grid, hi, side="right")) - 1
        return np.array([ilo, ihi], dtype=np.int64)

    def _update_band(
        self,
        k: int,
        out: StepOut,
        Jnext: FloatArray,
        band: FloatArray,
        band_i: IntArray,
        data_k: Any,
        pre: Any,
    ) -> bool:
        """Boundary lines at step ``k`` from those at ``k + 1``; False when the band is empty."""
        sp = self.space
        grid = sp.grids[0]
        n = grid.size
        btol = float(self.btol[0])
        lo_t = band[k + 1, 0]
        hi_t = band[k + 1, 2]
        cand_lo = np.flatnonzero(out.fmax >= lo_t - btol)
        cand_hi = np.flatnonzero(out.fmin <= hi_t + btol)
        if cand_lo.size == 0 or cand_hi.size == 0:
            out.J[:] = np.inf
            out.status[out.status == kn.ST_FEASIBLE] = kn.ST_UNREACHABLE
            return False
        i = int(cand_lo[0])
        if i == 0:
            lo, lo_j = float(grid[0]), float(out.J[0])
        else:
            lo = self._crossing(k, data_k, pre, grid[i - 1], grid[i], lo_t, upper=False)
            lo_j = self._boundary_cost(k, data_k, pre, lo, Jnext, band, band_i, upper=False)
        i = int(cand_hi[-1])
        if i == n - 1:
            hi, hi_j = float(grid[-1]), float(out.J[-1])
        else:
            hi = self._crossing(k, data_k, pre, grid[i], grid[i + 1], hi_t, upper=True)
            hi_j = self._boundary_cost(k, data_k, pre, hi, Jnext, band, band_i, upper=True)
        if lo > hi + btol:
            out.J[:] = np.inf
            out.status[out.status == kn.ST_FEASIBLE] = kn.ST_UNREACHABLE
            return False
        hi = max(hi, lo)
        band[k] = [lo, lo_j, hi, hi_j]
        band_i[k] = self._band_index(lo, hi)
        outside = (grid < lo) | (grid > hi)
        out.J[outside] = np.inf
        out.status[outside & (out.status == kn.ST_FEASIBLE)] = kn.ST_UNREACHABLE
        return True

    def _eval_states_1d(self, xs: FloatArray, k: int, data_k: Any, pre: Any) -> Block:
        q = self.space.q
        states = (xs.reshape((xs.size,) + (1,) * q),)
        return self.ev(states, k, data_k, pre)

    def _crossing(
        self, k: int, data_k: Any, pre: Any, a: float, b: float, target: float, *, upper: bool
    ) -> float:
        """State in [a, b] where the largest (smallest) next state crosses ``target``."""
        xs = np.linspace(a, b, REFINE_POINTS)
        blk = self._eval_states_1d(xs, k, data_k, pre)
        xn = blk.next_state(0)
        valid = np.isfinite(xn) & np.isfinite(blk.g)
        if blk.mask is not None:
            valid &= ~blk.mask
        if not upper:
            f = np.where(valid, xn, -np.inf).max(axis=1)
            idx = np.flatnonzero(f >= target)
            if idx.size == 0:
                return float(b)
            j = int(idx[0])
            if j == 0:
                return float(a)
            f0, f1 = f[j - 1], f[j]
            if not np.isfinite(f0) or f1 <= f0:
                return float(xs[j])
            return float(xs[j - 1] + (target - f0) / (f1 - f0) * (xs[j] - xs[j - 1]))
        f = np.where(valid, xn, np.inf).min(axis=1)
        idx = np.flatnonzero(f <= target)
        if idx.size == 0:
            return float(a)
        j = int(idx[-1])
        if j == xs.size - 1:
            return float(b)
        f0, f1 = f[j], f[j + 1]
        if not np.isfinite(f1) or f1 <= f0:
            return float(xs[j])
        return float(xs[j] + (target - f0) / (f1 - f0) * (xs[j + 1] - xs[j]))

    def _boundary_cost(
        self,
        k: int,
        data_k: Any,
        pre: Any,
        x: float,
        Jnext: FloatArray,
        band: FloatArray,
        band_i: IntArray,
        *,
        upper: bool,
    ) -> float:
        """Cost-to-go of the boundary point ``x``: extreme input, then the next boundary."""
        blk = self._eval_states_1d(np.array([x]), k, data_k, pre)
        xn = blk.next_state(0)[0]
        g = blk.g[0]
        valid = np.isfinite(xn) & np.isfinite(g)
        if blk.mask is not None:
            valid &= ~blk.mask[0]
        if not valid.any():
            return float("inf")
        m = int(np.argmin(np.where(valid, xn, np.inf)) if upper else np.argmax(np.where(valid, xn, -np.inf)))
        xnext = min(max(float(xn[m]), band[k + 1, 0]), band[k + 1, 2])
        pt = self.point_blocks(np.array([[xnext]]), np.array([g[m]]))
        out = self.step(pt, Jnext, None, band[k + 1], band_i[k + 1], False)
        return float(out.J[0])

    # ----------------------------------------------------------- point queries
    def point_feasible(self, x: FloatArray, bw: Backward) -> bool:
        """Whether the state ``x`` at step ``bw.k0`` lies in the admissible set."""
        if bw.k0 != 0 or bw.empty_step is not None:
            return False
        pt = self.point_blocks(x.reshape(1, -1))
        band, band_i = self._band_at(bw, 0)
        use_v = bw.V0 if self.mode == kn.MODE_LEVELSET else None
        out = self.step(pt, bw.J0, use_v, band, band_i, False)
        return bool(out.status[0] == kn.ST_FEASIBLE)

    def _band_at(self, bw: Backward, k: int) -> tuple[FloatArray, IntArray]:
        if bw.band is not None and bw.band_i is not None:
            return bw.band[k], bw.band_i[k]
        return np.zeros(4), np.zeros(2, dtype=np.int64)

    def interp_cost(self, bw: Backward, k: int, points: FloatArray) -> FloatArray:
        """Interpolated stored cost-to-go at step ``k`` (inf where infeasible for wall / band)."""
        assert bw.J is not None
        pts = points.copy()
        for j in range(self.space.d):
            pts[:, j] = np.clip(pts[:, j], self.space.lo[j], self.space.hi[j])
        band, band_i = self._band_at(bw, k)
        mode = kn.MODE_BAND if self.mode == kn.MODE_BAND else kn.MODE_PLAIN
        out = self.step(self.point_blocks(pts), bw.J[k], None, band, band_i, False, mode=mode)
        return out.J

    # ------------------------------------------------------------------ forward
    def forward(
        self, x0: FloatArray, bw: Backward, policy_mode: bool, bar: Any = None
    ) -> tuple[FloatArray, FloatArray, FloatArray, int]:
        """Optimal trajectory from ``x0``: states (N+1, d), inputs (N, q), stage costs (N,)."""
        sp = self.space
        N = self.N
        assert bw.J is not None
        xs = np.empty((N + 1, sp.d))
        us = np.empty((N, sp.q))
        gs = np.empty(N)
        xs[0] = x0
        n_fallback = 0
        use_levelset = self.mode == kn.MODE_LEVELSET
        for k in range(N):
            x = xs[k]
            data_k = self.ev.data_at(k)
            band, band_i = self._band_at(bw, k + 1)
            Vn = bw.V[k + 1] if (use_levelset and bw.V is not None) else None
            done = False
            if policy_mode:
                u = self._policy_input(bw, k, x)
                if u is not None:
                    ins = tuple(np.full((1,) * (sp.d + sp.q), u[j]) for j in range(sp.q))
                    pre = self.ev.pre_at(k, data_k, ins)
                    blk = self.ev(self._state_arrays(x), k, data_k, pre, inputs=ins)
                    out = self.bellman(blk, k, bw.J[k + 1], Vn, band, band_i)
                    if out.status[0] == kn.ST_BAD:
                        raise self.ev.bad_output_error(k, blk, 0)
                    if out.status[0] == kn.ST_FEASIBLE:
                        us[k] = u
                        gs[k] = blk.g[0, 0]
                        xs[k + 1] = [blk.next_state(j)[0, 0] for j in range(sp.d)]
                        done = True
                if not done:
                    n_fallback += 1
            if not done:
                pre = self.ev.pre_at(k, data_k)
                blk = self.ev(self._state_arrays(x), k, data_k, pre)
                out = self.bellman(blk, k, bw.J[k + 1], Vn, band, band_i)
                status = int(out.status[0])
                if status == kn.ST_BAD:
                    raise self.ev.bad_output_error(k, blk, 0)
                near_set = False
                if status != kn.ST_FEASIBLE and Vn is not None and k < N - 1:
                    relaxed = self._near_set_step(blk, k, x, out, bw, band, band_i)
                    if relaxed is not None:  # counted as a fallback step all the same
                        out, status = relaxed, kn.ST_FEASIBLE
                        n_fallback += 0 if policy_mode else 1
                        near_set = True
                m = int(out.arg[0])
                if (
                    FWD_REFINE
                    and Vn is not None
                    and sp.d >= 2
                    and k < N - 1
                    and status == kn.ST_FEASIBLE
                    and not near_set
                    and m >= 0
                ):
                    fine = self._refine_input(k, x, data_k, m, bw)
                    if fine is not None:
                        us[k], gs[k], xs[k + 1] = fine
                        if bar is not None:
                            bar.update(1)
                        continue
                frac = self.last_fractional.get(0) if k == N - 1 else None
                landed = None if frac is None else self._land(k, x, data_k, frac, bw)
                if landed is not None:
                    us[k], gs[k], xs[k + 1] = landed
                    if bar is not None:
                        bar.update(1)
                    continue
                if status != kn.ST_FEASIBLE:
                    if self.mode == kn.MODE_PLAIN or m < 0:
                        raise DPInfeasibleError(
                            f"forward pass: at step {k} no input keeps the state "
                            f"{self._fmt_state(x)} on a feasible path "
                            f"({self._status_text(status)}), although the interpolated "
                            "cost-to-go at this state was finite; the grid is too coarse "
                            "near the constraint boundary: refine the state grid or use "
                            "final_constraint='levelset' or 'boundary_line'."
                        )
                    if not policy_mode:
                        n_fallback += 1
                idx = np.unravel_index(m, sp.input_shape)
                us[k] = [sp.inputs[j][idx[j]] for j in range(sp.q)]
                gs[k] = blk.g[0, m]
                xs[k + 1] = [blk.next_state(j)[0, m] for j in range(sp.d)]
            if bar is not None:
                bar.update(1)
        return xs, us, gs, n_fallback

    def _refine_input(
        self, k: int, x: FloatArray, data_k: Any, m: int, bw: Backward
    ) -> tuple[FloatArray, float, FloatArray] | None:
        """Level set, forward pass: the grid arg-min input ``m`` refined between its grid
        neighbours, one continuous input at a time, with the same interpolated cost-to-go
        and the same admission test (next level value <= ``VTOL``, mask, state bounds).

        Only where the admission boundary cuts a grid cell on the cheaper side of the
        grid arg-min (the grid neighbour there costs less but is not admitted: a path on
        the boundary of the reachable set, where cost falls towards the boundary), that
        cell is tried at ``FWD_REFINE_SUB`` sub-steps and the cheapest admitted one is
        taken. Inputs inside the set are left alone: there the refined choice would be
        driven by interpolation error of the cost-to-go (tried: the flow split then
        wandered off its optimum for a few 1e-6 each), and a value bisected onto the
        boundary leaves no margin for the next steps (tried: the path then slipped out of
        the interpolated set at every later step). Returns ``(input, stage cost, next
        state)`` when a refined input is admitted and strictly cheaper, else None.

        Why (issue 26): the level set at a node is the minimum over the *grid* inputs, so
        where reaching the set needs an input between two grid values (the two tanks' flow
        split ``u2 = 0.25`` at the nodes one cell off the diagonal of a 201^2 grid, with
        ``u2`` on a 0.1 grid) it is over-estimated, and interpolation carries that into the
        cells the optimal path crosses: the two tanks at 201^2 x 11^2 admitted the start
        of the filling at ``u1 = 0.4`` but not ``0.3`` (exact: 0.28), +0.085 % against
        +0.012 % at 101^2. The refinement recovers most of that step in the forward pass
        without changing the recursion.
        """
        sp = self.space
        assert bw.J is not None and bw.V is not None
        Jn = bw.J[k + 1]
        Vn = bw.V[k + 1]
        idx = np.unravel_index(m, sp.input_shape)
        u0 = np.array([float(sp.inputs[j][idx[j]]) for j in range(sp.q)])
        zb = np.zeros(4)
        zbi = np.zeros(2, dtype=np.int64)

        def evaluate(us: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
            """Cost (inf where not admitted), cost regardless of the level set, stage cost
            and next states of the inputs ``us`` (P, q)."""
            P = us.shape[0]
            ins = tuple(us[:, j].reshape((1,) * sp.d + (P,) + (1,) * (sp.q - 1)) for j in range(sp.q))
            blk = self.ev(self._state_arrays(x), k, data_k, self.ev.pre_at(k, data_k, ins), inputs=ins)
            g = np.array(blk.g[0], dtype=np.float64)
            xn = np.stack([np.asarray(blk.next_state(j)[0], dtype=np.float64) for j in range(sp.d)], 1)
            ok = np.isfinite(g) & np.all(np.isfinite(xn), axis=1)
            if blk.mask is not None:
                ok &= ~blk.mask[0]
            pts = np.where(ok[:, None], xn, sp.lo)
            pb = self.point_blocks(pts)
            jo = self.step(pb, Jn, None, zb, zbi, False, mode=kn.MODE_PLAIN)
            vo = self.step(pb, Vn, None, zb, zbi, False, mode=kn.MODE_PLAIN)
            ok &= (jo.status == kn.ST_FEASIBLE) & (vo.status == kn.ST_FEASIBLE)
            raw = np.where(ok, g + jo.J, np.inf)
            return np.where(vo.J <= kn.VTOL, raw, np.inf), raw, g, xn

        best_c = np.inf
        best: tuple[FloatArray, float, FloatArray] | None = None
        for a in range(sp.q):
            grid = sp.inputs[a]
            if sp.discrete[a] or grid.size < 2:
                continue
            i = int(idx[a])
            for nb in (i - 1, i + 1):
                if not 0 <= nb < grid.size:
                    continue
                vals = np.linspace(float(grid[i]), float(grid[nb]), FWD_REFINE_SUB + 1)
                cand = np.repeat(u0.reshape(1, -1), vals.size, axis=0)
                cand[:, a] = vals
                c, raw, g, xn = evaluate(cand)
                if not np.isfinite(c[0]) or np.isfinite(c[-1]) or not raw[-1] < c[0]:
                    continue
                j = int(np.argmin(c[1:-1])) + 1
                if c[j] < min(c[0], best_c):
                    best_c = float(c[j])
                    best = (cand[j].copy(), float(g[j]), xn[j].copy())
        return best

    def _near_set_step(
        self,
        blk: Block,
        k: int,
        x: FloatArray,
        out: StepOut,
        bw: Backward,
        band: FloatArray,
        band_i: IntArray,
    ) -> StepOut | None:
        """Level set, forward pass: the state ``x`` has slipped out of the interpolated
        reachable set by round-off of the interpolation (the level value is invariant along
        an optimal path only at the nodes). Instead of the single input that comes closest
        to the set, admit every input whose next level value is within ``FWD_VTIE`` of the
        smallest one reachable, or of the current state's own level value when that is
        larger (so the excess cannot grow step by step), and take the cheapest of them.

        Why (issue 26): on a boundary that the optimal path follows (the two tanks fill at
        full flow for their last 138 steps), the level values of the inputs that differ only
        in a direction along the boundary (the split between the tanks) differ by
        interpolation noise (1e-8 of the span); the closest approach picked the noise's
        favourite, an extreme split, at every step, and paid the split's cost: +2.1 % at
        51^2 nodes with 41 values per input against +0.27 % with 21 values. The inputs
        that move the state across the boundary differ by far more (7.7e-5 for one step of
        the 41-value flow grid there) and are still excluded.
        """
        assert bw.V is not None and bw.J is not None
        v_min = float(out.V[0])
        if not np.isfinite(v_min) or v_min >= kn.V_CAP:
            return None
        cur = self.step(self.point_blocks(x.reshape(1, -1)), bw.V[k], None, np.zeros(4),
                        np.zeros(2, dtype=np.int64), False, mode=kn.MODE_PLAIN)  # fmt: skip
        v_cur = float(cur.J[0])
        thr = max(v_min, v_cur if np.isfinite(v_cur) else v_min) + kn.FWD_VTIE
        shifted = np.asarray(bw.V[k + 1], dtype=np.float64) - thr
        relaxed = self.step(blk, bw.J[k + 1], shifted, band, band_i, False)
        if int(relaxed.status[0]) != kn.ST_FEASIBLE:
            return None
        return relaxed

    def _land(
        self, k: int, x: FloatArray, data_k: Any, frac: tuple, bw: Backward
    ) -> tuple[FloatArray, float, FloatArray] | None:
        """Last forward step with a fractional input (see :meth:`_fractional_last_step`).

        Moves along the segment between the two grid inputs ``frac`` names until the next
        state lies in the target box (regula falsi, Illinois variant, on the most violated
        state; the model need not be linear in the input). Returns ``(input, stage cost,
        next state)`` or None when no point of the segment is found in the box.
        """
        sp = self.space
        _axis, ia, ib, theta = frac
        ua = np.array([sp.inputs[j][i] for j, i in enumerate(np.unravel_index(ia, sp.input_shape))])
        ub = np.array([sp.inputs[j][i] for j, i in enumerate(np.unravel_index(ib, sp.input_shape))])
        if bw.band is not None:
            lo, hi = bw.band[self.N, [0]], bw.band[self.N, [2]]
        else:
            lo, hi = sp.box_lo, sp.box_hi
        tol = kn.VTOL * sp.span

        def at(t: float) -> tuple[FloatArray, float, FloatArray, bool]:
            u = ua + t * (ub - ua)
            ins = tuple(np.full((1,) * (sp.d + sp.q), u[j]) for j in range(sp.q))
            blk = self.ev(self._state_arrays(x), k, data_k, self.ev.pre_at(k, data_k, ins), inputs=ins)
            xn = np.array([blk.next_state(j)[0, 0] for j in range(sp.d)])
            g = float(blk.g[0, 0])
            ok = bool(np.all(np.isfinite(xn)) and np.isfinite(g))
            if blk.mask is not None:
                ok = ok and not bool(blk.mask[0, 0])
            return u, g, xn, ok

        t_lo, t_hi = 0.0, 1.0
        x_lo = at(0.0)[2]
        t = min(max(theta, 0.0), 1.0)
        f_lo = f_hi = None
        for _ in range(60):
            u, g, xn, ok = at(t)
            viol = np.maximum(lo - tol - xn, xn - hi - tol) / sp.span
            if ok and np.all(viol <= 0.0):
                return u, g, xn
            j = int(np.argmax(viol))
            c = lo[j] if xn[j] < lo[j] else hi[j]
            f_t = xn[j] - c
            if (x_lo[j] - c) * f_t > 0.0:
                t_lo, x_lo, f_lo = t, xn, f_t
                if f_hi is not None:
                    f_hi *= 0.5
            else:
                t_hi, f_hi = t, f_t
                if f_lo is not None:
                    f_lo *= 0.5
            if f_lo is not None and f_hi is not None and f_hi != f_lo:
                t = t_lo + (t_hi - t_lo) * f_lo / (f_lo - f_hi)
            else:
                t = 0.5 * (t_lo + t_hi)
            if t_hi - t_lo < 1e-15:
                break
        return None

    def target_miss(self, x: FloatArray, box: tuple[FloatArray, FloatArray] | None = None) -> FloatArray:
        """Signed excess of the state ``x`` outside the target box, per state (0 inside, within
        the tolerance ``VTOL`` of the grid span) [state units]."""
        sp = self.space
        lo, hi = box if box is not None else (sp.box_lo, sp.box_hi)
        out = np.maximum(lo - x, 0.0) - np.maximum(x - hi, 0.0)
        out[np.abs(out) <= kn.VTOL * sp.span] = 0.0
        return -out

    def _sim_step(self, k: int, x: FloatArray, u: FloatArray) -> tuple[FloatArray, float, bool]:
        """Next state, stage cost and admissibility of the input ``u`` at the state ``x``."""
        sp = self.space
        data_k = self.ev.data_at(k)
        ins = tuple(np.full((1,) * (sp.d + sp.q), u[j]) for j in range(sp.q))
        blk = self.ev(self._state_arrays(x), k, data_k, self.ev.pre_at(k, data_k, ins), inputs=ins)
        xn = np.array([blk.next_state(j)[0, 0] for j in range(sp.d)], dtype=np.float64)
        g = float(blk.g[0, 0])
        ok = bool(np.all(np.isfinite(xn)) and np.isfinite(g))
        if blk.mask is not None:
            ok = ok and not bool(blk.mask[0, 0])
        ok = ok and bool(np.all((xn >= sp.lo - self.btol) & (xn <= sp.hi + self.btol)))
        return xn, g, ok

    def land(
        self, xs: FloatArray, us: FloatArray, gs: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, int] | None:
        """Move a trajectory that ends outside the target box onto it (exact targets).

        On a grid, the set of nodes from which a target narrower than a grid cell in two
        or more states is reached can be empty or so thin that the path the grid allows
        ends off the target. The continuous inputs of the last ``r`` steps are then
        corrected by Gauss-Newton with the model itself (Jacobian by finite differences,
        minimum-norm step in input units scaled by each input's grid span, inputs kept
        within their grids; discrete inputs unchanged) until the final state lies in the
        box to ``VTOL`` of the span. ``r`` starts at the number of steps the continuous
        inputs need to move every state (``ceil(d / q_continuous)``) and doubles up to
        ``8 d`` (or the horizon); every window that lands is evaluated, and the cheapest
        corrected trajectory (stage costs of the model along it) is returned with the
        window used, or None when none lands with admissible steps.
        """
        sp = self.space
        N = self.N
        cont = [a for a in range(sp.q) if not sp.discrete[a] and sp.inputs[a].size > 1]
        if not cont:
            return None
        ulo = np.array([float(sp.inputs[a].min()) for a in cont])
        uhi = np.array([float(sp.inputs[a].max()) for a in cont])
        uspan = np.maximum(uhi - ulo, 1e-300)
        r0 = max(1, -(-sp.d // len(cont)))
        cap = min(N, LAND_STEPS_PER_STATE * sp.d)
        windows = []
        r = min(r0, cap)
        while r < cap:
            windows.append(r)
            r *= 2
        windows.append(cap)
        best: tuple[FloatArray, FloatArray, FloatArray, int] | None = None
        best_total = np.inf

        def rollout(k0: int, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, bool]:
            xk = xs[k0].copy()
            u_all = us[k0:].copy()
            x_all = np.empty((N - k0 + 1, sp.d))
            g_all = np.empty(N - k0)
            x_all[0] = xk
            ok = True
            zz = z.reshape(N - k0, len(cont))
            for i in range(N - k0):
                u_all[i, cont] = ulo + zz[i] * uspan
                xk, g, ok_i = self._sim_step(k0 + i, xk, u_all[i])
                ok = ok and ok_i
                x_all[i + 1] = xk
                g_all[i] = g
            return x_all, u_all, g_all, ok

        for r in windows:
            k0 = N - r
            z = ((us[k0:, cont] - ulo) / uspan).ravel()
            x_all, u_all, g_all, ok = rollout(k0, z)
            for _ in range(40):
                res = self.target_miss(x_all[-1])
                if not np.any(res) and ok:
                    break
                if not np.all(np.isfinite(x_all[-1])):
                    break
                h = 1e-7
                jac = np.empty((sp.d, z.size))
                for i in range(z.size):
                    zp = z.copy()
                    step = h if zp[i] + h <= 1.0 else -h
                    zp[i] += step
                    jac[:, i] = (rollout(k0, zp)[0][-1] - x_all[-1]) / step
                scale = sp.span
                dz = np.linalg.lstsq(jac / scale[:, None], -res / scale, rcond=None)[0]
                z = np.clip(z + dz, 0.0, 1.0)
                x_all, u_all, g_all, ok = rollout(k0, z)
            if np.any(self.target_miss(x_all[-1])) or not ok:
                continue
            if POLISH:
                z, x_all, u_all, g_all = self._polish(k0, z, x_all, u_all, g_all, rollout)
            nx_, nu_, ng_ = xs.copy(), us.copy(), gs.copy()
            nx_[k0:] = x_all
            nu_[k0:] = u_all
            ng_[k0:] = g_all
            total = float(np.sum(ng_)) + sum(self.terminal_at(nx_[-1]))
            if best is None or total < best_total:
                best, best_total = (nx_, nu_, ng_, r), total
        return best

    def _polish(self, k0: int, z: FloatArray, x_all: FloatArray, u_all: FloatArray, g_all: FloatArray,
                rollout: Any) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:  # fmt: skip
        """The landed window's continuous inputs re-optimised for cost (SLSQP from the landed
        ones, final state kept in the target box, inputs within their grids); kept only when
        the result is admissible at every step, lands, and costs less."""
        from scipy.optimize import minimize

        sp = self.space
        lo, hi = sp.box_lo, sp.box_hi
        scale = np.maximum(sp.span, 1e-300)
        tol = kn.VTOL * sp.span

        def total(zz: FloatArray) -> float:
            xa, _, ga, ok = rollout(k0, zz)
            return float(np.sum(ga) + self.terminal_at(xa[-1])[0]) if ok else 1e300

        def cons(zz: FloatArray) -> FloatArray:
            xe = rollout(k0, zz)[0][-1]
            return np.r_[(xe - lo + 0.5 * tol) / scale, (hi + 0.5 * tol - xe) / scale]

        c0 = total(z)
        try:
            opt = minimize(total, z, method="SLSQP", bounds=[(0.0, 1.0)] * z.size,
                           constraints={"type": "ineq", "fun": cons},
                           options={"maxiter": 100, "ftol": 1e-12 * max(abs(c0), 1e-300)})  # fmt: skip
        except (ValueError, ArithmeticError):
            return z, x_all, u_all, g_all
        zn = np.clip(np.asarray(opt.x, dtype=np.float64), 0.0, 1.0)
        xa, ua, ga, ok = rollout(k0, zn)
        if not ok or np.any(self.target_miss(xa[-1])) or not total(zn) < c0:
            return z, x_all, u_all, g_all
        return zn, xa, ua, ga

    def _state_arrays(self, x: FloatArray) -> tuple[np.ndarray, ...]:
        sp = self.space
        return tuple(np.full((1,) * (sp.d + sp.q), x[j]) for j in range(sp.d))

    def _corners(self, x: FloatArray) -> list[tuple[int, float]]:
        """Flat node indices and multilinear weights of the cell holding ``x``."""
        sp = self.space
        idx = []
        wts = []
        for j, grid in enumerate(sp.grids):
            xj = min(max(float(x[j]), grid[0]), grid[-1])
            i = int(min(max(np.searchsorted(grid, xj, side="right") - 1, 0), grid.size - 2))
            w = (xj - grid[i]) / (grid[i + 1] - grid[i])
            idx.append(i)
            wts.append(w)
        out = []
        for c in range(1 << sp.d):
            wt = 1.0
            flat = 0
            for j in range(sp.d):
                bit = (c >> j) & 1
                wt *= wts[j] if bit else 1.0 - wts[j]
                flat += (idx[j] + bit) * int(sp.gstride[j])
            if wt > kn.WSNAP:
                out.append((flat, wt))
        return out

    def _policy_input(self, bw: Backward, k: int, x: FloatArray) -> FloatArray | None:
        """Interpolated stored policy at ``x``: weighted mean (continuous) or nearest (discrete)."""
        sp = self.space
        assert bw.policy is not None and bw.status is not None
        corners = [(f, w) for f, w in self._corners(x) if bw.status[k, f] == kn.ST_FEASIBLE]
        if not corners:
            return None
        wsum = sum(w for _, w in corners)
        u = np.zeros(sp.q)
        best = max(corners, key=lambda c: c[1])
        for flat, w in corners:
            idx = np.unravel_index(int(bw.policy[k, flat]), sp.input_shape)
            for j in range(sp.q):
                if not sp.discrete[j]:
                    u[j] += w / wsum * sp.inputs[j][idx[j]]
        idx_best = np.unravel_index(int(bw.policy[k, best[0]]), sp.input_shape)
        for j in range(sp.q):
            if sp.discrete[j]:
                u[j] = sp.inputs[j][idx_best[j]]
        return u

    # ------------------------------------------------------------------ costate
    def costate(self, bw: Backward, xs: FloatArray) -> FloatArray:
        """d(cost-to-go)/d(state) along the trajectory by central finite differences."""
        sp = self.space
        d = sp.d
        N = self.N
        lam = np.full((N + 1, d), np.nan)
        for k in range(N + 1):
            x = xs[k]
            pts = np.repeat(x.reshape(1, d), 2 * d + 1, axis=0)
            for j, grid in enumerate(sp.grids):
                xj = min(max(float(x[j]), grid[0]), grid[-1])
                i = int(min(max(np.searchsorted(grid, xj, side="right") - 1, 0), grid.size - 2))
                h = float(grid[i + 1] - grid[i])
                pts[1 + 2 * j, j] = min(xj + h, grid[-1])
                pts[2 + 2 * j, j] = max(xj - h, grid[0])
                pts[0, j] = xj
            vals = self.interp_cost(bw, k, pts)
            for j in range(d):
                xc, xp, xm = pts[0, j], pts[1 + 2 * j, j], pts[2 + 2 * j, j]
                jc, jp, jm = vals[0], vals[1 + 2 * j], vals[2 + 2 * j]
                if np.isfinite(jp) and np.isfinite(jm) and xp > xm:
                    lam[k, j] = (jp - jm) / (xp - xm)
                elif np.isfinite(jp) and np.isfinite(jc) and xp > xc:
                    lam[k, j] = (jp - jc) / (xp - xc)
                elif np.isfinite(jm) and np.isfinite(jc) and xc > xm:
                    lam[k, j] = (jc - jm) / (xc - xm)
        return lam

    # ---------------------------------------------------------------- messages
    def _fmt_state(self, x: FloatArray) -> str:
        sp = self.space
        return "(" + ", ".join(f"{sp.state_names[j]}={float(x[j]):.6g}" for j in range(sp.d)) + ")"

    def _fmt_box(self, lo: FloatArray, hi: FloatArray) -> str:
        sp = self.space
        return ", ".join(
            f"{sp.state_names[j]} in [{float(lo[j]):.6g}, {float(hi[j]):.6g}]" for j in range(sp.d)
        )

    @staticmethod
    def _status_text(status: int) -> str:
        return {
            kn.ST_MASKED: "every input is rejected by the model's infeasibility mask",
            kn.ST_BOUNDS: "every admissible input leaves the state bounds",
            kn.ST_UNREACHABLE: "no admissible input leads to a state from which the final "
            "target can be reached",
        }.get(status, "infeasible")

    # --------------------------------------------------------------- diagnosis
    def diagnose(self, x0: FloatArray, bw: Backward) -> DPInfeasibleError:
        """Explain why ``x0`` cannot reach the target: which constraint, from which step.

        1. If a target narrower than the grid is set, the recursion is rerun without it; if
           ``x0`` is then feasible, the target is the violated constraint, and the step at
           which its backward reachable set becomes empty (or its extent at step 0) is
           reported.
        2. Otherwise the states reachable from ``x0`` are propagated forward (continuous
           states, the extreme ones of every grid cell kept) until every one of them has
           all its inputs masked or leaving the state bounds: that step and constraint are
           reported.
        """
        sp = self.space
        N = self.N
        x0s = self._fmt_state(x0)
        if sp.has_target:
            relaxed = self.backward(sp.lo, sp.hi, store=False, keep_policy=False)
            if self.point_feasible(x0, relaxed):
                tgt = self._fmt_box(sp.box_lo, sp.box_hi)
                gap, closest = self._target_gap(x0)
                if gap == 0.0:
                    return self._grid_error(x0, bw, tgt, closest)
                if bw.empty_step is not None:
                    where = (
                        "the set of states from which the target can still be reached "
                        f"(computed backward from step {N}) becomes empty at step "
                        f"{bw.empty_step}"
                    )
                else:
                    where = (
                        "at step 0 the target can only be reached from "
                        f"{self._feasible_span(bw)}, which excludes the initial state"
                    )
                near = ""
                if closest is not None:
                    near = (
                        f"; the final states the model reaches from it come no closer than "
                        f"{self._fmt_state(closest)}"
                    )
                return DPInfeasibleError(
                    f"the initial state {x0s} cannot reach the final-state target ({tgt}) in "
                    f"{N} steps: the violated constraint is the final-state target; {where} "
                    f"(without the target the problem is feasible{near}). Widen the target, "
                    "lengthen the horizon, move the initial state or give the inputs more "
                    "authority."
                )
        info = self._forward_reach(x0)
        if info is not None:
            k, n_rows, n_masked, n_bounds = info
            bounds = f"state bounds ({self._fmt_box(sp.lo, sp.hi)})"
            cause = "input/model infeasibility mask" if n_masked >= n_bounds else bounds
            who = (
                "the initial state has"
                if k == 0
                else (f"each of the {n_rows} states still reachable from the initial state has")
            )
            if n_masked == n_rows:
                detail = "every input rejected by the model's infeasibility mask"
            elif n_bounds == n_rows:
                detail = "every admissible input driving the state outside the grid"
            else:
                detail = (
                    f"either every input masked ({n_masked} states) or every admissible "
                    f"input leaving the state bounds ({n_bounds} states)"
                )
            return DPInfeasibleError(
                f"no input sequence leads from the initial state {x0s} to the final step {N}: "
                f"the violated constraint is the {cause}, from step {k}: at step {k} {who} "
                f"{detail}."
            )
        where = (
            f"the admissible set becomes empty at step {bw.empty_step}"
            if bw.empty_step is not None
            else f"at step 0 the admissible states are {self._feasible_span(bw)}"
        )
        return DPInfeasibleError(
            f"the initial state {x0s} is infeasible on this state grid ({self._fmt_grid()}): "
            f"{where}, although the state bounds and the infeasibility mask alone do not "
            "forbid it (the interpolated cost-to-go near the initial state touches infeasible "
            f"nodes: final_constraint '{self.method}' is conservative by up to a grid cell per "
            f"step); the cause is grid resolution: {self._grid_hint()}."
        )

    def capture_box(self) -> tuple[FloatArray, FloatArray] | None:
        """The target box widened to one grid cell (the largest spacing) on each side in the
        states where it is narrower than a cell, when that is at least two states (a point
        or a line target in 2+ states), else None. See :meth:`land`."""
        sp = self.space
        if sp.d < 2 or not sp.has_target:
            return None
        h = np.array([float(np.diff(g).max()) for g in sp.grids])
        thin = (sp.box_hi - sp.box_lo) < h
        if np.count_nonzero(thin) < 2:
            return None
        lo = np.where(thin, np.maximum(sp.box_lo - h, sp.lo), sp.box_lo)
        hi = np.where(thin, np.minimum(sp.box_hi + h, sp.hi), sp.box_hi)
        return lo, hi

    def miss_error(self, x_end: FloatArray, bw: Backward) -> DPInfeasibleError:
        """Refusal when the grid admits the initial state but no path found ends on the target."""
        sp = self.space
        miss = self.target_miss(x_end)
        tol = ", ".join(f"{float(t):.3g}" for t in kn.VTOL * sp.span)
        return DPInfeasibleError(
            f"the optimal path on this state grid ({self._fmt_grid()}) ends at "
            f"{self._fmt_state(x_end)}, outside the final-state target "
            f"({self._fmt_box(sp.box_lo, sp.box_hi)}) by "
            f"({', '.join(f'{float(m):.3g}' for m in miss)}) (tolerance {tol}), and correcting "
            "the continuous inputs of the last steps with the model does not reach it with "
            "admissible steps. The grid admits the initial state, so the cause is grid "
            f"resolution, not the physics: {self._grid_hint()}, or refine the input grids."
        )

    def _fmt_grid(self) -> str:
        """The state grid in words: nodes and spacing per state."""
        sp = self.space
        parts = []
        for j, grid in enumerate(sp.grids):
            dx = np.diff(grid)
            spacing = (
                f"{float(dx[0]):.6g}" if sp.uniform[j] else f"{float(dx.min()):.6g} to {float(dx.max()):.6g}"
            )
            parts.append(f"{sp.state_names[j]}: {grid.size} nodes, spacing {spacing}")
        return "; ".join(parts)

    def _grid_hint(self) -> str:
        better = "'boundary_line' or 'levelset'" if self.space.d == 1 else "'levelset'"
        if self.method in ("wall", "penalty"):
            return f"refine the state grid or use final_constraint={better}"
        return "refine the state grid"

    def _grid_error(
        self, x0: FloatArray, bw: Backward, tgt: str, closest: FloatArray | None
    ) -> DPInfeasibleError:
        """Refusal when the model does reach the target from ``x0`` but the grid does not."""
        if bw.empty_step is not None:
            where = (
                "the set of grid states from which the target can still be reached becomes "
                f"empty at step {bw.empty_step}"
            )
        else:
            box = self._feasible_box(bw)
            inside = box is not None and bool(np.all((x0 >= box[0]) & (x0 <= box[1])))
            where = f"at step 0 the grid states that reach it span {self._feasible_span(bw)}" + (
                ", but the interpolation at the initial state touches infeasible nodes"
                if inside
                else ", which excludes the initial state"
            )
        via = "" if closest is None else f" (it gets to {self._fmt_state(closest)})"
        return DPInfeasibleError(
            f"the initial state {self._fmt_state(x0)} reaches the final-state target ({tgt}) "
            f"in {self.N} steps{via}, but not on this state grid ({self._fmt_grid()}) with "
            f"final_constraint '{self.method}': {where}. The cause is grid resolution, not "
            f"the physics: {self._grid_hint()}."
        )

    def _target_gap(self, x0: FloatArray) -> tuple[float, FloatArray | None]:
        """Distance, in grid cells, from the target to the closest final state reachable from
        ``x0`` (continuous forward propagation, see :meth:`_forward_reach`), and that state.

        0 when a reachable final state lies in the box (for one state: or when reachable
        final states lie on both sides of it, the reachable set being an interval);
        ``inf`` when none is found.
        """
        sp = self.space
        final: list[FloatArray] = []
        if self._forward_reach(x0, final) is not None or not final:
            return float("inf"), None
        pts = final[0]
        lo, hi = sp.box_lo, sp.box_hi
        cells = np.zeros(pts.shape[0])
        for j, grid in enumerate(sp.grids):
            c = np.clip(pts[:, j], lo[j], hi[j])
            i = np.clip(np.searchsorted(grid, c) - 1, 0, grid.size - 2)
            h = grid[i + 1] - grid[i]
            out = np.maximum(np.maximum(lo[j] - pts[:, j], pts[:, j] - hi[j]), 0.0)
            cells = np.maximum(cells, out / h)
        best = int(np.argmin(cells))
        if sp.d == 1 and np.any(pts[:, 0] <= hi[0]) and np.any(pts[:, 0] >= lo[0]):
            inside = np.clip(pts[best], lo, hi)
            return 0.0, inside
        if sp.d > 1 and cells[best] > 0.0:
            hit = self._hull_hits_box(pts, lo, hi)
            if hit is not None:
                return 0.0, hit
        return float(cells[best]), pts[best]

    def _hull_hits_box(self, pts: FloatArray, lo: FloatArray, hi: FloatArray) -> FloatArray | None:
        """A point of the target box inside the convex hull of the final states reached with
        grid inputs, or None (linear program). Continuous inputs between grid values reach
        points between those final states: for a model linear in state and input (and
        approximately for a smooth one) the reachable set is that convex hull, so a box
        the hull meets is a target the grid, not the physics, misses."""
        from scipy.optimize import linprog

        P = pts.shape[0]
        if P > 4000:  # the extreme points of a random subset still give a valid inner hull
            pts = pts[np.random.default_rng(0).choice(P, 4000, replace=False)]
            P = 4000
        # variables: weights (P) >= 0 summing to 1, and the box point y = pts' w in [lo, hi]
        a_eq = np.vstack([np.ones((1, P)), pts.T])
        scale = np.maximum(self.space.span, 1e-300)
        a_ub = np.vstack([pts.T / scale[:, None], -pts.T / scale[:, None]])
        b_ub = np.r_[hi / scale, -lo / scale] + kn.VTOL
        res = linprog(np.zeros(P), A_ub=a_ub, b_ub=b_ub, A_eq=a_eq[:1], b_eq=[1.0],
                      bounds=(0.0, None), method="highs")  # fmt: skip
        if res.status != 0:
            return None
        return np.asarray(pts.T @ res.x, dtype=np.float64)

    def _feasible_box(self, bw: Backward) -> tuple[FloatArray, FloatArray] | None:
        """Bounding box of the admissible states at step 0 (band or feasible nodes), or None."""
        sp = self.space
        if bw.band is not None and bw.k0 == 0 and np.isfinite(bw.band[0, 0]):
            return bw.band[0, [0]], bw.band[0, [2]]
        if self.mode == kn.MODE_LEVELSET:
            feas = bw.V0 <= kn.VTOL
        else:
            feas = np.isfinite(bw.J0)
        if not feas.any():
            return None
        idx = np.array(np.unravel_index(np.flatnonzero(feas), sp.shape))
        lo = np.array([sp.grids[j][idx[j].min()] for j in range(sp.d)])
        hi = np.array([sp.grids[j][idx[j].max()] for j in range(sp.d)])
        return lo, hi

    def _feasible_span(self, bw: Backward) -> str:
        box = self._feasible_box(bw)
        if box is None:
            return "no grid state"
        if bw.band is not None and bw.k0 == 0 and np.isfinite(bw.band[0, 0]):
            return self._fmt_box(*box)
        return "the box " + self._fmt_box(*box)

    def _forward_reach(self, x0: FloatArray, final: list | None = None) -> tuple[int, int, int, int] | None:
        """First step at which no state reachable from x0 has an admissible input.

        Returns ``(step, states tracked, of which all inputs masked, of which all admissible
        inputs leave the bounds)`` or None. The reachable set is tracked as continuous
        points; per grid cell only the points extreme in some state are kept.
        """
        sp = self.space
        d, q = sp.d, sp.q
        pts = x0.reshape(1, d)
        for k in range(self.N):
            data_k = self.ev.data_at(k)
            pre = self.ev.pre_at(k, data_k)
            P = pts.shape[0]
            states = tuple(pts[:, j].reshape((P,) + (1,) * (d - 1 + q)) for j in range(d))
            blk = self.ev(states, k, data_k, pre)
            xn = [blk.next_state(j) for j in range(d)]
            valid = np.isfinite(blk.g) & (blk.g < np.inf)
            for xr in xn:
                valid &= np.isfinite(xr)
            if blk.mask is not None:
                valid &= ~blk.mask
            inb = valid.copy()
            for j, xr in enumerate(xn):
                inb &= (xr >= sp.lo[j] - self.btol[j]) & (xr <= sp.hi[j] + self.btol[j])
            has_valid = valid.any(axis=1)
            has_inb = inb.any(axis=1)
            if not has_inb.any():
                n_masked = int(np.count_nonzero(~has_valid))
                return k, P, n_masked, P - n_masked
            r, m = np.nonzero(inb)
            cand = np.stack([np.clip(xr[r, m], sp.lo[j], sp.hi[j]) for j, xr in enumerate(xn)], 1)
            cells = np.stack(
                [
                    np.clip(np.searchsorted(g, cand[:, j], side="right") - 1, 0, g.size - 2)
                    for j, g in enumerate(sp.grids)
                ],
                1,
            )
            key = np.ravel_multi_index(tuple(cells.T), tuple(g.size - 1 for g in sp.grids))
            keep = []
            for j in range(d):  # per cell, the points with the smallest and largest x_j
                order = np.lexsort((cand[:, j], key))
                ks = key[order]
                first = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
                last = np.r_[first[1:] - 1, ks.size - 1]
                keep.append(order[first])
                keep.append(order[last])
            pts = cand[np.unique(np.concatenate(keep))]
        if final is not None:
            final.append(pts)
        return None


def progress_bar(total: int, show: bool) -> Any:
    """A tqdm bar on stderr, or None when hidden."""
    if not show:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc="DP", unit="step", file=sys.stderr, leave=False)

"""Backward recursion, forward pass, costate and infeasibility diagnosis of the DP solver."""

from __future__ import annotations

import sys
from dataclasses import dataclass, replace
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
PARALLEL_MIN_PAIRS = 20_000  # blocks smaller than this run the serial kernel
_DUMMY_MASK = np.zeros((1, 1), dtype=np.bool_)
_DUMMY_X = np.zeros((1, 1))


USE_HULL = True  # exact convex-hull input pruning for state-independent 1-D blocks (_hull.py)


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
        S, M = blk.g.shape
        out_J = np.empty(S)
        out_arg = np.empty(S, dtype=np.int64)
        out_status = np.empty(S, dtype=np.int8)
        out_V = np.empty(S)
        out_argv = np.empty(S, dtype=np.int64)
        has_mask = blk.mask is not None
        mask = blk.mask if blk.mask is not None else _DUMMY_MASK
        J = np.asarray(J, dtype=np.float64)  # stored float32 rows are widened
        Vk = J if V is None else np.asarray(V, dtype=np.float64)
        big = S >= 2 and S * M >= PARALLEL_MIN_PAIRS
        # the thread policy (hevsim.threads): one thread -> the serial Bellman kernels
        parallel = big and _numba_threads() > 1
        if sp.d == 1 and USE_HULL and big and not use_box:
            hull = self._hull_step(blk, J, Vk, band, band_i, mode)
            if hull is not None:
                return hull
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
        return self.step(blk, Jz, Vn, bz, band_i, self.method in ("wall", "levelset"))

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
        return replace(blk, g=blk.g + add)

    def point_blocks(self, points: FloatArray, cost: FloatArray | None = None) -> Block:
        """A block whose rows are the given next states (one input each)."""
        P = points.shape[0]
        g = np.zeros((P, 1)) if cost is None else cost.reshape(P, 1)
        xn = [np.ascontiguousarray(points[:, j].reshape(P, 1)) for j in range(self.space.d)]
        base = [np.zeros(P) for _ in range(self.space.d)]
        return Block(xn=xn, base=base, g=g, mask=None, shape=(P, 1), states=(), inputs=())

    # ------------------------------------------------------------------ terminal
    def box_distance(self, box_lo: FloatArray, box_hi: FloatArray) -> FloatArray:
        """Level-set function of the target box at every node (flat).

        With ``d_j`` the signed, span-normalised distance of state ``j`` to its target
        interval: ``max_j d_j`` inside the box (<= 0) and ``sum_j max(d_j, 0)`` outside. Both
        pieces are exact under multilinear interpolation for a box with one active face, and
        the sum keeps separable problems separable.
        """
        sp = self.space
        vmax = np.full(sp.shape, -np.inf)
        vpos = np.zeros(sp.shape)
        for j, grid in enumerate(sp.grids):
            shp = [1] * sp.d
            shp[j] = grid.size
            gj = grid.reshape(shp)
            dj = np.maximum(box_lo[j] - gj, gj - box_hi[j]) / sp.span[j]
            vmax = np.maximum(vmax, dj)
            vpos = vpos + np.maximum(dj, 0.0)
        return np.where(vpos > 0.0, vpos, vmax).ravel()

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
                m = int(out.arg[0])
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
                return DPInfeasibleError(
                    f"the initial state {x0s} cannot reach the final-state target ({tgt}) in "
                    f"{N} steps: the violated constraint is the final-state target; {where} "
                    "(without the target the problem is feasible). Widen the target, lengthen "
                    "the horizon, move the initial state or give the inputs more authority."
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
            f"the initial state {x0s} is infeasible on this grid: {where}, although the state "
            "bounds and the infeasibility mask alone do not forbid it (the interpolated "
            "cost-to-go near the initial state touches infeasible nodes: final_constraint "
            f"'{self.method}' is conservative by up to a grid cell per step); refine the "
            "state grid or use final_constraint='levelset' or 'boundary_line'."
        )

    def _feasible_span(self, bw: Backward) -> str:
        sp = self.space
        if bw.band is not None and bw.k0 == 0 and np.isfinite(bw.band[0, 0]):
            return f"{sp.state_names[0]} in [{bw.band[0, 0]:.6g}, {bw.band[0, 2]:.6g}]"
        if self.mode == kn.MODE_LEVELSET:
            feas = bw.V0 <= kn.VTOL
        else:
            feas = np.isfinite(bw.J0)
        if not feas.any():
            return "no grid state"
        idx = np.array(np.unravel_index(np.flatnonzero(feas), sp.shape))
        lo = np.array([sp.grids[j][idx[j].min()] for j in range(sp.d)])
        hi = np.array([sp.grids[j][idx[j].max()] for j in range(sp.d)])
        return "the box " + self._fmt_box(lo, hi)

    def _forward_reach(self, x0: FloatArray) -> tuple[int, int, int, int] | None:
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
        return None


def progress_bar(total: int, show: bool) -> Any:
    """A tqdm bar on stderr, or None when hidden."""
    if not show:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc="DP", unit="step", file=sys.stderr, leave=False)

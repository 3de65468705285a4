"""Generic, vectorised discrete-time dynamic programming (DP).

Solve ``min sum_k g_k(x_k, u_k) + phi(x_N)`` subject to ``x_{k+1} = f_k(x_k, u_k)``, state
bounds (the state grid), an infeasibility mask returned by the model and a final-state
target box, for 1 to 4 states on rectilinear grids (regular or irregular) and any number
of inputs (continuous grids or discrete sets such as gears). See ``docs/dp.md``.

The backward recursion evaluates the model once per step on the whole ``(states x
inputs)`` block and reduces it in a numba kernel (multilinear interpolation of the
cost-to-go, stage cost, minimum over the inputs), parallel over the state nodes. The
forward pass re-optimises at the actual, off-grid state by default.

Final-state constraint methods (``final_constraint``):

* ``"boundary_line"`` (1 state; default there): the lowest and highest states from which
  the target can be reached are computed backward (Sundström, Ambühl & Guzzella 2010) at
  sub-grid accuracy, together with the cost of following them; the region between them is
  treated exactly and the cost-to-go in the cells cut by a boundary is interpolated towards
  the boundary-line cost.
* ``"levelset"`` (any number of states; default for 2-4 states): a level-set function
  (span-normalised Chebyshev distance to the target box, the largest per-state distance,
  <= 0 inside; propagated backward by ``V_k(x) = min_u V_{k+1}(f(x, u))``) defines the
  backward reachable set at every step; both the recursion and the forward pass only admit
  inputs whose next state lies in it. Nodes outside the set keep the finite cost of the
  input that comes closest to it, so no infinite or large penalty is interpolated (Elbert
  et al. 2013); the nodes next to the set get an extrapolation of the cost-to-go inside
  it (``J(n+e) + |J(n+e) - J(n+2e)|`` averaged over the grid directions), so that
  interpolation does not under-estimate the cost along the boundary.
* ``"wall"``: infinite cost outside the target. Interpolation touching an infinite node is
  infinite, so the wall never leaks, but it is conservative by up to one cell per step
  near the boundary of the feasible region.
* ``"penalty"``: ``penalty_weight * distance`` to the target added to the terminal cost
  (exact penalty: with a weight above the largest marginal value of the state, the target
  is met up to grid resolution); infeasible-by-target nodes keep finite costs.

At the last step, every method evaluates the terminal cost, the penalty and the target box
exactly at the next states (no interpolation). Targets narrower than the input grid
resolves (equality targets ``lower == upper``) are reached with a fractional input between
two neighbouring grid values of a continuous input.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from hevsim.errors import DPSetupError
from hevsim.optimal._problem import DPProblem, FinalTarget, FloatArray, Increment
from hevsim.optimal._solver import METHODS, DPSolver, progress_bar

__all__ = [
    "FINAL_CONSTRAINTS",
    "FORWARD_MODES",
    "DPProblem",
    "DPResult",
    "FinalTarget",
    "Increment",
    "estimate_memory",
    "solve_dp",
]

FINAL_CONSTRAINTS: tuple[str, ...] = ("auto", *METHODS)
FORWARD_MODES: tuple[str, ...] = ("reoptimize", "policy")
COST_DTYPES: tuple[str, ...] = ("float64", "float32")
DEFAULT_MEMORY_LIMIT_BYTES = 4 * 1024**3
PROGRESS_MIN_WORK = 5_000_000  # auto progress bar only above this many (node, input, step)


@dataclass(frozen=True, eq=False)
class DPResult:
    """Optimal trajectory and, on request, the cost-to-go and policy of a DP solution.

    Attributes:
        states: state trajectory, shape (N+1, d) [state units].
        inputs: input trajectory, shape (N, q) [input units].
        stage_costs: stage cost of each step, shape (N,) [cost unit].
        terminal_cost: terminal cost ``phi(x_N)`` [cost unit].
        penalty_cost: linear final-state penalty (``final_constraint="penalty"``) [cost unit].
        total_cost: ``sum(stage_costs) + terminal_cost + penalty_cost`` [cost unit].
        costate: d(cost-to-go)/d(state) along the trajectory, shape (N+1, d), by central
            finite differences (one grid cell each side) of the interpolated cost-to-go;
            NaN where no finite difference exists [cost unit / state unit].
        final_constraint: method used (``"auto"`` resolved).
        forward: ``"reoptimize"`` or ``"policy"``.
        n_fallback_steps: forward steps where the preferred choice was inadmissible and a
            fallback was used (policy -> re-optimisation, or the input closest to the
            admissible set).
        n_feasible_nodes: number of grid nodes in the admissible set per step, shape (N+1,).
        n_landing_steps: final steps whose continuous inputs were corrected so that the
            final state lies in the target box (0 when the grid path already ends there;
            see ``docs/dp.md``, "Exact targets in several states").
        boundary_lines: lower and upper boundary lines, shape (N+1, 2) (boundary-line
            method), else None [state unit].
        cost_to_go: (N+1, n1, .., nd) if ``store_cost_to_go``, else None [cost unit].
        level_set: (N+1, n1, .., nd) level-set function if stored (levelset method).
        policy_index: (N, n1, .., nd) flat arg-min input index per node (int32) if
            ``store_policy`` (or policy forward pass), else None; ``-1`` or the closest
            input where the node is infeasible.
        memory_bytes: estimate of the memory used, by item.
        timings_s: wall-clock time of the backward and forward passes [s].
    """

    states: FloatArray
    inputs: FloatArray
    stage_costs: FloatArray
    terminal_cost: float
    penalty_cost: float
    total_cost: float
    costate: FloatArray
    final_constraint: str
    forward: str
    n_fallback_steps: int
    n_feasible_nodes: npt.NDArray[np.int64]
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    input_grids: tuple[FloatArray, ...]
    boundary_lines: FloatArray | None = None
    n_landing_steps: int = 0
    cost_to_go: np.ndarray | None = None
    level_set: np.ndarray | None = None
    policy_index: npt.NDArray[np.int32] | None = None
    memory_bytes: dict[str, int] = field(default_factory=dict)
    timings_s: dict[str, float] = field(default_factory=dict)

    def policy(self) -> tuple[FloatArray, ...] | None:
        """Optimal input values per node and step, one (N, n1, .., nd) array per input."""
        if self.policy_index is None:
            return None
        shape = tuple(u.size for u in self.input_grids)
        idx = np.unravel_index(np.maximum(self.policy_index, 0), shape)
        out = []
        for j, grid in enumerate(self.input_grids):
            vals = grid[idx[j]].astype(np.float64)
            vals[self.policy_index < 0] = np.nan
            out.append(vals)
        return tuple(out)


def _resolve_method(final_constraint: str, d: int) -> str:
    if final_constraint not in FINAL_CONSTRAINTS:
        raise DPSetupError(
            f"final_constraint {final_constraint!r} is not known; expected one of "
            f"{', '.join(FINAL_CONSTRAINTS)}."
        )
    if final_constraint == "auto":
        return "boundary_line" if d == 1 else "levelset"
    if final_constraint == "boundary_line" and d != 1:
        raise DPSetupError(
            f"final_constraint 'boundary_line' handles one state variable; the problem has {d}. "
            "Use 'levelset' (default for several states), 'wall' or 'penalty'."
        )
    return final_constraint


def _dtype(cost_dtype: str | type | np.dtype) -> np.dtype:
    try:
        dt = np.dtype(cost_dtype)
    except TypeError as exc:
        raise DPSetupError(
            f"cost_dtype {cost_dtype!r} is not a dtype; expected one of {COST_DTYPES}."
        ) from exc
    if dt.name not in COST_DTYPES:
        raise DPSetupError(f"cost_dtype {cost_dtype!r} is not supported; expected one of {COST_DTYPES}.")
    return dt


def estimate_memory(
    problem: DPProblem,
    *,
    final_constraint: str = "auto",
    forward: str = "reoptimize",
    store_policy: bool = False,
    cost_dtype: str | type | np.dtype = "float64",
) -> dict[str, int]:
    """Memory a solution needs [bytes], by item, plus ``"total"``.

    With ``S = n1*..*nd`` nodes, ``M = m1*..*mq`` input combinations and ``N`` steps:
    cost-to-go ``(N+1)*S*itemsize`` (always kept: the forward pass needs it); level set the
    same again (levelset method); policy ``N*S*5`` (int32 index + int8 status, when
    ``forward="policy"`` or ``store_policy``); one step's model outputs ``S*M*(d+2)*8``
    plus the kernel outputs ``S*40``.
    """
    sp = problem.space
    method = _resolve_method(final_constraint, sp.d)
    item = _dtype(cost_dtype).itemsize
    N, S, M, d = sp.n_steps, sp.S, sp.M, sp.d
    out = {
        "cost_to_go": (N + 1) * S * item,
        "level_set": (N + 1) * S * item if method == "levelset" else 0,
        "policy": N * S * 5 if (store_policy or forward == "policy") else 0,
        "step_block": S * M * (d + 2) * 8 + S * 40,
    }
    out["total"] = sum(out.values())
    return out


def _forward_on_target(
    solver: DPSolver,
    x: FloatArray,
    bw: Any,
    policy: bool,
    bar: Any,
    box: tuple[FloatArray, FloatArray] | None = None,
) -> tuple[Any, FloatArray | None, FloatArray, FloatArray, int, int, FloatArray]:
    """Forward pass (towards ``box`` if given), then the realised final state is checked
    against the target; a path ending outside it is corrected onto it
    (:meth:`DPSolver.land`). Returns ``(bw, states or None when it cannot be landed,
    inputs, stage costs, fallback steps, corrected steps, final state of the grid path)``."""
    saved = solver.box
    if box is not None:
        solver.box = box
    try:
        xs, us, gs, n_fb = solver.forward(x, bw, policy, bar=bar)
    finally:
        solver.box = saved
    x_end = xs[-1].copy()
    if solver.method == "penalty" or not np.any(solver.target_miss(x_end)):
        return bw, xs, us, gs, n_fb, 0, x_end
    landed = solver.land(xs, us, gs)
    if landed is None:
        return bw, None, us, gs, n_fb, 0, x_end
    xs, us, gs, n_land = landed
    return bw, xs, us, gs, n_fb, n_land, x_end


def _path_cost(solver: DPSolver, xs: FloatArray | None, gs: FloatArray) -> float:
    assert xs is not None
    return float(np.sum(gs)) + sum(solver.terminal_at(xs[-1]))


def solve_dp(
    problem: DPProblem,
    x0: npt.ArrayLike,
    *,
    final_constraint: str = "auto",
    penalty_weight: float | Sequence[float] | None = None,
    forward: str = "reoptimize",
    store_cost_to_go: bool = False,
    store_policy: bool = False,
    cost_dtype: str | type | np.dtype = "float64",
    memory_limit_bytes: float | None = DEFAULT_MEMORY_LIMIT_BYTES,
    progress: bool | None = None,
) -> DPResult:
    """Solve ``problem`` from the initial state ``x0`` by dynamic programming.

    Args:
        problem: the :class:`DPProblem` (model, grids, horizon, data, target).
        x0: initial state, one value per state variable [state units], inside the grid.
        final_constraint: ``"auto"`` (boundary line for 1 state, level set otherwise),
            ``"boundary_line"``, ``"levelset"``, ``"wall"`` or ``"penalty"``; see the
            module docstring and ``docs/dp.md``.
        penalty_weight: cost per unit of distance outside the target, scalar or one per
            state (required by ``"penalty"``) [cost unit / state unit].
        forward: ``"reoptimize"`` (evaluate the model at the actual off-grid state for all
            inputs and minimise stage cost + interpolated cost-to-go) or ``"policy"``
            (interpolate the stored arg-min input of the surrounding nodes: weighted mean
            for continuous inputs, nearest node for discrete ones; falls back to
            re-optimisation when the interpolated input is inadmissible).
        store_cost_to_go: return the cost-to-go (and level set) arrays in the result.
        store_policy: return the arg-min input index per node and step.
        cost_dtype: ``"float64"`` or ``"float32"`` for the stored cost-to-go (halves its
            memory; the recursion itself runs in float64).
        memory_limit_bytes: refuse (``DPSetupError``) when :func:`estimate_memory` exceeds
            this; None disables the check. The estimate is ``(N+1)*S*itemsize`` for the
            cost-to-go, the same again for the level set, ``N*S*5`` for a policy and
            ``S*M*(d+2)*8`` for one step's model outputs.
        progress: show a tqdm bar on stderr; None = only when stderr is a terminal and
            the problem is large.

    Returns:
        A :class:`DPResult`.

    Raises:
        DPSetupError: malformed arguments (grids, target, x0, options, memory limit).
        DPModelError: the model returns wrong shapes, NaN or -inf (names output and step).
        DPInfeasibleError: the target cannot be reached from ``x0``; the message names the
            violated constraint (state bounds, infeasibility mask, final-state target) and
            the step from which the admissible set is empty or excludes ``x0``.
    """
    sp = problem.space
    method = _resolve_method(final_constraint, sp.d)
    if forward not in FORWARD_MODES:
        raise DPSetupError(f"forward {forward!r} is not known; expected one of {', '.join(FORWARD_MODES)}.")
    dtype = _dtype(cost_dtype)
    x = np.atleast_1d(np.asarray(x0, dtype=np.float64))
    if x.shape != (sp.d,):
        raise DPSetupError(f"x0 has shape {x.shape}; expected one value per state ({sp.d},).")
    for j in range(sp.d):
        tol = 1e-9 * sp.span[j]
        if not np.isfinite(x[j]) or x[j] < sp.lo[j] - tol or x[j] > sp.hi[j] + tol:
            raise DPSetupError(
                f"x0[{j}] ('{sp.state_names[j]}') = {float(x[j])!r} is outside the state grid "
                f"[{float(sp.lo[j])!r}, {float(sp.hi[j])!r}]; expected a value inside it."
            )
    x = np.clip(x, sp.lo, sp.hi)
    weight = None
    if method == "penalty":
        if penalty_weight is None:
            raise DPSetupError(
                "final_constraint 'penalty' needs penalty_weight (cost per unit of state "
                "outside the target); choose it above the largest marginal value of the state."
            )
        weight = np.broadcast_to(np.asarray(penalty_weight, dtype=np.float64), (sp.d,)).copy()
        if not np.all(np.isfinite(weight)) or np.any(weight <= 0):
            raise DPSetupError(f"penalty_weight {penalty_weight!r} must be finite and > 0.")
    elif penalty_weight is not None:
        raise DPSetupError(f"penalty_weight is only used with final_constraint='penalty' (got {method!r}).")
    keep_policy = store_policy or forward == "policy"
    mem = estimate_memory(
        problem,
        final_constraint=method,
        forward=forward,
        store_policy=store_policy,
        cost_dtype=dtype,
    )
    if memory_limit_bytes is not None and mem["total"] > memory_limit_bytes:
        items = ", ".join(f"{k} {v / 1e6:.1f} MB" for k, v in mem.items() if k != "total" and v)
        raise DPSetupError(
            f"the DP solution needs about {mem['total'] / 1e6:.1f} MB ({items}), more than "
            f"memory_limit_bytes = {memory_limit_bytes / 1e6:.1f} MB; use "
            "cost_dtype='float32', a coarser grid, fewer steps, store_policy=False, or "
            "raise the limit."
        )
    solver = DPSolver(problem, method, weight, dtype)
    N = sp.n_steps
    if progress is None:
        isatty = getattr(sys.stderr, "isatty", None)
        show = bool(isatty and isatty()) and N * sp.S * sp.M >= PROGRESS_MIN_WORK
    else:
        show = bool(progress)
    bar = progress_bar(2 * N, show)
    try:
        t0 = time.perf_counter()
        bw = solver.backward(sp.box_lo, sp.box_hi, store=True, keep_policy=keep_policy, bar=bar)
        t1 = time.perf_counter()
        runs = []  # (bw, xs, us, gs, n_fallback, steps corrected onto the target)
        if solver.point_feasible(x, bw):
            runs.append(_forward_on_target(solver, x, bw, forward == "policy", bar))
        capture = solver.capture_box() if method == "levelset" else None
        if capture is not None:
            # a point-like target in 2+ states: also solve towards the one-cell capture box
            bwc = solver.backward(*capture, store=True, keep_policy=keep_policy)
            if solver.point_feasible(x, bwc):
                runs.append(_forward_on_target(solver, x, bwc, forward == "policy", None, capture))
        ok = [r for r in runs if r[1] is not None]
        if not ok:
            if runs:  # admitted by the grid, but no path ends on the target
                raise solver.miss_error(runs[0][6], bw)
            raise solver.diagnose(x, bw)
        bw, xs_ok, us, gs, n_fb, n_land, _ = min(ok, key=lambda r: _path_cost(solver, r[1], r[3]))
        assert xs_ok is not None
        xs = xs_ok
        t2 = time.perf_counter()
        lam = solver.costate(bw, xs)
    finally:
        if bar is not None:
            bar.close()
    phi, pen = solver.terminal_at(xs[-1])
    shape = (N + 1, *sp.shape)
    band = bw.band[:, [0, 2]].copy() if bw.band is not None else None
    return DPResult(
        states=xs,
        inputs=us,
        stage_costs=gs,
        terminal_cost=phi,
        penalty_cost=pen,
        total_cost=float(np.sum(gs) + phi + pen),
        costate=lam,
        final_constraint=method,
        forward=forward,
        n_fallback_steps=n_fb,
        n_landing_steps=n_land,
        n_feasible_nodes=bw.n_feasible,
        state_names=sp.state_names,
        input_names=sp.input_names,
        input_grids=sp.inputs,
        boundary_lines=band,
        cost_to_go=bw.J.reshape(shape) if (store_cost_to_go and bw.J is not None) else None,
        level_set=bw.V.reshape(shape) if (store_cost_to_go and bw.V is not None) else None,
        policy_index=(
            bw.policy.reshape((N, *sp.shape)) if (store_policy and bw.policy is not None) else None
        ),
        memory_bytes=mem,
        timings_s={"backward": t1 - t0, "forward": t2 - t1},
    )

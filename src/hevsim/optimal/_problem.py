"""Problem definition, validation and model evaluation of the generic DP solver."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from hevsim.errors import DPModelError, DPSetupError

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

MAX_STATES = 4
UNIFORM_RTOL = 1e-9  # a grid is "regular" when its steps differ by less than this (relative)


@dataclass(frozen=True)
class FinalTarget:
    """Box of admissible final states: ``lower[i] <= x_N[i] <= upper[i]``.

    ``lower`` and ``upper`` hold one bound per state variable, in the unit of that state
    (a scalar is accepted for a single state). ``None`` or an infinite bound means "no bound
    beyond the state grid" for that side. The box must lie inside the state grid.
    """

    lower: float | Sequence[float | None] | None = None
    upper: float | Sequence[float | None] | None = None


@dataclass(frozen=True, eq=False)
class DPProblem:
    """A discrete-time optimal control problem ``x[k+1] = f_k(x[k], u[k])``, k = 0..N-1.

    Attributes:
        model: vectorised model, called as ``model(states, inputs, k, data)`` (or
            ``model(states, inputs, k, data, pre)`` when ``precompute`` is given) with
            ``states`` a tuple of ``d`` arrays broadcastable as ``(n1, .., nd, 1, .., 1)`` and
            ``inputs`` a tuple of ``q`` arrays broadcastable as ``(1, .., 1, m1, .., mq)``.
            It returns ``(next_states, stage_cost, infeasible_mask)``: a sequence of ``d``
            arrays (a bare array is accepted when ``d == 1``), an array and a boolean array
            (or ``None``), each broadcastable to the block shape ``(n1..nd, m1..mq)``.
            ``stage_cost = +inf`` also marks a pair infeasible. NaN is allowed only where the
            mask is True. With several states, a model whose next state ``j`` has a size-1 axis
            for every other state, and whose cost and mask have size-1 axes for all states
            (each state moves on its own, e.g. ``x_j' = a_j x_j + b_j(u)``), is solved from
            per-state tables without forming the ``(states x inputs)`` block (same result,
            several times faster): keep such outputs unbroadcast.
        state_grids: one strictly increasing grid (>= 2 points) per state, 1 to 4 states.
        input_grids: one grid per input: strictly increasing for continuous inputs, or any
            set of distinct values for the inputs listed in ``discrete_inputs`` (gears).
        n_steps: horizon ``N`` (number of transitions).
        data: exogenous data: a mapping of arrays whose first axis is the time step (the
            model then receives ``{key: value[k]}``), a callable ``data(k)`` or None.
        precompute: optional ``precompute(inputs, k, data) -> pre`` for the parts of the
            model that do not depend on the state (e.g. engine maps along the cycle); it is
            called once per step and ``pre`` is passed to the model as fifth argument.
        terminal_cost: optional elementwise ``terminal_cost(states) -> cost`` of the final
            state, with ``states`` a tuple of ``d`` arrays of a common (broadcast) shape: the
            grid ``(n1, .., nd)``, and at the last step the next states of the whole block
            (the terminal cost is evaluated exactly there, not interpolated). NaN is allowed
            only for states outside the grid.
        target: final-state target box, or None for "anywhere on the grid".
        discrete_inputs: indices of the inputs that are discrete sets (used by the policy
            interpolation: nearest node instead of weighted average).
        state_names, input_names: names (with units) for messages and results.
    """

    model: Callable[..., Any]
    state_grids: Sequence[npt.ArrayLike]
    input_grids: Sequence[npt.ArrayLike]
    n_steps: int
    data: Mapping[str, npt.ArrayLike] | Callable[[int], Any] | None = None
    precompute: Callable[..., Any] | None = None
    terminal_cost: Callable[..., Any] | None = None
    target: FinalTarget | None = None
    discrete_inputs: Sequence[int] = ()
    state_names: Sequence[str] | None = None
    input_names: Sequence[str] | None = None
    space: Space = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "space", Space.build(self))


def _grid_label(kind: str, j: int, names: Sequence[str]) -> str:
    return f"{kind}[{j}] ('{names[j]}')"


def _check_grid(values: npt.ArrayLike, label: str, *, sorted_required: bool, min_size: int) -> FloatArray:
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DPSetupError(f"{label} must be a 1-D array of numbers; got {values!r} ({exc}).") from exc
    if arr.ndim != 1:
        raise DPSetupError(f"{label} must be a 1-D array of numbers; got shape {arr.shape}.")
    if arr.size < min_size:
        what = "is empty" if arr.size == 0 else f"has {arr.size} point"
        raise DPSetupError(f"{label} {what}; expected at least {min_size} point(s).")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise DPSetupError(
            f"{label} has a non-finite value {float(arr[bad[0]])!r} at position {bad[0]}; "
            "expected finite numbers."
        )
    if sorted_required:
        steps = np.diff(arr)
        bad = np.flatnonzero(steps <= 0)
        if bad.size:
            i = int(bad[0])
            raise DPSetupError(
                f"{label} is not strictly increasing: value {float(arr[i + 1])!r} at position {i + 1} "
                f"follows {float(arr[i])!r}; expected sorted, distinct grid points."
            )
    elif np.unique(arr).size != arr.size:
        raise DPSetupError(f"{label} has repeated values {arr.tolist()}; expected distinct values.")
    return np.ascontiguousarray(arr)


def _bound_vector(value: Any, d: int, name: str, default: FloatArray) -> FloatArray:
    if value is None:
        return default.copy()
    raw = [value] if np.ndim(value) == 0 and not isinstance(value, (list, tuple)) else list(value)
    if len(raw) != d:
        raise DPSetupError(f"target.{name} has {len(raw)} entries; expected one per state ({d}).")
    out = default.copy()
    for j, v in enumerate(raw):
        if v is None:
            continue
        fv = float(v)
        if np.isnan(fv):
            raise DPSetupError(f"target.{name}[{j}] is NaN; expected a number or None.")
        if np.isfinite(fv):
            out[j] = fv
    return out


@dataclass(frozen=True, eq=False)
class Space:
    """Validated grids, target box and broadcast arrays of a :class:`DPProblem`."""

    grids: tuple[FloatArray, ...]
    inputs: tuple[FloatArray, ...]
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    discrete: tuple[bool, ...]
    n_steps: int
    lo: FloatArray
    hi: FloatArray
    span: FloatArray
    uniform: BoolArray
    inv_dx: FloatArray
    gflat: FloatArray
    goff: IntArray
    gstride: IntArray
    box_lo: FloatArray
    box_hi: FloatArray
    states_b: tuple[FloatArray, ...]
    inputs_b: tuple[FloatArray, ...]
    data_arrays: dict[str, np.ndarray] | None

    @property
    def d(self) -> int:
        return len(self.grids)

    @property
    def q(self) -> int:
        return len(self.inputs)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(g.size for g in self.grids)

    @property
    def input_shape(self) -> tuple[int, ...]:
        return tuple(u.size for u in self.inputs)

    @property
    def S(self) -> int:
        return int(np.prod(self.shape))

    @property
    def M(self) -> int:
        return int(np.prod(self.input_shape))

    @property
    def has_target(self) -> bool:
        return bool(np.any(self.box_lo > self.lo) or np.any(self.box_hi < self.hi))

    @staticmethod
    def build(p: DPProblem) -> Space:
        if not callable(p.model):
            raise DPSetupError(f"model must be callable; got {type(p.model).__name__}.")
        if isinstance(p.state_grids, np.ndarray) and p.state_grids.ndim == 1:
            raise DPSetupError("state_grids must be a sequence of 1-D grids, e.g. [soc_grid].")
        if isinstance(p.input_grids, np.ndarray) and p.input_grids.ndim == 1:
            raise DPSetupError("input_grids must be a sequence of 1-D grids, e.g. [power_grid].")
        d = len(p.state_grids)
        q = len(p.input_grids)
        if not 1 <= d <= MAX_STATES:
            raise DPSetupError(
                f"state_grids has {d} grids; the solver handles 1 to {MAX_STATES} state variables."
            )
        if q < 1:
            raise DPSetupError("input_grids is empty; expected at least one input grid.")
        if isinstance(p.n_steps, bool) or not isinstance(p.n_steps, (int, np.integer)):
            raise DPSetupError(f"n_steps must be an integer >= 1; got {p.n_steps!r}.")
        if p.n_steps < 1:
            raise DPSetupError(f"n_steps must be >= 1; got {p.n_steps}.")
        n_steps = int(p.n_steps)
        snames = tuple(p.state_names) if p.state_names is not None else tuple(f"x{j + 1}" for j in range(d))
        inames = tuple(p.input_names) if p.input_names is not None else tuple(f"u{j + 1}" for j in range(q))
        if len(snames) != d:
            raise DPSetupError(f"state_names has {len(snames)} names; expected {d}.")
        if len(inames) != q:
            raise DPSetupError(f"input_names has {len(inames)} names; expected {q}.")
        disc = [False] * q
        for j in p.discrete_inputs:
            if not isinstance(j, (int, np.integer)) or not 0 <= j < q:
                raise DPSetupError(f"discrete_inputs entry {j!r} is not an input index; expected 0..{q - 1}.")
            disc[int(j)] = True
        grids = tuple(
            _check_grid(g, _grid_label("state_grids", j, snames), sorted_required=True, min_size=2)
            for j, g in enumerate(p.state_grids)
        )
        inputs = tuple(
            _check_grid(u, _grid_label("input_grids", j, inames), sorted_required=not disc[j], min_size=1)
            for j, u in enumerate(p.input_grids)
        )
        lo = np.array([g[0] for g in grids])
        hi = np.array([g[-1] for g in grids])
        span = hi - lo
        uniform = np.zeros(d, dtype=np.bool_)
        inv_dx = np.zeros(d)
        for j, g in enumerate(grids):
            steps = np.diff(g)
            mean = span[j] / (g.size - 1)
            uniform[j] = bool(np.max(np.abs(steps - mean)) <= UNIFORM_RTOL * mean)
            inv_dx[j] = (g.size - 1) / span[j]
        gflat = np.ascontiguousarray(np.concatenate(grids))
        goff = np.concatenate([[0], np.cumsum([g.size for g in grids])]).astype(np.int64)
        shape = tuple(g.size for g in grids)
        gstride = np.array([int(np.prod(shape[j + 1 :])) for j in range(d)], dtype=np.int64)  # C order
        # target box
        if p.target is not None and not isinstance(p.target, FinalTarget):
            raise DPSetupError(
                f"target must be a FinalTarget(lower=..., upper=...) or None; got {p.target!r}."
            )
        tgt = p.target or FinalTarget()
        box_lo = _bound_vector(tgt.lower, d, "lower", lo)
        box_hi = _bound_vector(tgt.upper, d, "upper", hi)
        for j in range(d):
            tol = 1e-9 * span[j]
            lab = f"state {j} ('{snames[j]}')"
            if (
                box_lo[j] < lo[j] - tol
                or box_hi[j] > hi[j] + tol
                or box_lo[j] > hi[j] + tol
                or box_hi[j] < lo[j] - tol
            ):
                raise DPSetupError(
                    f"target for {lab}: [{float(box_lo[j])!r}, {float(box_hi[j])!r}] lies "
                    f"(partly) outside the state grid [{float(lo[j])!r}, {float(hi[j])!r}]; "
                    "expected a target inside the grid (extend the grid or use None for an "
                    "unbounded side)."
                )
            if box_lo[j] > box_hi[j]:
                raise DPSetupError(
                    f"target for {lab}: lower bound {float(box_lo[j])!r} exceeds upper bound "
                    f"{float(box_hi[j])!r}; expected lower <= upper."
                )
            box_lo[j] = min(max(box_lo[j], lo[j]), hi[j])
            box_hi[j] = min(max(box_hi[j], lo[j]), hi[j])
        nd = d + q
        states_b = tuple(
            g.reshape(tuple(g.size if i == j else 1 for i in range(nd))) for j, g in enumerate(grids)
        )
        inputs_b = tuple(
            u.reshape(tuple(u.size if i == d + j else 1 for i in range(nd))) for j, u in enumerate(inputs)
        )
        data_arrays: dict[str, np.ndarray] | None = None
        if p.data is not None and not callable(p.data):
            if not isinstance(p.data, Mapping):
                raise DPSetupError(
                    "data must be a mapping of arrays indexed by time step, a callable "
                    f"data(k) or None; got {type(p.data).__name__}."
                )
            data_arrays = {}
            for key, value in p.data.items():
                arr = np.asarray(value)
                if arr.ndim < 1 or arr.shape[0] < n_steps:
                    raise DPSetupError(
                        f"data['{key}'] has shape {arr.shape}; expected an array whose first "
                        f"axis (time step) has at least n_steps = {n_steps} entries."
                    )
                data_arrays[str(key)] = arr
        if p.precompute is not None and not callable(p.precompute):
            raise DPSetupError("precompute must be callable or None.")
        if p.terminal_cost is not None and not callable(p.terminal_cost):
            raise DPSetupError("terminal_cost must be callable or None.")
        return Space(
            grids=grids,
            inputs=inputs,
            state_names=snames,
            input_names=inames,
            discrete=tuple(disc),
            n_steps=n_steps,
            lo=lo,
            hi=hi,
            span=span,
            uniform=uniform,
            inv_dx=inv_dx,
            gflat=gflat,
            goff=goff,
            gstride=gstride,
            box_lo=box_lo,
            box_hi=box_hi,
            states_b=states_b,
            inputs_b=inputs_b,
            data_arrays=data_arrays,
        )


@dataclass(frozen=True)
class Increment:
    """A next state given as an increment: ``x[k+1] = x[k] + delta``.

    Return ``Increment(delta)`` instead of ``x + delta`` in ``next_states`` when the
    increment is cheaper to form than the full block (for instance ``delta`` of shape
    ``(1, m)`` when it does not depend on the state): the solver then adds it inside its
    kernel and never materialises the ``(states x inputs)`` next-state array.
    """

    delta: Any


@dataclass(frozen=True)
class Separable:
    """Compact model outputs of a block in which each state moves on its own.

    Next state ``j`` depends on state ``j`` and the inputs only, the stage cost and the
    infeasibility mask on the inputs only (e.g. ``x_j' = a_j x_j + b_j(u)`` with a cost in
    ``u``): the ``(S, M)`` block is then fully described by one ``(n_j, M)`` table per state,
    ``S = n_1 ... n_d`` times smaller than the flattened block, and the Bellman kernel
    interpolates from per-state tables instead of streaming the block from memory.
    """

    x: tuple[FloatArray, ...]  # (n_j, M) next state of component j at node i_j of state j
    g: FloatArray  # (M,) stage cost
    mask: BoolArray | None  # (M,) infeasibility mask


class Block:
    """Model outputs for one step, flattened to ``(S, M)``.

    The next state of component ``j`` is ``base[j][:, None] + xn[j]`` (``base`` is zero
    unless the model returned an :class:`Increment`). The flattened arrays are built on first
    access when the block was made with ``build`` (its :class:`Separable` tables, ``sep``,
    are what the Bellman kernel then reads).
    """

    def __init__(
        self,
        shape: tuple[int, ...],
        states: tuple[np.ndarray, ...],
        inputs: tuple[np.ndarray, ...],
        parts: tuple[list[FloatArray], list[FloatArray], FloatArray, BoolArray | None] | None = None,
        build: Callable[[], tuple[list[FloatArray], list[FloatArray], FloatArray, BoolArray | None]]
        | None = None,
        sep: Separable | None = None,
    ) -> None:
        if (parts is None) == (build is None):
            raise ValueError("Block needs exactly one of parts and build")
        self.shape = shape
        self.states = states
        self.inputs = inputs
        self.sep = sep
        self._parts = parts
        self._build = build

    def _get(self) -> tuple[list[FloatArray], list[FloatArray], FloatArray, BoolArray | None]:
        if self._parts is None:
            assert self._build is not None
            self._parts = self._build()
            self._build = None
        return self._parts

    @property
    def xn(self) -> list[FloatArray]:
        """Next state (increment when ``base`` is not zero) per component, (S, M) each."""
        return self._get()[0]

    @property
    def base(self) -> list[FloatArray]:
        """State the increment ``xn`` is added to, (S,) per component."""
        return self._get()[1]

    @property
    def g(self) -> FloatArray:
        """Stage cost, (S, M)."""
        return self._get()[2]

    @property
    def mask(self) -> BoolArray | None:
        """Infeasibility mask, (S, M), or None."""
        return self._get()[3]

    def with_cost(self, g: FloatArray) -> Block:
        """The same block with the stage cost ``g`` (S, M)."""
        return Block(self.shape, self.states, self.inputs, parts=(self.xn, self.base, g, self.mask))

    def next_state(self, j: int) -> FloatArray:
        """Materialised next state of component ``j``, shape (S, M)."""
        return self.base[j][:, None] + self.xn[j]


class Evaluator:
    """Calls the user model and checks what it returns."""

    def __init__(self, problem: DPProblem) -> None:
        self.problem = problem
        self.space = problem.space

    def data_at(self, k: int) -> Any:
        p = self.problem
        if self.space.data_arrays is not None:
            return {key: arr[k] for key, arr in self.space.data_arrays.items()}
        if p.data is not None and callable(p.data):
            return p.data(k)
        return {}

    def pre_at(self, k: int, data_k: Any, inputs: tuple[np.ndarray, ...] | None = None) -> Any:
        if self.problem.precompute is None:
            return None
        return self.problem.precompute(self.space.inputs_b if inputs is None else inputs, k, data_k)

    def __call__(
        self,
        states: tuple[np.ndarray, ...],
        k: int,
        data_k: Any,
        pre: Any,
        inputs: tuple[np.ndarray, ...] | None = None,
    ) -> Block:
        sp = self.space
        d = sp.d
        ins = sp.inputs_b if inputs is None else inputs
        shape = tuple(np.broadcast_shapes(*(a.shape for a in states), *(a.shape for a in ins)))
        S = int(np.prod(shape[:d]))
        M = int(np.prod(shape[d:]))
        if self.problem.precompute is None:
            out = self.problem.model(states, ins, k, data_k)
        else:
            out = self.problem.model(states, ins, k, data_k, pre)
        if not isinstance(out, (tuple, list)) or len(out) != 3:
            raise DPModelError(
                f"model at step {k} returned {type(out).__name__}; expected a tuple "
                "(next_states, stage_cost, infeasible_mask)."
            )
        nxt, cost, mask = out
        if d == 1 and not isinstance(nxt, (tuple, list)):
            nxt = (nxt,)
        if not isinstance(nxt, (tuple, list)) or len(nxt) != d:
            got = f"{len(nxt)} entries" if isinstance(nxt, (tuple, list)) else type(nxt).__name__
            raise DPModelError(
                f"model output next_states at step {k} is {got}; expected a tuple or list of "
                f"{d} arrays (one per state variable)."
            )

        def check(a: Any, name: str, dtype: type) -> np.ndarray:
            arr: np.ndarray = np.asarray(a, dtype=dtype)
            if not _broadcasts_to(arr.shape, shape):
                raise DPModelError(
                    f"model output {name} at step {k} has shape {arr.shape}, which does not "
                    f"broadcast to the block shape {shape} (states {shape[:d]} x inputs "
                    f"{shape[d:]}); expected an array broadcastable to {shape}."
                )
            return arr

        def flat(arr: np.ndarray) -> np.ndarray:
            return np.broadcast_to(arr, shape).reshape(S, M)

        incr = [isinstance(a, Increment) for a in nxt]
        xraw = [
            check(a.delta, f"next_states[{j}] (Increment)", np.float64)
            if incr[j]
            else check(a, f"next_states[{j}]", np.float64)
            for j, a in enumerate(nxt)
        ]
        graw = check(cost, "stage_cost", np.float64)
        mraw = None if mask is None else check(mask, "infeasible_mask", np.bool_)

        def build() -> tuple[list[FloatArray], list[FloatArray], FloatArray, BoolArray | None]:
            base = []
            for j in range(d):
                if incr[j]:
                    sj = np.broadcast_to(np.asarray(states[j], dtype=np.float64), shape[:d] + (1,) * sp.q)
                    base.append(np.ascontiguousarray(sj.reshape(S)))
                else:
                    base.append(np.zeros(S))
            return [flat(x) for x in xraw], base, flat(graw), None if mraw is None else flat(mraw)

        sep = None
        if d >= 2 and states is sp.states_b and inputs is None:
            sep = _separable(sp, shape, xraw, incr, graw, mraw)
        if sep is None:
            return Block(shape, states, ins, parts=build())
        return Block(shape, states, ins, build=build, sep=sep)

    def bad_output_error(self, k: int, blk: Block, s: int) -> DPModelError:
        """Describe the first NaN / infinite output of an unmasked pair in row ``s``."""
        sp = self.space
        d = sp.d
        unmasked = np.ones(blk.g.shape[1], dtype=bool) if blk.mask is None else ~blk.mask[s]
        problems: list[tuple[str, int, str]] = []
        g = blk.g[s]
        for m in np.flatnonzero(unmasked & (np.isnan(g) | (g == -np.inf)))[:1]:
            problems.append(("stage_cost", int(m), "NaN" if np.isnan(g[m]) else "-inf"))
        for j in range(d):
            row = blk.base[j][s] + blk.xn[j][s]
            for m in np.flatnonzero(unmasked & ~np.isfinite(row))[:1]:
                problems.append((f"next_states[{j}]", int(m), repr(float(row[m]))))
        if not problems:  # pragma: no cover - kernel and this check agree
            return DPModelError(f"model output at step {k} contains NaN or infinite values.")
        name, m, what = problems[0]
        idx = np.unravel_index(s * blk.g.shape[1] + m, blk.shape)
        svals = ", ".join(
            f"{sp.state_names[j]}={float(np.broadcast_to(blk.states[j], blk.shape)[idx]):.6g}"
            for j in range(d)
        )
        uvals = ", ".join(
            f"{sp.input_names[j]}={float(np.broadcast_to(blk.inputs[j], blk.shape)[idx]):.6g}"
            for j in range(sp.q)
        )
        return DPModelError(
            f"model output {name} at step {k} is {what} at block index {tuple(int(i) for i in idx)} "
            f"of shape {blk.shape} ({svals}; {uvals}) where infeasible_mask is False; expected "
            "a finite value there, or infeasible_mask=True for that state/input pair."
        )

    def terminal(
        self,
        states: tuple[np.ndarray, ...],
        shape: tuple[int, ...],
        ignore: BoolArray | None = None,
    ) -> FloatArray:
        """Terminal cost on ``states`` broadcast to ``shape`` (zeros when not given).

        Where ``ignore`` is True (next states outside the grid, masked pairs) NaN is
        replaced by +inf instead of being reported.
        """
        tc = self.problem.terminal_cost
        if tc is None:
            return np.zeros(shape)
        arr = np.asarray(tc(states), dtype=np.float64)
        if not _broadcasts_to(arr.shape, shape):
            raise DPModelError(
                f"terminal_cost returned shape {arr.shape}; expected an array broadcastable "
                f"to the state shape {shape}."
            )
        out = np.array(np.broadcast_to(arr, shape))
        if ignore is not None:
            out[ignore & np.isnan(out)] = np.inf
        if np.isnan(out).any() or (out == -np.inf).any():
            raise DPModelError("terminal_cost returned NaN or -inf; expected finite values or +inf.")
        return out


def _separable(
    sp: Space,
    shape: tuple[int, ...],
    xraw: list[np.ndarray],
    incr: list[bool],
    graw: np.ndarray,
    mraw: np.ndarray | None,
) -> Separable | None:
    """The :class:`Separable` tables of a block on the state grid, or None when next state
    ``j`` depends on another state or the cost or mask on a state (read from the broadcast
    shapes of the model outputs, so only what the model wrote matters, not its values)."""
    d = sp.d
    nd = len(shape)

    def state_dims(a: np.ndarray) -> set[int]:
        full = (1,) * (nd - a.ndim) + a.shape
        return {i for i in range(d) if full[i] != 1}

    if state_dims(graw) or (mraw is not None and state_dims(mraw)):
        return None
    if any(state_dims(x) - {j} for j, x in enumerate(xraw)):
        return None
    M = int(np.prod(shape[d:]))
    tabs = []
    for j, x in enumerate(xraw):
        tshape = tuple(shape[i] if i == j else 1 for i in range(d)) + shape[d:]
        tab = np.broadcast_to(x, tshape).reshape(shape[j], M)
        if incr[j]:  # the same sum as Block.next_state: base + increment
            tab = sp.grids[j][:, None] + tab
        tabs.append(np.ascontiguousarray(tab, dtype=np.float64))
    ishape = (1,) * d + shape[d:]
    g = np.ascontiguousarray(np.broadcast_to(graw, ishape).reshape(M))
    m = None if mraw is None else np.ascontiguousarray(np.broadcast_to(mraw, ishape).reshape(M))
    return Separable(x=tuple(tabs), g=g, mask=m)


def _broadcasts_to(arr_shape: tuple[int, ...], shape: tuple[int, ...]) -> bool:
    """True when an array of ``arr_shape`` broadcasts to exactly ``shape``."""
    try:
        return np.broadcast_shapes(arr_shape, shape) == shape
    except ValueError:
        return False

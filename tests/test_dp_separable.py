"""Separable blocks (``_problem.Separable``): each state moves on its own and the stage cost
and mask depend on the inputs only, so the Bellman kernel interpolates from per-state tables
instead of the flattened (states x inputs) block (issue 15 item 6: the two-tank benchmark).

The reference is the generic kernel on the flattened block (``USE_SEPARABLE = False``): the
separable kernels do the same floating-point operations per pair in the same input order,
so cost-to-go, level set, policy and trajectory must be equal bit for bit, in every mode and
with masks, increments, infinite nodes and three states.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from hevsim.errors import DPModelError
from hevsim.optimal import DPProblem, FinalTarget, Increment, _solver, solve_dp
from hevsim.optimal._problem import Evaluator

DT = 0.01  # [s]
A = 1.0 - 0.5 * DT


def tanks(
    n_x: int,
    n_steps: int = 60,
    *,
    d: int = 2,
    increment: bool = False,
    masked: bool = False,
    target: float = 0.2,
    dt: float = DT,
    irregular: bool = False,
) -> DPProblem:
    """Two (or three) tanks of Elbert et al. (2013), shorter horizon: ``x_i' = a x_i +
    dt v_i(u)``, cost ``dt (u1 + 0.1 |u2 - 0.5|)``, optionally an input-only mask."""
    u = np.linspace(0.0, 1.0, 11)

    def model(states: tuple, inputs: tuple, k: int, data: Any) -> tuple:
        u1, u2 = inputs
        flows = [u1 * u2, u1 * (1.0 - u2), 0.5 * u1]
        nxt = []
        for j in range(d):
            x = states[j]
            nxt.append(
                Increment(dt * (-0.5 * x + flows[j])) if increment else (1.0 - 0.5 * dt) * x + dt * flows[j]
            )
        mask = (u1 > 0.85) & (u2 < 0.15) if masked else None
        return tuple(nxt), dt * (u1 + 0.1 * np.abs(u2 - 0.5)), mask

    grid = np.linspace(0.0, 1.0, n_x) ** (1.3 if irregular else 1.0)
    return DPProblem(model, [grid] * d, [u, u], n_steps, target=FinalTarget([target] * d, None))


def solve_both(problem: DPProblem, monkeypatch: pytest.MonkeyPatch, **kw: Any) -> tuple[Any, Any, int]:
    """Solve with the generic kernel and with the separable one; count separable steps."""
    calls = {"n": 0}
    original: Callable[..., Any] = _solver.DPSolver._sep_step

    def counting(self: Any, *args: Any) -> None:
        calls["n"] += 1
        original(self, *args)

    monkeypatch.setattr(_solver.DPSolver, "_sep_step", counting)
    monkeypatch.setattr(_solver, "USE_SEPARABLE", False)
    ref = solve_dp(problem, [0.0] * problem.space.d, store_cost_to_go=True, store_policy=True, **kw)
    assert calls["n"] == 0
    monkeypatch.setattr(_solver, "USE_SEPARABLE", True)
    new = solve_dp(problem, [0.0] * problem.space.d, store_cost_to_go=True, store_policy=True, **kw)
    return ref, new, calls["n"]


def assert_same(ref: Any, new: Any) -> None:
    np.testing.assert_array_equal(new.cost_to_go, ref.cost_to_go)
    if ref.level_set is not None:
        np.testing.assert_array_equal(new.level_set, ref.level_set)
    np.testing.assert_array_equal(new.policy_index, ref.policy_index)
    np.testing.assert_array_equal(new.states, ref.states)
    np.testing.assert_array_equal(new.inputs, ref.inputs)
    assert new.total_cost == ref.total_cost


@pytest.mark.parametrize(
    ("increment", "masked", "irregular"),
    [(False, False, False), (True, False, False), (False, True, False), (False, False, True)],
    ids=["full", "increment", "mask", "irregular-grid"],
)
def test_two_tank_separable_equals_flattened(
    monkeypatch: pytest.MonkeyPatch, increment: bool, masked: bool, irregular: bool
) -> None:
    """Level set, 2 states (the fast two-state kernel): identical to the generic kernel."""
    problem = tanks(26, increment=increment, masked=masked, irregular=irregular)
    assert not irregular or not problem.space.uniform.any()
    ref, new, n_sep = solve_both(problem, monkeypatch)
    assert n_sep >= 59  # every step but the last (the target box is checked exactly there)
    assert_same(ref, new)
    assert np.all(new.states[-1] >= 0.2 - 1e-9)


@pytest.mark.parametrize("method", ["wall", "penalty"])
def test_plain_modes_with_infinite_nodes(monkeypatch: pytest.MonkeyPatch, method: str) -> None:
    """Wall (infinite nodes: the exact table kernel) and penalty (plain cost-to-go)."""
    kw: dict[str, Any] = {"final_constraint": method}
    if method == "penalty":
        kw["penalty_weight"] = 5.0
    ref, new, n_sep = solve_both(tanks(41, 20, target=0.3, dt=0.2), monkeypatch, **kw)
    assert n_sep >= 19
    assert_same(ref, new)


def test_three_states(monkeypatch: pytest.MonkeyPatch) -> None:
    """Three states: the generic table kernel (any number of states)."""
    ref, new, n_sep = solve_both(tanks(11, 10, d=3, target=0.2, masked=True, dt=0.2), monkeypatch)
    assert n_sep >= 9
    assert_same(ref, new)


def _sep_of(model: Callable[..., Any], d: int = 2) -> Any:
    grid = np.linspace(0.0, 1.0, 5)
    p = DPProblem(model, [grid] * d, [np.linspace(0.0, 1.0, 3)], 2)
    sp = p.space
    return Evaluator(p)(sp.states_b, 0, {}, None).sep


def test_coupled_models_are_not_separable() -> None:
    """A next state that reads another state, or a cost or mask that reads a state, keeps
    the flattened block; an uncoupled one gets tables of shape (n_j, M)."""

    def coupled(s: tuple, u: tuple, k: int, data: Any) -> tuple:
        return (s[0] + 0.1 * s[1] * u[0], s[1]), u[0], None

    def state_cost(s: tuple, u: tuple, k: int, data: Any) -> tuple:
        return (s[0] + 0.1 * u[0], s[1]), u[0] + s[1], None

    def state_mask(s: tuple, u: tuple, k: int, data: Any) -> tuple:
        return (s[0] + 0.1 * u[0], s[1]), u[0], s[0] > 0.9

    def uncoupled(s: tuple, u: tuple, k: int, data: Any) -> tuple:
        return (s[0] + 0.1 * u[0], 0.5 + 0.0 * u[0]), u[0], u[0] > 2.0

    assert _sep_of(coupled) is None
    assert _sep_of(state_cost) is None
    assert _sep_of(state_mask) is None
    sep = _sep_of(uncoupled)
    assert sep is not None
    assert [x.shape for x in sep.x] == [(5, 3), (5, 3)]
    np.testing.assert_array_equal(sep.x[1], 0.5)
    assert sep.g.shape == (3,) and sep.mask is not None and sep.mask.shape == (3,)


def test_nan_output_reported_the_same(monkeypatch: pytest.MonkeyPatch) -> None:
    """A NaN next state where the mask is False is refused with the same message."""

    def model(s: tuple, u: tuple, k: int, data: Any) -> tuple:
        x1 = A * s[0] + DT * u[0]
        x1 = np.where((s[0] > 0.7) & (u[0] > 0.5), np.nan, x1)
        return (x1, A * s[1] + DT * u[0]), DT * u[0], None

    grid = np.linspace(0.0, 1.0, 11)
    p = DPProblem(model, [grid, grid], [np.linspace(0.0, 1.0, 5)], 5)
    msgs = []
    for use in (False, True):
        monkeypatch.setattr(_solver, "USE_SEPARABLE", use)
        with pytest.raises(DPModelError) as err:
            solve_dp(p, [0.0, 0.0])
        msgs.append(str(err.value))
    assert msgs[0] == msgs[1]
    assert "next_states[0]" in msgs[0]

"""The solver's convex-hull input pruning (``hevsim.optimal._hull``) is exact.

Random one-state problems whose increments, costs and masks do not depend on the state
(the structure of HEV problems with a SOC-independent battery) are solved with and without
the pruning; cost-to-go, policy, trajectory and boundary lines must agree.
"""

from __future__ import annotations

import numpy as np
import pytest

import hevsim.optimal._solver as dp_solver
from hevsim.optimal import DPProblem, FinalTarget, Increment, solve_dp
from hevsim.optimal._hull import hull_inputs


def _problem(seed: int) -> DPProblem:
    rng = np.random.default_rng(seed)
    n_steps, m = 60, 700
    d = rng.normal(0.0, 0.01, (n_steps, m))
    cost = rng.uniform(0.2, 1.5, (n_steps, m)) + 30.0 * np.maximum(d, 0.0)  # charging costs fuel
    mask = rng.uniform(size=(n_steps, m)) < 0.3
    cost[rng.uniform(size=(n_steps, m)) < 0.05] = np.inf
    d[:, :5] = d[:, :5].round(3)  # some increments exactly on grid lines (fraction 0)
    mask[:, 0] = False
    cost[:, 0] = 0.1  # idle: no change, small cost
    d[:, 0] = 0.0

    def model(states, inputs, k, data):  # type: ignore[no-untyped-def]
        return (Increment(d[k][None]),), cost[k][None], mask[k][None]

    return DPProblem(
        model,
        [np.linspace(0.3, 0.8, 201)],
        [np.arange(float(m))],
        n_steps,
        target=FinalTarget(0.55, 0.6),
        discrete_inputs=[0],
    )


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("method", ["boundary_line", "wall", "penalty"])
def test_hull_matches_generic_kernel(seed: int, method: str, monkeypatch: pytest.MonkeyPatch) -> None:
    kw = {"final_constraint": method, "store_cost_to_go": True, "store_policy": True}
    if method == "penalty":
        kw["penalty_weight"] = 1e3
    fast = solve_dp(_problem(seed), [0.5], **kw)  # type: ignore[arg-type]
    monkeypatch.setattr(dp_solver, "USE_HULL", False)
    slow = solve_dp(_problem(seed), [0.5], **kw)  # type: ignore[arg-type]
    assert fast.cost_to_go is not None and slow.cost_to_go is not None
    assert np.array_equal(np.isinf(fast.cost_to_go), np.isinf(slow.cost_to_go))
    fin = np.isfinite(slow.cost_to_go)
    assert np.allclose(fast.cost_to_go[fin], slow.cost_to_go[fin], rtol=1e-13, atol=1e-13)
    assert fast.total_cost == pytest.approx(slow.total_cost, rel=1e-13)
    assert np.allclose(fast.states, slow.states, rtol=0, atol=1e-13)
    if fast.boundary_lines is not None and slow.boundary_lines is not None:
        assert np.allclose(fast.boundary_lines, slow.boundary_lines, equal_nan=True)


def test_hull_keeps_extremes_and_drops_dominated_inputs() -> None:
    inv_dx = 100.0  # grid spacing 0.01
    d = np.array([0.001, 0.005, 0.009, 0.003, 0.0051, 0.015, -0.02])
    g = np.array([1.0, 3.0, 1.0, 5.0, 2.0, 1.0, 0.5])
    mask = np.zeros(d.size, dtype=bool)
    mask[4] = True  # would be the best in its group, but it is masked
    idx, dmin, dmax, n_valid, bad = hull_inputs(d, g, mask, True, inv_dx)
    assert not bad and n_valid == 6
    assert dmin == -0.02 and dmax == 0.015
    # group offset 0: (0.1, 1), (0.3, 5), (0.5, 3), (0.9, 1): hull (0.1, 1) - (0.9, 1)
    assert sorted(idx.tolist()) == [0, 2, 5, 6]
    g_nan = g.copy()
    g_nan[1] = np.nan
    assert hull_inputs(d, g_nan, mask, True, inv_dx)[4]  # NaN cost of an unmasked input: bad

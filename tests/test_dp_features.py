"""Interpolation rules, grids, discrete inputs, policy interpolation, progress, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from hevsim.optimal import DPProblem, FinalTarget, solve_dp


def bilinear(x):  # type: ignore[no-untyped-def]
    """A multilinear function of up to four states: multilinear interpolation is exact."""
    out = 3.0 + 0.0 * x[0]
    coef = [2.0, -1.0, 0.5, 0.25]
    for j, xj in enumerate(x):
        out = out + coef[j] * xj
    if len(x) > 1:
        out = out + 0.5 * x[0] * x[1]
    if len(x) > 2:
        out = out - 0.3 * x[0] * x[1] * x[2]
    return out


@pytest.mark.parametrize("d", [1, 2, 3, 4])
def test_multilinear_interpolation_is_exact_for_multilinear_costs(d: int) -> None:
    """J_0(node) = phi(node + shift): the interpolated terminal cost at off-grid points equals
    the multilinear function exactly, on irregular grids (bisection) and regular ones."""
    rng = np.random.default_rng(d)
    shift = np.array([0.37, -0.21, 0.13, 0.05])[:d]
    grids = []
    for j in range(d):
        n = 7 - j
        if j % 2 == 0:
            g = np.sort(np.r_[-1.0, 2.0, rng.uniform(-1.0, 2.0, n - 2)])  # irregular
        else:
            g = np.linspace(-1.0, 2.0, n)  # regular
        grids.append(g)

    def model(states, inputs, k, data):  # type: ignore[no-untyped-def]
        return tuple(s + shift[j] + 0.0 * inputs[0] for j, s in enumerate(states)), 0.0 * inputs[0], None

    p = DPProblem(model, grids, [[0.0]], 1, terminal_cost=bilinear)
    x0 = np.array([0.5, 0.4, 0.3, 0.2])[:d]
    res = solve_dp(p, x0, final_constraint="wall", store_cost_to_go=True)
    mesh = np.meshgrid(*grids, indexing="ij")
    shifted = [m + shift[j] for j, m in enumerate(mesh)]
    inside = np.ones(mesh[0].shape, dtype=bool)
    for j, m in enumerate(shifted):
        inside &= (m >= grids[j][0]) & (m <= grids[j][-1])
    assert res.cost_to_go is not None
    np.testing.assert_allclose(res.cost_to_go[0][inside], bilinear(shifted)[inside], rtol=0, atol=1e-12)
    assert np.all(np.isinf(res.cost_to_go[0][~inside]))  # leaves the grid: state bounds
    assert res.total_cost == pytest.approx(float(bilinear(list(x0 + shift))), abs=1e-12)
    # costate of a multilinear cost-to-go: exact partial derivatives at the final state
    assert np.all(np.isfinite(res.costate[-1]))


def test_infinite_nodes_touched_only_with_positive_weight() -> None:
    """Wall on grid {0,1,2,3} with target x_2 >= 2 and steps u in {0, 0.5, 1}: from x0 = 0
    only u = 1, 1 works. x = 0.5 touches the infeasible node 0 (infeasible); x = 1 lies on
    the feasible node 1 and must not be spoiled by its infinite neighbour."""

    def model(states, inputs, k, data):  # type: ignore[no-untyped-def]
        return (states[0] + inputs[0],), inputs[0], None

    p = DPProblem(model, [[0.0, 1.0, 2.0, 3.0]], [[0.0, 0.5, 1.0]], 2, target=FinalTarget(2.0, None))
    res = solve_dp(p, [0.0], final_constraint="wall", store_cost_to_go=True)
    assert res.cost_to_go is not None
    np.testing.assert_array_equal(res.cost_to_go[1], [np.inf, 1.0, 0.0, 0.0])
    np.testing.assert_array_equal(res.inputs[:, 0], [1.0, 1.0])
    assert res.total_cost == 2.0
    for method in ("levelset", "boundary_line"):
        res2 = solve_dp(p, [0.0], final_constraint=method)
        assert res2.total_cost == 2.0 and res2.states[-1, 0] == 2.0


def _gear_problem(n: int) -> DPProblem:
    """Travel at 2 m/s per step; pick a gear (unsorted discrete set) and a throttle; the fuel
    favours the middle gear and low throttle; state: energy in a buffer that must end >= 1."""
    ratios = [3.78, 1.36, 2.12]

    def model(states, inputs, k, data):  # type: ignore[no-untyped-def]
        (e,), (thr, ratio) = states, inputs
        eff = 1.0 - 0.1 * (ratio - 2.12) ** 2
        nxt = e + 0.2 * thr * eff - 0.05
        return (nxt,), thr**2 + 0.1 * thr, None

    return DPProblem(
        model,
        [np.linspace(0.0, 2.0, n)],
        [np.linspace(0.0, 1.0, 11), ratios],
        10,
        target=FinalTarget(1.0, None),
        discrete_inputs=[1],
        input_names=["throttle", "gear_ratio"],
    )


@pytest.mark.parametrize("forward", ["reoptimize", "policy"])
def test_discrete_inputs_and_policy_interpolation(forward: str) -> None:
    res = solve_dp(_gear_problem(81), [0.5], forward=forward)
    assert set(np.unique(res.inputs[:, 1])) <= {3.78, 1.36, 2.12}
    assert np.all(res.inputs[res.inputs[:, 0] > 0, 1] == 2.12)  # best efficiency when used
    assert res.states[-1, 0] >= 1.0 - 1e-12
    ref = solve_dp(_gear_problem(81), [0.5])
    assert res.total_cost == pytest.approx(ref.total_cost, rel=0.05)
    if forward == "policy":
        # policy interpolation produces throttles between grid values
        assert res.forward == "policy"


def test_irregular_grid_agrees_with_regular_grid() -> None:
    rng = np.random.default_rng(1)
    g = np.linspace(0.0, 2.0, 81)
    g_irr = np.sort(np.r_[0.0, 2.0, g[1:-1] + rng.uniform(-0.008, 0.008, 79)])
    p = _gear_problem(81)
    p_irr = DPProblem(p.model, [g_irr], p.input_grids, p.n_steps, target=p.target, discrete_inputs=[1])
    a = solve_dp(p, [0.5])
    b = solve_dp(p_irr, [0.5])
    assert not p_irr.space.uniform[0] and p.space.uniform[0]
    assert b.total_cost == pytest.approx(a.total_cost, rel=0.02)


def test_deterministic() -> None:
    a = solve_dp(_gear_problem(81), [0.5], store_cost_to_go=True)
    b = solve_dp(_gear_problem(81), [0.5], store_cost_to_go=True)
    assert a.total_cost == b.total_cost
    np.testing.assert_array_equal(a.states, b.states)
    assert a.cost_to_go is not None and b.cost_to_go is not None
    np.testing.assert_array_equal(a.cost_to_go, b.cost_to_go)


def test_progress_bar_only_on_request(capsys: pytest.CaptureFixture[str]) -> None:
    solve_dp(_gear_problem(41), [0.5])  # stderr is not a terminal under pytest: quiet
    assert capsys.readouterr().err == ""
    solve_dp(_gear_problem(41), [0.5], progress=False)
    assert capsys.readouterr().err == ""
    solve_dp(_gear_problem(41), [0.5], progress=True)
    assert "DP" in capsys.readouterr().err

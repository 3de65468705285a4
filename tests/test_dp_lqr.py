"""DP on a double integrator with quadratic cost against the finite-horizon discrete LQR.

``x = (p, v)`` [m, m/s], ``x[k+1] = A x[k] + B u[k]`` with the exact zero-order-hold
matrices ``A = [[1, dt], [0, 1]]``, ``B = [[dt^2/2], [dt]]``, stage cost
``dt (p^2 + v^2 + r u^2)`` and terminal cost ``p^2 + v^2``. Without constraints the optimum is
``J* = x0' P0 x0`` from the backward Riccati recursion
``K = (R + B'PB)^-1 B'PA``, ``P <- Q + A'PA - A'PB K`` started at ``P_N = Qf``.
The DP grids are wide enough for the optimal trajectory and inputs, so the only difference
is the state and input discretisation: the error must shrink with refinement.
"""

from __future__ import annotations

import itertools

import numpy as np

from hevsim.optimal import DPProblem, solve_dp

DT = 0.1  # [s]
N = 20
R_U = 0.1
A = np.array([[1.0, DT], [0.0, 1.0]])
B = np.array([[DT**2 / 2], [DT]])
Q = np.eye(2) * DT
R = np.array([[R_U * DT]])
QF = np.eye(2)
X0 = np.array([1.0, 0.0])


def lqr_cost() -> tuple[float, np.ndarray]:
    P = QF.copy()
    gains = []
    for _ in range(N):
        K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
        P = Q + A.T @ P @ A - A.T @ P @ B @ K
        gains.append(K)
    # optimal input sequence from X0 (for the grid-size sanity check)
    x = X0.copy()
    us = []
    for K in reversed(gains):
        u = -(K @ x)
        us.append(float(u[0]))
        x = A @ x + B @ u
    return float(X0 @ P @ X0), np.array(us)


J_STAR, U_STAR = lqr_cost()


def model(states, inputs, k, data):  # type: ignore[no-untyped-def]
    p, v = states
    (a,) = inputs
    return (p + DT * v + 0.5 * DT**2 * a, v + DT * a), DT * (p**2 + v**2 + R_U * a**2), None


def terminal(states):  # type: ignore[no-untyped-def]
    p, v = states
    return p**2 + v**2


def problem(n_x: int, n_u: int) -> DPProblem:
    g = np.linspace(-2.0, 2.0, n_x)
    return DPProblem(model, [g, g], [np.linspace(-4.0, 4.0, n_u)], N, terminal_cost=terminal)


def test_dp_matches_lqr_and_converges() -> None:
    assert np.abs(U_STAR).max() < 4.0  # the input grid covers the LQR inputs
    errors = []
    for n in (11, 21, 41, 81):
        res = solve_dp(problem(n, n), X0)
        errors.append(res.total_cost - J_STAR)
        # the reported cost is the cost of the reported trajectory
        p, v = res.states[:-1].T
        stage = DT * (p**2 + v**2 + R_U * res.inputs[:, 0] ** 2)
        np.testing.assert_allclose(res.stage_costs, stage, rtol=1e-12)
        assert res.terminal_cost == np.sum(res.states[-1] ** 2)
    # the DP uses a subset of the LQR's inputs: never better than the optimum
    assert min(errors) > -1e-12, errors
    assert all(b < a for a, b in itertools.pairwise(errors)), errors
    assert errors[-1] < 2e-3 * J_STAR, errors


def test_costate_matches_riccati_gradient() -> None:
    """The DP costate at k = 0 approximates dJ/dx = 2 P0 x0 (grid-size finite difference)."""
    P = QF.copy()
    for _ in range(N):
        K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
        P = Q + A.T @ P @ A - A.T @ P @ B @ K
    res = solve_dp(problem(81, 81), X0, final_constraint="wall")
    np.testing.assert_allclose(res.costate[0], 2 * P @ X0, atol=0.05 * np.abs(2 * P @ X0).max())

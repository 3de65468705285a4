"""Two-tank filling problem with the known continuous optimum 2 ln 2.

Problem. Two identical leaky tanks, levels ``x1, x2`` [-] in ``[0, 1]``, each filled through
its own valve ``u_i`` in ``[0, 1]`` (inflow per unit time) and draining in proportion to its
level: ``dx_i/dt = -x_i + u_i``. Starting empty, ``x_i(0) = 0``, both tanks must hold at
least half a unit at the final time ``T = 1``: ``x_i(T) >= 1/2``. The cost is the water
used, ``J = int_0^T (u1 + u2) dt``.

Continuous optimum (derivation). The problem is a linear program in ``u`` (the state is
linear in ``u``, the cost and the constraints are linear), so Pontryagin's conditions are
sufficient. With ``H = u1 + u2 + p1 (-x1 + u1) + p2 (-x2 + u2)``, the costates satisfy
``dp_i/dt = -dH/dx_i = p_i``, so ``p_i(t) = -nu_i exp(t - T)`` with ``nu_i >= 0`` the
multiplier of the active final constraint. ``H`` is minimised by ``u_i = 1`` when
``1 + p_i(t) < 0`` and ``u_i = 0`` otherwise; ``1 + p_i`` decreases in time, so each valve
is closed and then fully open during a final interval of length ``tau``. From ``x_i = 0``,
``x_i(T) = 1 - exp(-tau) = 1/2`` gives ``tau = ln 2`` (feasible because ``T >= ln 2``) and a
cost of ``ln 2`` per tank: ``J* = 2 ln 2``.

Discrete-time optimum. With the explicit Euler step ``x[k+1] = (1 - dt) x[k] + dt u[k]`` and
cost ``sum dt (u1 + u2)``, an input ``u[k]`` raises ``x[N]`` by ``dt (1 - dt)^(N-1-k)``,
which grows with ``k``: the LP is solved greedily from the end, ``u = 1`` on the last ``n``
steps (largest ``n`` with ``1 - (1-dt)^n <= 1/2``) and one fractional input ``f`` before
them, ``J_dt = 2 dt (n + f)``. Expanding, ``J_dt = 2 ln 2 (1 - dt/2 + O(dt^2))``.
The DP input grid includes ``f``, so the discrete optimum is representable exactly.

The two-tank DP runs on a 2-D state grid (bilinear interpolation of the cost-to-go and of
the level-set function); the problem is separable, so its optimum is twice that of one tank.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from hevsim.optimal import DPProblem, FinalTarget, solve_dp

LN2 = float(np.log(2.0))
T_FINAL = 1.0  # [s]
TARGET = 0.5


def discrete_optimum(dt: float) -> tuple[float, float]:
    """Optimal cost of the Euler-discretised two-tank problem, and the fractional input."""
    a = 1.0 - dt
    n = int(np.floor(np.log(1.0 - TARGET) / np.log(a)))
    assert n < round(T_FINAL / dt)
    f = (TARGET - (1.0 - a**n)) / (dt * a**n)
    assert 0.0 <= f < 1.0
    return 2.0 * dt * (n + f), f


def two_tank(n_x: int, dt: float, n_u: int = 11) -> DPProblem:
    _, f = discrete_optimum(dt)
    u = np.union1d(np.linspace(0.0, 1.0, n_u), [f])

    def model(states, inputs, k, data):  # type: ignore[no-untyped-def]
        x1, x2 = states
        u1, u2 = inputs
        nxt = ((1.0 - dt) * x1 + dt * u1, (1.0 - dt) * x2 + dt * u2)
        return nxt, (u1 + u2) * dt, None

    grid = np.linspace(0.0, 1.0, n_x)
    return DPProblem(
        model,
        [grid, grid],
        [u, u],
        round(T_FINAL / dt),
        target=FinalTarget([TARGET, TARGET], None),
        state_names=["x1", "x2"],
        input_names=["u1", "u2"],
    )


def one_tank(n_x: int, dt: float) -> DPProblem:
    _, f = discrete_optimum(dt)

    def model(states, inputs, k, data):  # type: ignore[no-untyped-def]
        return ((1.0 - dt) * states[0] + dt * inputs[0],), inputs[0] * dt, None

    u = np.union1d(np.linspace(0.0, 1.0, 11), [f])
    return DPProblem(
        model,
        [np.linspace(0.0, 1.0, n_x)],
        [u],
        round(T_FINAL / dt),
        target=FinalTarget(TARGET, None),
    )


def test_two_state_dp_converges_to_discrete_optimum() -> None:
    """(a) 2-D level-set DP: the error to the discrete optimum shrinks at each of three
    grid refinements (nested grids), the target is met, and the DP never beats the optimum."""
    dt = 0.05
    j_disc, _ = discrete_optimum(dt)
    errors = []
    for n_x in (11, 21, 41, 81):
        res = solve_dp(two_tank(n_x, dt), [0.0, 0.0])
        assert res.final_constraint == "levelset"
        assert np.all(res.states[-1] >= TARGET - 1e-12)
        errors.append(res.total_cost - j_disc)
    assert min(errors) > -1e-12, errors
    assert all(b < a for a, b in itertools.pairwise(errors)), errors
    assert errors[-1] < 0.02 * j_disc, errors


def test_discrete_optimum_tends_to_two_ln_two() -> None:
    """(b) |J_dt - 2 ln 2| <= 1.1 ln 2 dt (first order, stated tolerance), halving with dt;
    the DP (one tank, times two by separability) reproduces J_dt to 1e-9 at each dt."""
    dts = [0.1, 0.05, 0.025, 0.0125]
    errs = []
    for dt in dts:
        j_disc, _ = discrete_optimum(dt)
        errs.append(abs(j_disc - 2 * LN2))
        assert errs[-1] <= 1.1 * LN2 * dt
        res = solve_dp(one_tank(201, dt), [0.0])
        assert 2 * res.total_cost == pytest.approx(j_disc, abs=1e-9)
        assert res.states[-1, 0] >= TARGET - 1e-12
    ratios = np.array(errs[:-1]) / np.array(errs[1:])
    np.testing.assert_allclose(ratios, 2.0, rtol=0.05)


def test_two_state_solution_is_bang_bang() -> None:
    """The valves stay closed first and are (nearly, up to grid error) fully open at the end."""
    dt = 0.05
    res = solve_dp(two_tank(41, dt), [0.0, 0.0], store_policy=True)
    u = res.inputs
    assert u.shape == (20, 2)
    for j in range(2):
        assert np.all(u[:4, j] == 0.0)  # full flow is needed only for the last ~14 steps
        assert u[-12:, j].mean() >= 0.9
    assert res.policy_index is not None and res.policy_index.shape == (20, 41, 41)
    # costate along the path: dJ/dx_i <= 0 (a fuller tank needs less water)
    assert np.all(res.costate[np.isfinite(res.costate)] <= 1e-12)

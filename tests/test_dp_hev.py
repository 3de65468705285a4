"""DP on a toy hybrid-electric vehicle against an independent Pontryagin (PMP) optimum.

Problem (SI units). State: battery state of charge ``soc`` [-]. Input: engine power
``P_e`` [W] in ``[0, P_MAX]``. Exogenous demand ``P_d(k)`` [W] (positive = traction,
negative = regeneration, all of it into the battery: there is no friction brake). Battery
power ``P_b = P_d - P_e``; internal (chemical) power drawn from the battery
``P_int = P_b + R_EFF * P_b**2`` (quadratic losses in both directions), so

    soc[k+1] = soc[k] - P_int * DT / E_BATT,
    fuel power  = A * P_e**2 + B * P_e + C * (P_e > 0)      [W of fuel],

and the cost is the fuel energy ``sum(fuel power * DT)`` [J], charge-sustaining:
``soc[N] >= soc[0]`` (fuel is increasing in ``P_e``, so the optimum ends at equality).

Independent optimum (PMP). The dynamics do not depend on ``soc`` and no SOC bound is active,
so the costate is constant and the optimum minimises, step by step, the Hamiltonian
``h(P_e) = fuel(P_e) + s * P_int(P_e)`` with one equivalence factor ``s`` [-]. For
``P_e > 0``: ``dh/dP_e = 2 A P_e + B - s (1 + 2 R_EFF (P_d - P_e)) = 0`` gives
``P_on = (s (1 + 2 R_EFF P_d) - B) / (2 A + 2 s R_EFF)`` clipped to ``(0, P_MAX]``; the
engine runs iff ``h(P_on) < h(0)``. ``soc[N] - soc[0]`` increases with ``s``; ``s`` is found
by bisection so that it is zero. The demand is piecewise constant with levels chosen so that
no step is near the on/off indifference at the optimal ``s`` (the test checks the margin),
hence ``soc[N](s)`` is continuous there and the PMP solution is the exact optimum of the
continuous-input problem. The DP cost-to-go slope ``dJ/dsoc`` must equal ``-s * E_BATT``.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from hevsim.errors import DPInfeasibleError
from hevsim.optimal import DPProblem, FinalTarget, Increment, solve_dp

DT = 1.0  # [s]
E_BATT = 5.4e6  # battery energy capacity [J] (1.5 kWh)
A = 1e-5  # [1/W]
B = 2.5  # [-] marginal fuel power per engine power
C = 3000.0  # [W] fuel power of the running, unloaded engine
R_EFF = 2e-6  # [1/W] battery loss coefficient
P_MAX = 50e3  # [W]
SOC0 = 0.6
SOC_GRID = (0.45, 0.75)
LEVELS_W = (30e3, -12e3, 20e3, 40e3, -5e3, 12e3, -25e3)
DURATIONS = (20, 10, 15, 10, 5, 12, 6)
P_DEMAND = np.tile(np.concatenate([np.full(n, v) for v, n in zip(LEVELS_W, DURATIONS, strict=True)]), 3)
N = P_DEMAND.size


def fuel_w(pe: np.ndarray) -> np.ndarray:
    return A * pe**2 + B * pe + C * (pe > 0)


def p_int_w(pd: np.ndarray | float, pe: np.ndarray) -> np.ndarray:
    pb = pd - pe
    return pb + R_EFF * pb**2


def pmp_solution() -> tuple[float, np.ndarray, float]:
    """Equivalence factor s, optimal engine power per step [W], smallest on/off margin [W]."""

    def inputs(s: float) -> tuple[np.ndarray, np.ndarray]:
        p_on = np.clip((s * (1 + 2 * R_EFF * P_DEMAND) - B) / (2 * A + 2 * s * R_EFF), 1e-9, P_MAX)
        h_on = fuel_w(p_on) + s * p_int_w(P_DEMAND, p_on)
        h_off = s * p_int_w(P_DEMAND, np.zeros_like(p_on))
        return np.where(h_on < h_off, p_on, 0.0), np.abs(h_on - h_off)

    def dsoc(s: float) -> float:
        return float(-np.sum(p_int_w(P_DEMAND, inputs(s)[0])) * DT / E_BATT)

    lo, hi = 0.5, 10.0
    assert dsoc(lo) < 0 < dsoc(hi)
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if dsoc(mid) < 0 else (lo, mid)
    s = 0.5 * (lo + hi)
    pe, margin = inputs(s)
    return s, pe, float(margin.min())


S_EQ, PE_OPT, MARGIN = pmp_solution()
J_REF = float(np.sum(fuel_w(PE_OPT)) * DT)


def model(states, inputs, k, data):  # type: ignore[no-untyped-def]
    (soc,) = states
    (pe,) = inputs
    return (soc - p_int_w(data["pd"], pe) * DT / E_BATT,), fuel_w(pe) * DT, None


def problem(n_soc: int, n_pe: int, **kw) -> DPProblem:  # type: ignore[no-untyped-def]
    return DPProblem(
        model,
        [np.linspace(*SOC_GRID, n_soc)],
        [np.linspace(0.0, P_MAX, n_pe)],
        N,
        data={"pd": P_DEMAND},
        target=FinalTarget(SOC0, None),
        state_names=["soc"],
        input_names=["p_engine_w"],
        **kw,
    )


def test_reference_is_exact() -> None:
    """The PMP reference meets the charge-sustaining condition, stays off the SOC bounds,
    and no step is close to the on/off indifference (so the bisection root is exact)."""
    soc = SOC0 - np.cumsum(p_int_w(P_DEMAND, PE_OPT)) * DT / E_BATT
    assert abs(soc[-1] - SOC0) < 1e-12
    assert SOC_GRID[0] + 0.05 < soc.min() and soc.max() < SOC_GRID[1] - 0.05
    assert MARGIN > 100.0  # [W] of Hamiltonian
    assert np.any(PE_OPT == 0) and np.any(PE_OPT > 0)  # the on/off choice matters


REFINEMENTS = [(31, 26), (61, 51), (121, 101), (241, 201), (481, 401)]


def test_dp_converges_to_pmp_optimum() -> None:
    """Default method (boundary line): relative error shrinks at every refinement, ends
    below 3e-4, the final SOC meets the target, and the costate matches -s * E_BATT."""
    errors = []
    for n_soc, n_pe in REFINEMENTS:
        res = solve_dp(problem(n_soc, n_pe), [SOC0])
        assert res.final_constraint == "boundary_line"
        err = (res.total_cost - J_REF) / J_REF
        errors.append(err)
        assert res.states[-1, 0] >= SOC0 - 1e-12
    # DP is restricted to grid inputs: it cannot beat the continuous optimum (up to 1e-6)
    assert min(errors) > -1e-6, errors
    assert all(b < a for a, b in itertools.pairwise(errors)), errors
    assert errors[-1] < 3e-4, errors
    lam = res.costate[:-1, 0]
    assert np.nanmedian(lam) == pytest.approx(-S_EQ * E_BATT, rel=2e-3)


@pytest.mark.parametrize(
    ("method", "kw"),
    [
        ("boundary_line", {}),
        ("levelset", {}),
        ("wall", {}),
        ("penalty", {"penalty_weight": 3 * S_EQ * E_BATT}),
    ],
)
@pytest.mark.parametrize("forward", ["reoptimize", "policy"])
def test_final_constraint_methods(method: str, kw: dict, forward: str) -> None:
    """Every method finds the optimum within grid error; the hard methods do not leak."""
    res = solve_dp(problem(241, 201), [SOC0], final_constraint=method, forward=forward, **kw)
    assert res.final_constraint == method
    assert (res.total_cost - J_REF) / J_REF == pytest.approx(0.0, abs=1e-3)
    if method == "penalty":
        # an exact penalty: violation at most one input step of charge
        assert res.states[-1, 0] >= SOC0 - (P_MAX / 200) * DT / E_BATT
    else:
        assert res.states[-1, 0] >= SOC0 - 1e-12
    soc = res.states[:, 0]
    assert soc.min() >= SOC_GRID[0] and soc.max() <= SOC_GRID[1]
    # the trajectory is consistent with the model and the reported stage costs
    np.testing.assert_allclose(res.stage_costs, fuel_w(res.inputs[:, 0]) * DT)
    np.testing.assert_allclose(np.diff(soc), -p_int_w(P_DEMAND, res.inputs[:, 0]) * DT / E_BATT)


def test_wall_is_conservative_on_coarse_grid() -> None:
    """The hard wall erodes the feasible set on a grid much coarser than one step's SOC
    change; it then refuses (with a hint) instead of leaking, while the boundary line works."""
    with pytest.raises(DPInfeasibleError, match="boundary_line"):
        solve_dp(problem(31, 26), [SOC0], final_constraint="wall")
    res = solve_dp(problem(31, 26), [SOC0], final_constraint="boundary_line")
    assert res.states[-1, 0] >= SOC0 - 1e-12


def test_boundary_lines_bracket_the_trajectory() -> None:
    res = solve_dp(problem(121, 101), [SOC0], store_cost_to_go=True, store_policy=True)
    bl = res.boundary_lines
    assert bl is not None and bl.shape == (N + 1, 2)
    soc = res.states[:, 0]
    assert np.all(soc >= bl[:, 0] - 1e-9) and np.all(soc <= bl[:, 1] + 1e-9)
    assert bl[-1, 0] == pytest.approx(SOC0)
    # lower boundary at the last step: full engine power reaches SOC0 exactly
    pd = P_DEMAND[-1]
    assert bl[-2, 0] == pytest.approx(SOC0 + p_int_w(pd, np.array(P_MAX)) * DT / E_BATT, abs=1e-9)
    assert res.cost_to_go is not None and res.cost_to_go.shape == (N + 1, 121)
    assert res.policy_index is not None and res.policy_index.shape == (N, 121)
    pol = res.policy()
    assert pol is not None and pol[0].shape == (N, 121)


def test_increment_precompute_and_float32_agree() -> None:
    """Increment next states, a precompute hook and float32 storage give the same optimum."""
    ref = solve_dp(problem(121, 101), [SOC0])

    def pre(inputs, k, data):  # type: ignore[no-untyped-def]
        (pe,) = inputs
        return -p_int_w(data["pd"], pe) * DT / E_BATT, fuel_w(pe) * DT

    def model_inc(states, inputs, k, data, pre):  # type: ignore[no-untyped-def]
        dsoc, fuel = pre
        return (Increment(dsoc),), fuel, None

    p2 = DPProblem(
        model_inc,
        [np.linspace(*SOC_GRID, 121)],
        [np.linspace(0.0, P_MAX, 101)],
        N,
        data=lambda k: {"pd": P_DEMAND[k]},
        precompute=pre,
        target=FinalTarget(SOC0, None),
    )
    res = solve_dp(p2, [SOC0])
    assert res.total_cost == pytest.approx(ref.total_cost, rel=1e-12)
    np.testing.assert_allclose(res.states, ref.states, atol=1e-12)
    res32 = solve_dp(p2, [SOC0], cost_dtype="float32", store_cost_to_go=True)
    assert res32.cost_to_go is not None and res32.cost_to_go.dtype == np.float32
    assert res32.total_cost == pytest.approx(ref.total_cost, rel=1e-4)

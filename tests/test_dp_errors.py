"""Bad input to the DP solver fails early with a message naming argument, value and step."""

from __future__ import annotations

import numpy as np
import pytest

from hevsim.errors import DPInfeasibleError, DPModelError, DPSetupError, HevsimError
from hevsim.optimal import DPProblem, FinalTarget, estimate_memory, solve_dp

E_BATT = 5.4e6  # [J]
SOC_GRID = np.linspace(0.45, 0.75, 61)
PE_GRID = np.linspace(0.0, 50e3, 51)  # [W]


def p_int(pd, pe):  # type: ignore[no-untyped-def]
    pb = pd - pe
    return pb + 2e-6 * pb**2


def hev(pd: np.ndarray, *, mask_from: int | None = None, **kw) -> DPProblem:  # type: ignore[no-untyped-def]
    """Toy HEV (1 s steps): soc' = soc - P_int / E, cost 2.5 * P_e; mask all from a step."""

    def model(states, inputs, k, data):  # type: ignore[no-untyped-def]
        (soc,), (pe,) = states, inputs
        mask = None
        if mask_from is not None and k >= mask_from:
            mask = np.ones(np.broadcast_shapes(soc.shape, pe.shape), dtype=bool)
        return (soc - p_int(data["pd"], pe) / E_BATT,), 2.5 * pe, mask

    return DPProblem(model, [SOC_GRID], [PE_GRID], len(pd), data={"pd": pd}, **kw)


def simple_model(states, inputs, k, data):  # type: ignore[no-untyped-def]
    return (states[0] + 0.01 * inputs[0],), inputs[0] ** 2, None


def test_errors_are_hevsim_errors() -> None:
    for cls in (DPSetupError, DPModelError, DPInfeasibleError):
        assert issubclass(cls, HevsimError)


@pytest.mark.parametrize(
    ("state_grids", "input_grids", "match"),
    [
        ([[]], [[0.0, 1.0]], r"state_grids\[0\] \('x1'\) is empty"),
        ([[0.0]], [[0.0, 1.0]], r"state_grids\[0\] \('x1'\) has 1 point; expected at least 2"),
        ([[0.0, 0.5, 0.3]], [[0.0, 1.0]], r"not strictly increasing: value 0.3 at position 2"),
        ([[0.0, np.nan]], [[0.0, 1.0]], r"non-finite value nan at position 1"),
        ([[0.0, 1.0]], [[]], r"input_grids\[0\] \('u1'\) is empty"),
        ([[0.0, 1.0]], [[1.0, 0.0]], r"input_grids\[0\] \('u1'\) is not strictly increasing"),
        ([[0.0, 1.0]], [], r"input_grids is empty"),
        ([[0.0, 1.0]] * 5, [[0.0, 1.0]], r"1 to 4 state variables"),
        ([[[0.0, 1.0]]], [[0.0, 1.0]], r"1-D array"),
    ],
)
def test_bad_grids(state_grids, input_grids, match) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(DPSetupError, match=match):
        DPProblem(simple_model, state_grids, input_grids, 3)


def test_discrete_input_may_be_unsorted_but_not_repeated() -> None:
    DPProblem(simple_model, [[0.0, 1.0]], [[3.78, 2.12, 1.36]], 3, discrete_inputs=[0])
    with pytest.raises(DPSetupError, match=r"repeated values"):
        DPProblem(simple_model, [[0.0, 1.0]], [[3.78, 3.78]], 3, discrete_inputs=[0])
    with pytest.raises(DPSetupError, match=r"discrete_inputs entry 1"):
        DPProblem(simple_model, [[0.0, 1.0]], [[0.0, 1.0]], 3, discrete_inputs=[1])


@pytest.mark.parametrize(
    ("target", "match"),
    [
        (FinalTarget(1.5, None), r"\[1.5, 1.0\] lies \(partly\) outside the state grid \[0.0, 1.0\]"),
        (FinalTarget(None, -0.5), r"outside the state grid"),
        (FinalTarget(0.8, 0.2), r"lower bound 0.8 exceeds upper bound 0.2"),
        (FinalTarget([0.1, 0.2], None), r"target.lower has 2 entries; expected one per state \(1\)"),
    ],
)
def test_bad_target(target: FinalTarget, match: str) -> None:
    with pytest.raises(DPSetupError, match=match):
        DPProblem(simple_model, [[0.0, 0.5, 1.0]], [[0.0, 1.0]], 3, target=target)


def test_bad_problem_arguments() -> None:
    with pytest.raises(DPSetupError, match=r"n_steps must be >= 1; got 0"):
        DPProblem(simple_model, [[0.0, 1.0]], [[0.0, 1.0]], 0)
    with pytest.raises(DPSetupError, match=r"n_steps must be an integer"):
        DPProblem(simple_model, [[0.0, 1.0]], [[0.0, 1.0]], 2.5)  # type: ignore[arg-type]
    with pytest.raises(
        DPSetupError, match=r"data\['pd'\] has shape \(2,\); expected .* at least n_steps = 3"
    ):
        DPProblem(simple_model, [[0.0, 1.0]], [[0.0, 1.0]], 3, data={"pd": [1.0, 2.0]})
    with pytest.raises(DPSetupError, match=r"model must be callable"):
        DPProblem("model", [[0.0, 1.0]], [[0.0, 1.0]], 3)  # type: ignore[arg-type]


def test_bad_solve_options() -> None:
    p = DPProblem(simple_model, [np.linspace(0.0, 1.0, 11)], [np.linspace(-1, 1, 5)], 3)
    with pytest.raises(
        DPSetupError,
        match=r"final_constraint 'exact' is not known; "
        r"expected one of auto, boundary_line, levelset, wall, penalty",
    ):
        solve_dp(p, [0.5], final_constraint="exact")
    with pytest.raises(DPSetupError, match=r"forward 'backward' is not known"):
        solve_dp(p, [0.5], forward="backward")
    with pytest.raises(DPSetupError, match=r"x0\[0\] \('x1'\) = 1.5 is outside the state grid \[0.0, 1.0\]"):
        solve_dp(p, [1.5])
    with pytest.raises(DPSetupError, match=r"x0 has shape \(2,\); expected one value per state \(1,\)"):
        solve_dp(p, [0.5, 0.5])
    with pytest.raises(DPSetupError, match=r"'penalty' needs penalty_weight"):
        solve_dp(p, [0.5], final_constraint="penalty")
    with pytest.raises(DPSetupError, match=r"penalty_weight is only used with"):
        solve_dp(p, [0.5], penalty_weight=1.0)
    with pytest.raises(DPSetupError, match=r"cost_dtype 'float16' is not supported"):
        solve_dp(p, [0.5], cost_dtype="float16")
    p2 = DPProblem(simple_model, [[0.0, 1.0], [0.0, 1.0]], [[0.0, 1.0]], 3)
    with pytest.raises(DPSetupError, match=r"'boundary_line' handles one state variable; the problem has 2"):
        solve_dp(p2, [0.5, 0.5], final_constraint="boundary_line")


def test_memory_limit() -> None:
    p = DPProblem(simple_model, [np.linspace(0.0, 1.0, 1001)], [np.linspace(-1, 1, 11)], 1000)
    mem = estimate_memory(p)
    assert mem["cost_to_go"] == 1001 * 1001 * 8
    assert estimate_memory(p, cost_dtype="float32")["cost_to_go"] == 1001 * 1001 * 4
    with pytest.raises(
        DPSetupError,
        match=r"needs about 8\.\d MB .*cost_to_go 8\.0 MB.* "
        r"more than memory_limit_bytes = 1\.0 MB; use cost_dtype='float32'",
    ):
        solve_dp(p, [0.5], memory_limit_bytes=1e6)


def _bad_model(kind: str, bad_step: int = 3):  # type: ignore[no-untyped-def]
    def model(states, inputs, k, data):  # type: ignore[no-untyped-def]
        (x,), (u,) = states, inputs
        nxt = x + 0.01 * u
        cost = u**2 + 0 * x
        if k == bad_step:
            if kind == "shape":
                return (np.zeros(3),), cost, None
            if kind == "nan_cost":
                cost = np.where((u > 0.4) & (x > 0.45), np.nan, cost)
            if kind == "nan_state":
                nxt = np.where(u < -0.9, np.nan, nxt)
            if kind == "masked_nan":
                return (np.where(u < 0, np.nan, nxt),), cost, (u < 0) | (0 * x > 1)
            if kind == "count":
                return (nxt, nxt), cost, None
            if kind == "tuple":
                return nxt, cost  # type: ignore[return-value]
        return (nxt,), cost, None

    return model


@pytest.mark.parametrize(
    ("kind", "match"),
    [
        (
            "shape",
            r"next_states\[0\] at step 3 has shape \(3,\), "
            r"which does not broadcast to the block shape \(11, 5\)",
        ),
        (
            "nan_cost",
            r"stage_cost at step 3 is NaN at block index \(5, 3\) "
            r".*x1=0\.5; u1=0\.5.* infeasible_mask is False",
        ),
        ("nan_state", r"next_states\[0\] at step 3 is nan .*u1=-1"),
        ("count", r"next_states at step 3 is 2 entries; expected a tuple or list of 1 arrays"),
        ("tuple", r"at step 3 returned tuple; expected a tuple \(next_states, stage_cost, infeasible_mask\)"),
    ],
)
def test_bad_model_output(kind: str, match: str) -> None:
    p = DPProblem(_bad_model(kind), [np.linspace(0.0, 1.0, 11)], [np.linspace(-1, 1, 5)], 6)
    with pytest.raises(DPModelError, match=match):
        solve_dp(p, [0.5])


def test_nan_where_masked_is_allowed() -> None:
    p = DPProblem(_bad_model("masked_nan"), [np.linspace(0.0, 1.0, 11)], [np.linspace(-1, 1, 5)], 6)
    res = solve_dp(p, [0.5])
    assert res.inputs[3, 0] >= 0.0
    assert np.isfinite(res.total_cost)


def test_bad_terminal_cost() -> None:
    p = DPProblem(simple_model, [np.linspace(0, 1, 5)], [[0.0]], 2, terminal_cost=lambda s: np.ones(3))
    with pytest.raises(DPModelError, match=r"terminal_cost returned shape \(3,\); expected .* \(5,\)"):
        solve_dp(p, [0.5])


def test_infeasible_target_names_constraint_and_step() -> None:
    p = hev(np.full(20, 20e3), target=FinalTarget(0.74, None))
    for method in ("boundary_line", "levelset", "wall"):
        with pytest.raises(DPInfeasibleError) as exc:
            solve_dp(p, [0.5], final_constraint=method)
        msg = str(exc.value)
        assert "violated constraint is the final-state target" in msg
        assert "at step 0 the target can only be reached from" in msg
        assert "excludes the initial state" in msg


def test_infeasible_target_empty_from_a_step() -> None:
    """60 kW demand, 50 kW engine: the battery loses >= 0.0019 SOC per step, so no grid
    state (<= 0.75) reaches SOC >= 0.749 one step later: empty from step 19."""
    pd = np.full(20, 60e3)
    p = hev(pd, target=FinalTarget(0.749, None))
    with pytest.raises(DPInfeasibleError, match=r"final-state target .* becomes empty at step 19"):
        solve_dp(p, [0.5], final_constraint="levelset")


def test_infeasible_mask_names_constraint_and_step() -> None:
    p = hev(np.full(30, 20e3), mask_from=5)
    with pytest.raises(
        DPInfeasibleError, match=r"violated constraint is the input/model infeasibility mask, from step 5"
    ):
        solve_dp(p, [0.6])


def test_infeasible_state_bounds_names_constraint_and_step() -> None:
    """80 kW demand from step 10 with a 50 kW engine: after charging fully for 10 steps
    (SOC 0.683) the battery hits the lower bound 0.45 after ~39.6 steps: step 49."""
    p = hev(np.r_[np.zeros(10), np.full(50, 80e3)])
    for method in ("boundary_line", "levelset", "wall"):
        with pytest.raises(
            DPInfeasibleError,
            match=r"violated constraint is the state bounds \(x1 in \[0.45, 0.75\]\), from step 49",
        ):
            solve_dp(p, [0.6], final_constraint=method)

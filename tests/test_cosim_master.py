"""Validation of the co-simulation master against known monolithic solutions (issue 6, item 7)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from hevsim.cosim import Connection, CosimFault, FunctionParticipant, ode_participant, simulate
from hevsim.errors import ConfigError

A = np.array([[-1.0, 0.8], [0.5, -2.0]])
X0 = np.array([1.0, -0.5])
T_END = 2.0


def split_system() -> tuple[list, list[Connection]]:
    """x1' = a11 x1 + a12 x2 and x2' = a21 x1 + a22 x2, one state per participant."""
    p1 = ode_participant(
        "p1", lambda t, x, u: A[0, 0] * x + A[0, 1] * u["x2"], X0[0], lambda x, u: {"x1": x[0]}, {"x2": ""}
    )
    p2 = ode_participant(
        "p2", lambda t, x, u: A[1, 0] * u["x1"] + A[1, 1] * x, X0[1], lambda x, u: {"x2": x[0]}, {"x1": ""}
    )
    return [p1, p2], [Connection("p1", "x1", "p2", "x1"), Connection("p2", "x2", "p1", "x2")]


def coupling_error(h: float, **opt: object) -> float:
    parts, conns = split_system()
    res = simulate(parts, conns, stop_time_s=T_END, step_s=h, **opt)
    exact = np.array([expm(A * t) @ X0 for t in res.time_s])
    err = np.c_[res["p1.x1"], res["p2.x2"]] - exact
    return float(np.abs(err).max())


def observed_order(**opt: object) -> tuple[float, list[float]]:
    hs = [0.1, 0.05, 0.025]
    errs = [coupling_error(h, **opt) for h in hs]
    return float(np.polyfit(np.log(hs), np.log(errs), 1)[0]), errs


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_first_order_convergence(algorithm: str) -> None:
    order, errs = observed_order(algorithm=algorithm)
    assert 0.9 < order < 1.1, (order, errs)


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_iteration_with_midpoint_hold_is_second_order(algorithm: str) -> None:
    order, errs = observed_order(algorithm=algorithm, max_iterations=50, tolerance=1e-13)
    assert 1.9 < order < 2.1, (order, errs)
    plain = coupling_error(0.025, algorithm=algorithm)
    assert errs[-1] < 0.05 * plain


def test_iteration_with_end_hold_stays_first_order() -> None:
    order, _ = observed_order(algorithm="gauss-seidel", max_iterations=50, tolerance=1e-13, hold="end")
    assert 0.9 < order < 1.1


def test_iteration_converges_to_same_fixed_point_for_both_orders() -> None:
    ej = coupling_error(0.05, algorithm="jacobi", max_iterations=50, tolerance=1e-13)
    eg = coupling_error(0.05, algorithm="gauss-seidel", max_iterations=50, tolerance=1e-13, relaxation=0.8)
    assert ej == pytest.approx(eg, rel=1e-6)


def thermal_masses(c1: float = 500.0, c2: float = 200.0, g: float = 3.0) -> tuple[list, list[Connection]]:
    """Two lumped thermal masses [J/K] through a conductance [W/K]; heat sent in kW and kcal."""

    def hot(t, h, x, u):  # x = (temp_k, energy_out_j); exact exponential decay toward u
        tau = c1 / g
        t_end = u["t_other_k"] + (x[0] - u["t_other_k"]) * np.exp(-h / tau)
        q_avg = c1 * (x[0] - t_end) / h  # step-average heat flow out [W]
        return (t_end, x[1] + q_avg * h), {"temp_k": t_end, "heat_kw": q_avg / 1e3}

    def cold(t, h, x, u):
        t_new = x + u["heat_w"] * h / c2
        return t_new, {"temp_degc": t_new - 273.15}

    p1 = FunctionParticipant(
        "hot", hot, (350.0, 0.0), {"temp_k": 350.0, "heat_kw": 0.0}, {"t_other_k": "K"},
        {"temp_k": "K", "heat_kw": "kW"},
    )  # fmt: skip
    p2 = FunctionParticipant(
        "cold", cold, 290.0, {"temp_degc": 290.0 - 273.15}, {"heat_w": "W"}, {"temp_degc": "degC"}
    )
    conns = [
        Connection("cold", "temp_degc", "hot", "t_other_k"),
        Connection("hot", "heat_kw", "cold", "heat_w"),
    ]
    return [p1, p2], conns


def test_energy_conserved_across_thermal_interface_with_unit_conversion() -> None:
    parts, conns = thermal_masses()
    res = simulate(
        parts, conns, stop_time_s=600.0, step_s=5.0, algorithm="gauss-seidel", order=["hot", "cold"]
    )
    e_hot = 500.0 * (350.0 - res["hot.temp_k"][-1])
    e_cold = 200.0 * (res["cold.temp_degc"][-1] + 273.15 - 290.0)
    assert e_cold == pytest.approx(e_hot, rel=1e-12)
    # both converge to the energy-weighted mean temperature
    assert res["hot.temp_k"][-1] == pytest.approx((500 * 350 + 200 * 290) / 700, abs=0.5)


def test_jacobi_energy_defect_is_last_step_heat() -> None:
    parts, conns = thermal_masses()
    res = simulate(parts, conns, stop_time_s=100.0, step_s=5.0, algorithm="jacobi")
    e_hot = 500.0 * (350.0 - res["hot.temp_k"][-1])
    e_cold = 200.0 * (res["cold.temp_degc"][-1] + 273.15 - 290.0)
    assert e_hot - e_cold == pytest.approx(res["hot.heat_kw"][-1] * 1e3 * 5.0, rel=1e-9)


def test_negotiated_step_min_and_rejection() -> None:
    parts, conns = split_system()
    slow = FunctionParticipant(
        "slow", lambda t, h, x, u: (x, {"y": u["x1"]}), 0.0, {"y": 0.0}, {"x1": ""}, preferred_h=0.2
    )
    fussy = FunctionParticipant(
        "fussy",
        lambda t, h, x, u: (x, {"z": 1.0}),
        0.0,
        {"z": 0.0},
        {},
        preferred_h=0.05,
        reject_above_h=0.05,
    )
    conns.append(Connection("p1", "x1", "slow", "x1"))
    res = simulate([*parts, slow, fussy], conns, stop_time_s=1.0, step_s=0.1, negotiation="min")
    assert np.allclose(np.diff(res.time_s), 0.05)
    assert res.stats["rejected"] == 1
    res = simulate([*split_system()[0], slow], [], stop_time_s=1.0, step_s=0.1, negotiation="max")
    assert np.allclose(np.diff(res.time_s)[1:-1], 0.2)
    assert res.time_s[-1] == pytest.approx(1.0)


def test_early_termination_request() -> None:
    def step(t, h, x, u):
        return x + h, {"clock": x + h, "terminate": float(x + h >= 0.5)}

    p = FunctionParticipant("clock", step, 0.0, {"clock": 0.0}, {})
    res = simulate([p], [], stop_time_s=10.0, step_s=0.1)
    assert res.time_s[-1] == pytest.approx(0.5)
    assert "clock" in (res.stopped_by or "")


def test_send_before_receive_initial_exchange() -> None:
    def follower(t, h, x, u):
        return x, {"seen": u["v"]}

    src = FunctionParticipant("src", lambda t, h, x, u: (x, {"v": 7.0}), 0.0, {"v": 7.0}, {})

    class Echo(FunctionParticipant):
        def get_outputs(self):
            return {"seen": self.u["v"]}

    dst = Echo("dst", follower, 0.0, {"seen": 0.0}, {"v": ""})
    res = simulate([dst, src], [Connection("src", "v", "dst", "v")], stop_time_s=0.1, step_s=0.1,
                   send_before_receive={"dst": False})  # fmt: skip
    assert res["dst.seen"][0] == 7.0


def test_participant_fault_names_participant_time_call_and_keeps_results() -> None:
    def bad(t, h, x, u):
        if t >= 0.3 - 1e-9:
            raise RuntimeError("solver diverged")
        return x, {"y": t}

    parts, conns = split_system()
    p = FunctionParticipant("bad", bad, 0.0, {"y": 0.0}, {})
    with pytest.raises(
        CosimFault, match=r"'bad' failed in do_step at t = 0.3 s: RuntimeError: solver diverged"
    ) as ei:
        simulate([*parts, p], conns, stop_time_s=1.0, step_s=0.1)
    assert ei.value.partial is not None
    assert ei.value.partial.time_s[-1] == pytest.approx(0.3)


def test_bad_connections() -> None:
    parts, _ = split_system()
    with pytest.raises(ConfigError, match="has no output 'nope'"):
        simulate(parts, [Connection("p1", "nope", "p2", "x1")], stop_time_s=1, step_s=0.1)
    with pytest.raises(ConfigError, match="no participant 'p3'"):
        simulate(parts, [Connection("p3", "x", "p2", "x1")], stop_time_s=1, step_s=0.1)
    parts, _ = thermal_masses()
    with pytest.raises(ConfigError, match="incompatible units 'kW' -> 'K'"):
        simulate(parts, [Connection("hot", "heat_kw", "hot", "t_other_k")], stop_time_s=1, step_s=0.1)
    with pytest.raises(ConfigError, match="valid: jacobi, gauss-seidel"):
        simulate(parts, [], stop_time_s=1, step_s=0.1, algorithm="newton")


def test_checkpoint_resume_identical(tmp_path) -> None:
    ck = tmp_path / "run.ckpt"
    full = simulate(*split_system(), stop_time_s=2.0, step_s=0.1, algorithm="jacobi")

    class Killed(Exception):
        pass

    def kill_at_1(t, stop):
        if t >= 1.0 - 1e-9:
            raise Killed

    with pytest.raises(Killed):
        simulate(
            *split_system(),
            stop_time_s=2.0,
            step_s=0.1,
            algorithm="jacobi",
            checkpoint_path=ck,
            checkpoint_every=1,
            progress=kill_at_1,
        )
    assert ck.is_file()
    resumed = simulate(
        *split_system(), stop_time_s=2.0, step_s=0.1, algorithm="jacobi", checkpoint_path=ck, resume=True
    )
    assert np.array_equal(resumed.time_s, full.time_s)
    assert np.array_equal(resumed.data, full.data)

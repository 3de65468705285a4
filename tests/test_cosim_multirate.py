"""Multi-rate exchange (``rates``): a participant that communicates every k-th step."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm
from tests.cosim_helpers import interrupt_after
from tests.test_cosim_master import T_END, X0, A, split_system

from hevsim.cosim import Connection, FunctionParticipant, simulate
from hevsim.cosim.master import CosimResult
from hevsim.errors import ConfigError


def error(h: float, rate: int, **opt: object) -> float:
    parts, conns = split_system()
    res = simulate(parts, conns, stop_time_s=T_END, step_s=h, rates={"p2": rate}, **opt)
    exact = np.array([expm(A * t) @ X0 for t in res.time_s])
    return float(np.abs(np.c_[res["p1.x1"], res["p2.x2"]] - exact).max())


def test_rate_one_is_the_lockstep_run() -> None:
    parts, conns = split_system()
    a = simulate(parts, conns, stop_time_s=T_END, step_s=0.05, rates={"p2": 1})
    parts, conns = split_system()
    b = simulate(parts, conns, stop_time_s=T_END, step_s=0.05)
    assert np.array_equal(a.data, b.data)


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_multirate_error_is_first_order_in_the_window(algorithm: str) -> None:
    """The coupling error grows with the slow participant's window and, at a fixed rate,
    shrinks at first order with the step."""
    e1, e2, e4 = (error(0.05, k, algorithm=algorithm) for k in (1, 2, 4))
    assert e1 < e2 < e4, (e1, e2, e4)
    hs = [0.04, 0.02, 0.01]
    errs = [error(h, 4, algorithm=algorithm) for h in hs]
    order = float(np.polyfit(np.log(hs), np.log(errs), 1)[0])
    assert 0.9 < order < 1.1, (order, errs)


def counting(name: str, calls: list[tuple[float, float]]) -> FunctionParticipant:
    def step(t: float, h: float, x: float, u: dict[str, float]) -> tuple[float, dict[str, float]]:
        calls.append((t, h))
        return x + u["u"] * h, {"y": x + u["u"] * h}

    return FunctionParticipant(name, step, 0.0, {"y": 0.0}, inputs={"u": ""})


def source() -> FunctionParticipant:
    def step(t: float, h: float, x: None, u: dict[str, float]) -> tuple[None, dict[str, float]]:
        return None, {"u": 1.0 + t + h}

    return FunctionParticipant("src", step, None, {"u": 1.0}, inputs={})


def test_slow_participant_steps_once_per_window_and_holds_its_outputs() -> None:
    calls: list[tuple[float, float]] = []
    res = simulate([source(), counting("slow", calls)], [Connection("src", "u", "slow", "u")],
                   stop_time_s=1.1, step_s=0.1, rates={"slow": 4}, algorithm="gauss-seidel")  # fmt: skip
    t_calls = [round(t, 9) for t, _ in calls]
    h_calls = [round(h, 9) for _, h in calls]
    assert t_calls == [0.0, 0.4, 0.8] and h_calls == [0.4, 0.4, 0.3]  # last window cut at the stop time
    y = res["slow.y"]
    assert np.all(y[1:4] == 0.0) and y[4] > 0.0 and np.all(y[4:8] == y[4])  # held between exchanges
    # Gauss-Seidel: the slow participant gets the source's value at the end of its window
    assert y[4] == pytest.approx(0.4 * (1.0 + 0.4))


def test_checkpoint_inside_a_window_resumes_identically(tmp_path: Path) -> None:
    def run(**kw: object) -> CosimResult:
        return simulate([source(), counting("slow", [])], [Connection("src", "u", "slow", "u")],
                        stop_time_s=2.0, step_s=0.1, rates={"slow": 3}, **kw)  # fmt: skip

    ck = tmp_path / "ck.pkl"
    full = run()
    interrupt_after(run, 0.75, checkpoint_path=ck, checkpoint_every=1)  # killed inside the window 0.6 .. 0.9
    resumed = run(checkpoint_path=ck, resume=True)
    assert np.array_equal(resumed.data, full.data)


def test_rates_are_validated() -> None:
    parts, conns = split_system()
    with pytest.raises(ConfigError, match="negotiation 'fixed'"):
        simulate(parts, conns, stop_time_s=1.0, step_s=0.1, rates={"p2": 2}, negotiation="min")
    with pytest.raises(ConfigError, match="rates name unknown participant 'p9'"):
        simulate(parts, conns, stop_time_s=1.0, step_s=0.1, rates={"p9": 2})
    with pytest.raises(ConfigError, match="expected an integer >= 1"):
        simulate(parts, conns, stop_time_s=1.0, step_s=0.1, rates={"p2": 0})


def test_rates_round_trip_through_ssd(tmp_path: Path) -> None:
    from hevsim.cosim.ssd import PY_TYPE, Component, SystemDescription, read_ssd
    from hevsim.cosim.ssp_write import write_ssd

    desc = SystemDescription("s", [Component("a", PY_TYPE, "m:f")], [], 0.0, 1.0,
                             {"step_s": 0.1, "rates": {"a": 5}})  # fmt: skip
    back = read_ssd(write_ssd(desc, tmp_path / "s.ssd"))
    assert back.master["rates"] == {"a": 5}
    bad = (tmp_path / "s.ssd").read_text().replace('rates="a:5"', 'rates="a:five"')
    (tmp_path / "bad.ssd").write_text(bad)
    with pytest.raises(ConfigError, match="rates='a:five'"):
        read_ssd(tmp_path / "bad.ssd")

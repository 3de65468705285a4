"""Standard FMUs the way other masters run them (issue 13): FMI 2.0 early termination, FMUs
without state support, the time grid, O(1) checkpoints. The FMU is a small C model compiled
in the test (tests/cosim_cfmu.py), so it is loaded in this process too."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tests.cosim_cfmu import build_c_fmu
from tests.cosim_helpers import interrupt_after

from hevsim.cosim import Connection, CosimFault, FunctionParticipant, simulate
from hevsim.cosim.participant import FMUParticipant
from hevsim.cosim.ssd import Component, SystemDescription
from hevsim.cosim.ssp_write import write_ssd
from hevsim.cosim.worker import WorkerFMUParticipant
from hevsim.errors import ConfigError

CLASSES = [FMUParticipant, WorkerFMUParticipant]


@pytest.fixture(scope="module")
def cfmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_c_fmu(tmp_path_factory.mktemp("cfmu") / "c.fmu")


def fmpy_reference(
    fmu: Path, stop: float, h: float, start: dict[str, float], outputs: list[str]
) -> np.ndarray:
    from fmpy import simulate_fmu

    return simulate_fmu(str(fmu), stop_time=stop, step_size=h, output_interval=h, start_values=start,
                        output=outputs)  # fmt: skip


@pytest.mark.parametrize("cls", CLASSES)
def test_fmi2_terminated_ends_the_run_like_fmpy(cfmu: Path, cls: type) -> None:
    start = {"terminate_at": 0.55, "k": 2.0, "u": 1.5, "y0": 0.25}
    ref = fmpy_reference(cfmu, 1.0, 0.1, start, ["y"])
    res = simulate([cls("c", cfmu, start)], [], stop_time_s=1.0, step_s=0.1)
    assert res.stopped_by == "participant 'c' requested termination at t = 0.55 s"
    assert len(res.time_s) == len(ref) == 7
    assert np.array_equal(res.time_s, ref["time"])  # same grid, same termination point
    assert np.abs(res["c.y"] - ref["y"]).max() <= 1e-12
    assert res["c.y"][-1] == pytest.approx(0.25 + 2.0 * 1.5 * 0.55, abs=1e-12)


def test_fmi2_termination_through_cli_exits_zero(cfmu: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from hevsim.cli import main

    desc = SystemDescription(
        "term",
        [Component("c", "application/x-fmu-sharedlibrary", cfmu.name, parameters={"terminate_at": 0.55})],
        [],
        stop_time_s=1.0,
        master={"step_s": 0.1},
        base_dir=cfmu.parent,
    )
    ssd = write_ssd(desc, cfmu.parent / "term.ssd")
    assert main(["cosim", str(ssd), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "stopped: participant 'c' requested termination at t = 0.55 s" in out
    rows = (tmp_path / "out" / "results.csv").read_text().splitlines()
    assert rows[-1].startswith("0.55,")


def test_fmu_without_state_support_runs_and_says_what_it_cannot(cfmu: Path, tmp_path: Path) -> None:
    def parts() -> list:
        src = FunctionParticipant(
            "src", lambda t, h, x, u: (x + h, {"v": np.sin(x + h)}), 0.0, {"v": 0.0}, {}
        )
        return [src, WorkerFMUParticipant("c", cfmu, {"k": 3.0})]

    conns = [Connection("src", "v", "c", "u")]
    full = simulate(parts(), conns, stop_time_s=2.0, step_s=0.1, algorithm="jacobi")
    assert not parts()[1].can_save_state
    # Jacobi: y(t+h) = y + k sin(t) h (the source's value at the start of the step)
    t = np.arange(21) * 0.1
    expect = np.concatenate([[0.0], np.cumsum(3.0 * np.sin(t[:-1]) * 0.1)])
    assert np.abs(full["c.y"] - expect).max() <= 1e-12
    # a checkpoint holds no state of 'c': resume replays from the start, checked row by row
    ck = tmp_path / "ck.pkl"
    interrupt_after(lambda **kw: simulate(parts(), conns, **kw), 1.05, stop_time_s=2.0, step_s=0.1,
                    algorithm="jacobi", checkpoint_path=ck, checkpoint_every=1)  # fmt: skip
    assert ck.is_file()
    resumed = simulate(parts(), conns, stop_time_s=2.0, step_s=0.1, algorithm="jacobi", checkpoint_path=ck,
                       resume=True)  # fmt: skip
    assert np.array_equal(resumed.data, full.data) and np.array_equal(resumed.time_s, full.time_s)
    # a replay that does not reproduce the stored rows is refused
    interrupt_after(lambda **kw: simulate(parts(), conns, **kw), 1.05, stop_time_s=2.0, step_s=0.1,
                    algorithm="jacobi", checkpoint_path=ck, checkpoint_every=1)  # fmt: skip
    other = [parts()[0], WorkerFMUParticipant("c", cfmu, {"k": 3.5})]
    with pytest.raises(CosimFault, match=r"cannot resume: participant\(s\) 'c' cannot save their state"):
        simulate(
            other, conns, stop_time_s=2.0, step_s=0.1, algorithm="jacobi", checkpoint_path=ck, resume=True
        )
    # iterative schemes need the state: refused before running, naming the participant
    msg = r"'c' cannot save and restore its state \(FMU c.fmu declares canGetAndSetFMUstate=\"false\""
    with pytest.raises(ConfigError, match=msg + r".*iterative coupling \(max_iterations=3\)"):
        simulate(parts(), conns, stop_time_s=2.0, step_s=0.1, max_iterations=3)
    with pytest.raises(ConfigError, match=r"participant 'c' cannot save.*step negotiation 'min'"):
        simulate(parts(), conns, stop_time_s=2.0, step_s=0.1, negotiation="min")


def clock() -> FunctionParticipant:
    return FunctionParticipant("clk", lambda t, h, x, u: (x + 1, {"n": x + 1.0}), 0, {"n": 0.0}, {})


def test_time_grid_is_start_plus_n_h() -> None:
    res = simulate([clock()], [], start_time_s=0.3, stop_time_s=9.3, step_s=0.1)
    n = np.arange(91)
    assert np.array_equal(res.time_s, 0.3 + n * 0.1)  # not an accumulated t += h
    assert res.time_s[-1] == 9.3 and res["clk.n"][-1] == 90.0
    res = simulate([clock()], [], stop_time_s=9.0, step_s=0.1)
    assert res.time_s[-1] == 9.0 and len(res.time_s) == 91
    res = simulate([clock()], [], stop_time_s=1.05, step_s=0.1)  # a last, shorter step to the stop time
    assert res.time_s[-2] == 1.0 and res.time_s[-1] == 1.05


def test_checkpoint_size_does_not_grow_with_the_run(tmp_path: Path) -> None:
    sizes = []
    for steps in (100, 2000):
        ck = tmp_path / f"ck{steps}.pkl"
        interrupt_after(lambda **kw: simulate([clock()], [], **kw), steps * 0.01 - 0.005, stop_time_s=100.0,
                        step_s=0.01, checkpoint_path=ck, checkpoint_every=1)  # fmt: skip
        sizes.append(ck.stat().st_size)
        rows = ck.with_name(ck.name + ".rows").stat().st_size
        assert rows == 8 * 2 * (steps + 1)  # time + one output per row, streamed append-only
    assert sizes[1] <= sizes[0] + 16, sizes  # the state only: no results in the checkpoint


def test_checkpoint_interval_is_wall_time_by_default(tmp_path: Path) -> None:
    ck = tmp_path / "ck.pkl"
    interrupt_after(lambda **kw: simulate([clock()], [], **kw), 0.5, stop_time_s=1.0, step_s=0.1,
                    checkpoint_path=ck)  # fmt: skip
    assert not ck.exists()  # default: every 30 s of wall time, none in a run this short
    interrupt_after(lambda **kw: simulate([clock()], [], **kw), 0.5, stop_time_s=1.0, step_s=0.1,
                    checkpoint_path=ck, checkpoint_wall_s=1e-9)  # fmt: skip
    assert ck.is_file()
    resumed = simulate([clock()], [], stop_time_s=1.0, step_s=0.1, checkpoint_path=ck, resume=True)
    assert resumed["clk.n"].tolist() == list(range(11))
    with pytest.raises(ConfigError, match="checkpoint_every 0"):
        simulate([clock()], [], stop_time_s=1.0, step_s=0.1, checkpoint_every=0)


def test_ssd_checkpoint_every_steps_or_wall_time(tmp_path: Path) -> None:
    from hevsim.cosim.ssd import read_ssd

    for value, expect in (("50", {"checkpoint_every": 50}), ("30s", {"checkpoint_wall_s": 30.0})):
        desc = SystemDescription("s", [], [], stop_time_s=1.0, master={"step_s": 0.1, **expect})
        back = read_ssd(write_ssd(desc, tmp_path / "s.ssd"))
        assert back.master == {"step_s": 0.1, **expect}
        text = (tmp_path / "s.ssd").read_text()
        assert f'checkpoint_every="{value if value == "50" else "30.0s"}"' in text
    (tmp_path / "bad.ssd").write_text(text.replace('checkpoint_every="30.0s"', 'checkpoint_every="often"'))
    with pytest.raises(ConfigError, match=r"checkpoint_every='often': expected a number of steps"):
        read_ssd(tmp_path / "bad.ssd")


# ---------------------------------------------------------------------------- item 5: order
C = {"c1": 0.5, "c2": 0.25, "c3": 0.125}
H = 0.1


def feedthrough_chain(cfmu: Path, listing: tuple[str, ...]) -> tuple[list, list[Connection]]:
    """src (outputs n h at t_n) -> c1.x, c1.z -> c2.x, c2.z -> c3.x; z = x + c (direct feedthrough)."""
    made = {name: FMUParticipant(name, cfmu, {"c": c}) for name, c in C.items()}
    made["src"] = FunctionParticipant(
        "src", lambda t, h, n, u: (n + 1, {"v": (n + 1) * H}), 0, {"v": 0.0}, {}
    )
    conns = [
        Connection("src", "v", "c1", "x"),
        Connection("c1", "z", "c2", "x"),
        Connection("c2", "z", "c3", "x"),
    ]
    return [made[n] for n in listing], conns


def test_results_do_not_depend_on_the_listing_order(cfmu: Path) -> None:
    from itertools import permutations

    n = np.arange(11)
    for algorithm in ("jacobi", "gauss-seidel"):
        runs = []
        for listing in permutations(["src", "c1", "c2", "c3"]):
            res = simulate(*feedthrough_chain(cfmu, listing), stop_time_s=1.0, step_s=H, algorithm=algorithm)
            runs.append({c: res[c] for c in res.columns})
        for other in runs[1:]:
            assert all(np.array_equal(other[c], runs[0][c]) for c in runs[0])
        r = runs[0]
        for k in (1, 2, 3):
            lag = k if algorithm == "jacobi" else 0  # Jacobi: one step per link; Gauss-Seidel: none
            src = np.maximum(n - lag, 0) * H  # the initial values are consistent (propagated)
            expect = src
            for j in range(1, k + 1):
                expect = expect + C[f"c{j}"]
            assert np.array_equal(r[f"c{k}.z"], expect), (algorithm, k)
    # the default is Jacobi
    res = simulate(*feedthrough_chain(cfmu, ("c3", "c2", "c1", "src")), stop_time_s=1.0, step_s=H)
    assert res["c3.z"][3] == 0.0 + 0.875


def test_feedthrough_loop_without_fixed_point_is_named(cfmu: Path) -> None:
    a, b = FMUParticipant("a", cfmu, {"c": 1.0}), FMUParticipant("b", cfmu, {"c": 1.0})
    loop = [Connection("a", "z", "b", "x"), Connection("b", "z", "a", "x")]
    with pytest.raises(
        CosimFault, match=r"initial values at t = 0 s do not converge: the outputs of 'a', 'b'"
    ):
        simulate([a, b], loop, stop_time_s=1.0, step_s=H)
    a, b = FMUParticipant("a", cfmu, {"c": 0.0}), FMUParticipant("b", cfmu, {"c": 0.0})
    res = simulate([a, b], loop, stop_time_s=1.0, step_s=H)  # a loop with a fixed point (0) runs
    assert np.all(res["a.z"] == 0.0)

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
    with pytest.raises(CosimFault, match=r"cannot resume: participant\(s\) 'c' cannot save their state \("):
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


# ---------------------------------------------------------------------------- item 3: types
@pytest.mark.parametrize("cls", CLASSES)
def test_all_fmi2_types_recorded_like_fmpy(cfmu: Path, cls: type, tmp_path: Path) -> None:
    start = {"m": 3, "bi": True, "s": "hello, world", "u": 2.0}
    names = ["y", "slen", "n", "mi", "e", "b", "bo"]
    ref = fmpy_reference(cfmu, 0.5, 0.1, start, names)
    p = cls("c", cfmu, start)
    assert p.types == {"n": "Integer", "m": "Integer", "mi": "Integer", "e": "Enumeration", "b": "Boolean",
                       "bi": "Boolean", "bo": "Boolean", "s": "String", "so": "String"}  # fmt: skip
    res = simulate([p], [], stop_time_s=0.5, step_s=0.1)
    assert np.array_equal(res.time_s, ref["time"])
    for n in names:
        assert np.array_equal(res[f"c.{n}"], ref[n].astype(float)), n
    assert res["c.so"].tolist() == ["hello, world"] * 6
    res.write_csv(tmp_path / "r.csv")
    lines = (tmp_path / "r.csv").read_text().splitlines()
    assert lines[0].endswith(",c.so") and lines[1].endswith(',"hello, world"') and ",True" not in lines[1]


def test_typed_connections_and_conversions(cfmu: Path) -> None:
    def parts() -> list:
        a = FMUParticipant("a", cfmu, {"u": 1.0, "s": "abc", "bi": False, "m": 4})
        return [a, FMUParticipant("b", cfmu)]

    conns = [
        Connection("a", "n", "b", "u"),  # Integer -> Real: converted
        Connection("a", "bo", "b", "m"),  # Boolean -> Integer: 1 / 0
        Connection("a", "so", "b", "s"),  # String -> String
        Connection("a", "b", "b", "bi"),  # Boolean -> Boolean
    ]
    res = simulate(parts(), conns, stop_time_s=1.0, step_s=0.1, algorithm="jacobi")
    n = np.arange(11)
    assert np.array_equal(res["a.n"], n)
    # b integrates u = a.n of the step start: y(t_k) = sum_{j<k} j * 0.1
    assert np.allclose(res["b.y"], 0.1 * n * (n - 1) / 2, rtol=0, atol=1e-12)
    assert np.all(res["b.mi"] == 2.0)  # m = bo = not False = 1
    assert res["b.so"].tolist() == ["abc"] * 11 and np.all(res["b.slen"] == 3.0)
    # b.bi follows a.b (a.y > 0.5 from t = 0.6), one step late: b.bo = not a.b(t - h)
    assert res["a.b"].tolist() == [0.0] * 6 + [1.0] * 5
    assert res["b.bo"].tolist() == [1.0] * 7 + [0.0] * 4
    for src, dst, msg in (
        (("a", "y"), ("b", "m"), "a Real output to an Integer input"),
        (("a", "y"), ("b", "bi"), "a Real output to a Boolean input"),
        (("a", "so"), ("b", "u"), "a String output to a Real input"),
        (("a", "n"), ("b", "s"), "an Integer output to a String input"),
    ):
        with pytest.raises(ConfigError, match=rf"connection a.{src[1]} -> b.{dst[1]} \(a.{src[1]} is .*: "
                           rf"cannot connect {msg}; allowed conversions: Integer -> Real"):  # fmt: skip
            simulate(parts(), [Connection(*src, *dst)], stop_time_s=1.0, step_s=0.1)
    with pytest.raises(ConfigError, match=r"parameter 'm' is an Integer, got 2.5"):
        simulate([FMUParticipant("a", cfmu, {"m": 2.5})], [], stop_time_s=1.0, step_s=0.1)
    with pytest.raises(ConfigError, match=r"parameter 's' is a String, got 3"):
        simulate([FMUParticipant("a", cfmu, {"s": 3})], [], stop_time_s=1.0, step_s=0.1)


def test_string_results_survive_checkpoint_and_resume(cfmu: Path, tmp_path: Path) -> None:
    def run(**kw: object):  # type: ignore[no-untyped-def]
        a = FMUParticipant("a", cfmu, {"u": 1.0, "s": "x,y"})
        return simulate([a], [], stop_time_s=1.0, step_s=0.1, **kw)

    full = run()
    ck = tmp_path / "ck.pkl"
    interrupt_after(run, 0.55, checkpoint_path=ck, checkpoint_every=1)
    resumed = run(checkpoint_path=ck, resume=True)  # no state support: replayed and compared
    assert np.array_equal(resumed.data, full.data) and resumed.text == full.text
    assert full.text["a.so"] == ["x,y"] * 11


_ARRAY_MODEL = """
import numpy as np
from pythonfmu3 import Boolean, Dimension, Float64, Fmi3Causality, Fmi3Slave, Fmi3Variability, Int32
from pythonfmu3.enums import Fmi3Initial

D = Fmi3Variability.discrete


class CosimArrayModel(Fmi3Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.time = 0.0
        self.a = np.array([1.0, 2.0, 3.0])
        self.w = np.array([0.0, 0.0, 0.0])
        self.count = 0
        self.inc = 1
        self.odd = False
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous))
        self.register_variable(Float64("a", causality=Fmi3Causality.output, initial=Fmi3Initial.exact,
                                       dimensions=[Dimension(start="3")]))
        # an explicit setter: pythonfmu3 0.3.4's own calls np.reshape(newshape=), gone in numpy 2
        self.register_variable(Float64("w", causality=Fmi3Causality.input, dimensions=[Dimension(start="3")],
                                       setter=lambda v: setattr(self, "w", np.array(v, float))))
        self.register_variable(Int32("count", causality=Fmi3Causality.output, variability=D,
                                     initial=Fmi3Initial.exact))
        self.register_variable(Int32("inc", causality=Fmi3Causality.input, variability=D))
        self.register_variable(Boolean("odd", causality=Fmi3Causality.output, variability=D,
                                       initial=Fmi3Initial.exact))

    def do_step(self, current_time, step_size):
        self.a = self.a + self.w * step_size
        self.count += self.inc
        self.odd = bool(self.count % 2)
        self.time = current_time + step_size
        return True
"""


@pytest.fixture(scope="module")
def array_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from pythonfmu3 import FmuBuilder

    d = tmp_path_factory.mktemp("arr")
    (d / "CosimArrayModel.py").write_text(_ARRAY_MODEL)
    return Path(
        FmuBuilder.build_FMU(d / "CosimArrayModel.py", dest=d, canHandleVariableCommunicationStepSize=True)
    )


def test_fmi3_arrays_and_integer_types_exchanged_and_recorded(array_fmu: Path) -> None:
    w = [0.5, -1.0, 0.25]
    src = FunctionParticipant("src", lambda t, h, x, u: (x, {f"w{i}": w[i] for i in range(3)}), 0,
                              {f"w{i}": w[i] for i in range(3)}, {})  # fmt: skip
    m1, m2 = WorkerFMUParticipant("m1", array_fmu), WorkerFMUParticipant("m2", array_fmu)
    assert list(m1.outputs) == ["a[1]", "a[2]", "a[3]", "count", "odd"]
    assert m1.types == {"count": "Integer", "inc": "Integer", "odd": "Boolean"}
    conns = [Connection("src", f"w{i}", "m1", f"w[{i + 1}]") for i in range(3)]
    conns += [Connection("m1", "count", "m2", "inc"), Connection("m1", "a[3]", "m2", "w[2]")]
    res = simulate([src, m1, m2], conns, stop_time_s=1.0, step_s=0.1, algorithm="gauss-seidel")
    a = np.array([1.0, 2.0, 3.0])
    expect = [a.copy()]
    hs = np.diff(res.time_s)  # t_(k+1) - t_k on the grid k h (0.1 up to round-off)
    for k in range(10):
        a = a + np.array(w) * hs[k]
        expect.append(a.copy())
    e = np.array(expect)
    for i in range(3):
        assert np.array_equal(res[f"m1.a[{i + 1}]"], e[:, i]), i
    n = np.arange(11)
    assert np.array_equal(res["m1.count"], n) and np.array_equal(res["m1.odd"], n % 2)
    # Gauss-Seidel: m2 adds m1's count after m1's step: 1 + 2 + ... + k
    assert np.array_equal(res["m2.count"], n * (n + 1) / 2)
    # m2.w[2] = m1.a[3] at the step's end
    m2a = [2.0]
    for k in range(10):
        m2a.append(m2a[-1] + e[k + 1, 2] * hs[k])
    assert np.array_equal(res["m2.a[2]"], m2a)


def test_check_catches_type_mismatch_and_bad_parameter(cfmu: Path) -> None:
    from hevsim.cosim.datacheck import datacheck

    def desc(conns: list[Connection], params: dict | None = None) -> SystemDescription:
        comps = [Component(n, "application/x-fmu-sharedlibrary", cfmu.name, parameters=params or {})
                 for n in ("a", "b")]  # fmt: skip
        return SystemDescription(
            "t", comps, conns, stop_time_s=1.0, master={"step_s": 0.1}, base_dir=cfmu.parent
        )

    ok = [Connection("a", "n", "b", "u"), Connection("a", "so", "b", "s"), Connection("a", "bo", "b", "m")]
    datacheck(desc(ok))
    with pytest.raises(ConfigError, match=r"a.y -> b.m \(a.y is Real, b.m is Integer\): cannot connect"):
        datacheck(desc([Connection("a", "y", "b", "m")]))
    with pytest.raises(
        ConfigError, match=r"component 'a': FMU c.fmu: parameter 'bi' is a Boolean, got the text"
    ):
        datacheck(desc([], {"bi": "yes"}))


# ---------------------------------------------------------------------------- item 7: the FMU log
@pytest.mark.parametrize("cls", CLASSES)
def test_fmu_log_messages_come_with_the_failure(cfmu: Path, cls: type, tmp_path: Path, capfd) -> None:  # type: ignore[no-untyped-def]
    log = tmp_path / "fmu.log"
    p = cls("c", cfmu, {"fail_at": 0.35, "u": 1.0}, log_level="error", fmu_log=log)
    msg = r"participant 'c' failed in do_step at t = 0.3 s: .*fmi2DoStep failed.*FMU log: \[ERROR\] error: "
    with pytest.raises(
        CosimFault, match=msg + r"integrator blew up: step from t = 0.3 crosses fail_at = 0.35"
    ):
        simulate([p], [], stop_time_s=1.0, step_s=0.1)
    assert "c [ERROR] error: integrator blew up" in log.read_text()
    assert "FMU 'c' [ERROR] error: integrator blew up" in capfd.readouterr().err  # shown at log_level error
    q = cls("q", cfmu, {"fail_at": 0.35}, log_level="fatal")
    with pytest.raises(CosimFault, match="integrator blew up"):  # still explains the failure
        simulate([q], [], stop_time_s=1.0, step_s=0.1)
    assert "integrator blew up" not in capfd.readouterr().err
    with pytest.raises(ConfigError, match="log level 'loud'; valid: all, warning"):
        cls("r", cfmu, log_level="loud")


def test_cli_log_options(cfmu: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from hevsim.cli import main

    desc = SystemDescription("f", [Component("c", "application/x-fmu-sharedlibrary", cfmu.name,
                                             parameters={"fail_at": 0.35})], [],
                             stop_time_s=1.0, master={"step_s": 0.1}, base_dir=cfmu.parent)  # fmt: skip
    ssd = write_ssd(desc, tmp_path / "f.ssd")
    # the SSD refers to the FMU next to it
    (tmp_path / cfmu.name).write_bytes(cfmu.read_bytes())
    log = tmp_path / "fmu.log"
    code = main(
        ["cosim", str(ssd), "--out", str(tmp_path / "out"), "--fmu-log", str(log), "--log-level", "none"]
    )
    assert code == 2
    err = capsys.readouterr().err
    assert "integrator blew up" in err and "FMU log:" in err
    assert log.read_text().startswith("c [ERROR] error: integrator blew up")


# ---------------------------------------------------------------------------- item 6: SSP as others write it
def test_written_ssp_runs_in_fmpys_ssp_reader(cfmu: Path, tmp_path: Path) -> None:
    from types import SimpleNamespace

    from fmpy.ssp.simulation import simulate_ssp

    from hevsim.cosim.ssd import read_ssp
    from hevsim.cosim.ssp_write import write_ssp
    from hevsim.cosim.system import run_system

    params = {"a": {"u": 1.0, "k": 2.0}, "b": {"k": -1.0}}
    comps = [
        Component(n, "application/x-fmu-sharedlibrary", cfmu.name, parameters=p) for n, p in params.items()
    ]
    conns = [Connection("a", "y", "b", "u"), Connection("b", "y", "a", "x")]
    desc = SystemDescription("t", comps, conns, stop_time_s=1.0, master={"step_s": 0.1}, base_dir=cfmu.parent)
    ssp = write_ssp(desc, tmp_path / "t.ssp")
    # FMPy's runner is Jacobi, ignores the SSD's parameter bindings (given here instead) and
    # labels each row with the start of the step it ends; its t += h also takes an 11th step
    pset = SimpleNamespace(parameters=[SimpleNamespace(name=f"{c}.{k}", value=v)
                                       for c, p in params.items() for k, v in p.items()])  # fmt: skip
    ref = simulate_ssp(str(ssp), stop_time=1.0, step_size=0.1, parameter_set=pset)
    with read_ssp(ssp) as d:
        assert d.master["step_s"] == 0.1
        res = run_system(d)
    for col in ("a.y", "b.y"):
        assert len(ref) == 11 and np.abs(res[col][1:] - ref[col][:10]).max() <= 1e-12, col
    assert np.abs(res["b.y"][-1] - (-0.1 * sum(2.0 * 0.1 * j for j in range(10)))) <= 1e-12


LIBCOSIM_SSP = """
import json, sys
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimObserver import CosimObserver

log_output_level(CosimLogLevel.ERROR)
ex = CosimExecution.from_ssp_file(sys.argv[1])  # step size: the OSP annotation
obs = CosimObserver.create_last_value()
ex.add_observer(observer=obs)
index = {s.name.decode(): s.index for s in ex.slave_infos()}
vr = {n: {v.name.decode(): v.reference for v in ex.slave_variables(i)} for n, i in index.items()}
rows = []
for _ in range(int(sys.argv[2])):
    ex.step()
    rows.append([obs.last_real_values(index[n], [vr[n]["y"]])[0] for n in ("a", "b")])
print(json.dumps(rows))
"""


def test_written_ssp_runs_in_libcosim(cfmu: Path, tmp_path: Path) -> None:
    """libcosim (the C++ master of the Open Simulation Platform, through libcosimpy) loads the
    ``.ssp`` hevsim writes: step size from the OSP annotation, parameters from the inline
    parameter bindings, connections; its fixed-step (Jacobi) results equal hevsim's default."""
    pytest.importorskip("libcosimpy")
    import json
    import subprocess
    import sys

    from hevsim.cosim.ssd import read_ssp
    from hevsim.cosim.ssp_write import write_ssp
    from hevsim.cosim.system import run_system

    params = {"a": {"u": 1.0, "k": 2.0}, "b": {"k": -1.0}}
    comps = [
        Component(n, "application/x-fmu-sharedlibrary", cfmu.name, parameters=p) for n, p in params.items()
    ]
    conns = [Connection("a", "y", "b", "u"), Connection("b", "y", "a", "x")]
    desc = SystemDescription("t", comps, conns, stop_time_s=1.0, master={"step_s": 0.1}, base_dir=cfmu.parent)
    ssp = write_ssp(desc, tmp_path / "t.ssp")
    proc = subprocess.run([sys.executable, "-c", LIBCOSIM_SSP, str(ssp), "10"], capture_output=True,
                          text=True, timeout=120, check=False)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    ref = np.array(json.loads(proc.stdout.strip().splitlines()[-1]))
    with read_ssp(ssp) as d:
        res = run_system(d)
    assert np.array_equal(res.time_s, np.arange(11) * 0.1)
    for j, col in enumerate(("a.y", "b.y")):
        assert np.abs(res[col][1:] - ref[:, j]).max() <= 1e-12, col
    assert ref[-1, 0] == pytest.approx(2.0, abs=1e-12)  # the parameters were applied (u k t)
    assert ref[-1, 1] == pytest.approx(-0.1 * sum(2.0 * 0.1 * j for j in range(10)), abs=1e-12)


def test_osp_step_size_ssv_and_ssm(cfmu: Path, tmp_path: Path) -> None:
    from hevsim.cosim.load import load_system
    from hevsim.cosim.system import run_system

    (tmp_path / cfmu.name).write_bytes(cfmu.read_bytes())
    (tmp_path / "p.ssv").write_text("""<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    version="1.0" name="p">
  <ssv:Parameters>
    <ssv:Parameter name="c.gain"><ssv:Real value="3.0"/></ssv:Parameter>
    <ssv:Parameter name="c.u"><ssv:Real value="2.0"/></ssv:Parameter>
    <ssv:Parameter name="c.count"><ssv:Integer value="7"/></ssv:Parameter>
  </ssv:Parameters>
</ssv:ParameterSet>""")
    (tmp_path / "m.ssm").write_text("""<?xml version="1.0" encoding="UTF-8"?>
<ssm:ParameterMapping xmlns:ssm="http://ssp-standard.org/SSP1/SystemStructureParameterMapping"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" version="1.0">
  <ssm:MappingEntry source="gain" target="k">
    <ssc:LinearTransformation factor="0.5" offset="1.0"/>
  </ssm:MappingEntry>
  <ssm:MappingEntry source="count" target="m"/>
</ssm:ParameterMapping>""")
    (tmp_path / "s.ssd").write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations" version="1.0" name="s">
  <ssd:System name="s">
    <ssd:Elements>
      <ssd:Component name="c" type="application/x-fmu-sharedlibrary" source="{cfmu.name}">
        <ssd:ParameterBindings>
          <ssd:ParameterBinding source="p.ssv" prefix="c.">
            <ssd:ParameterMapping source="m.ssm"/>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="1">
    <ssd:Annotations>
      <ssc:Annotation type="com.opensimulationplatform">
        <osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="0.25"/></osp:Algorithm>
      </ssc:Annotation>
    </ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>""")
    with load_system(tmp_path / "s.ssd") as d:
        assert d.master == {"step_s": 0.25}
        assert d.components[0].parameters == {"k": 2.5, "u": 2.0, "m": 7}
        res = run_system(d)
    assert res.time_s.tolist() == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert res["c.y"][-1] == pytest.approx(2.5 * 2.0 * 1.0, abs=1e-12) and np.all(res["c.mi"] == 14.0)


# ---------------------------------------------------------------------------- item 4: --check
def test_check_refuses_what_the_run_would(cfmu: Path) -> None:
    from hevsim.cosim.datacheck import datacheck
    from hevsim.cosim.system import run_system

    def desc(conns: list[Connection], **master: object) -> SystemDescription:
        comps = [Component(n, "application/x-fmu-sharedlibrary", cfmu.name) for n in ("a", "b")]
        return SystemDescription(
            "t", comps, conns, stop_time_s=1.0, master=dict(master), base_dir=cfmu.parent
        )

    datacheck(desc([]))  # the step from the FMUs' DefaultExperiment (tests/test_cosim_defaults.py)
    py = Component("p", "application/x-hevsim-python", "hevsim.cosim.participant:StepperParticipant")
    with pytest.raises(ConfigError, match=r"no communication step size: give step_s .*no FMU participant"):
        datacheck(SystemDescription("t", [py], [], stop_time_s=1.0))
    with pytest.raises(ConfigError, match=r"valid: jacobi, gauss-seidel"):
        datacheck(desc([], step_s=0.1, algorithm="newton"))
    with pytest.raises(ConfigError, match=r"component 'a' cannot save and restore its state \(FMU c.fmu .*"
                       r"iterative coupling \(max_iterations=2\)"):  # fmt: skip
        datacheck(desc([], step_s=0.1, max_iterations=2))
    loop = [Connection("a", "z", "b", "x"), Connection("b", "z", "a", "x")]
    with pytest.raises(ConfigError, match=r"algebraic loop of direct feedthrough under Gauss-Seidel: "
                       r"a.x -> a.z -> b.x -> b.z -> a.x"):  # fmt: skip
        datacheck(desc(loop, step_s=0.1, algorithm="gauss-seidel"))
    with pytest.raises(ConfigError, match="algebraic loop"):  # the run refuses it too
        run_system(desc(loop, step_s=0.1, algorithm="gauss-seidel"))
    # no loop through y (y does not depend on u directly): Gauss-Seidel is fine
    datacheck(desc([Connection("a", "y", "b", "u"), Connection("b", "y", "a", "u")], step_s=0.1,
                   algorithm="gauss-seidel"))  # fmt: skip
    ok = desc(loop, step_s=0.1)  # Jacobi: passes the check, and runs
    datacheck(ok)
    res = run_system(ok)
    assert np.all(res["a.z"] == 0.0) and len(res.time_s) == 11


def test_check_refuses_an_fmu_without_an_interface_it_runs(tmp_path: Path) -> None:
    """An FMU whose model description declares neither ``CoSimulation`` nor ``ModelExchange``
    is refused by ``--check`` and by the run, naming the component (a Model Exchange FMU is
    a participant since issue 30: tests/test_cosim_me.py)."""
    import re

    from tests.cosim_cfmu import model_description

    from hevsim.cosim.datacheck import datacheck
    from hevsim.cosim.system import run_system

    def neither(ident: str) -> str:
        return re.sub(r"<CoSimulation [^>]*/>", "", model_description(ident))

    fmu = build_c_fmu(tmp_path / "none.fmu", "CNoneModel", description=neither)
    desc = SystemDescription("t", [Component("m", "application/x-fmu-sharedlibrary", fmu.name)], [],
                             stop_time_s=1.0, master={"step_s": 0.1}, base_dir=tmp_path)  # fmt: skip
    with pytest.raises(ConfigError, match=r"component 'm': .*none.fmu"):
        datacheck(desc)
    with pytest.raises(ConfigError, match=r"'m'.*none.fmu"):
        run_system(desc)

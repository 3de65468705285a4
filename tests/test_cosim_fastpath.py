"""The master's plain stepping path and the worker protocol (issue 13 item 11): the same
results as the general path, faults named with the right call and time, and a worker that
keeps its inputs and outputs straight across steps and interruptions."""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hevsim.cosim import Connection, CosimFault, FunctionParticipant
from hevsim.cosim._worker import FrameReader, send_frame
from hevsim.cosim.master import Master, Options
from hevsim.cosim.trivial import build_integrator_fmu
from hevsim.errors import SimulationError


def _system() -> tuple[list[FunctionParticipant], list[Connection]]:
    """A heater (degC out), a counter (an Integer output) and a mass heated by both (K in),
    which feeds its temperature back to the heater: unit and type conversions, a loop."""
    heater = FunctionParticipant(
        "heater", lambda t, h, x, u: (x, {"temp_c": 20.0 + 0.3 * u["back_k"] - 0.3 * 293.15 + t}), 0,
        {"temp_c": 20.0}, {"back_k": "K"}, {"temp_c": "degC"},
    )  # fmt: skip
    counter = FunctionParticipant("counter", lambda t, h, x, u: (x + 1, {"n": x + 1}), 0, {"n": 0}, {})
    counter.types = {"n": "Integer"}
    mass = FunctionParticipant(
        "mass", lambda t, h, x, u: (x + h * (u["src_k"] - x + 0.01 * u["n"]), {"temp_k": x}), 290.0,
        {"temp_k": 290.0}, {"src_k": "K", "n": ""}, {"temp_k": "K"},
    )  # fmt: skip
    conns = [
        Connection("heater", "temp_c", "mass", "src_k"),
        Connection("counter", "n", "mass", "n"),
        Connection("mass", "temp_k", "heater", "back_k"),
    ]
    return [mass, heater, counter], conns


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_plain_path_equals_general_path_bit_for_bit(algorithm: str) -> None:
    runs = []
    for plain in (True, False):
        parts, conns = _system()
        m = Master(parts, conns, Options(stop_time_s=2.0, step_s=0.1, algorithm=algorithm))
        assert m._plain  # no iteration, no multi-rate: the plain path is the one taken
        m._plain = plain
        runs.append(m.run())
    a, b = runs
    assert a.columns == b.columns and len(a.time_s) == 21
    assert np.array_equal(a.time_s, b.time_s) and np.array_equal(a.data, b.data)
    assert np.ptp(a["mass.temp_k"]) > 1.0  # the system does move


class _Failing(FunctionParticipant):
    """A pass-through participant whose ``call`` raises once ``steps`` steps are done."""

    def __init__(self, name: str, call: str, steps: int):
        super().__init__(name, lambda t, h, x, u: (x + 1, {"y": u["x"]}), 0, {"y": 0.0}, {"x": ""})
        self.call, self.after = call, steps

    def _check(self, call: str) -> None:
        if call == self.call and self.state >= self.after:
            raise RuntimeError(f"{call} refused")

    def set_inputs(self, values: Any) -> None:
        self._check("set_inputs")
        super().set_inputs(values)

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        self._check("do_step")
        return super().do_step(t, h)

    def get_outputs(self) -> dict[str, float]:
        self._check("get_outputs")
        return super().get_outputs()


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
@pytest.mark.parametrize(("call", "steps", "t_msg"), [("set_inputs", 3, 0.3), ("do_step", 3, 0.3),
                                                      ("get_outputs", 4, 0.4)])  # fmt: skip
def test_fault_names_the_call_and_its_time(algorithm: str, call: str, steps: int, t_msg: float) -> None:
    """The failing participant comes second (after its source): the message must give the
    time of its own call (set_inputs and do_step at t, get_outputs at t + h)."""
    src = FunctionParticipant("a", lambda t, h, x, u: (x, {"x": t + h}), 0, {"x": 0.0}, {})
    bad = _Failing("b", call, steps)
    m = Master([bad, src], [Connection("a", "x", "b", "x")], Options(stop_time_s=1.0, step_s=0.1,
               algorithm=algorithm))  # fmt: skip
    assert m.order == ["a", "b"]
    with pytest.raises(CosimFault) as ei:
        m.run()
    assert (
        str(ei.value) == f"participant 'b' failed in {call} at t = {t_msg:g} s: RuntimeError: {call} refused"
    )
    assert ei.value.partial is not None and ei.value.partial.time_s[-1] == pytest.approx(0.3)


def test_frames_round_trip_and_end_of_input() -> None:
    r, w = os.pipe()
    small: list[Any] = [("step", 0.1, 0.01, ("u",), (1.5,)), {"k": [1, 2.5, "x"]}, None]
    for o in small:  # all in the pipe before the first read: one read gets several frames
        send_frame(w, o)
    os.close(w)
    reader = FrameReader(r)
    try:
        assert [reader.recv() for _ in small] == small
        with pytest.raises(EOFError):
            reader.recv()
    finally:
        os.close(r)
    r, w = os.pipe()
    big = bytes(range(256)) * 1200  # more than a pipe holds at once: read in parts

    def write_big() -> None:
        send_frame(w, big)
        send_frame(w, small[0])
        os.close(w)

    writer = threading.Thread(target=write_big)
    writer.start()
    reader = FrameReader(r)
    try:
        got = [reader.recv(), reader.recv()]
        with pytest.raises(EOFError):
            reader.recv()
    finally:
        os.close(r)
        writer.join(timeout=10)
    assert got == [big, small[0]]


@pytest.fixture(scope="module")
def integrator(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_integrator_fmu(tmp_path_factory.mktemp("fast") / "i.fmu", name="FastPathInt", y0=1.0)


def test_worker_keeps_inputs_and_outputs_straight(integrator: Path) -> None:
    """y += k u h: inputs set, then not set (held), then set again; outputs by name."""
    from hevsim.cosim.worker import WorkerFMUParticipant

    p = WorkerFMUParticipant("w", integrator, {"k": 2.0})
    try:
        p.setup(0.0)
        ys = []
        for k, u in enumerate((1.0, None, 3.0, None, -1.0)):
            if u is not None:
                p.set_inputs({"u": u})
            assert p.do_step(k * 0.5, 0.5) == (True, None)
            ys.append(p.get_outputs())
        state = p.get_state()
        p.set_inputs({"u": 10.0})
        p.do_step(2.5, 0.5)
        assert p.get_outputs() == {"y": ys[-1]["y"] + 10.0}
        p.set_state(state)
        assert p.get_outputs() == ys[-1]
    finally:
        p.terminate()
    assert [y["y"] for y in ys] == [2.0, 3.0, 6.0, 9.0, 8.0]
    assert p.proc.poll() == 0


def test_interrupted_exchange_retires_the_worker(integrator: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An exception between a request and its reply (Ctrl-C) would leave the reply in the pipe
    for the next call: the worker is declared unusable instead of answering out of turn."""
    import hevsim.cosim.worker as W

    p = W.WorkerFMUParticipant("w", integrator)
    p.setup(0.0)

    def interrupted() -> Any:
        monkeypatch.undo()
        raise KeyboardInterrupt

    monkeypatch.setattr(p._reader, "recv", interrupted)
    with pytest.raises(KeyboardInterrupt):
        p.do_step(0.0, 0.1)
    with pytest.raises(SimulationError, match="interrupted in step; the worker cannot be used"):
        p.do_step(0.1, 0.1)
    p.terminate()
    assert p.proc.poll() is not None


def test_jacobi_worker_fmus_step_in_parallel_with_the_same_results(tmp_path: Path) -> None:
    """x' = v, v' = -x from two integrator FMUs in workers, Jacobi: started together
    (start_step) or one after the other, both give explicit Euler exactly."""
    from hevsim.cosim import simulate
    from hevsim.cosim.worker import WorkerFMUParticipant

    x_fmu = build_integrator_fmu(tmp_path / "x.fmu", name="FastPathX", y0=1.0)
    v_fmu = build_integrator_fmu(tmp_path / "v.fmu", name="FastPathV", y0=0.0)
    conns = [Connection("v", "y", "x", "u"), Connection("x", "y", "v", "u")]
    runs, started = [], []
    for early in (True, False):
        parts = [WorkerFMUParticipant("x", x_fmu), WorkerFMUParticipant("v", v_fmu, {"k": -1.0})]
        for p in parts:
            if early:
                real = p.start_step
                p.start_step = lambda t, h, real=real: (started.append(t), real(t, h))[1]  # type: ignore[method-assign]
            else:
                p.start_step = None  # type: ignore[assignment,method-assign]
        runs.append(simulate(parts, conns, stop_time_s=1.0, step_s=0.1))
    assert len(started) == 20  # 10 steps x 2 workers, started in the background
    x, v = [1.0], [0.0]
    for k in range(10):
        h = (k + 1) * 0.1 - k * 0.1  # the steps between grid points t_k = k * 0.1
        x, v = [*x, x[-1] + v[-1] * h], [*v, v[-1] - x[-1] * h]
    for r in runs:
        assert np.array_equal(r["x.y"], x) and np.array_equal(r["v.y"], v)


@pytest.fixture(scope="module")
def cfmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from tests.cosim_cfmu import build_c_fmu

    return build_c_fmu(tmp_path_factory.mktemp("fast_c") / "c.fmu")


def _ahead(fmu: Path, params: dict[str, float], batch: tuple[int, int] | None) -> tuple[Any, list[int]]:
    """The C FMU in a worker, running ahead ``batch`` = (first, most) steps per exchange (None:
    one at a time);
    also (steps asked for, steps run, whether none failed) per exchange."""
    from hevsim.cosim.worker import WorkerFMUParticipant

    p = WorkerFMUParticipant("c", fmu, params)
    sizes: list[tuple[int, int, bool]] = []
    if batch is None:
        p.run_ahead = None  # type: ignore[assignment,method-assign]
    else:
        real_run_ahead, real_send, real_recv = p.run_ahead, p._send, p._recv
        p.run_ahead = lambda next_end: real_run_ahead(next_end, *batch)  # type: ignore[method-assign]
        asked: list[int] = []

        def send(cmd: str, *args: Any) -> None:
            real_send(cmd, *args)
            if cmd == "steps":
                asked.append(len(args[0]))

        def recv(cmd: str) -> Any:
            res = real_recv(cmd)
            if cmd == "steps":  # (a packed reply: one preferred step per step run)
                run = len(res[0][3]) if isinstance(res[0], tuple) else len(res[0])
                sizes.append((asked.pop(0), run, res[1] is None))
            return res

        p._send, p._recv = send, recv  # type: ignore[method-assign]
    return p, sizes


def test_worker_without_inputs_runs_ahead_with_the_same_results(cfmu: Path) -> None:
    from hevsim.cosim import simulate

    params = {"k": 2.0, "u": 1.5, "y0": 0.25}
    runs = []
    for batch in ((4, 4), None, (2, 4)):
        p, sizes = _ahead(cfmu, params, batch)
        runs.append(simulate([p], [], stop_time_s=1.05, step_s=0.1))
        expect = {
            (4, 4): [(4, 4, True), (4, 4, True), (3, 3, True)],
            None: [],  # the last 0.05 s
            (2, 4): [(2, 2, True), (4, 4, True), (4, 4, True), (1, 1, True)],
        }  # doubling up to 4
        assert sizes == expect[batch]  # fmt: skip
    a, b, c = runs
    assert np.array_equal(a.data, c.data)
    assert np.array_equal(a.time_s, b.time_s) and np.array_equal(a.data, b.data)
    assert a.time_s[-1] == 1.05 and list(a["c.n"]) == list(range(12))
    assert np.abs(a["c.y"] - (0.25 + 3.0 * a.time_s)).max() < 1e-12


def test_worker_running_ahead_stops_and_fails_in_the_right_step(cfmu: Path) -> None:
    from hevsim.cosim import simulate

    p, sizes = _ahead(cfmu, {"terminate_at": 0.55, "k": 2.0, "u": 1.5, "y0": 0.25}, (4, 4))
    res = simulate([p], [], stop_time_s=1.0, step_s=0.1)
    assert sizes == [(4, 4, True), (4, 2, True)]  # no step after the one that asked to terminate
    assert res.stopped_by == "participant 'c' requested termination at t = 0.55 s"
    assert res.time_s[-1] == 0.55 and res["c.y"][-1] == pytest.approx(0.25 + 3.0 * 0.55, abs=1e-12)
    p, sizes = _ahead(cfmu, {"fail_at": 0.35, "u": 1.0}, (2, 2))
    msg = r"participant 'c' failed in do_step at t = 0.3 s: .*integrator blew up"
    with pytest.raises(CosimFault, match=msg) as ei:
        simulate([p], [], stop_time_s=1.0, step_s=0.1)
    assert sizes == [(2, 2, True), (2, 1, False)]  # the step from 0.2 s, then the failing one
    assert ei.value.partial is not None and ei.value.partial.time_s[-1] == pytest.approx(0.3)


def test_checkpoint_of_a_worker_running_ahead_resumes_identically(integrator: Path, tmp_path: Path) -> None:
    """The checkpoint holds the FMU's state where the worker got to plus the steps it ran
    ahead; resumed, the run goes on from the checkpoint's time with the same results."""
    import pickle

    from tests.cosim_helpers import interrupt_after

    from hevsim.cosim import simulate
    from hevsim.cosim.worker import WorkerFMUParticipant

    def run(**kw: Any) -> Any:
        p = WorkerFMUParticipant("i", integrator, {"k": 2.0, "u": 0.75})
        real = p.run_ahead
        p.run_ahead = lambda next_end: real(next_end, 4, 4)  # type: ignore[method-assign]
        return simulate([p], [], stop_time_s=1.0, step_s=0.1, **kw)

    ck = tmp_path / "ck.pkl"
    interrupt_after(run, 0.55, checkpoint_path=ck, checkpoint_every=1)
    saved = pickle.loads(ck.read_bytes())
    assert saved["t"] == pytest.approx(0.6)
    # at 0.8 s, with the steps from 0.6 and 0.7 s (the batch from 0.4 s, sent while the master
    # took the first one, was collected by the first checkpoint)
    st = saved["states"]["i"]
    fmu_state, ahead = st["fmu"], st["ahead"]
    assert isinstance(fmu_state, bytes) and [round(s[0], 9) for s in ahead] == [0.6, 0.7]
    resumed = run(checkpoint_path=ck, resume=True)
    full = run()
    assert np.array_equal(resumed.time_s, full.time_s) and np.array_equal(resumed.data, full.data)
    assert np.abs(full["i.y"] - (1.0 + 1.5 * full.time_s)).max() < 1e-12


def _oscillator_runs(tmp_path: Path, variants: list[dict[str, Any]]) -> list[tuple[Any, list[Any]]]:
    """x' = v, v' = -x from two integrator FMUs in workers (Jacobi), once per variant of
    WorkerFMUParticipant's class attributes: (result, participants)."""
    from hevsim.cosim import simulate
    from hevsim.cosim.worker import WorkerFMUParticipant

    x_fmu = build_integrator_fmu(tmp_path / "x.fmu", name="ShmX", y0=1.0)
    v_fmu = build_integrator_fmu(tmp_path / "v.fmu", name="ShmV", y0=0.0)
    conns = [Connection("v", "y", "x", "u"), Connection("x", "y", "v", "u")]
    runs = []
    for attrs in variants:
        cls = type("W", (WorkerFMUParticipant,), attrs)
        parts = [cls("x", x_fmu), cls("v", v_fmu, {"k": -1.0})]
        runs.append((simulate(parts, conns, stop_time_s=1.0, step_s=0.1), parts))
    return runs


def test_shared_memory_steps_equal_pickled_steps(tmp_path: Path) -> None:
    """Steps through shared memory (polling or not) give the pickled protocol's results bit for
    bit, and every communication step did go through the memory."""
    runs = _oscillator_runs(tmp_path, [{}, {"spin_s": 0.0}, {"shared_memory": False}])
    x, v = [1.0], [0.0]
    for k in range(10):
        h = (k + 1) * 0.1 - k * 0.1
        x, v = [*x, x[-1] + v[-1] * h], [*v, v[-1] - x[-1] * h]
    for res, _ in runs:
        assert np.array_equal(res["x.y"], x) and np.array_equal(res["v.y"], v)
    for _, parts in runs[:2]:
        assert [p._seq for p in parts] == [10, 10]  # 10 steps each in shared memory
    assert [p._seq for p in runs[2][1]] == [0, 0]  # no memory: pickled


def test_shared_memory_step_failure_reads_as_the_pickled_one(tmp_path: Path) -> None:
    from hevsim.cosim import simulate
    from hevsim.cosim.worker import WorkerFMUParticipant

    fmu = build_integrator_fmu(tmp_path / "f.fmu", name="ShmFail", y0=0.0)
    src = FunctionParticipant("s", lambda t, h, x, u: (x, {"y": 1.0}), 0, {"y": 1.0}, {})
    msgs = []
    for shm in (True, False):
        cls = type("W", (WorkerFMUParticipant,), {"shared_memory": shm})
        p = cls("f", fmu, {"stop_at": 0.25})
        with pytest.raises(CosimFault) as ei:
            simulate([src, p], [Connection("s", "y", "f", "u")], stop_time_s=1.0, step_s=0.1)
        msgs.append(str(ei.value))
        assert ei.value.partial is not None and ei.value.partial.time_s[-1] == pytest.approx(0.2)
        assert (p._seq > 0) == shm
    assert msgs[0] == msgs[1] and "participant 'f' failed in do_step at t = 0.2 s" in msgs[0]


def test_a_value_that_is_not_a_float_is_sent_pickled(integrator: Path) -> None:
    """A Real input given a value struct cannot pack goes by the pickled step (which reports
    it as before); float values go through the memory."""
    from hevsim.cosim.worker import WorkerFMUParticipant

    p = WorkerFMUParticipant("w", integrator, {"k": 1.0})
    try:
        p.setup(0.0)
        p.set_inputs({"u": 2})  # an int packs as a float
        assert p.do_step(0.0, 0.5) == (True, None) and p._seq == 1
        assert p.get_outputs() == {"y": 2.0}
        p.set_inputs({"u": "x"})
        with pytest.raises(SimulationError, match="set_inputs failed"):  # the phase it failed in
            p.do_step(0.5, 0.5)
        assert p._seq == 1  # not through the memory
    finally:
        p.terminate()


def test_polling_backs_off_while_it_is_not_answered_in_time(monkeypatch: pytest.MonkeyPatch) -> None:
    """Spin: a poll that runs out of time counts SPIN_MISS_WEIGHT misses and the next
    2**misses waits do not poll; a poll answered in time takes one miss off; the misses
    saturate; spin_s 0 never polls, nor does a machine with more runnable processes than
    cores."""
    import mmap

    import hevsim.cosim._worker as W
    from hevsim.cosim._worker import SPIN_BACKOFF_MAX, SPIN_MISS_WEIGHT, Spin, write_seq

    real = W.runnable_processes
    monkeypatch.setattr(W, "runnable_processes", lambda: 1)  # a free machine

    w = SPIN_MISS_WEIGHT
    mm = mmap.mmap(-1, 16)
    s = Spin(mm, 8, limit_s=1e-5)
    s.poll(1)  # the counter is 0: runs out of time
    assert (s.misses, s.skip) == (w, 2**w)
    for _ in range(2**w):
        s.poll(1)  # waits without polling
    assert (s.misses, s.skip) == (w, 0)
    write_seq(mm, 8, 1)
    s.poll(1)  # answered
    assert (s.misses, s.skip) == (w - 1, 0)
    for _ in range(3 * SPIN_BACKOFF_MAX):
        while s.skip:
            s.poll(2)
        s.poll(2)  # never answered: the misses saturate
    assert (s.misses, s.skip) == (SPIN_BACKOFF_MAX, 2**SPIN_BACKOFF_MAX)
    off = Spin(mm, 8, limit_s=0.0)
    off.poll(5)
    assert (off.misses, off.skip) == (0, 0)
    monkeypatch.setattr(W, "runnable_processes", lambda: 64)  # a crowded machine
    crowded = Spin(mm, 8, limit_s=1e-5)
    crowded.cores = 2
    for _ in range(3):
        crowded.poll(5)  # returns at once: no poll, no miss
    assert (crowded.misses, crowded.skip) == (0, 0) and crowded.crowded()
    n = real()
    assert n is None or n >= 1  # this process at least (Linux)

"""Model Exchange FMUs as participants (issue 30 item 1): the C models of tests/cosim_cme.py
against ``fmpy.simulate_fmu`` with the same solver (CVODE BDF) and settings (relative
tolerance 1e-5, output interval = communication step 0.01 s, no event rows): every output at
every communication point equal to 1e-12 (relative to 1 + |value|; in practice they are
bit-identical, the same solver called the same way), BouncingBall's state events, Stair's
time events and termination; CVODE Adams against the closed form; ME and CS participants
mixed, against the closed form; the default path (a forked worker) and ``--check``. FMI 2.0
and 3.0 versions of each model (tests/cosim_cme.py, tests/cosim_cme3.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tests.cosim_cfmu import build_c_fmu
from tests.cosim_cme import MODELS, build_me_fmu
from tests.cosim_cme3 import build_me_fmu3

from hevsim.cosim.master import Connection, simulate
from hevsim.cosim.me import MEParticipant
from hevsim.cosim.participant import FMUParticipant

H = 0.01


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("me")
    out = {name: build_me_fmu(name, d) for name in MODELS}
    out |= {f"{name}3": build_me_fmu3(name, d) for name in MODELS}  # FMI 3.0
    out["cs"] = build_c_fmu(d / "cs.fmu")
    return out


def fmpy_run(fmu: Path, stop: float) -> np.ndarray:
    from fmpy import simulate_fmu

    return simulate_fmu(str(fmu), stop_time=stop, output_interval=H, relative_tolerance=1e-5, solver="CVode",
                        record_events=False)  # fmt: skip


@pytest.mark.parametrize("fmi", ["2.0", "3.0"])
@pytest.mark.parametrize("name", ["BouncingBall", "Dahlquist", "VanDerPol", "Stair"])
def test_me_fmu_equals_fmpy(fmus: dict[str, Path], name: str, fmi: str) -> None:
    stop = float(MODELS[name]["stop"])  # type: ignore[arg-type]
    fmu = fmus[name if fmi == "2.0" else f"{name}3"]
    ref = fmpy_run(fmu, stop)
    p = MEParticipant("m", fmu)
    assert p.fmi3 == (fmi == "3.0")
    res = simulate([p], [], stop_time_s=stop, step_s=H)
    n = len(ref)
    assert n > 100 and np.array_equal(res.time_s[:n], ref["time"])
    for v in ref.dtype.names[1:]:
        a, b = ref[v].astype(float), res[f"m.{v}"][:n]
        assert np.max(np.abs(a - b) / (1 + np.abs(a))) <= 1e-12, (v, np.max(np.abs(a - b)))
    if name == "BouncingBall":  # state events: bounces located, the ball never below the floor
        assert p.events >= 5 and res["m.h"].min() >= -1e-9
        assert np.all(res["m.v"][-10:] == 0.0)  # at rest (v = 0 below 0.1 m/s)
    if name == "Stair":  # time events every second; termination at counter 10, t = 9 s
        assert p.events == 9 and res.stopped_by == "participant 'm' requested termination at t = 9 s"
        assert res.time_s[-1] == 9.0 and res["m.counter"][-1] == 10 and len(res.time_s) == n + 1
        assert res["m.counter"][np.searchsorted(res.time_s, 3.5)] == 4


def test_adams_and_bdf_against_the_closed_form(fmus: dict[str, Path]) -> None:
    """Dahlquist x = exp(-t): both CVODE methods to their tolerance."""
    t = np.arange(0, 1001) * H
    x = {}
    for solver in ("cvode-bdf", "cvode-adams"):
        p = MEParticipant("m", fmus["Dahlquist"], solver=solver, rtol=1e-8)
        x[solver] = simulate([p], [], stop_time_s=10.0, step_s=H)["m.x"]
        assert np.max(np.abs(x[solver] - np.exp(-t))) <= 1e-6, solver
    assert not np.array_equal(x["cvode-bdf"], x["cvode-adams"])  # two methods indeed


def test_mixed_me_and_cs_against_the_closed_form(fmus: dict[str, Path]) -> None:
    """Jacobi, h = 0.01 s: the CS integrator (y' = k u, k = 1) fed by the ME Dahlquist's
    x = exp(-t) gives y(t_n) = h sum_{j<n} exp(-t_j); the ME integrator (x' = u) fed by the CS
    integrator's y = t (its u = 1) gives x(t_n) = h^2 n (n - 1) / 2 (inputs held over each step:
    an input event and a solver restart at each communication point)."""
    parts = [
        MEParticipant("d", fmus["Dahlquist"], rtol=1e-10),
        FMUParticipant("cs", fmus["cs"]),
        FMUParticipant("src", fmus["cs"], {"u": 1.0}),
        MEParticipant("i", fmus["Integrator"]),
    ]
    conns = [Connection("d", "x", "cs", "u"), Connection("src", "y", "i", "u")]
    res = simulate(parts, conns, stop_time_s=1.0, step_s=H)
    n = np.arange(101)
    assert np.max(np.abs(res["cs.y"] - H * (1 - np.exp(-n * H)) / (1 - np.exp(-H)))) <= 1e-9
    assert np.max(np.abs(res["i.x"] - H * H * n * (n - 1) / 2)) <= 1e-12
    assert parts[3].events == 100  # the input changed at every communication point but the last


def test_me_fmus_on_the_default_path_and_check(fmus: dict[str, Path], tmp_path: Path) -> None:
    """An SSD with ME FMUs passes --check and runs on the default path (forked workers) with
    the in-process results; the step comes from their DefaultExperiment (0.01 s)."""
    from hevsim.cli import main
    from hevsim.cosim.ssd import FMU_TYPE, Component, SystemDescription
    from hevsim.cosim.ssp_write import write_ssd
    from hevsim.cosim.system import run_cosim

    for f in fmus.values():
        (tmp_path / f.name).write_bytes(f.read_bytes())
    desc = SystemDescription(
        "me", [Component("d", FMU_TYPE, "Dahlquist.fmu"), Component("cs", FMU_TYPE, "cs.fmu"),
               Component("b", FMU_TYPE, "BouncingBall.fmu")],
        [Connection("d", "x", "cs", "u")], stop_time_s=2.0, base_dir=tmp_path,
    )  # fmt: skip
    ssd = write_ssd(desc, tmp_path / "me.ssd")
    assert main(["cosim", str(ssd), "--check"]) == 0
    res = run_cosim(ssd, tmp_path / "out")
    ref = simulate([MEParticipant("d", fmus["Dahlquist"]), FMUParticipant("cs", fmus["cs"]),
                    MEParticipant("b", fmus["BouncingBall"])], [Connection("d", "x", "cs", "u")],
                   stop_time_s=2.0, step_s=0.01)  # fmt: skip
    assert res.stats["step_s"] == 0.01
    assert np.array_equal(res.time_s, ref.time_s)
    for c in ref.columns:
        assert np.array_equal(res[c], ref[c]), c


def test_me_worker_runs_ahead_packed_and_pipelined(fmus: dict[str, Path]) -> None:
    """The ME Van der Pol in a worker process: its run-ahead batches come back packed (one
    float64 buffer, no dict per step) and the next batch is sent while the master still takes
    the last one (the worker integrates while the master records); the results equal the
    in-process participant's bit for bit, also through a checkpoint taken with a batch in
    flight and restored into a fresh worker."""
    from hevsim.cosim.worker import WorkerFMUParticipant

    ref = simulate([MEParticipant("v", fmus["VanDerPol"])], [], stop_time_s=20.0, step_s=H)
    p = WorkerFMUParticipant("v", fmus["VanDerPol"])
    sent: list[tuple[int, int, int]] = []  # (the batch's first step, steps taken, steps buffered)
    taken = [0]
    packed: list[bool] = []
    real_send, real_recv, real_step = p._send, p._recv, p.do_step

    def send(cmd: str, *args: object) -> None:
        if cmd == "steps":
            sent.append((round(args[0][0][0] / H), taken[0], len(p._ahead)))  # type: ignore[index]
        real_send(cmd, *args)

    def recv(cmd: str) -> object:
        res = real_recv(cmd)
        if cmd == "steps":
            packed.append(res[0][0] == "packed")  # type: ignore[index]
        return res

    def do_step(t: float, h: float) -> tuple[bool, float | None]:
        res = real_step(t, h)
        taken[0] += 1
        return res

    p._send, p._recv, p.do_step = send, recv, do_step  # type: ignore[method-assign]
    res = simulate([p], [], stop_time_s=20.0, step_s=H)
    assert np.array_equal(res.data, ref.data) and np.array_equal(res.time_s, ref.time_s)
    assert packed and all(packed)
    assert len(sent) > 2 and sent[0] == (0, 0, 0)
    assert all(first > done for first, done, _ in sent[1:])  # pipelined: sent before the master needs it
    # and as soon as the last batch's reply is read, before it is unpacked into the buffer
    assert all(buffered == 0 for _, _, buffered in sent)


def test_me_worker_round_trips(fmus: dict[str, Path]) -> None:
    """The ME Van der Pol in a worker process: the run window goes with ``setup``, whose reply
    holds the first outputs (no ``window`` or ``get`` request), the batches run ahead are the
    only other requests, ``terminate`` and ``quit`` end the worker in one round trip (it exits
    with code 0); the results equal the in-process participant's bit for bit."""
    from hevsim.cosim.worker import WorkerFMUParticipant

    ref = simulate([MEParticipant("v", fmus["VanDerPol"])], [], stop_time_s=5.0, step_s=H)
    p = WorkerFMUParticipant("v", fmus["VanDerPol"])
    cmds: list[str] = []
    real_send = p._send

    def send(cmd: str, *args: object) -> None:
        cmds.append(cmd)
        real_send(cmd, *args)

    p._send = send  # type: ignore[method-assign]
    res = simulate([p], [], stop_time_s=5.0, step_s=H)
    assert np.array_equal(res.data, ref.data) and np.array_equal(res.time_s, ref.time_s)
    assert cmds[0] == "setup" and cmds[-1] == "terminate"
    assert set(cmds[1:-1]) == {"steps"}
    assert p.proc.poll() == 0


def test_me_fmu_clocks_against_the_closed_form(tmp_path: Path) -> None:
    """FMI 3.0 Model Exchange with clocks (tests/cosim_cme3_clocks.py): the periodic input
    clock (0.3 s, shift 0.1 s) ticks as a time event in event mode (fmi3SetClock, then the event
    iteration), wherever the communication points are; the output clock is read after the
    iteration. count = ticks so far, exactly; x = exp(-t) + sum exp(-(t - t_k)) to 1e-6 (rtol
    1e-8); the output clock with every third tick. Before: the clocks were not run (a warning)."""
    from tests.cosim_cme3_clocks import build_me_clocks_fmu

    fmu = build_me_clocks_fmu(tmp_path)
    tk = 0.1 + 0.3 * np.arange(7)
    for h in (0.05, 0.3):
        p = MEParticipant("m", fmu, rtol=1e-8)
        assert p.clock_inputs == {"tick": "constant"} and p.clock_outputs == {"third": "triggered"}
        res = simulate([p], [], stop_time_s=2.1, step_s=h)
        t = res.time_s
        count = [np.sum(tk <= ti + 1e-9) for ti in t]
        x = np.exp(-t) + [np.sum(np.exp(-(ti - tk[tk <= ti + 1e-9]))) for ti in t]
        np.testing.assert_array_equal(res["m.count"], count)
        assert np.max(np.abs(res["m.x"] - x)) <= 1e-6
        assert [c for _, c in p.clock_log] == ["tick"] * 2 + ["tick", "third"] + ["tick"] * 2 + [
            "tick",
            "third",
            "tick",
        ]
        np.testing.assert_allclose([s for s, c in p.clock_log if c == "third"], [0.7, 1.6], rtol=1e-12)

"""Model Exchange conformance on the Modelica Reference FMUs themselves (issue 30 item 1): the
models BouncingBall, Dahlquist, VanDerPol, Stair, Resource (FMI 2.0 and 3.0) and StateSpace
(FMI 3.0 only, array variables) compiled from their C sources (tests/cosim_reference.py), each
run as an :class:`MEParticipant` and by ``fmpy.simulate_fmu(fmi_type="ModelExchange")`` with
the same solver and settings (CVODE BDF, relative tolerance 1e-5, output interval = communication
step = stop time / 500, no event rows). Stated tolerance: every output at every communication
point equal to 1e-12 relative to 1 + |value| (the same solver called the same way: in practice
bit-identical). Independent references besides FMPy: StateSpace's closed form y = u exp(t)
(A = B = C = D = I, x0 = 0), Resource's y = 97 (the first character of resources/y.txt, "a"),
Stair's counter (one time event per second, termination at 10)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tests.cosim_reference import build_reference_fmu

from hevsim.cosim.master import simulate
from hevsim.cosim.me import MEParticipant

CASES = [(m, v) for m in ("BouncingBall", "Dahlquist", "VanDerPol", "Stair", "Resource") for v in (2, 3)]
CASES.append(("StateSpace", 3))
STOP = {"BouncingBall": 3.0, "Dahlquist": 10.0, "VanDerPol": 20.0, "Stair": 10.0, "Resource": 1.0,
        "StateSpace": 10.0}  # fmt: skip
"""The models' DefaultExperiment stop times [s]."""


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, int], Path]:
    d = tmp_path_factory.mktemp("reference")
    return {(m, v): build_reference_fmu(m, v, d) for m, v in CASES}


def fmpy_me(fmu: Path, stop: float, h: float) -> np.ndarray:
    from fmpy import simulate_fmu

    return simulate_fmu(str(fmu), fmi_type="ModelExchange", stop_time=stop, output_interval=h,
                        relative_tolerance=1e-5, solver="CVode", record_events=False)  # fmt: skip


def _columns(ref: np.ndarray, name: str) -> list[tuple[str, np.ndarray]]:
    """FMPy's column ``name`` as hevsim's scalar columns (an array ``y`` -> ``y[1]`` ..)."""
    a = ref[name].astype(float)
    if a.ndim == 1:
        return [(name, a)]
    return [(f"{name}[{k + 1}]", a[:, k]) for k in range(a.shape[1])]


@pytest.mark.parametrize(("model", "fmi"), CASES, ids=[f"{m}-fmi{v}" for m, v in CASES])
def test_reference_me_fmu_equals_fmpy(fmus: dict[tuple[str, int], Path], model: str, fmi: int) -> None:
    from fmpy import read_model_description

    fmu = fmus[model, fmi]
    md = read_model_description(str(fmu))
    assert md.modelExchange is not None and float(md.defaultExperiment.stopTime) == STOP[model]
    stop = STOP[model]
    h = 0.01 if model == "Stair" else stop / 500
    ref = fmpy_me(fmu, stop, h)
    p = MEParticipant("m", fmu)
    assert p.fmi3 == (fmi == 3)
    res = simulate([p], [], stop_time_s=stop, step_s=h)
    n = len(ref)
    assert n > 100 and np.array_equal(res.time_s[:n], ref["time"])
    checked = 0
    for v in ref.dtype.names[1:]:
        for col, a in _columns(ref, v):
            b = res[f"m.{col}"][:n]
            assert np.max(np.abs(a - b) / (1 + np.abs(a))) <= 1e-12, (col, np.max(np.abs(a - b)))
            checked += 1
    assert checked == len(res.columns)  # every output hevsim recorded is compared
    t = res.time_s
    if model == "StateSpace":  # y = u exp(t), u = (1, 2, 3): rtol 1e-5, global error grows with y
        for k, u in enumerate((1.0, 2.0, 3.0)):
            assert np.max(np.abs(res[f"m.y[{k + 1}]"] - u * np.exp(t)) / (u * np.exp(t))) <= 5e-4
    if model == "Resource":
        assert np.all(res["m.y"] == ord("a"))
    if model == "Stair":  # counter = 1 + floor(t) until it reaches 10 at t = 9 s: termination
        assert res.stopped_by == "participant 'm' requested termination at t = 9 s" and p.events == 9
        np.testing.assert_array_equal(res["m.counter"][:-1], 1 + np.floor(t[:-1] + 1e-9))
    if model == "BouncingBall":  # state events located: the ball never sinks below the floor
        assert p.events >= 8 and res["m.h"].min() >= -1e-6
    if model == "VanDerPol":  # the limit cycle's amplitude (about 2.0)
        assert 1.95 <= res["m.x0"][t >= 10].max() <= 2.05


@pytest.mark.parametrize("fmi", [2, 3])
def test_me_state_save_and_restore(fmus: dict[tuple[str, int], Path], fmi: int) -> None:
    """Issue 30 item 3: the Reference VanDerPol and BouncingBall (which declare
    canGetAndSetFMUstate) save their FMU state at t = 1 s; restored twice, the two replays are
    identical (CVODE re-initialised at the restored time from the restored states) and equal the
    uninterrupted run to the solver's tolerance (the integrator's history is not saved)."""
    grid = np.round(np.arange(301) * 0.01, 10)
    for model, var, tol in (("VanDerPol", "x0", 1e-3), ("BouncingBall", "h", 1e-3)):
        p = MEParticipant("m", fmus[model, fmi])
        assert p.can_save_state and not p.exact_restore
        p.run_window(0.0, 3.0)
        p.setup(0.0)
        for k in range(100):
            p.do_step(grid[k], 0.01)
        state = p.get_state()

        def run(p: MEParticipant = p, var: str = var) -> np.ndarray:
            out = []
            for k in range(100, 300):
                p.do_step(grid[k], grid[k + 1] - grid[k])
                out.append(p.get_outputs()[var])
            return np.array(out)

        a = run()
        with pytest.raises(Exception, match="goes back only by restoring a saved state"):
            p.do_step(1.0, 0.01)
        p.set_state(state)
        b = run()
        p.set_state(state)
        c = run()
        p.terminate()
        assert np.array_equal(b, c), model
        assert np.max(np.abs(a - b)) <= tol, (model, np.max(np.abs(a - b)))


def test_me_participant_under_iteration_equals_the_exact_hold(fmus: dict[tuple[str, int], Path]) -> None:
    """Iterative coupling (refused for ME participants before: it restores states): the
    Reference StateSpace (x' = x + u, y = x + u, first component) in a loop u = 1 - 0.5 y,
    Jacobi, 8 iterations per step, against the same loop with the exact zero-order-hold solution
    of the state-space model (x(t + h) = e^h x + (e^h - 1) u) in its place: equal to 1e-5 with
    CVODE at rtol 1e-8 (both about 1.2964 at t = 1 s, the continuous loop's closed form
    -1 + e^(2/3) + (3 - e^(2/3)) / 3 = 1.2985 up to the hold's O(h))."""
    import math

    from hevsim.cosim.master import Connection
    from hevsim.cosim.participant import FunctionParticipant

    def exact(t: float, h: float, x: float, u: dict[str, float]) -> tuple[float, dict[str, float]]:
        x1 = math.exp(h) * x + math.expm1(h) * u["u[1]"]
        return x1, {"y[1]": x1 + u["u[1]"]}

    out = []
    for ss in (MEParticipant("ss", fmus["StateSpace", 3], rtol=1e-8),
               FunctionParticipant("ss", exact, 0.0, {"y[1]": 1.0}, {"u[1]": ""})):  # fmt: skip
        fb = FunctionParticipant(
            "fb", lambda t, h, s, u: (s, {"u": 1.0 - 0.5 * u["y"]}), 0, {"u": 1.0}, {"y": ""}
        )
        conns = [Connection("ss", "y[1]", "fb", "y"), Connection("fb", "u", "ss", "u[1]")]
        out.append(simulate([ss, fb], conns, stop_time_s=1.0, step_s=0.01, max_iterations=8, tolerance=1e-9))
    me, ref = out
    assert np.max(np.abs(me["ss.y[1]"] - ref["ss.y[1]"])) <= 1e-5
    assert abs(ref["ss.y[1]"][-1] - (-1 + math.exp(2 / 3) + (3 - math.exp(2 / 3)) / 3)) <= 5e-3


def test_me_fmu_with_state_under_iteration_from_an_ssd(
    fmus: dict[tuple[str, int], Path], tmp_path: Path
) -> None:
    """An SSD with the Reference VanDerPol as a Model Exchange only FMU (it declares
    canGetAndSetFMUstate) and iterative coupling: ``--check`` passes it (refused before, as
    "cannot save and restore its state") and the run (a forked worker on the default path)
    gives the in-process participant's results."""
    from hevsim.cli import main
    from hevsim.cosim.ssd import FMU_TYPE, Component, SystemDescription
    from hevsim.cosim.ssp_write import write_ssd
    from hevsim.cosim.system import run_cosim

    fmu = build_reference_fmu("VanDerPol", 2, tmp_path, me_only=True)
    desc = SystemDescription("me", [Component("v", FMU_TYPE, fmu.name)], [], stop_time_s=2.0,
                             master={"step_s": 0.01, "max_iterations": 3}, base_dir=tmp_path)  # fmt: skip
    ssd = write_ssd(desc, tmp_path / "me.ssd")
    assert main(["cosim", str(ssd), "--check"]) == 0
    res = run_cosim(ssd, tmp_path / "out")
    assert res.stats["fmu_process"] == {"v": "worker process"}
    ref = simulate([MEParticipant("v", fmu)], [], stop_time_s=2.0, step_s=0.01, max_iterations=3)
    assert np.array_equal(res["v.x0"], ref["v.x0"]) and np.array_equal(res["v.x1"], ref["v.x1"])


@pytest.mark.parametrize(("model", "fmi"), CASES, ids=[f"{m}-fmi{v}" for m, v in CASES])
def test_reference_cs_fmu_equals_fmpy(fmus: dict[tuple[str, int], Path], model: str, fmi: int) -> None:
    """The same Reference FMUs through their co-simulation interface (:class:`FMUParticipant`,
    in process; the FMI 3.0 BouncingBall and Stair declare event mode, which hevsim uses)
    against ``fmpy.simulate_fmu(fmi_type="CoSimulation")`` with the output interval as the
    communication step: every output at every point equal to 1e-12 (in practice identical)."""
    from fmpy import simulate_fmu

    from hevsim.cosim.participant import FMUParticipant

    fmu, stop = fmus[model, fmi], STOP[model]
    h = 0.01 if model == "Stair" else stop / 500
    ref = simulate_fmu(str(fmu), fmi_type="CoSimulation", stop_time=stop, output_interval=h)
    res = simulate([FMUParticipant("m", fmu)], [], stop_time_s=stop, step_s=h)
    n = len(ref)
    assert n > 100 and np.array_equal(res.time_s[:n], ref["time"])
    for v in ref.dtype.names[1:]:
        for col, a in _columns(ref, v):
            assert np.max(np.abs(a - res[f"m.{col}"][:n]) / (1 + np.abs(a))) <= 1e-12, col

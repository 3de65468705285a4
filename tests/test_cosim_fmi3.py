"""FMI 3.0 co-simulation FMUs (built with pythonfmu3) through FMPy.

FMUs are loaded only in worker processes (:class:`WorkerFMUParticipant`) or in a child
process: pythonfmu binaries still loaded at exit can abort the host (they release their
interpreter handle twice, :mod:`hevsim._pythonfmu_exit`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pythonfmu3")

from tests.cosim_helpers import interrupt_after, run_child

from hevsim.cosim import Connection, CosimFault, simulate
from hevsim.cosim.trivial import build_integrator_fmu, build_integrator_fmu3
from hevsim.cosim.worker import WorkerFMUParticipant as W


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("fmus3")
    return {
        "x": build_integrator_fmu3(d / "x.fmu", name="Cosim3X", y0=1.0),
        "v": build_integrator_fmu3(d / "v.fmu", name="Cosim3V", y0=0.0),
        "k": build_integrator_fmu3(d / "k.fmu", name="Cosim3K", y0=300.0, unit="K"),
        "c": build_integrator_fmu3(d / "c.fmu", name="Cosim3C", y0=0.0, unit="degC"),
        "x2": build_integrator_fmu(d / "x2.fmu", name="Cosim2X", y0=1.0),  # FMI 2.0
    }


def oscillator(fmus: dict[str, Path], x_params: dict | None = None, x: str = "x") -> tuple[list, list]:
    """x' = v, v' = -x from two integrator FMUs: x(t) = cos t."""
    parts = [W("x", fmus[x], x_params or {}), W("v", fmus["v"], {"k": -1.0})]
    return parts, [Connection("v", "y", "x", "u"), Connection("x", "y", "v", "u")]


def test_fmi3_model_description_and_validation(fmus: dict[str, Path]) -> None:
    import fmpy
    from fmpy.validation import validate_fmu

    for key in ("x", "c"):
        md = fmpy.read_model_description(str(fmus[key]))
        assert md.fmiVersion == "3.0"
        assert md.coSimulation is not None
        assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
        assert md.coSimulation.canHandleVariableCommunicationStepSize
        assert validate_fmu(str(fmus[key])) == []
    c = W("c", fmus["c"])
    try:
        assert c.inputs == {"u": "degC"} and c.outputs == {"y": "degC"}
    finally:
        c.close()


def test_fmi3_unit_conversion_k_to_degc(fmus: dict[str, Path]) -> None:
    k = W("k", fmus["k"], {"k": 0.0})  # holds 300 K
    c = W("c", fmus["c"], {"k": 1.0})  # integrates its input in degC
    res = simulate([k, c], [Connection("k", "y", "c", "u")], stop_time_s=1.0, step_s=0.5)
    assert res["k.y"][-1] == 300.0
    assert res["c.y"][-1] == pytest.approx(300.0 - 273.15, rel=1e-12)


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_fmi3_oscillator_first_order(fmus: dict[str, Path], algorithm: str) -> None:
    errs = []
    for h in (0.02, 0.01):
        res = simulate(*oscillator(fmus), stop_time_s=3.0, step_s=h, algorithm=algorithm)
        assert res.time_s[-1] == pytest.approx(3.0)
        errs.append(np.abs(res["x.y"] - np.cos(res.time_s)).max())
    order = np.log2(errs[0] / errs[1])
    assert 0.85 < order < 1.15, errs
    assert errs[1] < (0.02 if algorithm == "jacobi" else 0.006), errs


def test_fmi3_iterated_coupling_restores_state(fmus: dict[str, Path]) -> None:
    res = simulate(*oscillator(fmus), stop_time_s=1.0, step_s=0.05, max_iterations=20, tolerance=1e-12)
    assert res.stats["iterations"] > res.stats["steps"]  # states were restored and steps redone
    assert res.stats["max_residual"] <= 1e-12
    assert np.abs(res["x.y"] - np.cos(res.time_s)).max() < 5e-4  # 2nd order once iterated


def test_fmi3_mixed_with_fmi2_identical(fmus: dict[str, Path]) -> None:
    a = simulate(*oscillator(fmus), stop_time_s=1.0, step_s=0.1)
    b = simulate(*oscillator(fmus, x="x2"), stop_time_s=1.0, step_s=0.1)
    assert np.array_equal(a.data, b.data)


def test_fmi3_state_roundtrip_bit_identical(fmus: dict[str, Path]) -> None:
    p = W("x", fmus["x"], {"k": 0.3})
    try:
        p.setup(0.0)
        for i in range(3):
            p.set_inputs({"u": 0.1 * i + 1 / 3})
            p.do_step(0.1 * i, 0.1)
        state = p.get_state()
        assert isinstance(state, bytes) and state

        def cont() -> list[float]:
            out = []
            for i in range(3, 6):
                p.set_inputs({"u": np.sin(i)})
                p.do_step(0.1 * i, 0.1)
                out.append(p.get_outputs()["y"])
            return out

        first = cont()
        p.set_state(state)
        assert cont() == first
    finally:
        p.terminate()


def test_fmi3_checkpoint_resume_identical(fmus: dict[str, Path], tmp_path: Path) -> None:
    ck = tmp_path / "ck.pkl"
    interrupt_after(lambda **kw: simulate(*oscillator(fmus), **kw), 0.55,
                    stop_time_s=1.0, step_s=0.1, checkpoint_path=ck, checkpoint_every=1)  # fmt: skip
    assert ck.is_file()
    full = simulate(*oscillator(fmus), stop_time_s=1.0, step_s=0.1)
    resumed = simulate(*oscillator(fmus), stop_time_s=1.0, step_s=0.1, checkpoint_path=ck, resume=True)
    assert np.array_equal(resumed.time_s, full.time_s)
    assert np.array_equal(resumed.data, full.data)


def test_fmi3_failing_fmu_names_participant_time_and_call(fmus: dict[str, Path]) -> None:
    with pytest.raises(
        CosimFault, match=r"participant 'x' failed in do_step at t = 0.3 s: .*fmi3DoStep"
    ) as ei:
        simulate(*oscillator(fmus, {"stop_at": 0.35}), stop_time_s=1.0, step_s=0.1)
    assert ei.value.partial is not None and ei.value.partial.time_s[-1] == pytest.approx(0.3)


def test_fmi3_terminate_simulation_stops_run(fmus: dict[str, Path]) -> None:
    res = simulate(*oscillator(fmus, {"terminate_at": 0.5}), stop_time_s=3.0, step_s=0.1)
    assert res.stopped_by == "participant 'x' requested termination at t = 0.5 s"
    assert res.time_s[-1] == pytest.approx(0.5)
    full = simulate(*oscillator(fmus), stop_time_s=1.0, step_s=0.1)
    assert np.array_equal(res.data, full.data[:6])


def test_fmi3_discarded_step_is_redone_shorter(fmus: dict[str, Path]) -> None:
    res = simulate(*oscillator(fmus, {"discard_above": 0.05}), stop_time_s=0.5, step_s=0.1, max_iterations=2)
    assert res.stats["rejected"] == 9  # each 0.1 s step discarded, redone as 0.05 s (the last fits)
    ref = simulate(*oscillator(fmus), stop_time_s=0.5, step_s=0.05, max_iterations=2)
    # same steps up to round-off: the grid here is 0.1 n (+ 0.05), there 0.05 n
    assert np.allclose(res.time_s, ref.time_s, rtol=0, atol=1e-15)
    assert np.allclose(res.data, ref.data, rtol=1e-12, atol=1e-15)
    with pytest.raises(CosimFault, match="redoing it needs saved states"):
        simulate(*oscillator(fmus, {"discard_above": 0.05}), stop_time_s=0.5, step_s=0.1)
    # x asks to terminate in a step that v then discards: the request is void once redone
    parts = [W("x", fmus["x"], {"terminate_at": 0.5}), W("v", fmus["v"], {"k": -1.0, "discard_above": 0.05})]
    conns = [Connection("v", "y", "x", "u"), Connection("x", "y", "v", "u")]
    res = simulate(parts, conns, stop_time_s=3.0, step_s=0.1, max_iterations=2)
    assert res.stopped_by == "participant 'x' requested termination at t = 0.5 s"
    assert res.time_s[-1] == pytest.approx(0.5) and len(res.time_s) == 11


# The in-process FMUParticipant's FMI 3.0 code, in a child process that prints JSON and
# leaves with os._exit.
_INPROCESS = """
from hevsim.cosim import Connection, CosimFault, simulate
from hevsim.cosim.participant import FMUParticipant as F
f = json.loads(sys.argv[1])
def osc(**xp):
    return ([F("x", f["x"], xp), F("v", f["v"], {"k": -1.0})],
            [Connection("v", "y", "x", "u"), Connection("x", "y", "v", "u")])
out = {}
r = simulate(*osc(), stop_time_s=1.0, step_s=0.05, max_iterations=20, tolerance=1e-12)
out["iterated"] = r.data.tolist()
out["stopped_by"] = simulate(*osc(terminate_at=0.5), stop_time_s=3.0, step_s=0.1).stopped_by
r = simulate(*osc(discard_above=0.05), stop_time_s=0.5, step_s=0.1, max_iterations=2)
out["rejected"] = r.stats["rejected"]
r = simulate(*osc(), stop_time_s=1.0, step_s=0.1, checkpoint_path=f["ck"], resume=True)
out["resumed"] = r.data.tolist()
try:
    simulate(*osc(stop_at=0.35), stop_time_s=1.0, step_s=0.1)
except CosimFault as e:
    out["fault"] = str(e)
finish(out)
"""


def test_fmi3_in_process_participant_matches_worker(fmus: dict[str, Path], tmp_path: Path) -> None:
    ck = tmp_path / "ck.pkl"
    # a worker run's checkpoint, resumed in process
    interrupt_after(lambda **kw: simulate(*oscillator(fmus), **kw), 0.55,
                    stop_time_s=1.0, step_s=0.1, checkpoint_path=ck, checkpoint_every=1)  # fmt: skip
    full = simulate(*oscillator(fmus), stop_time_s=1.0, step_s=0.1)
    iterated = simulate(*oscillator(fmus), stop_time_s=1.0, step_s=0.05, max_iterations=20, tolerance=1e-12)
    out = run_child(_INPROCESS, {k: str(v) for k, v in fmus.items()} | {"ck": str(ck)})
    assert np.array_equal(np.array(out["iterated"]), iterated.data)
    assert out["stopped_by"] == "participant 'x' requested termination at t = 0.5 s"
    assert out["rejected"] == 9
    assert np.array_equal(np.array(out["resumed"]), full.data)
    assert "participant 'x' failed in do_step at t = 0.3 s: fmi3DoStep failed" in out["fault"]
    assert "FMU log: [FATAL]" in out["fault"] and "integrator asked to fail" in out["fault"]

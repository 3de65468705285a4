"""FMU participants (FMPy, in process and in a worker process), faults and bad FMU input."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from tests.cosim_helpers import interrupt_after, run_child

from hevsim.cosim import Connection, CosimFault, StepperParticipant, simulate
from hevsim.cosim.participant import FMUParticipant
from hevsim.cosim.trivial import build_integrator_fmu
from hevsim.cosim.worker import WorkerFMUParticipant
from hevsim.errors import ConfigError


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("fmus")
    return {
        "x": build_integrator_fmu(d / "x.fmu", name="CosimTestX", y0=1.0),
        "v": build_integrator_fmu(d / "v.fmu", name="CosimTestV", y0=0.0),
        "k": build_integrator_fmu(d / "k.fmu", name="CosimTestK", y0=300.0, unit="K"),
        "c": build_integrator_fmu(d / "c.fmu", name="CosimTestC", y0=0.0, unit="degC"),
    }


def oscillator(fmus: dict[str, Path], cls: type) -> tuple[list, list[Connection]]:
    """x' = v, v' = -x from two integrator FMUs: x(t) = cos t."""
    x = cls("x", fmus["x"])
    v = cls("v", fmus["v"], {"k": -1.0})
    return [x, v], [Connection("v", "y", "x", "u"), Connection("x", "y", "v", "u")]


@pytest.mark.parametrize("cls", [WorkerFMUParticipant])
def test_fmu_oscillator_first_order(fmus: dict[str, Path], cls: type) -> None:
    errs = []
    for h in (0.02, 0.01):
        res = simulate(*oscillator(fmus, cls), stop_time_s=3.0, step_s=h, algorithm="gauss-seidel")
        errs.append(np.abs(res["x.y"] - np.cos(res.time_s)).max())
    order = np.log2(errs[0] / errs[1])
    assert 0.85 < order < 1.15, errs
    assert errs[1] < 0.02


# pythonfmu binaries still loaded at exit release their interpreter handle twice and can abort
# the host (hevsim._pythonfmu_exit; hevsim cosim releases it, a bare FMPy host of these test
# FMUs does not), so in-process runs happen in a child process that prints its results as JSON
# and leaves with os._exit; the test process only loads FMUs in workers.
_INPROCESS = """
import numpy as np
from hevsim.cosim import Connection, CosimFault, simulate
from hevsim.cosim.participant import FMUParticipant as F
f = json.loads(sys.argv[1])
osc = lambda: ([F("x", f["x"]), F("v", f["v"], {"k": -1.0})],
               [Connection("v", "y", "x", "u"), Connection("x", "y", "v", "u")])
out = {}
r = simulate(*osc(), stop_time_s=1.0, step_s=0.05, max_iterations=20, tolerance=1e-12)
out["iterated"] = r.data.tolist()
errs = []
for h in (0.02, 0.01):
    r = simulate(*osc(), stop_time_s=3.0, step_s=h, algorithm="gauss-seidel")
    errs.append(float(np.abs(r["x.y"] - np.cos(r.time_s)).max()))
out["errs"] = errs
k, c = F("k", f["k"], {"k": 0.0}), F("c", f["c"], {"k": 1.0})
out["degc"] = simulate([k, c], [Connection("k", "y", "c", "u")], stop_time_s=1.0, step_s=0.5)["c.y"].tolist()
r = simulate(*osc(), stop_time_s=1.0, step_s=0.1, checkpoint_path=f["ck"], resume=True)
out["resumed"] = r.data.tolist()
x = F("x", f["x"], {"stop_at": 0.35})
try:
    simulate([x, F("v", f["v"], {"k": -1.0})], [Connection("x", "y", "v", "u")], stop_time_s=1.0, step_s=0.1)
except CosimFault as e:
    out["fault"] = str(e)
    out["partial_t"] = float(e.partial.time_s[-1])
finish(out)
"""


def test_in_process_fmu_participant(fmus: dict[str, Path], tmp_path: Path) -> None:
    ck = tmp_path / "ck.pkl"
    # a checkpoint written by a run of worker FMUs, resumed in process
    interrupt_after(lambda **kw: simulate(*oscillator(fmus, WorkerFMUParticipant), **kw), 0.55,
                    stop_time_s=1.0, step_s=0.1, checkpoint_path=ck, checkpoint_every=1)  # fmt: skip
    full = simulate(*oscillator(fmus, WorkerFMUParticipant), stop_time_s=1.0, step_s=0.1)
    worker_iter = simulate(*oscillator(fmus, WorkerFMUParticipant), stop_time_s=1.0, step_s=0.05,
                           max_iterations=20, tolerance=1e-12)  # fmt: skip
    out = run_child(_INPROCESS, {k: str(v) for k, v in fmus.items()} | {"ck": str(ck)})
    assert np.array_equal(np.array(out["iterated"]), worker_iter.data)  # worker == in process
    assert np.abs(worker_iter["x.y"] - np.cos(worker_iter.time_s)).max() < 5e-4  # 2nd order once iterated
    e1, e2 = out["errs"]
    assert 0.85 < np.log2(e1 / e2) < 1.15 and e2 < 0.02
    assert out["degc"][-1] == pytest.approx(300.0 - 273.15, rel=1e-12)  # 300 K seen as 26.85 degC
    assert np.array_equal(np.array(out["resumed"]), full.data)
    assert "participant 'x' failed in do_step at t = 0.3 s" in out["fault"] and out[
        "partial_t"
    ] == pytest.approx(0.3)


def test_fmu_unit_conversion_degc_to_k_in_worker(fmus: dict[str, Path]) -> None:
    k = WorkerFMUParticipant("k", fmus["k"], {"k": 0.0})  # holds 300 K
    c = WorkerFMUParticipant("c", fmus["c"], {"k": 1.0})  # integrates its input in degC
    res = simulate([k, c], [Connection("k", "y", "c", "u")], stop_time_s=1.0, step_s=0.5)
    assert res["k.y"][-1] == 300.0
    assert res["c.y"][-1] == pytest.approx(300.0 - 273.15, rel=1e-12)


@pytest.mark.parametrize("cls", [WorkerFMUParticipant])
def test_fmu_error_names_participant_time_and_call(fmus: dict[str, Path], cls: type) -> None:
    x = cls("x", fmus["x"], {"stop_at": 0.35})
    v = cls("v", fmus["v"], {"k": -1.0})
    with pytest.raises(CosimFault, match=r"participant 'x' failed in do_step at t = 0.3 s") as ei:
        simulate(
            [x, v],
            [Connection("v", "y", "x", "u"), Connection("x", "y", "v", "u")],
            stop_time_s=1.0,
            step_s=0.1,
        )
    assert ei.value.partial is not None and ei.value.partial.time_s[-1] == pytest.approx(0.3)


def test_worker_crash_contained(fmus: dict[str, Path]) -> None:
    parts, conns = oscillator(fmus, WorkerFMUParticipant)

    def kill(t: float, stop: float) -> None:
        if t >= 0.5 - 1e-9 and parts[1].proc.poll() is None:
            os.kill(parts[1].proc.pid, 9)
            parts[1].proc.wait()

    with pytest.raises(CosimFault, match=r"participant 'v' failed in do_step at t = 0.5 s: .*worker process"):
        simulate(parts, conns, stop_time_s=1.0, step_s=0.1, progress=kill)


def test_missing_and_corrupt_fmu_and_variable(fmus: dict[str, Path], tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"FMU file .*nope\.fmu' does not exist"):
        FMUParticipant("a", tmp_path / "nope.fmu")
    bad = tmp_path / "bad.fmu"
    bad.write_bytes(b"this is not a zip archive")
    with pytest.raises(ConfigError, match=r"participant 'a': .*bad\.fmu is not a valid FMU"):
        FMUParticipant("a", bad)
    with pytest.raises(ConfigError, match=r"participant 'w': .*bad\.fmu is not a valid FMU"):
        WorkerFMUParticipant("w", bad)
    with pytest.raises(ConfigError, match="has no variable 'gain'"):
        FMUParticipant("a", fmus["x"], {"gain": 2.0})
    x, v = oscillator(fmus, FMUParticipant)[0]
    with pytest.raises(ConfigError, match="participant 'x' has no input 'w'"):
        simulate([x, v], [Connection("v", "y", "x", "w")], stop_time_s=1.0, step_s=0.1)


def test_stepper_participant_matches_cell_fmu(tmp_path: Path) -> None:
    from hevsim.battery.fmu import export_fmu

    fmu = export_fmu(
        "thesis_table_4_1",
        tmp_path / "cell.fmu",
        soc_initial=0.9,
        temp_initial_k=303.15,
        model_name="CosimCell",
    )
    from hevsim.cosim import FunctionParticipant

    def load(t, h, x, u):
        return x, {"current_a": 20.0 if int(t) % 2 == 0 else -10.0, "port_temp_k": 300.0}

    src = FunctionParticipant("load", load, 0.0, {"current_a": 20.0, "port_temp_k": 300.0}, {})
    conns = [
        Connection("load", "current_a", "cell", "current_a"),
        Connection("load", "port_temp_k", "cell", "port_temp_k"),
    ]
    a = simulate(
        [src, StepperParticipant("cell", soc_initial=0.9, temp_initial_k=303.15)],
        conns,
        stop_time_s=10,
        step_s=0.5,
    )
    src = FunctionParticipant("load", load, 0.0, {"current_a": 20.0, "port_temp_k": 300.0}, {})
    b = simulate([src, WorkerFMUParticipant("cell", fmu)], conns, stop_time_s=10, step_s=0.5)
    for k in ("voltage_v", "soc", "temp_k", "port_heat_w"):
        assert np.allclose(a[f"cell.{k}"][1:], b[f"cell.{k}"][1:], rtol=1e-10, atol=1e-12), k

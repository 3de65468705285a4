"""FMI 3.0 clocks in co-simulation (issue 30 item 2): the C FMUs of
tests/cosim_cfmu3_clocks.py. A periodic input clock (interval 0.3 s, shift 0.1 s) ticks in
event mode at its tick times, the communication steps (0.25 s) cut there; a triggered output
clock (every 0.7 s, early return) ticks the other FMU's triggered input clock through a clock
connection, carrying its clocked output to the clocked input. Against the closed-form schedule
below; the source FMU's clocked output also against FMPy (``simulate_fmu`` with event mode and
early return; FMPy 0.3 does not activate input clocks (no fmi3SetClock in its co-simulation
loop), so the counter is compared with the closed form only)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from tests.cosim_cfmu3_clocks import build_counter_fmu3, build_source_fmu3

from hevsim.cosim.master import Connection, simulate
from hevsim.cosim.participant import FMUParticipant
from hevsim.cosim.worker import WorkerFMUParticipant
from hevsim.errors import ConfigError

STEP_S, STOP_S = 0.25, 2.0
TIMES = [i * STEP_S for i in range(9)]
# t [s]: (count, trig_count, last_k) -- periodic ticks at 0.1 + 0.3 k (0.1 .. 1.9), triggered
# ticks at 0.7 and 1.4 (the source's output clock) carrying n_out = 10, 20
SCHEDULE = {
    0.0: (0, 0, 0),
    0.25: (1, 0, 0),  # 0.1
    0.5: (2, 0, 0),  # 0.4
    0.75: (3, 1, 10),  # 0.7 periodic and triggered in one event
    1.0: (4, 1, 10),  # 1.0
    1.25: (4, 1, 10),
    1.5: (5, 2, 20),  # 1.3, 1.4 triggered
    1.75: (6, 2, 20),  # 1.6
    2.0: (7, 2, 20),  # 1.9
}


def closed_form(t: float) -> tuple[int, int, int]:
    count = sum(1 for k in range(100) if 0.1 + 0.3 * k <= t + 1e-9)
    trig = math.floor(t / 0.7 + 1e-9)
    return count, trig, 10 * trig


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("clocks3")
    return {
        "counter": build_counter_fmu3(d),
        "source": build_source_fmu3(d),
        "fixed": build_counter_fmu3(d, "FixedCounter", "fixed", in_md=False),
        "tunable": build_counter_fmu3(d, "TunableCounter", "tunable"),
    }


def connections() -> list[Connection]:
    return [Connection("s", "out", "c", "trig"), Connection("s", "n_out", "c", "k_in")]


def test_the_schedule_table_is_the_closed_form() -> None:
    assert all(SCHEDULE[t] == closed_form(t) for t in TIMES)


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_periodic_and_triggered_clocks_follow_the_schedule(fmus: dict[str, Path], algorithm: str) -> None:
    # the ticks of a clock connection reach the receiver in the same step under both
    # algorithms (its source steps first); listed receiver first
    c, s = FMUParticipant("c", fmus["counter"]), FMUParticipant("s", fmus["source"])
    assert "k_in" not in c.inputs and c.clocked_inputs == {"k_in": "trig"}
    res = simulate([c, s], connections(), stop_time_s=STOP_S, step_s=STEP_S, algorithm=algorithm)
    assert np.allclose(res.time_s, TIMES, rtol=0, atol=1e-12)
    got = list(
        zip(res["c.count"].tolist(), res["c.trig_count"].tolist(), res["c.last_k"].tolist(), strict=True)
    )
    assert got == [SCHEDULE[t] for t in TIMES]
    assert res["s.n_out"].tolist() == [10 * math.floor(t / 0.7 + 1e-9) for t in TIMES]
    ticks = [(round(t, 9), k) for t, k in c.clock_log]
    periodic = [round(0.1 + 0.3 * k, 9) for k in range(7)]
    assert ticks == sorted([(t, "tick") for t in periodic] + [(0.7, "trig"), (1.4, "trig")])
    assert [(round(t, 9), k) for t, k in s.clock_log] == [(0.7, "out"), (1.4, "out")]


def test_ticks_on_communication_points(fmus: dict[str, Path]) -> None:
    # step 0.35 s: the source's ticks (0.7, 1.4) end its steps (eventHandlingNeeded at the step's
    # end, no early return) and the counter's ticks at 0.7 and 1.0 .. fall on or between the
    # points; the last step is 0.25 s (stop 2.0)
    c, s = FMUParticipant("c", fmus["counter"]), FMUParticipant("s", fmus["source"])
    res = simulate([c, s], connections(), stop_time_s=STOP_S, step_s=0.35)
    times = [0.35 * i for i in range(6)] + [STOP_S]
    assert np.allclose(res.time_s, times, rtol=0, atol=1e-12)
    got = list(
        zip(res["c.count"].tolist(), res["c.trig_count"].tolist(), res["c.last_k"].tolist(), strict=True)
    )
    assert got == [closed_form(t) for t in times]
    assert [(round(t, 9), k) for t, k in s.clock_log] == [(0.7, "out"), (1.4, "out")]


def test_interval_from_fmi3GetIntervalDecimal_and_a_tick_at_the_start(fmus: dict[str, Path]) -> None:
    # intervalVariability="fixed", no interval in the model description: 0.3 s from the FMU,
    # no shift: ticks at 0 (in the initial event mode), 0.3, .., 1.8; nothing connected to trig
    for cls in (FMUParticipant, WorkerFMUParticipant):
        res = simulate([cls("f", fmus["fixed"])], [], stop_time_s=STOP_S, step_s=STEP_S)
        assert res["f.count"].tolist() == [math.floor(t / 0.3 + 1e-9) + 1 for t in TIMES], cls
        assert res["f.trig_count"].tolist() == [0] * len(TIMES)


def test_periodic_clock_in_a_worker_process(fmus: dict[str, Path]) -> None:
    res = simulate([WorkerFMUParticipant("c", fmus["counter"])], [], stop_time_s=STOP_S, step_s=STEP_S)
    assert res["c.count"].tolist() == [SCHEDULE[t][0] for t in TIMES]


def test_source_clocked_output_equals_fmpy(fmus: dict[str, Path]) -> None:
    from fmpy import simulate_fmu

    res = simulate([FMUParticipant("s", fmus["source"])], [], stop_time_s=STOP_S, step_s=STEP_S)
    ref = simulate_fmu(str(fmus["source"]), stop_time=STOP_S, output_interval=STEP_S, use_event_mode=True,
                       early_return_allowed=True)  # fmt: skip
    last = {round(float(r["time"]), 9): int(r["n_out"]) for r in ref}  # the row after an event
    common = [i for i, t in enumerate(TIMES) if round(t, 9) in last]
    assert len(common) == len(TIMES)
    assert [int(res["s.n_out"][i]) for i in common] == [last[round(TIMES[i], 9)] for i in common]


@pytest.mark.parametrize(
    ("conns", "kwargs", "message"),
    [
        (connections(), {"order": ["c", "s"]}, "clock connection s -> c: 's' must step before 'c'"),
        ([Connection("s", "out", "c", "tick")], {}, "input clock c.tick is periodic"),
        ([Connection("s", "n_out", "c", "trig")], {}, "a clock connects only an output clock to an"),
        ([Connection("s", "out", "c", "trig"), Connection("c", "count", "c", "k_in")], {},
         "c.k_in is clocked by input clock 'trig'"),
        ([Connection("s", "n_out", "c", "k_in")], {}, "c.k_in is clocked by input clock 'trig'"),
    ],
)  # fmt: skip
def test_unsupported_clock_connections_are_refused(
    fmus: dict[str, Path], conns: list[Connection], kwargs: dict[str, str], message: str
) -> None:
    c, s = FMUParticipant("c", fmus["counter"]), FMUParticipant("s", fmus["source"])
    with pytest.raises(ConfigError, match=None) as exc:
        simulate([c, s], conns, stop_time_s=STOP_S, step_s=STEP_S, **kwargs)
    assert message in str(exc.value)


def test_clock_connection_to_a_worker_is_refused(fmus: dict[str, Path]) -> None:
    c, s = WorkerFMUParticipant("c", fmus["counter"]), FMUParticipant("s", fmus["source"])
    try:
        with pytest.raises(ConfigError, match="clock connections need both FMUs in process"):
            simulate([c, s], connections()[:1], stop_time_s=STOP_S, step_s=STEP_S)
    finally:
        c.terminate()


def test_input_clock_of_another_interval_variability_is_refused(fmus: dict[str, Path]) -> None:
    with pytest.raises(ConfigError, match="input clock 'tick' has intervalVariability=\"tunable\""):
        FMUParticipant("t", fmus["tunable"])


def test_system_description_with_clock_connections_runs_them_in_process(fmus: dict[str, Path]) -> None:
    # the run an SSD gives (datacheck, fmu_process "auto"): FMUs with a connected clock run in
    # process (other C FMUs in workers), the static check passes Clock -> Clock only
    from hevsim.cosim.datacheck import datacheck
    from hevsim.cosim.ssd import FMU_TYPE, Component, SystemDescription
    from hevsim.cosim.system import run_system

    comps = [Component("c", FMU_TYPE, fmus["counter"].name), Component("s", FMU_TYPE, fmus["source"].name)]
    desc = SystemDescription("clocks", comps, connections(), 0.0, STOP_S, {"step_s": STEP_S},
                             base_dir=fmus["counter"].parent)  # fmt: skip
    res = run_system(desc)
    assert res.stats["fmu_process"] == {"c": "in process", "s": "in process"}
    got = list(
        zip(res["c.count"].tolist(), res["c.trig_count"].tolist(), res["c.last_k"].tolist(), strict=True)
    )
    assert got == [SCHEDULE[t] for t in TIMES]
    desc.connections = [Connection("s", "out", "c", "tick")]  # refused by the static check too
    with pytest.raises(ConfigError, match=r"c\.tick: input clock, constant"):
        datacheck(desc)
    desc.connections = [Connection("s", "out", "c", "k_in")]
    with pytest.raises(ConfigError, match=r"s\.out is an FMI Clock variable.*connects only to a clock"):
        datacheck(desc)


def test_variable_of_several_clocks_is_refused(fmus: dict[str, Path], tmp_path: Path) -> None:
    import zipfile

    bad = tmp_path / "TwoClocks.fmu"
    with zipfile.ZipFile(fmus["counter"]) as z, zipfile.ZipFile(bad, "w") as out:
        for item in z.namelist():
            data = z.read(item)
            if item == "modelDescription.xml":
                count = b'name="count" valueReference="11" causality="output" variability="discrete" '
                data = data.replace(count + b'clocks="10"', count + b'clocks="10 20"')
                assert b'clocks="10 20"' in data
            out.writestr(item, data)
    with pytest.raises(ConfigError, match=r"clocked variable 'count' \(clocks \['tick', 'trig'\]\)"):
        FMUParticipant("two", bad)

"""FMI 3.0 Scheduled Execution (issue 30 item 2, clocked partitions): the Reference ``Clocks``
FMU (tests/reference_fmus/Clocks, compiled in the test) run by :class:`SEParticipant` against
the closed-form schedule written down here from its model.c.

The FMU: input clock inClock1 periodic (interval 1 s, priority 0), inClock2 triggered by the
simulation algorithm (priority 1; here at 0, 1, 8 and 9 s as in its model description), inClock3
a countdown clock (priority 2) whose interval partition 1 sets to 0 at t = 4 s (announced with
clockUpdate); each partition counts its ticks and totalInClockTicks; partition 2 adds input2 to
result2 and zeroes input2; partition 3 sets output3 = 1000; every partition sets outClock when
it was not set and totalInClockTicks is a multiple of 5 (reading outClock resets it).

Schedule with inClock2 at 0, 1, 8, 9 (ticks in [t, t + 1) run in the step from t, priorities in
order):

| t | partitions | total after | outClock |
| --- | --- | --- | --- |
| 0 | 1, 2 | 2 | |
| 1 | 1, 2 | 4 | |
| 2 | 1 | 5 | tick |
| 3 | 1 | 6 | |
| 4 | 1, 3 (countdown 0 s) | 8 | |
| 5, 6 | 1 | 9, 10 | tick at 6 |
| 7 | 1 | 11 | |
| 8 | 1, 2 | 13 | |
| 9 | 1, 2 | 15 | tick (partition 2) |

Without inClock2 (an SSD gives no trigger times): totals 1, 2, 3, 4, then at 4 s partition 1
makes 5 (outClock ticks, countdown announced) and partition 3 6; 7 .. 11 at 5 .. 9 s
(outClock ticks at 8 s).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tests.cosim_reference import build_reference_fmu

from hevsim.cosim.master import simulate
from hevsim.cosim.se import SEParticipant
from hevsim.errors import ConfigError


@pytest.fixture(scope="module")
def clocks(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_reference_fmu("Clocks", 3, tmp_path_factory.mktemp("clocks"))


def test_clocks_fmu_follows_the_closed_form_schedule(clocks: Path) -> None:
    p = SEParticipant("c", clocks, {"input2": 5}, ticks={"inClock2": [0, 1, 8, 9]})
    assert set(p.outputs) == {"inClock1Ticks", "inClock2Ticks", "inClock3Ticks", "totalInClockTicks",
                              "result2", "output3"}  # fmt: skip
    res = simulate([p], [], stop_time_s=10.0, step_s=1.0)
    np.testing.assert_array_equal(res.time_s, np.arange(11.0))
    # outputs at t = 0 .. 10 s: after the ticks before t
    np.testing.assert_array_equal(res["c.inClock1Ticks"], np.arange(11))
    np.testing.assert_array_equal(res["c.inClock2Ticks"], [0, 1, 2, 2, 2, 2, 2, 2, 2, 3, 4])
    np.testing.assert_array_equal(res["c.inClock3Ticks"], [0] * 5 + [1] * 6)
    np.testing.assert_array_equal(res["c.totalInClockTicks"], [0, 2, 4, 5, 6, 8, 9, 10, 11, 13, 15])
    np.testing.assert_array_equal(res["c.output3"], [0] * 5 + [1000] * 6)
    np.testing.assert_array_equal(res["c.result2"], [0] + [5] * 10)  # input2 taken once, then zeroed
    expected = [(0, "inClock1"), (0, "inClock2"), (1, "inClock1"), (1, "inClock2"), (2, "inClock1"),
                (2, "outClock"), (3, "inClock1"), (4, "inClock1"), (4, "inClock3"), (5, "inClock1"),
                (6, "inClock1"), (6, "outClock"), (7, "inClock1"), (8, "inClock1"), (8, "inClock2"),
                (9, "inClock1"), (9, "inClock2"), (9, "outClock")]  # fmt: skip
    assert p.clock_log == [(float(t), c) for t, c in expected]


def test_communication_step_does_not_change_the_schedule(clocks: Path) -> None:
    """Steps of 0.25 s and of 2.5 s: the same ticks (activation times are the clocks', not the
    grid's), the outputs at the common points equal."""
    runs = {}
    for h in (0.25, 2.5):
        p = SEParticipant("c", clocks, ticks={"inClock2": [0, 1, 8, 9]})
        runs[h] = (simulate([p], [], stop_time_s=10.0, step_s=h), p.clock_log)
    (fine, log_f), (coarse, log_c) = runs[0.25], runs[2.5]
    assert log_f == log_c and len(log_f) == 18
    idx = np.searchsorted(fine.time_s, coarse.time_s)
    for c in coarse.columns:
        np.testing.assert_array_equal(fine[c][idx], coarse[c], err_msg=c)


def test_clocks_fmu_from_an_ssd(clocks: Path, tmp_path: Path) -> None:
    """An SSD component with the SE-only Clocks FMU: ``--check`` passes, the run (a forked
    worker on the default path, its DefaultExperiment step of 1 s) follows the schedule
    without inClock2 (no trigger times in an SSD)."""
    from hevsim.cli import main
    from hevsim.cosim.ssd import FMU_TYPE, Component, SystemDescription
    from hevsim.cosim.ssp_write import write_ssd
    from hevsim.cosim.system import run_cosim

    (tmp_path / "Clocks.fmu").write_bytes(clocks.read_bytes())
    desc = SystemDescription("se", [Component("c", FMU_TYPE, "Clocks.fmu")], [], stop_time_s=10.0,
                             base_dir=tmp_path)  # fmt: skip
    ssd = write_ssd(desc, tmp_path / "se.ssd")
    assert main(["cosim", str(ssd), "--check"]) == 0
    res = run_cosim(ssd, tmp_path / "out")
    assert res.stats["step_s"] == 1.0 and res.stats["fmu_process"] == {"c": "worker process"}
    np.testing.assert_array_equal(res["c.totalInClockTicks"], [0, 1, 2, 3, 4, 6, 7, 8, 9, 10, 11])
    np.testing.assert_array_equal(res["c.inClock3Ticks"], [0] * 5 + [1] * 6)
    np.testing.assert_array_equal(res["c.inClock2Ticks"], [0] * 11)


def test_bad_trigger_times_are_refused(clocks: Path) -> None:
    with pytest.raises(ConfigError, match=r"ticks for 'inClock1'; triggered input clocks: \['inClock2'\]"):
        SEParticipant("c", clocks, ticks={"inClock1": [0.5]})

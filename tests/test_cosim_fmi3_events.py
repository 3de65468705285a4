"""FMI 3.0 co-simulation FMUs with event mode (issue 30 item 2, its event-mode part): the C
FMU of tests/cosim_cfmu3_events.py is instantiated with event mode and early return; a step
crossing a whole second returns early there, the master runs the event iteration in event
mode and the rest of the step. Against the closed form (counter = 1 + floor(t), x = u t) and
FMPy's ``simulate_fmu(use_event_mode=True, early_return_allowed=True)`` at the common times."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tests.cosim_cfmu3_events import build_event_fmu3

from hevsim.cosim.master import simulate
from hevsim.cosim.participant import FMUParticipant
from hevsim.cosim.worker import WorkerFMUParticipant


@pytest.fixture(scope="module")
def fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_event_fmu3(tmp_path_factory.mktemp("events3"))


@pytest.mark.parametrize("cls", [FMUParticipant, WorkerFMUParticipant])
def test_event_mode_and_early_return_against_fmpy_and_the_closed_form(fmu: Path, cls: type) -> None:
    from fmpy import simulate_fmu

    p = cls("e", fmu, {"u": 2.0})
    res = simulate([p], [], stop_time_s=3.0, step_s=0.3)
    t = np.arange(11) * 0.3
    assert np.allclose(res.time_s, t, rtol=0, atol=1e-12)
    assert res["e.counter"].tolist() == [1 + int(np.floor(x + 1e-9)) for x in t]  # 1 1 1 1 2 .. 4
    assert np.allclose(res["e.x"], 2.0 * t, rtol=0, atol=1e-12)
    if cls is FMUParticipant:
        assert p.events == 3  # t = 1, 2 (early returns) and 3 (the last step's end)
    ref = simulate_fmu(str(fmu), stop_time=3.0, output_interval=0.3, use_event_mode=True,
                       early_return_allowed=True, start_values={"u": 2.0})  # fmt: skip
    last = {round(float(r["time"]), 9): r for r in ref}  # the row after the event where there are two
    common = [i for i, x in enumerate(res.time_s) if round(float(x), 9) in last]
    assert len(common) >= 8
    for i in common:
        r = last[round(float(res.time_s[i]), 9)]
        assert res["e.counter"][i] == r["counter"] and res["e.x"][i] == pytest.approx(r["x"], abs=1e-12)

"""The study's progress display (issue 17 item 2): cases done, failures and rate.

On a terminal ``run_study`` shows a tqdm bar (cases done of the total, the rate in cases/s and
the failures so far as ``failed=N``); off a terminal it prints stage lines. Either way the last
line says how many cases ran, at what rate, and how many failed.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

from hevsim import progress
from hevsim.studies.runner import run_study

sys.path.insert(0, str(Path(__file__).resolve().parent))
import test_study_run as slow  # tests/ on sys.path, as in tests/test_study_dask.py


@pytest.mark.parametrize("terminal", [True, False])
def test_progress_shows_cases_done_failures_and_rate(
    terminal: bool, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    study = slow.slow_study(8, 0.0)  # 8 masses x 3 ratios; the 3 cases of one mass fail
    monkeypatch.setattr(progress, "is_terminal", lambda stream=None: terminal)
    monkeypatch.setattr(progress, "enabled", lambda: True)
    rows = run_study(study, scheduler="in-process", progress=True)
    assert len(rows) == 24 and int((rows["status"] != "ok").sum()) == 3
    err = capsys.readouterr().err
    assert "24 of 24 cases to run" in err, err
    end = re.search(r"24 cases in [0-9.]+ s \(([0-9.e+]+|inf) cases/s\), 3 failed", err)
    assert end is not None, err
    if terminal:  # the bar: done/total, rate and the running failure count
        assert "24/24" in err and "case/s" in err, err
        assert "failed=3" in err, err

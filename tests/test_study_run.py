"""Running studies in process (issue 17): rows equal the single-run APIs bit for bit, failed
cases are recorded, batching does not change rows, SIGINT + resume gives every case once.

``register_slow`` adds a test solver (a known function of the parameters that sleeps per
case) used here and by tests/test_study_dask.py (its workers import this module).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from tests.proc_helpers import sigint_default

from hevsim.architectures import build_vehicle
from hevsim.cli import main
from hevsim.optimal import optimize
from hevsim.sim.simulator import simulate
from hevsim.studies.report import study_report
from hevsim.studies.runner import read_results, run_study
from hevsim.studies.solvers import FAILED, OK, SOLVERS, Outcome, Solver, register_solver
from hevsim.studies.spec import load_study, study_from_dict, with_overrides

ROOT = Path(__file__).resolve().parents[1]
SERIES = str(ROOT / "examples" / "series_hev.toml")
PARALLEL = str(ROOT / "examples" / "parallel_hev.toml")
SLOW = "test_slow"
SLOW_FAILS_AT_KG = 1234.0
"""The slow test solver fails the cases with this body mass."""


def slow_run(
    ctx: Any, cycle: Any, values: np.ndarray, metrics: tuple[str, ...], threads: Any
) -> list[Outcome]:
    """Test solver: ``double_mass = 2 body.mass_kg + final_drive.ratio`` after a sleep."""
    out = []
    for row in values:
        time.sleep(ctx["delay_s"])
        if row[0] == SLOW_FAILS_AT_KG:
            out.append(Outcome(FAILED, f"body.mass_kg = {row[0]:g} is the failing test value", {}, 0.0))
        else:
            out.append(Outcome(OK, "", {"double_mass": 2.0 * row[0] + row[1]}, 0.0))
    return out


def register_slow(delay_s: float) -> None:
    """Register the slow test solver (delay per case [s])."""
    register_solver(Solver(
        SLOW, ("series",), lambda cfg, o, w: {}, lambda cfg: ("double_mass",),
        lambda study, sc: {"delay_s": delay_s}, lambda ctx, row: (), slow_run, default_batch=1,
    ))  # fmt: skip


def slow_study(n_mass: int = 8, delay_s: float = 0.0) -> Any:
    """A study of the slow solver: n_mass masses x 3 ratios (one mass fails)."""
    register_slow(delay_s)
    masses = [1000.0 + 10.0 * i for i in range(n_mass - 1)] + [SLOW_FAILS_AT_KG]
    return study_from_dict({
        "name": "slow", "vehicle": SERIES, "cycles": ["udds"], "metrics": ["double_mass"],
        "parameters": {"body.mass_kg": masses, "final_drive.ratio": [3.0, 3.5, 4.0]},
        "solvers": [{"name": SLOW}],
    })  # fmt: skip


def _same(a: pd.DataFrame, b: pd.DataFrame) -> None:
    cols = [c for c in a.columns if c != "wall_time_s"]
    pd.testing.assert_frame_equal(
        a[cols].reset_index(drop=True), b[cols].reset_index(drop=True), check_exact=True
    )


def _series_study(**over: Any) -> Any:
    data = {
        "name": "series", "vehicle": SERIES, "cycles": ["udds"], "metrics": ["mpgge", "soc_final", "fuel_kg"],
        "parameters": {"body.mass_kg": [1100.0, 1400.0], "final_drive.ratio": [3.5, 4.5],
                       "battery.n_parallel": [1, 2], "controller.soc_low": [0.6, 0.75]},
        "solvers": [{"name": "simulate"}],
    }  # fmt: skip
    data.update(over)
    return study_from_dict(data)


def test_simulate_rows_equal_single_runs_and_failures_are_recorded() -> None:
    study = _series_study()
    rows = run_study(study, scheduler="in-process", progress=False)
    assert rows["case_id"].tolist() == list(range(16))
    bad = rows["controller.soc_low"] == 0.75  # soc_low 0.75 >= soc_high 0.7: invalid vehicle
    assert (rows.loc[bad, "status"] == FAILED).all() and (rows.loc[~bad, "status"] == OK).all()
    assert rows.loc[bad, "error"].str.contains("controller.soc_low").all()
    assert rows.loc[bad, "mpgge"].isna().all()
    for _, r in rows[~bad].iterrows():
        over = {k: r[k] for k in study.keys}
        over["battery.n_parallel"] = int(over["battery.n_parallel"])
        res = simulate(build_vehicle(with_overrides(study.vehicle, over)), "udds")
        for m in ("mpgge", "soc_final", "fuel_kg"):
            assert r[m] == res.value(m), (over, m)  # bit for bit
    one = run_study(_series_study(batch_size=1), scheduler="in-process", progress=False)
    _same(rows, one)  # batch composition does not change a row


def test_sampled_values_between_the_probes_equal_single_runs_bit_for_bit() -> None:
    """Kernel keys that scale a parameter (brake force = decel x mass, rpm -> rad/s) are
    batched with the exact factor, not an interpolated one."""
    study = study_from_dict({
        "name": "lhs", "vehicle": SERIES, "cycles": ["udds"], "metrics": ["mpgge", "soc_final"],
        "sampling": {"method": "lhs", "samples": 7, "seed": 9},
        "parameters": {"body.mass_kg": {"min": 1100.0, "max": 1500.0},
                       "controller.engine_speed_rpm": {"min": 1400.0, "max": 1700.0}},
        "solvers": [{"name": "simulate"}],
    })  # fmt: skip
    ctx = SOLVERS["simulate"].prepare(study, study.solvers[0])
    assert ctx.structural == () and len(ctx.kernel) == 2, ctx.notes  # both batched
    rows = run_study(study, scheduler="in-process", progress=False)
    for _, r in rows.iterrows():
        over = {k: float(r[k]) for k in study.keys}
        res = simulate(build_vehicle(with_overrides(study.vehicle, over)), "udds")
        assert r["mpgge"] == res.value("mpgge") and r["soc_final"] == res.value("soc_final"), over


def test_a_metric_one_solver_lacks_is_nan_in_its_rows() -> None:
    register_slow(0.0)
    study = study_from_dict({
        "name": "mixed", "vehicle": SERIES, "cycles": ["udds"], "metrics": ["double_mass", "mpgge"],
        "parameters": {"body.mass_kg": [1100.0], "final_drive.ratio": [4.0]},
        "solvers": [{"name": "simulate"}, {"name": SLOW}],
    })  # fmt: skip
    rows = run_study(study, scheduler="in-process", progress=False)
    assert rows["solver"].tolist() == ["simulate", SLOW] and (rows["status"] == OK).all()
    assert np.isnan(rows["double_mass"][0]) and rows["double_mass"][1] == 2 * 1100.0 + 4.0
    assert rows["mpgge"][0] > 0 and np.isnan(rows["mpgge"][1])
    SOLVERS.pop(SLOW, None)


def test_optimize_rows_equal_optimize_and_infeasible_cases_fail() -> None:
    study = study_from_dict({
        "name": "dp", "vehicle": PARALLEL, "cycles": ["us06"], "metrics": ["l_per_100km", "soc_final"],
        "sampling": {"method": "list"},
        "parameters": {"motor.torque_scale": [1.0, 0.5], "battery.capacity_ah": [5.0, 3.0]},
        "solvers": [{"name": "optimize", "soc_grid_points": 31, "input_grid_points": 31}],
    })  # fmt: skip
    rows = run_study(study, scheduler="in-process", progress=False)
    assert rows["status"].tolist() == [OK, FAILED]
    assert "cannot follow drive cycle 'us06'" in rows["error"][1]
    ref = optimize(study.vehicle, "us06", soc_grid_points=31, input_grid_points=31, progress=False)
    assert rows["l_per_100km"][0] == ref.value("l_per_100km")
    assert rows["soc_final"][0] == ref.value("soc_final")


def test_cli_resume_reruns_only_missing_cases_and_report(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    p = tmp_path / "study.toml"
    p.write_text(f"""name = "resume"
vehicle = "{SERIES}"
cycles = ["udds"]
metrics = ["mpgge", "fuel_kg"]
batch_size = 2
solvers = ["simulate"]
[parameters]
"body.mass_kg" = [1100.0, 1200.0, 1300.0]
"final_drive.ratio" = [3.5, 4.5]
[[pareto]]
name = "light_and_frugal"
minimize = ["fuel_kg", "body.mass_kg"]
""")
    out = tmp_path / "out"
    assert main(["study", str(p), "--out", str(out), "--scheduler", "in-process"]) == 0
    full = read_results(out)
    parts = sorted((out / "results").glob("part-*.parquet"))
    assert len(parts) == 3 and len(full) == 6
    for q in parts[:2]:
        q.unlink()
    assert len(read_results(out)) == 2
    capsys.readouterr()
    assert main(["study", str(p), "--out", str(out), "--scheduler", "in-process", "--resume"]) == 0
    assert "6 of 6 cases, 6 ok" in capsys.readouterr().out
    again = read_results(out)
    _same(again, full)
    assert len(list((out / "results").glob("part-002-*.parquet"))) == 2  # only the missing batches re-ran
    # study-report: the Pareto front equals a brute-force check on the rows
    rep = study_report(out)
    front = rep["fronts"]["light_and_frugal"]
    f = again[["fuel_kg", "body.mass_kg"]].to_numpy()
    brute = [i for i in range(len(f)) if not np.any(np.all(f <= f[i], axis=1) & np.any(f < f[i], axis=1))]
    assert sorted(front["case_id"]) == sorted(again["case_id"][brute])
    for name in ("report.md", "sensitivity.csv", "pareto_light_and_frugal.csv", "scatter_udds_simulate.png"):
        assert (out / name).is_file(), name
    from hevsim.io import _is_results_folder

    assert _is_results_folder(out)  # the marker lists every file: a later run may replace it
    # resuming with a different study is refused
    p.write_text(p.read_text().replace("1300.0", "1350.0"))
    assert main(["study", str(p), "--out", str(out), "--scheduler", "in-process", "--resume"]) == 2
    assert "another study" in capsys.readouterr().err


_INTERRUPTED = """
import sys
sys.path.insert(0, {tests!r})
import test_study_run as t
from hevsim.studies.runner import run_study
run_study(t.slow_study(8, 0.15), {out!r}, scheduler="in-process", progress=False)
"""


def test_sigint_then_resume_gives_every_case_once(tmp_path: Path) -> None:
    out = tmp_path / "out"
    code = _INTERRUPTED.format(tests=str(Path(__file__).parent), out=str(out))
    proc = subprocess.Popen(  # Ctrl-C acts even if this run inherited SIGINT ignored
        [sys.executable, "-c", code],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        preexec_fn=sigint_default,
    )
    try:
        deadline = time.monotonic() + 120
        while len(list((out / "results").glob("part-*.parquet"))) < 4:
            assert proc.poll() is None, proc.communicate()[1].decode()[-2000:]
            assert time.monotonic() < deadline
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    partial = read_results(out)
    assert 4 <= len(partial) < 24 and partial["case_id"].is_unique
    assert not (out / "summary.json").exists()
    study = slow_study(8, 0.0)
    resumed = run_study(study, out, scheduler="in-process", resume=True, progress=False)
    reference = run_study(study, scheduler="in-process", progress=False)
    assert resumed["case_id"].tolist() == list(range(24))
    _same(resumed, reference)
    _same(read_results(out), reference)
    assert (reference["status"] == FAILED).sum() == 3
    SOLVERS.pop(SLOW, None)


def test_examples_load() -> None:
    for name in ("study_series_sizing.toml", "study_parallel_sizing.toml", "study_series_controllers.toml",
                 "study_parallel_controllers.toml"):  # fmt: skip
        s = load_study(ROOT / "examples" / name)
        assert s.n_cases > 0 and s.pareto, name
    sizing = load_study(ROOT / "examples" / "study_parallel_sizing.toml")
    assert [s.label for s in sizing.solvers] == ["simulate[controller=rule_based]", "optimize", "performance"]
    assert os.path.isfile(ROOT / "docs" / "studies.md")

"""Study solvers over every architecture (issue 17): ``simulate`` with a named controller,
``performance``, ECMS tuned from the same case's DP, and the cross-solver Pareto front.

References are independent of the study machinery: single forward runs
(:func:`hevsim.sim.forward.simulate_architecture`), :func:`hevsim.sim.performance.performance`
and :func:`hevsim.optimal.optimize` called directly, and a brute-force Pareto check.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from hevsim.cli import main
from hevsim.control.parallel import ecms_from_dp
from hevsim.optimal import optimize
from hevsim.sim.forward import simulate_architecture
from hevsim.sim.performance import performance
from hevsim.studies.report import fronts
from hevsim.studies.runner import run_study
from hevsim.studies.solvers import OK, PERFORMANCE_METRICS, performance_metrics
from hevsim.studies.spec import study_from_dict, with_overrides

ROOT = Path(__file__).resolve().parents[1]
PARALLEL = str(ROOT / "examples" / "parallel_hev.toml")
SERIES = str(ROOT / "examples" / "series_hev.toml")
PERF_DT_S = 0.5
METRICS = ["l_per_100km", "soc_final", "fuel_kg", "time_0_100_kmh_s", "top_speed_mph", "gradeability_pct"]


def _parallel_study(**over: Any) -> Any:
    data = {
        "name": "parallel", "vehicle": PARALLEL, "cycles": ["udds", "hwfet"], "metrics": METRICS,
        "parameters": {"motor.torque_scale": [0.7, 1.0], "battery.capacity_ah": [5.0]},
        "solvers": [{"name": "simulate", "controller": "rule_based"},
                    {"name": "performance", "dt_s": PERF_DT_S}],
        "pareto": [{"name": "fuel_vs_0_100", "minimize": ["fuel_kg", "time_0_100_kmh_s"]}],
    }  # fmt: skip
    data.update(over)
    return study_from_dict(data)


def _same(a: pd.DataFrame, b: pd.DataFrame) -> None:
    cols = [c for c in a.columns if c != "wall_time_s"]
    pd.testing.assert_frame_equal(
        a[cols].reset_index(drop=True), b[cols].reset_index(drop=True), check_exact=True
    )


@pytest.fixture(scope="module")
def parallel_rows() -> tuple[Any, pd.DataFrame]:
    study = _parallel_study()
    return study, run_study(study, scheduler="in-process", progress=False)


def test_parallel_simulate_rows_equal_single_forward_runs(parallel_rows: tuple[Any, pd.DataFrame]) -> None:
    study, rows = parallel_rows
    assert (rows["status"] == OK).all(), rows["error"].tolist()
    sim = rows[rows["solver"] == "simulate[controller=rule_based]"]
    assert len(sim) == 4
    for _, r in sim.iterrows():
        cfg = with_overrides(study.vehicle, {k: float(r[k]) for k in study.keys})
        assert cfg.controller.kind == "electric_assist"  # rule_based = the architecture's first
        res = simulate_architecture("parallel", cfg, r["cycle"])
        for m in ("l_per_100km", "soc_final", "fuel_kg"):
            assert r[m] == pytest.approx(res.metrics[m]["value"], rel=1e-12, abs=1e-12), (r["cycle"], m)
        assert np.isnan(r["time_0_100_kmh_s"])  # a performance metric: NaN in the simulate rows


def test_performance_rows_equal_performance_run_directly(parallel_rows: tuple[Any, pd.DataFrame]) -> None:
    study, rows = parallel_rows
    perf = rows[rows["solver"] == "performance"]
    assert len(perf) == 4
    for tm in (0.7, 1.0):
        cfg = with_overrides(study.vehicle, {"motor.torque_scale": tm, "battery.capacity_ah": 5.0})
        ref = performance(cfg, dt_s=PERF_DT_S)
        mine = perf[perf["motor.torque_scale"] == tm]
        assert set(mine["cycle"]) == {"udds", "hwfet"}  # the same vehicle's rows on each cycle
        for test, (metric, unit) in PERFORMANCE_METRICS.items():
            if metric not in METRICS:
                continue
            row = ref.table[ref.table["test"].str.startswith(test)].iloc[0]
            assert row["unit"] == unit
            assert (mine[metric] == row["value"]).all(), (tm, metric)
        assert np.isnan(mine["l_per_100km"]).all()
    assert performance_metrics(ref)["top_speed_mph"] == ref.value("top speed")


def test_parallel_study_on_local_cluster_equals_in_process(parallel_rows: tuple[Any, pd.DataFrame]) -> None:
    pytest.importorskip("distributed")
    study, rows = parallel_rows
    _same(run_study(study, workers=2, progress=False), rows)


def test_cross_solver_front_equals_brute_force(parallel_rows: tuple[Any, pd.DataFrame]) -> None:
    """fuel (simulate) vs 0-100 km/h time (performance): joined by sample and cycle."""
    study, rows = parallel_rows
    info = study.describe()
    front = fronts(info, rows)["fuel_vs_0_100"]
    assert set(front["solver"]) == {"simulate[controller=rule_based]"}  # fuel depends on the cycle
    sim = rows[rows["solver"] == "simulate[controller=rule_based]"]
    perf = rows[rows["solver"] == "performance"].set_index(["sample_id", "cycle"])["time_0_100_kmh_s"]
    for cycle, grp in sim.groupby("cycle"):
        t = np.array([perf[(s, cycle)] for s in grp["sample_id"]])
        f = np.column_stack([grp["fuel_kg"].to_numpy(), t])
        brute = [i for i in range(len(f)) if not np.any(np.all(f <= f[i], axis=1) & np.any(f < f[i], axis=1))]
        assert sorted(front[front["cycle"] == cycle]["case_id"]) == sorted(grp["case_id"].iloc[brute])


def test_ecms_tuned_from_the_case_dp_equals_ecms_with_the_dp_factor() -> None:
    dp = {"soc_grid_points": 21, "input_grid_points": 21}
    study = study_from_dict({
        "name": "ecms_dp", "vehicle": PARALLEL, "cycles": ["udds"], "metrics": ["fuel_kg", "soc_final"],
        "parameters": {"battery.capacity_ah": [4.0]},
        "solvers": [{"name": "simulate", "controller": "ecms_dp"}, {"name": "optimize", **dp}],
    })  # fmt: skip
    rows = run_study(study, scheduler="in-process", progress=False)
    assert (rows["status"] == OK).all(), rows["error"].tolist()
    cfg = with_overrides(study.vehicle, {"battery.capacity_ah": 4.0})
    s = ecms_from_dp(optimize(cfg, "udds", progress=False, **dp))["equivalence_factor"]
    assert s > 0
    ref = simulate_architecture("parallel", cfg, "udds", controller="ecms", equivalence_factor=s)
    got = rows[rows["solver"] == "simulate[controller=ecms_dp]"].iloc[0]
    assert got["fuel_kg"] == pytest.approx(ref.metrics["fuel_kg"]["value"], rel=1e-12)
    assert got["fuel_kg"] != rows[rows["solver"] == "optimize"].iloc[0]["fuel_kg"]


def test_controller_not_admitted_exits_2_naming_the_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    p = tmp_path / "study.toml"
    p.write_text(f"""name = "bad_controller"
vehicle = "{SERIES}"
cycles = ["udds"]
metrics = ["mpgge"]
[parameters]
"body.mass_kg" = [1200.0, 1300.0]
[[solvers]]
name = "simulate"
controller = "electric_assist"
""")
    out = tmp_path / "out"
    assert main(["study", str(p), "--out", str(out), "--scheduler", "in-process"]) == 2
    err = capsys.readouterr().err
    for needle in (
        str(p),
        "solvers[0]",
        "key 'controller' = 'electric_assist'",
        "series",
        "rule_based, thermostat",
    ):
        assert needle in err, (needle, err)
    assert not out.exists()


@pytest.mark.parametrize(
    ("vehicle", "kind"),
    [
        ("bev.toml", "direct"),
        ("conventional_sedan.toml", "shift_schedule"),
        ("prius_like_power_split.toml", "power_follower"),
    ],
)
def test_simulate_rule_based_on_every_other_architecture_equals_single_runs(vehicle: str, kind: str) -> None:
    study = study_from_dict({
        "name": "arch", "vehicle": str(ROOT / "examples" / vehicle), "cycles": ["udds"],
        "metrics": ["mpgge", "soc_final"], "parameters": {"body.mass_kg": [1400.0, 1650.0]},
        "solvers": [{"name": "simulate", "controller": "rule_based"}],
    })  # fmt: skip
    rows = run_study(study, scheduler="in-process", progress=False)
    assert (rows["status"] == OK).all(), rows["error"].tolist()
    for _, r in rows.iterrows():
        cfg = with_overrides(study.vehicle, {"body.mass_kg": r["body.mass_kg"]})
        assert cfg.controller.kind == kind
        ref = simulate_architecture(cfg.architecture, cfg, "udds")
        for m in ("mpgge", "soc_final"):
            assert r[m] == pytest.approx(ref.metrics[m]["value"], rel=1e-12, abs=1e-12), (vehicle, m)
    assert rows["mpgge"].iloc[0] > rows["mpgge"].iloc[1]  # the heavier vehicle uses more energy

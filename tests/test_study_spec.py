"""Study files, sampling and analysis (issue 17): validation, samples, Pareto, Sobol, SRC.

No Dask here: runs use the in-process executor.
"""

from __future__ import annotations

import socket
import time
from pathlib import Path

import numpy as np
import pytest

from hevsim.cli import main
from hevsim.errors import ConfigError
from hevsim.studies import sampling
from hevsim.studies.analysis import pareto_mask, regression_ranking, sobol_indices
from hevsim.studies.runner import run_study
from hevsim.studies.spec import StudyError, load_study, study_from_dict

ROOT = Path(__file__).resolve().parents[1]
SERIES = str(ROOT / "examples" / "series_hev.toml")
PARALLEL = str(ROOT / "examples" / "parallel_hev.toml")


def _study(**over: object) -> dict:
    base: dict = {
        "name": "t",
        "vehicle": SERIES,
        "cycles": ["udds"],
        "metrics": ["mpgge", "soc_final"],
        "sampling": {"method": "grid"},
        "parameters": {
            "body.mass_kg": [1100.0, 1300.0],
            "final_drive.ratio": {"min": 3.5, "max": 4.5, "num": 3},
        },
        "solvers": [{"name": "simulate"}],
    }
    base.update(over)
    return base


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "study.toml"
    p.write_text(text)
    return p


def _write_series_study(tmp_path: Path, parameters: str) -> Path:
    """study.toml: the series example on UDDS, MPGGE, simulate, then the ``parameters`` TOML."""
    return _write(
        tmp_path,
        f"""vehicle = "{SERIES}"
cycles = ["udds"]
metrics = ["mpgge"]
solvers = ["simulate"]
"""
        + parameters,
    )


# ------------------------------------------------------------------------------------------
# Validation
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("change", "needles"),
    [
        ({"parameters": {"motor.torque_scal": [1.0]}}, ["motor.torque_scal", "torque_scale", "[motor]"]),
        (
            {"parameters": {"traction_motor.torque_scale": [1.0]}},
            ["traction_motor.torque_scale", "final_drive"],
        ),
        ({"parameters": {"motor.model": ["map"]}}, ["motor.model", "not a numeric key"]),
        (
            {"parameters": {"body.mass_kg": {"min": 1500.0, "max": 1200.0, "num": 3}}},
            ["min = 1500", "max = 1200"],
        ),
        ({"parameters": {"body.mass_kg": [1200.0, -5.0]}}, ["body.mass_kg", "-5", "between"]),
        ({"parameters": {"battery.n_parallel": [1.5]}}, ["battery.n_parallel", "whole number"]),
        ({"sampling": {"method": "lhs", "samples": 0}}, ["sampling.samples", "0", ">= 1"]),
        ({"sampling": {"method": "sobol", "samples": 6}}, ["sampling.samples", "power of 2", "4 or 8"]),
        ({"sampling": {"method": "random"}}, ["sampling.method", "random", "lhs", "saltelli"]),
        ({"solvers": [{"name": "fuzzy_logic"}]}, ["fuzzy_logic", "optimize", "performance", "simulate"]),
        ({"solvers": [{"name": "performance", "dt_s": 20.0}]}, ["solvers[0]", "dt_s = 20.0", "(0, 10]"]),
        (
            {"solvers": [{"name": "simulate", "controller": "electric_assist"}]},  # ecms runs on a series HEV
            ["controller", "'electric_assist'", "series", "rule_based"],
        ),
        ({"solvers": [{"name": "simulate", "controller": "fuzzy"}]}, ["controller", "fuzzy", "thermostat"]),
        ({"solvers": [{"name": "optimize", "soc_grid_points": 1}]}, ["soc_grid_points", ">= 2"]),
        ({"metrics": ["mpg_typo"]}, ["mpg_typo", "mpgge", "simulate"]),
        ({"metrics": ["mpgge", "dp_total_cost"]}, ["dp_total_cost", "simulate", "speed_error_rms_mph"]),
        ({"cycles": ["nedc_typo"]}, ["nedc_typo", "udds"]),
        ({"vehicle": "missing.toml"}, ["vehicle", "missing.toml"]),
        ({"extra": 1}, ["extra", "valid top-level keys"]),
        ({"pareto": [{"minimize": ["mpgge"]}]}, ["two objectives"]),
        ({"pareto": [{"minimize": ["mpgge", "co2"]}]}, ["co2", "neither"]),
        (
            {
                "vehicle": PARALLEL,
                "parameters": {"motor.torque_scale": [1.0]},
                "solvers": [{"name": "simulate", "controller": "thermostat"}],
            },
            [
                "key 'controller'",
                "'thermostat'",
                "parallel",
                "rule_based, electric_assist, ecms, aecms, ecms_dp",
            ],
        ),
        (  # ECMS tuned from the case's DP needs the study's DP
            {
                "vehicle": PARALLEL,
                "parameters": {"motor.torque_scale": [1.0]},
                "solvers": [{"name": "simulate", "controller": "ecms_dp"}],
            },
            ["solvers[0]", "'ecms_dp'", "optimize"],
        ),
    ],
)
def test_bad_study_names_key_value_and_expectation(change: dict, needles: list[str]) -> None:
    with pytest.raises(ConfigError) as exc:
        study_from_dict(_study(**change), source="s.toml", base_dir=ROOT)
    msg = str(exc.value)
    assert msg.startswith("s.toml"), msg
    for n in needles:
        assert n in msg, (n, msg)


def test_nested_parameter_tables_and_renamed_sections(tmp_path: Path) -> None:
    p = _write_series_study(
        tmp_path,
        """[parameters.motor]
torque_scale = [0.9, 1.1]
[parameters.final_drive]
ratio = {min = 3.0, max = 4.0, step = 0.5}
""",
    )
    s = load_study(p)
    assert s.keys == ("motor.torque_scale", "final_drive.ratio")
    assert s.values.tolist() == [[0.9, 3.0], [0.9, 3.5], [0.9, 4.0], [1.1, 3.0], [1.1, 3.5], [1.1, 4.0]]
    assert s.name == "study" and s.n_cases == 6


def test_sampling_methods_are_seeded_and_inside_their_boxes() -> None:
    box = {"body.mass_kg": {"min": 1000.0, "max": 1400.0}, "battery.n_parallel": {"min": 1, "max": 3}}
    for method, n, rows in (("lhs", 10, 10), ("sobol", 8, 8), ("saltelli", 8, 8 * 4)):
        a = study_from_dict(_study(parameters=box, sampling={"method": method, "samples": n, "seed": 3}))
        b = study_from_dict(_study(parameters=box, sampling={"method": method, "samples": n, "seed": 3}))
        c = study_from_dict(_study(parameters=box, sampling={"method": method, "samples": n, "seed": 4}))
        assert a.values.shape == (rows, 2)
        assert np.array_equal(a.values, b.values) and not np.array_equal(a.values, c.values)
        assert a.values[:, 0].min() >= 1000.0 and a.values[:, 0].max() <= 1400.0
        assert set(np.unique(a.values[:, 1])) <= {1.0, 2.0, 3.0}
    lhs = study_from_dict(_study(parameters=box, sampling={"method": "lhs", "samples": 10, "seed": 1})).values
    strata = np.floor((lhs[:, 0] - 1000.0) / 40.0)  # Latin hypercube: one point per tenth of the range
    assert sorted(strata.tolist()) == list(range(10))
    z = study_from_dict(_study(parameters=box, sampling={"method": "saltelli", "samples": 4})).values
    fa, fb, fab = sampling.saltelli_blocks(z, 4, 2)
    assert np.array_equal(fab[0][:, 0], fb[:, 0]) and np.array_equal(fab[0][:, 1], fa[:, 1])


def test_list_method_zips_and_checks_lengths() -> None:
    s = study_from_dict(_study(parameters={"body.mass_kg": [1000.0, 1100.0], "final_drive.ratio": [3.0, 4.0]},
                               sampling={"method": "list"}))  # fmt: skip
    assert s.values.tolist() == [[1000.0, 3.0], [1100.0, 4.0]]
    with pytest.raises(StudyError, match="equal lengths"):
        study_from_dict(_study(parameters={"body.mass_kg": [1000.0], "final_drive.ratio": [3.0, 4.0]},
                               sampling={"method": "list"}))  # fmt: skip


# ------------------------------------------------------------------------------------------
# Analysis
# ------------------------------------------------------------------------------------------
def test_pareto_front_equals_brute_force() -> None:
    rng = np.random.default_rng(5)
    f = rng.random((300, 3))
    f[::17, 1] = np.nan  # never on the front
    f[10] = f[11]  # duplicates are kept together
    maximize = np.array([False, True, False])
    mask = pareto_mask(f, maximize)
    g = np.where(maximize, -f, f)
    brute = np.zeros(len(f), dtype=bool)
    for i in range(len(f)):
        if not np.all(np.isfinite(g[i])):
            continue
        others = g[np.all(np.isfinite(g), axis=1)]
        brute[i] = not np.any(np.all(others <= g[i], axis=1) & np.any(others < g[i], axis=1))
    assert np.array_equal(mask, brute)
    assert 3 < mask.sum() < 300


def _ishigami(x: np.ndarray, a: float = 7.0, b: float = 0.1) -> np.ndarray:
    return np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])


def test_sobol_indices_of_ishigami_within_sampling_error() -> None:
    axes = [sampling.Axis(f"x{i}", low=-np.pi, high=np.pi) for i in range(3)]
    n = 4096
    x = sampling.saltelli(axes, n, seed=11)
    fa, fb, fab = sampling.saltelli_blocks(_ishigami(x), n, 3)
    t = sobol_indices(fa, fb, fab, bootstrap=100, seed=1)
    # analytic values (Ishigami & Homma 1990, a = 7, b = 0.1)
    s1 = np.array([0.3139, 0.4424, 0.0])
    st = np.array([0.5576, 0.4424, 0.2437])
    assert np.all(np.abs(t["S1"] - s1) <= 4 * t["S1_se"] + 0.01), t
    assert np.all(np.abs(t["ST"] - st) <= 4 * t["ST_se"] + 0.01), t
    assert np.all(t["S1_se"] < 0.05)
    assert np.all(np.abs(t["S1"] - s1) < 0.06) and np.all(np.abs(t["ST"] - st) < 0.06)


def test_regression_ranking_recovers_linear_weights() -> None:
    rng = np.random.default_rng(2)
    x = rng.random((400, 3))
    y = 3.0 * x[:, 0] - 1.0 * x[:, 1] + 0.0 * x[:, 2]
    src, r2 = regression_ranking(x, y)
    expect = np.array([3.0, -1.0, 0.0]) * x.std(axis=0) / y.std()
    assert r2 == pytest.approx(1.0, abs=1e-12)
    assert np.allclose(src, expect, atol=1e-9)


# ------------------------------------------------------------------------------------------
# Bad input on the command line: exit 2, message, no output folder
# ------------------------------------------------------------------------------------------
def test_cli_bad_study_exits_2_without_output(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    inverted = '"body.mass_kg" = {min = 1500.0, max = 1200.0, num = 2}'
    p = _write_series_study(tmp_path, f"[parameters]\n{inverted}\n")
    out = tmp_path / "out"
    assert main(["study", str(p), "--out", str(out), "--scheduler", "in-process"]) == 2
    err = capsys.readouterr().err
    assert "body.mass_kg" in err and "min = 1500" in err and "Traceback" not in err
    assert not out.exists() and sorted(x.name for x in tmp_path.iterdir()) == ["study.toml"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_unreachable_scheduler_is_a_clear_error_within_10_s(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    p = _write_series_study(tmp_path, '[parameters]\n"body.mass_kg" = [1100.0, 1200.0]\n')
    out = tmp_path / "out"
    address = f"tcp://127.0.0.1:{_free_port()}"
    study = load_study(p)
    t0 = time.monotonic()
    with pytest.raises(StudyError, match="cannot reach the Dask scheduler") as exc:
        run_study(study, out, scheduler=address)
    assert time.monotonic() - t0 < 10.0
    assert address in str(exc.value) and not out.exists()
    monkeypatch.setenv("HEVSIM_DASK_SCHEDULER", address)  # the CLI reads the environment
    assert main(["study", str(p), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "cannot reach the Dask scheduler" in err and "Traceback" not in err and not out.exists()
    with pytest.raises(StudyError, match="tcp://HOST:PORT"):
        run_study(study, scheduler="localhost:8786")

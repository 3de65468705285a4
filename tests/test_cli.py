"""The hevsim command: outputs, refinement table and bad input (exit 2, no partial output)."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from hevsim.cli import main
from hevsim.refinement import format_table, run_refinement

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "series_hev.toml"


def test_simulate_writes_results_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    assert main(["simulate", str(EXAMPLE), "--cycle", "fu505", "--out", str(out)]) == 0
    for name in ("timeseries.parquet", "timeseries.csv", "metrics.json", "config.json",
                 "events.csv", "energy_audit.json", "report.md", "speed_tracking.png",
                 "soc.png", "currents.png", "engine.png", "engine_operating_points.png"):  # fmt: skip
        assert (out / name).is_file(), name
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["mpgge"]["unit"] == "mi/gal" and metrics["mpgge"]["value"] > 0
    ts = pd.read_parquet(out / "timeseries.parquet")
    assert ts["time_s"].iloc[-1] == pytest.approx(505.0)
    assert "mpgge" in capsys.readouterr().out
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp leftovers


def test_cycles_command_lists_udds(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["cycles"]) == 0
    text = capsys.readouterr().out
    assert "udds" in text and "1369" in text and "fu505x10" in text


def test_refinement_levels_lower_mpgge() -> None:
    rows = run_refinement("fu505", progress=False)
    assert len(rows) == 8
    mpgge = [r["mpgge"] for r in rows]
    # levels 1-3 add no loss; every later level adds one and must lower MPGGE
    for i in range(3, 8):
        assert mpgge[i] < mpgge[i - 1], (i + 1, mpgge)
    assert all(r["energy_audit_residual_pct"] < 0.5 for r in rows)
    assert "| 8 |" in format_table(rows, "fu505")


def _bad_run(tmp_path: Path, args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    out = tmp_path / "out"
    assert main([*args, "--out", str(out)]) == 2
    assert not out.exists()
    assert not list(tmp_path.glob(".out*"))
    return capsys.readouterr().err


def _cycle_csv(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "my_cycle.csv"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    ("csv", "fragments"),
    [
        ("time_s,velocity\n0,0\n1,1\n", ["my_cycle.csv", "speed"]),
        ("time_s,speed_mps\n0,0\n2,1\n1,2\n", ["my_cycle.csv", "line 4"]),
        ("time_s,speed_mps\n0,0\n1,nan\n2,2\n", ["my_cycle.csv", "line 3"]),
        ("time_s,speed_mps\n0,0\n1,-3\n2,2\n", ["my_cycle.csv", "-3"]),
    ],
)
def test_bad_cycle_csv(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], csv: str, fragments: list[str]
) -> None:
    path = _cycle_csv(tmp_path, csv)
    err = _bad_run(tmp_path, ["simulate", str(EXAMPLE), "--cycle", str(path)], capsys)
    for f in fragments:
        assert f in err


def _config(tmp_path: Path, extra: str) -> Path:
    p = tmp_path / "car.toml"
    p.write_text(EXAMPLE.read_text() + "\n" + extra)
    return p


@pytest.mark.parametrize(
    ("extra", "fragments"),
    [
        ("[wheels]\nradius_m = 0.3\n", ["car.toml", "'wheels'", "valid top-level keys"]),
        ("[tires]\n", ["car.toml", "'tires'"]),
    ],
)
def test_bad_config_unknown_section(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: str, fragments: list[str]
) -> None:
    err = _bad_run(tmp_path, ["simulate", str(_config(tmp_path, extra))], capsys)
    for f in fragments:
        assert f in err


def _edit(tmp_path: Path, old: str, new: str) -> Path:
    p = tmp_path / "car.toml"
    text = EXAMPLE.read_text()
    assert old in text
    p.write_text(text.replace(old, new, 1))
    return p


@pytest.mark.parametrize(
    ("old", "new", "fragments"),
    [
        ("mass_kg = 1200.0", "mass_kgs = 1200.0", ["'body.mass_kgs'", "not known", "mass_kg"]),
        ("mass_kg = 1200.0", 'mass_kg = "heavy"', ["'body.mass_kg'", "'heavy'", "a number"]),
        (
            'data = "vw_1p9_tdi_ci67"',
            'data = "no_such_engine"',
            ["engine.data", "no_such_engine", "vw_1p9_tdi_ci67"],
        ),
        ("soc_low = 0.6", "soc_low = 0.8", ["soc_low", "0.8", "soc_high"]),
        ('model = "table"', 'model = "tabel"', ["battery.model", "tabel", "rint"]),
    ],
)
def test_bad_config_values(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], old: str, new: str, fragments: list[str]
) -> None:
    err = _bad_run(tmp_path, ["simulate", str(_edit(tmp_path, old, new))], capsys)
    assert "car.toml" in err or "engine.data" in err
    for f in fragments:
        assert f in err


def test_missing_config_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    err = _bad_run(tmp_path, ["simulate", str(tmp_path / "nope.toml")], capsys)
    assert "nope.toml" in err and "not found" in err


def test_map_with_unsorted_axis(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import shutil

    from hevsim.sim.model import resolve_component

    src = resolve_component("vw_1p9_tdi_ci67", "engine", tmp_path, "engine.data")
    dst = tmp_path / "my_engine"
    shutil.copytree(src, dst)
    lines = (dst / "max_torque.csv").read_text().splitlines()
    lines[2], lines[3] = lines[3], lines[2]
    (dst / "max_torque.csv").write_text("\n".join(lines) + "\n")
    cfg = _edit(tmp_path, 'data = "vw_1p9_tdi_ci67"', 'data = "my_engine"')
    err = _bad_run(tmp_path, ["simulate", str(cfg)], capsys)
    assert "max_torque.csv" in err and "not strictly increasing" in err

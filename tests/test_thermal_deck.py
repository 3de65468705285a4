"""``hevsim thermal DECK.inp`` (issue 26 item 7): a deck runs from the command line, writing
VTU fields and summary.json; ``*Heat Transfer, deltmx=`` gets Abaqus's automatic
incrementation (was: silently fixed increments); bad increment options are refused by line.
CalculiX (``ccx``, skipped without it) is the independent reference."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("skfem")

from tests.test_thermal_abaqus import write_deck
from tests.test_thermal_nonlinear import _bar_deck

from hevsim.cli import main
from hevsim.thermal.abaqus import read_abaqus_inp
from hevsim.thermal.deck import run_deck


def _heated_bar(path: Path, step: str) -> Path:
    """The two-section bar of test_thermal_abaqus (mm, adiabatic) with 1 MW/m^3 in its plastic half."""
    write_deck(path)
    text = (
        path.read_text().replace("*Heat Transfer\n1., 300.", step).replace("CELL, BF, 1000.", "CELL, BF, 1e6")
    )
    path.write_text(text)
    return path


def test_cli_runs_a_deck_and_writes_fields_and_summary(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    deck = _heated_bar(tmp_path / "bar.inp", "*Heat Transfer\n2., 60.")
    out = tmp_path / "res"
    code = main(["thermal", str(deck), "--out", str(out), "--length-scale", "1e-3", "--bonded-w-m2k", "1e6"])
    assert code == 0
    assert "30 increments" in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    m = {k: v["value"] for k, v in summary["metrics"].items()}
    assert m["increments"] == 30 and m["cutbacks"] == 0
    volume = 6e-3 * 4e-3 * 4e-3  # the heated half [m^3]
    assert m["heat_in_j"] == pytest.approx(1e6 * volume * 60.0, rel=1e-9)
    assert m["heat_to_films_j"] == pytest.approx(0.0, abs=1e-9)  # adiabatic deck
    assert abs(m["energy_balance_relative"]) <= 1e-9
    assert summary["metadata"]["incrementation"] == "fixed (initial increment)"
    assert set(summary["parts"]) == {"ALU", "CELL"} and "CELL" in summary["heat_sources"]
    pvd = (out / "temperature.pvd").read_text()
    assert pvd.count("<DataSet") == 31 and len(list((out / "fields").glob("*.vtu"))) == 31
    import meshio

    last = meshio.read(out / "fields" / "temperature_0030.vtu")
    assert last.point_data["temperature_c"].max() == pytest.approx(m["max_temp_c"])
    # the deck's own options belong to decks only
    assert (
        main(
            [
                "thermal",
                "examples/module_thermal.toml",
                "--length-scale",
                "1e-3",
                "--out",
                str(tmp_path / "x"),
            ]
        )
        == 2
    )


def test_deltmx_gives_automatic_increments(tmp_path: Path) -> None:
    """Automatic incrementation: every accepted increment changes no node by more than deltmx,
    the increments grow as the transient slows (far fewer than at the initial increment), and the
    end state matches a fixed-increment run at the smallest increment used to within the
    implicit-Euler error; with the same deck but ``direct`` the increments are fixed."""
    auto = run_deck(_heated_bar(tmp_path / "auto.inp", "*Heat Transfer, deltmx=2.\n0.1, 60., 1e-3, 20."),
                    length_scale_m=1e-3, bonded_w_m2k=1e6)  # fmt: skip
    steps = np.diff(auto.time_s)
    assert auto.time_s[-1] == pytest.approx(60.0, abs=1e-9)
    assert auto.max_change_k.max() <= 2.0
    assert steps.max() > 20 * steps[0] and len(steps) < 100
    assert auto.metadata["incrementation"] == "automatic, deltmx = 2 K"
    fine = run_deck(_heated_bar(tmp_path / "fine.inp", "*Heat Transfer\n0.1, 60."), length_scale_m=1e-3,
                    bonded_w_m2k=1e6)  # fmt: skip
    assert len(fine.time_s) == 601
    rise = fine.metrics["max_temp_c"]["value"] - 30.0
    assert rise > 10.0
    for key in ("max_temp_c", "min_temp_c"):
        assert abs(auto.metrics[key]["value"] - fine.metrics[key]["value"]) <= 0.02 * rise
    direct = run_deck(
        _heated_bar(tmp_path / "direct.inp", "*Heat Transfer, deltmx=2., direct\n5., 60."),
        length_scale_m=1e-3, bonded_w_m2k=1e6,
    )  # fmt: skip
    assert len(direct.time_s) == 13 and direct.metadata["incrementation"] == "fixed (initial increment)"


@pytest.mark.parametrize(
    ("step", "match"),
    [
        ("*Heat Transfer, deltmx=hot\n1., 60.", "bad.inp: line \\d+: \\*Heat Transfer, deltmx=hot"),
        ("*Heat Transfer, end=SS\n1., 60.", "bad.inp: line \\d+: \\*Heat Transfer, end=SS"),
        ("*Heat Transfer, deltmx=1., maxit=3\n1., 60.", "bad.inp: line \\d+: \\*Heat Transfer, maxit="),
        ("*Heat Transfer, deltmx=1.\n1., 60., 2., 30.", "minimum 2 s, maximum 30 s"),
    ],
)
def test_bad_increment_options_are_refused_by_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], step: str, match: str
) -> None:
    import re

    deck = _heated_bar(tmp_path / "bad.inp", step)
    assert main(["thermal", str(deck), "--out", str(tmp_path / "o"), "--length-scale", "1e-3"]) == 2
    err = capsys.readouterr().err
    assert re.search(match, err), err
    assert "Traceback" not in err and not (tmp_path / "o").exists()


def test_deltmx_unreachable_at_the_minimum_increment_names_the_line(tmp_path: Path) -> None:
    from hevsim.errors import SimulationError

    deck = _heated_bar(tmp_path / "stiff.inp", "*Heat Transfer, deltmx=0.01\n1., 60., 1., 10.")
    with pytest.raises(SimulationError, match=r"bar.inp|stiff.inp: line \d+: \*Heat Transfer, deltmx=0.01"):
        run_deck(deck, length_scale_m=1e-3, bonded_w_m2k=1e6)
    assert read_abaqus_inp(deck, length_scale_m=1e-3).deltmx_k == 0.01


@pytest.mark.skipif(shutil.which("ccx") is None, reason="CalculiX (ccx) is not installed")
def test_deltmx_deck_equals_calculix(tmp_path: Path) -> None:
    """The k(T) bar deck with films, 60 s from 30 degC with ``deltmx = 5``: hevsim's automatic
    increments against CalculiX in fixed 0.1 s increments (the accurate reference) on the same
    deck: within 1 % of the rise."""
    _bar_deck(tmp_path / "ccx.inp", "*Heat Transfer, direct\n0.1, 60.")
    text = (tmp_path / "ccx.inp").read_text()
    (tmp_path / "ccx.inp").write_text(text.replace("*Step\n", "*Step, inc=1000\n"))  # 600 increments
    _bar_deck(tmp_path / "bar.inp", "*Heat Transfer, deltmx=5.\n0.1, 60., 1e-3, 10.")
    run = subprocess.run(
        ["ccx", "-i", "ccx"], cwd=tmp_path, capture_output=True, text=True, timeout=300, check=False
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    block = (tmp_path / "ccx.dat").read_text().split("temperatures for set NALL")[-1]
    assert "0.6000000E+02" in block.splitlines()[0]
    ccx = {int(a): float(b) for a, b in (ln.split() for ln in block.splitlines()[2:] if ln.strip())}
    out = tmp_path / "res"
    assert main(["thermal", str(tmp_path / "bar.inp"), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["metadata"]["solver"] == "NonlinearHeatModel"
    assert summary["metrics"]["increments"]["value"] < 200
    assert max(summary["increment_max_change_k"]) <= 5.0
    import meshio

    model = read_abaqus_inp(tmp_path / "bar.inp")
    disc = model.discretise()
    last = sorted((out / "fields").glob("*.vtu"))[-1]
    ours = meshio.read(last).point_data["temperature_c"]
    theirs = np.array([ccx[int(lab)] for lab in np.asarray(model.node_labels)[disc.original_node]])
    rise = float(np.abs(theirs - 30.0).max())
    assert rise > 50.0
    assert np.abs(ours - theirs).max() <= 0.01 * rise

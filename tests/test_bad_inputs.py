"""The command line on a table of bad inputs: a clean one-line error, the right exit status,
no traceback, and no pre-existing file touched.

Each case writes its input files into a sandbox that also holds canary files: one beside the
output target and one inside it (the target is a pre-existing folder that is not a hevsim
results folder, passed with ``--force`` where the command has it, so only the bad input can
stop the run). The whole sandbox (names, sizes, contents, modification times) must be the
same after the failed run (files: contents and modification times; folders: existence), and
the working directory (the sandbox) must gain no files.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

import pytest

from hevsim.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "series_hev.toml"
CELL_EXAMPLE = ROOT / "examples" / "cell.toml"
MODULE_EXAMPLE = ROOT / "examples" / "module.toml"
SSD_EXAMPLE = ROOT / "examples" / "cosim_module" / "module.ssd"
THERMAL_EXAMPLE = ROOT / "examples" / "module_thermal.toml"
LEVEL2 = Path(str(files("hevsim") / "data" / "refinement" / "level2_ideal_battery_soc.toml"))


def _section(name: str) -> str:
    """The current name of a renamed configuration section (``motor`` was ``traction_motor``)."""
    from hevsim import config

    renamed = getattr(config, "RENAMED_SECTIONS", {})
    return renamed.get(name, name)


# ------------------------------------------------------------------------------ helpers
def _edit_text(src: Path, dst: Path, old: str, new: str) -> Path:
    text = src.read_text()
    assert old in text, f"{old!r} not in {src}"
    dst.write_text(text.replace(old, new, 1))
    return dst


def _set_key(src: Path, dst: Path, section: str, key: str, value: str) -> Path:
    """Copy TOML ``src`` to ``dst`` with ``[section] key = value`` (replaced or added)."""
    lines = src.read_text().splitlines()
    header = f"[{section}]"
    try:
        start = next(i for i, line in enumerate(lines) if line.split("#")[0].strip() == header)
    except StopIteration:
        lines += ["", header, f"{key} = {value}"]
    else:
        end = next((i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith("[")), len(lines))
        for i in range(start + 1, end):
            if lines[i].split("=")[0].strip() == key:
                lines[i] = f"{key} = {value}"
                break
        else:
            lines.insert(start + 1, f"{key} = {value}")
    dst.write_text("\n".join(lines) + "\n")
    return dst


def car(d: Path, section: str, key: str, value: str) -> Path:
    """The series HEV example with one value changed."""
    return _set_key(EXAMPLE, d / "car.toml", _section(section), key, value)


def cell(d: Path, section: str, key: str, value: str) -> Path:
    return _set_key(CELL_EXAMPLE, d / "cell.toml", section, key, value)


def csv(d: Path, text: str, name: str = "cycle.csv") -> Path:
    p = d / name
    p.write_text(text)
    return p


def simulate(cfg: Path, *extra: str) -> list[str]:
    return ["simulate", str(cfg), "--no-plots", *extra]


def cycle_case(text: str) -> Callable[[Path], list[str]]:
    return lambda d: simulate(EXAMPLE, "--cycle", str(csv(d, text)))


def bad_fmu_ssd(d: Path) -> Path:
    (d / "corrupt.fmu").write_bytes(b"PK\x03\x04 broken")
    return _edit_text(SSD_EXAMPLE, d / "module.ssd", 'source="module_2s6p.fmu"', 'source="corrupt.fmu"')


def schedule(d: Path, text: str) -> list[str]:
    return simulate(EXAMPLE, "--cycle", "fu505", "--schedule", str(csv(d, text, "schedule.csv")))


@dataclass(frozen=True)
class Case:
    id: str
    argv: Callable[[Path], list[str]]
    code: int
    fragments: tuple[str, ...]


CASES = [
    # --- vehicle configuration files -----------------------------------------------------
    Case("config-missing", lambda d: simulate(d / "nope.toml"), 2, ("nope.toml", "not found")),
    Case(
        "config-malformed-toml",
        lambda d: simulate(csv(d, "[body\nmass_kg = 1\n", "car.toml")),
        2,
        ("car.toml",),
    ),
    Case(
        "config-unknown-section",
        lambda d: simulate(_set_key(EXAMPLE, d / "car.toml", "wheels", "radius_m", "0.3")),
        2,
        ("car.toml", "'wheels'", "not known"),
    ),
    Case(
        "config-unknown-key",
        lambda d: simulate(car(d, "body", "masss_kg", "1200.0")),
        2,
        ("car.toml", "body.masss_kg", "not known"),
    ),
    Case(
        "config-wrong-type",
        lambda d: simulate(car(d, "body", "mass_kg", '"heavy"')),
        2,
        ("car.toml", "body.mass_kg", "heavy"),
    ),
    Case(
        "config-unknown-architecture",
        lambda d: simulate(car(d, "powertrain", "architecture", '"tandem"')),
        2,
        ("architecture", "tandem", "series"),
    ),
    Case(
        "config-unknown-engine-map",
        lambda d: simulate(car(d, "engine", "data", '"no_such_engine"')),
        2,
        ("engine.data", "no_such_engine"),
    ),
    Case(
        "config-soc-band-inverted",
        lambda d: simulate(car(d, "controller", "soc_low", "0.8")),
        2,
        ("soc_low", "0.8", "soc_high"),
    ),
    Case(
        "config-soc-initial-1.5",
        lambda d: simulate(car(d, "simulation", "soc_initial", "1.5")),
        2,
        ("soc_initial", "1.5"),
    ),
    Case(
        "config-drag-inf",
        lambda d: simulate(car(d, "body", "drag_coefficient", "inf")),
        2,
        ("drag_coefficient", "inf"),
    ),
    Case(
        "config-drag-nan",
        lambda d: simulate(car(d, "body", "drag_coefficient", "nan")),
        2,
        ("drag_coefficient", "nan"),
    ),
    Case(
        "config-negative-rolling-resistance",
        lambda d: simulate(car(d, "body", "rolling_resistance", "-0.01")),
        2,
        ("rolling_resistance", "-0.01"),
    ),
    Case(
        "config-negative-frontal-area",
        lambda d: simulate(car(d, "body", "frontal_area_m2", "-3.0")),
        2,
        ("frontal_area_m2", "-3"),
    ),
    Case("config-zero-mass", lambda d: simulate(car(d, "body", "mass_kg", "0.0")), 2, ("mass_kg", "0")),
    Case(
        "config-zero-tire-radius", lambda d: simulate(car(d, "tire", "radius_m", "0.0")), 2, ("radius_m", "0")
    ),
    Case(
        "config-negative-torque-scale",
        lambda d: simulate(car(d, "traction_motor", "torque_scale", "-1.0")),
        2,
        ("torque_scale", "-1"),
    ),
    Case(
        "config-negative-current-limit",
        lambda d: simulate(car(d, "battery", "max_discharge_current_a", "-10.0")),
        2,
        ("max_discharge_current_a", "-10"),
    ),
    Case(
        "config-soc-window-outside-unit",
        lambda d: simulate(car(d, "battery", "soc_max", "1.2")),
        2,
        ("soc_max", "1.2"),
    ),
    # --- command-line options ----------------------------------------------------------------
    Case(
        "option-soc-initial-1.5",
        lambda d: simulate(EXAMPLE, "--soc-initial", "1.5"),
        2,
        ("--soc-initial", "1.5"),
    ),
    Case(
        "option-soc-initial-nan",
        lambda d: simulate(EXAMPLE, "--soc-initial", "nan"),
        2,
        ("--soc-initial", "nan"),
    ),
    Case("option-negative-dt", lambda d: simulate(EXAMPLE, "--dt", "-0.5"), 2, ("--dt", "-0.5")),
    Case("option-zero-dt", lambda d: simulate(EXAMPLE, "--dt", "0"), 2, ("--dt", "0")),
    Case("option-dt-not-a-number", lambda d: simulate(EXAMPLE, "--dt", "fast"), 2, ("--dt", "fast")),
    Case("option-unknown", lambda d: simulate(EXAMPLE, "--turbo"), 2, ("--turbo",)),
    Case("option-unknown-command", lambda d: ["fly"], 2, ("fly",)),
    # --- drive cycles ------------------------------------------------------------------------
    Case("cycle-unknown-name", lambda d: simulate(EXAMPLE, "--cycle", "nosuch"), 2, ("nosuch", "udds")),
    Case(
        "cycle-directory",
        lambda d: simulate(EXAMPLE, "--cycle", str(d)),
        2,
        ("is a directory", "expected a CSV file or a shipped cycle name"),
    ),
    Case(
        "cycle-1000-mps",
        cycle_case("time_s,speed_mps\n0,0\n1,1000\n2,0\n"),
        2,
        ("cycle.csv", "line 3", "speed_mps", "1000", "150 m/s"),
    ),
    Case(
        "cycle-nan-speed",
        cycle_case("time_s,speed_mps\n0,0\n1,nan\n2,2\n"),
        2,
        ("cycle.csv", "line 3", "nan"),
    ),
    Case("cycle-inf-time", cycle_case("time_s,speed_mps\n0,0\ninf,1\n"), 2, ("cycle.csv", "line 3", "inf")),
    Case(
        "cycle-time-not-increasing",
        cycle_case("time_s,speed_mps\n0,0\n2,1\n1,2\n"),
        2,
        ("cycle.csv", "line 4", "strictly increasing"),
    ),
    Case("cycle-negative-time", cycle_case("time_s,speed_mps\n-1,0\n1,1\n"), 2, ("cycle.csv", "-1", ">= 0")),
    Case("cycle-negative-speed", cycle_case("time_s,speed_mps\n0,0\n1,-3\n2,2\n"), 2, ("cycle.csv", "-3")),
    Case("cycle-no-speed-column", cycle_case("time_s,velocity\n0,0\n1,1\n"), 2, ("cycle.csv", "speed")),
    Case("cycle-not-a-number", cycle_case("time_s,speed_mps\n0,0\n1,fast\n"), 2, ("cycle.csv", "fast")),
    Case("cycle-one-row", cycle_case("time_s,speed_mps\n0,0\n"), 2, ("cycle.csv", "at least 2")),
    Case("cycle-empty-file", cycle_case(""), 2, ("cycle.csv", "header")),
    Case("cycle-ragged-row", cycle_case("time_s,speed_mps\n0,0\n1\n"), 2, ("cycle.csv", "line 3")),
    Case(
        "cycle-never-moves",
        cycle_case("time_s,speed_mps\n0,0\n100,0\n"),
        2,
        ("stands still", "distance 0 m"),
    ),
    # --- schedules --------------------------------------------------------------------------
    Case(
        "schedule-missing",
        lambda d: simulate(EXAMPLE, "--schedule", str(d / "nope.csv")),
        2,
        ("nope.csv", "not found"),
    ),
    Case(
        "schedule-no-speed-column",
        lambda d: schedule(d, "time_s,engine_throttle\n0,0.5\n"),
        2,
        ("schedule.csv", "engine_speed_rpm"),
    ),
    Case(
        "schedule-nan",
        lambda d: schedule(d, "time_s,engine_speed_rpm,engine_throttle\n0,1500,0.5\n10,nan,0.5\n"),
        2,
        ("schedule.csv", "nan", "finite"),
    ),
    # --- runs that leave the physical domain or cannot follow the cycle --------------------
    Case(  # the pack stops at its floor (soc_min): the EV then falls behind the trace
        "run-battery-runs-dry",
        lambda d: simulate(LEVEL2, "--cycle", "us06"),
        3,
        ("could not follow", "t = ", "battery is empty"),
    ),
    Case(
        "run-motor-too-weak",
        lambda d: simulate(car(d, "traction_motor", "torque_scale", "0.3"), "--cycle", "us06"),
        3,
        ("could not follow", "t = 50 s", "motor-limited"),
    ),
    Case(
        "run-brakes-too-weak",
        lambda d: simulate(car(d, "brakes", "max_decel_mps2", "0.3")),
        3,
        ("could not follow", "brakes"),
    ),
    Case(
        "run-battery-current-limit",
        lambda d: simulate(car(d, "battery", "max_discharge_current_a", "10.0"), "--cycle", "us06"),
        3,
        ("could not follow", "battery power-limited"),
    ),
    # --- cells --------------------------------------------------------------------------------
    Case(
        "cell-4000-a",
        lambda d: ["cell", str(cell(d, "profile", "current_a", "4000.0"))],
        2,
        ("4000 A", "short-circuit current", "t = 1 s"),
    ),
    Case(
        "cell-minus-4000-a",
        lambda d: ["cell", str(cell(d, "profile", "current_a", "-4000.0"))],
        2,
        ("-4000 A", "150..500 K"),
    ),
    Case(
        "module-current-beyond-cells",
        lambda d: ["cell", str(_set_key(MODULE_EXAMPLE, d / "module.toml", "profile", "scale", "2000.0"))],
        2,
        ("2s6p module", "terminal voltage", "short-circuit current"),
    ),
    Case(
        "cell-soc-initial-1.5",
        lambda d: ["cell", str(cell(d, "cell", "soc_initial", "1.5"))],
        2,
        ("cell.soc_initial", "1.5"),
    ),
    Case(
        "cell-unknown-parameters",
        lambda d: ["cell", str(cell(d, "cell", "parameters", '"unobtainium"'))],
        2,
        ("unobtainium",),
    ),
    Case(
        "cell-unknown-profile-kind",
        lambda d: ["cell", str(cell(d, "profile", "kind", '"sine"'))],
        2,
        ("profile.kind", "sine", "constant"),
    ),
    Case(
        "cell-zero-dt",
        lambda d: ["cell", str(cell(d, "profile", "dt_s", "0.0"))],
        2,
        ("profile.dt_s", "0"),
    ),
    Case(
        "cell-nan-current",
        lambda d: ["cell", str(cell(d, "profile", "current_a", "nan"))],
        2,
        ("nan",),
    ),
    # --- dynamic programming ------------------------------------------------------------
    Case(
        "optimize-soc-points-0",
        lambda d: ["optimize", str(EXAMPLE), "--cycle", "fu505", "--no-plots", "--soc-points", "0"],
        2,
        ("--soc-points", "0"),
    ),
    Case(
        "optimize-input-points-1",
        lambda d: ["optimize", str(EXAMPLE), "--cycle", "fu505", "--no-plots", "--input-points", "1"],
        2,
        ("--input-points", "1"),
    ),
    Case(
        "optimize-soc-initial-1.5",
        lambda d: ["optimize", str(EXAMPLE), "--cycle", "fu505", "--no-plots", "--soc-initial", "1.5"],
        2,
        ("--soc-initial", "1.5"),
    ),
    Case(
        "compare-unknown-cycle",
        lambda d: ["compare", str(EXAMPLE), "--cycles", "udds,nosuch"],
        2,
        ("nosuch",),
    ),
    # --- co-simulation, thermal, calibration ---------------------------------------------
    Case(
        "cosim-unknown-file-type",
        lambda d: ["cosim", str(csv(d, "hello", "system.txt")), "--check"],
        2,
        ("system.txt", ".ssp"),
    ),
    Case(
        "cosim-malformed-xml",
        lambda d: ["cosim", str(_edit_text(SSD_EXAMPLE, d / "bad.ssd", "</", "<")), "--check"],
        2,
        ("bad.ssd",),
    ),
    Case(
        "cosim-bad-fmu-check",
        lambda d: ["cosim", str(bad_fmu_ssd(d)), "--check"],
        2,
        ("corrupt.fmu", "not a valid FMU"),
    ),
    Case(
        "cosim-bad-fmu-run",
        lambda d: ["cosim", str(bad_fmu_ssd(d))],
        2,
        ("corrupt.fmu", "not a valid FMU"),
    ),
    Case(
        "thermal-unknown-key",
        lambda d: ["thermal", str(_set_key(THERMAL_EXAMPLE, d / "case.toml", "simulation", "bogus", "1.0"))],
        2,
        ("simulation.bogus", "not known"),
    ),
    Case(
        "thermal-negative-dt",
        lambda d: ["thermal", str(_set_key(THERMAL_EXAMPLE, d / "case.toml", "simulation", "dt_s", "-1.0"))],
        2,
        ("simulation.dt_s", "-1"),
    ),
    Case(
        "calibrate-malformed-fit",
        lambda d: [
            "calibrate",
            "thesis_table_4_1",
            str(csv(d, "time_s,current_a,voltage_v,temp_k\n0,0,4,298\n1,1,4,298\n2,1,4,298\n", "test.csv")),
            "--fit",
            "c_heat=90",
        ],
        2,
        ("--fit", "c_heat=90", "INITIAL,LOWER,UPPER"),
    ),
    Case(
        "calibrate-missing-test-file",
        lambda d: ["calibrate", "thesis_table_4_1", str(d / "nope.csv"), "--fit", "c_heat=90,10,1000"],
        2,
        ("nope.csv",),
    ),
    Case(
        "age-unknown-key",
        lambda d: ["age", str(cell(d, "cell", "colour", '"red"')), "--repetitions", "2"],
        2,
        ("cell.colour", "not known"),
    ),
    Case(
        "export-fmu-missing-config",
        lambda d: ["export-fmu", str(d / "nope.toml")],
        2,
        ("nope.toml",),
    ),
]


# ------------------------------------------------------------------------------ machinery
def _subparser(command: str) -> argparse.ArgumentParser | None:
    for action in build_parser()._subparsers._group_actions:  # type: ignore[union-attr]
        if isinstance(action, argparse._SubParsersAction):
            return action.choices.get(command)
    return None


def _with_target(argv: list[str], target: Path) -> list[str]:
    """``argv`` writing to ``target`` (forced where possible, so only bad input can stop it)."""
    sub = _subparser(argv[0]) if argv else None
    if sub is None:
        return argv
    options = sub._option_string_actions
    out_opt = "--out" if "--out" in options else ("-o" if "-o" in options else None)
    if out_opt is None:
        return argv
    if out_opt == "-o":
        return [*argv, "-o", str(target / "module.fmu"), *(["--force"] if "--force" in options else [])]
    if "--force" in options:
        return [*argv, "--out", str(target), "--force"]
    return [*argv, "--out", str(target / "run")]


def _snapshot(root: Path) -> dict[str, tuple[int, str]]:
    """Every file and folder under ``root``: for a file its mtime [ns] and content hash (a
    folder's mtime is not compared: it changes when a temporary file comes and goes)."""
    snap: dict[str, tuple[int, str]] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames:
            snap[str((Path(dirpath) / name).relative_to(root))] = (0, "folder")
        for name in filenames:
            p = Path(dirpath) / name
            snap[str(p.relative_to(root))] = (
                p.lstat().st_mtime_ns,
                hashlib.sha256(p.read_bytes()).hexdigest(),
            )
    return snap


@pytest.fixture
def sandbox(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[Path, Path]:
    """(inputs folder, target folder) with canary files beside and inside the target; the
    working directory is the sandbox so stray default outputs (``results/``) are seen."""
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    target = tmp_path / "target"
    target.mkdir()
    (target / "keep-inside.txt").write_text("canary inside the target\n")
    (tmp_path / "keep-beside.txt").write_text("canary beside the target\n")
    monkeypatch.chdir(tmp_path)
    return inputs, target


def _run(argv: list[str]) -> int:
    try:
        return main(argv)
    except SystemExit as exc:  # argparse usage errors
        return int(exc.code or 0)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input(case: Case, sandbox: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    inputs, target = sandbox
    argv = _with_target(case.argv(inputs), target)
    root = target.parent
    before = _snapshot(root)
    code = _run(argv)
    captured = capsys.readouterr()
    err = captured.err
    assert code == case.code, f"exit {code}, expected {case.code}; stderr: {err}"
    assert "Traceback" not in err + captured.out
    assert err.strip(), "no message on stderr"
    for fragment in case.fragments:
        assert fragment in err, f"{fragment!r} not in: {err}"
    assert "np.float64" not in err
    assert _snapshot(root) == before, "a file was written, changed or removed"


def test_table_is_large_enough() -> None:
    assert len(CASES) >= 40
    assert len({c.id for c in CASES}) == len(CASES)


@pytest.mark.parametrize(
    "case_id", ["config-drag-inf", "cycle-directory", "cell-4000-a", "run-brakes-too-weak"]
)
def test_no_traceback_from_the_real_command(case_id: str, sandbox: tuple[Path, Path]) -> None:
    """The installed entry point (a new process) prints one message, no traceback."""
    inputs, target = sandbox
    case = next(c for c in CASES if c.id == case_id)
    argv = _with_target(case.argv(inputs), target)
    before = _snapshot(target.parent)
    proc = subprocess.run(
        [sys.executable, "-m", "hevsim.cli", *argv], capture_output=True, text=True, check=False
    )
    assert proc.returncode == case.code, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr.startswith("hevsim: error: ")
    assert len(proc.stderr.strip().splitlines()) == 1
    for fragment in case.fragments:
        assert fragment in proc.stderr
    assert _snapshot(target.parent) == before


def test_tracking_error_is_documented_exit_3() -> None:
    from hevsim.errors import DomainError, HevsimError, TrackingError

    assert TrackingError.exit_code == 3 and DomainError.exit_code == 2
    assert issubclass(TrackingError, HevsimError) and issubclass(DomainError, HevsimError)
    import hevsim.cli

    assert "3" in (hevsim.cli.__doc__ or "") and "TrackingError" in (hevsim.cli.__doc__ or "")

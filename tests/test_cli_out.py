"""``--out`` never deletes anything the user made (issue 10, item 1).

Every command with an output refuses, with exit 2, a one-line message and before any
computation, an output path that would replace the user's files, the working directory, an
input or that cannot be written; hevsim results folders (recognised by their marker) are
replaced, and ``--force`` replaces a foreign folder but never the working directory.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from hevsim.cli import main
from hevsim.errors import OutputError
from hevsim.io import MARKER, atomic_directory, prepare_output, results_files

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"
CELL = EX / "cell.toml"
SERIES = EX / "series_hev.toml"
PARALLEL = EX / "parallel_hev.toml"

# command -> (argv before the output option, output option, output kind, the computation to forbid)
COMMANDS: dict[str, tuple[list[str], str, str, str]] = {
    "simulate": (
        ["simulate", str(SERIES), "--cycle", "fu505"],
        "--out",
        "dir",
        "hevsim.sim.simulator:simulate",
    ),
    "optimize": (
        ["optimize", str(SERIES), "--cycle", "fu505"],
        "--out",
        "dir",
        "hevsim.optimal.hev:optimize",
    ),
    "compare": (
        ["compare", str(SERIES), "--cycles", "fu505"],
        "--out",
        "dir",
        "hevsim.optimal.compare:compare",
    ),
    "cell": (["cell", str(CELL)], "--out", "dir", "hevsim.battery.config:run_config"),
    "calibrate": (
        ["calibrate", "thesis_table_4_1", str(ROOT / "no_such_test.csv"), "--fit", "c_heat=90,10,1000"],
        "--out",
        "dir",
        "hevsim.battery.calibrate:calibrate",
    ),
    "age": (["age", str(CELL), "--repetitions", "1"], "--out", "dir", "hevsim.battery.ageing:age_cell"),
    "thermal": (
        ["thermal", str(EX / "module_thermal.toml")],
        "--out",
        "dir",
        "hevsim.thermal.run:run_thermal",
    ),
    "cosim": (
        ["cosim", str(EX / "cosim_module" / "module.ssd")],
        "--out",
        "dir",
        "hevsim.cosim.system:run_cosim",
    ),
    "export-fmu": (["export-fmu", str(CELL)], "-o", "file", "hevsim.battery.native:export_native_fmu"),
    "refinement": (["refinement", "--cycle", "fu505"], "--out", "file", "hevsim.refinement:run_refinement"),
}


def _forbid_computation(monkeypatch: pytest.MonkeyPatch, target: str) -> None:
    module, name = target.split(":")

    def computed(*args: object, **kwargs: object) -> None:
        raise AssertionError(f"{target} ran although the output path is refused")

    monkeypatch.setattr(f"{module}.{name}", computed)


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _refused(capsys: pytest.CaptureFixture[str], argv: list[str], *fragments: str) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("hevsim: error: "), err
    assert "Traceback" not in err
    for f in fragments:
        assert f in err, (f, err)
    return err


@pytest.fixture
def site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A working directory with a canary file, a folder of the user's and a file of the user's."""
    work = tmp_path / "work"
    (work / "mine").mkdir(parents=True)
    (work / "mine" / "notes.txt").write_text("my notes\n")
    (work / "beside.txt").write_text("canary\n")
    (work / "thing.fmu").write_text("not an FMU of hevsim\n")
    (work / "table.md").write_text("# my own table\n")
    monkeypatch.chdir(work)
    return work


def _cases(command: str, kind: str, work: Path) -> list[tuple[str, str, list[str]]]:
    """(label, output path, expected message fragments) of refused outputs."""
    cases = [
        ("dot", ".", ["current working directory"]),
        ("abs-cwd", str(work), ["current working directory"]),
        ("parent-of-cwd", str(work.parent), ["contains the current working directory"]),
        ("under-a-file", str(work / "beside.txt" / "x"), ["beside.txt is a file, not a folder"]),
        ("read-only", "/proc/hevsim-out", ["cannot write in /proc"]),
    ]
    if kind == "dir":
        cases += [
            ("foreign-folder", "mine", ["exists and is not a hevsim results folder", "--force"]),
            ("existing-file", "beside.txt", ["exists and is a file"]),
        ]
    else:
        foreign = "table.md" if command == "refinement" else "thing.fmu"
        cases += [
            ("foreign-file", foreign, ["exists and was not written by hevsim", "--force"]),
            ("existing-folder", "mine", ["is a folder"]),
        ]
    return cases


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_refused_outputs_leave_everything_untouched(
    command: str, site: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    argv, option, kind, compute = COMMANDS[command]
    _forbid_computation(monkeypatch, compute)
    before = _snapshot(site.parent)
    for label, out, fragments in _cases(command, kind, site):
        err = _refused(capsys, [*argv, option, out], option, *fragments)
        assert _snapshot(site.parent) == before, (label, err)
        assert sorted(p.name for p in site.iterdir()) == ["beside.txt", "mine", "table.md", "thing.fmu"], (
            label
        )


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_force_never_replaces_cwd_or_a_folder_holding_an_input(
    command: str, site: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    argv, option, kind, compute = COMMANDS[command]
    _forbid_computation(monkeypatch, compute)
    before = _snapshot(site.parent)
    _refused(capsys, [*argv, option, ".", "--force"], "current working directory", "even with --force")
    _refused(capsys, [*argv, option, str(site), "--force"], "current working directory")
    if kind == "dir":
        # the folder holding an input (a copy of the configuration, or the test record)
        i = 2 if command == "calibrate" else 1
        held = site / "mine" / Path(argv[i]).name
        if Path(argv[i]).is_file():
            shutil.copy(argv[i], held)
        else:
            held.write_text("time_s,current_a,voltage_v,temp_k\n")
        before = _snapshot(site.parent)
        args = [*argv[:i], str(held), *argv[i + 1 :], option, "mine", "--force"]
        _refused(capsys, args, "contains the input")
    else:
        _refused(capsys, [*argv, option, "mine", "--force"], "is a folder")
    assert _snapshot(site.parent) == before


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores permission bits (the /proc case covers root)")
def test_non_writable_folder_is_refused(site: Path, capsys: pytest.CaptureFixture[str]) -> None:
    locked = site / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        _refused(capsys, ["cell", str(CELL), "--out", str(locked / "run")], "cannot write in")
    finally:
        locked.chmod(0o755)
    assert not list(locked.iterdir())


def test_simulate_rerun_force_empty_folder_and_message(
    site: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["simulate", str(SERIES), "--cycle", "fu505", "--no-plots"]
    # an empty existing folder loses nothing: accepted
    (site / "empty").mkdir()
    assert main([*argv, "--out", "empty"]) == 0
    out = capsys.readouterr().out
    files = sorted(p.name for p in (site / "empty").iterdir() if p.name != MARKER)
    assert results_files(site / "empty") == files
    assert f"results written to empty/ ({', '.join(files)})" in out
    assert "plot" not in out and "report.md" not in out
    # a rerun replaces a hevsim results folder (marker and nothing foreign)
    inode = (site / "empty").stat().st_ino
    assert main([*argv, "--out", "empty"]) == 0
    assert (site / "empty").stat().st_ino != inode  # a new folder was renamed into place
    assert results_files(site / "empty") == files
    # ... but not once the user put a file in it
    (site / "empty" / "my_analysis.py").write_text("print(1)\n")
    capsys.readouterr()
    _refused(capsys, [*argv, "--out", "empty"], "not a hevsim results folder")
    assert (site / "empty" / "my_analysis.py").read_text() == "print(1)\n"
    # --force replaces a foreign folder, moving it aside (issue 26 item 4); the canary stays
    capsys.readouterr()
    assert main([*argv, "--out", "mine", "--force"]) == 0
    assert not (site / "mine" / "notes.txt").exists()
    assert (site / "mine" / "metrics.json").is_file()
    (kept,) = site.glob("mine.replaced-*")
    assert (kept / "notes.txt").read_text() == "my notes\n"
    assert f"was moved to {kept}" in capsys.readouterr().err
    assert (site / "beside.txt").read_text() == "canary\n"
    assert not [p for p in site.iterdir() if p.name.startswith(".")]  # no temporary leftovers


def test_results_folder_gets_the_umask(tmp_path: Path) -> None:
    old = os.umask(0o027)
    try:
        with atomic_directory(tmp_path / "run") as tmp:
            (tmp / "a.txt").write_text("a")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "run").stat().st_mode) == 0o750
    marker = json.loads((tmp_path / "run" / MARKER).read_text())
    assert marker["files"] == ["a.txt"]
    assert {"hevsim_version", "command", "created"} <= set(marker)


def test_python_api_refuses_a_foreign_folder(tmp_path: Path) -> None:
    """The rule holds for the library too (result.save(...) goes through atomic_directory)."""
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine")
    with pytest.raises(OutputError, match="not a hevsim results folder"):
        with atomic_directory(tmp_path / "mine") as tmp:
            (tmp / "a.txt").write_text("a")
    assert _snapshot(tmp_path) == {"mine/notes.txt": b"mine"}
    # the user's file dropped into a results folder while a run computes: refused at the swap
    with pytest.raises(OutputError, match="not a hevsim results folder"):
        with atomic_directory(tmp_path / "run") as tmp:
            (tmp / "a.txt").write_text("a")
            (tmp_path / "run").mkdir()
            (tmp_path / "run" / "b.txt").write_text("b")
    assert _snapshot(tmp_path / "run") == {"b.txt": b"b"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "run"]
    with atomic_directory(tmp_path / "mine", force=True) as tmp:
        (tmp / "a.txt").write_text("a")
    assert results_files(tmp_path / "mine") == ["a.txt"]
    (kept,) = tmp_path.glob("mine.replaced-*")  # forced: the user's folder moved aside, not deleted
    assert _snapshot(kept) == {"notes.txt": b"mine"}


def test_prepare_output_files(tmp_path: Path) -> None:
    own = tmp_path / "own.md"
    own.write_text("ours\n")
    assert prepare_output(own, kind="file", ours=lambda p: p.read_text() == "ours\n") == own
    with pytest.raises(OutputError, match="was not written by hevsim"):
        prepare_output(own, kind="file", ours=lambda p: False)
    assert prepare_output(own, kind="file", force=True) == own
    with pytest.raises(OutputError, match="is a folder"):
        prepare_output(tmp_path, kind="file", force=True)
    with pytest.raises(OutputError, match="is the input"):
        prepare_output(own, kind="file", force=True, protect=[own])
    assert own.read_text() == "ours\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["own.md"]  # the probe file is gone


def test_refinement_replaces_its_own_table_only(
    site: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    rows = [
        {"level": 1, "name": "a", "description": "d", "mpg": 50.0, "mpgge": 40.0, "soc_final": 0.6,
         "speed_error_rms_mph": 0.1, "energy_audit_residual_pct": 1e-12},
    ]  # fmt: skip
    monkeypatch.setattr("hevsim.refinement.run_refinement", lambda cycle, **_: rows)
    assert main(["refinement", "--cycle", "fu505", "--out", "levels.md"]) == 0
    text = (site / "levels.md").read_text()
    assert text.startswith("Sequential refinement on fu505") and "| 1 | a: d |" in text
    assert main(["refinement", "--cycle", "udds", "--out", "levels.md"]) == 0  # its own file: replaced
    assert (site / "levels.md").read_text().startswith("Sequential refinement on udds")
    capsys.readouterr()
    _refused(capsys, ["refinement", "--out", "table.md"], "was not written by hevsim")
    assert main(["refinement", "--out", "table.md", "--force"]) == 0  # the default cycle: the thesis's FU505
    assert (site / "table.md").read_text().startswith("Sequential refinement on fu505")
    (kept,) = site.glob("table.md.replaced-*")  # the user's table moved aside (issue 26 item 4)
    assert kept.read_text() == "# my own table\n"
    assert f"was moved to {kept}" in capsys.readouterr().err
    assert main(["refinement", "--out", "table.md", "--force"]) == 0  # now its own: replaced
    assert len(list(site.glob("table.md.replaced-*"))) == 1


def test_export_fmu_to_another_file_system_and_rerun(tmp_path: Path) -> None:
    """The FMU is built in the temporary directory and copied, so a target on another file
    system works (a rename failed with "Invalid cross-device link"); a rerun replaces it."""
    shm = Path("/dev/shm")
    if not shm.is_dir() or shm.stat().st_dev == tmp_path.stat().st_dev:
        pytest.skip("no second file system (/dev/shm) to build the FMU on")
    out = tmp_path / "cell.fmu"
    env = {**os.environ, "TMPDIR": str(shm)}
    cmd = [sys.executable, "-m", "hevsim.cli", "export-fmu", str(CELL), "-o", str(out)]
    for _ in range(2):  # the second run replaces the FMU hevsim wrote
        run = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
        assert run.returncode == 0, run.stderr
        assert "Traceback" not in run.stderr
    from hevsim.battery.native import is_native_fmu

    assert is_native_fmu(out)  # the default export
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cell.fmu"]


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    from importlib.metadata import version

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"hevsim {version('hevsim')}"


ROUNDS = 200
"""Swaps per writer: without the lock around the swap two writers collide within a few
hundred rounds (seen: FileNotFoundError when both move the old folder aside)."""


def _writer(out: str, tag: str, rounds: int, errors: multiprocessing.Queue) -> None:  # type: ignore[type-arg]
    try:
        for i in range(rounds):
            with atomic_directory(out) as tmp:
                for k in range(5):
                    (tmp / f"part{k}.txt").write_text(f"{tag} {i}\n")
                (tmp / "sub").mkdir()
                (tmp / "sub" / "deep.txt").write_text(f"{tag} {i}\n")
    except BaseException as exc:  # reported to the parent
        errors.put(f"{tag}: {type(exc).__name__}: {exc}")


def test_concurrent_writers_never_fail_and_leave_a_consistent_folder(tmp_path: Path) -> None:
    out = tmp_path / "run"
    ctx = multiprocessing.get_context("fork" if sys.platform.startswith("linux") else "spawn")
    errors = ctx.Queue()
    procs = [ctx.Process(target=_writer, args=(str(out), tag, ROUNDS, errors)) for tag in ("A", "B")]
    for p in procs:
        p.start()
    for p in procs:
        p.join(timeout=120)
    assert all(p.exitcode == 0 for p in procs)
    reported = []
    while not errors.empty():
        reported.append(errors.get())
    assert reported == []
    files = results_files(out)
    assert files == ["part0.txt", "part1.txt", "part2.txt", "part3.txt", "part4.txt", "sub/deep.txt"]
    contents = {(out / f).read_text() for f in files}
    assert len(contents) == 1  # every file from the same (complete) run
    assert contents.pop().split()[1] == str(ROUNDS - 1)  # the last round of one of the writers
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no temporaries, no old copies

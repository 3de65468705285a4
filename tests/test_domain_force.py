"""``--force`` never deletes what hevsim did not write (issue 26 item 4): a folder at ``--out``
holding the user's files is moved aside whole to ``<out>.replaced-<UTC timestamp>`` (a line
says so) before the results take its place; a folder hevsim wrote is still simply replaced."""

from __future__ import annotations

from pathlib import Path

import pytest

from hevsim.cli import main
from hevsim.io import MARKER, results_files

CELL = Path(__file__).resolve().parents[1] / "examples" / "cell.toml"


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_force_moves_the_users_folder_aside(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Today: the user's files are deleted."""
    out = tmp_path / "analysis"
    (out / "data").mkdir(parents=True)
    (out / "notes.txt").write_text("my notes\n")
    (out / "data" / "measured.csv").write_bytes(b"t,v\n0,3.7\n")
    mine = _files(out)
    assert main(["cell", str(CELL), "--out", str(out)]) == 2  # refused without --force
    assert "--force (which moves that folder aside" in capsys.readouterr().err
    assert main(["cell", str(CELL), "--out", str(out), "--force"]) == 0
    (kept,) = tmp_path.glob("analysis.replaced-*")
    assert _files(kept) == mine  # every file of the user's, byte for byte
    assert results_files(out) == sorted(p.name for p in out.iterdir() if p.name != MARKER)
    err = capsys.readouterr().err
    assert f"{out} held files hevsim did not write" in err and f"was moved to {kept}" in err
    # a second forced run over the user's folder again keeps both copies
    (out / "more.txt").write_text("added later\n")
    assert main(["cell", str(CELL), "--out", str(out), "--force"]) == 0
    assert len(list(tmp_path.glob("analysis.replaced-*"))) == 2


def test_force_still_replaces_a_hevsim_results_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    assert main(["cell", str(CELL), "--out", str(out)]) == 0
    inode = out.stat().st_ino
    assert main(["cell", str(CELL), "--out", str(out), "--force"]) == 0
    assert out.stat().st_ino != inode and results_files(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # nothing moved aside, no leftovers
    assert "did not write" not in capsys.readouterr().err


def test_force_moves_a_symbolic_link_aside(tmp_path: Path) -> None:
    target = tmp_path / "elsewhere"
    target.mkdir()
    (target / "keep.txt").write_text("k\n")
    out = tmp_path / "link"
    out.symlink_to(target)
    assert main(["cell", str(CELL), "--out", str(out), "--force"]) == 0
    (kept,) = tmp_path.glob("link.replaced-*")
    assert kept.is_symlink() and kept.resolve() == target.resolve()
    assert _files(target) == {"keep.txt": b"k\n"} and not out.is_symlink()

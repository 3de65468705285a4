"""hevsim's numba cache folder follows the content of its compiled code (hevsim._numba_cache):
numba keys a function's cache on its own file only, so a kernel inlining another module's
function kept the old machine code after that module changed."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hevsim import _numba_cache as nc


def _package(root: Path) -> Path:
    (root / "sub").mkdir(parents=True)
    (root / "kernel.py").write_text(
        "from numba import njit\n\n@njit(cache=True)\ndef f(x):\n    return g(x)\n"
    )
    (root / "sub" / "inner.py").write_text(
        "from numba import njit\n\n@njit(cache=True)\ndef g(x):\n    return x\n"
    )
    (root / "cli.py").write_text("def main():\n    return 0\n")
    return root


def test_digest_follows_compiled_code_only(tmp_path: Path) -> None:
    root = _package(tmp_path / "pkg")
    d0 = nc.code_digest(root, "1.0")
    assert len(d0) == 16 and nc.code_digest(root, "1.0") == d0
    (root / "cli.py").write_text("def main():\n    return 1\n")  # no numba: same compiled code
    assert nc.code_digest(root, "1.0") == d0
    (root / "sub" / "inner.py").write_text(
        "from numba import njit\n\n@njit(cache=True)\ndef g(x):\n    return 2 * x\n"
    )
    d1 = nc.code_digest(root, "1.0")  # the inlined callee changed: a new cache for every kernel
    assert d1 != d0
    assert nc.code_digest(root, "1.1") != d1


def test_configure_creates_marks_and_prunes_only_its_own(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    root = _package(tmp_path / "pkg")
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    base = tmp_path / "cache" / "hevsim" / "numba"
    base.mkdir(parents=True)
    old = time.time() - 2 * nc.STALE_S
    made = []
    for k in range(5):  # hevsim's folders: 4 stale, 1 recent
        d = base / f"{k:016x}"
        d.mkdir()
        (d / nc.MARKER).touch()
        t = old if k < 4 else time.time()
        os.utime(d / nc.MARKER, (t, t))
        made.append(d)
    foreign = base / "0123456789abcdef"  # right name, no marker: not hevsim's
    foreign.mkdir()
    other = base / "notes"
    other.mkdir()
    folder = nc.configure(root, "1.0")
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    assert folder is not None and folder.parent == base and (folder / nc.MARKER).is_file()
    left = sorted(p.name for p in base.iterdir())
    assert folder.name in left and made[4].name in left and foreign.name in left and "notes" in left
    assert sum((base / n / nc.MARKER).is_file() for n in left) == nc.KEEP  # current + 2 most recent
    assert not made[0].exists()  # the oldest stale folder went


def test_user_folder_is_the_parent_of_the_digest_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A NUMBA_CACHE_DIR the user set held the old machine code after an update (a kernel inlines
    other modules' functions): the digest folder now goes inside it."""
    mine = tmp_path / "mine"
    (mine / "notes").mkdir(parents=True)  # the user's own content stays
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(mine))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    root = _package(tmp_path / "pkg")
    folder = nc.configure(root, "1.0")
    assert folder == mine / nc.code_digest(root, "1.0") and (folder / nc.MARKER).is_file()
    assert os.environ["NUMBA_CACHE_DIR"] == str(folder) and (mine / "notes").is_dir()
    assert not (tmp_path / "cache").exists()
    assert nc.configure(root, "1.0") == folder  # a process hevsim starts: no folder inside it
    assert os.environ["NUMBA_CACHE_DIR"] == str(folder) and not (folder / folder.name).exists()
    (root / "sub" / "inner.py").write_text(
        "from numba import njit\n\n@njit(cache=True)\ndef g(x):\n    return 3 * x\n"
    )
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(mine))  # the user's setting after an update
    changed = nc.configure(root, "1.0")
    assert changed is not None and changed.parent == mine and changed != folder


def test_unwritable_user_folder_is_left_alone(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(blocker))
    assert nc.configure(_package(tmp_path / "pkg"), "1.0") is None
    assert os.environ["NUMBA_CACHE_DIR"] == str(blocker) and blocker.read_text() == "not a folder"


def test_hevsim_import_points_numba_at_its_folder(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    code = "import numba, hevsim; from numba.core import config; print(config.CACHE_DIR)"  # numba first
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    folder = Path(out.stdout.strip())
    assert folder.parent == tmp_path / "cache" / "hevsim" / "numba" and (folder / nc.MARKER).is_file()

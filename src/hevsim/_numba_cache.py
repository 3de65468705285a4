"""Where numba keeps hevsim's compiled kernels: one cache folder per version of hevsim's
compiled code.

numba keys each function's on-disk cache on its own source file only. hevsim's kernels call
(and inline) numba functions of other modules (the series kernel runs the pack step, the
forward loops the component kernels), so after a change to one of those modules - a
``git pull``, an edit in a development install - a kernel whose own file did not change
would load the old machine code and compute with the old equations, silently. So the cache
lives in ``<user cache>/hevsim/numba/<digest>``, where the digest covers the version and the
content of every hevsim module that uses numba: any change to compiled code starts a fresh
cache (one compilation, about a minute), and unchanged code keeps its cache across processes.

A ``NUMBA_CACHE_DIR`` set by the user chooses the parent instead: the cache is
``$NUMBA_CACHE_DIR/<digest>`` (the same staleness hazard applies to a folder the user picked; a
value that already names this digest's marked folder, as in the processes hevsim starts, is
used as it is). If the folder cannot be written, the setting is left alone (the user's folder,
or numba's default ``__pycache__`` next to the sources). hevsim keeps the
:data:`KEEP` most recently used of its own cache folders (those holding :data:`MARKER`) and
removes older ones unused for :data:`STALE_S`; it never touches anything else. The setting is
also exported in the environment, so the processes hevsim starts (workers, FMU hosts) use the
same folder.

The digest reads every module of the package (a few ms), so ``import hevsim`` does not
compute it: :func:`configure_before_numba` does it just before numba is first imported (a
finder on ``sys.meta_path`` that removes itself), or at once when numba was imported first.
Commands that never compile (``hevsim cosim`` of FMUs) do not pay for it.
"""

from __future__ import annotations

import hashlib
import os
import re
import sys
import time
from pathlib import Path
from typing import Any

MARKER = ".hevsim-numba-cache"
"""File that marks a cache folder as created by hevsim."""
KEEP = 3
"""Number of hevsim cache folders kept (the current one and the most recently used others)."""
STALE_S = 7 * 86400.0
"""A folder beyond :data:`KEEP` is removed only when unused for this long [s] (another checkout
may be running with it)."""
_NAME = re.compile(r"^[0-9a-f]{16}$")


def code_digest(package_root: Path, version: str) -> str:
    """16 hex digits of SHA-256 over ``version`` and the path and content of every module under
    ``package_root`` that mentions numba."""
    h = hashlib.sha256(version.encode())
    for path in sorted(package_root.rglob("*.py")):
        data = path.read_bytes()
        if b"numba" in data:
            h.update(path.relative_to(package_root).as_posix().encode() + b"\0")
            h.update(hashlib.sha256(data).digest())
    return h.hexdigest()[:16]


def cache_root() -> Path:
    """``$XDG_CACHE_HOME/hevsim/numba`` (default ``~/.cache/hevsim/numba``)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "hevsim" / "numba"


def configure(package_root: Path, version: str) -> Path | None:
    """Point numba's cache at this code version's folder (see the module docstring); returns
    it, or None when the folder cannot be written."""
    user = os.environ.get("NUMBA_CACHE_DIR")
    try:
        digest = code_digest(package_root, version)
        if user and Path(user).name == digest and (Path(user) / MARKER).is_file():
            return Path(user)  # a process hevsim started: its parent chose the folder
        root = Path(user) if user else cache_root()
        folder = root / digest
        folder.mkdir(parents=True, exist_ok=True)
        (folder / MARKER).touch()  # raises if the folder cannot be written
        _prune(root, folder)
    except OSError:
        return None
    os.environ["NUMBA_CACHE_DIR"] = str(folder)  # for this process and the ones it starts
    numba_config = sys.modules.get("numba.core.config")
    if numba_config is not None:  # numba imported first: its configuration was read already
        numba_config.CACHE_DIR = str(folder)  # type: ignore[attr-defined]
    return folder


class _BeforeNumba:
    """A ``sys.meta_path`` finder that calls :func:`configure` when ``numba`` is about to be
    imported for the first time (then leaves the import to the other finders)."""

    def __init__(self, package_root: Path, version: str):
        self.args = (package_root, version)

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> None:
        if name == "numba":
            if self in sys.meta_path:
                sys.meta_path.remove(self)
            configure(*self.args)


def configure_before_numba(package_root: Path, version: str) -> None:
    """:func:`configure` now if numba is imported already, else just before its import."""
    if "numba" in sys.modules:
        configure(package_root, version)
    elif not any(isinstance(f, _BeforeNumba) for f in sys.meta_path):
        sys.meta_path.insert(0, _BeforeNumba(package_root, version))


def _prune(root: Path, current: Path) -> None:
    """Remove hevsim's cache folders beyond the :data:`KEEP` most recently used that have not
    been used for :data:`STALE_S`."""
    ours = [p for p in root.iterdir() if p.is_dir() and _NAME.match(p.name) and (p / MARKER).is_file()]
    ours.sort(key=lambda p: (p == current, (p / MARKER).stat().st_mtime), reverse=True)
    import shutil  # here: most imports of hevsim prune nothing

    now = time.time()
    for old in ours[KEEP:]:
        if now - (old / MARKER).stat().st_mtime > STALE_S:
            shutil.rmtree(old, ignore_errors=True)

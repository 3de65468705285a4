"""Atomic output: result folders and files appear whole or not at all, and never replace
anything the user made.

A results folder written by :func:`atomic_directory` carries a marker file
:data:`MARKER` (JSON: hevsim version, command, creation time and the list of files written).
An existing folder at the output path is replaced only if it is empty or is such a folder
with nothing foreign in it; otherwise :class:`~hevsim.errors.OutputError` is raised unless
replacing was forced, and then the folder is not deleted but moved aside whole to the sibling
``<out>.replaced-<UTC timestamp>`` (a line on stderr says so): ``--force`` never deletes a
file hevsim did not write. The current working directory, its ancestors and folders holding an
input are never replaced, forced or not. The swap (old folder aside, new folder in, old
folder removed) is serialised between processes by a lock on the parent folder, so two
concurrent writers to one path never fail and the last complete result wins.

Command-line tools call :func:`prepare_output` before any computation, inside
:func:`output_session`, so that a bad ``--out`` fails at once.
"""

from __future__ import annotations

import csv
import errno
import hashlib
import json
import os
import secrets
import shutil
import sys
import threading
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

import numpy as np

from hevsim.errors import ConfigError, InputError, OutputError

MARKER = ".hevsim-results"
"""Name of the marker file of a hevsim results folder."""

_FORCED: ContextVar[set[Path] | None] = ContextVar("hevsim_forced_outputs", default=None)
_ASIDE: ContextVar[set[Path] | None] = ContextVar("hevsim_files_to_move_aside", default=None)


def _abs(path: str | Path) -> Path:
    """``path`` made absolute and normalised (``..`` removed), without resolving symlinks."""
    return Path(os.path.abspath(os.fspath(path)))


@contextmanager
def output_session() -> Iterator[None]:
    """Scope in which :func:`prepare_output` with ``force=True`` lets :func:`atomic_directory`
    replace a foreign folder at that path (the command line runs each command in one)."""
    token, aside = _FORCED.set(set()), _ASIDE.set(set())
    try:
        yield
    finally:
        _FORCED.reset(token)
        _ASIDE.reset(aside)


def _forced(out: Path) -> bool:
    allowed = _FORCED.get()
    return allowed is not None and out in allowed


def results_files(folder: str | Path) -> list[str] | None:
    """The files listed in the marker of the hevsim results folder ``folder`` (relative
    POSIX paths), or None if ``folder`` has no readable marker."""
    try:
        data = json.loads((Path(folder) / MARKER).read_text())
    except (OSError, ValueError):
        return None
    files = data.get("files") if isinstance(data, dict) else None
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        return None
    return files


def _is_results_folder(folder: Path) -> bool:
    """True if ``folder`` has a hevsim marker and holds nothing the marker does not list."""
    files = results_files(folder)
    if files is None:
        return False
    allowed = {MARKER, *files}
    dirs = {str(p) for f in files for p in Path(f).parents if str(p) != "."}
    for root, subdirs, names in os.walk(folder):
        rel = Path(root).relative_to(folder)
        for d in subdirs:
            r = (rel / d).as_posix()
            if r not in dirs and os.path.islink(os.path.join(root, d)):
                return False
        for n in names:
            if (rel / n).as_posix() not in allowed:
                return False
    # unlisted sub-folders are accepted only when empty (os.walk visited their contents)
    return True


def _protection(out: Path, protect: Iterable[str | Path]) -> str | None:
    """Why ``out`` may never be replaced, or None."""
    real = out.resolve()
    try:
        cwd: Path | None = Path.cwd().resolve()
    except OSError:  # the working directory was removed: nothing there to protect
        cwd = None
    if cwd is not None and real == cwd:
        return f"is the current working directory ({cwd})"
    if cwd is not None and real in cwd.parents:
        return f"contains the current working directory {cwd}"
    for p in protect:
        pr = Path(p).resolve()
        if real == pr:
            return f"is the input {p}"
        if real in pr.parents:
            return f"contains the input {p}"
    return None


def _existing_ancestor(out: Path, option: str, shown: str | Path | None = None) -> Path:
    """The nearest existing ancestor of ``out``; an error if it is not a folder."""
    for anc in out.parents:
        if os.path.exists(anc):
            if not os.path.isdir(anc):
                raise OutputError(
                    f"{option} {shown or out}: {anc} is a file, not a folder; choose another {option}."
                )
            return anc
    return Path(out.anchor)  # pragma: no cover - the root always exists


def _check(
    out: Path,
    kind: Literal["dir", "file"],
    force: bool,
    option: str,
    protect: Iterable[str | Path] = (),
    ours: Callable[[Path], bool] | None = None,
    shown: str | Path | None = None,
) -> None:
    """Raise :class:`OutputError` if writing ``out`` could destroy something of the user's
    (messages name the path as ``shown``, the user's spelling)."""
    name = out if shown is None else shown
    if out.name in ("", ".", ".."):
        raise OutputError(
            f"{option} {name}: is not a name for a new {'folder' if kind == 'dir' else 'file'}."
        )
    why = _protection(out, protect)
    if why:
        raise OutputError(f"{option} {name}: {why}; hevsim never replaces it, even with --force.")
    _existing_ancestor(out, option, name)
    if not os.path.lexists(out):
        return
    if kind == "dir":
        if os.path.islink(out):
            if force:
                return
            raise OutputError(
                f"{option} {name}: exists and is a symbolic link, not a hevsim results folder; choose "
                f"another {option} or pass --force (the link is moved aside to {name}{REPLACED}<time>)."
            )
        if not os.path.isdir(out):
            raise OutputError(
                f"{option} {name}: exists and is a file; choose another {option} "
                "(hevsim never replaces a file with a folder)."
            )
        if force or not os.listdir(out) or _is_results_folder(out):
            return
        raise OutputError(
            f"{option} {name}: exists and is not a hevsim results folder; choose another {option} "
            f"or pass --force (which moves that folder aside to {name}{REPLACED}<time>, deleting nothing)."
        )
    if os.path.isdir(out):
        raise OutputError(f"{option} {name}: is a folder; {option} names a file to write.")
    if force or (ours is not None and ours(out)):
        return
    raise OutputError(
        f"{option} {name}: exists and was not written by hevsim; choose another {option} or pass --force "
        f"(which moves it aside to {name}{REPLACED}<time>)."
    )


def _probe(folder: Path, out: Path, option: str) -> None:
    """Create and remove a file in ``folder``: the only test of writability that holds for
    every user (root ignores permission bits, not read-only file systems)."""
    for _ in range(100):
        probe = folder / f".hevsim-probe-{secrets.token_hex(4)}"
        try:
            fd = os.open(probe, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600)
        except FileExistsError:
            continue
        except OSError as exc:
            raise OutputError(
                f"{option} {out}: cannot write in {folder} ({exc.strerror or exc}); "
                "choose a writable location."
            ) from exc
        os.close(fd)
        os.unlink(probe)
        return


def prepare_output(
    path: str | Path,
    *,
    kind: Literal["dir", "file"] = "dir",
    force: bool = False,
    option: str = "--out",
    protect: Iterable[str | Path] = (),
    ours: Callable[[Path], bool] | None = None,
) -> Path:
    """Check, before any computation, that ``path`` can be written without loss; returns it.

    ``kind="dir"``: a results folder. Refused: the working directory or an ancestor of it or
    of a ``protect``ed input (even with ``force``), an existing file, a path under a file, an
    unwritable location, and, unless ``force``, an existing folder that is neither empty nor
    a hevsim results folder. ``kind="file"``: refused: an existing folder, a protected input,
    a path under a file, an unwritable location and, unless ``force``, an existing file for
    which ``ours`` is not true. Inside :func:`output_session`, ``force`` also lets the later
    :func:`atomic_directory` replace the folder, and :func:`atomic_file` the file (either
    moved aside to ``<path>.replaced-<UTC timestamp>`` when hevsim did not write it). Nothing
    is created or removed (apart from a probe file in the nearest existing ancestor).
    """
    out = _abs(path)
    anc = _existing_ancestor(out, option, path)
    with _lock(anc if anc == out.parent else None):
        _check(out, kind, force, option, protect, ours, shown=path)
    _probe(anc, Path(path), option)
    allowed = _FORCED.get()
    if force and allowed is not None:
        allowed.add(out)
        aside = _ASIDE.get()
        theirs = os.path.isfile(out) and not (ours is not None and ours(out))
        if kind == "file" and aside is not None and theirs:
            aside.add(out)  # the user's file: atomic_file moves it aside, never overwrites it
    return out


@contextmanager
def _lock(folder: Path | None) -> Iterator[None]:
    """Exclusive lock (``flock``) on ``folder`` between processes; a no-op where unsupported."""
    if folder is None:
        yield
        return
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:  # pragma: no cover - file systems without flock
            pass
        yield
    finally:
        os.close(fd)  # closing releases the lock


def _unique(parent: Path, prefix: str, make: Callable[[Path], None]) -> Path:
    for _ in range(1000):
        p = parent / f"{prefix}{secrets.token_hex(4)}"
        try:
            make(p)
        except FileExistsError:
            continue
        return p
    raise FileExistsError(errno.EEXIST, f"no free name {prefix}* in {parent}")  # pragma: no cover


def _write_marker(folder: Path) -> None:
    from hevsim import __version__

    files = sorted(
        (Path(root) / n).relative_to(folder).as_posix() for root, _, names in os.walk(folder) for n in names
    )
    data = {
        "hevsim_version": __version__,
        "command": [Path(sys.argv[0]).name, *sys.argv[1:]] if sys.argv else [],
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "files": [f for f in files if f != MARKER],
    }
    (folder / MARKER).write_text(json.dumps(data, indent=2) + "\n")


def _remove(path: Path) -> None:
    if path.is_symlink() or not path.is_dir():
        path.unlink(missing_ok=True)
    else:
        shutil.rmtree(path, ignore_errors=True)


@contextmanager
def atomic_directory(out_dir: str | Path, *, force: bool = False) -> Iterator[Path]:
    """Yield a new temporary sibling folder; on success it replaces ``out_dir`` in one rename.

    The folder gets the marker :data:`MARKER` and the user's umask. ``out_dir`` must be
    absent, empty or a hevsim results folder (or, with ``force`` or after
    :func:`prepare_output` with ``force``, any folder or symbolic link, which is then moved to
    ``<out>.replaced-<UTC timestamp>`` rather than deleted; never a file, the working directory
    or an ancestor of it); this is checked before the body runs and again
    at the swap, which is locked between processes. On any error the temporary folder is
    removed and ``out_dir`` is left as it was, so an interrupted run never leaves a partial
    results folder.

    Raises:
        OutputError: ``out_dir`` holds something of the user's, or cannot be written.
    """
    out = _abs(out_dir)
    forced = force or _forced(out)
    _existing_ancestor(out, "output folder")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(
            f"output folder {out}: cannot create {out.parent} ({exc.strerror or exc})."
        ) from exc
    with _lock(out.parent):
        _check(out, "dir", forced, "output folder")
    try:
        # os.mkdir applies the umask (tempfile.mkdtemp would make the folder 0700)
        tmp = _unique(out.parent, f".{out.name}.", lambda p: p.mkdir(0o777))
    except OSError as exc:
        raise OutputError(
            f"output folder {out}: cannot write in {out.parent} ({exc.strerror or exc})."
        ) from exc
    try:
        yield tmp
        _write_marker(tmp)
        old: Path | None = None
        kept: Path | None = None
        with _lock(out.parent):
            _check(out, "dir", forced, "output folder")
            if os.path.lexists(out):
                if _ours_to_replace(out):
                    old = out.parent / f".{out.name}.old.{secrets.token_hex(8)}"  # unique: swaps are locked
                    os.rename(out, old)
                else:  # forced over something of the user's: moved aside whole, never deleted
                    kept = _aside(out)
                    os.rename(out, kept)
            os.rename(tmp, out)
        if old is not None:
            _remove(old)
        if kept is not None:
            print(
                f"hevsim: {out_dir} held files hevsim did not write: that folder, as it was, was moved to "
                f"{kept} (--force moves such files aside; it never deletes them).",
                file=sys.stderr,
            )
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


REPLACED = ".replaced-"
"""Infix of the sibling ``<out>.replaced-<UTC timestamp>`` that ``--force`` moves a folder
holding files hevsim did not write to (:func:`atomic_directory`)."""


def _ours_to_replace(out: Path) -> bool:
    """``out`` is an empty folder or a hevsim results folder with nothing foreign in it."""
    return not out.is_symlink() and out.is_dir() and (not os.listdir(out) or _is_results_folder(out))


def _aside(out: Path) -> Path:
    """A free sibling name ``<out>.replaced-<UTC timestamp>[-n]`` (a folder's: under the lock)."""
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    for n in range(1000):
        p = out.parent / f"{out.name}{REPLACED}{stamp}{f'-{n}' if n else ''}"
        if not os.path.lexists(p):
            return p
    raise OutputError(f"output folder {out}: no free name {out.name}{REPLACED}{stamp}-*.")  # pragma: no cover


def _strict(o: Any) -> Any:
    """``o`` with numpy values converted and non-finite floats replaced by None; a dict with
    a non-finite ``"value"`` (a metric) gains a ``"note"`` saying what the value was."""
    if isinstance(o, np.ndarray):
        o = o.tolist()
    elif isinstance(o, np.generic):
        o = o.item()
    if isinstance(o, float):
        return o if np.isfinite(o) else None
    if isinstance(o, dict):
        out = {k: _strict(v) for k, v in o.items()}
        value = o.get("value")
        if isinstance(value, float | np.floating) and not np.isfinite(value) and "note" not in o:
            out["note"] = f"the value was {float(value):g} (not a JSON number), written as null"
        return out
    if isinstance(o, list | tuple):
        return [_strict(v) for v in o]
    return o


def write_json(path: str | Path, data: Any) -> None:
    """Write ``data`` as indented, strict JSON (numpy scalars and arrays converted).

    JSON has no NaN or infinity: a non-finite number is written as ``null``, and a metric
    entry (a dict with a ``"value"``) whose value was not finite gains a ``"note"``.
    """

    def default(o: Any) -> Any:
        return str(o)

    Path(path).write_text(json.dumps(_strict(data), indent=2, default=default, allow_nan=False) + "\n")


def _new_file(p: Path) -> None:
    os.close(os.open(p, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))  # the umask applies


@contextmanager
def atomic_file(path: str | Path) -> Iterator[Path]:
    """Yield a new, uniquely named temporary sibling of ``path`` (mode from the umask); on
    success it replaces ``path`` in one rename, on error it is removed. Concurrent writers
    never collide. A folder at ``path`` is never replaced (:class:`~hevsim.errors.OutputError`).
    """
    target = _abs(path)
    if target.is_dir():
        raise OutputError(f"{path}: is a folder; expected a file to write.")
    _existing_ancestor(target, "output file", path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = _unique(target.parent, f".{target.name}.", _new_file)
    try:
        yield tmp
        aside = _ASIDE.get()
        kept = None
        if aside is not None and target in aside and os.path.isfile(target):  # forced over the user's file
            kept = _aside(target)
            os.rename(target, kept)
            aside.discard(target)
        os.replace(tmp, target)
        if kept is not None:
            print(f"hevsim: {path} was not written by hevsim: it was moved to {kept} (--force moves such "
                  "files aside; it never deletes them).", file=sys.stderr)  # fmt: skip
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (:func:`atomic_file`)."""
    with atomic_file(path) as tmp:
        tmp.write_text(text)
    return Path(path)


def copy_file_atomic(src: str | Path, path: str | Path) -> Path:
    """Copy ``src`` to ``path`` atomically (:func:`atomic_file`); ``src`` may be on another
    file system (a plain rename would fail with "Invalid cross-device link")."""
    with atomic_file(path) as tmp:
        shutil.copyfile(src, tmp)
    return Path(path)


def save_png(fig: Any, path: str | Path, dpi: float, **savefig_kwargs: Any) -> Path:
    """Write the matplotlib figure ``fig`` to ``path`` as PNG at ``dpi`` [dots per inch]
    atomically (to ``<name>.tmp`` beside it, then renamed: a reader never sees a half-written
    picture, and an existing one stays as it was if drawing fails) and release the figure.

    ``savefig_kwargs`` go to :meth:`matplotlib.figure.Figure.savefig` (e.g.
    ``bbox_inches="tight"``). Returns the path written."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(target.name + ".tmp")
    try:
        fig.savefig(tmp, format="png", dpi=dpi, **savefig_kwargs)
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)
        fig.clear()
    return target


def read_text_utf8(path: str | Path, what: str = "TOML", error: type[Exception] = ConfigError) -> str:
    """The text of ``path`` decoded as UTF-8; ``error`` (default :class:`ConfigError`, exit 2)
    names the file and the byte offset (with line and column) of a binary file (a NUL byte) or
    of the first byte that is not UTF-8 (a Latin-1 "°" in a comment, say)."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise error(f"{p}: cannot be read ({exc.strerror or exc}).") from exc
    nul = raw.find(b"\0")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        nul = nul if 0 <= nul < exc.start else -1
        bad = exc.start if nul < 0 else nul
    else:
        if nul < 0:
            return text
        bad = nul
    line = raw.count(b"\n", 0, bad) + 1
    col = bad - (raw.rfind(b"\n", 0, bad) + 1) + 1
    where = f"byte 0x{raw[bad]:02x} at offset {bad} (line {line}, column {col})"
    if raw[bad] == 0:
        raise error(f"{p}: is a binary file: {where}; expected a {what} text file.")
    raise error(
        f"{p}: is not UTF-8 text: {where} is not valid UTF-8; expected a UTF-8 {what} file (save it "
        "as UTF-8; a '°' or 'µ' written by a Latin-1 / Windows-1252 editor is the usual cause)."
    )


# ---------------------------------------------------------------------- parsed-input cache
CONTENT_CACHE_ENTRIES = 512
"""Parsed files kept by :func:`cached_by_content` (least recently used dropped first)."""
_CONTENT_CACHE: OrderedDict[tuple[Any, ...], Any] = OrderedDict()
_CONTENT_LOCK = threading.Lock()


def _digest(data: bytes) -> bytes:
    return hashlib.blake2b(data, digest_size=20).digest()


def cached_by_content(path: str | Path, load: Callable[..., Any], *args: Any) -> Any:
    """``load(path, *args)``, parsed once per file content: the result is kept under the
    resolved path, ``load``, ``args`` (hashable) and a hash of the file's bytes, so a changed
    file (whatever its time stamp) is read again. The cache holds at most
    :data:`CONTENT_CACHE_ENTRIES` results and is shared by threads.

    The cached object is returned as is: ``load`` must return something immutable, or the
    caller must hand out copies (:func:`hevsim.tables.read_csv_columns` copies its arrays,
    :func:`hevsim.schema.read_toml` its dictionary). A path that cannot be read goes straight
    to ``load``, whose errors name the file; errors are not cached.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError:
        _note_read(p, None)
        return load(p, *args)
    name = (getattr(load, "__module__", ""), getattr(load, "__qualname__", repr(load)))
    key = (*name, str(p), os.path.abspath(p), args, _digest(data))  # abspath: no system calls
    _note_read(p, key[-1])
    with _CONTENT_LOCK:
        if key in _CONTENT_CACHE:
            _CONTENT_CACHE.move_to_end(key)
            return _CONTENT_CACHE[key]
    value = load(p, *args)
    try:  # the file changed while it was parsed: do not keep what may be a mix
        same = _digest(p.read_bytes()) == key[-1]
    except OSError:
        same = False
    if same:
        with _CONTENT_LOCK:
            _CONTENT_CACHE[key] = value
            while len(_CONTENT_CACHE) > CONTENT_CACHE_ENTRIES:
                _CONTENT_CACHE.popitem(last=False)
    return value


_READS = threading.local()  # .stack: the files each running cached_build has read so far


def _note_read(path: Path, digest: bytes | None) -> None:
    """Tell every :func:`cached_build` running on this thread that ``path`` was read
    (``digest`` of its bytes; None: it could not be read)."""
    for reads in getattr(_READS, "stack", ()):
        reads[os.path.abspath(path)] = digest


def _file_digest(path: str) -> bytes | None:
    try:
        return _digest(Path(path).read_bytes())
    except OSError:
        return None


def _listing(folder: str) -> tuple[str, ...] | None:
    try:
        return tuple(sorted(os.listdir(folder)))
    except OSError:
        return None


def cached_build(folder: str | Path, build: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """``build(folder, *args, **kwargs)`` (a component read from its data folder) made once
    per content: the object is kept with the files ``build`` parsed through
    :func:`cached_by_content` (their hashes) and the names in ``folder``; a later call returns
    a deep copy of it while every one of those files has the same bytes and the folder the
    same names, and builds it again otherwise (a file changed, added or removed). Skips the
    parsing and the table checks of every call after the first: about 0.3 ms a component.
    Arguments must be hashable (else no caching). Errors are not cached."""
    import copy

    folder_s = os.path.abspath(folder)
    name = (getattr(build, "__module__", ""), getattr(build, "__qualname__", repr(build)))
    try:
        key = ("build", *name, folder_s, args, tuple(sorted(kwargs.items())))
        hash(key)
    except TypeError:
        return build(folder, *args, **kwargs)
    with _CONTENT_LOCK:
        entry = _CONTENT_CACHE.get(key)
        if entry is not None:
            _CONTENT_CACHE.move_to_end(key)
    if entry is not None:
        value, seen, names = entry
        if _listing(folder_s) == names and all(_file_digest(f) == d for f, d in seen.items()):
            for f, d in seen.items():  # an outer cached_build depends on them too
                _note_read(Path(f), d)
            return copy.deepcopy(value)
    stack = getattr(_READS, "stack", None)
    if stack is None:
        stack = _READS.stack = []
    reads: dict[str, bytes | None] = {}
    listing = _listing(folder_s)
    stack.append(reads)
    try:
        value = build(folder, *args, **kwargs)
    finally:
        stack.pop()
    for f, d in reads.items():
        _note_read(Path(f), d)
    with _CONTENT_LOCK:
        _CONTENT_CACHE[key] = (value, reads, listing)
        while len(_CONTENT_CACHE) > CONTENT_CACHE_ENTRIES:
            _CONTENT_CACHE.popitem(last=False)
    return copy.deepcopy(value)


def clear_content_cache() -> None:
    """Forget every parsed file of :func:`cached_by_content` and every component of
    :func:`cached_build`."""
    with _CONTENT_LOCK:
        _CONTENT_CACHE.clear()


def read_csv_rows(
    path: Path, expected: str, hash_header: tuple[str, ...] = ()
) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """Header names and data rows (with their 1-based physical line numbers) of a CSV text
    file, fields stripped. Blank lines and lines starting with ``#`` are skipped, except a
    first line ``# name, ...`` whose first name is in ``hash_header`` (a header written as
    a comment, as the TUM racetrack database does). ``expected`` says what the file should
    be, in the :class:`~hevsim.errors.InputError` of a missing, unreadable or headless file.
    """
    if not path.is_file():
        raise InputError(f"{path}: file not found; expected {expected}.")
    header: list[str] | None = None
    rows: list[tuple[int, list[str]]] = []
    try:
        with path.open(newline="", encoding="utf-8-sig") as stream:
            reader = csv.reader(stream)
            for raw in reader:
                fields = [f.strip() for f in raw]
                if not any(fields):
                    continue
                if fields[0].startswith("#"):
                    first = fields[0].lstrip("#").strip()
                    if header is None and first in hash_header:
                        header = [first, *fields[1:]]
                    continue
                if header is None:
                    header = fields
                else:
                    rows.append((reader.line_num, fields))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{path}: cannot be read as a CSV text file ({exc}).") from exc
    if header is None:
        raise InputError(f"{path}: no header line; expected {expected}.")
    return header, rows

"""Clean process exit for hosts of pythonfmu FMUs (``hevsim export-fmu --pythonfmu``).

pythonfmu 0.7's FMU binary keeps a namespace-scope ``std::shared_ptr<PyState>`` and resets it
again in an ``__attribute__((destructor))`` function, ``finalizePythonInterpreter``. When the
library is still loaded at process exit (FMPy's ``dlclose`` does not unload it, and hosts often
keep it), glibc runs the C++ static destructor first (from ``exit``'s handlers) and the ELF
destructor after it (``_dl_fini``): the second reset releases a control block that is already
freed, a write into freed heap memory. Whether glibc notices it ("corrupted double-linked
list", an abort after every result is written) depends on the heap's state, hence aborts in
some runs only, more often when numba compiled inside ``fmi2Instantiate``. Valgrind shows the
invalid access in ``finalizePythonInterpreter`` on a block allocated by ``fmi2Instantiate``
and freed by ``__run_exit_handlers``.

Calling the exported ``finalizePythonInterpreter`` while the process still runs empties the
pointer, so both exit-time destructors find nothing to release. Live instances hold their own
reference, so the call is safe at any time; a second call does nothing.
"""

from __future__ import annotations

import atexit
import ctypes
import os
import sys
from pathlib import Path
from typing import Any

_REGISTERED: set[str] = set()


def release_pythonfmu_state(dll: Any) -> None:
    """Call ``finalizePythonInterpreter`` of the loaded FMU library ``dll`` (a ctypes
    library) if it exports one (a pythonfmu FMU); do nothing for any other FMU."""
    try:
        finalize = dll.finalizePythonInterpreter
    except AttributeError:
        return
    finalize.argtypes = []
    finalize.restype = None
    finalize()


def release_at_exit(resources: str | None, model_identifier: str) -> None:
    """From inside a pythonfmu FMU's model: release its library's interpreter handle when the
    host's interpreter finalises (:mod:`atexit`), before the C library's exit handlers.

    Only in a Python host on Linux (the interpreter was started by a Python executable,
    ``sys.orig_argv`` is not empty): in a C host the interpreter is pythonfmu's own and is
    finalised by that very handle's destructor, which must not be re-entered. Once per
    library; nothing happens if the library was unloaded meanwhile."""
    if not sys.platform.startswith("linux") or not getattr(sys, "orig_argv", None) or not resources:
        return
    library = Path(resources).parent / "binaries" / "linux64" / f"{model_identifier}.so"
    if str(library) in _REGISTERED or not library.is_file():
        return
    _REGISTERED.add(str(library))

    def release() -> None:
        try:  # only if still loaded: RTLD_NOLOAD never loads it again
            dll = ctypes.CDLL(str(library), mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
        except OSError:
            return
        release_pythonfmu_state(dll)

    atexit.register(release)

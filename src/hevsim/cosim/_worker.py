"""Worker process of :class:`hevsim.cosim.worker.WorkerFMUParticipant`.

Speaks JSON lines on stdin/stdout: one request ``{"cmd": ..., ...}`` per line, one reply
``{"ok": true, "result": ...}`` or ``{"ok": false, "error": ...}`` per line. Leaves with
``os._exit`` so a crash in an FMU's teardown cannot hang or fail the master.
"""

from __future__ import annotations

import base64
import json
import os
import sys
from typing import Any


def main() -> None:
    """Serve requests until ``quit`` or end of input."""
    from hevsim.cosim.participant import FMUParticipant, start_jit_before_pythonfmu

    # the protocol gets its own copy of fd 1; what the FMU prints (Python or C, fd 1 or 2)
    # goes to the inherited stderr, with the FMU logger's lines (log_level and up)
    out = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    p: FMUParticipant | None = None
    for line in sys.stdin:
        req = json.loads(line)
        cmd = req["cmd"]
        try:
            res: Any = None
            if cmd == "open":
                if _runs_hevsim_kernels(req["fmu"]):
                    # compiled kernels for hevsim's pythonfmu FMUs, as before their guard (this
                    # process leaves with os._exit, so the exit abort cannot happen here)
                    start_jit_before_pythonfmu()
                p = FMUParticipant(
                    req["name"],
                    req["fmu"],
                    req.get("parameters"),
                    log_level=req.get("log_level", "error"),
                    fmu_log=req.get("fmu_log"),
                )
                res = {
                    "inputs": p.inputs,
                    "outputs": p.outputs,
                    "can_state": p.can_save_state,
                    "state_note": p.state_note,
                    "types": dict(p.types),
                }
            elif cmd == "quit":
                break
            else:
                assert p is not None
                if cmd == "setup":
                    p.setup(req["t0"])
                elif cmd == "set":
                    p.set_inputs(req["values"])
                elif cmd == "step":  # set inputs, step, get outputs in one round trip
                    if req.get("values"):
                        p.set_inputs(req["values"])
                    ok, pref = p.do_step(req["t"], req["h"])
                    res = [
                        ok,
                        pref,
                        p.terminate_requested,
                        p.terminate_time,
                        p.get_outputs() if ok else None,
                    ]
                elif cmd == "get":
                    res = p.get_outputs()
                elif cmd == "get_state":
                    res = base64.b64encode(p.get_state()).decode()
                elif cmd == "set_state":
                    p.set_state(base64.b64decode(req["state"]))
                elif cmd == "terminate":
                    p.terminate()
                elif cmd == "crash":  # for tests of fault containment
                    os._exit(17)
                else:
                    raise ValueError(f"unknown command {cmd!r}")
            out.write(json.dumps({"ok": True, "result": res}) + "\n")
        except Exception as exc:
            out.write(json.dumps({"ok": False, "error": f"{type(exc).__name__}: {exc}"}) + "\n")
        out.flush()
    out.flush()
    os._exit(0)


def _runs_hevsim_kernels(fmu: str) -> bool:
    """Whether ``fmu`` is a pythonfmu FMU whose model (a top-level script under
    ``resources/``) imports :mod:`hevsim.battery.fmu` (checked without importing it)."""
    import zipfile

    try:
        with zipfile.ZipFile(fmu) as z:
            scripts = [n for n in z.namelist() if n.count("/") == 1 and n.startswith("resources/")]
            return any(n.endswith(".py") and b"hevsim.battery.fmu" in z.read(n) for n in scripts)
    except (OSError, zipfile.BadZipFile):
        return False


if __name__ == "__main__":
    main()

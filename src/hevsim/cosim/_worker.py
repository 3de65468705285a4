"""Worker process of :class:`hevsim.cosim.worker.WorkerFMUParticipant`.

Protocol: length-prefixed pickle frames on two pipes (requests on fd 0, replies on a private
copy of fd 1). A request is a tuple ``(command, *arguments)``, a reply ``(True, result)`` or
``(False, "ExceptionType: message")``. The per-step request ``("step", t, h, names, values)``
carries the inputs as a tuple of values, with their names only when they differ from the
previous step's (``names`` None otherwise); its reply carries the outputs the same way.
``("steps", ((t, h), ...))`` runs several steps with the inputs held (a participant without
inputs running ahead of the master) and replies with each step's result. One round trip
per communication step (or batch of steps), no text encoding: about 2 µs of protocol work
per side on top of the pipe's wake-ups (``docs/cosim.md``, Speed).

Leaves with ``os._exit`` so a crash in an FMU's teardown cannot hang or fail the master.
"""

from __future__ import annotations

import os
import pickle
import struct
import sys
from typing import Any

_HEADER = struct.Struct("<I")  # payload length [bytes]


def encode_frame(obj: Any) -> bytes:
    """``obj`` as one frame: its pickle's length, then the pickle."""
    payload = pickle.dumps(obj, pickle.HIGHEST_PROTOCOL)
    return _HEADER.pack(len(payload)) + payload


def write_frame(fd: int, frame: bytes) -> None:
    """Write a frame made by :func:`encode_frame` to the pipe ``fd``."""
    view = memoryview(frame)
    while view:
        view = view[os.write(fd, view) :]


def send_frame(fd: int, obj: Any) -> None:
    """Write ``obj`` as one frame to the pipe ``fd``."""
    write_frame(fd, encode_frame(obj))


class FrameReader:
    """Reads frames from the pipe ``fd``, keeping bytes that arrived beyond a frame for the
    next one (in the request-reply exchange one read usually holds exactly one frame)."""

    def __init__(self, fd: int):
        self.fd = fd
        self.buf = b""

    def recv(self) -> Any:
        """The next frame's object; :class:`EOFError` if the writer has gone."""
        buf = self.buf
        while True:
            if len(buf) >= _HEADER.size:
                end = _HEADER.size + _HEADER.unpack_from(buf)[0]
                if len(buf) >= end:
                    self.buf = buf[end:]
                    return pickle.loads(memoryview(buf)[_HEADER.size : end])
                need = end - len(buf)
            else:
                need = _HEADER.size - len(buf)
            data = os.read(self.fd, max(need, _READ_BYTES))
            if not data:
                self.buf = buf
                raise EOFError
            buf += data


_READ_BYTES = 1 << 16


def main() -> None:
    """Serve requests until ``quit`` or end of input."""
    # the protocol gets its own copy of fd 1; what the FMU prints (Python or C, fd 1 or 2)
    # goes to the inherited stderr, with the FMU logger's lines (log_level and up)
    out = os.dup(1)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    serve(0, out)
    os._exit(0)


class _Stepper:
    """The per-step requests on one participant; remembers the input and output names last
    exchanged (sent only when they change)."""

    def __init__(self, p: Any):
        self.p = p
        self.in_names: tuple[str, ...] = ()
        self.out_names: tuple[str, ...] | None = None

    def step(self, t: float, h: float, names: tuple[str, ...] | None, values: tuple[Any, ...]) -> Any:
        """Set inputs, step, get outputs: (ok, preferred h, terminate requested, terminate
        time, (output names or None, output values) or None)."""
        p = self.p
        if names is not None:
            self.in_names = names
        if values:
            p.set_inputs(dict(zip(self.in_names, values, strict=True)))
        ok, pref = p.do_step(t, h)
        outs: Any = None
        if ok:
            o = p.get_outputs()
            keys = tuple(o)
            outs = (None if keys == self.out_names else keys, tuple(o.values()))
            self.out_names = keys
        return ok, pref, p.terminate_requested, p.terminate_time, outs

    def steps(self, schedule: tuple[tuple[float, float], ...]) -> Any:
        """Run ahead: the steps ``schedule`` ((t, h) pairs) with the inputs held, up to the first
        that is not accepted or asks to terminate: (their replies, the error of the step
        that raised or None)."""
        replies: list[Any] = []
        for t, h in schedule:
            try:
                r = self.step(t, h, None, ())
            except Exception as exc:
                return replies, f"{type(exc).__name__}: {exc}"
            replies.append(r)
            if not r[0] or r[2]:
                break
        return replies, None


def serve(rfd: int, wfd: int) -> None:
    """Answer the requests read from ``rfd`` on ``wfd`` until ``quit`` or end of input."""
    from hevsim.cosim.participant import FMUParticipant

    p: FMUParticipant | None = None
    st: _Stepper | None = None
    reader = FrameReader(rfd)
    while True:
        try:
            req = reader.recv()
        except EOFError:
            return
        cmd = req[0]
        try:
            res: Any = None
            if cmd == "step":  # set inputs, step, get outputs in one round trip
                assert st is not None
                res = st.step(*req[1:])
            elif cmd == "steps":  # several steps without inputs in one round trip
                assert st is not None
                res = st.steps(req[1])
            elif cmd == "open":
                _, name, fmu, parameters, log_level, fmu_log = req
                p = FMUParticipant(name, fmu, parameters, log_level=log_level, fmu_log=fmu_log)
                st = _Stepper(p)
                res = (p.inputs, p.outputs, p.can_save_state, p.state_note, dict(p.types))
            elif cmd == "quit":
                return
            elif cmd == "crash":  # for tests of fault containment
                os._exit(17)
            else:
                assert p is not None
                res = _other(p, cmd, req[1:])
            reply: tuple[bool, Any] = (True, res)
        except Exception as exc:
            reply = (False, f"{type(exc).__name__}: {exc}")
        send_frame(wfd, reply)


def _other(p: Any, cmd: str, args: tuple[Any, ...]) -> Any:
    """The requests that are not on the per-step path."""
    if cmd == "setup":
        p.setup(*args)
    elif cmd == "set":
        p.set_inputs(*args)
    elif cmd == "get":
        return p.get_outputs()
    elif cmd == "get_state":
        return bytes(p.get_state())
    elif cmd == "set_state":
        p.set_state(*args)
    elif cmd == "terminate":
        p.terminate()
    else:
        raise ValueError(f"unknown command {cmd!r}")
    return None


if __name__ == "__main__":
    main()

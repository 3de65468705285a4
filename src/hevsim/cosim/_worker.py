"""Worker process of :class:`hevsim.cosim.worker.WorkerFMUParticipant`.

Protocol: length-prefixed pickle frames on two pipes (requests on fd 0, replies on a private
copy of fd 1). A request is a tuple ``(command, *arguments)``, a reply ``(True, result)`` or
``(False, "ExceptionType: message")``. The per-step request ``("step", t, h, names, values)``
carries the inputs as a tuple of values, with their names only when they differ from the
previous step's (``names`` None otherwise); its reply carries the outputs the same way.
``("steps", ((t, h), ...))`` runs several steps with the inputs held (a participant without
inputs running ahead of the master) and replies with each step's result.

Steps of an FMU whose outputs are all float64 and whose inputs set in the step are scalar
float64 (the common case) go through shared memory instead (:class:`StepChannel`, Linux
``memfd``): the master writes the step's time, size and input values there, bumps a request
counter and sends a 4-byte token frame; the worker sets the inputs from that memory and
reads the outputs into it with the FMU's own ``fmi2SetReal`` / ``fmi2GetReal`` (FMI 3.0:
``fmi3SetFloat64`` / ``fmi3GetFloat64``), writes the step's outcome, bumps the reply counter
and sends a token back (a failure still replies with a pickled error frame). The first step
with a new set of input names is ``("bind", names, fd, size, spin_s)`` with its values
already in the memory. Each side waits for the other by polling the counter for a short,
adaptive time (:class:`Spin`, at most ``spin_s``) before it blocks on the pipe: the token is
always read, so the pipe orders the memory accesses and a side that stopped polling is woken
as before; the polling saves the two process wake-ups of a round trip when a core is free.

Leaves with ``os._exit`` so a crash in an FMU's teardown cannot hang or fail the master.
"""

from __future__ import annotations

import contextlib
import math
import os
import pickle
import struct
import sys
import time
from collections.abc import Iterator
from typing import Any

_HEADER = struct.Struct("<I")  # payload length [bytes]
_TOKEN_LENGTH = 0xFFFFFFFF  # a header with this length is a token frame (no payload)
TOKEN_FRAME = _HEADER.pack(_TOKEN_LENGTH)
"""A step (or its reply) is in the shared memory (:class:`StepChannel`)."""
TOKEN = object()
"""What :meth:`FrameReader.recv` returns for a :data:`TOKEN_FRAME`."""


PACKED = "packed"
"""Marks a run-ahead reply whose outputs come as one float64 buffer (:meth:`_Stepper.steps`)."""


def unpack_steps(packed: tuple[Any, ...]) -> tuple[tuple[str, ...], list[Any]]:
    """The output names and the per-step replies (ok, preferred h, terminate requested,
    terminate time, {output: value} or None) of a packed run-ahead reply."""
    _, names, data, prefs, (ok, term, t_term) = packed
    n = len(names)
    vals = memoryview(data).cast("d").tolist() if data else []
    last = len(prefs) - 1
    out: list[Any] = [(True, pref, False, None, dict(zip(names, vals[k * n : k * n + n], strict=True)))
           for k, pref in enumerate(prefs[:last])]  # fmt: skip
    if last >= 0:
        outs = dict(zip(names, vals[last * n : last * n + n], strict=True)) if ok else None
        out.append((ok, prefs[last], term, t_term, outs))
    return names, out


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
                length = _HEADER.unpack_from(buf)[0]
                if length == _TOKEN_LENGTH:
                    self.buf = buf[_HEADER.size :]
                    return TOKEN
                end = _HEADER.size + length
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

# The shared memory of a worker (StepChannel): two counters, the step's outcome and the
# output values (read by the master in one unpack), then the step's time and size and the
# input values (as many as the FMU has scalar float64 inputs; written in one pack)
_SEQ = struct.Struct("<Q")  # request / reply counter
REQUEST_SEQ_AT, REPLY_SEQ_AT = 0, 8
OUTCOME_FORMAT = "<iidd"  # accepted, terminate requested, preferred h [s], terminate time [s]
OUTCOME_AT = 16  # (NaN: None), followed by the outputs
OUTPUTS_AT = OUTCOME_AT + struct.calcsize(OUTCOME_FORMAT)
_FLOAT = 8  # bytes per value
STEP = struct.Struct("<dd")  # t [s], h [s], followed by the inputs


_OUTCOME = struct.Struct(OUTCOME_FORMAT)


def step_at(n_outputs: int) -> int:
    """Offset of the step (t, h, inputs) in a :class:`StepChannel` for ``n_outputs`` outputs."""
    return OUTPUTS_AT + _FLOAT * n_outputs


def channel_size(n_inputs: int, n_outputs: int) -> int:
    """Bytes of a :class:`StepChannel` for ``n_inputs`` inputs and ``n_outputs`` outputs."""
    return step_at(n_outputs) + STEP.size + _FLOAT * n_inputs


def read_seq(mm: Any, at: int) -> int:
    """The counter at offset ``at`` of the shared memory ``mm``."""
    return int(_SEQ.unpack_from(mm, at)[0])


def write_seq(mm: Any, at: int, seq: int) -> None:
    """Set the counter at offset ``at`` of the shared memory ``mm`` to ``seq``."""
    _SEQ.pack_into(mm, at, seq)


SPIN_MAX_S = 50e-6
"""Longest a side polls the shared memory for the other's token before it blocks on the pipe
[s] by default (:attr:`hevsim.cosim.worker.WorkerFMUParticipant.spin_s`)."""
SPIN_MISS_WEIGHT = 4
"""A poll that runs out of time counts this many misses in :class:`Spin`, one answered in
time takes one off: polling goes on while at least 4 in 5 polls are answered (a miss costs
the whole polling time, a hit saves a wake-up of some 10 µs)."""
SPIN_BACKOFF_MAX = 8
"""At most this many misses counted by :class:`Spin` (then 256 waits block between polls)."""
SPIN_SAMPLE = 32
"""Waits between two looks of :class:`Spin` at the number of runnable processes."""
_LOADAVG = "/proc/loadavg"  # its 4th field: runnable / all scheduling entities (Linux)


def runnable_processes() -> int | None:
    """Processes (threads) runnable on the machine right now, this one included (None when
    the system does not say)."""
    try:
        fd = os.open(_LOADAVG, os.O_RDONLY)
        try:
            data = os.read(fd, 128)
        finally:
            os.close(fd)
        return int(data.split()[3].split(b"/")[0])
    except (OSError, IndexError, ValueError):
        return None


def _cores() -> int:
    """Cores this process may run on."""
    affinity = getattr(os, "sched_getaffinity", None)
    return len(affinity(0)) if affinity is not None else os.cpu_count() or 1


class Spin:
    """Waits for a counter in the shared memory ``mm`` at offset ``at`` to reach a value by
    polling it for at most ``limit_s`` [s]; the caller then reads the token from the pipe (at
    once when it has come, else blocking as without the polling). Polling pays only when the
    other side runs on another core meanwhile, so it is done only while the machine's
    runnable processes (both sides included, looked at every :data:`SPIN_SAMPLE` waits,
    averaged) do not outnumber its cores: on a busy machine, the scheduler favours
    processes that sleep, and a polling side would only lose its turn later. The poll keeps
    the core (a yield would hand it to whatever else is runnable there for a whole time
    slice). A poll that runs out of time (the other side is slow, or waits for the very core
    this side holds) counts :data:`SPIN_MISS_WEIGHT` misses, a poll answered in time takes
    one off, and after ``k`` misses the next ``2**k`` waits block at once (``k`` at most
    :data:`SPIN_BACKOFF_MAX`). So on a free core a round trip costs no process wake-up, and
    on a loaded machine the polling soon stops costing anything."""

    def __init__(self, mm: Any, at: int, limit_s: float = SPIN_MAX_S):
        self.mm, self.at, self.limit_s = mm, at, float(limit_s)
        self.misses = 0  # polls that ran out of time, less those answered in time
        self.skip = 0  # waits left to block without polling
        self.cores = _cores()
        self.runnable = 0.0  # runnable processes, recent average
        self.count = 0  # waits since the last look at them

    def crowded(self) -> bool:
        """Whether the machine has more runnable processes than cores (looked at every
        :data:`SPIN_SAMPLE` calls)."""
        if self.count == 0:
            n = runnable_processes()
            if n is not None:
                self.runnable += (n - self.runnable) * 0.5
        self.count = (self.count + 1) % SPIN_SAMPLE
        return self.runnable > self.cores + 0.5

    def poll(self, seq: int) -> None:
        """Poll until the counter is ``seq`` or the time is up (see the class)."""
        limit = self.limit_s
        if limit <= 0.0 or self.crowded():
            return
        if self.skip:
            self.skip -= 1
            return
        clock, unpack, mm, at = time.perf_counter, _SEQ.unpack_from, self.mm, self.at
        t0 = clock()
        while unpack(mm, at)[0] != seq:
            if clock() - t0 > limit:
                self.misses = min(self.misses + SPIN_MISS_WEIGHT, SPIN_BACKOFF_MAX)
                self.skip = 1 << self.misses
                return
        if self.misses:
            self.misses -= 1


class StepChannel:
    """The worker's side of the shared memory (file descriptor ``fd`` inherited from the
    master, ``size`` bytes): steps with their inputs and outputs in place, the FMU's float64
    get / set functions reading and writing it directly."""

    def __init__(self, fd: int, size: int, spin_s: float):
        import mmap

        self.mm = mmap.mmap(fd, size)
        self.size = size
        self.spin = Spin(self.mm, REQUEST_SEQ_AT, spin_s)
        self.seq = 0  # the last request's counter
        self.set_inputs: Any = None
        self.get_outputs: Any = None
        self.step_at = step_at(0)

    def bind(self, p: Any, names: tuple[str, ...]) -> None:
        """Steps set the inputs ``names`` of the FMU participant ``p`` from the memory."""
        import ctypes

        n_out = len(p.outputs)
        self.step_at = at = step_at(n_out)
        ins = (ctypes.c_double * len(names)).from_buffer(self.mm, at + STEP.size) if names else None
        outs = (ctypes.c_double * n_out).from_buffer(self.mm, OUTPUTS_AT) if n_out else None
        self.set_inputs, self.get_outputs = p.real_io(names, ins, outs)

    def step(self, p: Any) -> None:
        """Run the step in the memory on ``p`` and write its outcome and outputs there."""
        mm = self.mm
        t, h = STEP.unpack_from(mm, self.step_at)
        if self.set_inputs is not None:
            try:  # (as phase("set_inputs"), without a generator per step)
                self.set_inputs()
            except Exception as exc:
                exc.hevsim_call = "set_inputs"  # type: ignore[attr-defined]
                raise
        ok, pref = p.do_step(t, h)
        if ok and self.get_outputs is not None:
            try:
                self.get_outputs()
            except Exception as exc:
                exc.hevsim_call = "get_outputs"  # type: ignore[attr-defined]
                raise
        tt = p.terminate_time
        nan = math.nan
        _OUTCOME.pack_into(mm, OUTCOME_AT, ok, p.terminate_requested, nan if pref is None else pref,
                          nan if tt is None else tt)  # fmt: skip


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
            with phase("set_inputs"):
                p.set_inputs(dict(zip(self.in_names, values, strict=True)))
        ok, pref = p.do_step(t, h)
        outs: Any = None
        if ok:
            with phase("get_outputs"):
                o = p.get_outputs()
            keys = tuple(o)
            outs = (None if keys == self.out_names else keys, tuple(o.values()))
            self.out_names = keys
        return ok, pref, p.terminate_requested, p.terminate_time, outs

    def steps(self, schedule: tuple[tuple[float, float], ...]) -> Any:
        """Run ahead: the steps ``schedule`` ((t, h) pairs) with the inputs held, up to the first
        that is not accepted or asks to terminate: (their replies, the error of the step
        that raised or None)."""
        packed = self._packed_steps(schedule)
        if packed is not None:
            return packed
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

    def _packed_steps(self, schedule: tuple[tuple[float, float], ...]) -> Any:
        """:meth:`steps` for an FMU whose outputs are all float64, its outputs read with the
        FMU's own get function into one buffer (no dict per step): ((``PACKED``, output
        names, the accepted steps' outputs as float64 bytes, row after row, each step's
        preferred step, (ok, terminate requested, terminate time) of the last step), error);
        every step but the last was accepted without a termination request. None: the FMU's
        outputs are not all float64 (or it has none)."""
        import ctypes

        p = self.p
        fast = p.vars.fast_names() if hasattr(p, "real_io") else None
        if fast is None or not fast[1]:
            return None
        names = fast[1]
        row = (ctypes.c_double * len(names))()
        _, get = p.real_io((), None, row)
        assert get is not None
        data, prefs = bytearray(), []
        tail: tuple[bool, bool, float | None] = (True, False, None)
        err = None
        for t, h in schedule:
            try:  # (the failure is reported as text either way: no phase marked)
                ok, pref = p.do_step(t, h)
                if ok:
                    get()
            except Exception as exc:
                err = f"{type(exc).__name__}: {exc}"
                break
            prefs.append(pref)
            if ok:
                data += row
            tail = (bool(ok), bool(p.terminate_requested), p.terminate_time)
            if not ok or tail[1]:
                break
        self.out_names = names
        return (PACKED, names, bytes(data), tuple(prefs), tail), err


@contextlib.contextmanager
def phase(call: str) -> Iterator[None]:
    """Mark an exception raised inside as a failure of the participant call ``call``."""
    try:
        yield
    except Exception as exc:
        exc.hevsim_call = call  # type: ignore[attr-defined]
        raise


def failure(exc: Exception) -> Any:
    """The reply text of a failed request: "Type: message", as (call, text) when the failure
    happened in another participant call than the request's (:func:`phase`)."""
    text = f"{type(exc).__name__}: {exc}"
    call = getattr(exc, "hevsim_call", None)
    return (call, text) if call else text


def serve(rfd: int, wfd: int) -> None:
    """Answer the requests read from ``rfd`` on ``wfd`` until ``quit`` or end of input."""
    from hevsim.cosim.me import participant_class
    from hevsim.cosim.participant import FMUParticipant

    p: FMUParticipant | None = None
    st: _Stepper | None = None
    ch: StepChannel | None = None
    reader = FrameReader(rfd)
    stepping = False  # the last request was a step in shared memory: poll for the next
    while True:
        if ch is not None and stepping and not reader.buf:
            ch.spin.poll(ch.seq + 1)
        try:
            req = reader.recv()
        except EOFError:
            return
        stepping = req is TOKEN or req[0] == "bind"
        if stepping:
            try:
                assert p is not None
                if req is not TOKEN:
                    _, names, fd, size, spin_s = req
                    if ch is None:
                        ch = StepChannel(fd, size, spin_s)
                    ch.bind(p, names)
                assert ch is not None
                ch.step(p)
                frame = TOKEN_FRAME
            except Exception as exc:
                frame = encode_frame((False, failure(exc)))
            if ch is not None:
                ch.seq = read_seq(ch.mm, REQUEST_SEQ_AT)
                write_seq(ch.mm, REPLY_SEQ_AT, ch.seq)
            write_frame(wfd, frame)
            continue
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
                p = participant_class(fmu)(name, fmu, parameters, log_level=log_level, fmu_log=fmu_log)
                st = _Stepper(p)
                fast = p.vars.fast_names()
                res = (
                    p.inputs,
                    p.outputs,
                    p.can_save_state,
                    p.state_note,
                    dict(p.types),
                    fast,
                    dict(p.fmi_types),
                    p.exact_restore,
                )
            elif cmd == "quit":
                return
            elif cmd == "crash":  # for tests of fault containment
                os._exit(17)
            else:
                assert p is not None
                res = _other(p, cmd, req[1:])
            reply: tuple[bool, Any] = (True, res)
        except Exception as exc:
            reply = (False, failure(exc))
        send_frame(wfd, reply)


def _other(p: Any, cmd: str, args: tuple[Any, ...]) -> Any:
    """The requests that are not on the per-step path."""
    if cmd == "setup":  # (t0, the run window or None): the outputs after it, None if unreadable
        t0, *run = args
        if run and run[0] is not None and hasattr(p, "run_window"):
            p.run_window(*run[0])
        p.setup(t0)
        try:
            return p.get_outputs()
        except Exception:  # (reported by the master's own query)
            return None
    elif cmd == "set":
        p.set_inputs(*args)
    elif cmd == "get":
        return p.get_outputs()
    elif cmd == "get_state":  # (an FMU's serialised state; a Model Exchange FMU's with its own)
        state = p.get_state()
        return bytes(state) if isinstance(state, bytearray | memoryview) else state
    elif cmd == "set_state":
        p.set_state(*args)
    elif cmd == "terminate":
        p.terminate()
    elif cmd == "window":  # a Model Exchange FMU's run window (its solver's maximum step)
        window = getattr(p, "run_window", None)
        if window is not None:
            window(*args)
    else:
        raise ValueError(f"unknown command {cmd!r}")
    return None


if __name__ == "__main__":
    main()

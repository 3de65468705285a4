"""An FMU participant in a persistent worker process (length-prefixed pickle frames over its
stdin/stdout pipes, float64 steps in shared memory: :mod:`hevsim.cosim._worker`), so an FMU
that crashes cannot take the master down: the master gets a :class:`SimulationError` naming
the participant and the call instead. One round trip per communication step (inputs,
doStep, outputs); under Jacobi the workers step in parallel
(:meth:`WorkerFMUParticipant.start_step`), and a worker without inputs runs ahead, several
steps per round trip (:meth:`WorkerFMUParticipant.run_ahead`)."""

from __future__ import annotations

import collections
import contextlib
import math
import os
import signal
import struct
import subprocess
import sys
import time
import weakref
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, NoReturn

from hevsim.cosim._worker import (
    OUTCOME_AT,
    OUTCOME_FORMAT,
    PACKED,
    REPLY_SEQ_AT,
    REQUEST_SEQ_AT,
    SPIN_MAX_S,
    TOKEN,
    TOKEN_FRAME,
    FrameReader,
    Spin,
    channel_size,
    encode_frame,
    send_frame,
    step_at,
    unpack_steps,
    write_frame,
    write_seq,
)
from hevsim.cosim.participant import Participant, PhaseError, fmu_file
from hevsim.errors import ConfigError, SimulationError

RUN_AHEAD_STEPS = 100
"""Steps of the first round trip of a worker FMU running ahead (:meth:`WorkerFMUParticipant.run_ahead`)."""
RUN_AHEAD_MAX = 3200
"""Most steps per round trip of a worker FMU running ahead (the batch doubles up to it)."""


START_METHOD = "fork" if sys.platform.startswith("linux") else "spawn"
"""The default :attr:`WorkerFMUParticipant.start_method`."""

_MASTER_ENDS: weakref.WeakSet[Any] = weakref.WeakSet()
"""The master's ends of the forked workers' pipes: a worker forked later closes them, so a
worker sees the end of its input when the master closes it or dies."""


class ForkedWorker:
    """A worker process forked from the master (:func:`hevsim.cosim._worker.serve` on two
    pipes), with the part of :class:`subprocess.Popen`'s interface the participant uses
    (``stdin``, ``stdout``, ``pid``, ``poll``, ``wait``, ``kill``, ``returncode``). The
    fork starts in milliseconds: the master's imports (FMPy, hevsim) are already done. The
    worker's fd 1 goes to the master's stderr (what the FMU prints), as a spawned worker's."""

    def __init__(self) -> None:
        r_req, w_req = os.pipe()
        r_rep, w_rep = os.pipe()
        for f in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                f.flush()  # (not written twice by the copy)
        pid = os.fork()
        if pid == 0:  # the worker: serve, never return into the master's code
            code = 1
            try:
                for f in list(_MASTER_ENDS):  # (closing the file objects, this process's
                    if not f.closed:  # copies: one collected later must not close a reused fd)
                        with contextlib.suppress(OSError):
                            f.close()
                os.close(w_req)
                os.close(r_rep)
                os.dup2(2, 1)
                sys.stdout = sys.stderr
                import faulthandler

                faulthandler.disable()  # (as a spawned worker: a crash is reported by the master)
                from hevsim.cosim._worker import serve

                serve(r_req, w_rep)
                code = 0
            except BaseException:
                import traceback

                with contextlib.suppress(Exception):
                    traceback.print_exc()
            finally:
                os._exit(code)
        os.close(r_req)
        os.close(w_rep)
        self.pid = pid
        self.returncode: int | None = None
        self.stdin = os.fdopen(w_req, "wb", buffering=0)
        self.stdout = os.fdopen(r_rep, "rb", buffering=0)
        _MASTER_ENDS.add(self.stdin)
        _MASTER_ENDS.add(self.stdout)

    def poll(self) -> int | None:
        """The exit code (negative: killed by that signal), None while it runs."""
        if self.returncode is None:
            try:
                pid, status = os.waitpid(self.pid, os.WNOHANG)
            except ChildProcessError:
                self.returncode = -1
                return self.returncode
            if pid:
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        end = None if timeout is None else time.monotonic() + timeout
        # its exit closes the reply pipe: wake up then rather than after a sleep (for at most
        # 50 ms: a process the FMU started may hold the pipe open; then the sleeps below)
        if self.poll() is None and not self.stdout.closed:
            import select

            with contextlib.suppress(OSError, ValueError):
                select.select([self.stdout], [], [], min(0.05, timeout if timeout is not None else 0.05))
        delay = 1e-4
        while self.poll() is None:
            if end is not None and time.monotonic() >= end:
                raise subprocess.TimeoutExpired(f"forked worker {self.pid}", timeout or 0.0)
            time.sleep(delay)
            delay = min(2 * delay, 0.02)
        assert self.returncode is not None
        return self.returncode

    def kill(self) -> None:
        if self.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGKILL)

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            if self.poll() is None:
                self.stdin.close()


_CALLS = {"set": "set_inputs", "get": "get_outputs"}
"""The participant call a worker request makes (named in failures)."""


class WorkerFMUParticipant(Participant):
    """Same behaviour as :class:`hevsim.cosim.participant.FMUParticipant`, in a subprocess."""

    shared_memory = True
    """Steps go through shared memory where the types allow (False: every step is a pickled
    frame, as on systems without ``os.memfd_create``; for comparisons)."""
    spin_s = SPIN_MAX_S
    """How long each side polls for the other's reply before blocking on the pipe [s]
    (0: never; see :class:`hevsim.cosim._worker.Spin`)."""
    start_method = START_METHOD
    """How the worker process starts: "fork" (a copy of the master, its imports done: a few
    ms; the default on Linux) or "spawn" (a fresh interpreter that imports FMPy and hevsim's
    worker: 0.3-0.9 s)."""

    def __init__(
        self,
        name: str,
        fmu: str | Path,
        parameters: Mapping[str, Any] | None = None,
        log_level: str = "error",
        fmu_log: str | Path | None = None,
    ):
        self.name = name
        self.fmu = fmu_file(name, fmu)
        self.terminate_requested = False
        # shared memory for the float64 steps (Linux; elsewhere every step is a pickled frame)
        shm = self.shared_memory and hasattr(os, "memfd_create")
        self._fd = os.memfd_create(f"hevsim-worker-{name}") if shm else -1
        self._mm: Any = None
        self._awaiting = 0  # counter of the step in shared memory whose reply is due
        try:
            self.proc: Any
            if self.start_method == "fork":
                self.proc = ForkedWorker()
            else:
                self.proc = subprocess.Popen(
                    [sys.executable, "-m", "hevsim.cosim._worker"],
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    stderr=None,  # the FMU's own output and its logger lines from log_level up
                    bufsize=0,
                    pass_fds=(self._fd,) if self._fd >= 0 else (),
                )
        except BaseException:
            if self._fd >= 0:
                os.close(self._fd)
            raise
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self._wfd = self.proc.stdin.fileno()
        self._reader = FrameReader(self.proc.stdout.fileno())
        self._broken = ""  # the call a protocol exchange was interrupted in
        self._in_flight = False  # a step was sent and its reply not read yet
        self._started = False  # start_step ran; do_step has not collected it yet
        self._step_reply: tuple[bool, Any] = (False, None)
        self._next_end: Callable[[float], float | None] | None = None  # running ahead
        self._batch = RUN_AHEAD_STEPS
        self._max_batch = RUN_AHEAD_MAX
        self._ahead: collections.deque[tuple[float, float, Any]] = collections.deque()
        self._prefetched: tuple[tuple[float, float], ...] | None = None  # steps sent, reply due
        self._upcoming: tuple[tuple[float, float], ...] = ()  # the batch after them
        self._in_names: tuple[str, ...] | None = None  # input names the worker holds
        self._out_names: tuple[str, ...] = ()
        self._window: tuple[float, float] | None = None  # the run window, sent with setup
        self._quit_sent = False
        try:
            info = self._rpc("open", name, str(self.fmu), dict(parameters or {}), log_level,
                             str(fmu_log) if fmu_log else None)  # fmt: skip
        except SimulationError as exc:
            self.close()
            raise ConfigError(str(exc)) from None
        ins, outs, can_state, note, types, fast, fmi_types, exact = info
        self.exact_restore = bool(exact)
        self.inputs, self.outputs = dict(ins), dict(outs)
        self.fmi_types = dict(fmi_types)
        self._can_state, self._state_note = bool(can_state), str(note)
        self.types = dict(types)
        self._open_channel(fast)

    def _open_channel(self, fast: tuple[tuple[str, ...], tuple[str, ...]] | None) -> None:
        """Map the shared memory when the FMU's outputs are all float64 (``fast``: its scalar
        float64 inputs and its outputs, else None): steps setting only such inputs go
        through it (:mod:`hevsim.cosim._worker`)."""
        self._fast_in: frozenset[str] = frozenset()
        self._fast_names: tuple[str, ...] | None = None  # the inputs the worker is bound to
        self._seq = 0
        self._packers: dict[tuple[str, ...], Callable[..., None]] = {}
        if fast is None or self._fd < 0:
            return
        import mmap

        fast_in, self._fast_out = fast
        self._size = channel_size(len(fast_in), len(self._fast_out))
        os.ftruncate(self._fd, self._size)
        self._mm = mmap.mmap(self._fd, self._size)
        self._spin = Spin(self._mm, REPLY_SEQ_AT, self.spin_s)
        self._step_at = step_at(len(self._fast_out))
        self._unpack_reply = struct.Struct(f"{OUTCOME_FORMAT}{len(self._fast_out)}d").unpack_from
        self._fast_in = frozenset(fast_in)

    @property
    def can_save_state(self) -> bool:
        return self._can_state

    @property
    def state_note(self) -> str:
        return self._state_note

    def _rpc(self, cmd: str, *args: Any) -> Any:
        self._send(cmd, *args)
        return self._recv(cmd)

    def _send(self, cmd: str, *args: Any) -> None:
        self._ready()
        self._write(cmd, encode_frame((cmd, *args)))  # (an argument that cannot be sent fails here)

    def _ready(self) -> None:
        """Check the worker can take a request (collecting a started step's reply first)."""
        if self._broken:
            raise SimulationError(
                f"participant {self.name!r}: the exchange with its worker process was interrupted "
                f"in {self._broken}; the worker cannot be used any more."
            )
        if self._in_flight:  # a started step's reply comes first
            self._collect()
        if self._prefetched is not None:  # so does that of the steps run ahead meanwhile
            self._take()

    def _write(self, cmd: str, frame: bytes) -> None:
        try:
            write_frame(self._wfd, frame)
        except OSError:
            self._crashed(cmd)
        except BaseException:  # e.g. KeyboardInterrupt: part of a frame may have gone
            self._broken = cmd
            raise

    def _recv(self, cmd: str) -> Any:
        seq, self._awaiting = self._awaiting, 0
        try:
            if seq:  # a step in shared memory: poll for its reply before blocking on the pipe
                if not self._reader.buf:
                    self._spin.poll(seq)
                msg = self._reader.recv()
                if msg is TOKEN:
                    return self._fast_reply()
                self._fast_names = None  # it failed: bind again
            else:
                msg = self._reader.recv()
        except (EOFError, OSError):
            self._crashed(cmd)
        except BaseException:  # e.g. KeyboardInterrupt between request and reply
            self._broken = cmd
            raise
        ok, res = msg
        if not ok:
            call = _CALLS.get(cmd)
            if isinstance(res, tuple):  # failed in another participant call than the request's
                call, res = res
            text = f"participant {self.name!r}: {call or cmd} failed: {res}"
            raise PhaseError(text, call) if call else SimulationError(text)
        return res

    def _crashed(self, cmd: str) -> NoReturn:
        proc = self.proc
        try:
            code = proc.wait(timeout=10)
        except subprocess.TimeoutExpired:  # closed its pipe but still running: stop it
            proc.kill()
            code = proc.wait()
        raise SimulationError(
            f"participant {self.name!r}: worker process crashed in {cmd} (exit code {code})."
        ) from None

    def _collect(self) -> None:
        """Read the reply of the step :meth:`start_step` sent (kept for :meth:`do_step`)."""
        self._in_flight = False
        try:
            self._step_reply = (True, self._recv("step"))
        except SimulationError as exc:
            if self.proc.poll() is not None:
                raise
            self._step_reply = (False, exc)

    def run_window(self, start_s: float, stop_s: float) -> None:
        """Tell the FMU the run's start and stop time (a Model Exchange FMU's solver takes its
        maximum step from them: :meth:`hevsim.cosim.me.MEParticipant.run_window`); sent with
        the next :meth:`setup` (one round trip less)."""
        self._window = (float(start_s), float(stop_s))

    # Inputs are sent with the next step (or output query): one round trip per step.
    def setup(self, t0: float) -> None:
        self._fast_names = None  # a new instance: bind the shared memory again
        self._pending: dict[str, Any] = {}
        self._out: dict[str, Any] | None = None
        self._started = False
        self._discard_ahead()
        # the reply holds the outputs after the set-up (the master's first query: one round
        # trip less), None when they could not be read (the query then asks again and fails)
        outs = self._rpc("setup", t0, self._window)
        if outs is not None:
            self._out = dict(outs)

    def set_inputs(self, values: Mapping[str, Any]) -> None:
        inputs = self.inputs
        for k in values:
            if k not in inputs:
                raise ConfigError(f"participant {self.name!r}: FMU {self.fmu.name} has no input {k!r}.")
        self._pending.update(values)
        self._out = None

    def start_step(self, t: float, h: float) -> None:
        """Send the step from ``t`` by ``h`` [s] with the inputs set so far and return at once:
        the worker steps while the master does other work; :meth:`do_step` with the same
        arguments collects the result (the master's Jacobi steps use this, so worker FMUs
        step at the same time as each other and as the participants in process)."""
        self._send_step(t, h)
        self._in_flight = self._started = True

    def _send_step(self, t: float, h: float) -> None:
        pending = self._pending
        names: tuple[str, ...] | None = tuple(pending)
        if self._mm is not None and self._fast_in.issuperset(names) and self._send_fast(t, h, names):  # type: ignore[arg-type]
            return
        same = names == self._in_names
        self._send("step", t, h, None if same else names, tuple(pending.values()))
        self._in_names = names  # the worker keeps them for the next steps
        self._pending = {}
        self._out = None

    def _send_fast(self, t: float, h: float, names: tuple[str, ...]) -> bool:
        """Send the step through the shared memory (False: a value is not a float, sent pickled)."""
        self._ready()
        mm = self._mm
        pack = self._packers.get(names)
        if pack is None:
            pack = self._packers[names] = struct.Struct(f"<{2 + len(names)}d").pack_into
        try:
            pack(mm, self._step_at, t, h, *self._pending.values())
        except struct.error:
            return False
        self._seq += 1
        write_seq(mm, REQUEST_SEQ_AT, self._seq)
        if names == self._fast_names:
            frame = TOKEN_FRAME
        else:  # the worker binds these inputs to the memory, then steps
            frame = encode_frame(("bind", names, self._fd, self._size, self.spin_s))
        self._write("step", frame)
        self._fast_names = names
        self._awaiting = self._seq
        self._pending = {}
        self._out = None
        return True

    def _fast_reply(self) -> tuple[bool, float | None, bool, float | None, Any]:
        """The reply of a step in shared memory, as the pickled step's."""
        ok, term, pref, tt, *outs = self._unpack_reply(self._mm, OUTCOME_AT)
        return (bool(ok), None if math.isnan(pref) else pref, bool(term), None if math.isnan(tt) else tt,
                (self._fast_out, outs) if ok else None)  # fmt: skip

    def run_ahead(
        self,
        next_end: Callable[[float], float | None],
        batch: int = RUN_AHEAD_STEPS,
        max_batch: int = RUN_AHEAD_MAX,
    ) -> None:
        """Step ``batch`` steps per round trip from now on, twice as many at each round trip up
        to ``max_batch`` (on a loaded machine each round trip can wait milliseconds for the
        scheduler, so long runs want few of them): the master calls this for a
        participant without inputs in a run whose steps are fixed and never redone (its
        state is only saved for checkpoints: :meth:`get_state` keeps the steps run ahead);
        ``next_end(t)`` is the end of the step from ``t`` [s] (None: ``t`` is the stop time).
        Steps already run come from the buffer, with the same results, termination
        requests and failures, in the same steps, as stepping one at a time."""
        self._next_end = next_end
        self._batch = int(batch)
        self._max_batch = max(int(max_batch), self._batch)
        self._discard_ahead()

    def _fetch(self, t: float) -> None:
        """Take the next steps from ``t``: those the worker is running already, else run
        them now; then let the worker run the batch after them while the master takes these
        (the worker computes while the master records: on two free cores the run costs the
        larger of the two, not their sum). The next batch's schedule is made while the
        worker runs this one, and sent as soon as this one's reply is read (before it is
        unpacked): the worker waits for the master only for a pipe round trip."""
        if self._prefetched is None:
            schedule = self._schedule(t)
            if not schedule:
                raise SimulationError(f"participant {self.name!r}: asked to step from the stop time {t!r} s.")
            self._send("steps", schedule)
            self._prefetched = schedule
            self._upcoming = self._schedule(schedule[-1][0] + schedule[-1][1])  # (made while it runs)
        self._take(prefetch=True)

    def _schedule(self, t: float) -> tuple[tuple[float, float], ...]:
        """The next batch of (t, h) steps from ``t`` (empty at the stop time)."""
        assert self._next_end is not None
        next_end = self._next_end
        schedule: list[tuple[float, float]] = []
        append = schedule.append
        tk = t
        for _ in range(self._batch):
            te = next_end(tk)
            if te is None:
                break
            append((tk, te - tk))
            tk = te
        self._batch = min(2 * self._batch, self._max_batch)
        return tuple(schedule)

    def _take(self, prefetch: bool = False) -> None:
        """Read the reply of the steps run ahead (:attr:`_prefetched`) into the buffer; with
        ``prefetch``, send the next batch (:attr:`_upcoming`) first when these steps all
        went through (accepted, no termination, no failure)."""
        schedule, self._prefetched = self._prefetched, None
        assert schedule is not None
        try:
            replies, err = self._recv("steps")
        except SimulationError as exc:  # crashed: in one of the steps, which is not known
            if self.proc.poll() is None:
                raise
            raise SimulationError(
                f"{str(exc).rstrip('.')} while running {len(schedule)} steps ahead from t = "
                f"{schedule[0][0]:g} s to {sum(schedule[-1]):g} s (a worker without inputs steps "
                "ahead of the exchange)"
            ) from None
        packed = isinstance(replies, tuple) and replies and replies[0] == PACKED
        if prefetch and err is None:
            if packed:
                go = replies[4][0] and not replies[4][1] and len(replies[3]) == len(schedule)
            else:
                last = replies[-1] if replies else None
                go = isinstance(last, tuple) and last[0] and not last[2] and len(replies) == len(schedule)
            nxt = self._upcoming
            if go and nxt:
                self._send("steps", nxt)
                self._prefetched = nxt
                self._upcoming = self._schedule(nxt[-1][0] + nxt[-1][1])
        if packed:
            self._out_names, replies = unpack_steps(replies)
        self._ahead.extend((*step, r) for step, r in zip(schedule, replies, strict=False))
        if err is not None:
            self._ahead.append((*schedule[len(replies)], err))

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        if self._next_end is not None:
            if self._pending:  # (the master sets no inputs on a participant running ahead)
                if self._ahead or self._prefetched is not None:
                    raise SimulationError(f"participant {self.name!r}: inputs set while running ahead.")
                self._flush()
            if not self._ahead:
                self._fetch(t)
            tk, hk, reply = self._ahead.popleft()
            if (tk, hk) != (t, h):
                raise SimulationError(
                    f"participant {self.name!r}: asked for the step from {t!r} by {h!r} s while it "
                    f"ran ahead from {tk!r} by {hk!r} s."
                )
            self._out = None
            if isinstance(reply, str):
                raise SimulationError(f"participant {self.name!r}: step failed: {reply}")
        elif self._started:
            self._started = False
            if self._in_flight:
                self._collect()
            done, reply = self._step_reply
            self._step_reply = (False, None)
            if not done:
                raise reply
        else:
            self._send_step(t, h)
            reply = self._recv("step")
        ok, pref, term, t_term, outs = reply
        self.terminate_requested = bool(term)
        self.terminate_time = t_term
        if type(outs) is dict:  # (a packed run-ahead step)
            self._out = outs
        elif outs is not None:
            keys, vals = outs
            if keys is not None:
                self._out_names = keys
            self._out = dict(zip(self._out_names, vals, strict=True))
        return bool(ok), pref

    def get_outputs(self) -> dict[str, Any]:
        if self._out is None:
            self._flush()
            self._out = dict(self._rpc("get"))
        return dict(self._out)

    def _discard_ahead(self) -> None:
        """Forget the steps run ahead (their reply read first, when one is due)."""
        if self._prefetched is not None:
            self._ready()
        self._ahead.clear()
        self._upcoming = ()

    def _flush(self) -> None:
        if self._pending:
            self._rpc("set", self._pending)
            self._pending = {}

    def get_state(self) -> Any:
        """The FMU's serialised state; running ahead, with the results of the steps run but
        not taken yet (a checkpoint then resumes with them)."""
        self._flush()
        state = self._rpc("get_state")
        if self._ahead:
            return {"fmu": state, "out_names": self._out_names, "ahead": tuple(self._ahead)}
        return state

    def set_state(self, state: Any) -> None:
        self._pending = {}
        self._out = None
        self._started = False  # a step started from the replaced state is void
        self._discard_ahead()
        if isinstance(state, dict):  # saved while running ahead
            self._out_names = state["out_names"]
            self._ahead.extend(state["ahead"])
            state = state["fmu"]
        self._rpc("set_state", bytes(state) if isinstance(state, bytearray | memoryview) else state)

    def terminate(self) -> None:
        if self.proc.poll() is None:
            try:
                if not self._broken:  # terminate and quit in one round trip
                    self._send("terminate")
                    self._write("terminate", encode_frame(("quit",)))
                    self._quit_sent = True
                    self._recv("terminate")
            finally:
                self.close()

    def close(self) -> None:
        """Stop the worker process (idempotent)."""
        if self._mm is not None:
            self._mm.close()
            self._mm = None
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1
        if self.proc.poll() is None:
            try:
                if not self._broken and not self._quit_sent:
                    send_frame(self._wfd, ("quit",))
                assert self.proc.stdin is not None
                self.proc.stdin.close()
                self.proc.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait()

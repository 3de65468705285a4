"""An FMU participant in a persistent worker process (JSON lines over stdin/stdout), so an FMU
that crashes cannot take the master down: the master gets a :class:`SimulationError` naming
the participant and the call instead."""

from __future__ import annotations

import base64
import json
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from hevsim.cosim.participant import Participant, fmu_file
from hevsim.errors import ConfigError, SimulationError


class WorkerFMUParticipant(Participant):
    """Same behaviour as :class:`hevsim.cosim.participant.FMUParticipant`, in a subprocess."""

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
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "hevsim.cosim._worker"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=None,  # the FMU's own output and its logger lines from log_level up
            text=True,
            bufsize=1,
        )
        try:
            info = self._rpc("open", name=name, fmu=str(self.fmu), parameters=dict(parameters or {}),
                             log_level=log_level, fmu_log=str(fmu_log) if fmu_log else None)  # fmt: skip
        except SimulationError as exc:
            self.close()
            raise ConfigError(str(exc)) from None
        self.inputs, self.outputs = dict(info["inputs"]), dict(info["outputs"])
        self._can_state, self._state_note = bool(info["can_state"]), str(info["state_note"])
        self.types = dict(info["types"])

    @property
    def can_save_state(self) -> bool:
        return self._can_state

    @property
    def state_note(self) -> str:
        return self._state_note

    def _rpc(self, cmd: str, **kw: Any) -> Any:
        proc = self.proc
        if proc.poll() is not None:
            raise SimulationError(
                f"participant {self.name!r}: worker process has exited (code {proc.returncode})."
            )
        try:
            assert proc.stdin is not None and proc.stdout is not None
            proc.stdin.write(json.dumps({"cmd": cmd, **kw}) + "\n")
            proc.stdin.flush()
            line = proc.stdout.readline()
        except (BrokenPipeError, OSError) as exc:
            line = ""
            _ = exc
        if not line:
            code = proc.wait(timeout=10)
            raise SimulationError(
                f"participant {self.name!r}: worker process crashed in {cmd} (exit code {code})."
            )
        rep = json.loads(line)
        if not rep["ok"]:
            raise SimulationError(f"participant {self.name!r}: {cmd} failed: {rep['error']}")
        return rep["result"]

    # Inputs are sent with the next step (or output query): one round trip per step.
    def setup(self, t0: float) -> None:
        self._pending: dict[str, float] = {}
        self._out: dict[str, float] | None = None
        self._rpc("setup", t0=t0)

    def set_inputs(self, values: Mapping[str, float]) -> None:
        unknown = [k for k in values if k not in self.inputs]
        if unknown:
            raise ConfigError(f"participant {self.name!r}: FMU {self.fmu.name} has no input {unknown[0]!r}.")
        self._pending.update(values)
        self._out = None

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        ok, pref, term, t_term, out = self._rpc("step", t=t, h=h, values=self._pending)
        self._pending = {}
        self.terminate_requested = bool(term)
        self.terminate_time = t_term
        self._out = out
        return bool(ok), pref

    def get_outputs(self) -> dict[str, float]:
        if self._out is None:
            if self._pending:
                self._rpc("set", values=self._pending)
                self._pending = {}
            self._out = dict(self._rpc("get"))
        return dict(self._out)

    def get_state(self) -> Any:
        if self._pending:
            self._rpc("set", values=self._pending)
            self._pending = {}
        return base64.b64decode(self._rpc("get_state"))

    def set_state(self, state: Any) -> None:
        self._pending = {}
        self._out = None
        self._rpc("set_state", state=base64.b64encode(bytes(state)).decode())

    def terminate(self) -> None:
        if self.proc.poll() is None:
            try:
                self._rpc("terminate")
            finally:
                self.close()

    def close(self) -> None:
        """Stop the worker process (idempotent)."""
        if self.proc.poll() is None:
            try:
                assert self.proc.stdin is not None
                self.proc.stdin.write(json.dumps({"cmd": "quit"}) + "\n")
                self.proc.stdin.close()
                self.proc.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait()

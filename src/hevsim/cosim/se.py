"""FMI 3.0 Scheduled Execution FMUs as co-simulation participants: :class:`SEParticipant`
activates the FMU's model partitions at the ticks of its input clocks.

In Scheduled Execution the importer is the scheduler: the FMU (instantiated with
``fmi3InstantiateScheduledExecution``) stays in clock activation mode after initialisation, and
each input clock's model partition runs when the importer calls
``fmi3ActivateModelPartition(clock, activation time)``. Between communication points ``t`` and
``t + h`` :meth:`SEParticipant.do_step` runs, in time order and at one time in the order of the
clocks' ``priority`` (smaller first, as the standard's priorities), the partitions of

* **periodic input clocks** (``intervalVariability`` ``constant`` / ``fixed``): ticks at
  ``t0 + shift + k * interval`` from the model description's ``intervalDecimal`` /
  ``shiftDecimal``;
* **triggered input clocks**: at the times given to the participant (``ticks={clock: [t, ..]}``;
  the simulation algorithm triggers them);
* **countdown input clocks**: when a partition calls the FMU's ``clockUpdate`` callback,
  ``fmi3GetIntervalDecimal`` is asked for each countdown clock, and one whose qualifier says the
  interval changed ticks that interval after the activation that announced it.

Output clocks are read with ``fmi3GetClock`` after each activation that called
``clockUpdate``; a tick is logged in :attr:`SEParticipant.clock_log` (time, clock) with every
activation. Ticks in [t, t + h) belong to the step from t (so a run to ``stop`` runs the
ticks before ``stop``). Outputs (the FMU's Int32 / Float64 ... variables, clocked or not) are read
at each communication point: a clocked output has its value since its clock's last tick. The
partitions run one after the other in the calling thread (no preemption: the lock / unlock
preemption callbacks do nothing), so the schedule is deterministic.

Not run: input clocks of other kinds (``tunable``, ``changing``, ``calculated``: refused),
clock connections to or from an SE participant, state save / restore (refused for iteration and
negotiation; checkpoints replay it).
"""

from __future__ import annotations

import heapq
from collections.abc import Mapping, Sequence
from ctypes import CFUNCTYPE, c_void_p
from pathlib import Path
from typing import Any

from hevsim.cosim.participant import FMUParticipant
from hevsim.errors import ConfigError, SimulationError

_PERIODIC = ("constant", "fixed")


class SEParticipant(FMUParticipant):
    """An FMI 3.0 Scheduled Execution FMU (see the module docstring); ``ticks``: the times
    [s] of each triggered input clock (by name)."""

    interface_name = "scheduled execution"
    runs_own_clocks = True

    @staticmethod
    def _interface(md: Any) -> Any:
        return md.scheduledExecution

    def __init__(
        self,
        name: str,
        fmu: str | Path,
        parameters: Mapping[str, Any] | None = None,
        log_level: str = "error",
        fmu_log: str | Path | None = None,
        ticks: Mapping[str, Sequence[float]] | None = None,
    ):
        super().__init__(name, fmu, parameters, log_level, fmu_log)
        self.can_state = False
        self._se_clocks(ticks or {})
        self.clock_log: list[tuple[float, str]] = []
        """(time [s], clock) of every activated input clock and every output clock tick."""

    @property
    def state_note(self) -> str:
        return f"Scheduled Execution FMU {self.fmu.name}: its state is not saved here"

    def _se_clocks(self, ticks: Mapping[str, Sequence[float]]) -> None:
        """The input clocks (with interval, shift, priority from the model description's XML:
        FMPy does not read them) and output clocks."""
        import xml.etree.ElementTree as ET
        import zipfile

        with zipfile.ZipFile(self.fmu) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
        attrs = {str(el.get("name")): el.attrib for el in root.iter("Clock")}
        self._inputs_se: dict[str, tuple[int, str, int]] = {}  # clock -> (vr, kind, priority)
        self._period: dict[str, tuple[float, float]] = {}  # periodic clock -> (interval, shift)
        self._out_clocks: dict[str, int] = {}
        where = f"participant {self.name!r}: FMU {self.fmu.name}"
        for name, a in attrs.items():
            vr = int(a["valueReference"])
            if a.get("causality") == "output":
                self._out_clocks[name] = vr
                continue
            kind = a.get("intervalVariability", "triggered")
            if kind not in (*_PERIODIC, "triggered", "countdown"):
                raise ConfigError(
                    f'{where}: input clock {name!r} has intervalVariability="{kind}"; hevsim runs '
                    'periodic ("constant", "fixed"), "triggered" and "countdown" input clocks.'
                )
            prio = int(a.get("priority", "0"))
            self._inputs_se[name] = (vr, kind, prio)
            if kind in _PERIODIC:
                try:
                    interval = float(a["intervalDecimal"])
                    shift = float(a.get("shiftDecimal", "0"))
                except (KeyError, ValueError):
                    raise ConfigError(
                        f"{where}: periodic input clock {name!r} needs an intervalDecimal > 0 in the "
                        "model description."
                    ) from None
                if not interval > 0:
                    raise ConfigError(f"{where}: clock {name!r}: intervalDecimal {interval!r}; expected > 0.")
                self._period[name] = (interval, shift)
        self._ticks: dict[str, list[float]] = {}
        for name, times in ticks.items():
            if self._inputs_se.get(name, (0, ""))[1] != "triggered":
                valid = sorted(n for n, (_, k, _) in self._inputs_se.items() if k == "triggered")
                raise ConfigError(f"{where}: ticks for {name!r}; triggered input clocks: {valid}.")
            self._ticks[name] = sorted(float(x) for x in times)

    def setup(self, t0: float) -> None:
        from fmpy.fmi3 import (
            FMU3ScheduledExecution,
            fmi3Boolean,
            fmi3InstanceEnvironment,
            fmi3LockPreemptionCallback,
            fmi3LogMessageCallback,
            fmi3UnlockPreemptionCallback,
        )

        ident, logging_on = self._extract()
        self._updated = False

        def clock_update(_env: Any) -> None:
            self._updated = True

        with self._logged():
            sl = self.slave = FMU3ScheduledExecution(
                guid=self.md.guid, unzipDirectory=self._dir, modelIdentifier=ident, instanceName=self.name
            )
            # (FMPy's instantiate passes a clockUpdate that does nothing: ours records the call)
            self._cbs = (
                fmi3LogMessageCallback(lambda env, status, cat, msg: self._on_log(status, cat, msg)),
                CFUNCTYPE(None, c_void_p)(clock_update),
                fmi3LockPreemptionCallback(lambda: None),
                fmi3UnlockPreemptionCallback(lambda: None),
            )
            resources = str(Path(self._dir) / "resources") + "/"
            sl.component = sl.fmi3InstantiateScheduledExecution(
                self.name.encode(), self.md.guid.encode(), resources.encode(), fmi3Boolean(False),
                fmi3Boolean(logging_on), fmi3InstanceEnvironment(), *self._cbs,
            )  # fmt: skip
            if not sl.component:
                raise SimulationError(f"participant {self.name!r}: fmi3InstantiateScheduledExecution failed.")
            sl.enterInitializationMode(startTime=t0)
            self._set_params()
            sl.exitInitializationMode()  # -> clock activation mode
        self.vars.bind(sl)
        self._t0 = float(t0)
        self.terminate_requested = False
        self.clock_log = []
        # the coming activations: (time, priority, order, clock)
        self._queue: list[tuple[float, int, int, str]] = []
        self._n = 0
        for name in self._period:
            self._push(self._next_periodic(name, t0 - 1e300), name)  # the first tick at or after t0
        for name, times in self._ticks.items():
            for tk in times:
                if tk >= t0:
                    self._push(tk, name)

    def _next_periodic(self, name: str, after: float) -> float:
        """The first tick of periodic clock ``name`` after ``after`` [s] (at or after t0)."""
        interval, shift = self._period[name]
        first = self._t0 + shift
        if after < first:
            return first
        k = int((after - first) / interval) + 1
        return first + k * interval

    def _push(self, t: float, clock: str) -> None:
        self._n += 1
        heapq.heappush(self._queue, (t, self._inputs_se[clock][2], self._n, clock))

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        mark = self._log_count
        t_end = t + h
        eps = 1e-9 * max(1.0, abs(t_end))
        try:
            while self._queue and self._queue[0][0] < t_end - eps:
                tk, _, _, clock = heapq.heappop(self._queue)
                vr, kind, _ = self._inputs_se[clock]
                self._updated = False
                self.slave.activateModelPartition(vr, tk)
                self.clock_log.append((tk, clock))
                if kind in _PERIODIC:
                    self._push(self._next_periodic(clock, tk), clock)
                if self._updated:
                    self._clock_update(tk)
        except Exception as exc:
            self._failed = True
            if self._log_count != mark:
                raise self._explained(exc, mark) from exc
            raise
        return True, None

    def _clock_update(self, t: float) -> None:
        """After a partition called clockUpdate at ``t``: the countdown clocks whose interval
        changed tick that interval later; output clocks that ticked are logged."""
        from ctypes import c_double, c_int

        from fmpy.fmi3 import fmi3ValueReference

        for name, (vr, kind, _) in self._inputs_se.items():
            if kind != "countdown":
                continue
            intervals, qualifiers = (c_double * 1)(), (c_int * 1)()
            self.slave.getIntervalDecimal((fmi3ValueReference * 1)(vr), intervals, qualifiers)
            if qualifiers[0] == 2:  # fmi3IntervalChanged
                self._push(t + intervals[0], name)
        if self._out_clocks:
            ticked = self.slave.getClock(list(self._out_clocks.values()))
            for name, on in zip(self._out_clocks, ticked, strict=True):
                if on:
                    self.clock_log.append((t, name))


def has_only_scheduled_execution(md: Any) -> bool:
    """Whether the model description ``md`` offers Scheduled Execution and no other interface."""
    return (
        getattr(md, "scheduledExecution", None) is not None
        and md.coSimulation is None
        and md.modelExchange is None
    )


__all__ = ["SEParticipant", "has_only_scheduled_execution"]

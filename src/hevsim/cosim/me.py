"""Model Exchange FMUs (FMI 2.0 and 3.0) as co-simulation participants: :class:`MEParticipant`
integrates the FMU between communication points.

Solver: SUNDIALS CVODE as FMPy ships it (:mod:`fmpy.sundials`), with FMPy's own wrapper
(``CVodeSolver``): BDF (``solver="cvode-bdf"``, stiff, FMPy's ``simulate_fmu`` default) or Adams
(``"cvode-adams"``, non-stiff), relative tolerance ``rtol`` (default 1e-5, FMPy's) and absolute
tolerances ``rtol`` times the states' nominal values, maximum step ``(stop - start) / 50`` as
FMPy takes it. Chosen over scipy's ``solve_ivp`` because its right-hand side and root
functions are called from C (no Python per internal step of the method itself), its root
finding locates state events on the FMU's event indicators, and it is the solver FMPy's
results come from: the same settings give the same numbers, so the comparison with FMPy is
close (``tests/test_cosim_me.py`` states its tolerances).

Between two communication points ``t`` and ``t + h`` (inputs held, as for a co-simulation
FMU) the loop is FMPy's ``simulateME``: integrate to the earlier of ``t + h`` and the FMU's
next time event; after each solver return call ``completedIntegratorStep`` where the FMU needs
it; on a time event, a state event (a root of an event indicator, located by CVODE's root
finding to its tolerance) or a step event, enter event mode and iterate
``newDiscreteStates`` / ``updateDiscreteStates`` until no discrete state needs an update, then
reinitialise the solver. An input that changed since the last step is an event at ``t``
(the same iteration, then a solver restart). ``terminateSimulation`` from the FMU ends the
run there (as a co-simulation FMU's request).

State: an FMU declaring ``canGetAndSetFMUstate`` and ``canSerializeFMUstate`` saves and
restores its FMU state with the participant's time, next time event and held inputs; a restore
re-initialises CVODE at the restored time (the solver's step-size and order history is not
saved, so after a restore the run equals an uninterrupted one to the solver's tolerance, not
bit for bit). Iteration and step negotiation use it; checkpoints resume an ME participant by
replay (exact) rather than by restoring it (:attr:`MEParticipant.exact_restore`).

Not supported: FMI 3.0 clocks of Model Exchange FMUs.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping
from math import isclose, isfinite
from pathlib import Path
from typing import Any

from hevsim.cosim.participant import FMUParticipant, fmi2_callbacks
from hevsim.errors import ConfigError, SimulationError

SOLVERS = ("cvode-bdf", "cvode-adams")
"""``MEParticipant(solver=...)``: CVODE's BDF (stiff) or Adams (non-stiff) method."""


class _NoInput:
    """FMPy's solver applies its input signals in the root function: here the inputs are
    set by the master and held over the step."""

    def apply(self, time: float, discrete: bool = False, after_event: bool = False) -> None:
        pass


@contextlib.contextmanager
def _method(solver: str) -> Iterator[None]:
    """FMPy's ``CVodeSolver`` creates CVODE with BDF; for ``"cvode-adams"`` create it with
    Adams instead (the wrapper is otherwise the same)."""
    import fmpy.sundials as sundials

    if solver != "cvode-adams":
        yield
        return
    from fmpy.sundials.cvode import CV_ADAMS

    create = sundials.CVodeCreate
    sundials.CVodeCreate = lambda _lmm, ctx: create(CV_ADAMS, ctx)
    try:
        yield
    finally:
        sundials.CVodeCreate = create


class MEParticipant(FMUParticipant):
    """An FMI 2.0 or 3.0 Model Exchange FMU integrated between communication points (see
    the module docstring); inputs, outputs and parameters as :class:`FMUParticipant`'s."""

    interface_name = "model exchange"

    @staticmethod
    def _interface(md: Any) -> Any:
        return md.modelExchange

    def _event_capable(self, md: Any) -> bool:
        """FMI 3.0 Model Exchange always has event mode: its clocks are run (periodic input
        clocks tick as time events, output clocks are read after each event iteration)."""
        return bool(md.fmiVersion.startswith("3"))

    def __init__(
        self,
        name: str,
        fmu: str | Path,
        parameters: Mapping[str, Any] | None = None,
        log_level: str = "error",
        fmu_log: str | Path | None = None,
        solver: str = "cvode-bdf",
        rtol: float = 1e-5,
        max_step_s: float | None = None,
    ):
        super().__init__(name, fmu, parameters, log_level, fmu_log)
        if solver not in SOLVERS:
            raise ConfigError(f"participant {name!r}: solver {solver!r}; valid: {', '.join(SOLVERS)}.")
        if not (isfinite(rtol) and 0 < rtol < 1):
            raise ConfigError(f"participant {name!r}: rtol {rtol!r}; expected a number in (0, 1).")
        if max_step_s is not None and not max_step_s > 0:
            raise ConfigError(f"participant {name!r}: max_step_s {max_step_s!r}; expected > 0.")
        self.solver, self.rtol, self.max_step_s = solver, float(rtol), max_step_s
        # (can_state: the FMU's canGetAndSetFMUstate and canSerializeFMUstate, read by FMUParticipant)
        self._window: tuple[float, float] | None = None
        self._next_event: float | None = None  # the FMU's next time event [s]
        self._held: dict[str, Any] = {}  # the inputs last set
        self.events = 0
        """Events handled (time, state, step and input events) since :meth:`setup`."""

    exact_restore = False
    """A restored state restarts CVODE (its step size and order history are not saved), so the
    run after a restore equals an uninterrupted one only to the solver's tolerance: checkpoints
    replay an ME participant (exactly) instead of restoring it."""

    @property
    def state_note(self) -> str:
        key = "FMUState" if self.fmi3 else "FMUstate"
        return (f'Model Exchange FMU {self.fmu.name} declares canGetAndSet{key}="false" or '
                f'canSerialize{key}="false"')  # fmt: skip

    def get_state(self) -> Any:
        """The FMU's serialised state (FMI get / serialise FMU state, in continuous-time mode
        after a step) with the participant's own: time, next time event, held inputs, events,
        termination request. The integrator is not part of it (see :attr:`exact_restore`)."""
        fmu_state = super().get_state()
        return (fmu_state, self._time, self._next_event, dict(self._held), self._inputs_changed,
                self.events, self.terminate_requested)  # fmt: skip

    def set_state(self, state: Any) -> None:
        """Restore a :meth:`get_state` snapshot and re-initialise CVODE at its time (from the
        restored continuous states and nominals)."""
        fmu_state, t, nxt, held, changed, events, term = state
        super().set_state(fmu_state)
        self._time, self._next_event, self._held = float(t), nxt, dict(held)
        self._inputs_changed, self.events, self.terminate_requested = bool(changed), int(events), bool(term)
        self._set_time(self._time)
        self._solver.reset(self._time)

    def run_window(self, start_s: float, stop_s: float) -> None:
        """The run's start and stop time [s] (the master tells it before :meth:`setup`): the
        solver's maximum step is (stop - start) / 50 unless ``max_step_s`` is given."""
        self._window = (float(start_s), float(stop_s))

    def setup(self, t0: float) -> None:
        ident, logging_on = self._extract()
        with self._logged():
            if self.fmi3:
                from fmpy.fmi3 import FMU3Model

                self.slave = FMU3Model(
                    guid=self.md.guid, unzipDirectory=self._dir, modelIdentifier=ident, instanceName=self.name
                )
                self._log_cb = lambda env, status, cat, msg: self._on_log(status, cat, msg)
                self.slave.instantiate(loggingOn=logging_on, logMessage=self._log_cb)
                self.slave.enterInitializationMode(startTime=t0)
                self._set_params()
                self.slave.exitInitializationMode()
                self._t0 = float(t0)
                self._schedule = self._clock_schedule() if self._periodic else []
                self._pending, self.clock_log, self.clock_ticks = [], [], {}
                eps = 1e-9 * max(1.0, abs(t0))
                self._tick_inputs(t0, [c for c, t1, _ in self._schedule if t1 <= t0 + eps], [])
            else:
                from fmpy.fmi2 import FMU2Model

                self.slave = FMU2Model(
                    guid=self.md.guid, unzipDirectory=self._dir, modelIdentifier=ident, instanceName=self.name
                )
                cb = self._callbacks = fmi2_callbacks(self._on_log)
                self.slave.instantiate(callbacks=cb, loggingOn=logging_on)
                self.slave.setupExperiment(startTime=t0)
                self.slave.enterInitializationMode()
                self._set_params()
                self.slave.exitInitializationMode()
            self._time = float(t0)
            self.events = 0
            self._next_event = None
            self.terminate_requested = False
            if self._iterate_events():  # (the FMU is in event mode after initialisation)
                raise SimulationError(f"FMU {self.fmu.name} requested termination during initialisation.")
            self.slave.enterContinuousTimeMode()
            self._solver = self._make_solver(t0)
        self.vars.bind(self.slave)
        self._raw_calls()
        self._inputs_changed = False
        self._held = {}

    def _raw_calls(self) -> None:
        """setTime and completedIntegratorStep through the FMU's own functions (FMPy's wrappers
        cost microseconds a call, twice per communication step)."""
        from ctypes import byref, c_int

        fns, comp = self.slave._functions, self.slave.component
        v3 = "3" if self.fmi3 else "2"
        set_time, completed = fns[f"fmi{v3}SetTime"], fns[f"fmi{v3}CompletedIntegratorStep"]
        enter, term = c_int(), c_int()
        if self.fmi3:  # (fmi3Boolean is a C bool: a byte)
            from fmpy.fmi3 import fmi3Boolean

            enter, term = fmi3Boolean(), fmi3Boolean()
        args = (comp, 1, byref(enter), byref(term))

        def set_t(t: float) -> None:
            st = set_time(comp, t)
            if st > 1:
                self._status(f"fmi{v3}SetTime", st)

        def done() -> tuple[bool, bool]:
            st = completed(*args)
            if st > 1:
                self._status(f"fmi{v3}CompletedIntegratorStep", st)
            return bool(enter.value), bool(term.value)

        self._set_time, self._completed = set_t, done
        self._needs_step = bool(self.md.modelExchange.needsCompletedIntegratorStep)  # (as FMPy reads it)

    @staticmethod
    def _status(fn: str, status: int) -> None:
        from fmpy.fmi1 import FMICallException

        raise FMICallException(function=fn, status=status)

    def _make_solver(self, t0: float) -> Any:
        from fmpy.sundials import CVodeSolver

        md, m = self.md, self.slave
        if self.max_step_s is not None:
            max_step = self.max_step_s
        elif self._window is not None and self._window[1] > self._window[0]:
            max_step = (self._window[1] - self._window[0]) / 50.0
        else:
            max_step = float("inf")
        with _method(self.solver):
            return CVodeSolver(
                nx=md.numberOfContinuousStates,
                nz=md.numberOfEventIndicators,
                get_x=m.getContinuousStates,
                set_x=m.setContinuousStates,
                get_dx=m.getContinuousStateDerivatives if self.fmi3 else m.getDerivatives,
                get_z=m.getEventIndicators,
                get_nominals=m.getNominalsOfContinuousStates,
                set_time=m.setTime,
                input=_NoInput(),
                startTime=t0,
                maxStep=max_step,
                relativeTolerance=self.rtol,
            )

    def _iterate_events(self) -> bool:
        """The event iteration (the FMU in event mode): update the discrete states until none
        needs it; keeps the next time event. Returns whether the FMU asked to terminate."""
        m = self.slave
        update = m.updateDiscreteStates if self.fmi3 else m.newDiscreteStates
        need, terminate = True, False
        while need and not terminate:
            need, terminate, _, _, defined, t_next = update()
        self._next_event = float(t_next) if defined else None
        if self.clock_outputs:  # output clocks that ticked in this event (fmi3GetClock)
            names = list(self.clock_outputs)
            for c, on in zip(names, self.slave.getClock([self._clock_vr[c] for c in names]), strict=True):
                if on:
                    out = self.vars.get_outputs(self.slave) if self._clocked_outputs[c] else {}
                    self.clock_ticks.setdefault(c, []).append(
                        (self._time, {k: out[k] for k in self._clocked_outputs[c]})
                    )
                    self.clock_log.append((self._time, c))
        return bool(terminate)

    def _event(self, t: float) -> bool:
        """Handle an event at ``t``: event mode, the input clocks ticking at ``t`` activated
        (fmi3SetClock), iteration, continuous-time mode, solver restart. Returns whether the
        FMU asked to terminate."""
        self.events += 1
        self.slave.enterEventMode()
        if self.fmi3 and (self._schedule or self._pending):
            self._tick_due_inputs(t)
        self._time = t
        if self._iterate_events():
            return True
        self.slave.enterContinuousTimeMode()
        self._solver.reset(t)
        return False

    def set_inputs(self, values: Mapping[str, Any]) -> None:
        changed = {k: v for k, v in values.items() if self._held.get(k, _UNSET) != v}
        if changed:
            super().set_inputs(changed)
            self._held.update(changed)
            self._inputs_changed = True

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        mark = self._log_count
        try:
            return self._integrate(t, t + h)
        except Exception as exc:
            self._failed = True
            if self._log_count != mark:
                raise self._explained(exc, mark) from exc
            raise

    def _integrate(self, t: float, t_end: float) -> tuple[bool, float | None]:
        if not isclose(t, self._time, rel_tol=1e-9, abs_tol=1e-12):
            raise SimulationError(
                f"FMU {self.fmu.name} is at t = {self._time!r} s, asked to step from {t!r} s "
                "(a Model Exchange participant goes back only by restoring a saved state)."
            )
        solver, set_time, completed, needs_step = (
            self._solver,
            self._set_time,
            self._completed,
            self._needs_step,
        )
        time = self._time
        self.terminate_requested = False
        ticks = self._ticks_in(time, t_end) if self.fmi3 and (self._schedule or self._pending) else []
        if self.fmi3:
            self.clock_ticks = {}
        if self._inputs_changed:  # inputs changed at t: an event there
            self._inputs_changed = False
            if self._event(time):
                return self._stop(time)
        while not (time > t_end or isclose(time, t_end)):
            t_next = t_end
            nxt = self._next_event
            while ticks and (ticks[0] < time or isclose(ticks[0], time)):
                ticks.pop(0)
            if ticks and (nxt is None or ticks[0] < nxt):  # a clock tick: a time event
                nxt = ticks[0]
            if nxt is not None and t_next > nxt and not isclose(t_next, nxt):
                t_next = nxt
            time_event = nxt is not None and isclose(t_next, nxt)
            state_event, _, time = solver.step(time, t_next)
            set_time(time)
            step_event = False
            if needs_step:
                step_event, terminate = completed()
                if terminate:
                    return self._stop(time)
            if (time_event or state_event or step_event) and self._event(time):
                return self._stop(time)
        self._time = t_end if isclose(time, t_end) else time
        return True, None

    def _stop(self, time: float) -> tuple[bool, float | None]:
        self._time = time
        self.terminate_requested = True
        self.terminate_time = time
        return True, None

    def terminate(self) -> None:
        self._solver = None
        super().terminate()


_UNSET = object()


def participant_class(fmu: str | Path) -> type[FMUParticipant]:
    """:class:`FMUParticipant` for an FMU with a co-simulation interface, else
    :class:`MEParticipant` when it has a model exchange one, else
    :class:`hevsim.cosim.se.SEParticipant` when it has only Scheduled Execution (the FMU is
    read; a file that is not an FMU is left to the participant to report)."""
    from fmpy import read_model_description

    try:
        md = read_model_description(str(fmu))
    except Exception:
        return FMUParticipant
    if md.coSimulation is None and md.modelExchange is not None:
        return MEParticipant
    from hevsim.cosim.se import SEParticipant, has_only_scheduled_execution

    return SEParticipant if has_only_scheduled_execution(md) else FMUParticipant


__all__ = ["SOLVERS", "MEParticipant", "participant_class"]

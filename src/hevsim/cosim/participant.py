"""Co-simulation participants behind one small interface.

Every participant has a ``name``, declared ``inputs`` and ``outputs`` (name -> unit string)
and the calls ``setup(t0)``, ``set_inputs(values)``, ``do_step(t, h) -> (accepted,
preferred_h)``, ``get_outputs()``, ``get_state()`` / ``set_state(state)`` and
``terminate()``. ``terminate_requested`` becomes true when the participant asks to stop early
(an FMU's ``fmi2Terminated`` / ``earlyReturn``).

Implementations: :class:`FunctionParticipant` (any Python step function; tests),
:func:`ode_participant` (an ODE integrated with RK4 sub-steps), :class:`StepperParticipant`
(hevsim's cell / module electro-thermal steppers), :class:`FMUParticipant` (an FMI 2.0 or 3.0
co-simulation FMU through FMPy, in this process) and
:class:`hevsim.cosim.worker.WorkerFMUParticipant` (the same in a worker process).
"""

from __future__ import annotations

import collections
import contextlib
import copy
import math
import sys
import warnings
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from hevsim._pythonfmu_exit import release_pythonfmu_state
from hevsim.cosim.fmi_vars import UNSUPPORTED_WHY, FmuVariables
from hevsim.errors import ConfigError, SimulationError


def store_inputs(p: Participant, store: dict[str, float], values: Mapping[str, float]) -> None:
    """Check ``values`` against ``p.inputs`` and store them (as floats) in ``store``."""
    for k, v in values.items():
        if k not in p.inputs:
            raise ConfigError(f"participant {p.name!r} has no input {k!r}; inputs: {sorted(p.inputs)}.")
        store[k] = float(v)


class PhaseError(SimulationError):
    """A participant failure in the call ``call`` ("set_inputs", "do_step", "get_outputs")
    when that is not the call the master made: a worker process sets the inputs with the
    step or the output query, so its failure names the phase it really failed in."""

    def __init__(self, message: str, call: str):
        super().__init__(message)
        self.call = call


class Participant(ABC):
    """Base class: declares the interface and sensible defaults."""

    name: str = "participant"
    inputs: dict[str, str]
    outputs: dict[str, str]
    terminate_requested: bool = False
    terminate_time: float | None = None
    types: Mapping[str, str] = {}
    """Type class of a variable that is not Real: "Integer", "Enumeration", "Boolean" or
    "String" (:mod:`hevsim.cosim.fmi_vars`); absent: Real."""
    """Where a participant that asked to stop got to [s] (None: the end of the step)."""
    fmi_types: Mapping[str, str] = {}
    """FMI type of an FMU's variable (Float64, Int8, ..): narrowing connections are refused
    (:func:`hevsim.cosim.fmi_vars.narrowing`); absent: not checked."""
    clock_inputs: Mapping[str, str] = {}
    """FMI 3.0 input clocks a clock connection can tick (name -> intervalVariability)."""
    clock_outputs: Mapping[str, str] = {}
    """FMI 3.0 output clocks (name -> intervalVariability); their ticks in the last step are
    ``clock_ticks[name]``: [(time [s], {clocked output: value at the tick})]."""
    clocked_outputs: Mapping[str, str] = {}
    """Output variables clocked by an output clock (name -> clock name)."""
    clocked_inputs: Mapping[str, str] = {}
    """Input variables set only when their clock ticks (name -> clock name): not in
    :attr:`inputs`, delivered with the ticks of their clock (:meth:`deliver_ticks`)."""
    exact_restore: bool = True
    """A restored state continues exactly as the run it was saved from (False: only to a
    tolerance, e.g. a Model Exchange FMU whose integrator restarts): checkpoints replay such
    participants from the start instead of restoring them; iteration and step negotiation
    restore them."""
    deterministic: bool = True
    """Same inputs give the same outputs: a run it cannot checkpoint can be resumed by
    replaying from the start (the replay is compared with the stored results)."""

    @property
    def can_save_state(self) -> bool:
        """Whether :meth:`get_state` / :meth:`set_state` work (iteration, step rejection,
        checkpoints need them)."""
        return type(self).get_state is not Participant.get_state

    @property
    def state_note(self) -> str:
        """Why the participant cannot save its state (for messages)."""
        return "it does not implement get_state / set_state"

    def setup(self, t0: float) -> None:  # noqa: B027 (optional hook: nothing to prepare by default)
        """Prepare to run from ``t0`` [s] (instantiate, initialise)."""

    @abstractmethod
    def set_inputs(self, values: Mapping[str, float]) -> None:
        """Set input values (units as declared in :attr:`inputs`)."""

    @abstractmethod
    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        """Advance from ``t`` by ``h`` [s]; return (accepted, preferred next step [s] or None)."""

    @abstractmethod
    def get_outputs(self) -> dict[str, float]:
        """Current output values (units as declared in :attr:`outputs`)."""

    def get_state(self) -> Any:
        """A picklable snapshot of the complete state (for iteration and checkpoints)."""
        raise SimulationError(f"participant {self.name!r} cannot save its state.")

    def set_state(self, state: Any) -> None:
        """Restore a snapshot made by :meth:`get_state`."""
        raise SimulationError(f"participant {self.name!r} cannot restore a state.")

    def terminate(self) -> None:  # noqa: B027 (optional hook: nothing to release by default)
        """Release resources; the participant is not stepped again."""

    def write_fields(self, out_dir: Path) -> dict[str, Any]:
        """Write what the participant keeps beyond its outputs (fields, pictures) under
        ``out_dir`` after the run; returns a JSON-able summary ({} when there is nothing)."""
        return {}


StepFunction = Callable[[float, float, Any, dict[str, float]], tuple[Any, dict[str, float]]]
"""``step(t, h, state, inputs) -> (new_state, outputs)``; must not mutate ``state``."""


class FunctionParticipant(Participant):
    """A participant defined by a pure Python step function (tests, small models).

    ``preferred_h`` [s] (optional) is reported after every step; ``reject_above_h`` [s]
    makes steps longer than it rejected (to exercise step negotiation).
    """

    def __init__(
        self,
        name: str,
        step: StepFunction,
        state0: Any,
        outputs0: Mapping[str, float],
        inputs: Mapping[str, str],
        outputs: Mapping[str, str] | None = None,
        preferred_h: float | None = None,
        reject_above_h: float | None = None,
    ):
        self.name = name
        self._step = step
        self._state0 = copy.deepcopy(state0)
        self._out0 = dict(outputs0)
        self.inputs = dict(inputs)
        self.outputs = dict(outputs) if outputs is not None else {k: "" for k in outputs0}
        self.preferred_h = preferred_h
        self.reject_above_h = reject_above_h
        self.state: Any = copy.deepcopy(state0)
        self.out = dict(outputs0)
        self.u = {k: 0.0 for k in self.inputs}
        self.terminate_requested = False

    def setup(self, t0: float) -> None:
        self.state, self.out = copy.deepcopy(self._state0), dict(self._out0)

    def set_inputs(self, values: Mapping[str, float]) -> None:
        store_inputs(self, self.u, values)

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        if self.reject_above_h is not None and h > self.reject_above_h * (1 + 1e-12):
            return False, self.reject_above_h
        self.state, out = self._step(t, h, self.state, dict(self.u))
        self.out = {k: float(v) for k, v in out.items()}
        if self.out.pop("terminate", 0.0):
            self.terminate_requested = True
        return True, self.preferred_h

    def get_outputs(self) -> dict[str, float]:
        return dict(self.out)

    def get_state(self) -> Any:
        return copy.deepcopy((self.state, self.out, self.u, self.terminate_requested))

    def set_state(self, state: Any) -> None:
        s, o, u, term = copy.deepcopy(state)
        self.state, self.out, self.u, self.terminate_requested = s, o, u, term


def ode_participant(
    name: str,
    rhs: Callable[[float, np.ndarray, dict[str, float]], np.ndarray],
    x0: Any,
    output: Callable[[np.ndarray, dict[str, float]], dict[str, float]],
    inputs: Mapping[str, str],
    substeps: int = 20,
    **kwargs: Any,
) -> FunctionParticipant:
    """An ODE ``dx/dt = rhs(t, x, u)`` with inputs held constant over a communication step
    (zero-order hold), integrated by ``substeps`` classical RK4 steps; outputs
    ``output(x, u)`` at the end of the step."""
    x0a = np.atleast_1d(np.asarray(x0, float))

    def step(t: float, h: float, x: np.ndarray, u: dict[str, float]) -> tuple[np.ndarray, dict[str, float]]:
        dt = h / substeps
        x = x.copy()
        for i in range(substeps):
            tt = t + i * dt
            k1 = rhs(tt, x, u)
            k2 = rhs(tt + dt / 2, x + dt / 2 * k1, u)
            k3 = rhs(tt + dt / 2, x + dt / 2 * k2, u)
            k4 = rhs(tt + dt, x + dt * k3, u)
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return x, output(x, u)

    u0 = {k: 0.0 for k in inputs}
    return FunctionParticipant(name, step, x0a, output(x0a, u0), inputs, **kwargs)


class StepperParticipant(Participant):
    """hevsim's electro-thermal cell or module (:class:`hevsim.battery.fmu.CellStepper` /
    ``ModuleStepper``) in process: the same interface and variables as its exported FMU.

    Inputs ``current_a`` [A] (or ``power_w`` [W] when ``power_input``) and ``port_temp_k``
    [K]; outputs ``voltage_v``, ``soc``, ``port_heat_w``, ``temp_k``, ``soh``.
    """

    def __init__(
        self,
        name: str,
        params: str | Path = "thesis_table_4_1",
        soc_initial: float = 1.0,
        temp_initial_k: float = 298.15,
        n_series: int = 1,
        n_parallel: int = 1,
        power_input: bool = False,
        **overrides: float,
    ):
        self.name = name
        self._args = (params, soc_initial, temp_initial_k, n_series, n_parallel, overrides)
        self.power_input = power_input
        self.inputs = {
            "power_w" if power_input else "current_a": "W" if power_input else "A",
            "port_temp_k": "K",
        }
        self.outputs = {"voltage_v": "V", "soc": "1", "port_heat_w": "W", "temp_k": "K", "soh": "1"}
        self.u = {"current_a": 0.0, "power_w": 0.0, "port_temp_k": float(temp_initial_k)}
        self.stepper: Any = None
        self.terminate_requested = False

    def setup(self, t0: float) -> None:
        from hevsim.battery.fmu import CellStepper, ModuleStepper
        from hevsim.battery.params import load_cell_parameters

        params, soc, temp, ns, np_, over = self._args
        p = load_cell_parameters(params)
        if ns * np_ > 1:
            self.stepper = ModuleStepper(p, soc, temp, int(ns), int(np_), **over)  # type: ignore[arg-type]
        else:
            self.stepper = CellStepper(p, soc, temp, **over)
        self.current_a = 0.0

    def set_inputs(self, values: Mapping[str, float]) -> None:
        store_inputs(self, self.u, values)

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        from hevsim.battery.fmu import current_for_power

        s = self.stepper
        if self.power_input:
            self.current_a = current_for_power(s, self.u["power_w"], self.u["port_temp_k"], h)
        else:
            self.current_a = self.u["current_a"]
        s.step(self.current_a, self.u["port_temp_k"], h)
        return True, None

    def get_outputs(self) -> dict[str, float]:
        return dict(self.stepper.outputs, current_a=self.current_a)

    def get_state(self) -> Any:
        return {"stepper": self.stepper.get_state(), "u": dict(self.u), "current_a": self.current_a}

    def set_state(self, state: Any) -> None:
        self.stepper.set_state(state["stepper"])
        self.u = dict(state["u"])
        self.current_a = state["current_a"]


class ModuleCellsParticipant(StepperParticipant):
    """hevsim's n_s x n_p module (:class:`hevsim.battery.fmu.ModuleStepper`) in process with a
    thermal port per cell, for coupling cell by cell with a thermal model
    (:class:`hevsim.cosim.fem.FemModuleParticipant`).

    Inputs ``current_a`` [A] (or ``power_w`` [W] when ``power_input``) and
    ``cell<c>_port_temp_k`` [K]; outputs ``voltage_v``, ``current_a``, ``soc`` (mean),
    ``port_heat_w`` (module total), ``temp_k`` (hottest cell), ``soh`` (lowest),
    ``cell<c>_port_heat_w`` [W] (heat into cell c's port, step mean) and ``cell<c>_temp_k``
    [K] (cell c's lumped temperature), c = 0 .. n_s n_p - 1 = series group * n_p + branch.
    """

    def __init__(
        self,
        name: str,
        params: str | Path = "thesis_table_4_1",
        soc_initial: float = 1.0,
        temp_initial_k: float = 298.15,
        n_series: int = 2,
        n_parallel: int = 6,
        power_input: bool = False,
        **overrides: float,
    ):
        super().__init__(
            name, params, soc_initial, temp_initial_k, n_series, n_parallel, power_input, **overrides
        )
        self.n_cells = int(n_series) * int(n_parallel)
        if self.n_cells < 2:
            raise ConfigError(f"participant {name!r}: a per-cell module needs at least 2 cells.")
        self.inputs = {
            "power_w" if power_input else "current_a": "W" if power_input else "A",
            **{f"cell{c}_port_temp_k": "K" for c in range(self.n_cells)},
        }
        self.outputs = {
            "voltage_v": "V", "current_a": "A", "soc": "1", "port_heat_w": "W", "temp_k": "K", "soh": "1",
            **{f"cell{c}_port_heat_w": "W" for c in range(self.n_cells)},
            **{f"cell{c}_temp_k": "K" for c in range(self.n_cells)},
        }  # fmt: skip
        self.u = {"current_a": 0.0, "power_w": 0.0}
        self.u.update({f"cell{c}_port_temp_k": float(temp_initial_k) for c in range(self.n_cells)})

    def port_temps_k(self) -> np.ndarray:
        """The cells' port temperatures [K] held over the step."""
        return np.array([self.u[f"cell{c}_port_temp_k"] for c in range(self.n_cells)])

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        from hevsim.battery.fmu import current_for_power

        s, tp = self.stepper, self.port_temps_k()
        if self.power_input:
            self.current_a = current_for_power(s, self.u["power_w"], tp, h)
        else:
            self.current_a = self.u["current_a"]
        s.step(self.current_a, tp, h)
        return True, None

    def get_outputs(self) -> dict[str, float]:
        from hevsim.battery.kernel import STEMP

        s = self.stepper
        out = dict(s.outputs, current_a=self.current_a)
        temps = s.m.state[:, STEMP]
        for c in range(self.n_cells):
            out[f"cell{c}_port_heat_w"] = float(s.cell_port_heat_w[c])
            out[f"cell{c}_temp_k"] = float(temps[c])
        return out


def fmu_file(name: str, fmu: str | Path) -> Path:
    """The FMU file of participant ``name`` (ConfigError if it does not exist)."""
    path = Path(fmu)
    if not path.is_file():
        raise ConfigError(f"participant {name!r}: FMU file {str(path)!r} does not exist.")
    return path


def fmi2_callbacks(on_log: Any) -> Any:
    """FMI 2.0 callback functions whose logger calls ``on_log(status, category, message)``
    (FMPy's logger proxy formats the variadic message); keep the result alive as long as the
    instance it is given to."""
    from ctypes import byref

    from fmpy.fmi2 import defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
    from fmpy.logging import addLoggerProxy

    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(lambda c, inst, status, cat, msg: on_log(status, cat, msg))
    cb.allocateMemory = defaultCallbacks.allocateMemory
    cb.freeMemory = defaultCallbacks.freeMemory
    addLoggerProxy(byref(cb))
    return cb


class FMUParticipant(Participant):
    """An FMI 2.0 or 3.0 co-simulation FMU driven through FMPy in this process.

    ``parameters`` (name -> value) are set during initialisation. Inputs and outputs are the
    FMU's variables of causality input / output of every type (Real / Float64 / Float32 with
    their declared units, Integer and FMI 3.0 Int8 .. UInt64, Enumeration, Boolean, String;
    FMI 3.0 arrays as one element each, ``a[1]`` ..: :mod:`hevsim.cosim.fmi_vars`). State
    save/restore uses FMI get/set FMU state where the FMU supports it.

    Early termination: an FMI 3.0 step returned with ``terminateSimulation``, or a step
    discarded (``fmi2Discard`` / ``fmi3Discard``) by an FMU that then reports termination
    (FMI 2.0: ``fmi2GetBooleanStatus(fmi2Terminated)``; FMI 3.0: ``terminateSimulation``),
    sets :attr:`terminate_requested` and :attr:`terminate_time` (the last successful time):
    the master records that point and ends the run cleanly. Any other discarded step is
    rejected (the master redoes it with a shorter step: ``lastSuccessfulTime - t`` when the
    FMU got part way, else half). An FMI 3.0 FMU declaring ``hasEventMode`` is instantiated
    with event mode and early return: its events inside a step are handled in event mode
    (:meth:`_do_step3`); others without. Steps are taken with
    ``noSetFMUStatePriorToCurrentPoint = false`` (the master may restore earlier states when
    iterating or rejecting steps).
    """

    def __init__(
        self,
        name: str,
        fmu: str | Path,
        parameters: Mapping[str, Any] | None = None,
        log_level: str = "error",
        fmu_log: str | Path | None = None,
    ):
        from fmpy import read_model_description

        self.name = name
        if log_level not in LOG_LEVELS:
            raise ConfigError(
                f"participant {name!r}: log level {log_level!r}; valid: {', '.join(LOG_LEVELS)}."
            )
        self.log_threshold = LOG_LEVELS[log_level]
        self.fmu_log = Path(fmu_log) if fmu_log else None
        self.log: collections.deque[tuple[int, str]] = collections.deque(maxlen=LOG_KEEP)
        self._log_count = 0
        self.fmu = fmu_file(name, fmu)
        try:
            md = read_model_description(str(self.fmu))
        except Exception as exc:
            raise ConfigError(f"participant {name!r}: {self.fmu} is not a valid FMU ({exc}).") from exc
        if self._interface(md) is None:
            raise ConfigError(f"participant {name!r}: {self.fmu} has no {self.interface_name} interface.")
        self.md = md
        self.fmi3 = md.fmiVersion.startswith("3")
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self._var = {v.name: v for v in md.modelVariables}
        try:
            self.vars = FmuVariables(md, self.fmu.name)
        except ConfigError as exc:
            raise ConfigError(f"participant {name!r}: FMU {self.fmu.name}: {exc}") from None
        self.inputs, self.outputs = self.vars.inputs, self.vars.outputs
        if self._event_capable(md) or self.runs_own_clocks:  # clocks are run: not "unsupported"
            for k in [k for k, t in self.vars.unsupported.items() if t == "Clock"]:
                del self.vars.unsupported[k]
        if self.vars.unsupported:
            warnings.warn(
                f"participant {name!r}: FMU {self.fmu.name}: "
                + "; ".join(
                    f"{typ} variable(s) {sorted(v for v, t in self.vars.unsupported.items() if t == typ)} "
                    f"are not exchanged or recorded ({UNSUPPORTED_WHY.get(typ, 'not supported')})"
                    for typ in sorted(set(self.vars.unsupported.values()))
                ),
                stacklevel=2,
            )
        self._init_clocks(md)
        self.types = {k: t for k, t in self.vars.types.items() if t != "Real"}
        self.fmi_types = dict(self.vars.fmi_types)
        self.parameters = dict(parameters or {})
        for k, val in self.parameters.items():
            if k not in self.vr:
                raise ConfigError(
                    f"participant {name!r}: FMU {self.fmu.name} has no variable {k!r} (parameter)."
                )
            try:
                self.vars.check_parameter(self._var[k], val)
            except ConfigError as exc:
                raise ConfigError(f"participant {name!r}: {exc}") from None
        cs = self._interface(md)
        self.can_state = bool(getattr(cs, "canGetAndSetFMUstate", False)) and bool(
            getattr(cs, "canSerializeFMUstate", False)
        )
        self.slave: Any = None
        self.terminate_requested = False

    interface_name = "co-simulation"
    runs_own_clocks = False
    """The subclass runs the FMU's clocks itself (Scheduled Execution: :mod:`hevsim.cosim.se`)."""

    def _event_capable(self, md: Any) -> bool:
        """Whether the FMU runs in event mode here (FMI 3.0 co-simulation with hasEventMode)."""
        return (
            md.fmiVersion.startswith("3")
            and type(self)._interface is FMUParticipant._interface
            and bool(getattr(md.coSimulation, "hasEventMode", False))
        )

    def _init_clocks(self, md: Any) -> None:
        """The FMU's clocks (FMI 3.0 co-simulation in event mode): periodic input clocks
        (intervalVariability constant / fixed: ticked by this participant at their interval),
        triggered input clocks (ticked through clock connections), output clocks (read with
        fmi3GetClock at every event) and the clocked variables. Anything else is refused."""
        self.clock_inputs, self.clock_outputs, self.clocked_inputs = {}, {}, {}
        self.clocked_outputs = {}
        self._clock_vr: dict[str, int] = {}
        self._clocked_outputs: dict[str, list[str]] = {}  # output clock -> its clocked outputs
        self._periodic: list[tuple[str, int]] = []  # (input clock, value reference)
        self.clock_ticks: dict[str, list[tuple[float, dict[str, Any]]]] = {}
        self._pending: list[tuple[float, str, dict[str, Any]]] = []  # delivered ticks
        self.clock_log: list[tuple[float, str]] = []  # (time, clock) of every tick run
        clocks = [v for v in md.modelVariables if str(v.type) == "Clock"]
        if not clocks or not self._event_capable(md):
            return  # (without event mode clock variables are reported as not exchanged)
        fmu = self.fmu.name
        for v in clocks:
            iv = str(v.intervalVariability or "triggered")
            if v.causality == "input":
                if iv not in ("constant", "fixed", "triggered"):
                    raise ConfigError(
                        f"participant {self.name!r}: FMU {fmu}: input clock {v.name!r} has "
                        f'intervalVariability="{iv}"; hevsim runs input clocks that are periodic '
                        '("constant", "fixed") or "triggered" (through a clock connection).'
                    )
                self.clock_inputs[v.name] = iv
                if iv != "triggered":
                    self._periodic.append((v.name, v.valueReference))
            elif v.causality == "output":
                self.clock_outputs[v.name] = iv
                self._clocked_outputs[v.name] = []
            else:
                continue
            self._clock_vr[v.name] = v.valueReference
        for v in md.modelVariables:
            cl = getattr(v, "clocks", None) or []
            if not cl or v.causality not in ("input", "output") or str(v.type) == "Clock":
                continue  # (a clock's own "clocks": the clocks it depends on, not a clocked value)
            if len(cl) != 1 or v.name not in self.vars.types:
                raise ConfigError(
                    f"participant {self.name!r}: FMU {fmu}: clocked variable {v.name!r} "
                    f"(clocks {[c.name for c in cl]}): hevsim exchanges scalar clocked variables "
                    "of one clock."
                )
            if v.causality == "input":
                self.clocked_inputs[v.name] = cl[0].name
                self.inputs = {k: u for k, u in self.inputs.items() if k != v.name}
            elif cl[0].name in self._clocked_outputs:
                self._clocked_outputs[cl[0].name].append(v.name)
                self.clocked_outputs[v.name] = cl[0].name

    def deliver_ticks(self, clock: str, ticks: list[tuple[float, dict[str, Any]]]) -> None:
        """Ticks of the triggered input clock ``clock`` in the coming step: (time [s], values
        of its clocked inputs) each, run in event mode at that time (by a clock connection)."""
        if clock not in self.clock_inputs:
            raise ConfigError(f"participant {self.name!r} has no input clock {clock!r}.")
        for _, vals in ticks:
            for k in vals:
                if self.clocked_inputs.get(k) != clock:
                    raise ConfigError(
                        f"participant {self.name!r}: {k!r} is not an input clocked by {clock!r}."
                    )
        self._pending = [e for e in self._pending if e[1] != clock]  # (a step redone: anew)
        for tk, vals in ticks:
            self._pending.append((float(tk), clock, dict(vals)))

    @staticmethod
    def _interface(md: Any) -> Any:
        """The interface of the model description this class drives (None: it has none)."""
        return md.coSimulation

    def _extract(self) -> tuple[str, bool]:
        """Unpack the FMU (``self._dir``); its model identifier for this class's interface and
        whether the FMU's own logging is switched on."""
        from fmpy import extract

        self._dir = extract(str(self.fmu))
        logging_on = self.fmu_log is not None or self.log_threshold <= 1
        return self._interface(self.md).modelIdentifier, logging_on

    def setup(self, t0: float) -> None:
        ident, logging_on = self._extract()
        if _jit_guarded_export(Path(self._dir)):
            import numba  # noqa: F401 (keeps the JIT on, see _jit_guarded_export)
        with self._logged():
            if self.fmi3:
                from fmpy.fmi3 import FMU3Slave

                self.slave = FMU3Slave(
                    guid=self.md.guid, unzipDirectory=self._dir, modelIdentifier=ident, instanceName=self.name
                )
                self._log_cb = lambda env, status, cat, msg: self._on_log(status, cat, msg)
                # FMI 3.0 event mode where the FMU has it (its events: early return, event mode)
                self._event_mode = bool(getattr(self.md.coSimulation, "hasEventMode", False))
                self.slave.instantiate(
                    loggingOn=logging_on, logMessage=self._log_cb, eventModeUsed=self._event_mode,
                    earlyReturnAllowed=self._event_mode,
                )  # fmt: skip
                self.slave.enterInitializationMode(startTime=t0)
                self._set_params()
                self.slave.exitInitializationMode()
                self.events = 0
                self._t0 = t0
                self._schedule = self._clock_schedule() if self._periodic else []
                self._pending, self.clock_log = [], []
                if self._event_mode:  # (in event mode after initialisation)
                    first = [c for c, t1, _ in self._schedule if t1 <= t0 + 1e-9 * max(1.0, abs(t0))]
                    self._tick_inputs(t0, first, [])
                    if self._update_discrete_states():
                        raise SimulationError(
                            f"FMU {self.fmu.name} requested termination during initialisation."
                        )
                    self.slave.enterStepMode()
            else:
                from fmpy.fmi2 import FMU2Slave

                self.slave = FMU2Slave(
                    guid=self.md.guid, unzipDirectory=self._dir, modelIdentifier=ident, instanceName=self.name
                )
                cb = self._callbacks = fmi2_callbacks(self._on_log)  # kept alive as long as the instance
                self.slave.instantiate(callbacks=cb, loggingOn=logging_on)
                self._raw_do_step = self.slave._functions["fmi2DoStep"]  # FMPy's wrapper costs ~10 µs
                self.slave.setupExperiment(startTime=t0)
                self.slave.enterInitializationMode()
                self._set_params()
                self.slave.exitInitializationMode()
        self.vars.bind(self.slave)

    # -- the FMI logger: kept for failures, shown from log_level up, all to fmu_log ----------
    def _on_log(self, status: int, category: bytes | str | None, message: bytes | str | None) -> None:
        dec = lambda b: b.decode("utf-8", "replace") if isinstance(b, bytes) else str(b or "")  # noqa: E731
        label = _STATUS_LABELS[status] if 0 <= status < len(_STATUS_LABELS) else str(status)
        line = f"[{label}] {dec(category)}: {dec(message)}"
        self._log_count += 1
        self.log.append((self._log_count, line))
        if self.fmu_log is not None:
            with open(self.fmu_log, "a", encoding="utf-8") as f:
                f.write(f"{self.name} {line}\n")
        if status >= self.log_threshold:
            print(f"FMU {self.name!r} {line}", file=sys.stderr, flush=True)

    def _explained(self, exc: Exception, mark: int) -> SimulationError:
        """``exc`` with the FMU's log messages since message number ``mark``."""
        lines = [line for n, line in self.log if n > mark]
        return SimulationError(f"{exc}; FMU log: " + " | ".join(lines))

    @contextlib.contextmanager
    def _logged(self) -> Iterator[None]:
        """Re-raise a failure with the FMU's log messages since the call began."""
        mark = self._log_count
        try:
            yield
        except Exception as exc:
            if self._log_count == mark:
                raise
            raise self._explained(exc, mark) from exc

    def _set_params(self) -> None:
        for k, v in self.parameters.items():
            try:
                self.vars.set_parameter(self.slave, self._var[k], v)
            except ConfigError as exc:
                raise ConfigError(f"participant {self.name!r}: {exc}") from None

    def set_inputs(self, values: Mapping[str, Any]) -> None:
        mark = self._log_count
        try:
            self.vars.set_inputs(self.slave, values)
        except ConfigError as exc:
            raise ConfigError(f"participant {self.name!r}: {exc}") from None
        except Exception as exc:
            if self._log_count != mark:
                raise self._explained(exc, mark) from exc
            raise

    def real_io(
        self, names: tuple[str, ...], in_values: Any, out_values: Any
    ) -> tuple[Callable[[], None] | None, Callable[[], None] | None]:
        """Calls that set the scalar float64 inputs ``names`` from the ctypes double array
        ``in_values`` and read all outputs into ``out_values``
        (:meth:`hevsim.cosim.fmi_vars.FmuVariables.real_io`: the worker's steps in shared
        memory), failing as :meth:`set_inputs` and :meth:`get_outputs` do."""
        set_call, get_call = self.vars.real_io(self.slave, names, in_values, out_values)
        return self._explaining(set_call), self._explaining(get_call)

    def _explaining(self, call: Callable[[], None] | None) -> Callable[[], None] | None:
        """``call`` re-raising a failure with the FMU's log messages since it began."""
        if call is None:
            return None

        def explained() -> None:
            mark = self._log_count
            try:
                call()
            except Exception as exc:
                if self._log_count != mark:
                    raise self._explained(exc, mark) from exc
                raise

        return explained

    @property
    def can_save_state(self) -> bool:
        return self.can_state

    @property
    def state_note(self) -> str:
        key = "FMUState" if self.fmi3 else "FMUstate"
        return f'FMU {self.fmu.name} declares canGetAndSet{key}="false" or canSerialize{key}="false"'

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        mark = self._log_count
        try:
            if self.fmi3:
                return self._do_step3(t, h)
            return self._do_step2(t, h)
        except Exception as exc:
            self._failed = True
            if self._log_count != mark:
                raise self._explained(exc, mark) from exc
            raise

    def _do_step2(self, t: float, h: float) -> tuple[bool, float | None]:
        """fmi2DoStep; on fmi2Discard ask fmi2GetBooleanStatus(fmi2Terminated): a terminated
        FMU ends the run at fmi2LastSuccessfulTime (as FMPy does), otherwise the step is
        rejected (the master redoes it shorter where it can restore states)."""
        status = self._raw_do_step(self.slave.component, t, h, 1)  # noSetFMUStatePriorTo.. = true
        if status <= 1:  # fmi2OK, fmi2Warning
            self.terminate_requested = False
            return True, None
        from fmpy.fmi1 import FMICallException  # (imported here: not on the per-step path)
        from fmpy.fmi2 import fmi2Discard, fmi2LastSuccessfulTime, fmi2Terminated

        if status != fmi2Discard:
            raise FMICallException(function="fmi2DoStep", status=status)
        try:
            terminated = bool(self.slave.getBooleanStatus(fmi2Terminated))
        except FMICallException:
            terminated = False
        last: float | None = None
        try:
            last = float(self.slave.getRealStatus(fmi2LastSuccessfulTime))
        except FMICallException:
            pass
        if terminated:
            self.terminate_requested = True
            self.terminate_time = last if last is not None and t <= last <= t + h else t + h
            return True, None
        self.terminate_requested = False
        return False, (last - t if last is not None and t < last < t + h else None)

    def _update_discrete_states(self) -> bool:
        """The event iteration of an FMI 3.0 FMU in event mode (``fmi3UpdateDiscreteStates``
        until no discrete state needs an update); returns whether it asked to terminate."""
        need, terminate = True, False
        while need and not terminate:
            need, terminate, *_ = self.slave.updateDiscreteStates()
        return bool(terminate)

    def _clock_schedule(self) -> list[tuple[str, float, float]]:
        """(clock, first tick [s], interval [s]) of each periodic input clock: interval and
        shift from the model description (intervalDecimal, shiftDecimal), else the interval
        from fmi3GetIntervalDecimal (after initialisation) and no shift."""
        import zipfile

        from hevsim.cosim._xml import local_name, number, parse_xml

        with zipfile.ZipFile(self.fmu) as z:
            root = parse_xml(self.fmu, z.read("modelDescription.xml"))
        attrs = {el.get("name"): el.attrib for el in root.iter() if local_name(el.tag) == "Clock"}
        out = []
        for name, vr in self._periodic:
            a = attrs.get(name, {})
            where = f"{self.fmu.name}: clock {name!r}"
            interval = (
                number(a["intervalDecimal"], f"{where} intervalDecimal") if "intervalDecimal" in a else None
            )
            if interval is None:
                from ctypes import c_double, c_int

                from fmpy.fmi3 import fmi3ValueReference

                iv, q = (c_double * 1)(), (c_int * 1)()
                self.slave.getIntervalDecimal((fmi3ValueReference * 1)(vr), iv, q)
                interval = float(iv[0]) if q[0] != 0 else None  # 0: fmi3IntervalNotYetKnown
            if interval is None or not interval > 0 or not math.isfinite(interval):
                raise ConfigError(
                    f"participant {self.name!r}: {where}: interval {interval!r}; a periodic input "
                    "clock needs an intervalDecimal > 0 (model description or fmi3GetIntervalDecimal)."
                )
            shift = number(a["shiftDecimal"], f"{where} shiftDecimal") if "shiftDecimal" in a else 0.0
            out.append((name, self._t0 + shift, interval))
        return out

    def _ticks_in(self, t0: float, t1: float) -> list[float]:
        """Times of the clock ticks (periodic and delivered) in (t0, t1] [s], ascending."""
        eps = 1e-9 * max(1.0, abs(t1))
        times = [tk for tk, _, _ in self._pending if t0 + eps < tk <= t1 + eps]
        for _, first, dt in self._schedule:
            k = max(0, math.ceil((t0 + eps - first) / dt))
            while first + k * dt <= t1 + eps:
                if first + k * dt > t0 + eps:
                    times.append(first + k * dt)
                k += 1
        out: list[float] = []
        for tk in sorted(times):
            if not out or tk - out[-1] > eps:
                out.append(tk)
        return out

    def _tick_inputs(
        self, t: float, periodic: list[str], delivered: list[tuple[str, dict[str, Any]]]
    ) -> None:
        """In event mode at ``t``: activate the input clocks ticking now (fmi3SetClock) and set
        the clocked inputs they bring (the FMU deactivates them in fmi3UpdateDiscreteStates)."""
        names = list(dict.fromkeys([*periodic, *(c for c, _ in delivered)]))
        if not names:
            return
        self.slave.setClock([self._clock_vr[c] for c in names], [True] * len(names))
        for c in names:
            self.clock_log.append((t, c))
        for _, vals in delivered:
            if vals:
                self.vars.set_inputs(self.slave, vals)

    def _event(self, t: float) -> bool:
        """Event mode at ``t`` (the FMU entered it): read the output clocks (fmi3GetClock) and
        the clocked outputs of those ticking, tick the input clocks due at ``t``, run the
        event iteration; returns whether the FMU asked to terminate."""
        if self.clock_outputs:
            names = list(self.clock_outputs)
            active = self.slave.getClock([self._clock_vr[c] for c in names])
            for c, on in zip(names, active, strict=True):
                if on:
                    out = self.vars.get_outputs(self.slave) if self._clocked_outputs[c] else {}
                    vals = {k: out[k] for k in self._clocked_outputs[c]}
                    self.clock_ticks.setdefault(c, []).append((t, vals))
                    self.clock_log.append((t, c))
        self._tick_due_inputs(t)
        return self._update_discrete_states()

    def _tick_due_inputs(self, t: float) -> None:
        """Tick the input clocks due at ``t`` (to 1e-9 relative): the periodic ones whose
        schedule lands on ``t`` and the pending triggered ticks (removed once delivered)."""
        eps = 1e-9 * max(1.0, abs(t))
        periodic = [
            c for c, first, dt in self._schedule
            if t >= first - eps and abs(t - first - round((t - first) / dt) * dt) <= eps
        ]  # fmt: skip
        due = [(c, v) for tk, c, v in self._pending if abs(tk - t) <= eps]
        self._pending = [e for e in self._pending if abs(e[0] - t) > eps]
        self._tick_inputs(t, periodic, due)

    def _do_step3(self, t: float, h: float) -> tuple[bool, float | None]:
        """The communication step from ``t`` by ``h`` of an FMI 3.0 FMU: with event mode (the
        FMU has it), an early return at an event (``eventHandlingNeeded``) is followed by the
        event iteration in event mode and the rest of the step, as often as the FMU returns
        early (:attr:`events` counts them), so the master sees the step end as without events.
        Clock ticks in the step (periodic input clocks, ticks delivered by clock connections)
        end sub-steps there: event mode, the clocks activated (:meth:`_event`)."""
        t_end, t_cur = t + h, t
        ticks: list[float] = []
        if self._event_mode:
            self.clock_ticks = {}
            ticks = self._ticks_in(t, t_end)
        while True:
            while ticks and ticks[0] <= t_cur + 1e-9 * max(1.0, abs(t_cur)):
                ticks.pop(0)
            t_stop = ticks[0] if ticks else t_end
            ok, pref, event, early, reached = self._do_step3_once(t_cur, t_stop - t_cur)
            if not ok or self.terminate_requested:
                return ok, pref
            at_tick = bool(ticks) and (
                not early or math.isclose(reached, t_stop, rel_tol=1e-12, abs_tol=1e-12)
            )
            if self._event_mode and (event or at_tick):
                self.events += 1
                self.slave.enterEventMode()
                if self._event(reached):
                    self.terminate_requested, self.terminate_time = True, reached
                    return True, None
                self.slave.enterStepMode()
            if t_stop < t_end and not early:
                t_cur = t_stop
                continue
            if not early or reached >= t_end or math.isclose(reached, t_end):
                return True, None
            if not reached > t_cur:
                raise SimulationError(
                    f"FMU {self.fmu.name} returned early at t = {reached!r} s, not after {t_cur!r} s."
                )
            t_cur = reached

    def _do_step3_once(self, t: float, h: float) -> tuple[bool, float | None, bool, bool, float]:
        """fmi3DoStep with its status and out-arguments (FMPy's ``doStep`` raises on
        fmi3Discard before returning them, and defaults noSetFMUStatePriorToCurrentPoint to
        true): (accepted, preferred step, eventHandlingNeeded, earlyReturn, lastSuccessfulTime)."""
        from ctypes import byref

        from fmpy.fmi1 import FMICallException
        from fmpy.fmi3 import fmi3Boolean, fmi3Discard, fmi3Float64

        event, term, early, last = fmi3Boolean(), fmi3Boolean(), fmi3Boolean(), fmi3Float64()
        discarded = False
        try:
            self.slave.fmi3DoStep(
                self.slave.component,
                t,
                h,
                fmi3Boolean(False),
                byref(event),
                byref(term),
                byref(early),
                byref(last),
            )
        except FMICallException as exc:
            if exc.status != fmi3Discard:
                raise
            discarded = True
        lt = float(last.value)
        if discarded:
            if term.value:  # stop where it got to, as an FMI 2.0 discard + fmi2Terminated
                self.terminate_requested = True
                self.terminate_time = lt if t <= lt <= t + h else t
                return True, None, False, False, lt
            self.terminate_requested = False
            return False, (lt - t if t < lt < t + h else None), False, False, lt
        # per step: a request from a step the master then redid (restored state) is void
        self.terminate_requested = bool(term.value)
        if not term.value and early.value and not self._event_mode:  # not allowed: non-conforming
            raise SimulationError(
                f"FMU {self.fmu.name} returned early at t = {last.value:g} s although early return "
                "was not allowed."
            )
        return True, None, bool(event.value), bool(early.value), (lt if early.value else t + h)

    def get_outputs(self) -> dict[str, Any]:
        mark = self._log_count
        try:
            return self.vars.get_outputs(self.slave)
        except Exception as exc:
            if self._log_count != mark:
                raise self._explained(exc, mark) from exc
            raise

    def get_state(self) -> Any:
        if not self.can_state:
            raise SimulationError(f"participant {self.name!r}: FMU {self.fmu.name} cannot get/set its state.")
        sl = self.slave
        if self.fmi3:
            st = sl.getFMUState()
            data = bytes(sl.serializeFMUState(st))
            sl.freeFMUState(st)
        else:
            st = sl.getFMUstate()
            data = bytes(sl.serializeFMUstate(st))
            sl.freeFMUstate(st)
        return data

    def set_state(self, state: Any) -> None:
        if not self.can_state:
            raise SimulationError(f"participant {self.name!r}: FMU {self.fmu.name} cannot get/set its state.")
        sl = self.slave
        if self.fmi3:
            st = sl.deserializeFMUState(state)
            sl.setFMUState(st)
            sl.freeFMUState(st)
        else:
            st = sl.deSerializeFMUstate(state)
            sl.setFMUstate(st)
            sl.freeFMUstate(st)

    def terminate(self) -> None:
        if self.slave is None:
            return
        if getattr(self, "_failed", False):
            # An FMU in the error state may crash when freed or unloaded: keep it alive and
            # untouched (run failing FMUs in a worker process to reclaim the memory).
            _FAILED_INSTANCES.append(self.slave)
        else:
            self.slave.terminate()
            # Free the instance but keep the shared library loaded (FMPy's freeInstance also
            # dlcloses it): the interpreter keeps the model module a pythonfmu FMU imported.
            sl = self.slave
            (sl.fmi3FreeInstance if self.fmi3 else sl.fmi2FreeInstance)(sl.component)
            _LOADED_LIBRARIES.append(sl)
        release_pythonfmu_state(self.slave.dll)  # see hevsim._pythonfmu_exit
        self.slave = None


def _jit_guarded_export(unzipped: Path) -> bool:
    """Whether the FMU extracted to ``unzipped`` is a pythonfmu FMU from an hevsim that
    guarded its exit abort by importing numba with the JIT off when the host had not imported
    numba yet (which leaves every numba function of the process uncompiled). The abort's real
    cause is fixed by :mod:`hevsim._pythonfmu_exit`; importing numba before such an FMU keeps
    the JIT on."""
    module = unzipped / "resources" / "slavemodule.txt"
    if not module.is_file() or "numba" in sys.modules:
        return False
    script = module.with_name(module.read_text(encoding="utf-8").strip() + ".py")
    text = script.read_text(encoding="utf-8", errors="replace") if script.is_file() else ""
    return "NUMBA_DISABLE_JIT" in text


_FAILED_INSTANCES: list[Any] = []
_LOADED_LIBRARIES: list[Any] = []  # freed instances whose FMU libraries stay loaded

LOG_LEVELS = {"all": 0, "warning": 1, "discard": 2, "error": 3, "fatal": 4, "none": 99}
"""``log_level``: FMU log messages of at least this status are printed to stderr."""
LOG_KEEP = 50
"""FMU log messages kept to explain a failure."""
_STATUS_LABELS = ("OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING")

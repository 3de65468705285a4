"""FMI 2.0 co-simulation FMU of an electro-thermal cell (thesis section 4.2), via pythonfmu.

The FMU wraps the same compiled step (:func:`hevsim.battery.kernel.cell_step`) as
:class:`hevsim.battery.Cell`, so an FMI master reproduces the in-process model exactly.

Interface: inputs ``current_a`` [A, discharge > 0] (or ``power_w`` [W] with ``power_input``)
and ``port_temp_k`` [K]; outputs
``voltage_v`` [V], ``soc`` [-], ``port_heat_w`` [W, heat flow into the port], ``temp_k``
[K, core] and ``soh`` [-] (SOH_C of eq 43 from the capacity at the reference temperature, so
1 for a new cell at any temperature; the impedance factor of eq 44 is 1 because the
cell's impedance does not age within a run); parameters ``power_input`` (Boolean),
``soc_initial``, ``temp_initial_k`` and the scalars of :data:`FMU_PARAMETERS`. With
``power_input`` the solved current is readable as ``current_a`` (an input variable, so
``fmi2GetReal`` returns it after each step); the output ``terminal_current_a`` [A] is the
current drawn over the last step either way (connectable, recorded by masters).

A module FMU (n_s x n_p > 1 cells, cell c = series group * n_p + branch) has in addition, with
the names of :class:`hevsim.cosim.participant.ModuleCellsParticipant`: inputs
``cell<c>_port_temp_k`` [K], outputs ``cell<c>_port_heat_w`` [W, heat into cell c's port, step
mean] and ``cell<c>_temp_k`` [K, cell c's lumped temperature], and the Boolean parameter
``per_cell_ports`` (default false): when true cell c's port temperature is
``cell<c>_port_temp_k``, otherwise every cell's is ``port_temp_k``. Its lumped outputs are the
module voltage, the mean SOC, the total port heat, the hottest cell's temperature and the
lowest SOH.

Units: ``modelDescription.xml`` declares ``UnitDefinitions`` and the unit of every Real
variable whose name ends in a unit suffix (:data:`UNIT_SUFFIXES`; ``_k`` K, ``_w`` W, ``_v``
V, ``_a`` A, ...), so a master converts units on connections. FMU state: the FMU can get, set
and serialise its complete state (``canGetAndSetFMUstate``, ``canSerializeFMUstate``), for
iteration and checkpoints of co-simulations.

Run-time needs: a host process with CPython loaded (FMPy and other Python-based masters; a C
master must preload libpython) in which ``hevsim`` is importable. The FMU carries Linux and
Windows binaries (pythonfmu's). Its model module is named after the FMU, so two FMUs of
different names can share a process.

Exit of the host: pythonfmu 0.7's binary releases its interpreter handle twice when it is still
loaded at process exit (a C++ static destructor, then its ``__attribute__((destructor))``
function), a write into freed heap memory that makes some hosts abort after the results are
written ("corrupted double-linked list"). The model releases the handle when the host's Python
finalises and ``hevsim cosim`` right after freeing the instance
(:mod:`hevsim._pythonfmu_exit`). FMUs exported by earlier versions switched numba's JIT off
in hosts that had not imported numba, a guard against the same abort; ``hevsim cosim``
imports numba before loading one, so their kernels stay compiled.
"""

from __future__ import annotations

import os
import re
import tempfile
import zipfile
from functools import partial
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from hevsim._pythonfmu_exit import release_at_exit
from hevsim.battery import kernel as K
from hevsim.battery.ageing import soh_of_state
from hevsim.battery.cell import check_cell_domain
from hevsim.battery.params import CellParameters, load_cell_parameters, parameters_from_dict
from hevsim.errors import ConfigError, DomainError

FMU_PARAMETERS = K.TUNABLE_SCALARS
"""FMU parameter name -> index in the cell parameter vector (the calibration's scalars)."""

OUTPUTS = ("voltage_v", "soc", "port_heat_w", "temp_k", "soh")
INPUTS = ("current_a", "power_w", "port_temp_k")
"""``power_w`` [W, discharge > 0] is used instead of ``current_a`` when the Boolean
parameter ``power_input`` is true."""

CELL_INPUTS = ("cell{c}_port_temp_k",)
CELL_OUTPUTS = ("cell{c}_port_heat_w", "cell{c}_temp_k")
"""Per-cell variables of a module FMU (``c`` = cell index), used when ``per_cell_ports``."""

UNIT_SUFFIXES = (
    ("_j_per_k", "J/K"),
    ("_k_per_w", "K/W"),
    ("_per_k", "1/K"),
    ("_k", "K"),
    ("_w", "W"),
    ("_v", "V"),
    ("_a", "A"),
    ("_c", "C"),
)
"""Variable-name suffix -> unit declared in the model description (first match wins)."""

UNIT_EXPONENTS = {
    "J/K": {"kg": 1, "m": 2, "s": -2, "K": -1},
    "K/W": {"kg": -1, "m": -2, "s": 3, "K": 1},
    "1/K": {"K": -1},
    "K": {"K": 1},
    "W": {"kg": 1, "m": 2, "s": -3},
    "V": {"kg": 1, "m": 2, "s": -3, "A": -1},
    "A": {"A": 1},
    "C": {"s": 1, "A": 1},
}
"""SI base-unit exponents (FMI ``BaseUnit`` attributes) of the declared units."""


def current_for_power(stepper: Any, power_w: float, port_temp_k: float | np.ndarray, dt_s: float) -> float:
    """Current [A] whose step-average terminal power equals ``power_w`` [W] (secant method on
    trial steps that leave the stepper's state untouched; the relation is affine in the
    current for a fixed direction, so it converges in a few iterations)."""
    if power_w == 0.0:
        return 0.0

    def residual(i: float) -> float:
        return stepper.trial_voltage(i, port_temp_k, dt_s) * i - power_w

    i0 = power_w / max(stepper.outputs["voltage_v"], 1e-6)
    i1 = i0 * 1.01
    f0, f1 = residual(i0), residual(i1)
    for _ in range(30):
        if f1 == f0 or abs(f1) <= 1e-12 * abs(power_w):
            break
        i0, i1 = i1, i1 - f1 * (i1 - i0) / (f1 - f0)
        f0, f1 = f1, residual(i1)
    return i1


class CellStepper:
    """The cell state advanced one communication step at a time (what the FMU runs)."""

    def __init__(self, params: CellParameters, soc_initial: float, temp_k: float, **overrides: float):
        self.params = params
        self.p = params.vector(soc_initial)
        for name, value in overrides.items():
            self.p[FMU_PARAMETERS[name]] = value
        self.x = params.initial_state(temp_k)
        self.tabs = params.tables()
        self.rec = np.zeros(len(K.RECORD))
        soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d = self.tabs[:6]
        ocv, _ = K.cell_ocv_rs(self.p, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, soc_initial, temp_k, 1.0)
        self.outputs = {"voltage_v": ocv, "soc": soc_initial, "port_heat_w": 0.0, "temp_k": temp_k}
        self.outputs["soh"] = self._soh()
        self.time_s = 0.0  # the time stepped so far [s] (for messages)

    def _soh(self) -> float:
        """SOH_C (eq 43) at the reference temperature: 1 for a new cell at any temperature."""
        return float(soh_of_state(self.p, self.x[K.SQABS], self.p[K.C0], self.params.ageing.x_c))

    def trial_voltage(self, current_a: float, port_temp_k: float, dt_s: float) -> float:
        """Step-average terminal voltage [V] of a step at ``current_a``, state unchanged."""
        rec = np.zeros(len(K.RECORD))
        K.cell_step(self.p, *self.tabs, self.x.copy(), current_a, dt_s, port_temp_k, rec)  # type: ignore[call-arg]
        return float(rec[K.RVAVG])

    def step(self, current_a: float, port_temp_k: float, dt_s: float) -> dict[str, float]:
        """Advance by ``dt_s`` [s] at constant current [A] and port temperature [K].

        Raises :class:`~hevsim.errors.DomainError` (state unchanged) for a step that leaves
        the cell's domain (:func:`hevsim.battery.cell.check_cell_domain`)."""
        r = np.zeros(len(K.RECORD))
        x = self.x.copy()
        K.cell_step(self.p, *self.tabs, x, current_a, dt_s, port_temp_k, r)  # type: ignore[call-arg]
        with np.errstate(divide="ignore", invalid="ignore"):
            i_short = r[K.ROCV] / r[K.RRS]
        one = np.ones(1)
        check_cell_domain(f"cell {self.params.name}", one * (self.time_s + dt_s), one * current_a,
                          one * r[K.RV], one * r[K.RTEMP], one * r[K.RCAP], one * i_short,
                          soc=one * r[K.RSOC])  # fmt: skip
        self.x[:] = x
        self.rec[:] = r
        self.time_s += dt_s
        self.outputs = {
            "voltage_v": float(r[K.RV]),
            "soc": float(r[K.RSOC]),
            "port_heat_w": float(r[K.RPORT]),
            "temp_k": float(r[K.RTEMP]),
            "soh": self._soh(),
        }
        return self.outputs

    def get_state(self) -> dict[str, Any]:
        """The complete mutable state as JSON-able lists and floats (a copy)."""
        return {
            "p": self.p.tolist(),
            "x": self.x.tolist(),
            "rec": self.rec.tolist(),
            "outputs": dict(self.outputs),
            "time_s": self.time_s,
        }

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a state made by :meth:`get_state` (bit-identical continuation)."""
        self.p[:] = state["p"]
        self.x[:] = state["x"]
        self.rec[:] = state["rec"]
        self.outputs = {k: float(v) for k, v in state["outputs"].items()}
        self.time_s = float(state.get("time_s", 0.0))


class ModuleStepper:
    """An n_s x n_p module (:class:`hevsim.battery.Module`) advanced one step at a time.

    Outputs: module terminal voltage, mean cell SOC, heat into the ports, the hottest cell's
    core temperature and the lowest cell SOH.
    """

    def __init__(
        self,
        params: CellParameters,
        soc_initial: float,
        temp_k: float,
        n_series: int,
        n_parallel: int,
        capacity_spread: float = 0.0,
        resistance_spread: float = 0.0,
        seed: int = 0,
        **overrides: float,
    ):
        from hevsim.battery.module import Module

        self.params = params
        self.m = Module(
            params, n_series, n_parallel, soc_initial, temp_k, capacity_spread, resistance_spread, seed
        )
        for name, value in overrides.items():
            scale = {"c0_c": self.m.c0_scale, "r_scale": self.m.r_scale}.get(name, 1.0)
            self.m.p[:, FMU_PARAMETERS[name]] = value * scale
        self.tabs = params.tables()
        n = self.m.n_cells
        self.out_m = np.zeros((1, 4))
        self.out_c = np.zeros((1, n, 4))
        self.cell_port_heat_w = np.zeros(n)
        soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, _ = self.tabs[:7]
        ocv, _ = K.cell_ocv_rs(self.m.p[0], soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, soc_initial, temp_k, 1.0)
        self.outputs = {
            "voltage_v": n_series * ocv,
            "soc": soc_initial,
            "port_heat_w": 0.0,
            "temp_k": temp_k,
            "soh": self._soh(),
        }
        self.time_s = 0.0  # the time stepped so far [s] (for messages)

    def _soh(self) -> float:
        """Lowest SOH_C (eq 43) of the cells, at the reference temperature (1 when new)."""
        x, p = self.m.state, self.m.p
        return float(np.min(soh_of_state(p, x[:, K.SQABS], p[:, K.C0], self.params.ageing.x_c)))

    def trial_voltage(self, current_a: float, port_temp_k: float | np.ndarray, dt_s: float) -> float:
        """Step-average module voltage [V] of a step at ``current_a``, state unchanged
        (``port_temp_k``: one port temperature [K] or one per cell)."""
        m = self.m
        out_m, out_c = np.zeros((1, 4)), np.zeros((1, m.n_cells, 4))
        K.run_module(  # type: ignore[call-arg]
            m.p, *self.tabs, m.state.copy(), m.n_series, m.n_parallel, np.array([current_a]), dt_s,
            np.full((1, m.n_cells), port_temp_k), out_m, out_c,
        )  # fmt: skip
        return float(out_m[0, 1])

    def step(self, current_a: float, port_temp_k: float | np.ndarray, dt_s: float) -> dict[str, float]:
        """Advance by ``dt_s`` [s] at constant module current [A] and port temperature [K]
        (one for all cells or one per cell, cell c = series group * n_parallel + branch).

        Also sets :attr:`cell_port_heat_w`: each cell's step-mean heat into its port [W]
        (generated heat minus the change of its stored heat; they sum to ``port_heat_w``)."""
        m = self.m
        tp = np.full((1, m.n_cells), port_temp_k)
        temp0 = m.state[:, K.STEMP].copy()
        x, out_m, out_c = m.state.copy(), np.zeros_like(self.out_m), np.zeros_like(self.out_c)
        K.run_module(  # type: ignore[call-arg]
            m.p, *self.tabs, x, m.n_series, m.n_parallel, np.array([current_a]), dt_s, tp, out_m, out_c,
        )  # fmt: skip
        one = np.ones(1)
        check_cell_domain(f"{m.n_series}s{m.n_parallel}p module of {self.params.name}",
                          one * (self.time_s + dt_s), one * current_a, out_m[:, 0], out_c[:, :, 2],
                          soc=out_c[:, :, 1])  # fmt: skip
        m.state[:] = x
        self.out_m[:], self.out_c[:] = out_m, out_c
        self.time_s += dt_s
        stored = m.p[:, K.CHEAT] * (m.state[:, K.STEMP] - temp0)
        self.cell_port_heat_w = self.out_c[0, :, 3] - stored / dt_s
        self.outputs = {
            "voltage_v": float(self.out_m[0, 0]),
            "soc": float(self.out_c[0, :, 1].mean()),
            "port_heat_w": float(self.out_m[0, 3]),
            "temp_k": float(self.out_c[0, :, 2].max()),
            "soh": self._soh(),
        }
        return self.outputs

    def get_state(self) -> dict[str, Any]:
        """The complete mutable state as JSON-able lists and floats (a copy)."""
        return {
            "p": self.m.p.tolist(),
            "x": self.m.state.tolist(),
            "out_m": self.out_m.tolist(),
            "out_c": self.out_c.tolist(),
            "cell_port_heat_w": self.cell_port_heat_w.tolist(),
            "outputs": dict(self.outputs),
            "time_s": self.time_s,
        }

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a state made by :meth:`get_state` (bit-identical continuation)."""
        self.m.p[:] = state["p"]
        self.m.state[:] = state["x"]
        self.out_m[:] = state["out_m"]
        self.out_c[:] = state["out_c"]
        self.cell_port_heat_w = np.array(state["cell_port_heat_w"], dtype=float)
        self.outputs = {k: float(v) for k, v in state["outputs"].items()}
        self.time_s = float(state.get("time_s", 0.0))


class CellSlaveMixin:
    """FMU behaviour, mixed into the generated ``pythonfmu.Fmi2Slave`` subclass.

    The generated class sets :attr:`PARAMETERS_TOML` (the embedded cell parameter file) and
    :attr:`DEFAULTS` (``soc_initial``, ``temp_initial_k``; for a module also ``n_series``,
    ``n_parallel``, ``capacity_spread``, ``resistance_spread``, ``seed``).
    """

    PARAMETERS_TOML = ""
    DEFAULTS: ClassVar[dict[str, Any]] = {}
    _STEPPER_KEY = "__hevsim_stepper__"

    def __init__(self, **kwargs: Any) -> None:
        import tomllib

        from pythonfmu import Boolean, Fmi2Causality, Fmi2Variability, Real
        from pythonfmu.enums import Fmi2Initial

        super().__init__(**kwargs)
        release_at_exit(self.resources, type(self).__name__)  # type: ignore[attr-defined]
        self._params = parameters_from_dict(tomllib.loads(self.PARAMETERS_TOML), "<FMU parameters>")
        self.description = f"hevsim electro-thermal cell '{self._params.name}' (thesis eqs 33-44)"
        self.author = "hevsim"
        self.current_a = 0.0
        self.power_w = 0.0
        self.power_input = False
        self.per_cell_ports = False
        self.soc_initial = float(self.DEFAULTS["soc_initial"])
        self.temp_initial_k = float(self.DEFAULTS["temp_initial_k"])
        self.port_temp_k = self.temp_initial_k
        self._n_cells = int(self.DEFAULTS.get("n_series", 1)) * int(self.DEFAULTS.get("n_parallel", 1))
        self._cell_port_temp_k = np.full(self._n_cells, self.temp_initial_k)
        vec = self._params.vector(self.soc_initial)
        for name, idx in FMU_PARAMETERS.items():
            setattr(self, name, float(vec[idx]))
        self._stepper = self._new_stepper()
        self._set_outputs(self._stepper.outputs)
        register = self.register_variable  # type: ignore[attr-defined]
        for name in INPUTS:
            register(Real(name, causality=Fmi2Causality.input))
        booleans = ("power_input", "per_cell_ports") if self._n_cells > 1 else ("power_input",)
        for name in booleans:
            register(Boolean(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        for name in ("soc_initial", "temp_initial_k", *FMU_PARAMETERS):
            register(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        for name in OUTPUTS:
            register(Real(name, causality=Fmi2Causality.output, initial=Fmi2Initial.exact))
        self.terminal_current_a = 0.0  # the current drawn over the last step (input or solved)
        register(Real("terminal_current_a", causality=Fmi2Causality.output, initial=Fmi2Initial.exact))
        if self._n_cells > 1:
            (port_in,) = CELL_INPUTS
            for c in range(self._n_cells):
                get_in, set_in = partial(self._cell_port_temp, c), partial(self._set_cell_port_temp, c)
                register(
                    Real(port_in.format(c=c), causality=Fmi2Causality.input, getter=get_in, setter=set_in)
                )
            getters = dict(zip(CELL_OUTPUTS, (self._cell_port_heat, self._cell_temp), strict=True))
            for template, getter in getters.items():
                for c in range(self._n_cells):
                    out = Real(
                        template.format(c=c),
                        causality=Fmi2Causality.output,
                        initial=Fmi2Initial.exact,
                        getter=partial(getter, c),
                    )
                    register(out)

    # per-cell variables of a module FMU (getters and setters of cell c)
    def _cell_port_temp(self, c: int) -> float:
        return float(self._cell_port_temp_k[c])

    def _set_cell_port_temp(self, c: int, value: float) -> None:
        self._cell_port_temp_k[c] = value

    def _cell_port_heat(self, c: int) -> float:
        return float(self._stepper.cell_port_heat_w[c])  # type: ignore[union-attr]

    def _cell_temp(self, c: int) -> float:
        return float(self._stepper.m.state[c, K.STEMP])  # type: ignore[union-attr]

    def _new_stepper(self) -> CellStepper | ModuleStepper:
        overrides = {n: float(getattr(self, n)) for n in FMU_PARAMETERS}
        layout = {k: v for k, v in self.DEFAULTS.items() if k not in ("soc_initial", "temp_initial_k")}
        if self._n_cells == 1:
            return CellStepper(self._params, self.soc_initial, self.temp_initial_k, **overrides)
        return ModuleStepper(self._params, self.soc_initial, self.temp_initial_k, **layout, **overrides)  # type: ignore[arg-type]

    def _set_outputs(self, out: dict[str, float]) -> None:
        for name, value in out.items():
            setattr(self, name, value)

    def exit_initialization_mode(self) -> None:
        """Start from the (possibly changed) initial SOC, temperature and parameters."""
        self._stepper = self._new_stepper()
        self._set_outputs(self._stepper.outputs)

    def do_step(self, current_time: float, step_size: float) -> bool:
        """One communication step at the current inputs (current, or power when power_input;
        one port temperature, or one per cell when per_cell_ports)."""
        port: float | np.ndarray = self.port_temp_k
        if self._n_cells > 1 and self.per_cell_ports:
            port = self._cell_port_temp_k.copy()
        if self.power_input:
            self.current_a = current_for_power(self._stepper, self.power_w, port, step_size)
        try:
            outputs = self._stepper.step(self.current_a, port, step_size)  # type: ignore[arg-type]
        except DomainError as exc:  # the message logged, the step refused, the state as before it
            from pythonfmu.enums import Fmi2Status

            self.log(str(exc), Fmi2Status.error)  # type: ignore[attr-defined]
            return False
        self._set_outputs(outputs)
        self.terminal_current_a = self.current_a
        return True

    # FMU state (fmi2Get/SetFMUstate, fmi2(De)SerializeFMUstate): the registered variables
    # (inputs, parameters, outputs) plus the stepper's arrays, all JSON-able.
    def _get_fmu_state(self) -> dict[str, Any]:
        state: dict[str, Any] = {k: _plain(v) for k, v in super()._get_fmu_state().items()}  # type: ignore[misc]
        state[self._STEPPER_KEY] = self._stepper.get_state()
        return state

    def _set_fmu_state(self, state: dict[str, Any]) -> None:
        rest = {k: v for k, v in state.items() if k != self._STEPPER_KEY}
        super()._set_fmu_state(rest)  # type: ignore[misc]
        if self._STEPPER_KEY in state:
            self._stepper.set_state(state[self._STEPPER_KEY])
        self._set_outputs(self._stepper.outputs)


def _plain(value: Any) -> Any:
    """A JSON-able Python scalar (bool, int, float or str) for ``value``."""
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value)
    return value


_SCRIPT = '''"""FMU model module generated by hevsim.battery.fmu.export_fmu."""

from typing import Any, ClassVar

from pythonfmu import Fmi2Slave

from hevsim.battery.fmu import CellSlaveMixin


class {name}(CellSlaveMixin, Fmi2Slave):
    PARAMETERS_TOML = {toml!r}
    DEFAULTS = {defaults!r}

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
'''


def export_fmu(
    params: str | Path,
    out_fmu: str | Path,
    soc_initial: float = 1.0,
    temp_initial_k: float = 298.15,
    model_name: str | None = None,
    n_series: int = 1,
    n_parallel: int = 1,
    capacity_spread: float = 0.0,
    resistance_spread: float = 0.0,
    seed: int = 0,
) -> Path:
    """Build ``out_fmu``: an FMI 2.0 co-simulation FMU of the cell parameter set ``params``
    (a shipped name or a TOML path), or of an ``n_series`` x ``n_parallel`` module of it.
    Returns the FMU path.
    """
    from pythonfmu import FmuBuilder

    from hevsim.io import copy_file_atomic

    p = load_cell_parameters(params)
    name = model_name or "HevsimCell_" + re.sub(r"\W", "_", p.name)
    if not name.isidentifier():
        raise ConfigError(f"FMU model name {name!r} must be a Python identifier.")
    src = Path(p.source)
    if not src.is_file():
        raise ConfigError(f"cell parameters {params!r}: no TOML file to embed in the FMU ({src}).")
    out = Path(out_fmu)
    out.parent.mkdir(parents=True, exist_ok=True)
    defaults: dict[str, Any] = {"soc_initial": float(soc_initial), "temp_initial_k": float(temp_initial_k)}
    if n_series * n_parallel > 1:
        defaults.update(
            n_series=int(n_series), n_parallel=int(n_parallel), capacity_spread=float(capacity_spread),
            resistance_spread=float(resistance_spread), seed=int(seed),
        )  # fmt: skip
        name = model_name or f"{name}_{n_series}s{n_parallel}p"
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / f"{name}.py"
        script.write_text(_SCRIPT.format(toml=src.read_text(), name=name, defaults=defaults))
        built = FmuBuilder.build_FMU(script, dest=tmp, canGetAndSetFMUstate=True, canSerializeFMUstate=True)
        declare_units(built)
        # a copy, not a rename: the temporary directory may be on another file system
        copy_file_atomic(built, out)
    return out


def is_hevsim_fmu(path: str | Path) -> bool:
    """True if ``path`` is an FMU written by :func:`export_fmu` (its model script, under
    ``resources/``, says it was generated by this module)."""
    mark = _SCRIPT.splitlines()[0].encode()
    try:
        with zipfile.ZipFile(path) as z:
            return any(
                n.startswith("resources/") and n.endswith(".py") and z.read(n).startswith(mark)
                for n in z.namelist()
            )
    except (OSError, zipfile.BadZipFile):
        return False


_AFTER_UNIT_DEFINITIONS = (
    "TypeDefinitions", "LogCategories", "DefaultExperiment", "VendorAnnotations", "ModelVariables",
    "ModelStructure",
)  # fmt: skip
"""fmiModelDescription children that follow ``UnitDefinitions`` (FMI 2.0 schema order)."""


def unit_of(name: str) -> str | None:
    """The unit of an FMU variable from its name's suffix (:data:`UNIT_SUFFIXES`), or None."""
    return next((unit for suffix, unit in UNIT_SUFFIXES if name.endswith(suffix)), None)


def declare_units(fmu: str | Path) -> Path:
    """Add units to the ``modelDescription.xml`` of ``fmu`` (pythonfmu cannot declare them):
    ``UnitDefinitions`` with SI base-unit exponents and a ``unit`` on the ``Real`` element of
    every variable named with a unit suffix (:func:`unit_of`). The zip is rewritten atomically
    (a temporary file in the same folder, then a rename). Returns the FMU path."""
    import xml.etree.ElementTree as ET

    path = Path(fmu)
    with zipfile.ZipFile(path) as zin:
        root = ET.fromstring(zin.read("modelDescription.xml"))
    used: list[str] = []
    for var in root.iter("ScalarVariable"):
        real, unit = var.find("Real"), unit_of(var.get("name", ""))
        if real is not None and unit is not None:
            real.set("unit", unit)
            if unit not in used:
                used.append(unit)
    defs = root.find("UnitDefinitions")
    if defs is None and used:
        defs = ET.Element("UnitDefinitions")
        pos = next((i for i, e in enumerate(root) if e.tag in _AFTER_UNIT_DEFINITIONS), len(root))
        root.insert(pos, defs)
    if defs is not None:
        declared = {u.get("name") for u in defs.findall("Unit")}
        for unit in used:
            if unit not in declared:
                u = ET.SubElement(defs, "Unit", name=unit)
                ET.SubElement(u, "BaseUnit", {k: str(v) for k, v in UNIT_EXPONENTS[unit].items()})
    ET.indent(root)
    xml = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        with zipfile.ZipFile(path) as zin, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zout:
            for item in zin.infolist():
                data = xml if item.filename == "modelDescription.xml" else zin.read(item.filename)
                zout.writestr(item, data)
        tmp.replace(path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def simulate_fmu(
    fmu: str | Path,
    current_a: Any,
    port_temp_k: Any,
    dt_s: float,
    parameters: dict[str, float] | None = None,
    timeout_s: float = 600.0,
    power_w: Any = None,
    cell_port_temps_k: Any = None,
    outputs: tuple[str, ...] | list[str] | None = None,
) -> dict[str, np.ndarray]:
    """Drive a cell or module FMU with FMPy, in a worker process, one step per input sample.

    ``current_a`` [A] and ``port_temp_k`` [K] are arrays (or a scalar temperature);
    ``parameters`` are set during initialisation. With ``power_w`` [W] (array) the FMU is
    driven by power instead (``current_a`` is then ignored and may be None); the solved
    current is returned as output ``current_a``. ``cell_port_temps_k`` [K] (module FMU only,
    shape (steps, cells) or (cells,)) drives the per-cell ports (``per_cell_ports`` is set).
    ``outputs`` names the variables returned (default :data:`OUTPUTS` and ``current_a``).
    Returns the outputs per step.
    """
    import json
    import subprocess
    import sys

    from hevsim.errors import SimulationError

    drive = np.asarray(power_w if power_w is not None else current_a, float)
    port = np.broadcast_to(np.asarray(port_temp_k, float), drive.shape)
    key = "power_w" if power_w is not None else "current_a"
    inputs = {key: drive.tolist(), "port_temp_k": port.tolist()}
    booleans = {"power_input": power_w is not None}
    if cell_port_temps_k is not None:
        cells = np.asarray(cell_port_temps_k, float)
        cells = np.broadcast_to(cells, (drive.size, cells.shape[-1]))
        inputs.update({f"cell{c}_port_temp_k": cells[:, c].tolist() for c in range(cells.shape[1])})
        booleans["per_cell_ports"] = True
    req = {
        "fmu": str(fmu),
        "dt_s": float(dt_s),
        "inputs": inputs,
        "parameters": parameters or {},
        "booleans": booleans,
        "outputs": list(outputs) if outputs is not None else [*OUTPUTS, "current_a"],
    }
    proc = subprocess.run(
        [sys.executable, "-m", "hevsim.battery._fmu_worker"],
        input=json.dumps(req),
        capture_output=True,
        text=True,
        timeout=timeout_s,
        check=False,
    )
    if proc.returncode != 0 or not proc.stdout.strip():
        raise SimulationError(
            f"{fmu}: the FMU run failed (exit {proc.returncode}): {proc.stderr.strip()[-800:]}"
        )
    return {k: np.asarray(v) for k, v in json.loads(proc.stdout).items()}

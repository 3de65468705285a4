"""FMI 2.0 co-simulation FMU of an electro-thermal cell (thesis section 4.2), via pythonfmu.

The FMU wraps the same compiled step (:func:`hevsim.battery.kernel.cell_step`) as
:class:`hevsim.battery.Cell`, so an FMI master reproduces the in-process model exactly.

Interface: inputs ``current_a`` [A, discharge > 0] (or ``power_w`` [W] with ``power_input``)
and ``port_temp_k`` [K]; outputs
``voltage_v`` [V], ``soc`` [-], ``port_heat_w`` [W, heat flow into the port], ``temp_k``
[K, core] and ``soh`` [-] (SOH_C of eq 43; the impedance factor of eq 44 is 1 because the
cell's impedance does not age within a run); parameters ``soc_initial``, ``temp_initial_k``
and the scalars of :data:`FMU_PARAMETERS`.

Run-time needs: a host process with CPython loaded (FMPy and other Python-based masters; a C
master must preload libpython) in which ``hevsim`` is importable. The FMU carries Linux and
Windows binaries (pythonfmu's). Its model module is named after the FMU, so two FMUs of
different names can share a process.
"""

from __future__ import annotations

import re
import tempfile
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from hevsim.battery import kernel as K
from hevsim.battery.ageing import soh_capacity
from hevsim.battery.params import CellParameters, load_cell_parameters, parameters_from_dict
from hevsim.errors import ConfigError

FMU_PARAMETERS = K.TUNABLE_SCALARS
"""FMU parameter name -> index in the cell parameter vector (the calibration's scalars)."""

OUTPUTS = ("voltage_v", "soc", "port_heat_w", "temp_k", "soh")
INPUTS = ("current_a", "power_w", "port_temp_k")
"""``power_w`` [W, discharge > 0] is used instead of ``current_a`` when the Boolean
parameter ``power_input`` is true."""


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
        soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf = self.tabs[:7]
        ocv, _ = K.cell_ocv_rs(self.p, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, soc_initial, temp_k, 1.0)
        self.outputs = {"voltage_v": ocv, "soc": soc_initial, "port_heat_w": 0.0, "temp_k": temp_k}
        self.outputs["soh"] = self._soh(K.cell_capacity(self.p, t_ax, capf, self.x[K.SQABS], temp_k))

    def _soh(self, capacity_c: float) -> float:
        return float(soh_capacity(capacity_c, self.p[K.C0], self.params.ageing.x_c))

    def trial_voltage(self, current_a: float, port_temp_k: float, dt_s: float) -> float:
        """Step-average terminal voltage [V] of a step at ``current_a``, state unchanged."""
        rec = np.zeros(len(K.RECORD))
        K.cell_step(self.p, *self.tabs, self.x.copy(), current_a, dt_s, port_temp_k, rec)  # type: ignore[call-arg]
        return float(rec[K.RVAVG])

    def step(self, current_a: float, port_temp_k: float, dt_s: float) -> dict[str, float]:
        """Advance by ``dt_s`` [s] at constant current [A] and port temperature [K]."""
        r = self.rec
        K.cell_step(self.p, *self.tabs, self.x, current_a, dt_s, port_temp_k, r)  # type: ignore[call-arg]
        self.outputs = {
            "voltage_v": float(r[K.RV]),
            "soc": float(r[K.RSOC]),
            "port_heat_w": float(r[K.RPORT]),
            "temp_k": float(r[K.RTEMP]),
            "soh": self._soh(float(r[K.RCAP])),
        }
        return self.outputs


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

    def _soh(self) -> float:
        t_ax, capf = self.tabs[1], self.tabs[6]
        x, p = self.m.state, self.m.p
        caps = [K.cell_capacity(p[c], t_ax, capf, x[c, K.SQABS], x[c, K.STEMP]) for c in range(len(x))]
        return float(min(soh_capacity(cap, p[c, K.C0], self.params.ageing.x_c) for c, cap in enumerate(caps)))

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
        K.run_module(  # type: ignore[call-arg]
            m.p, *self.tabs, m.state, m.n_series, m.n_parallel, np.array([current_a]), dt_s, tp,
            self.out_m, self.out_c,
        )  # fmt: skip
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


class CellSlaveMixin:
    """FMU behaviour, mixed into the generated ``pythonfmu.Fmi2Slave`` subclass.

    The generated class sets :attr:`PARAMETERS_TOML` (the embedded cell parameter file) and
    :attr:`DEFAULTS` (``soc_initial``, ``temp_initial_k``).
    """

    PARAMETERS_TOML = ""
    DEFAULTS: ClassVar[dict[str, Any]] = {}

    def __init__(self, **kwargs: Any) -> None:
        import tomllib

        from pythonfmu import Boolean, Fmi2Causality, Fmi2Variability, Real
        from pythonfmu.enums import Fmi2Initial

        super().__init__(**kwargs)
        self._params = parameters_from_dict(tomllib.loads(self.PARAMETERS_TOML), "<FMU parameters>")
        self.description = f"hevsim electro-thermal cell '{self._params.name}' (thesis eqs 33-44)"
        self.author = "hevsim"
        self.current_a = 0.0
        self.power_w = 0.0
        self.power_input = False
        self.soc_initial = float(self.DEFAULTS["soc_initial"])
        self.temp_initial_k = float(self.DEFAULTS["temp_initial_k"])
        self.port_temp_k = self.temp_initial_k
        vec = self._params.vector(self.soc_initial)
        for name, idx in FMU_PARAMETERS.items():
            setattr(self, name, float(vec[idx]))
        self._stepper = self._new_stepper()
        self._set_outputs(self._stepper.outputs)
        register = self.register_variable  # type: ignore[attr-defined]
        for name in INPUTS:
            register(Real(name, causality=Fmi2Causality.input))
        register(
            Boolean("power_input", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable)
        )
        for name in ("soc_initial", "temp_initial_k", *FMU_PARAMETERS):
            register(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        for name in OUTPUTS:
            register(Real(name, causality=Fmi2Causality.output, initial=Fmi2Initial.exact))

    def _new_stepper(self) -> CellStepper | ModuleStepper:
        overrides = {n: float(getattr(self, n)) for n in FMU_PARAMETERS}
        layout = {k: v for k, v in self.DEFAULTS.items() if k not in ("soc_initial", "temp_initial_k")}
        if layout.get("n_series", 1) * layout.get("n_parallel", 1) == 1:
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
        """One communication step at the current inputs (current, or power when power_input)."""
        if self.power_input:
            self.current_a = current_for_power(self._stepper, self.power_w, self.port_temp_k, step_size)
        self._set_outputs(self._stepper.step(self.current_a, self.port_temp_k, step_size))
        return True


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
        built = FmuBuilder.build_FMU(script, dest=tmp)
        tmp_fmu = out.with_name(f".{out.name}.tmp")
        Path(built).replace(tmp_fmu)
        tmp_fmu.replace(out)
    return out


def simulate_fmu(
    fmu: str | Path,
    current_a: Any,
    port_temp_k: Any,
    dt_s: float,
    parameters: dict[str, float] | None = None,
    timeout_s: float = 600.0,
    power_w: Any = None,
) -> dict[str, np.ndarray]:
    """Drive a cell FMU with FMPy, in a worker process, one step per input sample.

    ``current_a`` [A] and ``port_temp_k`` [K] are arrays (or a scalar temperature);
    ``parameters`` are set during initialisation. With ``power_w`` [W] (array) the FMU is
    driven by power instead (``current_a`` is then ignored and may be None); the solved
    current is returned as output ``current_a``. Returns the outputs per step.
    """
    import json
    import subprocess
    import sys

    from hevsim.errors import SimulationError

    drive = np.asarray(power_w if power_w is not None else current_a, float)
    port = np.broadcast_to(np.asarray(port_temp_k, float), drive.shape)
    key = "power_w" if power_w is not None else "current_a"
    req = {
        "fmu": str(fmu),
        "dt_s": float(dt_s),
        "inputs": {key: drive.tolist(), "port_temp_k": port.tolist()},
        "parameters": parameters or {},
        "booleans": {"power_input": power_w is not None},
        "outputs": [*OUTPUTS, "current_a"],
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

"""Trivial FMUs built with pythonfmu / pythonfmu3, for tests and the overhead benchmark.

:func:`build_integrator_fmu` writes an FMI 2.0 co-simulation FMU ``y(t+h) = y(t) + k*u*h``
(input ``u``, output ``y``, parameter ``k``; variable units given by ``unit``) that supports
get/set/serialise FMU state (its state is just ``y``). :func:`build_integrator_fmu3` writes
the same model as an FMI 3.0 co-simulation FMU (needs the ``pythonfmu3`` package), which can
also ask the importer to terminate (``terminateSimulation``) at a given time."""

from __future__ import annotations

import tempfile
from pathlib import Path

_SCRIPT = """
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Initial


class {name}(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.y = {y0!r}
        self.k = 1.0
        self.stop_at = 1e300
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(
            Real("y", causality=Fmi2Causality.output, initial=Fmi2Initial.exact)
        )
        self.register_variable(
            Real("k", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable)
        )
        self.register_variable(
            Real("stop_at", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable)
        )

    def do_step(self, current_time, step_size):
        if current_time + step_size > self.stop_at:
            raise RuntimeError("integrator asked to fail")
        self.y += self.k * self.u * step_size
        return True
"""


def build_integrator_fmu(
    out_fmu: str | Path, name: str = "HevsimIntegrator", y0: float = 0.0, unit: str = ""
) -> Path:
    """Build the integrator FMU at ``out_fmu`` (model ``name``, a Python identifier);
    ``unit`` (a temperature unit such as "K" or "degC") is written as the unit of ``u`` and
    ``y``. Returns the path."""
    from pythonfmu import FmuBuilder

    out = Path(out_fmu)
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / f"{name}.py"
        script.write_text(_SCRIPT.format(name=name, y0=float(y0)))
        built = Path(
            FmuBuilder.build_FMU(script, dest=tmp, canGetAndSetFMUstate=True, canSerializeFMUstate=True)
        )
        if unit:
            _set_unit(built, unit)
        built.replace(out)
    return out


_SCRIPT3 = """
from pythonfmu3 import Fmi3Causality, Fmi3Slave, Fmi3Status, Fmi3StepResult, Fmi3Variability, Float64, Unit
from pythonfmu3.enums import Fmi3Initial


class {name}(Fmi3Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        unit = {unit!r} or None
        if unit:
            offset = 273.15 if unit == "degC" else 0.0
            self.register_units([Unit(unit, K=1, offset=offset)])
        self.time = 0.0
        self.u = 0.0
        self.y = {y0!r}
        self.k = 1.0
        self.stop_at = 1e300
        self.terminate_at = 1e300
        self.discard_above = 1e300
        self.register_variable(
            Float64("time", causality=Fmi3Causality.independent, variability=Fmi3Variability.continuous)
        )
        self.register_variable(Float64("u", causality=Fmi3Causality.input, unit=unit))
        self.register_variable(
            Float64("y", causality=Fmi3Causality.output, initial=Fmi3Initial.exact, unit=unit)
        )
        for par in ("k", "stop_at", "terminate_at", "discard_above"):
            self.register_variable(
                Float64(par, causality=Fmi3Causality.parameter, variability=Fmi3Variability.tunable)
            )

    def do_step(self, current_time, step_size):
        end = current_time + step_size
        if step_size > self.discard_above * (1 + 1e-12):
            return Fmi3StepResult(status=Fmi3Status.discard)
        if end > self.stop_at:
            raise RuntimeError("integrator asked to fail")
        self.y += self.k * self.u * step_size
        self.time = end
        return Fmi3StepResult(terminateSimulation=end >= self.terminate_at - 1e-9 * max(1.0, abs(end)))
"""


def build_integrator_fmu3(
    out_fmu: str | Path, name: str = "HevsimIntegrator3", y0: float = 0.0, unit: str = ""
) -> Path:
    """Build the FMI 3.0 integrator FMU at ``out_fmu`` (model ``name``, a Python identifier)
    with pythonfmu3: input ``u``, output ``y`` (unit ``unit``, e.g. "K" or "degC", declared in
    its UnitDefinitions), independent variable ``time`` and tunable Float64 parameters ``k``
    (gain), ``stop_at`` (a step ending after it fails: pythonfmu3 reports the Python
    exception as fmi3Fatal), ``terminate_at`` (a step ending at or after it returns
    ``terminateSimulation = true``) and ``discard_above`` (a longer step is discarded with
    fmi3Discard, ``lastSuccessfulTime`` = its start, state unchanged). Supports
    get/set/serialise FMU state (pythonfmu3 snapshots every registered variable). Returns the
    path."""
    from pythonfmu3 import FmuBuilder as Fmu3Builder

    out = Path(out_fmu)
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / f"{name}.py"
        script.write_text(_SCRIPT3.format(name=name, y0=float(y0), unit=unit))
        built = Path(
            Fmu3Builder.build_FMU(
                script,
                dest=tmp,
                canGetAndSetFMUState=True,
                canSerializeFMUState=True,
                # pythonfmu3 0.3.4 otherwise writes the value of its last common option here
                canHandleVariableCommunicationStepSize=True,
            )
        )
        built.replace(out)
    return out


def _set_unit(fmu: Path, unit: str) -> None:
    """Rewrite modelDescription.xml so ``u`` and ``y`` carry ``unit``."""
    import zipfile

    tmp = fmu.with_suffix(".tmp")
    with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                offset = 273.15 if unit == "degC" else 0.0
                defs = (
                    f'<UnitDefinitions><Unit name="{unit}"><BaseUnit K="1" offset="{offset}"/>'
                    "</Unit></UnitDefinitions>"
                )
                text = text.replace("<LogCategories>", defs + "<LogCategories>", 1)
                for var in ("u", "y"):
                    head = f'name="{var}"'
                    i = text.index(head)
                    j = text.index("<Real", i)
                    text = text[: j + 5] + f' unit="{unit}"' + text[j + 5 :]
                data = text.encode()
            zout.writestr(item, data)
    tmp.replace(fmu)

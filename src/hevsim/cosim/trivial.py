"""Trivial FMUs built with pythonfmu, for tests and the overhead benchmark.

:func:`build_integrator_fmu` writes an FMI 2.0 co-simulation FMU ``y(t+h) = y(t) + k*u*h``
(input ``u``, output ``y``, parameter ``k``; variable units given by ``unit``) that supports
get/set/serialise FMU state (its state is just ``y``)."""

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

"""No impossible state with exit 0 (issue 26 item 1): every command that steps a battery, driven
by a load that empties it, either derates (no cell's SOC ever below 0) or stops with a non-zero
exit and one message naming the time, the cell and the state.

The shared check is :func:`hevsim.battery.cell.check_cell_domain`; the standalone pack's BMS
applies the same SOC/voltage current limits as a vehicle's (:mod:`hevsim.battery.bms`).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hevsim.cli import main
from hevsim.errors import DomainError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"

CELL_EMPTY = """
[cell]
parameters = "thesis_table_4_1"
soc_initial = 0.05
temp_c = 23.0

[profile]
kind = "constant"
current_a = 4.0
duration_s = 600.0
dt_s = 1.0

[thermal]
port_temp_c = 23.0
"""

MODULE_EMPTY = """
[cell]
parameters = "saft_li_ion_6ah"
soc_initial = 0.05

[module]
n_series = 2
n_parallel = 3
capacity_spread = 0.03
resistance_spread = 0.05
seed = 42

[profile]
kind = "constant"
current_a = 30.0
duration_s = 600.0
dt_s = 1.0

[thermal]
port_temp_c = 30.0
"""


def _pack_file(tmp_path: Path, extra: str = "") -> Path:
    """examples/pack_coolant.toml on 2 modules, starting at 30 % SOC (US06 empties it)."""
    text = (EXAMPLES / "pack_coolant.toml").read_text()
    text = text.replace("n_modules = 8", "n_modules = 2").replace("soc_initial = 0.9", "soc_initial = 0.3")
    text = text.replace(
        'thermal_config = "module_thermal.toml"', f'thermal_config = "{EXAMPLES / "module_thermal.toml"}"'
    )
    p = tmp_path / "pack.toml"
    p.write_text(text + extra)
    return p


def _one_message(err: str) -> str:
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("hevsim: error:"), err
    return lines[0]


@pytest.mark.parametrize(("text", "cell"), [(CELL_EMPTY, ""), (MODULE_EMPTY, "cell ")])
def test_cell_and_module_commands_stop_a_run_that_empties_a_cell(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, cell: str
) -> None:
    """Today's tree: exit 0 and final SOC -2.7 (cell) / below 0 (module)."""
    cfg = tmp_path / "run.toml"
    cfg.write_text(text)
    out = tmp_path / "out"
    assert main(["cell", str(cfg), "--out", str(out)]) == 2
    msg = _one_message(capsys.readouterr().err)
    assert re.search(r"at t = \d+ s with a current of [\d.]+ A", msg), msg
    assert re.search(rf"{cell}\d*:? ?state of charge -[\d.e-]+ outside \[0, 1\]", msg), msg
    assert not out.exists()


def test_pack_command_derates_before_a_cell_empties(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The documented pack command's case (US06 beyond the pack's charge): today every cell's
    SOC goes below 0 with "derated 0 s" and exit 0; now the BMS's low-SOC/voltage limits hold
    the current back, no cell goes below 0, the run ends and says so."""
    out = tmp_path / "out"
    code = main(
        ["pack", str(_pack_file(tmp_path)), "--cycle", "us06", "--duration", "1800", "--out", str(out)]
    )
    text = capsys.readouterr().out
    assert code == 0
    ts = pd.read_csv(out / "timeseries.csv")
    assert ts["min_soc"].min() >= 0.0
    assert (ts["current_a"] < ts["current_request_a"] - 1e-9).sum() > 100  # held back by the BMS
    assert "BMS held the current below the request" in text and "by low/high cell SOC or voltage" in text
    assert float(re.search(r"(\d+\.\d) % of the requested discharge", text).group(1)) < 100.0


def test_pack_without_soc_derating_stops_with_a_message(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A derating table that lets the cells empty (no SOC factor, voltage limits far below the
    cells' range): either the pack's remaining limits keep every cell in [0, 1] or the run stops
    with exit 2 naming the time, the cell and its state; never exit 0 with a cell below 0."""
    cells = tmp_path / "cells.toml"
    src = (ROOT / "src" / "hevsim" / "data" / "cells" / "thesis_table_4_1.toml").read_text()
    src = re.sub(r"v_min_v\s*=\s*[\d.]+", "v_min_v = 0.1", src)
    cells.write_text(src)
    extra = "discharge_soc_factor = [1.0, 1.0, 1.0, 1.0, 1.0, 1.0]\n"
    p = _pack_file(tmp_path, extra)
    p.write_text(p.read_text().replace('parameters = "thesis_table_4_1"', f'parameters = "{cells}"'))
    out = tmp_path / "out"
    code = main(["pack", str(p), "--cycle", "us06", "--duration", "1800", "--out", str(out)])
    if code == 0:
        assert pd.read_csv(out / "timeseries.csv")["min_soc"].min() >= 0.0
        return
    assert code == 2
    msg = _one_message(capsys.readouterr().err)
    assert re.search(r"module \d+ cell \d+: state of charge -[\d.e-]+ outside \[0, 1\]", msg), msg
    assert "at t = " in msg and not out.exists()


def test_stepper_participants_and_python_fmu_steppers_refuse_an_empty_cell() -> None:
    """The cosim participant (hevsim cell/module in process) and the pythonfmu FMU's steppers:
    DomainError at the step that empties a cell, state as before the step."""
    from hevsim.battery.fmu import CellStepper, ModuleStepper
    from hevsim.battery.params import load_cell_parameters
    from hevsim.cosim.participant import StepperParticipant

    p = load_cell_parameters("thesis_table_4_1")
    for stepper in (CellStepper(p, 0.01, 298.15), ModuleStepper(p, 0.01, 298.15, 2, 2)):
        before = stepper.get_state()
        with pytest.raises(DomainError, match=r"at t = 100 s .*state of charge -[\d.e-]+ outside \[0, 1\]"):
            stepper.step(40.0, 298.15, 100.0)
        assert stepper.get_state() == before
        stepper.step(0.1, 298.15, 1.0)  # a valid step still runs
    part = StepperParticipant("battery", soc_initial=0.01, n_series=2, n_parallel=1)
    part.setup(0.0)
    part.set_inputs({"current_a": 40.0, "port_temp_k": 298.15})
    with pytest.raises(DomainError, match="state of charge"):
        part.do_step(0.0, 100.0)


def test_cosim_run_with_a_draining_cell_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`hevsim cosim` with an in-process hevsim cell drained by a constant load: exit 2 and one
    line naming the time and the state (today: exit 0 with the cell's SOC below 0)."""
    path = tmp_path / "drain.ssd"
    path.write_text(_DRAIN_SSD)
    out = tmp_path / "out"
    code = main(["cosim", str(path), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2, err
    msg = _one_message(err)
    assert "state of charge" in msg and "at t = " in msg, msg
    # cosim keeps the results up to the last completed communication point, each state valid
    import json

    assert "state of charge" in json.loads((out / "summary.json").read_text())["error"]
    soc = pd.read_csv(out / "results.csv")["battery.soc"]
    assert len(soc) > 10 and soc.min() >= 0.0


def _param(name: str, kind: str, value: str) -> str:
    return f'<ssv:Parameter name="{name}"><ssv:{kind} value="{value}" /></ssv:Parameter>'


def _component(name: str, source: str, params: str) -> str:
    return (
        f'<ssd:Component name="{name}" type="application/x-hevsim-python" source="{source}">'
        "<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>"
        f'<ssv:ParameterSet version="1.0" name="parameters"><ssv:Parameters>{params}</ssv:Parameters>'
        "</ssv:ParameterSet></ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>"
        "</ssd:Component>"
    )


_LOAD = (
    _param("discharge_w", "Real", "20.0")
    + _param("charge_w", "Real", "0.0")
    + _param("period_s", "Real", "1000.0")
)
_CELL = _param("soc_initial", "Real", "0.05") + _param("power_input", "Boolean", "true")
_DRAIN_SSD = f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:hevsim="https://hevsim.org/cosim"
 xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
 xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
 xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="drain">
  <ssd:System name="drain">
    <ssd:Elements>
      {_component("load", "hevsim.cosim.library:power_cycle", _LOAD)}
      {_component("battery", "hevsim.cosim.participant:StepperParticipant", _CELL)}
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="load" startConnector="power_w"
       endElement="battery" endConnector="power_w" />
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0.0" stopTime="900.0">
    <ssd:Annotations>
      <ssc:Annotation type="org.hevsim.cosim">
        <hevsim:Master algorithm="gauss-seidel" step_s="1.0" order="load battery" />
      </ssc:Annotation>
    </ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""


@pytest.mark.parametrize("pythonfmu", [False, True])
def test_fmus_return_an_error_when_a_cell_empties(tmp_path: Path, pythonfmu: bool) -> None:
    """The native (C) and the pythonfmu FMU of a cell: the step that empties the cell returns
    fmi2Error with a logged message naming the SOC (today: fmi2OK and soc < 0)."""
    pytest.importorskip("fmpy")
    from hevsim.battery.fmu import simulate_fmu
    from hevsim.errors import SimulationError

    fmu = tmp_path / "cell.fmu"
    args = [
        "export-fmu",
        str(EXAMPLES / "cell.toml"),
        "-o",
        str(fmu),
        *(["--pythonfmu"] if pythonfmu else []),
    ]
    assert main(args) == 0
    current = np.full(30, 4.0)
    with pytest.raises(SimulationError, match=r"soc|state of charge") as info:
        simulate_fmu(fmu, current, 298.15, 100.0, parameters={"soc_initial": 0.2})
    assert "outside [0, 1]" in str(info.value) and "at t = 200 s" in str(info.value)
    # native: fmi2Error; pythonfmu: fmi2Discard (its wrapper turns an exception into fmi2Fatal)
    assert re.search(r"fmi2DoStep failed with status [23] \((error|discard)\)", str(info.value))

"""SSP / SSD round trip, the SIMULIA CSE importer, datacheck and bad input (issue 6, items 3, 9)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from hevsim.cosim import Connection
from hevsim.cosim.cse import read_cse
from hevsim.cosim.datacheck import datacheck
from hevsim.cosim.ssd import FMU_TYPE, PY_TYPE, Component, Connector, SystemDescription, read_ssd, read_ssp
from hevsim.cosim.ssp_write import write_ssd, write_ssp
from hevsim.cosim.system import run_cosim
from hevsim.cosim.trivial import build_integrator_fmu
from hevsim.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
THESIS_XML = ROOT / "examples" / "cosim_module" / "thesis_cse.xml"
LIB = "hevsim.cosim.library:"


def thermal_system(base: Path) -> SystemDescription:
    hot_params = {"capacity_j_per_k": 500.0, "temp_initial_k": 350.0, "conductance_w_per_k": 3.0}
    hot_conn = [Connector("t_other_k", "input", "K"), Connector("heat_out_w", "output", "W")]
    hot = Component("hot", PY_TYPE, LIB + "thermal_mass", hot_conn, hot_params)
    cold_conn = [Connector("heat_in_w", "input", "kW"), Connector("temp_k", "output", "degC")]
    cold_params = {"capacity_j_per_k": 200.0, "temp_initial_k": 290.0}
    cold = Component("cold", PY_TYPE, LIB + "thermal_mass", cold_conn, cold_params)
    conns = [
        Connection("cold", "temp_k", "hot", "t_other_k"),
        Connection("hot", "heat_out_w", "cold", "heat_in_w"),
    ]
    master = {"algorithm": "gauss-seidel", "step_s": 5.0, "order": ["hot", "cold"]}
    return SystemDescription("two_masses", [hot, cold], conns, 0.0, 300.0, master, base_dir=base)


def test_ssd_round_trip_and_run(tmp_path: Path) -> None:
    desc = thermal_system(tmp_path)
    desc.connections = [
        Connection("cold", "temp_k", "hot", "t_other_k"),
        Connection("hot", "heat_out_w", "cold", "heat_in_w"),
    ]
    # declared connector units are used only by datacheck; the participants' own units (K, W) run
    for c in desc.components:
        c.connectors = [
            Connector(k.name, k.kind, "K" if k.name.startswith("t") else "W") for k in c.connectors
        ]
    path = write_ssd(desc, tmp_path / "sys.ssd")
    back = read_ssd(path)
    assert [c.name for c in back.components] == ["hot", "cold"]
    assert back.components[0].parameters == desc.components[0].parameters
    assert back.master == desc.master and back.stop_time_s == 300.0
    assert back.connections == desc.connections
    res = run_cosim(path, tmp_path / "out")
    e_hot, e_cold = res["hot.energy_j"][-1], res["cold.energy_j"][-1]
    assert e_cold == pytest.approx(-e_hot, rel=1e-12)  # energy conserved across the interface
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["final"]["cold.energy_j"] == pytest.approx(e_cold)
    assert (tmp_path / "out" / "results.csv").read_text().startswith("time_s,hot.temp_k")
    assert read_ssd(tmp_path / "out" / "system.ssd").master == desc.master


def test_ssp_with_fmus_round_trip_and_run(tmp_path: Path) -> None:
    build_integrator_fmu(tmp_path / "x.fmu", name="SspTestX", y0=1.0)
    build_integrator_fmu(tmp_path / "v.fmu", name="SspTestV")
    desc = SystemDescription(
        "osc",
        [Component("x", FMU_TYPE, "x.fmu"), Component("v", FMU_TYPE, "v.fmu", parameters={"k": -1.0})],
        [Connection("v", "y", "x", "u"), Connection("x", "y", "v", "u")],
        0.0, 2.0, {"algorithm": "jacobi", "step_s": 0.01, "max_iterations": 10, "tolerance": 1e-12},
        base_dir=tmp_path,
    )  # fmt: skip
    ssp = write_ssp(desc, tmp_path / "osc.ssp")
    back = read_ssp(ssp, tmp_path / "unpacked")
    assert back.components[1].source.startswith("resources/") and back.components[1].parameters == {"k": -1.0}
    res = run_cosim(ssp, tmp_path / "out")
    assert np.abs(res["x.y"] - np.cos(res.time_s)).max() < 1e-4


def test_cse_import_of_thesis_file() -> None:
    d = read_cse(THESIS_XML)
    assert d.master["algorithm"] == "gauss-seidel" and d.master["negotiation"] == "min"
    assert d.master["order"] == ["Module1", "Fluidz", "BatteryCoSim System"]
    assert d.master["send_before_receive"] == {"Fluidz": False}
    assert d.stop_time_s == 300.0
    pairs = {(c.src, c.src_var, c.dst, c.dst_var) for c in d.connections}
    assert ("Fluidz", "heat_flux", "Module1", "heat_flux") in pairs
    assert ("Module1", "temperature", "Fluidz", "temperature") in pairs
    assert ("BatteryCoSim System", "bodyflux", "Module1", "BODYFLUX") in pairs
    assert ("Module1", "TEMP", "BatteryCoSim System", "temp") in pairs
    assert len(d.connections) == 5
    from hevsim.cosim.units import conversion

    assert conversion("J/kg", "kcal/kg", d.units) == pytest.approx((1 / 4186.8, 0.0))
    assert conversion("degC", "K", d.units) == pytest.approx((1.0, 273.15))
    datacheck(d)  # all five requirements hold for the thesis file


def _edit(tmp_path: Path, old: str, new: str) -> Path:
    text = THESIS_XML.read_text()
    assert old in text
    p = tmp_path / "edited.xml"
    p.write_text(text.replace(old, new, 1))
    return p


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("</connectors>", "</connector>", r"line \d+: not well-formed XML"),
        ("<SchemaVersion>1.1</SchemaVersion>", "", "lacks the required <SchemaVersion>"),
        (
            "<component>CFD</component>",
            "<component>CFX</component>",
            "'Fluidz' refers to unknown component 'CFX'",
        ),
        (
            "<connector>CFD_to_STD_OUTPUT</connector>",
            "<connector>CFD_OUT</connector>",
            "connectionSet 'CFD_to_STD' connection #1: unknown connector 'CFD_OUT'",
        ),
        (
            "<variable>heat_capacitance</variable></output>",
            "</output>",
            r"connector 'CFD_to_STD_INPUT' has 2 input variable\(s\) but connector 'CFD_to_STD_OUTPUT' has 1",
        ),
        ('<Real unit="J/kg"/>', '<Real unit="W"/>', "incompatible units 'W' -> 'kcal/kg'"),
        (
            "<algorithm>GAUSS-SEIDEL</algorithm>",
            "<algorithm>NEWTON</algorithm>",
            "valid: GAUSS-SEIDEL, JACOBI",
        ),
        (
            "<connectionSet>STD_and_FMI</connectionSet>\n      </connectionCategory>",
            "<connectionSet>STD_FMI</connectionSet></connectionCategory>",
            "names unknown connectionSet 'STD_FMI'",
        ),
        (
            "<atomicActor>Fluidz</atomicActor>",
            "<atomicActor>Fluid</atomicActor>",
            "'Fluid' is not a componentInstance",
        ),
    ],
)
def test_cse_bad_input(tmp_path: Path, old: str, new: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        datacheck(_edit(tmp_path, old, new))


def test_unbound_cse_cannot_run(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="component 'Fluidz' is not bound"):
        run_cosim(THESIS_XML, tmp_path / "out")


def test_ssd_bad_input(tmp_path: Path) -> None:
    build_integrator_fmu(tmp_path / "x.fmu", name="SspBadX")
    comps = [Component("x", FMU_TYPE, "x.fmu"), Component("y", FMU_TYPE, "x.fmu")]
    conns = [Connection("x", "y", "y", "u")]
    good = SystemDescription("s", comps, conns, 0.0, 1.0, {"step_s": 0.1}, base_dir=tmp_path)
    write_ssd(good, tmp_path / "good.ssd")
    datacheck(tmp_path / "good.ssd")

    def check(old: str, new: str, message: str) -> None:
        p = tmp_path / "bad.ssd"
        text = (tmp_path / "good.ssd").read_text()
        assert old in text, old
        p.write_text(text.replace(old, new, 1))
        with pytest.raises(ConfigError, match=message):
            datacheck(p)

    check('source="x.fmu"', 'source="missing.fmu"', "component 'x': FMU file .*missing.fmu' does not exist")
    check('startConnector="y"', 'startConnector="z"', "component 'x' has no variable 'z'")
    check('startConnector="y"', 'startConnector="u"', "x.u is an input, expected an output")
    check('endElement="y"', 'endElement="q"', "unknown component 'q'")
    check(
        'startElement="x" ',
        "",
        "<ssd:Connection> #1: element <Connection> lacks required attribute 'startElement'",
    )
    text = (tmp_path / "good.ssd").read_text()
    (tmp_path / "nosys.ssd").write_text(
        text.replace("<ssd:System ", "<ssd:Sys ").replace("</ssd:System>", "</ssd:Sys>")
    )
    with pytest.raises(ConfigError, match="has no <ssd:System> element"):
        datacheck(tmp_path / "nosys.ssd")
    check('type="application/x-fmu-sharedlibrary"', 'type="text/plain"', "component 'x': type 'text/plain'")
    check('step_s="0.1"', 'step="0.1"', "unknown attribute 'step'")
    (tmp_path / "corrupt.fmu").write_bytes(b"PK\x03\x04 broken")
    check('source="x.fmu"', 'source="corrupt.fmu"', "corrupt.fmu is not a valid FMU")
    with pytest.raises(ConfigError, match="not a readable SSP archive"):
        read_ssp(tmp_path / "corrupt.fmu")


def test_cosim_command(tmp_path, capsys, cosim_module_dir) -> None:  # type: ignore[no-untyped-def]
    from hevsim.cli import main

    ssd = cosim_module_dir / "module.ssd"  # the shipped SSD with its FMU built
    assert main(["cosim", str(ssd), "--check"]) == 0
    assert "ok" in capsys.readouterr().out
    bad = tmp_path / "bad.ssd"
    bad.write_text(ssd.read_text().replace("</", "<", 1))
    assert main(["cosim", str(bad), "--check"]) == 2
    assert "bad.ssd" in capsys.readouterr().err


def test_cosim_command_runs_and_summarises(tmp_path, capsys, cosim_module_dir) -> None:  # type: ignore[no-untyped-def]
    """``hevsim cosim CONFIG --out DIR`` on (a 3 s cut of) the shipped module case."""
    import shutil

    from hevsim.cli import main

    shutil.copytree(cosim_module_dir, tmp_path / "cosim_module")  # with its FMU built
    shutil.copy(cosim_module_dir.parent / "module_thermal.toml", tmp_path / "module_thermal.toml")
    ssd = tmp_path / "cosim_module" / "module.ssd"
    ssd.write_text(ssd.read_text().replace('stopTime="300.0"', 'stopTime="3.0"'))
    assert main(["cosim", str(ssd), "--out", str(tmp_path / "out")]) == 0
    text = capsys.readouterr().out
    assert "3 communication steps to t = 3 s" in text
    assert "hot spot 1 (fem, " in text
    # units match values: temperatures in °C without the kelvin suffix, powers in W
    assert re.search(r"coolant\.outlet_temp +\d+\.\d{3} °C", text), text
    assert re.search(r"fem\.cell_max_temp +\d+\.\d{3} °C", text), text
    assert "_temp_k" not in text
    assert (tmp_path / "out" / "fem_temperature.pvd").is_file()

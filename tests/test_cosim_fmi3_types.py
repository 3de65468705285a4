# ruff: noqa: E501 (XML and messages)
"""Every FMI 3.0 scalar type (Float32, Float64, Int8 .. UInt64, Boolean, String, Enumeration,
Binary) and a Float32 array exchanged through connections, set from an SSV file and recorded
(issue 13 item 3), with the C feedthrough FMU of :mod:`tests.cosim_cfmu3`: two instances
``src -> snk`` in an SSD written here, run by ``run_cosim`` (FMUs in process and in worker
processes) and by ``hevsim cosim``; the results equal FMPy's ``simulate_fmu`` of each FMU
alone and the closed-form values, 64-bit integers beyond 2**53 exactly.
"""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.cosim_cfmu3 import NUMERIC, TYPES, build_c_fmu3

from hevsim.cosim.master import CosimFault
from hevsim.errors import ConfigError

# (src input u, src parameter p, snk parameter p) per type: src.y = u + p, snk.y = src.y + p
VALUES: dict[str, tuple[Any, Any, Any]] = {
    "Float32": (0.1, 0.2, 1 / 3),
    "Float64": (0.1, 0.2, 0.7),
    "Int8": (-100, -28, 127),
    "UInt8": (200, 55, 0),
    "Int16": (-32000, -768, 32767),
    "UInt16": (65000, 535, 0),
    "Int32": (-(2**31) + 1, -1, 2**31 - 1),
    "UInt32": (2**32 - 2, 1, 0),
    "Int64": (-(2**63) + 2, -1, -1),  # src.y = -2**63 + 1 (no float64), snk.y = Int64 min
    "UInt64": (2**63, 2**53 + 1, 2**63 - 2**53 - 2),  # src.y odd above 2**63, snk.y = 2**64 - 1
    "Boolean": (True, False, True),
    "String": ("a,b", ' "q"', "!"),
    "Enumeration": (2, 1, 2),
    "Binary": ("0102", "ff", "00"),
}
NP = {t: np.dtype(t.lower()) for t in NUMERIC}
STOP_S, STEP_S = 1.0, 0.1
ROWS = 11


def expected() -> dict[str, Any]:
    """Closed-form outputs of both instances (numbers in the type's own arithmetic)."""
    out: dict[str, Any] = {}
    for t, (u, p, q) in VALUES.items():
        if t in NUMERIC:
            y = (NP[t].type(u) + NP[t].type(p)).item()
            z = (NP[t].type(y) + NP[t].type(q)).item()
        elif t == "Boolean":
            y, z = u != p, (u != p) != q
        elif t == "Enumeration":
            y, z = u + p, u + p + q
        else:  # String, Binary (hexadecimal text)
            y, z = u + p, u + p + q
        out[f"src.y_{t}"], out[f"snk.y_{t}"] = y, z
    p32 = np.float32(VALUES["Float32"][1])
    q32 = np.float32(VALUES["Float32"][2])
    for k in (1, 2, 3):
        ya = np.float32(0) + np.float32(k) * p32
        out[f"src.ya[{k}]"] = float(ya)
        out[f"snk.ya[{k}]"] = float(np.float32(ya) + np.float32(k) * q32)
    return out


def _ssv_value(t: str, v: Any) -> str:
    if t == "Boolean":
        return f'<ssv:Boolean value="{str(v).lower()}"/>'
    if t in ("Float32", "Float64"):
        return f'<ssv:Real value="{v!r}"/>'
    if t == "String":
        return f'<ssv:String value="{v.replace(chr(34), "&quot;")}"/>'
    if t == "Binary":
        return f'<ssv:Binary value="{v}"/>'
    if t == "Enumeration":
        return f'<ssv:Enumeration value="{v}"/>'
    return f'<ssv:Integer value="{v}"/>'


def write_system(
    d: Path,
    fmu: Path,
    conns: list[tuple[str, str]] | None = None,
    process: str = "worker",
    params: dict[str, Any] | None = None,
) -> Path:
    """``d/types.ssd`` with ``src`` and ``snk`` (``fmu``), connected ``src.a -> snk.b`` for
    each ``(a, b)`` of ``conns`` (default: ``y_T -> u_T`` for every type and the array),
    parameters from ``d/src.ssv`` and ``d/snk.ssv`` (:data:`VALUES`, updated by ``params``)."""
    if conns is None:
        conns = [(f"y_{t}", f"u_{t}") for t in TYPES] + [(f"ya[{k}]", f"ua[{k}]") for k in (1, 2, 3)]
    values = {}
    for t, (u, p, q) in VALUES.items():
        values[f"src.u_{t}"], values[f"src.p_{t}"], values[f"snk.p_{t}"] = (t, u), (t, p), (t, q)
    for k, v in (params or {}).items():
        values[k] = (values[k][0], v)
    for n in ("src", "snk"):  # one parameter set per component, names with its prefix
        ssv = "".join(
            f'    <ssv:Parameter name="{k}">{_ssv_value(t, v)}</ssv:Parameter>\n'
            for k, (t, v) in values.items()
            if k.startswith(f"{n}.")
        )
        (d / f"{n}.ssv").write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="{n}">
  <ssv:Parameters>
{ssv}  </ssv:Parameters>
</ssv:ParameterSet>
""")
    if not (d / fmu.name).is_file():
        (d / fmu.name).write_bytes(fmu.read_bytes())
    comps = "".join(
        f"""      <ssd:Component name="{n}" type="application/x-fmu-sharedlibrary" source="{fmu.name}">
        <ssd:ParameterBindings><ssd:ParameterBinding source="{n}.ssv" prefix="{n}."/></ssd:ParameterBindings>
      </ssd:Component>
"""
        for n in ("src", "snk")
    )
    links = "".join(
        f'      <ssd:Connection startElement="src" startConnector="{a}" endElement="snk" endConnector="{b}"/>\n'
        for a, b in conns
    )
    ssd = d / "types.ssd"
    ssd.write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:hevsim="https://hevsim.org/cosim" version="1.0" name="types">
  <ssd:System name="types">
    <ssd:Elements>
{comps}    </ssd:Elements>
    <ssd:Connections>
{links}    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="{STOP_S}">
    <ssd:Annotations>
      <ssc:Annotation type="org.hevsim.cosim">
        <hevsim:Master step_s="{STEP_S}" fmu_process="{process}"/>
      </ssc:Annotation>
    </ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
""")
    return ssd


@pytest.fixture(scope="module")
def fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_c_fmu3(tmp_path_factory.mktemp("cfmu3") / "types3.fmu")


@pytest.fixture(scope="module")
def fmpy_refs(fmu: Path) -> dict[str, np.ndarray]:
    """FMPy's ``simulate_fmu`` of ``src`` alone, then of ``snk`` alone with its inputs held
    at ``src``'s outputs (constant: every output of ``src`` but ``steps`` is)."""
    from fmpy import simulate_fmu

    def run(start: dict[str, Any]) -> np.ndarray:
        return simulate_fmu(str(fmu), stop_time=STOP_S, step_size=STEP_S, output_interval=STEP_S,
                            start_values=start)  # fmt: skip

    src = {f"u_{t}": v[0] for t, v in VALUES.items()} | {f"p_{t}": v[1] for t, v in VALUES.items()}
    a = run(src)
    e = expected()
    snk = {f"p_{t}": v[2] for t, v in VALUES.items()}
    snk |= {f"u_{t}": a[f"y_{t}"][0].item() for t in (*NUMERIC, "Boolean", "Enumeration")}
    snk |= {"u_String": e["src.y_String"], "u_Binary": e["src.y_Binary"], "ua": a["ya"][0].tolist()}
    return {"src": a, "snk": run(snk)}


def check_results(res: Any, refs: dict[str, np.ndarray]) -> None:
    """``res`` (a CosimResult) equals the closed form and FMPy's runs, exactly."""
    e = expected()
    assert len(res.time_s) == ROWS and np.array_equal(res.time_s, np.arange(ROWS) * STEP_S)
    for col, v in e.items():
        got = res[col].tolist()
        assert got == [v] * ROWS, (col, got[:2], v)
        kind = float if isinstance(v, bool) else type(v)  # Booleans are recorded as 0.0 / 1.0
        assert all(type(g) is kind for g in got), (col, type(got[0]), kind)
        n, var = col.split(".")
        if var.startswith("ya["):
            k = int(var[3]) - 1
            assert np.array_equal(res[col], refs[n]["ya"][:, k].astype(float)), col
        elif var[2:] in (*NUMERIC, "Boolean", "Enumeration"):
            ref = refs[n][var]
            assert [r.item() for r in ref] == [v] * ROWS, col  # FMPy agrees with the closed form
    steps = [VALUES["UInt64"][1] + k for k in range(ROWS)]  # odd ones are not float64 numbers
    assert res["src.steps"].tolist() == steps and res["src.steps"].dtype == np.int64
    assert res["snk.y_UInt64"].dtype == np.uint64  # above 2**63
    assert res["src.steps"].tolist() == refs["src"]["steps"].tolist()
    # 64-bit extremes, no float64 round trip
    assert res.integers["snk.y_UInt64"][-1] == 2**64 - 1 and res.integers["snk.y_Int64"][0] == -(2**63)
    assert (
        res.integers["src.y_UInt64"][0] == 2**63 + 2**53 + 1
        and res.integers["src.y_Int64"][0] == -(2**63) + 1
    )
    assert res["src.y_Float32"][0] == float(np.float32(0.1) + np.float32(0.2)) != 0.1 + 0.2


def check_csv(path: Path) -> None:
    """``results.csv``: a column per output (array elements ``ya[k]``), integers exactly."""
    e = expected()
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    head, last = rows[0], dict(zip(rows[0], rows[-1], strict=True))
    assert len(rows) == ROWS + 1
    assert set(head) == {"time_s", *e, "src.steps", "snk.steps"}
    # the components' listing order, each FMU's outputs in its model description's order (String
    # and Binary among them, not moved to the end)
    from fmpy import read_model_description

    from hevsim.cosim.fmi_vars import FmuVariables

    fmu = next(path.parent.parent.glob("*.fmu"))
    outs = list(FmuVariables(read_model_description(str(fmu)), fmu.name).outputs)
    assert head == ["time_s", *(f"{n}.{v}" for n in ("src", "snk") for v in outs)]
    assert outs.index("y_String") < outs.index("y_Enumeration") < outs.index("y_Binary") < outs.index("steps")
    for col, v in e.items():
        if isinstance(v, bool):
            assert last[col] == ("true" if v else "false"), col  # not 1.0 / 0.0
        elif isinstance(v, int):
            assert last[col] == str(v), col  # not "1.8446744073709552e+19"
        elif isinstance(v, float):
            assert float(last[col]) == v, col
        else:
            assert last[col] == v, col
    assert last["src.steps"] == str(VALUES["UInt64"][1] + ROWS - 1)


@pytest.mark.parametrize("process", ["inprocess", "worker"])
def test_every_fmi3_type_through_connections_ssv_and_results(
    fmu: Path, fmpy_refs: dict[str, np.ndarray], tmp_path: Path, process: str
) -> None:
    from hevsim.cosim.system import run_cosim

    ssd = write_system(tmp_path, fmu, process=process)
    res = run_cosim(ssd, tmp_path / "out")
    check_results(res, fmpy_refs)
    check_csv(tmp_path / "out" / "results.csv")
    final = json.loads((tmp_path / "out" / "summary.json").read_text())["final"]
    assert final["snk.y_UInt64"] == 2**64 - 1 and final["snk.y_Int64"] == -(2**63)


def test_every_fmi3_type_through_the_cli(fmu: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from hevsim.cli import main

    ssd = write_system(tmp_path, fmu)
    assert main(["cosim", str(ssd), "--check"]) == 0
    assert main(["cosim", str(ssd), "--out", str(tmp_path / "out")]) == 0
    check_csv(tmp_path / "out" / "results.csv")


@pytest.mark.parametrize(
    ("src", "dst", "msg"),
    [
        ("y_Float32", "u_Int8", "src.y_Float32 is Real, snk.u_Int8 is Integer.*cannot connect a Real output to an Integer"),
        ("y_String", "u_Float64", "src.y_String is String, snk.u_Float64 is Real.*cannot connect a String output"),
        ("y_Binary", "u_String", "src.y_Binary is Binary, snk.u_String is String.*cannot connect a Binary output"),
        ("y_Float64", "u_Boolean", "src.y_Float64 is Real, snk.u_Boolean is Boolean"),
    ],
)  # fmt: skip
def test_mismatched_connection_is_refused_at_check_and_run(
    fmu: Path, tmp_path: Path, capsys: pytest.CaptureFixture, src: str, dst: str, msg: str
) -> None:
    from hevsim.cli import main
    from hevsim.cosim.system import run_cosim

    ssd = write_system(tmp_path, fmu, [(src, dst)], process="inprocess")
    capsys.readouterr()
    assert main(["cosim", str(ssd), "--check"]) == 2
    assert f"connection src.{src} -> snk.{dst}" in capsys.readouterr().err
    with pytest.raises(ConfigError, match=rf"connection src.{src} -> snk.{dst} \({msg}"):
        run_cosim(ssd, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_allowed_conversions_are_applied(fmu: Path, tmp_path: Path) -> None:
    from hevsim.cosim.system import run_cosim

    conns = [("y_Int8", "u_Float64"), ("y_Float32", "u_Float32"), ("y_Boolean", "u_Int16"),
             ("y_Enumeration", "u_Int64"), ("y_UInt8", "u_Enumeration")]  # fmt: skip
    ssd = write_system(
        tmp_path, fmu, conns, process="inprocess", params={"snk.p_Enumeration": -254, "snk.p_Int16": 5}
    )
    res = run_cosim(ssd, tmp_path / "out")
    assert res["snk.y_Float64"].tolist() == [-128.0 + 0.7] * ROWS  # Int8 -> Float64
    assert res["snk.y_Int16"].tolist() == [1 + 5] * ROWS  # Boolean -> Int16: True -> 1
    assert res["snk.y_Int64"].tolist() == [3 - 1] * ROWS  # Enumeration -> Int64
    assert res["snk.y_Enumeration"].tolist() == [255 - 254] * ROWS  # UInt8 -> Enumeration
    assert res["snk.y_Float32"][0] == float(np.float32(np.float32(0.1) + np.float32(0.2)) + np.float32(1 / 3))


def test_integers_out_of_range_are_refused_not_wrapped(
    fmu: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    from hevsim.cli import main
    from hevsim.cosim.system import run_cosim

    # a parameter: at --check
    ssd = write_system(tmp_path, fmu, [], process="inprocess", params={"snk.p_UInt8": 256})
    capsys.readouterr()
    assert main(["cosim", str(ssd), "--check"]) == 2
    assert "parameter 'p_UInt8' is a UInt8 (0 .. 255), got 256" in capsys.readouterr().err
    # a narrowing connection within the Integer class (Int64 -> Int8): at --check and at the run
    for a, b, msg in (
        ("y_Int64", "u_Int8", r"an Int64 output \(-9223372036854775808 .. 9223372036854775807\) into an Int8"),
        ("y_UInt8", "u_Int8", r"a UInt8 output \(0 .. 255\) into an Int8 input \(-128 .. 127\)"),
        ("y_Float64", "u_Float32", "a Float64 output into a Float32 input loses precision"),
    ):  # fmt: skip
        ssd = write_system(tmp_path, fmu, [(a, b)], process="inprocess")
        capsys.readouterr()
        assert main(["cosim", str(ssd), "--check"]) == 2
        err = capsys.readouterr().err
        assert f"connection src.{a} -> snk.{b}" in err and "narrowing connection" in err, err
        assert re.search(msg, err), err
        with pytest.raises(
            ConfigError, match=rf"connection src.{a} -> snk.{b} .*narrowing connection: {msg}"
        ):
            run_cosim(ssd, tmp_path / "out")
        assert not (tmp_path / "out").exists()
    with pytest.raises(ConfigError, match=r"parameter 'p_Binary' is a Binary: expected hexadecimal"):
        run_cosim(write_system(tmp_path, fmu, [], process="inprocess", params={"src.p_Binary": "xyz"}),
                  tmp_path / "out2")  # fmt: skip


def test_clock_variables_are_refused_by_name_not_dropped(
    fmu: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """An FMI 3.0 Clock cannot be exchanged (event mode): a connection naming one is refused at
    ``--check`` and by the run, saying why (a clock-to-clock link used to pass the check as a
    same-type link), and an unconnected clock output is reported as not recorded (it vanished)."""
    import shutil
    import warnings
    import zipfile

    from hevsim.cli import main
    from hevsim.cosim.participant import FMUParticipant
    from hevsim.cosim.system import run_cosim

    clocked = tmp_path / "clocked.fmu"
    with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(clocked, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                clock = '    <Clock name="tick" valueReference="9001" causality="output" intervalVariability="triggered"/>\n'
                data = data.decode().replace("  </ModelVariables>", clock + "  </ModelVariables>").encode()
            zout.writestr(item, data)
    ssd = write_system(tmp_path, clocked, [("tick", "u_Float64")], process="inprocess")
    capsys.readouterr()
    assert main(["cosim", str(ssd), "--check"]) == 2
    err = capsys.readouterr().err
    assert "src.tick is an FMI Clock variable" in err and "event mode" in err
    with pytest.raises(ConfigError, match=r"src\.tick is an FMI Clock variable"):
        run_cosim(ssd, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    shutil.copy(clocked, tmp_path / "alone.fmu")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        FMUParticipant("src", tmp_path / "alone.fmu")
    assert any("tick" in str(w.message) and "not exchanged or recorded" in str(w.message) for w in caught)


@pytest.mark.parametrize("process", ["inprocess", "worker"])
def test_a_value_out_of_range_names_the_phase_it_failed_in(fmu: Path, process: str) -> None:
    """An Integer source without an FMI type (a Python participant: not checked statically)
    feeding an Int8 input: the value out of range fails in set_inputs, also where a worker
    process sets the inputs with the output query (initial values) or with the step (before:
    "failed in get_outputs" / "failed in do_step")."""
    from hevsim.cosim.master import Connection, simulate
    from hevsim.cosim.participant import FMUParticipant, FunctionParticipant
    from hevsim.cosim.worker import WorkerFMUParticipant

    cls = FMUParticipant if process == "inprocess" else WorkerFMUParticipant
    for first, at in ((1000, "0"), (100, "0.1")):  # out of range at once / from the second step on

        def step(t: float, h: float, s: Any, u: dict[str, float]) -> tuple[Any, dict[str, float]]:
            return s, {"y": 1000}

        src = FunctionParticipant("src", step, None, {"y": first}, {})
        src.types = {"y": "Integer"}
        snk = cls("snk", fmu)
        try:
            with pytest.raises(
                CosimFault,
                match=rf"participant 'snk' failed in set_inputs at t = {at} s: .*input 'u_Int8' is an Int8 "
                r"\(-128 .. 127\), got 1000",
            ):
                simulate([src, snk], [Connection("src", "y", "snk", "u_Int8")], stop_time_s=0.3, step_s=0.1)
        finally:
            snk.terminate()

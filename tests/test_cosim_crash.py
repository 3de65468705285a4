"""A segfaulting FMU on the default path (issue 30 item 3): every FMU runs in a worker process
forked from the master (started in milliseconds), so an FMU that crashes in native code
becomes a CosimFault naming the participant, the call and the time, with the results up to
the last communication point written, and the master goes on."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from tests.cosim_cfmu import C_SOURCE, build_c_fmu

from hevsim.cosim.master import CosimFault

SEGV_SOURCE = C_SOURCE.replace(
    '#include "fmi2Functions.h"', '#include <signal.h>\n#include "fmi2Functions.h"'
).replace("    if (end > m->r[5]) {\n", "    if (end > m->r[5]) {\n        raise(SIGSEGV);\n", 1)
"""The C test FMU whose step crossing ``fail_at`` raises SIGSEGV (a crash in native code)."""


@pytest.fixture(scope="module")
def segv_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    assert SEGV_SOURCE.count("raise(SIGSEGV)") == 1
    return build_c_fmu(tmp_path_factory.mktemp("segv") / "segv.fmu", ident="CSegv", source=SEGV_SOURCE)


def ssd(d: Path, fmu: Path) -> Path:
    (d / fmu.name).write_bytes(fmu.read_bytes())
    p = d / "segv.ssd"
    p.write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:hevsim="https://hevsim.org/cosim" version="1.0" name="segv">
  <ssd:System name="segv"><ssd:Elements>
    <ssd:Component name="ok" type="application/x-fmu-sharedlibrary" source="{fmu.name}">
      <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
        <ssv:ParameterSet version="1.0" name="p"><ssv:Parameters>
          <ssv:Parameter name="u"><ssv:Real value="1"/></ssv:Parameter>
        </ssv:Parameters></ssv:ParameterSet>
      </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
    </ssd:Component>
    <ssd:Component name="bad" type="application/x-fmu-sharedlibrary" source="{fmu.name}">
      <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
        <ssv:ParameterSet version="1.0" name="p"><ssv:Parameters>
          <ssv:Parameter name="fail_at"><ssv:Real value="0.35"/></ssv:Parameter>
        </ssv:Parameters></ssv:ParameterSet>
      </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
    </ssd:Component>
  </ssd:Elements>
  <ssd:Connections>
    <ssd:Connection startElement="ok" startConnector="y" endElement="bad" endConnector="u"/>
  </ssd:Connections></ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="1"/>
</ssd:SystemStructureDescription>
""")
    return p


def test_a_segfaulting_fmu_does_not_take_the_master_down(segv_fmu: Path, tmp_path: Path) -> None:
    from hevsim.cosim.load import load_system
    from hevsim.cosim.system import build_participants, run_cosim
    from hevsim.cosim.worker import ForkedWorker, WorkerFMUParticipant

    with load_system(ssd(tmp_path, segv_fmu)) as desc:
        assert "fmu_process" not in desc.master  # the default path
        parts = build_participants(desc)
        try:
            assert all(
                isinstance(p, WorkerFMUParticipant) and isinstance(p.proc, ForkedWorker) for p in parts
            )
        finally:
            for p in parts:
                p.terminate()
    out = tmp_path / "out"
    with pytest.raises(
        CosimFault,
        match=r"participant 'bad' failed in do_step at t = 0.3 s: .*worker process crashed .*exit code -11",
    ):
        run_cosim(ssd(tmp_path, segv_fmu), out)
    # the results up to the last communication point, the fault in the summary
    with open(out / "results.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert [float(r[0]) for r in rows[1:]] == pytest.approx([0.0, 0.1, 0.2, 0.3])
    head = rows[0]
    assert float(rows[-1][head.index("ok.y")]) == pytest.approx(0.3)  # y = k u t, k = 1, u = 1
    assert float(rows[-1][head.index("bad.y")]) == pytest.approx(0.1 * (0.0 + 0.1 + 0.2))  # ok.y a step late
    assert "crashed" in json.loads((out / "summary.json").read_text())["error"]


def test_a_segfault_while_running_ahead_says_so(segv_fmu: Path) -> None:
    """A worker without inputs runs ahead (several steps per exchange): its crash is reported
    at the start of the steps it was running, saying which."""
    from hevsim.cosim.master import simulate
    from hevsim.cosim.worker import WorkerFMUParticipant

    bad = WorkerFMUParticipant("bad", segv_fmu, {"fail_at": 0.35})
    with pytest.raises(
        CosimFault,
        match=r"participant 'bad' failed in do_step at t = 0 s: .*worker process crashed in steps "
        r"\(exit code -11\) while running 10 steps ahead from t = 0 s to 1 s",
    ):
        simulate([bad], [], stop_time_s=1.0, step_s=0.1)


def test_auto_runs_trusted_fmus_in_process_and_others_in_forked_workers(
    segv_fmu: Path, tmp_path: Path
) -> None:
    """fmu_process "auto" (the default): a pythonfmu FMU (Python model code) in process, a
    foreign C FMU in a forked worker; "worker" / "inprocess" put both one way; the summary
    says where each ran."""
    from hevsim.cosim.participant import FMUParticipant
    from hevsim.cosim.ssd import FMU_TYPE, Component, SystemDescription
    from hevsim.cosim.system import build_participants, run_cosim, trusted_fmu
    from hevsim.cosim.trivial import build_integrator_fmu
    from hevsim.cosim.worker import WorkerFMUParticipant

    py = build_integrator_fmu(tmp_path / "py.fmu", name="AutoPy", y0=1.0)
    (tmp_path / "c.fmu").write_bytes(segv_fmu.read_bytes())
    assert trusted_fmu(py) and not trusted_fmu(tmp_path / "c.fmu")
    import zipfile

    from hevsim.battery.native import is_native_fmu

    native = tmp_path / "native.fmu"  # what trusted_fmu reads of an FMU hevsim generated
    with zipfile.ZipFile(native, "w") as z:
        z.writestr(
            "modelDescription.xml", '<fmiModelDescription generationTool="hevsim 9 (native C99 FMU)"/>'
        )
    assert trusted_fmu(native) == "an FMU hevsim generated (native C99)" and is_native_fmu(native)
    comps = [Component("py", FMU_TYPE, "py.fmu"), Component("c", FMU_TYPE, "c.fmu")]
    for mode, kinds in (
        (None, (FMUParticipant, WorkerFMUParticipant)),
        ("worker", (WorkerFMUParticipant, WorkerFMUParticipant)),
        ("inprocess", (FMUParticipant, FMUParticipant)),
    ):
        master = {"step_s": 0.1} | ({"fmu_process": mode} if mode else {})
        desc = SystemDescription("auto", comps, [], stop_time_s=0.5, master=master, base_dir=tmp_path)
        parts = build_participants(desc)
        try:
            assert [type(p) for p in parts] == list(kinds), mode
        finally:
            for p in parts:
                p.terminate()
    desc = SystemDescription("auto", comps, [], stop_time_s=0.5, master={"step_s": 0.1}, base_dir=tmp_path)
    run_cosim(desc, tmp_path / "out")
    stats = json.loads((tmp_path / "out" / "summary.json").read_text())["stats"]
    assert stats["fmu_process"] == {"py": "in process", "c": "worker process"}

"""Defaults as other masters take them and results as users read them (issue 30 items 4, 5):
the step from the FMUs' DefaultExperiment, Booleans as true / false and the columns in the
listing order in results.csv, where --resume went on from, a final checkpoint."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.cosim_cfmu import build_c_fmu, model_description

from hevsim.cosim.master import simulate
from hevsim.cosim.participant import FunctionParticipant


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The C test FMU twice in one folder: ``c.fmu`` (DefaultExperiment stepSize 0.1 s) and
    ``c05.fmu`` (0.05 s)."""
    d = tmp_path_factory.mktemp("defaults")
    build_c_fmu(d / "c.fmu")
    build_c_fmu(
        d / "c05.fmu",
        ident="CTestModel05",
        description=lambda ident: model_description(ident).replace('stepSize="0.1"', 'stepSize="0.05"'),
    )
    return d


def write_ssd(d: Path, name: str, comps: dict[str, str], master: str = "") -> Path:
    elems = "".join(
        f'<ssd:Component name="{n}" type="application/x-fmu-sharedlibrary" source="{f}"/>\n'
        for n, f in comps.items()
    )
    ann = (
        '<ssd:Annotations><ssc:Annotation type="org.hevsim.cosim">'
        f"<hevsim:Master {master}/></ssc:Annotation></ssd:Annotations>"
        if master
        else ""
    )
    p = d / f"{name}.ssd"
    p.write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:hevsim="https://hevsim.org/cosim" version="1.0" name="{name}">
  <ssd:System name="{name}"><ssd:Elements>
{elems}  </ssd:Elements></ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="1">{ann}</ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
""")
    return p


def test_step_from_the_fmus_default_experiment(
    fmus: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """No step in the SSD: the largest step every FMU accepts (the smaller DefaultExperiment
    stepSize, as FMPy takes an FMU's), stated in the summary (before: exit 2)."""
    from hevsim.cli import main

    ssd = write_ssd(fmus, "nostep", {"a": "c.fmu", "b": "c05.fmu"}, master='fmu_process="inprocess"')
    assert main(["cosim", str(ssd), "--check"]) == 0
    out = tmp_path / "out"
    assert main(["cosim", str(ssd), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "step_s = 0.05 s from the FMUs' DefaultExperiment stepSize (a 0.1 s, b 0.05 s)" in said, said
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stats"]["step_s"] == 0.05 and summary["stats"]["steps"] == 20
    with open(out / "results.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert [float(r[0]) for r in rows[1:]] == pytest.approx(np.linspace(0.0, 1.0, 21).tolist(), abs=1e-12)


def test_results_csv_booleans_and_listing_order(fmus: Path, tmp_path: Path) -> None:
    """Booleans are written true / false (before 0.0 / 1.0); the columns follow the listing of
    the components and each FMU's model description (String and Binary outputs among the
    others: tests/test_cosim_fmi3_types.py)."""
    from fmpy import read_model_description

    from hevsim.cosim.system import run_cosim

    ssd = write_ssd(
        fmus, "order", {"z": "c.fmu", "a": "c.fmu"}, master='step_s="0.1" fmu_process="inprocess"'
    )
    run_cosim(ssd, tmp_path / "out")
    with open(tmp_path / "out" / "results.csv", newline="") as f:
        rows = list(csv.reader(f))
    outs = [
        v.name for v in read_model_description(str(fmus / "c.fmu")).modelVariables if v.causality == "output"
    ]
    assert rows[0] == ["time_s", *(f"{n}.{v}" for n in ("z", "a") for v in outs)]
    first, last = dict(zip(rows[0], rows[1], strict=True)), dict(zip(rows[0], rows[-1], strict=True))
    assert first["z.b"] == "false" and first["z.bo"] == "true"  # y = 0 <= 0.5; bo = not bi = not false
    assert {r[rows[0].index("a.b")] for r in rows[1:]} == {"false"}
    assert last["a.n"] == "10" and float(last["a.y"]) == 0.0


def counter(name: str = "c") -> FunctionParticipant:
    def step(t: float, h: float, s: float, u: dict[str, float]) -> tuple[float, dict[str, float]]:
        return s + 1, {"n": s + 1, "t": t + h}

    return FunctionParticipant(name, step, 0.0, {"n": 0.0, "t": 0.0}, {})


def test_a_run_shorter_than_the_checkpoint_interval_has_a_final_checkpoint(tmp_path: Path) -> None:
    """10 steps, a checkpoint every 50: the end is checkpointed (before: no checkpoint at all),
    and resuming says where it went on from and returns the same results without stepping."""
    ck = tmp_path / "ck.pkl"
    full = simulate([counter()], [], stop_time_s=1.0, step_s=0.1, checkpoint_path=ck, checkpoint_every=50)
    assert ck.is_file() and "resume" not in full.stats
    again = simulate([counter()], [], stop_time_s=1.0, step_s=0.1, checkpoint_path=ck, resume=True)
    assert again.stats["resume"] == "resumed from the checkpoint at t = 1 s (step 10)"
    assert np.array_equal(again.data, full.data) and np.array_equal(again.time_s, full.time_s)
    assert again.stats["steps"] == 10


def test_resume_says_where_it_went_on_from(fmus: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """An interrupted run resumed: in process (a participant with state: from the checkpoint's
    time and step) and through the command line (the C FMU has no state: replayed and checked
    against the stored rows up to the checkpoint's time and step)."""
    from hevsim.cli import main
    from hevsim.cosim.system import run_cosim

    ck = tmp_path / "ck.pkl"

    def stop_at(t_stop: float) -> Any:
        def progress(t: float, stop: float) -> None:
            if t >= t_stop - 1e-9:
                raise KeyboardInterrupt

        return progress

    with pytest.raises(KeyboardInterrupt):
        simulate([counter()], [], stop_time_s=1.0, step_s=0.1, checkpoint_path=ck, checkpoint_every=3,
                 progress=stop_at(0.5))  # fmt: skip
    res = simulate([counter()], [], stop_time_s=1.0, step_s=0.1, checkpoint_path=ck, resume=True)
    assert res.stats["resume"] == "resumed from the checkpoint at t = 0.3 s (step 3)"
    assert res["c.n"].tolist() == list(range(11))

    ssd = write_ssd(
        fmus, "resume", {"a": "c.fmu"}, master='step_s="0.1" fmu_process="inprocess" checkpoint_every="2"'
    )
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        run_cosim(ssd, out, progress=stop_at(0.5))
    capsys.readouterr()
    assert main(["cosim", str(ssd), "--out", str(out), "--resume"]) == 0
    said = capsys.readouterr().out
    assert "replayed from t = 0 s" in said and "rows stored up to t = 0.4 s (step 4)" in said, said
    assert not list(tmp_path.glob(".out.checkpoint*"))  # the finished run left no checkpoint files

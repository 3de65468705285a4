"""Running a co-simulation configuration: :func:`build_participants` (the participants of a
:class:`~hevsim.cosim.ssd.SystemDescription`), :func:`run_system` (check, build, run the
master) and :func:`run_cosim` (a configuration file or description to a results folder)."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hevsim.cosim.datacheck import datacheck, default_step
from hevsim.cosim.load import load_system
from hevsim.cosim.master import CosimResult, Options, simulate
from hevsim.cosim.participant import Participant
from hevsim.cosim.ssd import COMPONENT_TYPES, FMU_TYPE, PY_TYPE, SystemDescription
from hevsim.cosim.ssp_write import ssd_xml
from hevsim.errors import ConfigError

if TYPE_CHECKING:
    from hevsim.cosim.worker import WorkerFMUParticipant


def build_participants(
    desc: SystemDescription, log_level: str = "error", fmu_log: str | Path | None = None
) -> list[Participant]:
    """Instantiate the participants of ``desc`` (their FMUs' logger messages from ``log_level``
    up on stderr, all of them in ``fmu_log``). Where an FMU runs follows the master setting
    ``fmu_process``: "auto" (the default) runs the FMUs :func:`trusted_fmu` names in process
    and every other one in a worker process forked from the master (a crash in its native
    code ends only the worker); "worker" runs every FMU in a worker, "inprocess" none."""
    from hevsim.cosim.participant import FMUParticipant

    mode = desc.master.get("fmu_process", "auto")
    clocked = clock_connected(desc) if mode == "auto" else set()
    parts: list[Participant] = []
    for c in desc.components:
        if c.type == FMU_TYPE:
            path = desc.base_dir / c.source
            if mode == "inprocess" or (mode == "auto" and (c.name in clocked or trusted_fmu(path))):
                from hevsim.cosim.me import participant_class  # (Model Exchange FMUs: MEParticipant)

                cls: type[FMUParticipant] | type[WorkerFMUParticipant] = participant_class(path)
            else:
                from hevsim.cosim.worker import WorkerFMUParticipant

                cls = WorkerFMUParticipant
            parts.append(cls(c.name, desc.base_dir / c.source, c.parameters, log_level, fmu_log))
        elif c.type == PY_TYPE:
            mod, _, fn = c.source.partition(":")
            try:
                factory = getattr(importlib.import_module(mod), fn)
            except (ImportError, AttributeError, ValueError) as exc:
                raise ConfigError(
                    f"{desc.source}: component {c.name!r}: cannot import {c.source!r} ({exc})."
                ) from None
            params = {
                k: str((desc.base_dir / v).resolve())
                if isinstance(v, str) and v.startswith(("./", "../"))
                else v
                for k, v in c.parameters.items()
            }
            parts.append(factory(name=c.name, **params))
        else:
            raise ConfigError(
                f"{desc.source}: component {c.name!r} is not bound to an implementation (type {c.type!r})."
            )
    return parts


def clock_connected(desc: SystemDescription) -> set[str]:
    """FMU components of ``desc`` with an FMI 3.0 Clock variable in a connection: under
    ``fmu_process="auto"`` they run in process (clock connections need it)."""
    import zipfile
    from xml.etree import ElementTree as ET

    named: dict[str, set[str]] = {}
    for k in desc.connections:
        named.setdefault(k.src, set()).add(k.src_var)
        named.setdefault(k.dst, set()).add(k.dst_var)
    out = set()
    for c in desc.components:
        if c.type != FMU_TYPE or c.name not in named:
            continue
        try:
            with zipfile.ZipFile(desc.base_dir / c.source) as z:
                root = ET.fromstring(z.read("modelDescription.xml"))
        except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError):
            continue  # (reported by the participant)
        clocks = {el.get("name") for el in root.iter() if el.tag.rsplit("}", 1)[-1] == "Clock"}
        if clocks & named[c.name]:
            out.add(c.name)
    return out


def trusted_fmu(path: str | Path) -> str:
    """Why the FMU ``path`` runs in process under ``fmu_process="auto"`` ("": it does not, it
    runs in a forked worker process): a pythonfmu FMU (its model is Python code run by this
    interpreter: a failure is a Python exception the FMU returns as an FMI error, not a crash)
    or an FMU hevsim generated (its ``generationTool`` names hevsim's native C99 generator,
    as :func:`hevsim.battery.native.is_native_fmu` reads it; not imported here: that package
    imports numba and pandas, a second of start-up)."""
    import zipfile
    from xml.etree import ElementTree as ET

    try:
        with zipfile.ZipFile(path) as z:
            if "resources/slavemodule.txt" in z.namelist():
                return "a pythonfmu FMU (Python model code)"
            root = ET.fromstring(z.read("modelDescription.xml"))
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError):
        return ""  # (reported by the participant)
    return (
        "an FMU hevsim generated (native C99)" if "(native C99 FMU)" in root.get("generationTool", "") else ""
    )


def run_system(
    desc: SystemDescription,
    progress: Callable[[float, float], None] | None = None,
    checkpoint_path: str | Path | None = None,
    resume: bool = False,
    log_level: str = "error",
    fmu_log: str | Path | None = None,
) -> CosimResult:
    """Check ``desc``, build its participants and run the master."""
    datacheck(desc)
    for c in desc.components:
        if c.type not in COMPONENT_TYPES:
            raise ConfigError(
                f"{desc.source}: component {c.name!r} is not bound to an implementation (type {c.type!r})."
            )
    m = dict(desc.master)
    m.pop("fmu_process", None)
    step_note = ""
    if "step_s" not in m:
        m["step_s"], step_note = default_step(desc)
    opts = Options(
        stop_time_s=desc.stop_time_s, start_time_s=desc.start_time_s, checkpoint_path=checkpoint_path, **m
    )
    opts.check()
    parts = build_participants(desc, log_level, fmu_log)
    res = simulate(parts, desc.connections, progress=progress, resume=resume, extra_units=desc.units,
                   **vars(opts))  # fmt: skip
    res.stats["fmu_process"] = {
        p.name: "worker process" if hasattr(p, "proc") else "in process" for p in parts if hasattr(p, "fmu")
    }
    if step_note:
        res.stats["step_s"], res.stats["step_from"] = opts.step_s, step_note
    return res


def run_cosim(
    config_path: str | Path | SystemDescription,
    out_dir: str | Path,
    progress: Callable[[float, float], None] | None = None,
    resume: bool = False,
    log_level: str = "error",
    fmu_log: str | Path | None = None,
) -> CosimResult:
    """Run the configuration ``config_path`` (``.ssp`` / ``.ssd`` / a bound CSE ``.xml``, or a
    :class:`SystemDescription`) and write ``out_dir``:
    ``results.csv`` (every output vs time), ``summary.json`` (final values, step
    statistics, stop reason), the system as ``system.ssd`` and ``pictures/*.png``
    (:func:`hevsim.cosim.plots.plot_cosim`), plus what participants keep beyond their
    outputs (:meth:`~hevsim.cosim.participant.Participant.write_fields`: the FEM module's
    temperature fields ``fields/*.vtu`` with a ``.pvd``, plate and cell pictures; listed with
    the hot spots under ``fields`` in ``summary.json``). A checkpoint
    ``<out_dir>.checkpoint`` is kept while running; with ``resume`` a killed run continues
    from it. On a participant fault the results so far are written to ``out_dir`` before
    the error is raised. A temporary folder an ``.ssp`` is extracted to is removed at the end
    (also on error) when ``config_path`` is a file."""
    from hevsim.cosim.master import CosimFault
    from hevsim.io import atomic_directory, write_json

    if not isinstance(config_path, SystemDescription):
        with load_system(config_path) as desc:
            return run_cosim(desc, out_dir, progress, resume, log_level, fmu_log)
    desc = config_path
    out = Path(out_dir)
    ck = out.with_name(f".{out.name}.checkpoint")

    def write(res: CosimResult, error: str | None) -> None:
        with atomic_directory(out) as tmp:
            res.write_csv(tmp / "results.csv")
            final = {
                c: res.integers[c][-1] if c in res.integers else float(res.data[-1, i])
                for i, c in enumerate(res.columns)
            } if len(res.data) else {}  # fmt: skip
            fields: dict[str, Any] = {}
            if len(res.data):
                from hevsim.cosim.plots import plot_cosim

                plot_cosim(res, desc, tmp / "pictures")
                fields = {n: p.write_fields(tmp) for n, p in res.participants.items()}
            write_json(tmp / "summary.json", {
                "config": desc.source, "final": final, "stats": res.stats,
                "stopped_by": res.stopped_by, "error": error,
                "fields": {n: f for n, f in fields.items() if f},
            })  # fmt: skip
            (tmp / "system.ssd").write_bytes(ssd_xml(desc))

    out.parent.mkdir(parents=True, exist_ok=True)  # the checkpoint streams live beside out_dir
    try:
        res = run_system(desc, progress, ck, resume, log_level, fmu_log)
    except CosimFault as exc:
        if exc.partial is not None:
            write(exc.partial, str(exc))
        raise
    write(res, None)
    for f in (ck, ck.with_name(ck.name + ".rows"), ck.with_name(ck.name + ".text")):
        f.unlink(missing_ok=True)  # (the run is in out_dir: nothing left to resume)
    return res

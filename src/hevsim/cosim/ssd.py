"""The native system description and its reading from SSP: :class:`SystemDescription`
(components, connections, units, master settings), :func:`read_ssd` (an ``.ssd`` XML file)
and :func:`read_ssp` (an ``.ssp`` archive). Writing is in :mod:`hevsim.cosim.ssp_write`,
the SIMULIA CSE import in :mod:`hevsim.cosim.cse`.

Component types in an SSD:

* ``application/x-fmu-sharedlibrary`` (SSP's FMU type): ``source`` is the FMU path relative
  to the SSD (or inside the ``.ssp``); where it runs follows the master annotation's
  ``fmu_process``: ``"auto"`` (default: pythonfmu FMUs and FMUs hevsim generated in
  process, others in a worker process forked from the master), ``"worker"``, ``"inprocess"``
  (:func:`hevsim.cosim.system.build_participants`);
* ``application/x-hevsim-python``: ``source`` is ``"package.module:factory"``; the factory is
  called with ``name=`` and the component's parameters as keyword arguments (a string
  parameter starting with ``./`` or ``../`` is a path relative to the SSD) and returns a
  :class:`hevsim.cosim.participant.Participant` (for example
  ``hevsim.cosim.participant:StepperParticipant``).

Master settings go in ``ssd:DefaultExperiment`` (``startTime``, ``stopTime``) and an
``ssc:Annotation type="org.hevsim.cosim"`` holding ``<hevsim:Master algorithm=... step_s=...
negotiation=... max_iterations=... tolerance=... relaxation=... order="a b"
send_before_receive="a:false" rates="fem:5" fmu_process=... checkpoint_every=.../>``
(``checkpoint_every="50"``: a checkpoint every 50 communication steps; ``"30s"``: every 30 s
of wall time, the default).
"""

from __future__ import annotations

import shutil
import tempfile
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hevsim.cosim import units as U
from hevsim.cosim._xml import local_name, number, parse_xml, required
from hevsim.cosim.master import Connection
from hevsim.errors import ConfigError

SSD_NS = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC_NS = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV_NS = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
HEV_NS = "https://hevsim.org/cosim"
FMU_TYPE = "application/x-fmu-sharedlibrary"
PY_TYPE = "application/x-hevsim-python"
COMPONENT_TYPES = (FMU_TYPE, PY_TYPE)
NS = {"ssd": SSD_NS, "ssc": SSC_NS, "ssv": SSV_NS, "hevsim": HEV_NS}

OPTION_TYPES: dict[str, Callable[[str], Any]] = {
    "algorithm": str.lower,
    "step_s": float,
    "negotiation": str.lower,
    "min_step_s": float,
    "max_step_s": float,
    "max_iterations": int,
    "tolerance": float,
    "relaxation": float,
    "hold": str,
    "record_every": int,
}


@dataclass
class Connector:
    """A component's variable: ``kind`` input / output / parameter, ``unit`` ("" unknown)."""

    name: str
    kind: str
    unit: str = ""
    type: str = "Real"
    """Type class: Real, Integer, Enumeration, Boolean, String (:mod:`hevsim.cosim.fmi_vars`)."""
    fmi_type: str = ""
    """The FMI type (Float64, Float32, Int8 .. UInt64, FMI 2.0 Integer ..; "" unknown): narrowing
    connections (Int64 -> Int8, Float64 -> Float32) are refused (:func:`~hevsim.cosim.fmi_vars.narrowing`)."""


@dataclass
class Component:
    """One participant: ``type`` (:data:`COMPONENT_TYPES`), ``source``, ``parameters``."""

    name: str
    type: str
    source: str
    connectors: list[Connector] = field(default_factory=list)
    parameters: dict[str, Any] = field(default_factory=dict)


@dataclass
class SystemDescription:
    """The native system description (what an SSD holds)."""

    name: str
    components: list[Component]
    connections: list[Connection]
    start_time_s: float = 0.0
    stop_time_s: float = 1.0
    master: dict[str, Any] = field(default_factory=dict)
    units: dict[str, U.Unit] = field(default_factory=dict)
    base_dir: Path = field(default_factory=Path)
    source: str = "system"
    scratch_dir: Path | None = None
    """A temporary folder this description owns (the FMUs extracted from an ``.ssp`` by
    :func:`read_ssp`); :meth:`cleanup` removes it. ``None``: nothing to remove."""

    def cleanup(self) -> None:
        """Remove :attr:`scratch_dir` (and everything in it), if any."""
        if self.scratch_dir is not None:
            shutil.rmtree(self.scratch_dir, ignore_errors=True)
            self.scratch_dir = None

    def __enter__(self) -> SystemDescription:
        return self

    def __exit__(self, *exc: object) -> None:
        self.cleanup()

    def component(self, name: str) -> Component:
        """The component called ``name``."""
        for c in self.components:
            if c.name == name:
                return c
        raise ConfigError(
            f"{self.source}: no component {name!r}; components: {[c.name for c in self.components]}."
        )


_CONNECTOR_TYPES = {
    "Real": "Real", "Float64": "Real", "Float32": "Real", "Integer": "Integer", "Int8": "Integer",
    "UInt8": "Integer", "Int16": "Integer", "UInt16": "Integer", "Int32": "Integer", "UInt32": "Integer",
    "Int64": "Integer", "UInt64": "Integer", "Boolean": "Boolean", "String": "String",
    "Enumeration": "Enumeration", "Binary": "Binary",
}  # fmt: skip
"""Type elements of an ``ssd:Connector`` (SSP 1.0 ``ssc:Real`` ..., SSP 2.0 ``ssc:Float64`` ...)."""


# --------------------------------------------------------------------------- typed values
def _value(text: str) -> Any:
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return text


def _typed(tag: str, text: str, where: str) -> Any:
    try:
        if tag == "Real":
            return float(text)
        if tag in ("Integer", "Enumeration"):
            return int(text)
        if tag == "Boolean":
            if text.strip().lower() not in ("true", "false", "1", "0"):
                raise ValueError(text)
            return text.strip().lower() in ("true", "1")
    except ValueError:
        raise ConfigError(f"{where}: value {text!r} is not a valid {tag}.") from None
    if tag in ("String", "Binary"):  # Binary: hexadecimal text, as SSV writes it
        return text
    return _value(text)


# --------------------------------------------------------------------------- SSD / SSP read
def read_ssd(path: str | Path, text: bytes | None = None, base_dir: Path | None = None) -> SystemDescription:
    """Read an SSP system structure description (``.ssd``) into a :class:`SystemDescription`.

    Raises :class:`ConfigError` naming the file and element on a structural error."""
    path = Path(path)
    root = parse_xml(path, text)
    src = str(path)
    if root.tag != f"{{{SSD_NS}}}SystemStructureDescription":
        raise ConfigError(
            f"{src}: root element is <{local_name(root.tag)}>, expected <ssd:SystemStructureDescription>."
        )
    system = root.find("ssd:System", NS)
    if system is None:
        raise ConfigError(f"{src}: <ssd:SystemStructureDescription> has no <ssd:System> element.")
    units: dict[str, U.Unit] = {}
    for u in root.findall("ssd:Units/ssc:Unit", NS):
        name = required(u, "name", f"{src}: <ssc:Unit>")
        base = u.find("ssc:BaseUnit", NS)
        units[name] = U.unit_from_base(name, dict(base.attrib) if base is not None else {})
    comps: list[Component] = []
    for i, el in enumerate(system.findall("ssd:Elements/ssd:Component", NS)):
        where = f"{src}: <ssd:Component> #{i + 1}"
        name = required(el, "name", where)
        where = f"{src}: component {name!r}"
        ctype = el.get("type", FMU_TYPE)
        if ctype not in COMPONENT_TYPES:
            raise ConfigError(f"{where}: type {ctype!r}; valid: {', '.join(COMPONENT_TYPES)}.")
        conns = []
        for c in el.findall("ssd:Connectors/ssd:Connector", NS):
            cname = required(c, "name", where + " <ssd:Connector>")
            kind = required(c, "kind", f"{where}: connector {cname!r}")
            if kind not in ("input", "output", "parameter", "calculatedParameter", "inout"):
                raise ConfigError(
                    f"{where}: connector {cname!r}: kind {kind!r}; valid: input, output, parameter."
                )
            typed = next((t for t in c if local_name(t.tag) in _CONNECTOR_TYPES), None)
            vtype = _CONNECTOR_TYPES[local_name(typed.tag)] if typed is not None else "Real"
            unit = (typed.get("unit") or "") if typed is not None and vtype == "Real" else ""
            tag = local_name(typed.tag) if typed is not None else ""
            sized = tag in ("Float32", "Float64") or (tag[:3] in ("Int", "UIn") and tag != "Integer")
            conns.append(Connector(cname, kind, unit, vtype, tag if sized else ""))
        params: dict[str, Any] = {}
        for pb in el.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS):
            params.update(_binding(pb, base_dir if base_dir is not None else path.parent, where))
        comps.append(Component(name, ctype, required(el, "source", where), conns, params))
    connections = []
    for i, el in enumerate(system.findall("ssd:Connections/ssd:Connection", NS)):
        where = f"{src}: <ssd:Connection> #{i + 1}"
        se, sc = required(el, "startElement", where), required(el, "startConnector", where)
        ee, ec = required(el, "endElement", where), required(el, "endConnector", where)
        connections.append(Connection(se, sc, ee, ec))
    desc = SystemDescription(
        system.get("name") or root.get("name") or path.stem, comps, connections, units=units,
        base_dir=base_dir if base_dir is not None else path.parent, source=src,
    )  # fmt: skip
    exp = root.find("ssd:DefaultExperiment", NS)
    if exp is not None:
        desc.start_time_s = number(exp.get("startTime", "0"), f"{src}: DefaultExperiment startTime")
        desc.stop_time_s = number(exp.get("stopTime", "1"), f"{src}: DefaultExperiment stopTime")
        m = exp.find(".//hevsim:Master", NS)
        if m is not None:
            desc.master = _master_options(dict(m.attrib), f"{src}: <hevsim:Master>")
        if "step_s" not in desc.master:  # the common tool annotations
            for a in exp.iter():
                name = local_name(a.tag)
                key = {"FixedStepAlgorithm": ("baseStepSize", "stepSize"), "FixedStepMaster": ("stepSize",)}
                for attr in key.get(name, ()):
                    if a.get(attr) is not None:
                        desc.master["step_s"] = number(a.get(attr, ""), f"{src}: <{name}> {attr}")
                        break
                if "step_s" in desc.master:
                    break
    return desc


def _source_file(base: Path, source: str, where: str, what: str) -> Path:
    """The file a ``source`` attribute names (relative to ``base``); ConfigError if missing."""
    f = base / source
    if not f.is_file():
        raise ConfigError(f"{where}: {what} file {str(f)!r} (source={source!r}) does not exist.")
    return f


def _binding(pb: Any, base: Path, where: str) -> dict[str, Any]:
    """Parameter values of one ``ssd:ParameterBinding``: inline ``ssv:ParameterSet`` or an
    ``.ssv`` file (``source``), names without the binding's ``prefix``, renamed and linearly
    transformed by an inline or ``.ssm`` ``ssd:ParameterMapping``."""
    source = pb.get("source")
    if source:
        f = _source_file(base, source, where, "parameter values")
        pset = parse_xml(f)
        pwhere = f"{f}"
    else:
        pset = pb.find("ssd:ParameterValues/ssv:ParameterSet", NS)
        pwhere = where
    out: dict[str, Any] = {}
    if pset is None:
        return out
    if local_name(pset.tag) != "ParameterSet":
        raise ConfigError(f"{pwhere}: root element is <{local_name(pset.tag)}>, expected <ssv:ParameterSet>.")
    prefix = pb.get("prefix", "")
    for p in pset.findall(".//ssv:Parameter", NS):
        pname = required(p, "name", pwhere + " <ssv:Parameter>")
        val = next((c for c in p if local_name(c.tag) != "Unit"), None)
        if val is None or val.get("value") is None:
            raise ConfigError(f"{pwhere}: parameter {pname!r} has no typed value element.")
        if prefix and pname.startswith(prefix):
            pname = pname[len(prefix) :]
        out[pname] = _typed(local_name(val.tag), val.get("value", ""), f"{pwhere}: parameter {pname!r}")
    mapping = pb.find("ssd:ParameterMapping", NS)
    if mapping is not None:
        msrc = mapping.get("source")
        if msrc:
            mf = _source_file(base, msrc, where, "parameter mapping")
            mroot, mwhere = parse_xml(mf), str(mf)
        else:
            mroot, mwhere = mapping, where
        for e in mroot.iter():
            if local_name(e.tag) != "MappingEntry":
                continue
            s, t = required(e, "source", mwhere + " <ssm:MappingEntry>"), required(e, "target", mwhere)
            if s not in out:
                raise ConfigError(
                    f"{mwhere}: mapping entry source {s!r} is not a parameter; parameters: {sorted(out)}."
                )
            v = out.pop(s)
            lin = next((c for c in e if local_name(c.tag) == "LinearTransformation"), None)
            if lin is not None:
                if isinstance(v, (bool, str)):
                    raise ConfigError(f"{mwhere}: linear transformation of the non-numeric parameter {s!r}.")
                f_, o_ = float(lin.get("factor", "1")), float(lin.get("offset", "0"))
                v = f_ * v + o_
            out[t] = v
    return out


def _pairs(value: str, key: str, where: str) -> list[tuple[str, str]]:
    """``"a:x b:y"`` -> ``[("a", "x"), ("b", "y")]``."""
    items = [item.split(":") for item in value.split()]
    if any(len(i) != 2 or not all(i) for i in items):
        raise ConfigError(f"{where}: {key}={value!r}: expected space-separated 'participant:value' pairs.")
    return [(a, b) for a, b in items]


def _master_options(attrs: dict[str, str], where: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in attrs.items():
        if k == "order":
            out[k] = v.split()
        elif k == "send_before_receive":
            out[k] = {a: b.lower() == "true" for a, b in _pairs(v, k, where)}
        elif k == "rates":
            try:
                out[k] = {a: int(b) for a, b in _pairs(v, k, where)}
            except ValueError:
                raise ConfigError(f"{where}: rates={v!r}: expected 'participant:integer ...'.") from None
        elif k == "checkpoint_every":  # "50": every 50 steps; "30s": every 30 s of wall time
            try:
                if v.strip().endswith("s"):
                    out["checkpoint_wall_s"] = float(v.strip()[:-1])
                else:
                    out[k] = int(v)
            except ValueError:
                raise ConfigError(
                    f"{where}: checkpoint_every={v!r}: expected a number of steps ('50') or a "
                    "wall-clock interval in seconds ('30s')."
                ) from None
        elif k == "fmu_process":
            if v not in ("auto", "worker", "inprocess"):
                raise ConfigError(f"{where}: fmu_process {v!r}; valid: auto, worker, inprocess.")
            out[k] = v
        elif k in OPTION_TYPES:
            try:
                out[k] = OPTION_TYPES[k](v)
            except ValueError:
                raise ConfigError(
                    f"{where}: attribute {k}={v!r} is not a valid {OPTION_TYPES[k].__name__}."
                ) from None
        else:
            valid = sorted([*OPTION_TYPES, "order", "send_before_receive", "rates", "fmu_process",
                            "checkpoint_every"])  # fmt: skip
            raise ConfigError(f"{where}: unknown attribute {k!r}; valid: {', '.join(valid)}.")
    return out


def read_ssp(path: str | Path, extract_to: str | Path | None = None) -> SystemDescription:
    """Read an ``.ssp`` archive. Its FMUs are extracted to ``extract_to`` or, without it, to a
    temporary ``hevsim-ssp-*`` folder that the returned description owns
    (:attr:`SystemDescription.scratch_dir`): remove it with :meth:`~SystemDescription.cleanup`
    or use the description as a context manager (``with read_ssp(p) as desc: ...``)."""
    path = Path(path)
    try:
        z = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise ConfigError(f"{path}: not a readable SSP archive ({exc}).") from None
    with z:
        if "SystemStructure.ssd" not in z.namelist():
            raise ConfigError(f"{path}: the archive has no SystemStructure.ssd.")
        scratch = None if extract_to else Path(tempfile.mkdtemp(prefix="hevsim-ssp-"))
        dest = Path(extract_to) if extract_to else scratch
        assert dest is not None
        try:
            z.extractall(dest)
            desc = read_ssd(dest / "SystemStructure.ssd", base_dir=dest)
        except BaseException:
            if scratch is not None:
                shutil.rmtree(scratch, ignore_errors=True)
            raise
    desc.source = f"{path}!SystemStructure.ssd"
    desc.scratch_dir = scratch
    return desc

"""Co-simulation configurations: SSP (``.ssp`` archive / ``.ssd`` XML, the native system
description), an importer for the SIMULIA co-simulation engine (CSE) XML of the thesis
(appendix 3), :func:`datacheck` (section 4.1.4's five requirements) and :func:`run_cosim`.

Component types in an SSD:

* ``application/x-fmu-sharedlibrary`` (SSP's FMU type): ``source`` is the FMU path relative
  to the SSD (or inside the ``.ssp``); run in a worker process unless the master annotation
  says ``fmu_process="inprocess"``;
* ``application/x-hevsim-python``: ``source`` is ``"package.module:factory"``; the factory is
  called with ``name=`` and the component's parameters as keyword arguments (a string
  parameter starting with ``./`` or ``../`` is a path relative to the SSD) and returns a
  :class:`hevsim.cosim.participant.Participant` (for example
  ``hevsim.cosim.participant:StepperParticipant``).

Master settings go in ``ssd:DefaultExperiment`` (``startTime``, ``stopTime``) and an
``ssc:Annotation type="org.hevsim.cosim"`` holding ``<hevsim:Master algorithm=... step_s=...
negotiation=... max_iterations=... tolerance=... relaxation=... order="a b"
send_before_receive="a:false" rates="fem:5" fmu_process=.../>``.
"""

from __future__ import annotations

import importlib
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hevsim.cosim import units as U
from hevsim.cosim.master import Connection, CosimResult, Options, simulate
from hevsim.cosim.participant import Participant
from hevsim.errors import ConfigError

SSD_NS = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC_NS = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV_NS = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
HEV_NS = "https://hevsim.org/cosim"
FMU_TYPE = "application/x-fmu-sharedlibrary"
PY_TYPE = "application/x-hevsim-python"
COMPONENT_TYPES = (FMU_TYPE, PY_TYPE)
NS = {"ssd": SSD_NS, "ssc": SSC_NS, "ssv": SSV_NS, "hevsim": HEV_NS}
for _p, _u in NS.items():
    ET.register_namespace(_p, _u)

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
    "checkpoint_every": int,
    "record_every": int,
}


@dataclass
class Connector:
    """A component's variable: ``kind`` input / output / parameter, ``unit`` ("" unknown)."""

    name: str
    kind: str
    unit: str = ""


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

    def component(self, name: str) -> Component:
        """The component called ``name``."""
        for c in self.components:
            if c.name == name:
                return c
        raise ConfigError(
            f"{self.source}: no component {name!r}; components: {[c.name for c in self.components]}."
        )


# --------------------------------------------------------------------------- parsing helpers
def _parse(path: Path, text: bytes | None = None) -> ET.Element:
    try:
        return ET.fromstring(text) if text is not None else ET.parse(path).getroot()
    except ET.ParseError as exc:
        line = exc.position[0]
        raise ConfigError(f"{path}: line {line}: not well-formed XML ({exc}).") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc.strerror}).") from None


def _req(el: ET.Element, attr: str, where: str) -> str:
    v = el.get(attr)
    if v is None or v == "":
        raise ConfigError(f"{where}: element <{_local(el.tag)}> lacks required attribute {attr!r}.")
    return v


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _num(v: str, what: str) -> float:
    try:
        return float(v)
    except ValueError:
        raise ConfigError(f"{what}: {v!r} is not a number.") from None


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
    if tag == "String":
        return text
    return _value(text)


# --------------------------------------------------------------------------- SSD read / write
def read_ssd(path: str | Path, text: bytes | None = None, base_dir: Path | None = None) -> SystemDescription:
    """Read an SSP system structure description (``.ssd``) into a :class:`SystemDescription`.

    Raises :class:`ConfigError` naming the file and element on a structural error."""
    path = Path(path)
    root = _parse(path, text)
    src = str(path)
    if root.tag != f"{{{SSD_NS}}}SystemStructureDescription":
        raise ConfigError(
            f"{src}: root element is <{_local(root.tag)}>, expected <ssd:SystemStructureDescription>."
        )
    system = root.find("ssd:System", NS)
    if system is None:
        raise ConfigError(f"{src}: <ssd:SystemStructureDescription> has no <ssd:System> element.")
    units: dict[str, U.Unit] = {}
    for u in root.findall("ssd:Units/ssc:Unit", NS):
        name = _req(u, "name", f"{src}: <ssc:Unit>")
        base = u.find("ssc:BaseUnit", NS)
        units[name] = U.unit_from_base(name, dict(base.attrib) if base is not None else {})
    comps: list[Component] = []
    for i, el in enumerate(system.findall("ssd:Elements/ssd:Component", NS)):
        where = f"{src}: <ssd:Component> #{i + 1}"
        name = _req(el, "name", where)
        where = f"{src}: component {name!r}"
        ctype = el.get("type", FMU_TYPE)
        if ctype not in COMPONENT_TYPES:
            raise ConfigError(f"{where}: type {ctype!r}; valid: {', '.join(COMPONENT_TYPES)}.")
        conns = []
        for c in el.findall("ssd:Connectors/ssd:Connector", NS):
            cname = _req(c, "name", where + " <ssd:Connector>")
            kind = _req(c, "kind", f"{where}: connector {cname!r}")
            if kind not in ("input", "output", "parameter", "calculatedParameter", "inout"):
                raise ConfigError(
                    f"{where}: connector {cname!r}: kind {kind!r}; valid: input, output, parameter."
                )
            real = c.find("ssc:Real", NS)
            conns.append(Connector(cname, kind, (real.get("unit") or "") if real is not None else ""))
        params: dict[str, Any] = {}
        for p in el.findall(".//ssv:Parameter", NS):
            pname = _req(p, "name", where + " <ssv:Parameter>")
            val = next(iter(p), None)
            if val is None or val.get("value") is None:
                raise ConfigError(f"{where}: parameter {pname!r} has no typed value element.")
            params[pname] = _typed(_local(val.tag), val.get("value", ""), f"{where}: parameter {pname!r}")
        comps.append(Component(name, ctype, _req(el, "source", where), conns, params))
    connections = []
    for i, el in enumerate(system.findall("ssd:Connections/ssd:Connection", NS)):
        where = f"{src}: <ssd:Connection> #{i + 1}"
        se, sc = _req(el, "startElement", where), _req(el, "startConnector", where)
        ee, ec = _req(el, "endElement", where), _req(el, "endConnector", where)
        connections.append(Connection(se, sc, ee, ec))
    desc = SystemDescription(
        system.get("name") or root.get("name") or path.stem, comps, connections, units=units,
        base_dir=base_dir if base_dir is not None else path.parent, source=src,
    )  # fmt: skip
    exp = root.find("ssd:DefaultExperiment", NS)
    if exp is not None:
        desc.start_time_s = _num(exp.get("startTime", "0"), f"{src}: DefaultExperiment startTime")
        desc.stop_time_s = _num(exp.get("stopTime", "1"), f"{src}: DefaultExperiment stopTime")
        m = exp.find(".//hevsim:Master", NS)
        if m is not None:
            desc.master = _master_options(dict(m.attrib), f"{src}: <hevsim:Master>")
    return desc


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
        elif k == "fmu_process":
            if v not in ("worker", "inprocess"):
                raise ConfigError(f"{where}: fmu_process {v!r}; valid: worker, inprocess.")
            out[k] = v
        elif k in OPTION_TYPES:
            try:
                out[k] = OPTION_TYPES[k](v)
            except ValueError:
                raise ConfigError(
                    f"{where}: attribute {k}={v!r} is not a valid {OPTION_TYPES[k].__name__}."
                ) from None
        else:
            valid = sorted([*OPTION_TYPES, "order", "send_before_receive", "rates", "fmu_process"])
            raise ConfigError(f"{where}: unknown attribute {k!r}; valid: {', '.join(valid)}.")
    return out


def ssd_xml(desc: SystemDescription) -> bytes:
    """The SSD XML text of ``desc``."""
    q = lambda ns, tag: f"{{{NS[ns]}}}{tag}"  # noqa: E731
    root = ET.Element(q("ssd", "SystemStructureDescription"), version="1.0", name=desc.name)
    system = ET.SubElement(root, q("ssd", "System"), name=desc.name)
    elements = ET.SubElement(system, q("ssd", "Elements"))
    for c in desc.components:
        el = ET.SubElement(elements, q("ssd", "Component"), name=c.name, type=c.type, source=c.source)
        if c.connectors:
            cs = ET.SubElement(el, q("ssd", "Connectors"))
            for k in c.connectors:
                ce = ET.SubElement(cs, q("ssd", "Connector"), name=k.name, kind=k.kind)
                r = ET.SubElement(ce, q("ssc", "Real"))
                if k.unit:
                    r.set("unit", k.unit)
        if c.parameters:
            pb = ET.SubElement(ET.SubElement(el, q("ssd", "ParameterBindings")), q("ssd", "ParameterBinding"))
            ps = ET.SubElement(
                ET.SubElement(pb, q("ssd", "ParameterValues")),
                q("ssv", "ParameterSet"),
                version="1.0",
                name="parameters",
            )
            params = ET.SubElement(ps, q("ssv", "Parameters"))
            for pname, v in c.parameters.items():
                p = ET.SubElement(params, q("ssv", "Parameter"), name=pname)
                typ = (
                    "Boolean"
                    if isinstance(v, bool)
                    else "Integer"
                    if isinstance(v, int)
                    else "Real"
                    if isinstance(v, float)
                    else "String"
                )
                ET.SubElement(
                    p,
                    q("ssv", typ),
                    value=str(v).lower()
                    if isinstance(v, bool)
                    else repr(v)
                    if isinstance(v, float)
                    else str(v),
                )
    cons = ET.SubElement(system, q("ssd", "Connections"))
    for cn in desc.connections:
        ET.SubElement(
            cons,
            q("ssd", "Connection"),
            startElement=cn.src,
            startConnector=cn.src_var,
            endElement=cn.dst,
            endConnector=cn.dst_var,
        )
    if desc.units:
        us = ET.SubElement(root, q("ssd", "Units"))
        for u in desc.units.values():
            ue = ET.SubElement(us, q("ssc", "Unit"), name=u.name)
            attrs = {b: str(e) for b, e in zip(U.BASE, u.exponents, strict=True) if e}
            attrs.update(factor=repr(u.factor), offset=repr(u.offset))
            ET.SubElement(ue, q("ssc", "BaseUnit"), attrs)
    exp = ET.SubElement(
        root,
        q("ssd", "DefaultExperiment"),
        startTime=repr(desc.start_time_s),
        stopTime=repr(desc.stop_time_s),
    )
    if desc.master:
        ann = ET.SubElement(
            ET.SubElement(exp, q("ssd", "Annotations")), q("ssc", "Annotation"), type="org.hevsim.cosim"
        )
        attrs = {}
        for key, v in desc.master.items():
            if key == "order":
                attrs[key] = " ".join(v)
            elif key == "send_before_receive":
                attrs[key] = " ".join(f"{a}:{str(b).lower()}" for a, b in v.items())
            elif key == "rates":
                attrs[key] = " ".join(f"{a}:{b}" for a, b in v.items())
            else:
                attrs[key] = str(v)
        ET.SubElement(ann, q("hevsim", "Master"), attrs)
    ET.indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8")


def write_ssd(desc: SystemDescription, path: str | Path) -> Path:
    """Write ``desc`` as an ``.ssd`` file (atomically)."""
    from hevsim.io import write_text_atomic

    return write_text_atomic(path, ssd_xml(desc).decode())


def write_ssp(desc: SystemDescription, path: str | Path) -> Path:
    """Write an ``.ssp`` archive: ``SystemStructure.ssd`` plus every FMU under ``resources/``."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    comps = []
    files: list[tuple[Path, str]] = []
    for c in desc.components:
        if c.type == FMU_TYPE:
            f = (desc.base_dir / c.source).resolve()
            if not f.is_file():
                raise ConfigError(f"component {c.name!r}: FMU file {str(f)!r} does not exist.")
            arc = f"resources/{c.name}_{f.name}"
            files.append((f, arc))
            comps.append(Component(c.name, c.type, arc, c.connectors, c.parameters))
        else:
            comps.append(c)
    packed = SystemDescription(
        desc.name, comps, desc.connections, desc.start_time_s, desc.stop_time_s, desc.master, desc.units
    )
    tmp = out.with_name(f".{out.name}.tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", ssd_xml(packed))
        for f, arc in files:
            z.write(f, arc)
    tmp.replace(out)
    return out


def read_ssp(path: str | Path, extract_to: str | Path | None = None) -> SystemDescription:
    """Read an ``.ssp`` archive (its FMUs are extracted to ``extract_to`` or a temporary
    folder that lives as long as the process)."""
    path = Path(path)
    try:
        z = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise ConfigError(f"{path}: not a readable SSP archive ({exc}).") from None
    with z:
        if "SystemStructure.ssd" not in z.namelist():
            raise ConfigError(f"{path}: the archive has no SystemStructure.ssd.")
        dest = Path(extract_to) if extract_to else Path(tempfile.mkdtemp(prefix="hevsim-ssp-"))
        z.extractall(dest)
    desc = read_ssd(dest / "SystemStructure.ssd", base_dir=dest)
    desc.source = f"{path}!SystemStructure.ssd"
    return desc


def load_system(path: str | Path, bindings: dict[str, Component] | None = None) -> SystemDescription:
    """Read ``.ssp``, ``.ssd`` or a CSE ``.xml`` (``bindings`` map CSE instances to components)."""
    p = Path(path)
    if not p.exists():
        raise ConfigError(f"{p}: configuration file does not exist.")
    if p.suffix == ".ssp":
        return read_ssp(p)
    if p.suffix == ".ssd":
        return read_ssd(p)
    if p.suffix == ".xml":
        return read_cse(p, bindings)
    raise ConfigError(f"{p}: unknown configuration type {p.suffix!r}; valid: .ssp, .ssd, .xml (SIMULIA CSE).")


# --------------------------------------------------------------------------- SIMULIA CSE import
def read_cse(path: str | Path, bindings: dict[str, Component] | None = None) -> SystemDescription:
    """Import a SIMULIA co-simulation engine XML file (thesis appendix 3).

    Components with ``UnitDefinitions`` / ``ModelVariables`` give units; each connection of
    a connection set pairs one connector's inputs with the other connector's outputs in
    order. ``execution`` gives the algorithm (order from the ``atomicActor`` list), the
    negotiation method and the duration. ``bindings`` maps a component instance name to
    the :class:`Component` that implements it (an FMU or a Python factory); without it the
    description can be checked (:func:`datacheck`) but not run.
    """
    path = Path(path)
    root = _parse(path)
    src = str(path)
    if _local(root.tag) != "CoupledMultiphysicsSimulation":
        raise ConfigError(
            f"{src}: root element is <{_local(root.tag)}>, expected <CoupledMultiphysicsSimulation>."
        )
    if root.find("header/SchemaVersion") is None:
        raise ConfigError(f"{src}: <header> lacks the required <SchemaVersion>.")
    for req in ("components", "componentInstances", "connectors", "connectionSets", "execution"):
        if root.find(req) is None:
            raise ConfigError(f"{src}: <CoupledMultiphysicsSimulation> lacks required element <{req}>.")
    units: dict[str, U.Unit] = {}
    var_units: dict[str, dict[str, str]] = {}
    components: set[str] = set()
    for c in root.findall("components/component"):
        cname = _req(c, "name", f"{src}: <component>")
        components.add(cname)
        for u in c.findall(".//UnitDefinitions/Unit"):
            uname = _req(u, "name", f"{src}: component {cname!r} <Unit>")
            base = u.find("BaseUnit")
            units[uname] = U.unit_from_base(uname, dict(base.attrib) if base is not None else {})
        var_units[cname] = {}
        for v in c.findall(".//ModelVariables/ScalarVariable"):
            vname = _req(v, "name", f"{src}: component {cname!r} <ScalarVariable>")
            real = v.find("Real")
            var_units[cname][vname] = (real.get("unit") or "") if real is not None else ""
    inst_comp: dict[str, str] = {}
    sbr: dict[str, bool] = {}
    for ci in root.findall("componentInstances/componentInstance"):
        iname = _req(ci, "name", f"{src}: <componentInstance>")
        comp = (ci.findtext("component") or "").strip()
        if comp not in components:
            raise ConfigError(
                f"{src}: componentInstance {iname!r} refers to unknown component {comp!r}; "
                f"components: {sorted(components)}."
            )
        inst_comp[iname] = comp
        s = ci.findtext("initialConditions/sendBeforeReceive")
        if s is not None:
            sbr[iname] = s.strip().lower() == "true"
    connectors: dict[str, tuple[str, list[str], list[str]]] = {}
    for cn in root.findall("connectors/connector"):
        name = _req(cn, "name", f"{src}: <connector>")
        inst = (cn.findtext("componentInstance") or "").strip()
        if inst not in inst_comp:
            raise ConfigError(
                f"{src}: connector {name!r} refers to unknown componentInstance {inst!r}; "
                f"instances: {sorted(inst_comp)}."
            )
        ins = [(v.text or "").strip() for v in cn.findall("variables/input/variable")]
        outs = [(v.text or "").strip() for v in cn.findall("variables/output/variable")]
        connectors[name] = (inst, ins, outs)
    connections: list[Connection] = []
    sets: set[str] = set()
    for cs in root.findall("connectionSets/connectionSet"):
        sname = _req(cs, "name", f"{src}: <connectionSet>")
        sets.add(sname)
        for k, conn in enumerate(cs.findall("connection")):
            names = [(c.text or "").strip() for c in conn.findall("connector")]
            where = f"{src}: connectionSet {sname!r} connection #{k + 1}"
            if len(names) != 2:
                raise ConfigError(f"{where}: needs exactly 2 connectors, has {len(names)}.")
            for n in names:
                if n not in connectors:
                    raise ConfigError(f"{where}: unknown connector {n!r}; connectors: {sorted(connectors)}.")
            (ia, ina, outa), (ib, inb, outb) = (connectors[n] for n in names)
            if len(ina) + len(inb) == 0 or len(outa) + len(outb) == 0:
                raise ConfigError(
                    f"{where}: connectors {names[0]!r} and {names[1]!r} do not pair an input with an output."
                )
            for dst, dvars, srcp, svars, a, b in (
                (ia, ina, ib, outb, names[0], names[1]),
                (ib, inb, ia, outa, names[1], names[0]),
            ):
                if len(dvars) != len(svars):
                    raise ConfigError(
                        f"{where}: connector {a!r} has {len(dvars)} input variable(s) but connector {b!r} "
                        f"has {len(svars)} output variable(s)."
                    )
                for dv, sv in zip(dvars, svars, strict=True):
                    su = var_units.get(inst_comp[srcp], {}).get(sv, "")
                    du = var_units.get(inst_comp[dst], {}).get(dv, "")
                    U.conversion(su, du, units, f"{where}: {srcp}.{sv} -> {dst}.{dv}")
                    connections.append(Connection(srcp, sv, dst, dv, su or None, du or None))
    master: dict[str, Any] = {}
    actors = [
        (a.text or "").strip()
        for a in root.findall("execution/compositeActors/compositeActor/actors/atomicActor")
    ]
    for a in actors:
        if a not in inst_comp:
            raise ConfigError(
                f"{src}: atomicActor {a!r} is not a componentInstance; instances: {sorted(inst_comp)}."
            )
    if actors:
        master["order"] = actors
    alg = root.findtext(".//modelOfComputation/continuousTime/algorithm")
    if alg:
        mapped = {"GAUSS-SEIDEL": "gauss-seidel", "JACOBI": "jacobi"}.get(alg.strip().upper())
        if mapped is None:
            raise ConfigError(f"{src}: <algorithm> {alg!r}; valid: GAUSS-SEIDEL, JACOBI.")
        master["algorithm"] = mapped
    neg = root.findtext(".//modelOfComputation/continuousTime/negotiationMethod")
    if neg:
        if neg.strip().upper() not in ("MIN", "MAX"):
            raise ConfigError(f"{src}: <negotiationMethod> {neg!r}; valid: MIN, MAX.")
        master["negotiation"] = neg.strip().lower()
    for cat in root.findall("execution/connectionGroups/connectionCategory"):
        for cs_ref in cat.findall("connectionSet"):
            if (cs_ref.text or "").strip() not in sets:
                raise ConfigError(
                    f"{src}: connectionCategory {cat.get('name')!r} names unknown connectionSet "
                    f"{cs_ref.text!r}; sets: {sorted(sets)}."
                )
    if sbr:
        master["send_before_receive"] = sbr
    dur = root.findtext("execution/scenario/duration")
    if dur is None:
        raise ConfigError(f"{src}: <execution> lacks <scenario><duration>.")
    bindings = bindings or {}
    comps = []
    for inst in inst_comp:
        bound = bindings.get(inst)
        comps.append(
            Component(inst, bound.type, bound.source, bound.connectors, bound.parameters)
            if bound
            else Component(inst, "unbound", "", [])
        )
    return SystemDescription(
        root.get("name") or path.stem, comps, connections, 0.0, _num(dur.strip(), f"{src}: <duration>"),
        master, units, path.parent, src,
    )  # fmt: skip


# --------------------------------------------------------------------------- datacheck / build
def datacheck(
    path_or_desc: str | Path | SystemDescription, bindings: dict[str, Component] | None = None
) -> SystemDescription:
    """Check a configuration against section 4.1.4's requirements: (1) well-formed XML and
    (2) the schema's structure (both while reading), (3) internal references (components,
    connectors, FMU files and their variables), (4) input/output pairing of connections
    (an output feeds an input; an input is fed once) and (5) compatible, known units.
    Returns the description; raises :class:`ConfigError` naming the element otherwise."""
    desc = (
        path_or_desc if isinstance(path_or_desc, SystemDescription) else load_system(path_or_desc, bindings)
    )
    src = desc.source
    names = [c.name for c in desc.components]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise ConfigError(f"{src}: duplicate component name(s) {sorted(dup)}.")
    kinds: dict[str, dict[str, Connector]] = {}
    for c in desc.components:
        kinds[c.name] = {k.name: k for k in c.connectors}
        if c.type == FMU_TYPE:
            kinds[c.name].update(_fmu_connectors(desc, c))
    fed: set[tuple[str, str]] = set()
    for k in desc.connections:
        what = f"{src}: connection {k.src}.{k.src_var} -> {k.dst}.{k.dst_var}"
        for comp, var, want in ((k.src, k.src_var, "output"), (k.dst, k.dst_var, "input")):
            if comp not in kinds:
                raise ConfigError(f"{what}: unknown component {comp!r}; components: {names}.")
            declared = kinds[comp]
            if declared and var not in declared:
                raise ConfigError(
                    f"{what}: component {comp!r} has no variable {var!r}; variables: {sorted(declared)}."
                )
            if var in declared and declared[var].kind not in (want, "inout"):
                raise ConfigError(f"{what}: {comp}.{var} is an {declared[var].kind}, expected an {want}.")
        if (k.dst, k.dst_var) in fed:
            raise ConfigError(f"{what}: input {k.dst}.{k.dst_var} is connected more than once.")
        fed.add((k.dst, k.dst_var))
        su = k.src_unit if k.src_unit is not None else getattr(kinds[k.src].get(k.src_var), "unit", "")
        du = k.dst_unit if k.dst_unit is not None else getattr(kinds[k.dst].get(k.dst_var), "unit", "")
        U.conversion(su, du, desc.units, what)
    if desc.stop_time_s <= desc.start_time_s:
        raise ConfigError(
            f"{src}: stop time {desc.stop_time_s} s must exceed start time {desc.start_time_s} s."
        )
    return desc


def _fmu_connectors(desc: SystemDescription, c: Component) -> dict[str, Connector]:
    from fmpy import read_model_description

    f = desc.base_dir / c.source
    if not f.is_file():
        raise ConfigError(f"{desc.source}: component {c.name!r}: FMU file {str(f)!r} does not exist.")
    try:
        md = read_model_description(str(f))
    except Exception as exc:
        raise ConfigError(f"{desc.source}: component {c.name!r}: {f} is not a valid FMU ({exc}).") from None
    out: dict[str, Connector] = {}
    for v in md.modelVariables:
        unit = (
            getattr(v, "unit", None)
            or (v.declaredType.unit if getattr(v, "declaredType", None) else None)
            or ""
        )
        out[v.name] = Connector(v.name, v.causality, unit)
    for p in c.parameters:
        if p not in out:
            raise ConfigError(
                f"{desc.source}: component {c.name!r}: FMU {f.name} has no variable {p!r} (parameter)."
            )
    for k in c.connectors:
        if k.name not in out:
            raise ConfigError(
                f"{desc.source}: component {c.name!r}: FMU {f.name} has no variable {k.name!r} (connector)."
            )
    return out


def build_participants(desc: SystemDescription) -> list[Participant]:
    """Instantiate the participants of ``desc`` (FMUs in worker processes by default)."""
    from hevsim.cosim.participant import FMUParticipant
    from hevsim.cosim.worker import WorkerFMUParticipant

    inproc = desc.master.get("fmu_process", "worker") == "inprocess"
    parts: list[Participant] = []
    for c in desc.components:
        if c.type == FMU_TYPE:
            cls = FMUParticipant if inproc else WorkerFMUParticipant
            parts.append(cls(c.name, desc.base_dir / c.source, c.parameters))
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


def run_system(
    desc: SystemDescription,
    progress: Callable[[float, float], None] | None = None,
    checkpoint_path: str | Path | None = None,
    resume: bool = False,
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
    if "step_s" not in m:
        raise ConfigError(f"{desc.source}: the master settings lack step_s (the communication step [s]).")
    opts = Options(
        stop_time_s=desc.stop_time_s, start_time_s=desc.start_time_s, checkpoint_path=checkpoint_path, **m
    )
    opts.check()
    return simulate(build_participants(desc), desc.connections, progress=progress, resume=resume,
                    extra_units=desc.units, **vars(opts))  # fmt: skip


def run_cosim(
    config_path: str | Path | SystemDescription,
    out_dir: str | Path,
    progress: Callable[[float, float], None] | None = None,
    resume: bool = False,
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
    the error is raised."""
    from hevsim.cosim.master import CosimFault
    from hevsim.io import atomic_directory, write_json

    desc = config_path if isinstance(config_path, SystemDescription) else load_system(config_path)
    out = Path(out_dir)
    ck = out.with_name(f".{out.name}.checkpoint")

    def write(res: CosimResult, error: str | None) -> None:
        with atomic_directory(out) as tmp:
            res.write_csv(tmp / "results.csv")
            final = {c: float(res.data[-1, i]) for i, c in enumerate(res.columns)} if len(res.data) else {}
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

    try:
        res = run_system(desc, progress, ck, resume)
    except CosimFault as exc:
        if exc.partial is not None:
            write(exc.partial, str(exc))
        raise
    write(res, None)
    ck.unlink(missing_ok=True)
    return res

"""Writing a :class:`~hevsim.cosim.ssd.SystemDescription` as SSP: :func:`ssd_xml` (the XML
text), :func:`write_ssd` (an ``.ssd`` file) and :func:`write_ssp` (an ``.ssp`` archive with
the FMUs under ``resources/``). Reading is in :mod:`hevsim.cosim.ssd`.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from hevsim.cosim import units as U
from hevsim.cosim.ssd import FMU_TYPE, NS, Component, Connector, SystemDescription
from hevsim.errors import ConfigError

OSP_NS = "http://opensimulationplatform.com/SSP/OSPAnnotations"
for _p, _u in {**NS, "osp": OSP_NS}.items():
    ET.register_namespace(_p, _u)


def _connected(desc: SystemDescription, c: Component) -> list[Connector]:
    """Connectors of ``c`` from the connections (SSP readers such as libcosim and FMPy need
    them declared), typed from the FMU where it can be read."""
    types: dict[str, str] = {}
    units: dict[str, str] = {}
    f = desc.base_dir / c.source
    if c.type == FMU_TYPE and f.is_file():
        from fmpy import read_model_description

        from hevsim.cosim.fmi_vars import FmuVariables

        try:
            fv = FmuVariables(read_model_description(str(f)), f.name)
            types, units = fv.types, {**fv.inputs, **fv.outputs}
        except Exception:  # an unreadable FMU is reported by the data check, not here
            pass
    out: dict[str, Connector] = {}
    for k in desc.connections:
        if k.src == c.name:
            out.setdefault(
                k.src_var,
                Connector(k.src_var, "output", units.get(k.src_var, ""), types.get(k.src_var, "Real")),
            )
        if k.dst == c.name:
            out.setdefault(
                k.dst_var,
                Connector(k.dst_var, "input", units.get(k.dst_var, ""), types.get(k.dst_var, "Real")),
            )
    return list(out.values())


def ssd_xml(desc: SystemDescription) -> bytes:
    """The SSD XML text of ``desc``."""
    q = lambda ns, tag: f"{{{NS[ns]}}}{tag}"  # noqa: E731
    root = ET.Element(q("ssd", "SystemStructureDescription"), version="1.0", name=desc.name)
    system = ET.SubElement(root, q("ssd", "System"), name=desc.name)
    elements = ET.SubElement(system, q("ssd", "Elements"))
    for c in desc.components:
        el = ET.SubElement(elements, q("ssd", "Component"), name=c.name, type=c.type, source=c.source)
        connectors = c.connectors or _connected(desc, c)
        if connectors:
            cs = ET.SubElement(el, q("ssd", "Connectors"))
            for k in connectors:
                ce = ET.SubElement(cs, q("ssd", "Connector"), name=k.name, kind=k.kind)
                r = ET.SubElement(ce, q("ssc", k.type))
                if k.unit and k.type == "Real":
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
        anns = ET.SubElement(exp, q("ssd", "Annotations"))
        if "step_s" in desc.master:  # the OSP annotation libcosim reads
            osp = ET.SubElement(anns, q("ssc", "Annotation"), type="com.opensimulationplatform")
            alg = ET.SubElement(
                ET.SubElement(osp, f"{{{OSP_NS}}}Algorithm"), f"{{{OSP_NS}}}FixedStepAlgorithm"
            )
            alg.set("baseStepSize", repr(float(desc.master["step_s"])))
        ann = ET.SubElement(anns, q("ssc", "Annotation"), type="org.hevsim.cosim")
        attrs = {}
        for key, v in desc.master.items():
            if key == "order":
                attrs[key] = " ".join(v)
            elif key == "send_before_receive":
                attrs[key] = " ".join(f"{a}:{str(b).lower()}" for a, b in v.items())
            elif key == "rates":
                attrs[key] = " ".join(f"{a}:{b}" for a, b in v.items())
            elif key == "checkpoint_wall_s":
                attrs.setdefault("checkpoint_every", f"{v!r}s")
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

"""Import of the SIMULIA co-simulation engine (CSE) XML of the thesis (appendix 3) into a
:class:`~hevsim.cosim.ssd.SystemDescription`: :func:`read_cse`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hevsim.cosim import units as U
from hevsim.cosim._xml import local_name, number, parse_xml, required
from hevsim.cosim.master import Connection
from hevsim.cosim.ssd import Component, SystemDescription
from hevsim.errors import ConfigError


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
    root = parse_xml(path)
    src = str(path)
    if local_name(root.tag) != "CoupledMultiphysicsSimulation":
        raise ConfigError(
            f"{src}: root element is <{local_name(root.tag)}>, expected <CoupledMultiphysicsSimulation>."
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
        cname = required(c, "name", f"{src}: <component>")
        components.add(cname)
        for u in c.findall(".//UnitDefinitions/Unit"):
            uname = required(u, "name", f"{src}: component {cname!r} <Unit>")
            base = u.find("BaseUnit")
            units[uname] = U.unit_from_base(uname, dict(base.attrib) if base is not None else {})
        var_units[cname] = {}
        for v in c.findall(".//ModelVariables/ScalarVariable"):
            vname = required(v, "name", f"{src}: component {cname!r} <ScalarVariable>")
            real = v.find("Real")
            var_units[cname][vname] = (real.get("unit") or "") if real is not None else ""
    inst_comp: dict[str, str] = {}
    sbr: dict[str, bool] = {}
    for ci in root.findall("componentInstances/componentInstance"):
        iname = required(ci, "name", f"{src}: <componentInstance>")
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
        name = required(cn, "name", f"{src}: <connector>")
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
        sname = required(cs, "name", f"{src}: <connectionSet>")
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
        root.get("name") or path.stem, comps, connections, 0.0, number(dur.strip(), f"{src}: <duration>"),
        master, units, path.parent, src,
    )  # fmt: skip

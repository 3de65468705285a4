"""The data check of a co-simulation configuration (thesis section 4.1.4): :func:`datacheck`."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from hevsim.cosim import units as U
from hevsim.cosim.fmi_vars import (
    TYPE_CLASS,
    UNSUPPORTED_WHY,
    FmuVariables,
    article,
    narrowing,
    type_conversion,
)
from hevsim.cosim.load import load_system
from hevsim.cosim.master import Connection, Options, state_needs
from hevsim.cosim.ssd import COMPONENT_TYPES, FMU_TYPE, Component, Connector, SystemDescription
from hevsim.errors import ConfigError


def datacheck(
    path_or_desc: str | Path | SystemDescription, bindings: dict[str, Component] | None = None
) -> SystemDescription:
    """Check a configuration against section 4.1.4's requirements: (1) well-formed XML and
    (2) the schema's structure (both while reading), (3) internal references (components,
    connectors, FMU files and their variables), (4) input/output pairing of connections
    (an output feeds an input; an input is fed once) and (5) compatible, known units.
    Returns the description; raises :class:`ConfigError` naming the element otherwise.
    Given a path, the temporary folder an ``.ssp`` is extracted to is removed before
    returning (also on error): to run the system, load it with
    :func:`~hevsim.cosim.load.load_system`."""
    if isinstance(path_or_desc, SystemDescription):
        return _check(path_or_desc)
    with load_system(path_or_desc, bindings) as desc:
        return _check(desc)


EXCHANGED_CLASSES = frozenset(TYPE_CLASS.values())
"""Type classes a connection can carry as values (FMI 3.0 Clock variables connect only to
each other: a clock connection, :class:`hevsim.cosim.master.Master`)."""


def _check(desc: SystemDescription) -> SystemDescription:
    src = desc.source
    names = [c.name for c in desc.components]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise ConfigError(f"{src}: duplicate component name(s) {sorted(dup)}.")
    kinds: dict[str, dict[str, Connector]] = {}
    info: dict[str, dict[str, Any]] = {}
    for c in desc.components:
        kinds[c.name] = {k.name: k for k in c.connectors}
        if c.type == FMU_TYPE:
            info[c.name] = {}
            kinds[c.name].update(_fmu_connectors(desc, c, info[c.name]))
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
                raise ConfigError(
                    f"{what}: {comp}.{var} is {article(declared[var].kind)}, expected {article(want)}."
                )
        if (k.dst, k.dst_var) in fed:
            raise ConfigError(f"{what}: input {k.dst}.{k.dst_var} is connected more than once.")
        fed.add((k.dst, k.dst_var))
        su = k.src_unit if k.src_unit is not None else getattr(kinds[k.src].get(k.src_var), "unit", "")
        du = k.dst_unit if k.dst_unit is not None else getattr(kinds[k.dst].get(k.dst_var), "unit", "")
        st = getattr(kinds[k.src].get(k.src_var), "type", "Real")
        dt = getattr(kinds[k.dst].get(k.dst_var), "type", "Real")
        if st == dt == "Clock":  # a clock connection: an output clock to a triggered input clock
            _check_clocks(what, k, info)
            continue
        for comp, var, typ in ((k.src, k.src_var, st), (k.dst, k.dst_var, dt)):
            if typ not in EXCHANGED_CLASSES:
                raise ConfigError(
                    f"{what}: {comp}.{var} is an FMI {typ} variable; hevsim exchanges "
                    f"{', '.join(sorted(EXCHANGED_CLASSES))} variables only "
                    f"({UNSUPPORTED_WHY.get(typ, 'not supported')})."
                    + (" A clock connects only to a clock." if "Clock" in (st, dt) else "")
                )
        type_conversion(st, dt, f"{what} ({k.src}.{k.src_var} is {st}, {k.dst}.{k.dst_var} is {dt})")
        sf = getattr(kinds[k.src].get(k.src_var), "fmi_type", "")
        df = getattr(kinds[k.dst].get(k.dst_var), "fmi_type", "")
        narrowing(sf, df, f"{what} ({k.src}.{k.src_var} is {sf}, {k.dst}.{k.dst_var} is {df})")
        if st == dt == "Real":
            U.conversion(su, du, desc.units, what)
    if desc.stop_time_s <= desc.start_time_s:
        raise ConfigError(
            f"{src}: stop time {desc.stop_time_s} s must exceed start time {desc.start_time_s} s."
        )
    if all(c.type in COMPONENT_TYPES for c in desc.components):  # runnable: what the run would refuse
        _check_run(desc, info)
    return desc


def _check_clocks(what: str, k: Connection, info: dict[str, dict[str, Any]]) -> None:
    """What the master refuses of a Clock -> Clock connection, statically: the source's clock
    must be an output clock, the destination's a triggered input clock, both FMUs co-simulation
    FMUs with event mode."""
    for comp in (k.src, k.dst):
        if comp in info and not info[comp]["event_mode"]:
            raise ConfigError(
                f"{what}: {comp}'s FMU has no co-simulation interface with event mode "
                '(hasEventMode="true"): its clocks are not run.'
            )
    src = info.get(k.src, {}).get("clocks", {}).get(k.src_var)
    dst = info.get(k.dst, {}).get("clocks", {}).get(k.dst_var)
    if src is not None and dst is not None and (src[0] != "output" or dst != ("input", "triggered")):
        raise ConfigError(
            f"{what}: a clock connection goes from an output clock to a triggered input clock "
            f"({k.src}.{k.src_var}: {src[0]} clock, {src[1]}; {k.dst}.{k.dst_var}: {dst[0]} clock, {dst[1]})."
        )


def _check_run(desc: SystemDescription, info: dict[str, dict[str, Any]]) -> None:
    """The master settings (step size, valid options), FMUs an iterative scheme cannot
    restore, and algebraic loops of direct feedthrough under Gauss-Seidel."""
    src = desc.source
    m = {k: v for k, v in desc.master.items() if k != "fmu_process"}
    if "step_s" not in m:
        m["step_s"] = default_step(desc)[0]
    try:
        opts = Options(stop_time_s=desc.stop_time_s, start_time_s=desc.start_time_s, **m)
    except TypeError as exc:
        raise ConfigError(f"{src}: master settings: {exc}.") from None
    try:
        opts.check()
    except ConfigError as exc:
        raise ConfigError(f"{src}: {exc}") from None
    needs = state_needs(opts)
    for name, i in info.items():
        if needs and not i["can_state"]:
            raise ConfigError(
                f"{src}: component {name!r} cannot save and restore its state ({i['state_note']}), "
                f"which {needs} needs; use max_iterations=1 and negotiation 'fixed' with it."
            )
    if opts.algorithm == "gauss-seidel" and opts.max_iterations == 1:
        loop = algebraic_loop(desc.connections, {n: i["feedthrough"] for n, i in info.items()})
        if loop:
            raise ConfigError(
                f"{src}: algebraic loop of direct feedthrough under Gauss-Seidel: {' -> '.join(loop)}; "
                "no order can give every participant its inputs at the end of the step. Use "
                "algorithm 'jacobi' (one step of lag per connection) or max_iterations > 1."
            )


def default_step(desc: SystemDescription) -> tuple[float, str]:
    """The communication step [s] when the system description gives none, as other masters
    take it (FMPy: the FMU's ``DefaultExperiment stepSize``): the largest step every FMU
    participant accepts, i.e. the smallest of their ``stepSize`` values, with a note saying
    where it comes from. :class:`ConfigError` when no FMU states one."""
    from fmpy import read_model_description

    steps: dict[str, float] = {}
    for c in desc.components:
        if c.type != FMU_TYPE or not (desc.base_dir / c.source).is_file():
            continue
        try:
            de = read_model_description(str(desc.base_dir / c.source)).defaultExperiment
        except Exception:  # (an unreadable FMU is reported by the data check)
            continue
        size = getattr(de, "stepSize", None) if de is not None else None
        if size not in (None, "") and float(size) > 0:
            steps[c.name] = float(size)
    if not steps:
        raise ConfigError(
            f"{desc.source}: no communication step size: give step_s in the hevsim master annotation or "
            "the OSP annotation (osp:FixedStepAlgorithm baseStepSize) of ssd:DefaultExperiment "
            "(no FMU participant states a DefaultExperiment stepSize either)."
        )
    h = min(steps.values())
    each = ", ".join(f"{n} {v:g} s" for n, v in steps.items())
    return h, (
        f"step_s = {h:g} s from the FMUs' DefaultExperiment stepSize ({each}): the largest step "
        "every participant accepts (no step_s in the system description)"
    )


def algebraic_loop(
    connections: Sequence[Connection], feedthrough: Mapping[str, Mapping[str, set[str]]]
) -> list[str]:
    """A cycle ["a.y", "b.u", "b.z", "a.x", "a.y"] of connections and direct feedthrough
    (``feedthrough[component][output]`` = the inputs it depends on directly, as the FMUs'
    ModelStructure declares), or [] when there is none."""
    succ: dict[str, list[str]] = {}
    for k in connections:
        succ.setdefault(f"{k.src}.{k.src_var}", []).append(f"{k.dst}.{k.dst_var}")
    for comp, outs in feedthrough.items():
        for out, ins in outs.items():
            for i in ins:
                succ.setdefault(f"{comp}.{i}", []).append(f"{comp}.{out}")
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(n: str) -> list[str]:
        state[n] = 1
        path.append(n)
        for m in sorted(succ.get(n, ())):
            if state.get(m) == 1:
                return [*path[path.index(m) :], m]
            if m not in state:
                found = visit(m)
                if found:
                    return found
        state[n] = 2
        path.pop()
        return []

    for n in sorted(succ):
        if n not in state:
            found = visit(n)
            if found:
                return found
    return []


FMU_BUILD_HINT = (
    "An hevsim battery FMU is exported with `hevsim export-fmu CELL_PARAMS -o FILE.fmu --native`; "
    "the examples' FMUs are not in git but built on this machine: `make examples` "
    "(or `python examples/cosim_module/run_module.py --build-fmu` for examples/cosim_module/module_2s6p.fmu)."
)
"""Appended to the message for a missing FMU file."""


def _fmu_connectors(desc: SystemDescription, c: Component, info: dict[str, Any]) -> dict[str, Connector]:
    """The FMU's variables as connectors; ``info`` receives ``can_state``, ``state_note`` and
    ``feedthrough`` (output -> inputs it depends on directly, from ModelStructure)."""
    from fmpy import read_model_description

    f = desc.base_dir / c.source
    if not f.is_file():
        raise ConfigError(
            f"{desc.source}: component {c.name!r}: FMU file {str(f)!r} does not exist. {FMU_BUILD_HINT}"
        )
    try:
        md = read_model_description(str(f))
    except Exception as exc:
        raise ConfigError(f"{desc.source}: component {c.name!r}: {f} is not a valid FMU ({exc}).") from None
    se = getattr(md, "scheduledExecution", None)
    if md.coSimulation is None and md.modelExchange is None and se is None:
        raise ConfigError(
            f"{desc.source}: component {c.name!r}: FMU {f.name} has neither a co-simulation, a "
            "model exchange nor a scheduled execution interface."
        )
    try:
        fv = FmuVariables(md, f.name)
    except ConfigError as exc:
        raise ConfigError(f"{desc.source}: component {c.name!r}: {exc}") from None
    cs, key = md.coSimulation, "FMUState" if md.fmiVersion.startswith("3") else "FMUstate"
    iface = cs if cs is not None else md.modelExchange  # (run as the participant runs it; SE: no state)
    info["can_state"] = bool(getattr(iface, f"canGetAndSet{key}", False)) and bool(
        getattr(iface, f"canSerialize{key}", False)
    )
    info["state_note"] = (
        f'FMU {f.name} declares canGetAndSet{key}="false" or canSerialize{key}="false"'
        if cs is not None
        else f'Model Exchange FMU {f.name} declares canGetAndSet{key}="false" or canSerialize{key}="false"'
        if md.modelExchange is not None
        else f"Scheduled Execution FMU {f.name}: its state is not saved here"
    )
    info["event_mode"] = bool(md.fmiVersion.startswith("3") and getattr(cs, "hasEventMode", False))
    info["clocks"] = {
        v.name: (str(v.causality), str(v.intervalVariability or "triggered"))
        for v in md.modelVariables
        if str(v.type) == "Clock"
    }
    inputs = {v.name for v in md.modelVariables if v.causality == "input"}
    info["feedthrough"] = {
        u.variable.name: {d.name for d in u.dependencies if d.name in inputs}
        for u in getattr(md, "outputs", [])
        if u.dependencies  # absent: unknown, not taken as feedthrough
    }
    out: dict[str, Connector] = {}
    for v in md.modelVariables:
        unit = (
            getattr(v, "unit", None)
            or (v.declaredType.unit if getattr(v, "declaredType", None) else None)
            or ""
        )
        out[v.name] = Connector(
            v.name, v.causality, unit, TYPE_CLASS.get(str(v.type), str(v.type)), str(v.type)
        )
    for kind, table in (("input", fv.inputs), ("output", fv.outputs)):
        for e, u in table.items():
            out[e] = Connector(e, kind, u, fv.types[e], fv.fmi_types[e])
    by_name = {v.name: v for v in md.modelVariables}
    for p, val in c.parameters.items():
        if p not in out:
            raise ConfigError(
                f"{desc.source}: component {c.name!r}: FMU {f.name} has no variable {p!r} (parameter)."
            )
        if p in by_name:
            try:
                fv.check_parameter(by_name[p], val)
            except ConfigError as exc:
                raise ConfigError(f"{desc.source}: component {c.name!r}: {exc}") from None
    for k in c.connectors:
        if k.name not in out:
            raise ConfigError(
                f"{desc.source}: component {c.name!r}: FMU {f.name} has no variable {k.name!r} (connector)."
            )
    return out

"""The variables an FMU exchanges, of every type: :class:`FmuVariables` (inputs, outputs and
parameters of an FMI 2.0 or 3.0 model description, arrays expanded to one element each) and
the connection type rules (:func:`type_conversion`).

Types are grouped in classes: ``Real`` (FMI 2.0 Real; FMI 3.0 Float64, Float32), ``Integer``
(FMI 2.0 Integer; FMI 3.0 Int8 .. UInt64), ``Enumeration``, ``Boolean``, ``String`` and
``Binary`` (FMI 3.0). Values travel as Python ``float`` / ``int`` / ``bool`` / ``str``; a
Binary value travels and is recorded as its bytes in hexadecimal text (``"01ff"``). An
integer outside its FMI 3.0 type's range (an Int64 output into an Int8 input, a parameter)
is refused naming the variable, not wrapped around. An FMI 3.0 array variable
``a`` with dimensions (n) is exchanged and recorded as ``a[1]`` .. ``a[n]`` (1-based, as
FMI 2.0 names scalarised array elements; ``a[i,j]`` for two dimensions, row-major).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from hevsim.errors import ConfigError

TYPE_CLASS = {
    "Real": "Real",
    "Float64": "Real",
    "Float32": "Real",
    "Integer": "Integer",
    **{t: "Integer" for t in ("Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")},
    "Enumeration": "Enumeration",
    "Boolean": "Boolean",
    "String": "String",
    "Binary": "Binary",
}
UNSUPPORTED_WHY = {
    "Clock": "an FMI 3.0 clock ticks in event mode, which hevsim's fixed-step master does not run",
}
"""Why a variable type is neither exchanged nor recorded (the message of a refused connection)."""
INT_RANGE = {
    t: ((-(2 ** (b - 1)), 2 ** (b - 1) - 1) if t[0] == "I" else (0, 2**b - 1))
    for t, b in (("Int8", 8), ("UInt8", 8), ("Int16", 16), ("UInt16", 16), ("Int32", 32), ("UInt32", 32),
                 ("Int64", 64), ("UInt64", 64))
}  # fmt: skip
"""Smallest and largest value of each FMI 3.0 integer type."""
PY_TYPE: dict[str, Callable[[Any], Any]] = {
    "Real": float,
    "Integer": int,
    "Enumeration": int,
    "Boolean": bool,
    "String": str,
    "Binary": str,
}

# Conversions applied on a connection between different type classes: only lossless ones
# (a Boolean is 0 / 1); anything else (Real -> Integer, Real -> Boolean, to or from String)
# is refused naming both ends.
_CONVERSIONS: dict[tuple[str, str], Callable[[Any], Any]] = {
    ("Integer", "Real"): float,
    ("Enumeration", "Real"): float,
    ("Boolean", "Real"): float,
    ("Boolean", "Integer"): int,
    ("Integer", "Enumeration"): int,
    ("Enumeration", "Integer"): int,
}


def article(word: str) -> str:
    """``word`` with its indefinite article: "an Integer", "an Int8", "a UInt8", "a Real"."""
    return f"{'an' if word[:1].upper() in 'AEIO' else 'a'} {word}"


def narrowing(src_fmi: str, dst_fmi: str, what: str) -> None:
    """:class:`ConfigError` naming ``what`` when a connection from an output of FMI type
    ``src_fmi`` to an input of FMI type ``dst_fmi`` can lose values: an integer type whose
    range does not hold the source's (Int64 -> Int8, UInt8 -> Int8, FMI 2.0 Integer is Int32),
    an Enumeration (Int64 in FMI 3.0) into a shorter integer, or Float64 -> Float32.
    Unknown types ("" or a Python participant's class) are not checked."""
    ranges = {**INT_RANGE, "Integer": INT_RANGE["Int32"], "Enumeration": INT_RANGE["Int64"],
              "Boolean": (0, 1)}  # fmt: skip
    if src_fmi in ranges and (dst_fmi in INT_RANGE or dst_fmi == "Integer"):
        (slo, shi), (dlo, dhi) = ranges[src_fmi], ranges[dst_fmi]
        if slo < dlo or shi > dhi:
            raise ConfigError(
                f"{what}: narrowing connection: {article(src_fmi)} output ({slo} .. {shi}) into "
                f"{article(dst_fmi)} input ({dlo} .. {dhi}) can lose values; connect it to an input "
                "whose type holds every value of the output's, or change the output's type."
            )
    if src_fmi == "Float64" and dst_fmi == "Float32":
        raise ConfigError(
            f"{what}: narrowing connection: a Float64 output into a Float32 input loses precision "
            "and range; connect it to a Float64 input, or make the output a Float32."
        )


def type_conversion(src_type: str, dst_type: str, what: str) -> Callable[[Any], Any] | None:
    """The conversion a connection from a ``src_type`` output to a ``dst_type`` input applies
    (None: none needed, same class); :class:`ConfigError` naming ``what`` if not allowed."""
    if src_type == dst_type:
        return None
    conv = _CONVERSIONS.get((src_type, dst_type))
    if conv is None:
        allowed = ", ".join(f"{a} -> {b}" for a, b in _CONVERSIONS)
        raise ConfigError(
            f"{what}: cannot connect {article(src_type)} output to {article(dst_type)} input; "
            f"allowed conversions: {allowed} (and any type to itself)."
        )
    return conv


def _fmi_type(v: Any) -> str:
    return str(v.type)


def element_names(v: Any, by_vr: Mapping[int, Any]) -> list[str]:
    """``v.name`` for a scalar, ``name[1]`` .. for an array (sizes from the dimensions' start
    values or the structural parameters they reference)."""
    dims = getattr(v, "dimensions", None) or []
    if not dims:
        return [v.name]
    sizes = []
    for d in dims:
        if d.start not in (None, ""):
            sizes.append(int(d.start))
        else:
            ref = by_vr.get(d.valueReference)
            if ref is None or ref.start in (None, ""):
                raise ConfigError(
                    f"array variable {v.name!r}: dimension refers to value reference {d.valueReference} "
                    "without a start value."
                )
            sizes.append(int(ref.start))
    idx = itertools.product(*(range(1, s + 1) for s in sizes))
    return [f"{v.name}[{','.join(map(str, i))}]" for i in idx]


@dataclass
class _Group:
    """Variables of one FMI type read or written in one call."""

    fmi_type: str
    vrs: list[int]
    names: list[str]  # element names, in value order
    convert: Callable[[Any], Any]


class FmuVariables:
    """Inputs, outputs (element name -> unit), their type classes (:attr:`types`) and the
    calls that read / write them for one model description."""

    def __init__(self, md: Any, fmu_name: str):
        self.fmi3 = md.fmiVersion.startswith("3")
        self.fmu_name = fmu_name
        by_vr = {v.valueReference: v for v in md.modelVariables}
        self.inputs: dict[str, str] = {}
        self.outputs: dict[str, str] = {}
        self.types: dict[str, str] = {}
        self.fmi_types: dict[str, str] = {}
        """Each element's FMI type (Float64, Int8, .., FMI 2.0 Real, Integer ..)."""
        self.unsupported: dict[str, str] = {}  # variable -> its FMI type (Binary, Clock)
        out_groups: dict[str, _Group] = {}
        self._in_vars: dict[str, tuple[str, int, list[str]]] = {}  # variable -> (type, vr, elements)
        self._in_element: dict[str, str] = {}  # element -> variable
        self._in_values: dict[str, list[Any]] = {}
        for v in md.modelVariables:
            if v.causality not in ("input", "output"):
                continue
            ftype = _fmi_type(v)
            cls = TYPE_CLASS.get(ftype)
            if cls is None:
                self.unsupported[v.name] = ftype
                continue
            names = element_names(v, by_vr)
            unit = _unit(v) if cls == "Real" else ""
            for e in names:
                self.types[e] = cls
                self.fmi_types[e] = ftype
                (self.inputs if v.causality == "input" else self.outputs)[e] = unit
            if v.causality == "output":
                g = out_groups.setdefault(ftype, _Group(ftype, [], [], PY_TYPE[cls]))
                g.vrs.append(v.valueReference)
                g.names.extend(names)
            else:
                self._in_vars[v.name] = (ftype, v.valueReference, names)
                self._in_values[v.name] = _starts(v, cls, len(names))
                for e in names:
                    self._in_element[e] = v.name
        self._out_groups = list(out_groups.values())
        self._raw_get: Any = None
        self._raw_set: Any = None
        self._scalar_real_in: dict[str, int] = {}
        self._slave: Any = None
        self._other_groups = self._out_groups  # read through FMPy's wrappers

    def _call(self, op: str, ftype: str) -> str:
        if self.fmi3:
            return f"{op}{'Int64' if ftype == 'Enumeration' else ftype}"
        return f"{op}{'Integer' if ftype == 'Enumeration' else ftype}"

    def bind(self, slave: Any) -> None:
        """Prepare direct calls of the FMU's float64 get/set functions for ``slave`` (an
        instantiated FMPy slave): FMPy's wrappers cost about 10 µs a call."""
        import ctypes

        self._raw_get = self._raw_set = None
        real = "Float64" if self.fmi3 else "Real"
        g = next((g for g in self._out_groups if g.fmi_type == real), None)
        fns = getattr(slave, "_functions", {})
        name = "fmi3GetFloat64" if self.fmi3 else "fmi2GetReal"
        self._other_groups = self._out_groups
        if g is not None and name in fns:
            n = len(g.names)
            self._raw_get = (
                fns[name],
                (ctypes.c_uint * len(g.vrs))(*g.vrs),
                len(g.vrs),
                (ctypes.c_double * n)(),
                n,
                tuple(g.names),
            )
            self._other_groups = [o for o in self._out_groups if o is not g]
        name = "fmi3SetFloat64" if self.fmi3 else "fmi2SetReal"
        if name in fns:
            self._raw_set = fns[name]
        self._set_plans: dict[tuple[str, ...], Any] = {}
        self._scalar_real_in = {
            e: vr for var, (ftype, vr, names) in self._in_vars.items() if ftype == real and len(names) == 1
            for e in names
        }  # fmt: skip
        self._slave = slave

    def fast_names(self) -> tuple[tuple[str, ...], tuple[str, ...]] | None:
        """(The scalar float64 inputs, the outputs in the order :meth:`real_io` reads them)
        when every output is float64 (FMI 2.0 Real, FMI 3.0 Float64), else None."""
        real = "Float64" if self.fmi3 else "Real"
        if len(self._out_groups) > 1 or any(g.fmi_type != real for g in self._out_groups):
            return None
        ins = tuple(e for ftype, _, names in self._in_vars.values() if ftype == real and len(names) == 1
                    for e in names)  # fmt: skip
        return ins, tuple(self._out_groups[0].names) if self._out_groups else ()

    def real_io(
        self, slave: Any, names: tuple[str, ...], in_values: Any, out_values: Any
    ) -> tuple[Callable[[], None] | None, Callable[[], None] | None]:
        """Calls of the FMU's own float64 set / get functions on ``slave`` (instantiated) that
        set the scalar float64 inputs ``names`` from the ctypes double array ``in_values``
        and read every output (:meth:`fast_names`) into ``out_values`` (None: no call)."""
        import ctypes

        fns, comp, fmi3 = slave._functions, slave.component, self.fmi3
        set_call = get_call = None
        if names:
            scalar = (self.fast_names() or ((), ()))[0]
            missing = [e for e in names if e not in scalar]
            if missing:
                raise ConfigError(f"FMU {self.fmu_name}: {missing} are not scalar float64 inputs.")
            vrs = (ctypes.c_uint * len(names))(*(self._in_vars[e][1] for e in names))
            set_call = self._raw_call("fmi3SetFloat64" if fmi3 else "fmi2SetReal", fns, comp, vrs, in_values)
        g = self._out_groups[0] if self._out_groups else None
        if g is not None:
            vrs = (ctypes.c_uint * len(g.vrs))(*g.vrs)
            get_call = self._raw_call("fmi3GetFloat64" if fmi3 else "fmi2GetReal", fns, comp, vrs, out_values)
        return set_call, get_call

    def _raw_call(
        self, name: str, fns: Mapping[str, Any], comp: Any, vrs: Any, values: Any
    ) -> Callable[[], None]:
        fn, nvr, n = fns[name], len(vrs), len(values)
        args = (comp, vrs, nvr, values, n) if self.fmi3 else (comp, vrs, nvr, values)

        def call() -> None:
            st = fn(*args)
            if st > 1:
                self._status(name, st)

        return call

    def _status(self, fn: str, status: int) -> None:
        if status > 1:  # fmiOK, fmiWarning
            from fmpy.fmi1 import FMICallException

            raise FMICallException(function=fn, status=status)

    def get_outputs(self, slave: Any) -> dict[str, Any]:
        """Every output element's value."""
        raw = self._raw_get if slave is self._slave else None
        groups = self._out_groups
        if raw is not None:
            fn, vrs, nvr, buf, n, names = raw
            st = fn(slave.component, vrs, nvr, buf, n) if self.fmi3 else fn(slave.component, vrs, nvr, buf)
            if st > 1:
                self._status("fmi3GetFloat64" if self.fmi3 else "fmi2GetReal", st)
            out = dict(zip(names, buf, strict=True))
            groups = self._other_groups
        else:
            out = {}
        for g in groups:
            fn = getattr(slave, self._call("get", g.fmi_type))
            vals = fn(g.vrs, len(g.names)) if self.fmi3 else fn(g.vrs)
            if g.fmi_type == "Binary":
                out.update(zip(g.names, (bytes(v).hex() for v in vals), strict=True))
                continue
            for n, val in zip(g.names, vals, strict=True):
                out[n] = g.convert(val.decode() if isinstance(val, bytes) else val)
        return out

    def set_inputs(self, slave: Any, values: Mapping[str, Any]) -> None:
        """Set input elements (an array variable is written whole, with its other elements
        as last set)."""
        fast = self._raw_set is not None and slave is self._slave
        key = tuple(values)
        plan = self._set_plans.get(key) if fast else None
        if plan is None and fast and all(e in self._scalar_real_in for e in values):
            import ctypes

            n = len(values)
            # value references of these inputs, made once (scalars: a later write through
            # the general path below sets each of them from its own value, so no copy is kept)
            plan = ((ctypes.c_uint * n)(*(self._scalar_real_in[e] for e in values)), ctypes.c_double * n, n)
            self._set_plans[key] = plan
        if plan is not None:
            cvrs, ctype, n = plan
            cvals = ctype(*values.values())
            st = (
                self._raw_set(slave.component, cvrs, n, cvals, n)
                if self.fmi3
                else self._raw_set(slave.component, cvrs, n, cvals)
            )
            if st > 1:
                self._status("fmi3SetFloat64" if self.fmi3 else "fmi2SetReal", st)
            return
        touched: dict[str, None] = {}
        for e, val in values.items():
            var = self._in_element.get(e)
            if var is None:
                raise ConfigError(f"FMU {self.fmu_name} has no input {e!r}; inputs: {sorted(self.inputs)}.")
            ftype, _, names = self._in_vars[var]
            val = PY_TYPE[self.types[e]](val)
            if ftype in INT_RANGE:
                self._in_range(ftype, e, val, "input")
            self._in_values[var][names.index(e) if len(names) > 1 else 0] = val
            touched[var] = None
        by_type: dict[str, tuple[list[int], list[Any]]] = {}
        for var in touched:
            ftype, vr, _ = self._in_vars[var]
            refs, vals = by_type.setdefault(ftype, ([], []))
            refs.append(vr)
            vals.extend(self._in_values[var])
        for ftype, (refs, vals) in by_type.items():
            if ftype == "Binary":
                vals = [_hex_bytes(v, self.fmu_name, "input") for v in vals]
            getattr(slave, self._call("set", ftype))(refs, vals)

    def _in_range(self, ftype: str, name: str, value: int, what: str) -> None:
        lo, hi = INT_RANGE[ftype]
        if not lo <= value <= hi:
            raise ConfigError(
                f"FMU {self.fmu_name}: {what} {name!r} is {article(ftype)} ({lo} .. {hi}), got {value}."
            )

    def set_parameter(self, slave: Any, var: Any, value: Any) -> None:
        """Set the scalar variable ``var`` (a model variable) to ``value`` (checked against
        its type)."""
        self.check_parameter(var, value)
        ftype = _fmi_type(var)
        cls = TYPE_CLASS[ftype]
        v = PY_TYPE[cls](value)
        if ftype == "Binary":
            v = _hex_bytes(v, self.fmu_name, f"parameter {var.name!r}")
        getattr(slave, self._call("set", ftype))([var.valueReference], [v])

    def check_parameter(self, var: Any, value: Any) -> None:
        """:class:`ConfigError` unless ``value`` suits the scalar variable ``var``."""
        ftype = _fmi_type(var)
        cls = TYPE_CLASS.get(ftype)
        if cls is None:
            raise ConfigError(f"FMU {self.fmu_name}: variable {var.name!r} of type {ftype} cannot be set.")
        if getattr(var, "dimensions", None):
            raise ConfigError(
                f"FMU {self.fmu_name}: variable {var.name!r} is an array; set array parameters through "
                "a start value in the FMU."
            )
        if cls == "String" and not isinstance(value, str):
            raise ConfigError(f"FMU {self.fmu_name}: parameter {var.name!r} is a String, got {value!r}.")
        if cls == "Binary":
            if not isinstance(value, str):
                raise ConfigError(
                    f"FMU {self.fmu_name}: parameter {var.name!r} is a Binary (hexadecimal text), "
                    f"got {value!r}."
                )
            _hex_bytes(value, self.fmu_name, f"parameter {var.name!r}")
            return
        if cls in ("Integer", "Enumeration") and (isinstance(value, float) and value != int(value)):
            raise ConfigError(
                f"FMU {self.fmu_name}: parameter {var.name!r} is {article(cls)}, got {value!r}."
            )
        if cls != "String" and isinstance(value, str):
            raise ConfigError(
                f"FMU {self.fmu_name}: parameter {var.name!r} is {article(cls)}, got the text {value!r}."
            )
        if ftype in INT_RANGE:
            self._in_range(ftype, var.name, int(value), "parameter")


def _hex_bytes(text: str, fmu: str, what: str) -> bytes:
    """The bytes of the hexadecimal ``text`` (a Binary value); :class:`ConfigError` naming
    ``what`` of FMU ``fmu`` if it is not hexadecimal."""
    try:
        return bytes.fromhex(text)
    except ValueError:
        raise ConfigError(
            f"FMU {fmu}: {what} is a Binary: expected hexadecimal bytes such as '01ff', got {text!r}."
        ) from None


def _starts(v: Any, cls: str, n: int) -> list[Any]:
    """Start values of the ``n`` elements of ``v`` (the type's zero without one)."""
    s = getattr(v, "start", None)
    if s in (None, "", b""):
        return [PY_TYPE[cls]("" if cls in ("String", "Binary") else 0)] * n
    if cls in ("String", "Binary"):
        return [s.hex() if isinstance(s, bytes) else str(s)] * n
    items = str(s).split()
    items = items if len(items) == n else [items[0]] * n
    if cls == "Boolean":
        return [i.lower() in ("true", "1") for i in items]
    return [int(i) if cls in ("Integer", "Enumeration") else float(i) for i in items]


def _unit(v: Any) -> str:
    u = getattr(v, "unit", None) or (v.declaredType.unit if getattr(v, "declaredType", None) else None)
    return str(u or "")

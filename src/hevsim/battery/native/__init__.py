"""Native (compiled C99) FMI co-simulation FMUs of a cell or an n_s x n_p module (issue 16).

:func:`export_native_fmu` generates C source from a cell parameter set (the OCV, resistance
and capacity tables as constant arrays, the RC sets, the lumped thermal model, the capacity
fade with charge throughput, the module's current sharing and cell-to-cell spread), compiles
it with the system C compiler against the FMI headers that FMPy ships (``fmpy/c-code``) and
packs an FMU that needs no Python: the binary for this platform, the sources
(``sources/`` with ``buildDescription.xml``) to rebuild it elsewhere, and a model description
with the variables, units, causalities, start values and capabilities of the pythonfmu FMU of
:mod:`hevsim.battery.fmu` (so a co-simulation runs with either kind unchanged), plus two
constants ``v_min_v`` / ``v_max_v`` (the cell's voltage limits).

The C kernel (``templates/hevsim_kernel.h``) is a line-by-line translation of
:mod:`hevsim.battery.kernel` with its model options (``[model] rc_mode``/``ocv_mode``,
``[charge_transfer]``, ``[hysteresis]``; off by default, the thesis's model).

Run-time checks (``fmi2Error``/``fmi3Error`` with a logger message naming the variable and the
value; the state is left as before the call): setting an output or a constant, a non-finite
value, a parameter outside its range (``soc_initial`` outside the SOC axis of the tables and
[0, 1], ``temp_initial_k`` outside 150..500 K, a non-positive capacity, heat capacity, skin
resistance or resistance scale); at ``DoStep`` a port temperature outside the cell model's
150..500 K, a non-finite current or power, and a step that leaves the model's domain (terminal
voltage <= 0, a cell's state of charge outside [0, 1], a cell temperature outside 150..500 K) as
:func:`hevsim.battery.cell.check_cell_domain`.
"""

from __future__ import annotations

import hashlib
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from hevsim.battery import kernel as K
from hevsim.battery.cell import CELL_TEMP_RANGE_K, SOC_TOLERANCE
from hevsim.battery.fmu import (
    CELL_INPUTS,
    CELL_OUTPUTS,
    FMU_PARAMETERS,
    INPUTS,
    OUTPUTS,
    UNIT_EXPONENTS,
    unit_of,
)
from hevsim.battery.params import CellParameters, load_cell_parameters
from hevsim.errors import ConfigError, HevsimError

TEMPLATES = ("hevsim_kernel.h", "hevsim_model.h", "hevsim_fmi.h")
"""C sources shared by the FMI 2.0 and 3.0 wrappers (package data under ``templates/``)."""
WRAPPERS = {2: "fmi2_model.c", 3: "fmi3_model.c"}
"""The FMI interface source per FMI major version."""
FMI_VERSIONS = tuple(WRAPPERS)

CELL_TEMP_DOMAIN_K = CELL_TEMP_RANGE_K
"""Temperature domain of the lumped cell model [K] (:data:`hevsim.battery.cell.CELL_TEMP_RANGE_K`),
compiled into the FMU as ``HV_T_MIN_K`` / ``HV_T_MAX_K``; the SOC domain [0, 1] with
:data:`hevsim.battery.cell.SOC_TOLERANCE` as ``HV_SOC_TOL``."""

# variable kinds of the generated table VAR_KIND (hevsim_model.h, fmi2_model.c)
_KINDS = {"input": "K_INPUT", "parameter": "K_PARAMETER", "boolean": "K_BOOLEAN", "output": "K_OUTPUT"}
_KINDS.update(constant="K_CONSTANT", independent="K_INDEPENDENT")


class NativeFMUError(HevsimError):
    """A native FMU cannot be built: no C compiler, a compiler error, an unknown platform."""


@dataclass(frozen=True)
class Variable:
    """One FMU variable: value reference = position in :func:`variables`."""

    name: str
    kind: str  # input | parameter | boolean | output | constant | independent
    start: float
    description: str = ""
    lo: float = -np.inf
    hi: float = np.inf
    lo_open: bool = False
    range_text: str = ""
    unit: str | None = None  # None: from the name's suffix (hevsim.battery.fmu.unit_of)

    @property
    def causality(self) -> str:
        return {"boolean": "parameter", "constant": "local"}.get(self.kind, self.kind)

    @property
    def settable(self) -> bool:
        return self.kind in ("input", "parameter", "boolean")

    @property
    def declared_unit(self) -> str | None:
        """The unit declared in the model description (none for a Boolean)."""
        if self.kind == "boolean":
            return None
        if self.kind == "independent":
            return "s"
        return self.unit or unit_of(self.name)


def _num(v: float) -> str:
    """A double as C / XML text that reads back to the same value."""
    v = float(v)
    if not np.isfinite(v):
        raise NativeFMUError(f"internal: non-finite number {v!r} in the generated model data")
    return repr(v)


def _c_limit(v: float) -> str:
    return "HUGE_VAL" if v == np.inf else "-HUGE_VAL" if v == -np.inf else _num(v)


def variables(
    p: CellParameters,
    n_cells: int,
    soc_initial: float,
    temp_initial_k: float,
    starts: dict[str, float],
    fmi_version: int = 2,
) -> list[Variable]:
    """The FMU's variables in the value-reference order of the pythonfmu FMU, then the constants
    (and, for FMI 3.0, the independent variable ``time`` [s]).

    ``starts``: start values of the outputs (the stepper's initial outputs).
    """
    vec = p.vector(soc_initial)
    soc_lo, soc_hi = max(0.0, float(p.soc[0])), min(1.0, float(p.soc[-1]))
    t_lo, t_hi = CELL_TEMP_DOMAIN_K
    out: list[Variable] = [
        Variable("current_a", "input", 0.0, "cell or module current, discharge > 0"),
        Variable("power_w", "input", 0.0, "terminal power when power_input, discharge > 0"),
        Variable("port_temp_k", "input", temp_initial_k, "heat-port temperature"),
        Variable("power_input", "boolean", 0.0, "drive by power_w instead of current_a"),
    ]
    if n_cells > 1:
        out.append(Variable("per_cell_ports", "boolean", 0.0, "use cell<c>_port_temp_k per cell"))
    out += [
        Variable(
            "soc_initial", "parameter", soc_initial, "initial SOC", soc_lo, soc_hi, False,
            f"[{soc_lo:g}, {soc_hi:g}] (the SOC axis of the cell tables and [0, 1])",
        ),
        Variable(
            "temp_initial_k", "parameter", temp_initial_k, "initial cell temperature", t_lo, t_hi, False,
            f"[{t_lo:g}, {t_hi:g}] K (the cell model's temperature domain)",
        ),
    ]  # fmt: skip
    positive = {"c0_c", "c_heat_j_per_k", "r_skin_k_per_w", "r_scale"}
    for name, idx in FMU_PARAMETERS.items():
        if name in positive:
            out.append(Variable(name, "parameter", float(vec[idx]), "", 0.0, np.inf, True, "(0, inf): > 0"))
        else:
            out.append(Variable(name, "parameter", float(vec[idx]), "", range_text="any finite number"))
    out += [Variable(name, "output", starts[name]) for name in OUTPUTS]
    out.append(Variable("terminal_current_a", "output", 0.0, "current drawn over the last step"))
    if n_cells > 1:
        (port_in,) = CELL_INPUTS
        out += [Variable(port_in.format(c=c), "input", temp_initial_k) for c in range(n_cells)]
        heat_t, temp_t = CELL_OUTPUTS
        out += [Variable(heat_t.format(c=c), "output", 0.0) for c in range(n_cells)]
        out += [Variable(temp_t.format(c=c), "output", temp_initial_k) for c in range(n_cells)]
    out += [
        Variable("v_min_v", "constant", p.limits.v_min_v, "cell discharge voltage limit (OCV at SOC 0)"),
        Variable("v_max_v", "constant", p.limits.v_max_v, "cell charge voltage limit (OCV at SOC 1)"),
    ]
    if fmi_version == 3:
        out.append(Variable("time", "independent", 0.0, "simulation time [s]"))
    assert set(INPUTS) <= {v.name for v in out}
    return out


def _macro(name: str) -> str:
    return "VR_" + re.sub(r"\W", "_", name).upper()


def _c_array(values: np.ndarray) -> str:
    a = np.asarray(values, float)
    if a.ndim == 1:
        return "{" + ", ".join(_num(v) for v in a) + "}"
    return "{\n    " + ",\n    ".join(_c_array(row) for row in a) + "\n}"


def model_data(
    p: CellParameters,
    model_identifier: str,
    vars_: list[Variable],
    n_series: int,
    n_parallel: int,
    c0_scale: np.ndarray,
    r_scale: np.ndarray,
) -> str:
    """Text of ``model_data.h`` (without the GUID line, which hashes this text)."""
    tabs = p.tables()
    soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c = tabs
    base = p.vector(1.0)
    prm = [base[i] for i in (K.C0, K.KCQ, K.ALPHAC, K.TREF, K.ALPHARS, K.CHEAT, K.RSKIN, K.VMIN, K.VMAX)]
    prm += [base[K.SOCINI], base[K.RSCALE], base[K.IBAND]]
    prm += [base[i] for i in (K.RCPERS, K.OCVSTEP, K.CTI0, K.CTM, K.CTEA, K.HMAX, K.HGAMMA)]
    prm += [base[i] for i in (K.EARS, K.HEA, K.ENTROPIC)]
    rc_d, rc_c = (np.c_[rc, np.zeros((rc.shape[0], 4 - rc.shape[1]))] for rc in (rc_d, rc_c))
    n_cells = n_series * n_parallel
    lines = [
        f"/* Model data of the hevsim native FMU {model_identifier}, generated by hevsim.battery.native",
        f" * from the cell parameter set '{p.name}' ({Path(p.source).name}). SI units. */",
        "#ifndef HEVSIM_MODEL_DATA_H",
        "#define HEVSIM_MODEL_DATA_H",
        "#include <math.h>",
        f'#define MODEL_IDENTIFIER "{model_identifier}"',
        f"#define NSOC {soc_ax.size}",
        f"#define NT {t_ax.size}",
        f"#define NRC {p.n_rc}",
        f"#define N_SER {n_series}",
        f"#define N_PAR {n_parallel}",
        f"#define N_CELLS {n_cells}",
        f"#define X_C {_num(p.ageing.x_c)} /* SOH_C end-of-life capacity fraction, eq (43) */",
        f"static const double SOC_AX[NSOC] = {_c_array(soc_ax)};",
        f"static const double T_AX[NT] = {_c_array(t_ax)};",
        "/* tables [SOC][temperature] */",
        f"static const double OCV_C[NSOC][NT] = {_c_array(ocv_c)};",
        f"static const double OCV_D[NSOC][NT] = {_c_array(ocv_d)};",
        f"static const double RS_C[NSOC][NT] = {_c_array(rs_c)};",
        f"static const double RS_D[NSOC][NT] = {_c_array(rs_d)};",
        f"static const double CAPF[NT] = {_c_array(capf)};",
        "/* RC elements (R [ohm], tau [s], their activation energies Ea_R, Ea_tau [J/mol]) of the",
        " * discharge and charge sets (one unused row if NRC = 0) */",
        f"static const double RC_D[{max(p.n_rc, 1)}][4] = {_c_array(rc_d)};",
        f"static const double RC_C[{max(p.n_rc, 1)}][4] = {_c_array(rc_c)};",
        "/* c0, k_cqabs, alpha_c, t_ref, alpha_rs, c_heat, r_skin, v_min, v_max, soc_ini, r_scale, band,",
        " * options: rc_persistent, ocv_in_step, ct_i0_a, ct_scale, ct_ea, hyst_max_v, hyst_gamma,",
        " * temperature laws: rs_ea, hyst_ea, entropic_heat */",
        f"static const double PRM_BASE[{len(prm)}] = {_c_array(np.array(prm))};",
        "/* per-cell spread: C0 and resistance scale factors (cell c = series group * N_PAR + branch) */",
        f"static const double C0_SCALE[N_CELLS] = {_c_array(c0_scale)};",
        f"static const double R_SCALE[N_CELLS] = {_c_array(r_scale)};",
        f"#define HV_T_MIN_K {_num(CELL_TEMP_DOMAIN_K[0])}",
        f"#define HV_T_MAX_K {_num(CELL_TEMP_DOMAIN_K[1])}",
        f"#define HV_SOC_TOL {_num(SOC_TOLERANCE)}",
    ]
    return "\n".join(lines + variable_table(vars_)) + "\n"


def variable_table(vars_: list[Variable]) -> list[str]:
    """Lines of ``model_data.h`` that describe the variables: a ``VR_<NAME>`` macro per value
    reference (``VR_CELL_<QUANTITY>0`` / ``VR_SEGMENT_<QUANTITY>0`` for the first of a numbered
    series ``cell<c>_...`` / ``segment<s>_...``, whose members follow it) and the tables of kinds,
    names, start values and ranges."""
    lines = [
        "/* variables by value reference */",
        "enum { K_INPUT, K_PARAMETER, K_BOOLEAN, K_OUTPUT, K_CONSTANT, K_INDEPENDENT };",
        f"#define N_VR {len(vars_)}",
    ]
    first: dict[str, int] = {}
    for vr, v in enumerate(vars_):
        m = re.fullmatch(r"(cell|segment)(\d+)_(.*)", v.name)
        if m:
            quantity = m.group(3).upper().removesuffix("_K").removesuffix("_W")
            macro = f"VR_{m.group(1).upper()}_{quantity}0"
            if macro not in first:
                first[macro] = vr
                lines.append(f"#define {macro} {vr}")
            if vr != first[macro] + int(m.group(2)):
                raise NativeFMUError(f"internal: variable {v.name} is not at {macro} + {m.group(2)}")
            continue
        lines.append(f"#define {_macro(v.name)} {vr}")
    lines += [
        f"static const int VAR_KIND[N_VR] = {{{', '.join(_KINDS[v.kind] for v in vars_)}}};",
        "static const char *const VAR_NAME[N_VR] = {" + ", ".join(f'"{v.name}"' for v in vars_) + "};",
        f"static const double VAR_START[N_VR] = {_c_array(np.array([v.start for v in vars_]))};",
        "static const double VAR_MIN[N_VR] = {" + ", ".join(_c_limit(v.lo) for v in vars_) + "};",
        "static const double VAR_MAX[N_VR] = {" + ", ".join(_c_limit(v.hi) for v in vars_) + "};",
        "static const int VAR_MIN_OPEN[N_VR] = {" + ", ".join(str(int(v.lo_open)) for v in vars_) + "};",
        "static const char *const VAR_RANGE[N_VR] = {" + ", ".join(f'"{v.range_text}"' for v in vars_) + "};",
    ]
    return lines


_EXPONENTS = {
    **UNIT_EXPONENTS,
    "s": {"s": 1},
    "J": {"kg": 1, "m": 2, "s": -2},
    "W/(m2.K)": {"kg": 1, "s": -3, "K": -1},
}


def _units_used(vars_: list[Variable]) -> list[str]:
    used: list[str] = []
    for v in vars_:
        u = v.declared_unit
        if u is not None and u not in used:
            used.append(u)
    return used


def model_description(
    fmi_version: int, model_identifier: str, guid: str, description: str, vars_: list[Variable]
) -> bytes:
    """``modelDescription.xml`` (FMI 2.0 or 3.0 co-simulation) of the native FMU."""
    from hevsim import __version__

    tool = f"hevsim {__version__} (native C99 FMU)"
    common = {"modelName": model_identifier, "description": description, "author": "hevsim"}
    caps = {
        "modelIdentifier": model_identifier,
        "needsExecutionTool": "false",
        "canHandleVariableCommunicationStepSize": "true",
        "canBeInstantiatedOnlyOncePerProcess": "false",
        "canGetAndSetFMUstate": "true",
        "canSerializeFMUstate": "true",
    }
    if fmi_version == 2:
        head = {"fmiVersion": "2.0", **common, "guid": guid, "generationTool": tool}
        root = ET.Element("fmiModelDescription", head)
        root.set("variableNamingConvention", "structured")
        root.set("numberOfEventIndicators", "0")
        caps.update(canInterpolateInputs="false", canNotUseMemoryManagementFunctions="true")
    else:
        head = {"fmiVersion": "3.0", **common, "instantiationToken": guid, "generationTool": tool}
        root = ET.Element("fmiModelDescription", head)
        root.set("variableNamingConvention", "structured")
        # FMI 3.0 spells the state capabilities with a capital S
        del caps["canGetAndSetFMUstate"], caps["canSerializeFMUstate"]
        caps.update(canGetAndSetFMUState="true", canSerializeFMUState="true")
        caps.update(providesIntermediateUpdate="false", hasEventMode="false")
    ET.SubElement(root, "CoSimulation", caps)
    used = _units_used(vars_)
    if used:
        defs = ET.SubElement(root, "UnitDefinitions")
        for name in used:
            u = ET.SubElement(defs, "Unit", name=name)
            ET.SubElement(u, "BaseUnit", {k: str(v) for k, v in _EXPONENTS[name].items()})
    cats = ET.SubElement(root, "LogCategories")
    for name, text in (
        ("logStatusError", "Log messages with error status (refused values, model domain left)."),
        ("logAll", "Log all messages."),
    ):
        ET.SubElement(cats, "Category", name=name, description=text)
    mv = ET.SubElement(root, "ModelVariables")
    outputs: list[int] = []
    for vr, v in enumerate(vars_):
        attrs = {"name": v.name, "valueReference": str(vr)}
        if v.description:
            attrs["description"] = v.description
        attrs["causality"] = v.causality
        if v.kind in ("parameter", "boolean"):
            attrs["variability"] = "tunable"
        elif v.kind == "constant":
            attrs["variability"] = "constant"
        if v.kind in ("output", "constant"):
            attrs["initial"] = "exact"
        if v.kind == "output":
            outputs.append(vr)
        unit = v.declared_unit
        start = ("true" if v.start else "false") if v.kind == "boolean" else _num(v.start)
        if v.kind == "independent":
            el = ET.SubElement(mv, "Float64", attrs)
            el.set("unit", "s")
            continue
        if fmi_version == 2:
            sv = ET.SubElement(mv, "ScalarVariable", attrs)
            typ = ET.SubElement(sv, "Boolean" if v.kind == "boolean" else "Real", start=start)
            if unit:
                typ.set("unit", unit)
        else:
            el = ET.SubElement(mv, "Boolean" if v.kind == "boolean" else "Float64", attrs)
            if unit:
                el.set("unit", unit)
            el.set("start", start)
    ms = ET.SubElement(root, "ModelStructure")
    if fmi_version == 2:
        outs = ET.SubElement(ms, "Outputs")
        for vr in outputs:
            ET.SubElement(outs, "Unknown", index=str(vr + 1))
    else:
        for vr in outputs:
            ET.SubElement(ms, "Output", valueReference=str(vr))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def build_description(model_identifier: str, fmi_version: int) -> bytes:
    """``sources/buildDescription.xml`` (the FMI 3.0 build description format, also used by
    FMI 2.0.4 FMUs): one C99 source file (it includes the other sources, headers); link the
    maths library where it is separate."""
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    bc = ET.SubElement(root, "BuildConfiguration", modelIdentifier=model_identifier)
    fs = ET.SubElement(bc, "SourceFileSet", language="C99")
    ET.SubElement(fs, "SourceFile", name=WRAPPERS[fmi_version])
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def fmi_headers(fmi_version: int) -> Path:
    """FMPy's folder of FMI headers (``fmpy/c-code``), checked for the version's header."""
    try:
        import fmpy
    except ImportError as exc:  # pragma: no cover - fmpy is a dependency
        raise NativeFMUError(
            "the FMI headers come from FMPy, which is not installed (pip install fmpy)."
        ) from exc
    folder = Path(fmpy.__file__).parent / "c-code"
    header = folder / f"fmi{fmi_version}Functions.h"
    if not header.is_file():
        raise NativeFMUError(f"FMPy's FMI headers are missing: {header} not found (reinstall fmpy).")
    return folder


def find_compiler() -> str:
    """The C compiler: ``$CC``, else ``cc``, ``gcc`` or ``clang`` on the PATH."""
    candidates = [os.environ["CC"]] if os.environ.get("CC") else []
    candidates += ["cc", "gcc", "clang"]
    for name in candidates:
        path = shutil.which(name)
        if path:
            return path
    raise NativeFMUError(
        f"no C compiler found (looked for {', '.join(candidates)} on the PATH) to build the native FMU; "
        "install one (Debian/Ubuntu: apt-get install gcc; Fedora: dnf install gcc; macOS: "
        "xcode-select --install) or set CC; or export with --pythonfmu (an FMU that needs no compiler "
        "but a host with Python and hevsim installed)."
    )


def platform_binary(fmi_version: int, model_identifier: str) -> str:
    """The FMU path of this platform's binary (``binaries/<platform>/<id>.<ext>``)."""
    machine = platform.machine().lower()
    arch = {"amd64": "x86_64", "x86_64": "x86_64", "arm64": "aarch64", "aarch64": "aarch64"}.get(machine)
    if sys.platform.startswith("linux"):
        osname, ext = "linux", "so"
    elif sys.platform == "darwin":
        osname, ext = "darwin", "dylib"
    else:
        raise NativeFMUError(
            f"native FMUs are built on Linux and macOS (this is {sys.platform}); the FMU's sources "
            "can be compiled on Windows by an FMI tool."
        )
    if arch is None:
        raise NativeFMUError(f"native FMUs: processor {machine!r} is not known (x86_64 or aarch64).")
    if fmi_version == 2:
        if arch != "x86_64" and osname == "linux":
            raise NativeFMUError(
                f"FMI 2.0 has no platform folder for {osname} on {arch}; use --fmi-version 3."
            )
        folder = f"{osname}64"
    else:
        folder = f"{arch}-{osname}"
    return f"binaries/{folder}/{model_identifier}.{ext}"


def compile_command(cc: str, src_dir: Path, fmi_version: int, out_lib: Path, opt: str = "-O2") -> list[str]:
    """The compiler call that builds the FMU's shared library from its sources (``opt``: the
    optimisation flag; IEEE semantics are kept: no fast-math, no contraction into FMA)."""
    shared = "-dynamiclib" if sys.platform == "darwin" else "-shared"
    return [
        cc, "-std=c99", opt, "-ffp-contract=off", "-fPIC", shared, "-Wall", "-Wextra",
        f"-I{fmi_headers(fmi_version)}", f"-I{src_dir}", str(src_dir / WRAPPERS[fmi_version]),
        "-o", str(out_lib), "-lm",
    ]  # fmt: skip


def _template(name: str) -> str:
    return (resources.files("hevsim.battery.native") / "templates" / name).read_text()


def export_native_fmu(
    params: str | Path | CellParameters,
    out_fmu: str | Path,
    soc_initial: float = 1.0,
    temp_initial_k: float = 298.15,
    model_name: str | None = None,
    n_series: int = 1,
    n_parallel: int = 1,
    capacity_spread: float = 0.0,
    resistance_spread: float = 0.0,
    seed: int = 0,
    fmi_version: int = 2,
) -> Path:
    """Build ``out_fmu``: a native FMI 2.0 or 3.0 co-simulation FMU of the cell parameter set
    ``params`` (a shipped name, a TOML path or a :class:`CellParameters`), or of an
    ``n_series`` x ``n_parallel`` module of it with the given spread (as
    :class:`hevsim.battery.Module`). Same arguments as :func:`hevsim.battery.fmu.export_fmu`.
    Returns the FMU path; the file is written atomically.
    """
    from hevsim.battery.fmu import CellStepper, ModuleStepper

    if fmi_version not in FMI_VERSIONS:
        raise ConfigError(f"--fmi-version {fmi_version!r} is not supported; expected one of 2, 3.")
    p = params if isinstance(params, CellParameters) else load_cell_parameters(params)
    name = model_name or "HevsimCell_" + re.sub(r"\W", "_", p.name)
    n_cells = int(n_series) * int(n_parallel)
    if n_cells > 1 and model_name is None:
        name = f"{name}_{n_series}s{n_parallel}p"
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        raise ConfigError(f"FMU model name {name!r} must be a C identifier (letters, digits, _).")
    if not 0.0 <= soc_initial <= 1.0:
        raise ConfigError(f"soc_initial {soc_initial!r} must be between 0 and 1.")
    stepper: CellStepper | ModuleStepper
    if n_cells == 1:
        stepper = CellStepper(p, soc_initial, temp_initial_k)
        c0_scale, r_scale = np.ones(1), np.ones(1)
    else:
        stepper = ModuleStepper(
            p, soc_initial, temp_initial_k, n_series, n_parallel, capacity_spread, resistance_spread, seed
        )
        c0_scale, r_scale = stepper.m.c0_scale, stepper.m.r_scale
    vars_ = variables(p, n_cells, float(soc_initial), float(temp_initial_k), stepper.outputs, fmi_version)
    data = model_data(p, name, vars_, int(n_series), int(n_parallel), c0_scale, r_scale)
    what = "cell" if n_cells == 1 else f"{n_series}s{n_parallel}p module"
    desc = f"hevsim electro-thermal {what} '{p.name}' (thesis eqs 33-44), native C99"
    return build_fmu(out_fmu, fmi_version, name, desc, vars_, data, TEMPLATES)


def build_fmu(
    out_fmu: str | Path,
    fmi_version: int,
    name: str,
    description: str,
    vars_: list[Variable],
    data: str,
    templates: tuple[str, ...],
    opt: str = "-O2",
) -> Path:
    """Compile and pack a native FMU: ``data`` is the text of ``model_data.h`` (starting with
    its include guard ``#define HEVSIM_MODEL_DATA_H``, without the GUID, which hashes the
    sources, and without the closing ``#endif``), ``templates`` the other sources (besides the
    FMI wrapper). Writes ``out_fmu`` atomically and returns its path."""
    from hevsim.io import copy_file_atomic

    wrapper = _template(WRAPPERS[fmi_version])
    digest = hashlib.sha256((data + wrapper + "".join(_template(t) for t in templates)).encode()).hexdigest()
    guid = "{" + str(uuid.UUID(digest[:32])) + "}"
    guard = "#define HEVSIM_MODEL_DATA_H\n"
    data = data.replace(guard, f'{guard}#define MODEL_GUID "{guid}"\n', 1) + "#endif\n"
    xml = model_description(fmi_version, name, guid, description, vars_)
    lib_name = platform_binary(fmi_version, name)
    cc = find_compiler()
    out = Path(out_fmu)
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "sources"
        src.mkdir()
        files = {"model_data.h": data, WRAPPERS[fmi_version]: wrapper}
        files.update({t: _template(t) for t in templates})
        for fname, text in files.items():
            (src / fname).write_text(text)
        (src / "buildDescription.xml").write_bytes(build_description(name, fmi_version))
        lib = Path(tmp) / Path(lib_name).name
        cmd = compile_command(cc, src, fmi_version, lib, opt)
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if proc.returncode != 0 or not lib.is_file():
            raise NativeFMUError(
                f"the C compiler failed to build the native FMU (exit {proc.returncode}): {' '.join(cmd)}\n"
                f"{proc.stderr.strip()[-2000:]}"
            )
        fmu = Path(tmp) / f"{name}.fmu"
        with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", xml)
            z.write(lib, lib_name)
            for fname in sorted(os.listdir(src)):
                z.write(src / fname, f"sources/{fname}")
        copy_file_atomic(fmu, out)
    return out


def native_binary(fmu: str | Path) -> tuple[str, bytes]:
    """(name, bytes) of the platform binary inside a native FMU (for dependency checks)."""
    with zipfile.ZipFile(fmu) as z:
        names = [n for n in z.namelist() if n.startswith("binaries/") and not n.endswith("/")]
        if not names:
            raise NativeFMUError(f"{fmu}: no binary in the FMU.")
        return names[0], z.read(names[0])


def is_native_fmu(path: str | Path) -> bool:
    """True if ``path`` is an FMU written by :func:`export_native_fmu` (its model description
    names this generator)."""
    try:
        with zipfile.ZipFile(path) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError):
        return False
    return "(native C99 FMU)" in root.get("generationTool", "")


__all__ = [
    "FMI_VERSIONS",
    "NativeFMUError",
    "export_native_fmu",
    "find_compiler",
    "is_native_fmu",
    "model_description",
]

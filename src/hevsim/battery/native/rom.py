"""Native (compiled C99) FMI co-simulation FMU of a module's thermal reduced-order model.

:func:`export_rom_fmu` turns a ROM file written by ``hevsim rom build``
(:class:`hevsim.thermal.rom.ThermalRom`) into an FMI 2.0 or 3.0 co-simulation FMU that needs no
Python: the reduced matrices are embedded as constant arrays (``model_data.h``), the step is
the implicit Euler of :class:`hevsim.thermal.rom.RomStepper` (``templates/hevsim_rom.h``), so
the FMU equals the ROM stepped in Python to rounding.

Variables (value references in this order):

* inputs ``cell<c>_heat_w`` [W] (heat generated in cell c), ``segment<s>_fluid_temp_k`` [K]
  (coolant temperature along channel segment s), ``ambient_temp_k`` [K];
* parameters ``wall_h_w_m2k`` [W/(m^2 K)] (the channel-wall film, inside the range the ROM was
  built for; tunable: a change takes effect at the next step) and ``initial_temp_k`` [K] (the
  uniform initial temperature);
* outputs ``cell<c>_mean_temp_k`` and ``cell<c>_max_temp_k`` [K] (volume-mean and hot-spot
  temperature of cell c), ``segment<s>_wall_temp_k`` [K] (mean wall temperature of segment s),
  ``segment<s>_wall_heat_w`` [W] (heat into the coolant through segment s),
  ``ambient_heat_w`` [W] (to the ambient and the fixed boundary films) and ``stored_heat_j`` [J]
  (``sum C T`` of the reconstructed field, relative to 0 K);
* constant ``rom_order`` (the reduced order), and for FMI 3.0 the independent ``time`` [s].

The inputs act at the end of each communication step (implicit Euler, as the FEM), so a step
of the FMU is one step of the ROM at the communication step size; any step size is accepted
(the step matrices are recomputed when it or the wall film changes).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hevsim.battery.native import (
    FMI_VERSIONS,
    NativeFMUError,
    Variable,
    _c_array,
    _num,
    build_fmu,
    variable_table,
)
from hevsim.errors import ConfigError

if TYPE_CHECKING:
    from hevsim.thermal.rom import ThermalRom

ROM_TEMPLATES = ("hevsim_fmi.h", "hevsim_rom.h")
"""C sources of the ROM FMU besides the FMI wrapper and ``model_data.h``."""
WALL_H_SLACK = 1e-9
"""Relative slack of the wall-film range (as :meth:`hevsim.thermal.rom.ThermalRom.check_wall_h`)."""
WALL_H_UNIT = "W/(m2.K)"


def rom_variables(
    rom: ThermalRom, initial_temp_k: float, wall_h_w_m2k: float, fmi_version: int
) -> list[Variable]:
    """The ROM FMU's variables in value-reference order (module docstring), with the start
    values of the outputs for the uniform initial field, the metadata's inlet and ambient."""
    meta = rom.metadata
    fluid0 = float(meta.get("inlet_temp_k", initial_temp_k))
    amb0 = float(meta.get("ambient_k", initial_temp_k))
    z0 = rom.state_of_uniform(initial_temp_k)
    lo, hi = rom.wall_h_range_w_m2k

    def positive(name: str, kind: str, start: float, description: str) -> Variable:
        return Variable(name, kind, start, description, 0.0, np.inf, True, "(0, inf) K")

    out: list[Variable] = [
        Variable(f"cell{c}_heat_w", "input", 0.0, "heat generated in the cell") for c in range(rom.n_cells)
    ]
    out += [
        positive(f"segment{s}_fluid_temp_k", "input", fluid0, "coolant temperature along the segment")
        for s in range(rom.n_segments)
    ]
    out += [
        positive("ambient_temp_k", "input", amb0, "ambient temperature"),
        Variable(
            "wall_h_w_m2k", "parameter", wall_h_w_m2k, "channel-wall heat transfer coefficient",
            lo * (1 - WALL_H_SLACK), hi * (1 + WALL_H_SLACK), False,
            f"[{lo:.6g}, {hi:.6g}] W/(m^2 K) (the range the ROM was built and validated for)", WALL_H_UNIT,
        ),
        positive("initial_temp_k", "parameter", initial_temp_k, "uniform initial temperature"),
    ]  # fmt: skip
    wall = rom.wall_temp_k(z0)
    out += [Variable(f"cell{c}_mean_temp_k", "output", float(t), "cell volume-mean temperature")
            for c, t in enumerate(rom.cell_mean_k(z0))]  # fmt: skip
    out += [Variable(f"cell{c}_max_temp_k", "output", float(t), "cell hot-spot temperature")
            for c, t in enumerate(rom.cell_max_k(z0))]  # fmt: skip
    out += [Variable(f"segment{s}_wall_temp_k", "output", float(t), "mean wall temperature of the segment")
            for s, t in enumerate(wall)]  # fmt: skip
    heat0 = rom.wall_heat_w(z0, np.full(rom.n_segments, fluid0), wall_h_w_m2k)
    out += [Variable(f"segment{s}_wall_heat_w", "output", float(q), "heat into the coolant, segment")
            for s, q in enumerate(heat0)]  # fmt: skip
    out += [
        Variable("ambient_heat_w", "output", float(rom.ambient_heat_w(z0, amb0)), "heat to the ambient"),
        Variable(
            "stored_heat_j", "output", float(rom.stored_j(z0)), "sum C T of the field (from 0 K)", unit="J"
        ),
        Variable("rom_order", "constant", float(rom.order), "order of the reduced model", unit=""),
    ]
    if fmi_version == 3:
        out.append(Variable("time", "independent", 0.0, "simulation time [s]"))
    return out


def rom_model_data(
    rom: ThermalRom,
    model_identifier: str,
    source: str,
    vars_: list[Variable],
    dt_s: float,
    wall_h_w_m2k: float,
) -> str:
    """Text of ``model_data.h`` of the ROM FMU (without the GUID and the closing ``#endif``),
    with the step matrix of :class:`~hevsim.thermal.rom.RomStepper` for ``dt_s`` [s] and
    ``wall_h_w_m2k`` [W/(m^2 K)]."""
    from hevsim.battery.pack_run import hot_spot_rounding
    from hevsim.thermal.rom import RomStepper

    # the stepper's own (r + m, r) matrix, so that the FMU's product uses the same numbers
    step_t = RomStepper(rom, dt_s, wall_h_w_m2k, 0.0).step_matrix
    n_cells = rom.n_cells
    n_cand = rom.out_candidates.shape[0] // n_cells
    cand = np.asarray(rom.out_candidates, dtype=float)
    consts = hot_spot_rounding(cand, np.asarray(rom.unit_state, dtype=float))
    lines = [
        f"/* Model data of the hevsim native thermal ROM FMU {model_identifier}, generated by",
        f" * hevsim.battery.native.rom from {source} (mesh sha256 {rom.mesh_hash}). SI units. */",
        "#ifndef HEVSIM_MODEL_DATA_H",
        "#define HEVSIM_MODEL_DATA_H",
        "#include <math.h>",
        "#define HV_THERMAL_ROM 1",
        f'#define MODEL_IDENTIFIER "{model_identifier}"',
        f"#define NZ {rom.order} /* reduced order */",
        f"#define NCELL {n_cells}",
        f"#define NSEG {rom.n_segments}",
        f"#define NCAND {n_cand} /* hot-spot candidate nodes per cell */",
        "/* reduced conduction (K_s) and wall-film (K_w, per unit h) matrices [1/s] */",
        f"static const double K_SOLID[NZ][NZ] = {_c_array(rom.k_solid)};",
        f"static const double K_WALL[NZ][NZ] = {_c_array(rom.k_wall)};",
        "/* input matrices: cell heat, fluid per segment (per unit h), ambient, constant load */",
        f"static const double B_HEAT[NZ][NCELL] = {_c_array(rom.b_heat)};",
        f"static const double B_WALL[NZ][NSEG] = {_c_array(rom.b_wall)};",
        f"static const double B_AMB[NZ] = {_c_array(rom.b_amb)};",
        f"static const double B_CONST[NZ] = {_c_array(rom.b_const)};",
        "/* reduced state of the uniform field 1 K */",
        f"static const double UNIT_STATE[NZ] = {_c_array(rom.unit_state)};",
        "/* output rows: cell means (transposed), hot-spot candidates (NCAND per cell), wall integrals */",
        f"static const double OUT_MEAN_T[NZ][NCELL] = {_c_array(rom.out_mean.T)};",
        f"static const double OUT_CAND[NCELL * NCAND][NZ] = {_c_array(cand)};",
        "/* the hot-spot screening (hv_hot_spots): the rows in single precision, transposed, their",
        " * norms, and the rounding constants gamma_{NZ+2} (float), the double product's, eta, |u| */",
        f"static const float CAND32_T[NZ][NCELL * NCAND] = {_c_array(cand.astype(np.float32).T)};",
        f"static const double CAND_NORM[NCELL * NCAND] = {_c_array(np.linalg.norm(cand, axis=1))};",
        f"#define HS_G32 {_num(consts[0])}",
        f"#define HS_G64 {_num(consts[1])}",
        f"#define HS_ETA {_num(consts[2])}",
        f"#define HS_UNIT_NORM {_num(consts[3])}",
        f"static const double OUT_WALL_T[NZ][NSEG] = {_c_array(rom.out_wall.T)};",
        f"static const double WALL_AREA[NSEG] = {_c_array(rom.wall_area_m2)};",
        f"static const double ENERGY[NZ] = {_c_array(rom.energy)};",
        f"static const double FILM_ROW[NZ] = {_c_array(rom.film_row)};",
        f"#define B_AMB_TOTAL {_num(rom.b_amb_total)}",
        f"#define F_CONST_TOTAL {_num(rom.f_const_total)}",
        "/* RomStepper's step matrix [inv/dt | inv B(h)]^T (z_1 = [z_0, u_1] ST) for DT_DESIGN, H_DESIGN */",
        f"#define DT_DESIGN {_num(dt_s)}",
        f"#define H_DESIGN {_num(wall_h_w_m2k)}",
        f"static const double ST_DESIGN[NZ + NCELL + NSEG + 2][NZ] = {_c_array(step_t)};",
    ]
    return "\n".join(lines + variable_table(vars_)) + "\n"


def export_rom_fmu(
    rom: str | Path | ThermalRom,
    out_fmu: str | Path,
    fmi_version: int = 2,
    model_name: str | None = None,
    initial_temp_k: float | None = None,
    wall_h_w_m2k: float | None = None,
    dt_s: float | None = None,
) -> Path:
    """Build ``out_fmu``: a native FMI 2.0 or 3.0 co-simulation FMU of the thermal ROM ``rom``
    (a ``.rom.npz`` path or a loaded :class:`~hevsim.thermal.rom.ThermalRom`). Start values:
    ``initial_temp_k`` [K] (default: the ROM's build case), ``wall_h_w_m2k`` [W/(m^2 K)]
    (default: the configured film, the top of the ROM's range). ``dt_s`` [s] (default: the
    ROM's build step): the communication step whose step matrix is embedded as computed by
    :class:`~hevsim.thermal.rom.RomStepper` (other steps are computed by the FMU). Returns the
    FMU path (written atomically)."""
    from hevsim.thermal.rom import ThermalRom, load_rom

    if fmi_version not in FMI_VERSIONS:
        raise ConfigError(f"--fmi-version {fmi_version!r} is not supported; expected one of 2, 3.")
    r = rom if isinstance(rom, ThermalRom) else load_rom(rom)
    source = Path(rom).name if not isinstance(rom, ThermalRom) else str(r.metadata.get("config", "a ROM"))
    name = model_name or "HevsimThermalRom_" + re.sub(
        r"\W", "_", Path(str(r.metadata.get("config", "module"))).stem
    )
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        raise ConfigError(f"FMU model name {name!r} must be a C identifier (letters, digits, _).")
    t0 = float(initial_temp_k if initial_temp_k is not None else r.metadata.get("initial_temp_k", 298.15))
    if not (np.isfinite(t0) and t0 > 0.0):
        raise ConfigError(f"initial_temp_k {t0!r}: expected a positive temperature [K].")
    h = r.check_wall_h(float(wall_h_w_m2k if wall_h_w_m2k is not None else r.wall_h_range_w_m2k[1]))
    if r.out_candidates.shape[0] % r.n_cells:
        raise NativeFMUError(f"{source}: {r.out_candidates.shape[0]} hot-spot rows for {r.n_cells} cells.")
    dt = float(dt_s if dt_s is not None else r.metadata.get("dt_s", 1.0))
    if not (np.isfinite(dt) and dt > 0.0):
        raise ConfigError(f"dt_s {dt!r}: expected a positive communication step [s].")
    vars_ = rom_variables(r, t0, h, fmi_version)
    data = rom_model_data(r, name, source, vars_, dt, h)
    desc = (
        f"hevsim module thermal ROM (order {r.order}, {r.n_cells} cells, {r.n_segments} wall segments; "
        f"mesh {r.mesh_hash[:12]}), implicit Euler, native C99"
    )
    # -O3: the vector-matrix products vectorise across outputs (each sum keeps its order)
    return build_fmu(out_fmu, fmi_version, name, desc, vars_, data, ROM_TEMPLATES, opt="-O3")


def is_rom_file(path: str | Path) -> bool:
    """True if ``path`` looks like a thermal ROM file (``.npz``) rather than a cell configuration."""
    return Path(path).suffix == ".npz"


__all__ = ["ROM_TEMPLATES", "export_rom_fmu", "is_rom_file", "rom_model_data", "rom_variables"]

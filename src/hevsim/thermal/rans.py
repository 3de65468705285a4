"""Turbulent coolant flow in the plate's channel: a RANS solve (k-omega SST) with OpenFOAM.

Above the laminar limit (:data:`~hevsim.thermal.coolant.RE_LAMINAR_MAX`; the shipped
10 L/min gives Re about 3450 in the 8 x 4 mm channel) the flow is solved by OpenFOAM's
steady incompressible solver ``simpleFoam`` with the k-omega SST model, from the same
parametric channel as the laminar solver (:class:`~hevsim.thermal.flow.Channel`: the plate's
serpentine or a straight duct), and read back onto hevsim's tetrahedral mesh.

**Mesh.** The channel is a union of axis-aligned boxes, so the case's mesh is a tensor grid
of hexahedra restricted to that union, written directly as an OpenFOAM ``polyMesh`` (points,
faces, owner, neighbour, boundary) rather than through gmsh + ``gmshToFoam``: hexahedra
aligned with the walls need far fewer cells than tetrahedra for the same wall resolution, the
grid lines can be graded geometrically towards every wall plane (first cell height
``flow.rans_wall_cell_m`` [m], growth ratio ``flow.growth`` [-], cells no larger than the
channel width / ``flow.rans_cells_across_width``, height / ``flow.rans_cells_across_height``
and ``flow.rans_cell_length_m`` along the channel), which sets the wall y+, and there is no
mesh generator to run (``blockMesh`` would need one block per grid box with matching
gradings; the result is the same). Patches: ``inlet``, ``outlet`` and ``walls``.

**Case.** ``0/``: U (uniform inlet velocity = flow rate / inlet area, no-slip walls,
zero-gradient outlet), p (kinematic; the outlet at ``flow.outlet_pressure_pa`` / rho), k and
omega at the inlet from the turbulence intensity ``flow.turbulence_intensity`` [-] (default
0.05) and length scale ``flow.turbulence_length_m`` [m] (0 = 0.07 D_h, the usual duct value):
``k = 1.5 (I U)^2``, ``omega = sqrt(k) / (C_mu^0.25 l)``; walls: ``kqRWallFunction``,
``omegaWallFunction`` and ``nutUSpaldingWallFunction`` (Spalding's law covers the viscous,
buffer and log layers, so the first cell may sit anywhere from y+ about 1 to 100).
``constant/``: ``transportProperties`` (Newtonian, nu = mu / rho of the coolant),
``turbulenceProperties`` (``simulationType RAS; RAS { RASModel kOmegaSST; }``, the v1912
keys). ``system/``: ``controlDict`` (ASCII output, a ``yPlus`` function object),
``fvSchemes`` (second-order linearUpwind for U, upwind for k and omega), ``fvSolution``
(SIMPLEC, ``residualControl`` at ``flow.rans_tolerance``, at most ``flow.rans_iterations``
iterations). ``flow.rans_processes`` = 2 decomposes the case and runs ``mpirun -np 2
simpleFoam -parallel``.

**Reading back.** The cell-centre fields U, p, nut of the last time directory are averaged
onto the grid's vertices (walls: U = nut = 0; inlet: the inlet velocity) and interpolated
trilinearly within the hexahedra to any point of the channel (:class:`GridField`): the P2
velocity and P1 pressure of a :class:`~hevsim.thermal.flow.FlowResult` on the tetrahedral mesh
:func:`~hevsim.thermal.flow.channel_mesh` builds from the ``[flow]`` resolution keys, and the
turbulent (eddy) diffusivity ``nu_t / Pr_t`` [m^2/s] at its vertices (``Pr_t`` =
``flow.prandtl_turbulent``, default 0.85, the usual value for water-like liquids, e.g.
W. M. Kays, J. Heat Transfer 116 (1994) 284-295), which the coolant heat transfer
(:mod:`hevsim.thermal.cht`) adds to the molecular one. The flow is frozen for the thermal run.
:func:`on_fem_mesh` reads one solution onto another FEM mesh and :func:`read_rans_case` a
finished case folder (``openfoam/`` of ``hevsim flow --out``) without solving again. FEM wall
cells too thick for the conduction sublayer (:func:`wall_cells_resolve_sublayer`) take the
thermal wall function (:mod:`hevsim.thermal.wall_function`) or are refused.

**Finding OpenFOAM.** :func:`find_openfoam`: ``$HEVSIM_OPENFOAM`` (an installation folder with
``etc/bashrc``), an already sourced environment (``$WM_PROJECT_DIR`` and ``simpleFoam`` on the
``PATH``), Debian's package (``/usr/bin/simpleFoam`` with its files in
``/usr/share/openfoam``) or the openfoam.com / openfoam.org packages'
``/usr/lib/openfoam/openfoam*/etc/bashrc`` and ``/opt/openfoam*/etc/bashrc``. Missing: a
:class:`OpenFoamMissingError` (exit 2) naming what to install.

Verification (``tests/test_rans.py``): the friction factor of a straight duct against
Blasius (``f = 0.316 Re^-0.25``, H. Blasius, Forschungsarbeiten VDI 131 (1913)) and the
Nusselt number of the coolant heat transfer on the frozen RANS flow against Gnielinski
(V. Gnielinski, Int. Chem. Eng. 16 (1976) 359-368).
"""

from __future__ import annotations

import glob
import math
import os
import re
import shutil
import subprocess
import tempfile
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import ConfigError, SimulationError
from hevsim.thermal.channel import (  # the graded grid lives with the channel (re-exported here)
    ChannelGrid,
    FlowResult,
    FlowSection,
    channel_grid,
    channel_mesh,
    check_channel_mesh,
    hydraulic_metrics,
)
from hevsim.thermal.channel import (
    graded_axis as graded_axis,
)
from hevsim.thermal.channel import (
    wall_planes as wall_planes,
)
from hevsim.thermal.coolant import Coolant

#: Environment variable naming an OpenFOAM installation folder (the one holding ``etc/bashrc``).
OPENFOAM_ENV = "HEVSIM_OPENFOAM"
#: Debian's package: solvers in /usr/bin, the ``etc`` files here (``WM_PROJECT_DIR``).
DEBIAN_PROJECT_DIR = "/usr/share/openfoam"
#: bashrc files of the openfoam.com (``/usr/lib/openfoam``) and openfoam.org (``/opt``) packages.
KNOWN_BASHRC = (
    "/usr/lib/openfoam/openfoam*/etc/bashrc",
    "/opt/openfoam*/etc/bashrc",
    "/opt/OpenFOAM-*/etc/bashrc",
)
#: What to install, for the error message.
INSTALL_HINT = (
    "install OpenFOAM: on Debian/Ubuntu 'apt-get install openfoam' (or 'make openfoam' in the hevsim "
    "repository, as root), otherwise the packages of openfoam.com or openfoam.org; or set "
    f"{OPENFOAM_ENV} to an installation folder holding etc/bashrc"
)
#: k-epsilon/k-omega constant C_mu [-] (omega = sqrt(k) / (C_mu^0.25 l)).
C_MU = 0.09
#: Inlet turbulence length scale as a fraction of the hydraulic diameter when not given [-].
LENGTH_SCALE_FRACTION = 0.07
#: Edge of the viscous sublayer in wall units [-]; the conduction sublayer is this times
#: Pr^(-1/3) wall units thick (the usual high-Pr scaling, e.g. Kays, Crawford & Weigand,
#: Convective Heat and Mass Transfer, 4th ed. (2005), ch. 13).
SUBLAYER_YPLUS = 5.0
#: Thickest FEM wall cell for the resolved coolant heat transfer, in conduction-sublayer
#: thicknesses [-] (a P2 node inside the sublayer).
SUBLAYER_CELLS = 2.0


def conduction_sublayer_m(reynolds: float, hydraulic_diameter_m: float, prandtl: float) -> float:
    """Thickness [m] of the near-wall conduction sublayer of developed turbulent duct flow:
    ``SUBLAYER_YPLUS Pr^(-1/3) nu / u_tau`` with ``u_tau = U (f/8)^(1/2)`` and Blasius' f, so
    ``nu / u_tau = D_h / (Re (f/8)^(1/2))``. The P2 temperature of the coolant heat transfer
    needs its first cell at the wall no thicker than about twice this (a node inside it)."""
    f = 0.316 * reynolds**-0.25
    return SUBLAYER_YPLUS * prandtl ** (-1.0 / 3.0) * hydraulic_diameter_m / (reynolds * math.sqrt(f / 8))


def wall_cells_resolve_sublayer(metrics: dict[str, float]) -> bool:
    """Whether the FEM wall cells of a RANS flow's ``metrics`` (``fem_wall_cell_m``,
    ``conduction_sublayer_m``) are no thicker than twice the conduction sublayer (a P2 node
    inside it): the criterion of :func:`check_thermal_wall_mesh` and of ``flow.thermal_wall =
    "auto"``."""
    return bool(metrics["fem_wall_cell_m"] <= SUBLAYER_CELLS * metrics["conduction_sublayer_m"])


def check_thermal_wall_mesh(flow: Any, where: str = "cht") -> None:
    """Refuse (:class:`~hevsim.errors.ConfigError`, exit 2) heat transfer on a RANS ``flow``
    whose FEM mesh has wall cells thicker than twice the conduction sublayer (metrics
    ``fem_wall_cell_m``, ``conduction_sublayer_m``): the eddy diffusivity, interpolated across
    a cell that spans the sublayer, then reaches the wall and the coolant's wall heat comes out
    far too high (on the shipped plate's uniform default mesh about 7x the 1-D model's), a
    wrong number rather than an approximate one."""
    m = flow.metrics
    cell, delta = m["fem_wall_cell_m"], m["conduction_sublayer_m"]
    if not wall_cells_resolve_sublayer(m):
        raise ConfigError(
            f"{where}: the coolant heat transfer on the turbulent flow needs FEM cells at the wall no "
            f"thicker than about {SUBLAYER_CELLS * delta:.2g} m (twice the conduction sublayer at Re "
            f"{m['reynolds']:.0f}, "
            f"Pr {m['prandtl']:.3g}), but they are {cell:.2g} m: the eddy diffusivity would reach the wall "
            "and the wall heat would be far too high. Set flow.wall_cell_m (graded FEM mesh) accordingly, "
            'use the thermal wall function (flow.thermal_wall = "wall_function" or "auto"), '
            "or use the 1-D coolant channel at this flow rate."
        )


class OpenFoamMissingError(ConfigError):
    """OpenFOAM (``simpleFoam``) is not installed or not found (exit 2)."""


# --------------------------------------------------------------------------- finding OpenFOAM
@dataclass(frozen=True)
class OpenFoam:
    """An OpenFOAM installation: the environment its applications run in and where it came from."""

    env: dict[str, str]
    source: str

    def which(self, app: str) -> str | None:
        """Full path of the application ``app`` on this installation's PATH (None if absent)."""
        return shutil.which(app, path=self.env.get("PATH", ""))


def _sourced_env(bashrc: Path) -> dict[str, str] | None:
    """The environment after ``source bashrc`` in bash (None when it fails)."""
    bash = shutil.which("bash")
    if bash is None:
        return None
    try:
        out = subprocess.run(
            [bash, "-c", f'source "{bashrc}" >/dev/null 2>&1; env -0'],
            capture_output=True,
            check=False,
            timeout=60,
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    env = dict(kv.split("=", 1) for kv in out.decode(errors="replace").split("\0") if "=" in kv)
    return env or None


def find_openfoam(
    environ: dict[str, str] | None = None, known_bashrc: Sequence[str] | None = None
) -> OpenFoam:
    """Locate OpenFOAM's ``simpleFoam`` (see the module docstring for the order of the search).

    ``environ``: the environment to search (default ``os.environ``); ``known_bashrc``: glob
    patterns of installations' bashrc files (default :data:`KNOWN_BASHRC`).

    Raises:
        OpenFoamMissingError: nothing found; the message says what to install.
    """
    env = dict(os.environ if environ is None else environ)
    known_bashrc = KNOWN_BASHRC if known_bashrc is None else known_bashrc
    tried: list[str] = []
    candidates: list[tuple[str, dict[str, str] | None]] = []
    given = env.get(OPENFOAM_ENV, "").strip()
    if given:
        rc = Path(given) / "etc" / "bashrc"
        tried.append(f"{OPENFOAM_ENV}={given}")
        if not rc.is_file():
            raise OpenFoamMissingError(
                f"{OPENFOAM_ENV}={given!r}: no etc/bashrc there; expected an OpenFOAM installation folder. "
                f"To use another one, {INSTALL_HINT}."
            )
        candidates.append((str(rc), _sourced_env(rc)))
    path = env.get("PATH", "")
    on_path = shutil.which("simpleFoam", path=path)
    if on_path:
        tried.append(f"simpleFoam on PATH ({on_path})")
        if env.get("WM_PROJECT_DIR"):
            candidates.append((f"PATH (WM_PROJECT_DIR={env['WM_PROJECT_DIR']})", env))
        elif Path(DEBIAN_PROJECT_DIR, "etc", "controlDict").is_file():
            candidates.append((f"Debian package ({on_path})", {**env, "WM_PROJECT_DIR": DEBIAN_PROJECT_DIR}))
    for pattern in known_bashrc:
        for rc_name in sorted(glob.glob(pattern), reverse=True):
            tried.append(rc_name)
            candidates.append((rc_name, _sourced_env(Path(rc_name))))
    for source, cand in candidates:
        if cand is not None and shutil.which("simpleFoam", path=cand.get("PATH", "")):
            return OpenFoam(cand, source)
    looked = "; ".join(tried) if tried else f"PATH, {OPENFOAM_ENV}, {', '.join(known_bashrc)}"
    raise OpenFoamMissingError(
        f"OpenFOAM's simpleFoam is needed for a turbulent (RANS) coolant flow but was not found "
        f"(looked at: {looked}). To solve it, {INSTALL_HINT}; or solve a laminar case "
        '(flow.model = "laminar" with a lower flow.flow_l_min).'
    )


# --------------------------------------------------------------------------- case writer
def _header(cls: str, obj: str, location: str = "") -> str:
    loc = f'    location    "{location}";\n' if location else ""
    return (
        "FoamFile\n{\n    version     2.0;\n    format      ascii;\n"
        f"    class       {cls};\n{loc}    object      {obj};\n}}\n\n"
    )


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def _faces_of_axis(grid: ChannelGrid, axis: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Faces normal to ``axis``: (lower cell id, upper cell id, (F, 4) point grid indices with
    the right-hand normal along +axis); -1 marks a cell outside the channel."""
    ids = np.pad(grid.cell_id, [(1, 1) if a == axis else (0, 0) for a in range(3)], constant_values=-1)
    lo = np.take(ids, np.arange(ids.shape[axis] - 1), axis=axis)
    hi = np.take(ids, np.arange(1, ids.shape[axis]), axis=axis)
    keep = (lo >= 0) | (hi >= 0)
    idx = np.nonzero(keep)  # (p, q, r) with the plane index along `axis`
    # in-plane axes in cyclic order after `axis`: x -> (y, z), y -> (z, x), z -> (x, y)
    a1, a2 = (axis + 1) % 3, (axis + 2) % 3
    corners = []
    for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
        ijk = [idx[axis], idx[a1] + du, idx[a2] + dv]
        ijk = [ijk[(a - axis) % 3] for a in range(3)]
        corners.append(np.column_stack(ijk))
    return lo[keep], hi[keep], np.stack(corners, axis=1)


def write_polymesh(grid: ChannelGrid, channel: Any, mesh_dir: Path) -> dict[str, int]:
    """Write ``constant/polyMesh`` of ``grid`` (patches inlet, outlet, walls); returns counts."""
    shape = tuple(len(n) for n in grid.nodes)
    lows, highs, quads = [], [], []
    for axis in range(3):
        lo, hi, q = _faces_of_axis(grid, axis)
        lows.append(lo)
        highs.append(hi)
        quads.append(q)
    lo, hi, q = np.concatenate(lows), np.concatenate(highs), np.concatenate(quads)
    axis_of = np.concatenate([np.full(len(x), a) for a, x in enumerate(lows)])
    internal = (lo >= 0) & (hi >= 0)
    # boundary faces: owner is the inside cell; flip the quad when that cell is the upper one
    flip = ~internal & (lo < 0)
    owner = np.where(lo >= 0, lo, hi)
    q = np.where(flip[:, None, None], q[:, ::-1], q)
    # points used by the faces, numbered in grid order
    flat = np.ravel_multi_index(tuple(q.reshape(-1, 3).T), shape)
    used, inverse = np.unique(flat, return_inverse=True)
    face_pts = inverse.reshape(-1, 4)
    pijk = np.unravel_index(used, shape)
    points = np.column_stack([grid.nodes[a][pijk[a]] for a in range(3)])
    # patches of the boundary faces
    centre = points[face_pts].mean(axis=1)
    port_in = (axis_of == 0) & _on_port_one(channel.inlet, centre)
    port_out = (axis_of == 0) & _on_port_one(channel.outlet, centre)
    kind = np.where(internal, 0, np.where(port_in, 1, np.where(port_out, 2, 3)))
    order_int = np.nonzero(internal)[0]
    order_int = order_int[np.lexsort((hi[order_int], lo[order_int]))]
    groups = [order_int] + [np.nonzero(kind == k)[0] for k in (1, 2, 3)]
    order = np.concatenate(groups)
    if len(groups[1]) == 0 or len(groups[2]) == 0:
        raise ConfigError("rans: the channel mesh has no inlet or outlet face; check the geometry.")
    n_int = len(groups[0])
    loc = "constant/polyMesh"
    pts_txt = "\n".join(f"({x:.12g} {y:.12g} {z:.12g})" for x, y, z in points)
    _write(mesh_dir / "points", _header("vectorField", "points", loc) + f"{len(points)}\n(\n{pts_txt}\n)\n")
    f_txt = "\n".join(f"4({a} {b} {c} {d})" for a, b, c, d in face_pts[order])
    _write(mesh_dir / "faces", _header("faceList", "faces", loc) + f"{len(order)}\n(\n{f_txt}\n)\n")
    own_txt = "\n".join(map(str, owner[order]))
    note = f"nPoints:{len(points)} nCells:{grid.n_cells} nFaces:{len(order)} nInternalFaces:{n_int}"
    _write(
        mesh_dir / "owner",
        _header("labelList", "owner", loc).replace("    object", f'    note        "{note}";\n    object')
        + f"{len(order)}\n(\n{own_txt}\n)\n",
    )
    nei_txt = "\n".join(map(str, hi[order[:n_int]]))
    _write(
        mesh_dir / "neighbour",
        _header("labelList", "neighbour", loc).replace("    object", f'    note        "{note}";\n    object')
        + f"{n_int}\n(\n{nei_txt}\n)\n",
    )
    start = n_int
    entries = []
    for name, ptype, g in (
        ("inlet", "patch", groups[1]),
        ("outlet", "patch", groups[2]),
        ("walls", "wall", groups[3]),
    ):
        entries.append(
            f"    {name}\n    {{\n        type {ptype};\n        nFaces {len(g)};\n"
            f"        startFace {start};\n    }}"
        )
        start += len(g)
    _write(
        mesh_dir / "boundary",
        _header("polyBoundaryMesh", "boundary", loc) + "3\n(\n" + "\n".join(entries) + "\n)\n",
    )
    return {"points": len(points), "cells": grid.n_cells, "faces": len(order), "internal_faces": n_int}


def _on_port_one(spec: tuple[float, float, float, int], centre: np.ndarray) -> np.ndarray:
    x, y0, y1, _ = spec
    tol = 1e-9 * max(abs(y1 - y0), 1e-3)
    return (np.abs(centre[:, 0] - x) < tol) & (centre[:, 1] > y0 - tol) & (centre[:, 1] < y1 + tol)


def _field(name: str, cls: str, dims: str, internal: str, patches: dict[str, str]) -> str:
    """An OpenFOAM field file; ``patches`` maps a patch to its ``key value; key value`` entries."""
    blocks = []
    for patch, spec in patches.items():
        lines = "".join(f"        {item.strip()};\n" for item in spec.split(";") if item.strip())
        blocks.append(f"    {patch}\n    {{\n{lines}    }}")
    body = "\n".join(blocks)
    return (
        _header(cls, name, "0")
        + f"dimensions      {dims};\n\ninternalField   {internal};\n\nboundaryField\n{{\n{body}\n}}\n"
    )


@dataclass(frozen=True)
class RansCase:
    """Inputs of one RANS case: inlet velocity vector [m/s], kinematic viscosity [m^2/s],
    inlet k [m^2/s^2] and omega [1/s], outlet kinematic pressure [m^2/s^2], iterations,
    residual tolerance and number of processes."""

    inlet_velocity_mps: tuple[float, float, float]
    nu_m2_s: float
    k_inlet: float
    omega_inlet: float
    outlet_p_kin: float
    iterations: int
    tolerance: float
    processes: int


def write_case(case: Path, grid: ChannelGrid, channel: Any, rc: RansCase) -> dict[str, int]:
    """Write the OpenFOAM case (mesh, ``0/``, ``constant/``, ``system/``) into the folder ``case``."""
    counts = write_polymesh(grid, channel, case / "constant" / "polyMesh")
    ux, uy, uz = rc.inlet_velocity_mps
    fields = {
        "U": ("volVectorField", "[0 1 -1 0 0 0 0]", "uniform (0 0 0)", {
            "inlet": f"type fixedValue; value uniform ({ux:.12g} {uy:.12g} {uz:.12g})",
            "outlet": "type inletOutlet; inletValue uniform (0 0 0); value uniform (0 0 0)",
            "walls": "type noSlip",
        }),
        "p": ("volScalarField", "[0 2 -2 0 0 0 0]", f"uniform {rc.outlet_p_kin:.12g}", {
            "inlet": "type zeroGradient",
            "outlet": f"type fixedValue; value uniform {rc.outlet_p_kin:.12g}",
            "walls": "type zeroGradient",
        }),
        "k": ("volScalarField", "[0 2 -2 0 0 0 0]", f"uniform {rc.k_inlet:.12g}", {
            "inlet": f"type fixedValue; value uniform {rc.k_inlet:.12g}",
            "outlet": (f"type inletOutlet; inletValue uniform {rc.k_inlet:.12g}; "
                       f"value uniform {rc.k_inlet:.12g}"),
            "walls": f"type kqRWallFunction; value uniform {rc.k_inlet:.12g}",
        }),
        "omega": ("volScalarField", "[0 0 -1 0 0 0 0]", f"uniform {rc.omega_inlet:.12g}", {
            "inlet": f"type fixedValue; value uniform {rc.omega_inlet:.12g}",
            "outlet": (f"type inletOutlet; inletValue uniform {rc.omega_inlet:.12g}; "
                       f"value uniform {rc.omega_inlet:.12g}"),
            "walls": f"type omegaWallFunction; value uniform {rc.omega_inlet:.12g}",
        }),
        "nut": ("volScalarField", "[0 2 -1 0 0 0 0]", "uniform 0", {
            "inlet": "type calculated; value uniform 0",
            "outlet": "type calculated; value uniform 0",
            "walls": "type nutUSpaldingWallFunction; value uniform 0",
        }),
    }  # fmt: skip
    for name, (cls, dims, internal, patches) in fields.items():
        _write(case / "0" / name, _field(name, cls, dims, internal, patches))
    _write(
        case / "constant" / "transportProperties",
        _header("dictionary", "transportProperties", "constant")
        + f"transportModel  Newtonian;\n\nnu              [0 2 -1 0 0 0 0] {rc.nu_m2_s:.12g};\n",
    )
    _write(
        case / "constant" / "turbulenceProperties",
        _header("dictionary", "turbulenceProperties", "constant")
        + "simulationType  RAS;\n\nRAS\n{\n    RASModel        kOmegaSST;\n    turbulence      on;\n"
        "    printCoeffs     off;\n}\n",
    )
    _write(
        case / "system" / "controlDict",
        _header("dictionary", "controlDict", "system")
        + "application     simpleFoam;\nstartFrom       startTime;\nstartTime       0;\n"
        f"stopAt          endTime;\nendTime         {rc.iterations};\ndeltaT          1;\n"
        f"writeControl    timeStep;\nwriteInterval   {rc.iterations};\npurgeWrite      0;\n"
        "writeFormat     ascii;\nwritePrecision  10;\nwriteCompression off;\ntimeFormat      general;\n"
        "timePrecision   6;\nrunTimeModifiable false;\n\nfunctions\n{\n    yPlus\n    {\n"
        '        type            yPlus;\n        libs            ("libfieldFunctionObjects.so");\n'
        "        writeControl    writeTime;\n    }\n    inletPressure\n    {\n"
        "        type            surfaceFieldValue;\n"
        '        libs            ("libfieldFunctionObjects.so");\n'
        "        writeControl    timeStep;\n        writeInterval   1;\n        log             false;\n"
        "        writeFields     false;\n        regionType      patch;\n        name            inlet;\n"
        "        operation       areaAverage;\n        fields          (p);\n    }\n}\n",
    )
    _write(
        case / "system" / "fvSchemes",
        _header("dictionary", "fvSchemes", "system")
        + "ddtSchemes\n{\n    default         steadyState;\n}\n\n"
        "gradSchemes\n{\n    default         Gauss linear;\n"
        "    grad(U)         cellLimited Gauss linear 1;\n}\n\ndivSchemes\n{\n    default         none;\n"
        "    div(phi,U)      bounded Gauss linearUpwind grad(U);\n    div(phi,k)      bounded Gauss upwind;\n"
        "    div(phi,omega)  bounded Gauss upwind;\n    div((nuEff*dev2(T(grad(U))))) Gauss linear;\n}\n\n"
        "laplacianSchemes\n{\n    default         Gauss linear corrected;\n}\n\n"
        "interpolationSchemes\n{\n    default         linear;\n}\n\n"
        "snGradSchemes\n{\n    default         corrected;\n}\n\n"
        "wallDist\n{\n    method          meshWave;\n}\n",
    )
    _write(
        case / "system" / "fvSolution",
        _header("dictionary", "fvSolution", "system")
        + "solvers\n{\n    p\n    {\n        solver          GAMG;\n        smoother        GaussSeidel;\n"
        '        tolerance       1e-08;\n        relTol          0.05;\n    }\n\n    "(U|k|omega)"\n    {\n'
        "        solver          smoothSolver;\n        smoother        symGaussSeidel;\n"
        "        tolerance       1e-10;\n        relTol          0.1;\n    }\n}\n\n"
        "SIMPLE\n{\n    nNonOrthogonalCorrectors 0;\n    consistent      yes;\n    residualControl\n    {\n"
        f"        p               {rc.tolerance:.3g};\n        U               {rc.tolerance:.3g};\n"
        f'        "(k|omega)"     {rc.tolerance:.3g};\n    }}\n}}\n\n'
        "relaxationFactors\n{\n    equations\n    {\n        U               0.9;\n"
        '        ".*"            0.7;\n'
        "    }\n}\n",
    )
    if rc.processes > 1:
        _write(
            case / "system" / "decomposeParDict",
            _header("dictionary", "decomposeParDict", "system")
            # split along x, the channels' long axis (Debian's build has no scotch library)
            + f"numberOfSubdomains {rc.processes};\n\nmethod          simple;\n\n"
            f"coeffs\n{{\n    n               ({rc.processes} 1 1);\n    delta           0.001;\n}}\n",
        )
    return counts


# --------------------------------------------------------------------------- running
_TIME_LINE = re.compile(r"^Time = (\d+)\s*$")
_RESIDUAL = re.compile(r"Solving for (\w+), Initial residual = ([0-9.eE+-]+)")


def _run(of: OpenFoam, args: list[str], case: Path, log: Path, total: int | None, progress: bool) -> str:
    """Run one OpenFOAM application in ``case``, its output to ``log``; returns the output."""
    from hevsim.progress import task

    env = dict(of.env)
    if hasattr(os, "geteuid") and os.geteuid() == 0:  # Open MPI refuses root without these
        env.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
        env.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    exe = of.which(args[0])
    if exe is None:
        raise OpenFoamMissingError(
            f"OpenFOAM application {args[0]!r} not found ({of.source}); {INSTALL_HINT}."
        )
    lines: list[str] = []
    with (
        task(
            f"{args[-2] if args[0] == 'mpirun' else args[0]}",
            total or 1,
            "iteration",
            show=progress and bool(total),
        ) as t,
        log.open("w") as fh,
    ):
        proc = subprocess.Popen(
            [exe, *args[1:]], cwd=case, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        assert proc.stdout is not None
        for line in proc.stdout:
            fh.write(line)
            lines.append(line)
            if total and _TIME_LINE.match(line.strip()):
                t.update(1)
        proc.stdout.close()
        rc = proc.wait()
    out = "".join(lines)
    if rc != 0:
        tail = "".join(lines[-25:])
        raise SimulationError(f"OpenFOAM {' '.join(args)} failed (exit {rc}) in {case}; log {log}:\n{tail}")
    return out


def _latest_time(case: Path) -> Path:
    times = [
        (float(p.name), p) for p in case.iterdir() if p.is_dir() and re.fullmatch(r"[0-9.eE+-]+", p.name)
    ]
    times = [tp for tp in times if tp[0] > 0]
    if not times:
        raise SimulationError(f"OpenFOAM wrote no result time folder in {case}.")
    return max(times)[1]


def read_internal_field(path: Path, n_cells: int) -> np.ndarray:
    """The ``internalField`` of an ASCII OpenFOAM field file: (n_cells,) or (n_cells, 3)."""
    text = path.read_text()
    m = re.search(r"internalField\s+(uniform|nonuniform)\s+", text)
    if m is None:
        raise SimulationError(f"{path}: no internalField.")
    rest = text[m.end() :]
    if m.group(1) == "uniform":
        value = rest.split(";", 1)[0].strip().strip("()")
        vals = np.array([float(v) for v in value.split()])
        return np.tile(vals, (n_cells, 1)) if vals.size > 1 else np.full(n_cells, vals[0])
    m2 = re.match(r"List<(\w+)>\s*(\d+)\s*\(", rest)
    if m2 is None:
        raise SimulationError(f"{path}: cannot read the internalField list.")
    n = int(m2.group(2))
    body = rest[m2.end() :]
    vector = m2.group(1) == "vector"
    end = body.index("\n)")
    arr = np.array(body[:end].replace("(", " ").replace(")", " ").split(), dtype=float)
    arr = arr.reshape(n, 3) if vector else arr
    if n != n_cells:
        raise SimulationError(f"{path}: {n} values for {n_cells} cells.")
    return arr


def _read_inlet_pressure(case: Path) -> np.ndarray:
    """Area-mean kinematic inlet pressure [m^2/s^2] per iteration (the ``inletPressure``
    function object); empty if absent."""
    rows: list[float] = []
    for f in sorted(case.glob("postProcessing/inletPressure/*/surfaceFieldValue.dat")):
        for ln in f.read_text().splitlines():
            parts = ln.split()
            if len(parts) >= 2 and not ln.startswith("#"):
                rows.append(float(parts[1]))
    return np.array(rows)


def _read_yplus(case: Path) -> dict[str, float]:
    files = sorted(case.glob("postProcessing/yPlus/*/yPlus.dat"))
    for f in reversed(files):
        rows = [ln.split() for ln in f.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
        rows = [r for r in rows if len(r) >= 5 and r[1] == "walls"]
        if rows:
            return {
                "yplus_min": float(rows[-1][2]),
                "yplus_max": float(rows[-1][3]),
                "yplus_mean": float(rows[-1][4]),
            }
    return {"yplus_min": math.nan, "yplus_max": math.nan, "yplus_mean": math.nan}


# --------------------------------------------------------------------------- reading back
def boundary_points(grid: ChannelGrid, channel: Any) -> tuple[np.ndarray, np.ndarray]:
    """Masks over the grid's points: on the walls, and on the inlet (not on a wall)."""
    shape = tuple(len(n) for n in grid.nodes)
    wall = np.zeros(shape, dtype=bool)
    inlet = np.zeros(shape, dtype=bool)
    for axis in range(3):
        lo, hi, q = _faces_of_axis(grid, axis)
        bnd = (lo < 0) | (hi < 0)
        qb = q[bnd]
        centre = np.column_stack([grid.nodes[a][qb[:, :, a]].mean(axis=1) for a in range(3)])
        port_in = _on_port_one(channel.inlet, centre) if axis == 0 else np.zeros(len(qb), dtype=bool)
        port = port_in | (_on_port_one(channel.outlet, centre) if axis == 0 else False)
        for target, sel in ((wall, ~port), (inlet, port_in)):
            pts = qb[sel].reshape(-1, 3)
            target[pts[:, 0], pts[:, 1], pts[:, 2]] = True
    return wall, inlet & ~wall


@dataclass
class GridField:
    """A field at the vertices of a :class:`ChannelGrid`, (nx+1, ny+1, nz+1, c), interpolated
    trilinearly within the hexahedra (:meth:`at`)."""

    grid: ChannelGrid
    values: np.ndarray

    @classmethod
    def from_cells(
        cls, grid: ChannelGrid, cells: np.ndarray, fixed: Sequence[tuple[np.ndarray, np.ndarray]] = ()
    ) -> GridField:
        """Vertex values = the mean of the cells around each vertex, then ``fixed`` (mask over
        the points, value) pairs applied in order (boundary conditions)."""
        c = cells.reshape(len(cells), -1)
        nx, ny, nz = grid.inside.shape
        full = np.zeros((nx, ny, nz, c.shape[1]))
        full[grid.inside] = c
        total = np.zeros((nx + 1, ny + 1, nz + 1, c.shape[1]))
        count = np.zeros((nx + 1, ny + 1, nz + 1, 1))
        ins = grid.inside[..., None].astype(float)
        for di in (0, 1):
            for dj in (0, 1):
                for dk in (0, 1):
                    total[di : di + nx, dj : dj + ny, dk : dk + nz] += full
                    count[di : di + nx, dj : dj + ny, dk : dk + nz] += ins
        with np.errstate(invalid="ignore", divide="ignore"):
            vals = np.where(count > 0, total / count, np.nan)
        for mask, value in fixed:
            vals[mask] = value
        return cls(grid, vals)

    def at(self, points_m: np.ndarray) -> np.ndarray:
        """Values at ``points_m`` (N, 3) [m], (N, c); every point must lie in the channel."""
        pts = np.asarray(points_m, dtype=float)
        choices = []
        frac = []
        for a in range(3):
            nodes = self.grid.nodes[a]
            q = pts[:, a]
            n = len(nodes) - 1
            hi = np.clip(np.searchsorted(nodes, q, "right") - 1, 0, n - 1)
            near = np.abs(q - nodes[np.clip(np.searchsorted(nodes, q), 0, n)]) < 1e-9 * (nodes[-1] - nodes[0])
            lo = np.where(near, np.clip(hi - 1, 0, n - 1), hi)
            choices.append((hi, lo))
            frac.append(nodes)
        out = np.full((len(pts), self.values.shape[-1]), np.nan)
        lo_b = np.array([n[0] for n in self.grid.nodes])
        hi_b = np.array([n[-1] for n in self.grid.nodes])
        slack = 1e-9 * float(np.max(hi_b - lo_b))
        todo = np.all((pts >= lo_b - slack) & (pts <= hi_b + slack), axis=1)
        outside = ~todo
        for ci in choices[0]:
            for cj in choices[1]:
                for ck in choices[2]:
                    ok = todo & self.grid.inside[ci, cj, ck]
                    if not ok.any():
                        continue
                    idx = (ci[ok], cj[ok], ck[ok])
                    t = [
                        np.clip(
                            (pts[ok, a] - frac[a][idx[a]]) / (frac[a][idx[a] + 1] - frac[a][idx[a]]), 0.0, 1.0
                        )
                        for a in range(3)
                    ]
                    acc = np.zeros((int(ok.sum()), self.values.shape[-1]))
                    for di in (0, 1):
                        for dj in (0, 1):
                            for dk in (0, 1):
                                wgt = (
                                    (t[0] if di else 1 - t[0])
                                    * (t[1] if dj else 1 - t[1])
                                    * (t[2] if dk else 1 - t[2])
                                )
                                acc += wgt[:, None] * self.values[idx[0] + di, idx[1] + dj, idx[2] + dk]
                    out[ok] = acc
                    todo &= ~ok
        todo |= outside
        if todo.any():
            raise SimulationError(
                f"rans: {int(todo.sum())} points lie outside the channel grid (first {pts[todo][0]} m)."
            )
        return out


def _port_cells(grid: ChannelGrid, spec: tuple[float, float, float, int]) -> tuple[np.ndarray, np.ndarray]:
    """Cells next to a port (inlet/outlet plane) and the areas [m^2] of their port faces."""
    lo, hi, q = _faces_of_axis(grid, 0)
    centre = np.column_stack([grid.nodes[a][q[:, :, a]].mean(axis=1) for a in range(3)])
    on = ((lo < 0) | (hi < 0)) & _on_port_one(spec, centre)
    cells = np.where(lo[on] >= 0, lo[on], hi[on])
    y, z = grid.nodes[1], grid.nodes[2]
    qo = q[on]
    area = (y[qo[:, 2, 1]] - y[qo[:, 0, 1]]) * (z[qo[:, 2, 2]] - z[qo[:, 0, 2]])
    return cells, np.abs(area)


@dataclass
class RansResult:
    """The OpenFOAM solution on its own grid: cell-centre velocity [m/s], pressure [Pa] and
    turbulent viscosity [m^2/s], the vertex fields (:class:`GridField`), the log's residuals."""

    grid: ChannelGrid
    velocity_mps: np.ndarray
    pressure_pa: np.ndarray
    nut_m2_s: np.ndarray
    u_field: GridField
    p_field: GridField
    nut_field: GridField
    residuals: dict[str, float]
    log: str


def project_solenoidal(
    mesh: Any, basis_u: Any, basis_p: Any, channel: Any, velocity: np.ndarray, flow_m3_s: float
) -> np.ndarray:
    """The P2 velocity nearest to ``velocity`` [m/s] (in the norm weighted by the mass matrix's
    diagonal D) that is discretely divergence-free against P1 (``int q div u = 0`` for every
    P1 ``q``, as the Taylor-Hood flows are), with u = 0 on the walls and the inlet values
    scaled to carry ``flow_m3_s`` [m^3/s] exactly: ``u = u_0 + D^-1 B^T lambda`` with
    ``(B D^-1 B^T) lambda = -B u_0`` on the free dofs (a P1-sized sparse solve). The
    interpolated OpenFOAM field is divergence-free only to its interpolation error; after this
    the coolant heat transfer's energy balance closes as on the laminar flow and the outlet
    carries exactly the inlet flow."""
    from scipy.sparse import diags
    from scipy.sparse.linalg import splu
    from skfem import BilinearForm, FacetBasis, LinearForm
    from skfem.helpers import div, dot

    @BilinearForm
    def mass(u: Any, v: Any, _: Any) -> Any:
        return dot(u, v)

    @BilinearForm
    def divergence(u: Any, q: Any, _: Any) -> Any:
        return div(u) * q

    @LinearForm
    def flux(v: Any, w: Any) -> Any:
        return dot(v, w.n)

    tol = 1e-9 * max(max(b[1] for b in channel.boxes), channel.width_m)
    mid = mesh.p[:, mesh.facets].mean(axis=1)
    bnd = mesh.boundary_facets()

    def port(spec: tuple[float, float, float, int]) -> np.ndarray:
        x, y0, y1, _ = spec
        return bnd[(np.abs(mid[0, bnd] - x) < tol) & (mid[1, bnd] > y0 - tol) & (mid[1, bnd] < y1 + tol)]

    f_in, f_out = port(channel.inlet), port(channel.outlet)
    wall_dofs = basis_u.get_dofs(np.setdiff1d(bnd, np.union1d(f_in, f_out))).all()
    in_dofs = np.setdiff1d(basis_u.get_dofs(f_in).all(), wall_dofs)
    u = np.array(velocity, dtype=float)
    u[wall_dofs] = 0.0
    phi_in = flux.assemble(FacetBasis(mesh, basis_u.elem, facets=f_in, intorder=4))
    u[in_dofs] *= -flow_m3_s / float(phi_in[in_dofs] @ u[in_dofs])  # outward normal: inflow < 0
    free = np.setdiff1d(np.arange(basis_u.N), np.union1d(wall_dofs, in_dofs))
    d_inv = 1.0 / mass.assemble(basis_u).diagonal()[free]
    b = divergence.assemble(basis_u, basis_p).tocsr()  # (P1, P2 vector)
    b_free = b[:, free]
    schur = (b_free @ diags(d_inv) @ b_free.T).tocsc()
    lam = splu(schur).solve(-(b @ u))
    u[free] += d_inv * (b_free.T @ lam)
    return u


def _inlet_figures(
    channel: Any, coolant: Coolant, flow_m3_s: float, sec: Any
) -> tuple[float, float, float, float, float]:
    """The bulk figures of the flow through ``channel``: kinematic viscosity [m^2/s], mean
    velocity [m/s], hydraulic diameter [m], Reynolds number and the inlet turbulence length
    scale [m] (``flow.turbulence_length_m``, default a fraction of the hydraulic diameter)."""
    nu = coolant.viscosity_pa_s / coolant.density_kg_m3
    w, h = channel.width_m, channel.height_m
    dh = 2 * w * h / (w + h)
    u_mean = flow_m3_s / (w * h)
    length = sec.turbulence_length_m or LENGTH_SCALE_FRACTION * dh
    return nu, u_mean, dh, u_mean * dh / nu, length


def _grid(channel: Any, sec: Any) -> Any:
    """The graded hexahedral OpenFOAM grid of ``channel`` from the ``[flow]`` section ``sec``."""
    return channel_grid(
        channel,
        sec.rans_cells_across_width,
        sec.rans_cells_across_height,
        sec.rans_cell_length_m,
        sec.rans_wall_cell_m,
        sec.growth,
    )


def solve_rans(
    channel: Any,
    coolant: Coolant,
    flow_m3_s: float,
    *,
    section: Any = None,
    where: str = "flow",
    case_dir: str | Path | None = None,
    progress: bool = False,
) -> Any:
    """Steady turbulent flow through ``channel`` at ``flow_m3_s`` [m^3/s] with OpenFOAM
    (module docstring); returns a :class:`~hevsim.thermal.flow.FlowResult` on the
    ``[flow]`` tetrahedral mesh, its ``rans`` holding the :class:`RansResult`.

    ``case_dir``: folder for the OpenFOAM case (absent or empty; created); default a temporary
    folder removed afterwards. ``progress``: iterations on the terminal.

    Raises:
        OpenFoamMissingError: OpenFOAM is not installed.
        ConfigError: bad flow rate or mesh settings.
        SimulationError: OpenFOAM failed.
    """

    sec = section or FlowSection()
    coolant.check(f"{where}: coolant")
    if not (math.isfinite(flow_m3_s) and flow_m3_s > 0.0):
        raise ConfigError(f"{where}: flow rate {flow_m3_s!r} m^3/s; expected a finite positive flow rate.")
    check_channel_mesh(channel_mesh(channel, 1, 1, max(b[1] - b[0] for b in channel.boxes)), channel, where)
    of = find_openfoam()
    rho = coolant.density_kg_m3
    nu, u_mean, _dh, reynolds, length = _inlet_figures(channel, coolant, flow_m3_s, sec)
    k_in = 1.5 * (sec.turbulence_intensity * u_mean) ** 2
    omega_in = math.sqrt(k_in) / (C_MU**0.25 * length)
    t0 = time.perf_counter()
    grid = _grid(channel, sec)
    rc = RansCase(
        (channel.inlet[3] * u_mean, 0.0, 0.0),
        nu,
        k_in,
        omega_in,
        sec.outlet_pressure_pa / rho,
        sec.rans_iterations,
        sec.rans_tolerance,
        sec.rans_processes,
    )
    own_tmp = case_dir is None
    case = Path(tempfile.mkdtemp(prefix="hevsim-rans-")) if own_tmp else Path(case_dir)  # type: ignore[arg-type]
    if not own_tmp:
        if case.exists() and (not case.is_dir() or any(case.iterdir())):
            raise ConfigError(
                f"{where}: OpenFOAM case folder {case} exists and is not empty; expected a new folder."
            )
        case.mkdir(parents=True, exist_ok=True)
    try:
        write_case(case, grid, channel, rc)
        if progress:
            from hevsim.progress import stage

            stage(
                f"RANS k-omega SST with OpenFOAM ({of.source}): Re = {reynolds:.0f}, {grid.n_cells} cells, "
                f"at most {rc.iterations} iterations, {rc.processes} process(es), case {case}"
            )
        if rc.processes > 1:
            _run(of, ["decomposePar", "-force"], case, case / "log.decomposePar", None, False)
            _run(
                of,
                ["mpirun", "-np", str(rc.processes), of.which("simpleFoam") or "simpleFoam", "-parallel"],
                case,
                case / "log.simpleFoam",
                rc.iterations,
                progress,
            )
            _run(of, ["reconstructPar", "-latestTime"], case, case / "log.reconstructPar", None, False)
        else:
            _run(of, ["simpleFoam"], case, case / "log.simpleFoam", rc.iterations, progress)
        return read_rans_case(case, channel, coolant, flow_m3_s, section=sec, where=where, started=t0)
    finally:
        if own_tmp:
            shutil.rmtree(case, ignore_errors=True)


def read_rans_case(
    case_dir: str | Path,
    channel: Any,
    coolant: Coolant,
    flow_m3_s: float,
    *,
    section: Any = None,
    where: str = "flow",
    started: float | None = None,
) -> Any:
    """Read a finished OpenFOAM case of :func:`solve_rans` (its folder ``case_dir``, e.g. the
    ``openfoam/`` of ``hevsim flow --out``) back onto the ``[flow]`` tetrahedral mesh: the same
    :class:`~hevsim.thermal.flow.FlowResult` the solve returned, without solving again. The
    channel, coolant, flow rate [m^3/s] and ``section`` must be the solve's (the grid is rebuilt
    from them and must match the case's cell count). ``started``: ``time.perf_counter()`` at
    the start of the solve (the metrics' ``solve_time_s``; default: now)."""

    sec = section or FlowSection()
    t0 = time.perf_counter() if started is None else started
    case = Path(case_dir)
    rho = coolant.density_kg_m3
    nu, u_mean, dh, reynolds, length = _inlet_figures(channel, coolant, flow_m3_s, sec)
    grid = _grid(channel, sec)
    n = grid.n_cells
    log_file = case / "log.simpleFoam"
    if not log_file.is_file():
        raise ConfigError(f"{where}: {case} holds no finished OpenFOAM case (no log.simpleFoam).")
    log_text = log_file.read_text()
    last = _latest_time(case)
    u_c = read_internal_field(last / "U", n)
    p_c = read_internal_field(last / "p", n) * rho
    nut_c = read_internal_field(last / "nut", n)
    yplus = _read_yplus(case)
    p_hist = _read_inlet_pressure(case) * rho - sec.outlet_pressure_pa
    faces = re.search(r"nFaces:(\d+)", (case / "constant" / "polyMesh" / "owner").read_text())
    n_faces = int(faces.group(1)) if faces else 0
    iterations = max((int(m.group(1)) for m in re.finditer(r"^Time = (\d+)\s*$", log_text, re.M)), default=0)
    converged = "solution converged in" in log_text
    residuals: dict[str, float] = {}
    for m in _RESIDUAL.finditer(log_text):
        residuals[m.group(1)] = float(m.group(2))
    tail = p_hist[-max(1, len(p_hist) // 10) :] if p_hist.size else np.array([np.nan])
    dp_change = float(np.max(np.abs(tail - tail[-1])) / max(abs(tail[-1]), 1e-300))
    if not converged:
        last_res = ", ".join(f"{k} {v:.2g}" for k, v in residuals.items())
        warnings.warn(
            f"{where}: simpleFoam did not reach the residual tolerance {sec.rans_tolerance:g} in "
            f"{iterations} iterations (last initial residuals: {last_res}; the pressure drop changed by "
            f"{dp_change:.1e} (relative) over the last tenth of the iterations); raise "
            "flow.rans_iterations or flow.rans_tolerance, or accept the result if that change is small "
            "(steady RANS in the bends may not settle further).",
            RuntimeWarning,
            stacklevel=3,
        )
    wall_pts, inlet_pts = boundary_points(grid, channel)
    u_in = np.array((channel.inlet[3] * u_mean, 0.0, 0.0))
    u_field = GridField.from_cells(grid, u_c, [(inlet_pts, u_in), (wall_pts, np.zeros(3))])
    p_field = GridField.from_cells(grid, p_c)
    nut_field = GridField.from_cells(grid, nut_c, [(wall_pts, np.zeros(1))])
    rres = RansResult(grid, u_c, p_c, nut_c, u_field, p_field, nut_field, residuals, log_text)
    # figures from the OpenFOAM cells
    cin, a_in = _port_cells(grid, channel.inlet)
    cout, a_out = _port_cells(grid, channel.outlet)
    p_in = float((p_c[cin] * a_in).sum() / a_in.sum())
    q_in = float(abs(u_in[0]) * a_in.sum())
    q_out = float(abs((u_c[cout, 0] * a_out).sum()))
    metrics = {
        **hydraulic_metrics(flow_m3_s, q_in, q_out, reynolds, u_mean, dh, p_in, sec.outlet_pressure_pa),
        # largest change of the pressure drop over the last tenth of the iterations, relative [-]
        "pressure_drop_change_rel": dp_change,
        "max_velocity_mps": float(np.max(np.linalg.norm(u_c, axis=1))),
        "channel_volume_m3": float(
            np.einsum("i,j,k->ijk", *[np.diff(nd) for nd in grid.nodes])[grid.inside].sum()
        ),
        "iterations": float(iterations),
        "converged": float(converged),
        "rans_cells": float(n),
        "rans_faces": float(n_faces),
        **yplus,
        "max_eddy_viscosity_ratio": float(np.max(nut_c) / nu),
        "turbulence_intensity": sec.turbulence_intensity,
        "prandtl": coolant.prandtl,
        "conduction_sublayer_m": conduction_sublayer_m(reynolds, dh, coolant.prandtl),
        "turbulence_length_m": length,
        "solve_time_s": time.perf_counter() - t0,
    }
    for key, val in residuals.items():
        metrics[f"final_residual_{key}"] = val
    # onto the tetrahedral mesh of the [flow] resolution keys
    return on_fem_mesh(rres, channel, metrics, sec, [float(v) for v in p_hist])


def on_fem_mesh(
    rres: RansResult, channel: Any, metrics: dict[str, float], section: Any, history: Sequence[float] = ()
) -> Any:
    """A :class:`~hevsim.thermal.flow.FlowResult` of the OpenFOAM solution ``rres`` on the
    tetrahedral mesh of ``section``'s resolution keys (``cells_across_width``,
    ``cells_across_height``, ``cell_length_m``, ``wall_cell_m``, ``growth``): the P2 velocity
    interpolated and projected to be discretely divergence-free (:func:`project_solenoidal`,
    carrying ``metrics["flow_m3_s"]``), the P1 pressure [Pa] and the eddy diffusivity
    ``nu_t / section.prandtl_turbulent`` [m^2/s] at the vertices. ``metrics``: the solve's
    figures, completed with the FEM mesh's. One OpenFOAM solve can so be read onto several FEM
    meshes (a mesh study, or a coarse mesh with the thermal wall function)."""
    from skfem import Basis, ElementTetP1, ElementTetP2, ElementVector

    sec = section
    w, h = channel.width_m, channel.height_m
    mesh = channel_mesh(
        channel,
        sec.cells_across_width,
        sec.cells_across_height,
        sec.cell_length_m,
        sec.wall_cell_m,
        sec.growth,
    )
    basis_u = Basis(mesh, ElementVector(ElementTetP2()), intorder=4)
    basis_p = basis_u.with_element(ElementTetP1())
    scalar = basis_u.with_element(ElementTetP2())
    flow_m3_s = float(metrics["flow_m3_s"])
    velocity = project_solenoidal(
        mesh, basis_u, basis_p, channel, rres.u_field.at(scalar.doflocs.T).reshape(-1), flow_m3_s
    )
    pressure = rres.p_field.at(mesh.p.T)[:, 0]
    eddy = rres.nut_field.at(mesh.p.T)[:, 0] / sec.prandtl_turbulent
    fem = {
        "fem_wall_cell_m": sec.wall_cell_m
        or min(h / sec.cells_across_height, w / sec.cells_across_width, sec.cell_length_m),
        "velocity_dofs": float(basis_u.N),
        "pressure_dofs": float(basis_p.N),
        "elements": float(mesh.t.shape[1]),
        "cells_across_width": float(sec.cells_across_width),
        "cells_across_height": float(sec.cells_across_height),
    }
    res = FlowResult({**metrics, **fem}, mesh, velocity, pressure, basis_u, basis_p, list(history))
    res.eddy_diffusivity_m2_s = eddy
    res.rans = rres
    return res

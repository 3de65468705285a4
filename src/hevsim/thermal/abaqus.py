"""Import of Abaqus/Standard heat-transfer input decks (``.inp``) such as the thesis's Standard.inp.

Supported keywords: *Node, *Element (C3D4 / DC3D4 linear tetrahedra), *Elset and *Nset (with
``generate``), *Solid Section (elset -> material: one part per section), *Material,
*Conductivity, *Density, *Specific Heat, *Initial Conditions (type=TEMPERATURE), *Surface
(type=ELEMENT, faces S1-S4), *Gap Conductance (the zero-clearance value), *Dflux (BF body
flux per element set: each set becomes one heat source "cell"). The wrappers *Part, *End
Part, *Assembly, *Instance, *End Instance, *End Assembly and purely descriptive keywords are
accepted. An *Instance's data lines are applied to the nodes of its part (Abaqus Keywords
Reference, *INSTANCE): the first line is a translation (dx, dy, dz), the optional second line a
rotation about the axis through points a and b by an angle in degrees (right-hand rule about
a -> b); when both are given the translation is applied first. A part placed by more than one
instance is reported (only the first placement is applied: the reader keeps one copy).
Every other keyword is reported in :attr:`AbaqusModel.unsupported` (keyword and line), never
silently dropped.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hevsim.errors import InputError
from hevsim.thermal.materials import Material
from hevsim.thermal.mesh import ThermalMesh

#: Node order of faces S1..S4 of a 4-node tetrahedron (Abaqus Analysis User's Guide).
TET_FACES = {"S1": (0, 1, 2), "S2": (0, 3, 1), "S3": (1, 3, 2), "S4": (2, 3, 0)}
_TET_TYPES = {"C3D4", "DC3D4", "C3D4T"}
_ACCEPTED = {
    "heading", "preprint", "part", "end part", "assembly", "end assembly", "instance", "end instance",
    "amplitude", "step", "end step", "heat transfer", "output", "node output", "element output",
    "contact output", "restart", "surface interaction", "contact pair", "co-simulation",
    "co-simulation region", "co-simulation controls", "monitor",
}  # fmt: skip


@dataclass
class AbaqusModel:
    """What was read: the mesh, per-part materials, initial temperature and loads."""

    mesh: ThermalMesh
    materials: dict[str, Material]
    initial_temp_c: dict[str, float] = field(default_factory=dict)  # node set -> °C
    gap_conductance_w_m2k: float | None = None
    body_flux_w_m3: dict[str, float] = field(default_factory=dict)  # element set -> W/m^3
    unsupported: list[str] = field(default_factory=list)


def _options(line: str) -> tuple[str, dict[str, str]]:
    parts = [p.strip() for p in line[1:].split(",")]
    opts = {}
    for p in parts[1:]:
        k, _, v = p.partition("=")
        opts[k.strip().lower()] = v.strip()
    return parts[0].lower(), opts


def _rotate(points: np.ndarray, a: np.ndarray, b: np.ndarray, angle_deg: float) -> np.ndarray:
    """Rotate ``points`` about the axis a -> b by ``angle_deg`` (right-hand rule, Rodrigues)."""
    axis = b - a
    norm = float(np.linalg.norm(axis))
    if norm == 0.0:
        raise ValueError("rotation axis points a and b coincide")
    k = axis / norm
    th = np.radians(angle_deg)
    v = points - a
    rot = v * np.cos(th) + np.cross(k, v) * np.sin(th) + np.outer(v @ k, k) * (1.0 - np.cos(th))
    return rot + a


def read_abaqus_inp(path: str | Path, *, length_scale_m: float = 1.0) -> AbaqusModel:
    """Read an ``.inp`` deck; coordinates are multiplied by ``length_scale_m`` (1e-3 for mm decks)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: Abaqus input file not found.")
    src = str(p)
    nodes: dict[int, tuple[float, float, float]] = {}
    elements: dict[int, tuple[int, int, int, int]] = {}
    elsets: dict[str, list[int]] = {}
    nsets: dict[str, list[int]] = {}
    sections: list[tuple[str, str]] = []
    materials: dict[str, dict[str, float]] = {}
    surfaces: dict[str, list[tuple[str, str]]] = {}
    initial: dict[str, float] = {}
    dflux: dict[str, float] = {}
    gap: float | None = None
    unsupported: list[str] = []
    part_nodes: dict[str, list[int]] = {}
    current_part = ""
    placements: dict[str, list[list[float]]] = {}  # part -> instance data lines
    instance_part = ""
    kw, material = "", ""
    opts: dict[str, str] = {}
    lines = p.read_text(encoding="utf-8", errors="replace").splitlines()
    for no, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("**"):
            continue
        if line.startswith("*"):
            kw, opts = _options(line)
            if kw == "element" and opts.get("type", "").upper() not in _TET_TYPES:
                raise InputError(
                    f"{src}: line {no}: element type {opts.get('type')!r} is not supported; "
                    f"expected one of {sorted(_TET_TYPES)} (linear tetrahedra)."
                )
            if kw == "material":
                material = opts.get("name", "")
                materials[material] = {}
            elif kw == "solid section":
                sections.append((opts.get("elset", ""), opts.get("material", "")))
            elif kw == "surface":
                if opts.get("type", "ELEMENT").upper() != "ELEMENT":
                    unsupported.append(f"line {no}: *Surface type={opts.get('type')}")
                surfaces[opts.get("name", "")] = []
            elif kw == "part":
                current_part = opts.get("name", "")
            elif kw == "end part":
                current_part = ""
            elif kw == "instance":
                instance_part = opts.get("part", "")
                if instance_part in placements:
                    unsupported.append(
                        f"line {no}: *Instance of part '{instance_part}' placed a second time "
                        "(only the first placement is applied)"
                    )
                    instance_part = ""
                elif instance_part:
                    placements[instance_part] = []
            elif kw == "initial conditions" and opts.get("type", "").upper() != "TEMPERATURE":
                unsupported.append(f"line {no}: *Initial Conditions type={opts.get('type')}")
            elif kw not in _ACCEPTED and kw not in {
                "node", "element", "elset", "nset", "conductivity", "density", "specific heat",
                "initial conditions", "gap conductance", "dflux",
            }:  # fmt: skip
                unsupported.append(f"line {no}: *{line[1:].split(',')[0].strip()}")
            continue
        vals = [v.strip() for v in line.split(",") if v.strip()]
        try:
            if kw == "node":
                nodes[int(vals[0])] = (float(vals[1]), float(vals[2]), float(vals[3]))
                if current_part:
                    part_nodes.setdefault(current_part, []).append(int(vals[0]))
            elif kw == "instance":
                if instance_part:
                    if len(placements[instance_part]) >= 2:
                        raise ValueError("more than two data lines")
                    expected = 3 if not placements[instance_part] else 7
                    if len(vals) != expected:
                        raise ValueError(f"expected {expected} numbers, got {len(vals)}")
                    placements[instance_part].append([float(v) for v in vals])
            elif kw == "element":
                e = [int(v) for v in vals]
                elements[e[0]] = (e[1], e[2], e[3], e[4])
                if "elset" in opts:
                    elsets.setdefault(opts["elset"], []).append(e[0])
            elif kw in ("elset", "nset"):
                target = (elsets if kw == "elset" else nsets).setdefault(opts.get(kw, ""), [])
                if "generate" in opts:
                    a, b, *step = (int(v) for v in vals)
                    target.extend(range(a, b + 1, step[0] if step else 1))
                else:
                    target.extend(int(v) for v in vals)
            elif kw in ("conductivity", "density", "specific heat"):
                materials[material][kw] = float(vals[0])
            elif kw == "initial conditions" and opts.get("type", "").upper() == "TEMPERATURE":
                initial[vals[0]] = float(vals[1])
            elif kw == "surface":
                surfaces[opts.get("name", "")].append((vals[0], vals[1].upper()))
            elif kw == "gap conductance" and gap is None:
                if len(vals) < 2 or float(vals[1]) == 0.0:
                    gap = float(vals[0])
            elif kw == "dflux":
                if vals[1].upper() != "BF":
                    unsupported.append(f"line {no}: *Dflux load type {vals[1]} (only BF)")
                else:
                    dflux[vals[0]] = float(vals[2])
        except (ValueError, IndexError) as exc:
            raise InputError(f"{src}: line {no}: cannot read data line {line!r} of *{kw} ({exc}).") from exc

    if not elements:
        raise InputError(f"{src}: no *Element block of linear tetrahedra found.")
    for pname, data in placements.items():
        ids = part_nodes.get(pname, [])
        if not data or not ids:
            continue
        xyz = np.array([nodes[i] for i in ids], dtype=float) + np.array(data[0])
        if len(data) == 2:
            r = data[1]
            try:
                xyz = _rotate(xyz, np.array(r[0:3]), np.array(r[3:6]), r[6])
            except ValueError as exc:
                raise InputError(f"{src}: *Instance of part '{pname}': {exc}.") from exc
        for i, row in zip(ids, xyz.tolist(), strict=True):
            nodes[i] = (row[0], row[1], row[2])
    nid = np.array(sorted(nodes))
    lookup = {n: i for i, n in enumerate(nid.tolist())}
    pts = np.array([nodes[n] for n in nid.tolist()]) * length_scale_m
    eid = np.array(sorted(elements))
    eindex = {e: i for i, e in enumerate(eid.tolist())}
    try:
        tets = np.array([[lookup[n] for n in elements[e]] for e in eid.tolist()], dtype=np.int64)
    except KeyError as exc:
        raise InputError(f"{src}: an element refers to node {exc.args[0]} which is not defined.") from exc

    def elset_rows(name: str, what: str) -> np.ndarray:
        if name not in elsets:
            raise InputError(f"{src}: {what} refers to element set '{name}' which is not defined.")
        return np.array([eindex[e] for e in elsets[name] if e in eindex], dtype=np.int64)

    part = np.full(len(eid), -1)
    part_names: list[str] = []
    mats: dict[str, Material] = {}
    for elset, mname in sections:
        if mname not in materials:
            raise InputError(
                f"{src}: *Solid Section elset={elset} uses material '{mname}' which is not defined."
            )
        props = materials[mname]
        missing = [k for k in ("conductivity", "density", "specific heat") if k not in props]
        if missing:
            raise InputError(
                f"{src}: material '{mname}' has no {', '.join(missing)}; expected *Conductivity, "
                "*Density and *Specific Heat for a transient heat analysis."
            )
        part[elset_rows(elset, "*Solid Section")] = len(part_names)
        part_names.append(elset)
        mats[elset] = Material(mname, props["conductivity"], props["density"], props["specific heat"])
    if (part < 0).any():
        raise InputError(
            f"{src}: {int((part < 0).sum())} elements (first {int(eid[part < 0][0])}) have no "
            "*Solid Section; expected every element to have a material."
        )
    cell = np.full(len(eid), -1)
    for i, name in enumerate(dflux):
        cell[elset_rows(name, "*Dflux")] = i
    groups: dict[str, np.ndarray] = {}
    for sname, entries in surfaces.items():
        tris = []
        for elset, face in entries:
            if face not in TET_FACES:
                raise InputError(f"{src}: surface '{sname}' face {face!r}; expected one of S1-S4.")
            rows = elset_rows(elset, f"*Surface {sname}")
            tris.append(tets[rows][:, list(TET_FACES[face])])
        groups[sname] = np.vstack(tris) if tris else np.zeros((0, 3), dtype=np.int64)
    mesh = ThermalMesh(pts, tets, part, tuple(part_names), cell, groups, None, src).validate()
    return AbaqusModel(mesh, mats, initial, gap, dflux, unsupported)

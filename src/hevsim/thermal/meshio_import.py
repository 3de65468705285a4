"""Import of tetrahedral meshes in any format meshio reads (gmsh .msh, VTU, XDMF, ...).

Volumes are mapped to parts (materials) through an integer region tag per tetrahedron: the
gmsh physical group (``gmsh:physical``, named through the file's physical names) or any
integer cell-data array (``tag_key``, e.g. ``"region"`` in a VTU file). The caller maps every
region, by its physical name or by its tag written as a string, to a material: a name from
thesis Table 4.3 (``"aluminium"``, ``"plastic"``, ...) or a :class:`Material`. Tagged triangles
become named surfaces (facet groups) under their physical name or tag, renamed through
``surface_names`` (e.g. ``{"wall": "INTERFACE"}`` for the channel wall). Regions listed in
``heat_sources`` are battery cells (body heat flux), numbered in the given order.

Vertices, lines and other lower-dimensional cells are skipped and reported in
:attr:`ImportedMesh.ignored`; 3D cells other than linear tetrahedra are an error.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import InputError
from hevsim.thermal.materials import TABLE_4_3, Material
from hevsim.thermal.mesh import ThermalMesh, tet_volumes_m3

_SOLID_TYPES = {"hexahedron", "wedge", "pyramid", "tetra10", "hexahedron20", "hexahedron27", "wedge15"}


@dataclass
class ImportedMesh:
    """What was read: the mesh (one part per mapped region) and each part's material."""

    mesh: ThermalMesh
    materials: dict[str, Material]
    region_tags: dict[str, int] = field(default_factory=dict)  # part name -> region tag
    ignored: list[str] = field(default_factory=list)


def _names(field_data: Mapping[str, Any], dim: int) -> dict[int, str]:
    """Tag -> physical name of dimension ``dim`` from meshio's ``field_data`` (gmsh)."""
    out = {}
    for name, val in field_data.items():
        arr = np.asarray(val).ravel()
        if arr.size >= 2 and int(arr[1]) == dim:
            out[int(arr[0])] = str(name)
    return out


def read_mesh(
    path: str | Path,
    part_materials: Mapping[str, str | Material],
    *,
    tag_key: str | None = None,
    surface_names: Mapping[str, str] | None = None,
    heat_sources: Sequence[str] = (),
    length_scale_m: float = 1.0,
    channel_path_m: np.ndarray | None = None,
) -> ImportedMesh:
    """Read a tetrahedral mesh with meshio and map its regions to parts and materials.

    ``part_materials`` maps every volume region (physical name, or tag as a string) to a
    Table 4.3 material name or a :class:`Material`; unmapped regions and keys that match no
    region are errors. ``tag_key`` selects the integer cell-data array holding the region tags
    (default ``gmsh:physical`` when present, else the only integer cell-data array).
    """
    import meshio

    p = Path(path)
    src = str(p)
    if not p.is_file():
        raise InputError(f"{src}: mesh file not found.")
    try:
        m = meshio.read(p)
    except Exception as exc:  # meshio raises many types for unreadable files
        raise InputError(f"{src}: meshio cannot read this file ({type(exc).__name__}: {exc}).") from exc

    blocks = list(m.cells)
    ints = [
        k
        for k, arrs in m.cell_data.items()
        if all(np.issubdtype(np.asarray(a).dtype, np.integer) for a in arrs)
    ]
    if tag_key is None:
        if "gmsh:physical" in m.cell_data:
            tag_key = "gmsh:physical"
        elif len(ints) == 1:
            tag_key = ints[0]
        else:
            raise InputError(
                f"{src}: cannot tell which cell data holds the region tags; pass tag_key= one of "
                f"{ints or '(none: the file has no integer cell data)'}."
            )
    if tag_key not in m.cell_data:
        raise InputError(f"{src}: no cell data '{tag_key}'; the file has {sorted(m.cell_data)}.")
    tags_of = m.cell_data[tag_key]
    vol_names, surf_names = _names(m.field_data, 3), _names(m.field_data, 2)

    tets, tet_tags, tris, tri_tags, ignored = [], [], [], [], []
    for b, block in enumerate(blocks):
        data = np.asarray(block.data, dtype=np.int64)
        btag = np.asarray(tags_of[b], dtype=np.int64).ravel()
        if block.type == "tetra":
            tets.append(data)
            tet_tags.append(btag)
        elif block.type == "triangle":
            tris.append(data)
            tri_tags.append(btag)
        elif block.type in _SOLID_TYPES:
            raise InputError(
                f"{src}: cell type '{block.type}' is not supported; expected linear tetrahedra ('tetra')."
            )
        else:
            ignored.append(f"{len(data)} '{block.type}' cells")
    if not tets:
        raise InputError(f"{src}: no linear tetrahedra ('tetra' cells) in the file.")
    t_all, t_tag = np.vstack(tets), np.concatenate(tet_tags)

    # regions -> parts
    region_name = {int(t): vol_names.get(int(t), str(int(t))) for t in np.unique(t_tag)}
    keys = {name: t for t, name in region_name.items()}
    keys.update({str(t): t for t in region_name})
    unknown = [k for k in part_materials if k not in keys]
    if unknown:
        raise InputError(
            f"{src}: material map names {unknown} which are not volume regions; the regions are "
            f"{sorted(region_name.values())} (tags {sorted(region_name)})."
        )
    part_of_tag: dict[int, str] = {}
    materials: dict[str, Material] = {}
    for key, spec in part_materials.items():
        tag = keys[key]
        name = region_name[tag]
        if tag in part_of_tag:
            raise InputError(f"{src}: region '{name}' (tag {tag}) is mapped twice in the material map.")
        if isinstance(spec, Material):
            mat = spec
        elif spec in TABLE_4_3:
            mat = TABLE_4_3[spec]
        else:
            raise InputError(
                f"{src}: region '{name}' material {spec!r} is not known; expected a Material or one of "
                f"{sorted(TABLE_4_3)}."
            )
        part_of_tag[tag] = name
        materials[name] = mat.check(f"{src}: region '{name}'")
    missing = sorted(set(region_name) - set(part_of_tag))
    if missing:
        raise InputError(
            f"{src}: volume regions {[region_name[t] for t in missing]} (tags {missing}) have no "
            "material; map every region in part_materials."
        )
    part_names = tuple(region_name[t] for t in sorted(part_of_tag))
    index = {name: i for i, name in enumerate(part_names)}
    part = np.array([index[region_name[int(t)]] for t in t_tag], dtype=np.int64)
    cell = np.full(len(t_all), -1, dtype=np.int64)
    for i, key in enumerate(heat_sources):
        if key not in keys:
            raise InputError(f"{src}: heat source '{key}' is not a volume region; regions are {part_names}.")
        cell[t_tag == keys[key]] = i

    # keep the nodes of the tetrahedra only; surfaces must lie on them
    used, inv = np.unique(t_all.ravel(), return_inverse=True)
    t_all = inv.reshape(-1, 4)
    renum = np.full(len(m.points), -1, dtype=np.int64)
    renum[used] = np.arange(used.size)
    groups: dict[str, np.ndarray] = {}
    rename = dict(surface_names or {})
    if tris:
        tri_all, tri_tag = np.vstack(tris), np.concatenate(tri_tags)
        for t in np.unique(tri_tag).tolist():
            base = surf_names.get(int(t), str(int(t)))
            name = rename.get(base, rename.get(str(int(t)), base))
            rows = renum[tri_all[tri_tag == t]]
            if (rows < 0).any():
                raise InputError(f"{src}: surface '{base}' has nodes that belong to no tetrahedron.")
            groups[name] = np.vstack([groups[name], rows]) if name in groups else rows
    unknown_s = [k for k in rename if k not in groups and rename[k] not in groups]
    if unknown_s:
        raise InputError(f"{src}: surface_names names {unknown_s} which are not surfaces of the file.")
    pts = np.asarray(m.points, dtype=float)[used]
    if pts.shape[1] == 2:
        raise InputError(f"{src}: the mesh is 2D; expected 3D points.")
    pts = pts[:, :3] * length_scale_m
    vol = tet_volumes_m3(pts, t_all)
    if np.all(vol < 0):  # the file's convention is left-handed: flip every element
        t_all = t_all[:, [1, 0, 2, 3]]
    mesh = ThermalMesh(pts, t_all, part, part_names, cell, groups, channel_path_m, src).validate()
    return ImportedMesh(mesh, materials, {region_name[t]: t for t in part_of_tag}, ignored)

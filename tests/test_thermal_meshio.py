"""Import of meshio-readable meshes (gmsh .msh, VTU) mapped to parts and interfaces (issue 5, item 2)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("skfem")
pytest.importorskip("gmsh")
pytest.importorskip("meshio")

from hevsim.errors import InputError
from hevsim.thermal.materials import TABLE_4_3, Material
from hevsim.thermal.mesh import CHANNEL_WALL, tet_volumes_m3, triangle_areas_m2
from hevsim.thermal.meshio_import import read_mesh
from hevsim.thermal.solver import HeatModel, discretise


def write_two_blocks(path: Path) -> None:
    """Two 10 x 4 x 4 mm blocks side by side: physical volumes 'alu' and 'cell', surface 'wall' at x = 0."""
    import gmsh

    from hevsim.thermal.geometry import initialize_gmsh

    initialize_gmsh(gmsh)  # not gmsh.initialize: it would leave SIGPIPE fatal in the test process
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("blocks")
        occ = gmsh.model.occ
        a = occ.addBox(0, 0, 0, 0.010, 0.004, 0.004)
        b = occ.addBox(0.010, 0, 0, 0.010, 0.004, 0.004)
        occ.fragment([(3, a)], [(3, b)])
        occ.synchronize()
        gmsh.model.addPhysicalGroup(3, [a], 11, name="alu")
        gmsh.model.addPhysicalGroup(3, [b], 12, name="cell")
        left = [t for _, t in gmsh.model.getEntities(2) if abs(gmsh.model.getBoundingBox(2, t)[3]) < 1e-6]
        gmsh.model.addPhysicalGroup(2, left, 21, name="wall")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.002)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


@pytest.fixture(scope="module")
def msh(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("msh") / "blocks.msh"
    write_two_blocks(path)
    return path


def test_gmsh_physical_groups_map_to_parts_and_interfaces(msh: Path) -> None:
    plastic = Material("my plastic", 0.3, 1900.0, 1700.0)
    imp = read_mesh(
        msh,
        {"alu": "aluminium", "cell": plastic},
        surface_names={"wall": CHANNEL_WALL},
        heat_sources=["cell"],
    )
    m = imp.mesh
    assert m.part_names == ("alu", "cell") and imp.region_tags == {"alu": 11, "cell": 12}
    assert imp.materials["alu"] == TABLE_4_3["aluminium"] and imp.materials["cell"] == plastic
    vol = tet_volumes_m3(m.points_m, m.tets)
    assert np.all(vol > 0)
    for i in range(2):
        assert vol[m.part_of_tet == i].sum() == pytest.approx(160e-9, rel=1e-9)
    assert m.n_cells == 1 and np.all((m.cell_of_tet == 0) == (m.part_of_tet == 1))
    wall = m.facet_groups[CHANNEL_WALL]
    assert triangle_areas_m2(m.points_m, wall).sum() == pytest.approx(16e-6, rel=1e-9)
    assert np.all(m.points_m[wall][:, :, 0] == 0.0)
    assert imp.ignored == []
    disc = discretise(m, imp.materials, gap_conductance_w_m2k=1000.0)
    assert disc.interfaces == {"alu|cell": pytest.approx(16e-6, rel=1e-9)}
    hm = HeatModel(disc, dt_s=1.0, initial_temp_k=300.0)
    hm.set_cell_heat_w(1.0)
    hm.step()
    assert hm.report().stored_energy_j > float(np.sum(disc.capacity @ np.full(disc.points_m.shape[0], 300.0)))


def test_vtu_round_trip_with_cell_data_tags(msh: Path, tmp_path: Path) -> None:
    import meshio

    ref = read_mesh(msh, {"alu": "aluminium", "cell": "plastic"}, surface_names={"wall": CHANNEL_WALL}).mesh
    m = meshio.read(msh)
    cells = [(b.type, b.data) for b in m.cells if b.type in ("tetra", "triangle")]
    tags = [np.asarray(t, dtype=np.int32) for b, t in zip(m.cells, m.cell_data["gmsh:physical"], strict=True)
            if b.type in ("tetra", "triangle")]  # fmt: skip
    cells.append(("vertex", np.array([[0]])))  # lower-dimensional cells are skipped and reported
    tags.append(np.array([99], dtype=np.int32))
    vtu = tmp_path / "blocks.vtu"
    meshio.write(vtu, meshio.Mesh(m.points * 1e3, cells, cell_data={"region": tags}))  # in mm
    imp = read_mesh(
        vtu, {"11": "aluminium", "12": "plastic"}, surface_names={"21": CHANNEL_WALL}, length_scale_m=1e-3
    )
    got = imp.mesh
    assert got.part_names == ("11", "12") and imp.ignored == ["1 'vertex' cells"]
    assert np.allclose(got.points_m, ref.points_m, rtol=0, atol=1e-12)
    assert np.array_equal(got.tets, ref.tets) and np.array_equal(got.part_of_tet, ref.part_of_tet)
    assert np.array_equal(got.facet_groups[CHANNEL_WALL], ref.facet_groups[CHANNEL_WALL])


def test_bad_maps(msh: Path, tmp_path: Path) -> None:
    import meshio

    with pytest.raises(InputError, match=r"regions \['cell'\] \(tags \[12\]\) have no material"):
        read_mesh(msh, {"alu": "aluminium"})
    with pytest.raises(InputError, match=r"names \['celll'\] which are not volume regions"):
        read_mesh(msh, {"alu": "aluminium", "celll": "plastic"})
    with pytest.raises(InputError, match="material 'unobtainium' is not known"):
        read_mesh(msh, {"alu": "aluminium", "cell": "unobtainium"})
    with pytest.raises(InputError, match="mapped twice"):
        read_mesh(msh, {"alu": "aluminium", "11": "plastic", "cell": "plastic"})
    with pytest.raises(InputError, match="not surfaces of the file"):
        read_mesh(msh, {"alu": "aluminium", "cell": "plastic"}, surface_names={"wal": CHANNEL_WALL})
    with pytest.raises(Exception, match="conductivity_w_mk"):
        read_mesh(msh, {"alu": Material("bad", -1.0, 1.0, 1.0), "cell": "plastic"})
    bad = tmp_path / "hex.vtu"
    meshio.write(
        bad, meshio.Mesh(np.eye(8, 3), [("hexahedron", np.arange(8)[None])], cell_data={"r": [np.array([1])]})
    )
    with pytest.raises(InputError, match="cell type 'hexahedron' is not supported"):
        read_mesh(bad, {"1": "plastic"})
    with pytest.raises(InputError, match="mesh file not found"):
        read_mesh(tmp_path / "none.msh", {})

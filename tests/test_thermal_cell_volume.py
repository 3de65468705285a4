"""Faceted cells (issue 15, item 4): the curvature meshing is its own setting, the meshed and
nominal volume of every part are reported, and every cell receives exactly its stated watts
whatever its meshed volume."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("skfem")
pytest.importorskip("gmsh")

from hevsim.errors import ConfigError
from hevsim.thermal.geometry import ModuleGeometry, build_module_mesh
from hevsim.thermal.materials import DEFAULT_PART_MATERIALS, TABLE_4_3
from hevsim.thermal.mesh import tet_volumes_m3
from hevsim.thermal.run import format_summary, run_thermal, thermal_config_from_dict
from hevsim.thermal.solver import HeatModel, discretise

COARSE = ModuleGeometry(mesh_size_m=0.01)


def _cell_volumes(mesh: object) -> np.ndarray:
    m: object = mesh
    vol = np.abs(tet_volumes_m3(m.points_m, m.tets))  # type: ignore[attr-defined]
    sel = m.cell_of_tet >= 0  # type: ignore[attr-defined]
    return np.bincount(m.cell_of_tet[sel], weights=vol[sel])  # type: ignore[attr-defined]


def test_curvature_elements_control_the_facets_and_nominal_volumes_are_exact() -> None:
    exact_cell = np.pi * (COARSE.cell_diameter_m / 2) ** 2 * COARSE.cell_height_m
    ratios = []
    for n in (12, 24):
        mesh = build_module_mesh(dataclasses.replace(COARSE, curvature_elements=n))
        assert mesh.nominal_volume_m3["cells"] == pytest.approx(12 * exact_cell, rel=1e-9)
        vols = _cell_volumes(mesh)
        ratios.append(float(vols.sum() / mesh.nominal_volume_m3["cells"]))
        assert np.all(vols < exact_cell)  # inscribed facets
    # a 12-gon holds (12 / 2 pi) sin(2 pi / 12) = 95.5 % of the disc, a 24-gon 98.9 %
    assert 0.95 < ratios[0] < 0.985 < ratios[1] < 1.0
    with pytest.raises(ConfigError, match="curvature_elements' = 4; expected at least 6"):
        ModuleGeometry(curvature_elements=4).check()


def test_every_cell_receives_its_stated_watts_whatever_its_meshed_volume() -> None:
    mesh = build_module_mesh(COARSE)
    vols = _cell_volumes(mesh)
    assert np.ptp(vols) > 0  # the facets differ from cell to cell
    mats = {p: TABLE_4_3[DEFAULT_PART_MATERIALS[p]] for p in mesh.part_names}
    disc = discretise(mesh, mats, film_w_m2k=0.0)
    watts = 0.5 + np.arange(mesh.n_cells)  # [W]
    load = disc.cell_load @ watts  # nodal heat [W]
    in_cell = mesh.cell_of_tet >= 0
    cell_of_node = np.full(disc.points_m.shape[0], -1)
    cell_of_node[disc.tets[in_cell].ravel()] = np.repeat(mesh.cell_of_tet[in_cell], 4)
    assert np.all(load[cell_of_node < 0] == 0.0)
    per_cell = np.bincount(cell_of_node[cell_of_node >= 0], weights=load[cell_of_node >= 0])
    np.testing.assert_allclose(per_cell, watts, rtol=1e-13)
    # adiabatic module: the stored heat after one implicit step is exactly the watts x step
    model = HeatModel(disc, dt_s=10.0, initial_temp_k=300.0)
    model.set_cell_heat_w(watts)
    model.step()
    stored = float(np.sum(model.capacity @ (model.temp_k - 300.0)))
    assert stored == pytest.approx(10.0 * watts.sum(), rel=1e-9)


def test_run_reports_meshed_and_nominal_part_volumes() -> None:
    data = {
        "geometry": {"mesh_size_m": 0.01, "curvature_elements": 12},
        "simulation": {"duration_s": 2.0, "dt_s": 2.0},
        "output": {"field_every_s": 0.0, "pictures": 0},
    }
    res = run_thermal(thermal_config_from_dict(data, "vol.toml"), None)
    cells = res.part_stats["cells"]
    assert cells["volume_ratio"] == pytest.approx(cells["meshed_volume_m3"] / cells["nominal_volume_m3"])
    assert 0.95 < cells["volume_ratio"] < 0.99
    assert res.part_stats["housing"]["volume_ratio"] == pytest.approx(1.0, rel=1e-9)  # straight walls
    assert "meshed/nominal volume: plate" in format_summary(res)
    with pytest.raises(ConfigError, match="curvature_elements"):
        thermal_config_from_dict({"geometry": {"curvature_elements": 2}}, "vol.toml")

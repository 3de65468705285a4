"""Module geometry, coupled coolant energy balance and the end-to-end run (issue 5, items 1, 4, 5, 6)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("skfem")
pytest.importorskip("gmsh")

from hevsim.thermal.coolant import ChannelModel, segments_along_path
from hevsim.thermal.geometry import ModuleGeometry, build_module_mesh
from hevsim.thermal.materials import DEFAULT_PART_MATERIALS, TABLE_4_3
from hevsim.thermal.mesh import CHANNEL_WALL, ThermalMesh
from hevsim.thermal.run import format_summary, load_thermal_config, run_thermal, thermal_config_from_dict
from hevsim.thermal.solver import HeatModel, discretise

ROOT = Path(__file__).resolve().parents[1]
COARSE = ModuleGeometry(mesh_size_m=0.01)


@pytest.fixture(scope="module")
def coarse_mesh() -> ThermalMesh:
    return build_module_mesh(COARSE)


def test_geometry_parts_groups_and_reproducible(coarse_mesh: ThermalMesh) -> None:
    m = coarse_mesh
    assert m.part_names == ("plate", "holder", "cells", "connector", "cover", "bms", "housing")
    assert m.n_cells == 12
    assert set(np.unique(m.part_of_tet)) == set(range(7))
    vol = np.bincount(
        m.cell_of_tet[m.cell_of_tet >= 0],
        weights=np.abs(
            np.einsum(
                "ij,ij->i",
                *(lambda p: (p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])))(
                    m.points_m[m.tets[m.cell_of_tet >= 0]]
                ),
            )
        )
        / 6,
    )
    exact = np.pi * 0.009**2 * 0.065
    assert np.all(np.abs(vol / exact - 1) < 0.06)  # faceted cylinders
    wall = m.facet_groups[CHANNEL_WALL]
    z = m.points_m[wall][:, :, 2]
    assert z.min() >= 0.002 - 1e-9 and z.max() <= 0.006 + 1e-9
    from hevsim.thermal.mesh import triangle_areas_m2

    cell_area = triangle_areas_m2(m.points_m, m.facet_groups["INTERFACE2"]).sum()
    exact_area = 12 * (np.pi * 0.018 * 0.065 + 2 * np.pi * 0.009**2)
    assert abs(cell_area / exact_area - 1) < 0.05
    ext = triangle_areas_m2(m.points_m, m.facet_groups["EXTERNAL"]).sum()
    assert ext > 2 * 0.128 * 0.048  # at least top and bottom of the module
    again = build_module_mesh(COARSE)
    assert np.array_equal(again.points_m, m.points_m) and np.array_equal(again.tets, m.tets)


def test_housing_is_its_own_plastic_part_with_external_walls(coarse_mesh: ThermalMesh) -> None:
    from hevsim.thermal.mesh import EXTERNAL, tet_volumes_m3, triangle_areas_m2

    m, g = coarse_mesh, COARSE
    hi = m.part_names.index("housing")
    assert DEFAULT_PART_MATERIALS["housing"] == "plastic" and TABLE_4_3["plastic"].conductivity_w_mk == 0.2
    vol = tet_volumes_m3(m.points_m, m.tets)[m.part_of_tet == hi].sum()
    th, lx, ly = g.housing_thickness_m, g.length_x_m, g.length_y_m
    z0 = g.plate_thickness_m + g.holder_height_m
    z1 = g.plate_thickness_m + g.cell_height_m + g.connector_thickness_m
    exact = (lx * ly - (lx - 2 * th) * (ly - 2 * th)) * (z1 - z0)
    assert vol == pytest.approx(exact, rel=1e-9)  # straight walls: the mesh is exact
    # the four outer faces of the walls are in the convection (EXTERNAL) group
    ext = m.facet_groups[EXTERNAL]
    c = m.points_m[ext].mean(axis=1)
    band = (c[:, 2] > z0) & (c[:, 2] < z1)
    area = triangle_areas_m2(m.points_m, ext)
    for sel, side in (
        (np.abs(c[:, 0]) < 1e-12, ly),
        (np.abs(c[:, 0] - lx) < 1e-12, ly),
        (np.abs(c[:, 1]) < 1e-12, lx),
        (np.abs(c[:, 1] - ly) < 1e-12, lx),
    ):
        assert area[sel & band].sum() == pytest.approx(side * (z1 - z0), rel=1e-9)
    # the housing touches the holder and the cover (contact interfaces), not the cells
    mats = {p: TABLE_4_3[DEFAULT_PART_MATERIALS[p]] for p in m.part_names}
    disc = discretise(m, mats)
    assert disc.interfaces["holder|housing"] > 0 and disc.interfaces["cover|housing"] > 0
    assert "cells|housing" not in disc.interfaces
    with pytest.raises(Exception, match="housing_thickness_m"):
        ModuleGeometry(housing_thickness_m=0.005).check()


def _coupled(
    mesh: ThermalMesh, dt: float, contact: dict[str, float] | None = None
) -> tuple[HeatModel, ChannelModel]:
    wall = mesh.facet_groups[CHANNEL_WALL]
    assert mesh.channel_path_m is not None
    seg = segments_along_path(mesh.points_m[wall].mean(axis=1), mesh.channel_path_m, 12)
    seg = np.searchsorted(np.unique(seg), seg)
    mats = {p: TABLE_4_3[DEFAULT_PART_MATERIALS[p]] for p in mesh.part_names}
    disc = discretise(
        mesh,
        mats,
        film_w_m2k=10.0,
        ambient_k=298.15,
        wall_segment_of_facet=seg,
        interface_conductance_w_m2k=contact,
    )
    ch = ChannelModel(
        int(seg.max()) + 1, inlet_temp_k=288.15, flow_m3_s=10 / 60000, width_m=0.008, height_m=0.004
    )
    model = HeatModel(disc, dt_s=dt, initial_temp_k=303.15, coolant=ch, coupling_iterations=2)
    model.set_cell_heat_w(np.linspace(0.5, 2.0, 12))
    return model, ch


def test_steady_energy_balance_with_coolant(coarse_mesh: ThermalMesh) -> None:
    model, ch = _coupled(coarse_mesh, dt=1e7)
    for _ in range(15):
        model.step()
    rep = model.report()
    assert rep.heat_in_w == pytest.approx(15.0)
    assert abs(rep.heat_in_w - rep.wall_w - rep.film_w) / rep.heat_in_w < 0.005
    assert abs(ch.heat_w - rep.wall_w) / rep.heat_in_w < 0.005
    assert ch.outlet_temp_k > 288.15 and rep.film_w > 0.0


def test_contact_conductance_really_resists(coarse_mesh: ThermalMesh) -> None:
    hot = {}
    for h in (50.0, 20000.0):
        model, _ = _coupled(coarse_mesh, dt=1e7, contact={"cells|plate": h, "cells|holder": h})
        for _ in range(8):
            model.step()
        hot[h] = float(model.temp_k.max())
    assert hot[50.0] > hot[20000.0] + 0.5, hot  # cells (k = 0.2) dominate; contact still adds ~0.9 K


def test_run_thermal_end_to_end(tmp_path: Path) -> None:
    cfg = load_thermal_config(ROOT / "examples" / "module_thermal.toml")
    assert cfg.simulation.initial_temp_c == 30.0 and cfg.coolant.inlet_temp_c == 15.0
    small = thermal_config_from_dict(
        {
            "name": "t",
            "geometry": {"mesh_size_m": 0.01},
            "simulation": {"duration_s": 20.0, "dt_s": 2.0, "cell_heat_w": [2.0]},
            "output": {"field_every_s": 10.0, "hot_spots": 3},
        }
    )
    out = tmp_path / "res"
    res = run_thermal(small, out)
    assert res.metadata["factorisations"] == 1
    assert len(res.timeseries["time_s"]) == 11
    outlet = res.timeseries["outlet_temp_c"]  # plate starts at 30 °C and cools towards the inlet
    assert np.all(np.diff(outlet) < 1e-9) and np.all((outlet > 15.0) & (outlet < 30.0))
    assert len(res.hot_spots) == 3 and res.hot_spots[0]["temp_c"] >= res.hot_spots[1]["temp_c"]
    assert len(res.cell_stats) == 12 and set(res.part_stats) == {
        "plate",
        "holder",
        "cells",
        "connector",
        "cover",
        "bms",
        "housing",
    }
    assert res.metadata["materials"]["housing"]["name"] == "plastic"
    for name in (
        "timeseries.csv",
        "summary.json",
        "temperature.pvd",
        "cells_temperature.png",
        "plate_temperature.png",
        "timeseries.png",
    ):
        assert (out / name).is_file(), name
    assert len(list((out / "fields").glob("*.vtu"))) == 3
    summary = json.loads((out / "summary.json").read_text())
    assert summary["hot_spots"][0]["part"] in {"cells", "holder"}
    import meshio

    m = meshio.read(out / "fields" / "temperature_0002.vtu")
    assert np.allclose(m.point_data["temperature_c"].max(), res.metrics["module_max_temp_c"]["value"])
    assert not list(tmp_path.glob(".res*"))
    text = format_summary(res)
    assert "cell_max_temp_c" in text and "hot spots" in text and str(out) in text


def test_run_with_temperature_dependent_coolant(tmp_path: Path) -> None:
    res = {}
    for props in ("table_4_4", "meg50_table"):
        cfg = thermal_config_from_dict(
            {
                "name": props,
                "geometry": {"mesh_size_m": 0.01},
                "simulation": {"duration_s": 10.0, "dt_s": 2.0, "cell_heat_w": [2.0]},
                "coolant": {"properties": props},
                "output": {"field_every_s": 0.0, "hot_spots": 1, "pictures": 0},
            }
        )
        res[props] = run_thermal(cfg, None)
    tab, meg = res["table_4_4"], res["meg50_table"]
    assert meg.metrics["coolant_viscosity_pa_s"]["value"] == pytest.approx(2.326e-3)
    assert tab.metrics["coolant_viscosity_pa_s"]["value"] == 0.0085
    assert meg.metrics["reynolds"]["value"] > 3 * tab.metrics["reynolds"]["value"]
    assert meg.metrics["nusselt"]["value"] > 2 * tab.metrics["nusselt"]["value"]
    # better film: the 30 °C plate gives more heat at first (warmer outlet), more heat in total,
    # so the plate is cooler afterwards
    assert meg.timeseries["cooling_power_w"][1] > 1.5 * tab.timeseries["cooling_power_w"][1]
    assert meg.timeseries["outlet_temp_c"][1] > tab.timeseries["outlet_temp_c"][1]
    assert meg.metrics["heat_removed_j"]["value"] > tab.metrics["heat_removed_j"]["value"]
    assert meg.part_stats["plate"]["mean_temp_c"] < tab.part_stats["plate"]["mean_temp_c"]
    with pytest.raises(Exception, match="outside the MEG 50 table"):
        thermal_config_from_dict({"coolant": {"properties": "meg50_table", "inlet_temp_c": 60.0}})
    with pytest.raises(Exception, match="not a valid choice"):
        thermal_config_from_dict({"coolant": {"properties": "water"}})

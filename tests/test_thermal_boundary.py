"""Fixed boundary conditions from the configuration (issue 15, item 3): [[boundary]] tables
and --boundary give a film, a fixed temperature or a heat flux on a named surface."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("skfem")
pytest.importorskip("gmsh")

from hevsim.cli import main
from hevsim.errors import ConfigError
from hevsim.thermal.geometry import build_module_mesh
from hevsim.thermal.mesh import CHANNEL_WALL, EXTERNAL, triangle_areas_m2
from hevsim.thermal.run import (
    boundary_from_option,
    module_model,
    run_thermal,
    surface_nodes_and_load,
    thermal_config_from_dict,
)
from hevsim.thermal.solver import HeatModel, discretise

BASE = {
    "geometry": {"mesh_size_m": 0.01},
    "simulation": {"duration_s": 8.0, "dt_s": 2.0, "cell_heat_w": [2.0], "film_w_m2k": 0.0},
    "output": {"field_every_s": 0.0, "pictures": 0},
}


def _cfg(boundary: list[dict[str, Any]], **sim: Any) -> Any:
    data = {**BASE, "simulation": {**BASE["simulation"], **sim}, "boundary": boundary}
    return thermal_config_from_dict(data, "bc.toml")


def _v(res: Any, key: str) -> float:
    return float(res.metrics[key]["value"])


@pytest.mark.parametrize(
    ("boundary", "match"),
    [
        (
            [{"surface": "TOP", "kind": "film"}],
            r"'boundary\[1\].surface' = 'TOP'; expected one of INTERFACE, EXTERNAL",
        ),
        ([{"surface": "EXTERNAL", "kind": "dirichlet"}], "expected one of film, temperature, heat_flux"),
        ([{"surface": "EXTERNAL", "kind": "film", "film_w_m2k": 5.0}], r"\(EXTERNAL, film\) has no temp_c"),
        (
            [{"surface": "EXTERNAL", "kind": "temperature", "temp_c": 20.0, "h": 1.0}],
            r"'boundary\[1\].h' is not known",
        ),
        ([{"surface": "EXTERNAL", "kind": "heat_flux", "heat_flux_w_m2": "x"}], "heat_flux_w_m2"),
        ([{"surface": "EXTERNAL", "kind": "film", "film_w_m2k": -1.0, "temp_c": 20.0}], "film_w_m2k"),
        (
            [{"surface": "EXTERNAL", "kind": "temperature", "temp_c": 20.0}] * 2,
            "'EXTERNAL' has a second",
        ),
    ],
)
def test_bad_boundary_tables(boundary: list[dict[str, Any]], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        _cfg(boundary)


def test_boundary_option_parsing() -> None:
    assert boundary_from_option("INTERFACE:film:film_w_m2k=4600,temp_c=15") == {
        "surface": "INTERFACE",
        "kind": "film",
        "film_w_m2k": 4600.0,
        "temp_c": 15.0,
    }
    for bad in ("INTERFACE:film", "INTERFACE:film:h", "INTERFACE:film:h=x"):
        with pytest.raises(ConfigError, match="--boundary"):
            boundary_from_option(bad)


def test_fixed_coolant_film_on_the_channel_wall_equals_a_plain_surface_film() -> None:
    cfg = _cfg([{"surface": "INTERFACE", "kind": "film", "film_w_m2k": 3000.0, "temp_c": 15.0}])
    mesh = build_module_mesh(cfg.geometry)
    _, coolant, model = module_model(cfg, mesh)
    assert not hasattr(coolant, "reynolds")  # no 1-D channel
    model.set_cell_heat_w(2.0, from_now=True)
    ref_disc = discretise(mesh, cfg.materials, film_w_m2k=0.0, surface_films={CHANNEL_WALL: (3000.0, 288.15)})
    ref = HeatModel(ref_disc, dt_s=2.0, initial_temp_k=303.15)
    ref.set_cell_heat_w(2.0)
    for _ in range(4):
        model.step()
        ref.step()
    scale = np.abs(ref.temp_k - 303.15).max()
    assert scale > 1.0
    assert np.abs(model.temp_k - ref.temp_k).max() <= 1e-9 * scale
    res = run_thermal(cfg, None)
    assert "reynolds" not in res.metrics
    assert abs(_v(res, "energy_balance_relative")) <= 1e-9
    wall = model.report().wall_w
    assert res.timeseries["wall_heat_w"][-1] == pytest.approx(wall, rel=1e-9)
    assert res.timeseries["cooling_power_w"][-1] == pytest.approx(wall, rel=1e-12)


def test_heat_fluxes_are_applied_exactly() -> None:
    q_ext, q_wall = 50.0, -2000.0  # [W/m^2] into the solid (the wall draws heat out)
    cfg = _cfg(
        [
            {"surface": "EXTERNAL", "kind": "heat_flux", "heat_flux_w_m2": q_ext},
            {"surface": "INTERFACE", "kind": "heat_flux", "heat_flux_w_m2": q_wall},
        ],
        cell_heat_w=[0.0],
    )
    res = run_thermal(cfg, None)
    mesh = build_module_mesh(cfg.geometry)
    disc, _, _ = module_model(cfg, mesh)
    a_ext = float(surface_nodes_and_load(mesh, disc, EXTERNAL)[1].sum())
    a_wall = float(disc.wall_area_m2.sum())
    ext_area = triangle_areas_m2(mesh.points_m, mesh.facet_groups[EXTERNAL]).sum()
    assert a_ext == pytest.approx(ext_area, rel=1e-12)  # EXTERNAL is all on the boundary
    assert _v(res, "heat_to_ambient_j") == pytest.approx(-q_ext * a_ext * 8.0, rel=1e-9)
    assert _v(res, "heat_removed_j") == pytest.approx(-q_wall * a_wall * 8.0, rel=1e-12)
    assert abs(_v(res, "energy_balance_relative")) <= 1e-9


def test_fixed_temperature_holds_the_surface(tmp_path: Path) -> None:
    cfg = _cfg(
        [{"surface": "INTERFACE", "kind": "temperature", "temp_c": 15.0}],
        duration_s=20.0,
        dt_s=5.0,
    )
    res = run_thermal(cfg, None)
    dev = _v(res, "boundary_INTERFACE_max_deviation_k")
    assert dev < 1e-4  # 15 K below the module: held to ~1e-6 of the drop
    assert _v(res, "heat_removed_j") > 100.0
    assert abs(_v(res, "energy_balance_relative")) <= 1e-9
    # the same case from the command line
    toml = tmp_path / "bc.toml"
    toml.write_text(
        "[geometry]\nmesh_size_m = 0.01\n[simulation]\nduration_s = 20.0\ndt_s = 5.0\ncell_heat_w = [2.0]\n"
        "film_w_m2k = 0.0\n[output]\nfield_every_s = 0.0\npictures = 0\n"
    )
    out = tmp_path / "out"
    assert (
        main(["thermal", str(toml), "--out", str(out), "--boundary", "INTERFACE:temperature:temp_c=15"]) == 0
    )
    summary = json.loads((out / "summary.json").read_text())
    assert summary["metadata"]["boundary"] == [dataclasses.asdict(cfg.boundary[0])]
    assert summary["metrics"]["heat_removed_j"]["value"] == pytest.approx(_v(res, "heat_removed_j"), rel=1e-9)
    assert main(["thermal", str(toml), "--out", str(tmp_path / "o2"), "--boundary", "TOP:film:h=1"]) == 2

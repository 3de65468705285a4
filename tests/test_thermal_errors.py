"""Bad input to the thermal model fails early with a clear message (issue 5, item 8)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("skfem")

from hevsim.errors import ConfigError, HevsimError, InputError
from hevsim.thermal.materials import Material
from hevsim.thermal.mesh import ThermalMesh
from hevsim.thermal.run import load_thermal_config, run_thermal, thermal_config_from_dict
from hevsim.thermal.solver import HeatModel, discretise

P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float) * 0.01
GOOD = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
AL = Material("al", 167.0, 2700.0, 902.0)


def tmesh(
    tets: np.ndarray, parts: tuple[str, ...] = ("a",), part: np.ndarray | None = None, points: np.ndarray = P
) -> ThermalMesh:
    part_of = np.zeros(len(tets), dtype=int) if part is None else part
    return ThermalMesh(points, tets, part_of, parts, np.zeros(len(tets), dtype=int), source="bad.msh")


def fix(t: np.ndarray) -> np.ndarray:
    from hevsim.thermal.mesh import tet_volumes_m3

    t = t.copy()
    v = tet_volumes_m3(P, t)
    t[v < 0] = t[v < 0][:, [1, 0, 2, 3]]
    return t


def test_inverted_element() -> None:
    t = fix(GOOD)
    t[1] = t[1][[1, 0, 2, 3]]
    with pytest.raises(InputError, match=r"bad.msh: 1 inverted tetrahedra .* element 1"):
        tmesh(t).validate()


def test_degenerate_element() -> None:
    pts = np.vstack([P, [[0.005, 0.005, 0.0]]])
    t = np.vstack([fix(GOOD), [[0, 1, 2, 5]]])
    with pytest.raises(InputError, match="degenerate"):
        tmesh(t, points=pts).validate()


def test_node_index_out_of_range() -> None:
    with pytest.raises(InputError, match="out of range"):
        tmesh(np.array([[0, 1, 2, 9]])).validate()


def test_missing_named_interface() -> None:
    m = tmesh(fix(GOOD), ("a", "b"), np.array([0, 1]))
    with pytest.raises(ConfigError, match=r"contact interface 'a\|c' does not exist.*'a\|b'"):
        discretise(m, {"a": AL, "b": AL}, interface_conductance_w_m2k={"a|c": 100.0})


def test_missing_film_surface() -> None:
    with pytest.raises(ConfigError, match="film surface 'LEFT'"):
        discretise(tmesh(fix(GOOD)), {"a": AL}, surface_films={"LEFT": (10.0, 300.0)})


def test_part_without_material() -> None:
    m = tmesh(fix(GOOD), ("a", "b"), np.array([0, 1]))
    with pytest.raises(ConfigError, match="part 'b' has no material properties"):
        discretise(m, {"a": AL})


@pytest.mark.parametrize("bad", [Material("x", -1.0, 1.0, 1.0), Material("x", 1.0, float("nan"), 1.0)])
def test_non_physical_material(bad: Material) -> None:
    with pytest.raises(ConfigError, match="not physical"):
        discretise(tmesh(fix(GOOD)), {"a": bad})


def test_non_physical_solver_values() -> None:
    disc = discretise(tmesh(fix(GOOD)), {"a": AL})
    with pytest.raises(ConfigError, match="dt_s"):
        HeatModel(disc, dt_s=0.0)
    with pytest.raises(ConfigError, match="theta"):
        HeatModel(disc, dt_s=1.0, theta=0.2)
    with pytest.raises(ConfigError, match="initial temperature"):
        HeatModel(disc, dt_s=1.0, initial_temp_k=-5.0)


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"simulation": {"dt_s": -1.0}}, r"key 'simulation.dt_s' = -1.0 is out of range"),
        ({"coolant": {"flow_l_min": 0.0}}, r"coolant.flow_l_min"),
        ({"simulation": {"bogus": 1.0}}, r"'simulation.bogus' is not known"),
        ({"materials": {"bms": {"material": "unobtainium"}}}, r"materials.bms.material.*expected one of"),
        ({"materials": {"plate": {"conductivity_w_mk": 0.0}}}, r"materials.plate.*not physical"),
        ({"materials": {"wing": {"conductivity_w_mk": 1.0}}}, r"'materials.wing' is not a part"),
        ({"geometry": {"cell_diameter_m": 0.03}}, r"cell_diameter_m"),
        ({"geometry": {"channel_height_m": 0.0079}}, r"channel_height_m"),
    ],
)
def test_bad_config_values(data: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        thermal_config_from_dict(data, "case.toml")


def test_missing_interface_in_config_run_leaves_no_folder(tmp_path: Path) -> None:
    pytest.importorskip("gmsh")
    cfg_file = tmp_path / "case.toml"
    cfg_file.write_text(
        '[geometry]\nmesh_size_m = 0.012\n[simulation]\nduration_s = 2.0\n[contact]\n"cells|wing" = 10.0\n'
    )
    with pytest.raises(HevsimError, match=r"'cells\|wing' does not exist"):
        run_thermal(cfg_file, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    with pytest.raises(ConfigError, match="not found"):
        load_thermal_config(tmp_path / "nope.toml")

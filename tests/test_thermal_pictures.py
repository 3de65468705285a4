"""Field pictures of the module thermal model (hevsim.thermal.pictures) on a coarse mesh."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("skfem")
pytest.importorskip("gmsh")
pytest.importorskip("matplotlib")

from hevsim.errors import InputError
from hevsim.thermal.geometry import build_module_mesh
from hevsim.thermal.pictures import (
    cell_temperatures_c,
    plot_cells_section,
    plot_cells_top,
    plot_fields,
    plot_plate,
    raster_triangles,
    section_hot_points,
    section_y,
)
from hevsim.thermal.run import load_thermal_config, module_model, run_thermal

ROOT = Path(__file__).resolve().parents[1]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
FIELD_NAMES = ("cells_temperature.png", "plate_temperature.png", "cells_section.png")


@pytest.fixture(scope="module")
def case() -> tuple[Any, Any, Any, Any]:
    cfg = load_thermal_config(ROOT / "examples" / "module_thermal.toml")
    cfg = dataclasses.replace(cfg, geometry=dataclasses.replace(cfg.geometry, mesh_size_m=0.008))
    mesh = build_module_mesh(cfg.geometry)
    disc, _, _ = module_model(cfg, mesh)
    return cfg, mesh, disc, cfg.geometry


def _field(disc: Any) -> np.ndarray:
    """Smooth synthetic field [°C]: warm at the top, a little warmer towards large x."""
    p = disc.points_m
    return 15.0 + 250.0 * p[:, 2] + 10.0 * p[:, 0]


def _assert_png(path: Path, min_bytes: int = 20_000) -> None:
    from PIL import Image

    assert path.is_file(), path
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC, path
    assert len(data) > min_bytes, (path, len(data))
    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        w, h = im.size
    assert 500 <= w <= 4000 and 250 <= h <= 4000, (path, w, h)


def test_plot_fields_writes_three_pngs(case: tuple[Any, Any, Any, Any], tmp_path: Path) -> None:
    _, mesh, disc, geom = case
    out = plot_fields(mesh, disc, geom, _field(disc), 12.5, tmp_path / "new" / "dir", prefix="fem_")
    assert [p.name for p in out] == [f"fem_{n}" for n in FIELD_NAMES]
    for p in out:
        assert p.parent == tmp_path / "new" / "dir"
        _assert_png(p)


@pytest.mark.parametrize("func", [plot_cells_top, plot_plate, plot_cells_section])
def test_each_plot_returns_its_path(case: tuple[Any, Any, Any, Any], tmp_path: Path, func: Any) -> None:
    _, mesh, disc, geom = case
    path = tmp_path / f"{func.__name__}.png"
    assert func(mesh, disc, geom, _field(disc), 0.0, path) == path
    _assert_png(path)


@pytest.mark.parametrize("func", [plot_cells_top, plot_plate, plot_cells_section, plot_fields])
def test_wrong_field_length_is_an_input_error(
    case: tuple[Any, Any, Any, Any], tmp_path: Path, func: Any
) -> None:
    _, mesh, disc, geom = case
    n = disc.points_m.shape[0]
    short = np.full(mesh.points_m.shape[0], 20.0)  # the unsplit mesh has fewer nodes
    assert short.size != n
    with pytest.raises(InputError, match=rf"shape \({short.size},\); expected shape \({n},\)"):
        func(mesh, disc, geom, short, 0.0, tmp_path / "x.png")
    with pytest.raises(InputError, match="one temperature"):
        func(mesh, disc, geom, np.zeros((n, 1)), 0.0, tmp_path / "x.png")
    bad = np.full(n, 20.0)
    bad[3] = np.nan
    with pytest.raises(InputError, match="NaN"):
        func(mesh, disc, geom, bad, 0.0, tmp_path / "x.png")
    assert not list(tmp_path.iterdir())
    with pytest.raises(InputError, match=rf"expected shape \({n},\)"):
        section_hot_points(mesh, disc, geom, short)


def test_section_hot_point_is_at_the_top_of_the_cells_for_t_equal_z(case: tuple[Any, Any, Any, Any]) -> None:
    _, mesh, disc, geom = case
    temp = 1000.0 * disc.points_m[:, 2]  # [°C] = z [mm]
    top = geom.plate_thickness_m + geom.cell_height_m
    hot = section_hot_points(mesh, disc, geom, temp)
    assert [h["row"] for h in hot] == list(range(1, geom.rows + 1))
    r = geom.cell_diameter_m / 2
    for h in hot:
        assert h["part"] == "cells"
        assert h["z_m"] == pytest.approx(top, abs=1e-9)
        assert h["temp_c"] == pytest.approx(1000.0 * top, abs=1e-6)
        y_row = geom.cell_centre_xy_m(h["row"] - 1, 0)[1]
        assert h["y_m"] == pytest.approx(y_row)
        centres = np.array([geom.cell_centre_xy_m(h["row"] - 1, c)[0] for c in range(geom.columns)])
        assert np.min(np.abs(centres - h["x_m"])) <= r + 1e-9  # inside a cell of this row
    # any part: the top of the section (BMS board on the cover), above the cells
    anywhere = section_hot_points(mesh, disc, geom, temp, part=None)
    z_top = (
        top + geom.connector_thickness_m + geom.cover_thickness_m + geom.bms_thickness_m
    )  # the BMS board spans both rows' centre lines
    for h in anywhere:
        assert h["part"] == "bms" and h["z_m"] == pytest.approx(z_top, abs=1e-9)
    with pytest.raises(InputError, match="not in the mesh"):
        section_hot_points(mesh, disc, geom, temp, part="fluid")


def test_section_is_an_exact_cut_of_the_linear_field(case: tuple[Any, Any, Any, Any]) -> None:
    _, mesh, disc, geom = case
    p = disc.points_m
    temp = 3.0 + 40.0 * p[:, 0] - 70.0 * p[:, 1] + 110.0 * p[:, 2]
    y = geom.cell_centre_xy_m(0, 0)[1]
    sec = section_y(mesh, disc, temp, y)
    assert sec.triangles.shape[0] > 100 and sec.outline.shape[0] > 50
    expect = 3.0 + 40.0 * sec.x_m - 70.0 * y + 110.0 * sec.z_m
    assert np.allclose(sec.temp_c, expect, atol=1e-6)
    # every triangle of the cut lies in the module and has one part
    assert sec.x_m.min() >= -1e-12 and sec.x_m.max() <= geom.length_x_m + 1e-12
    assert np.all(sec.part[sec.triangles].min(axis=1) == sec.part[sec.triangles].max(axis=1))
    # solid area in the plane: module box minus channel, air between cells and the BMS margins
    a = sec.x_m[sec.triangles]
    b = sec.z_m[sec.triangles]
    area = 0.5 * np.abs((a[:, 1] - a[:, 0]) * (b[:, 2] - b[:, 0]) - (a[:, 2] - a[:, 0]) * (b[:, 1] - b[:, 0]))
    z_cover = (
        geom.plate_thickness_m + geom.cell_height_m + geom.connector_thickness_m + geom.cover_thickness_m
    )
    assert 0.6 * geom.length_x_m * z_cover < area.sum() < geom.length_x_m * z_cover
    # the raster of the cut reproduces the linear field at the pixel centres it covers
    corners = np.stack([sec.x_m, sec.z_m], axis=1)[sec.triangles]
    extent = (0.0, geom.length_x_m, 0.0, z_cover)
    img = raster_triangles(corners, sec.temp_c[sec.triangles], extent, (60, 120))
    xs = (np.arange(120) + 0.5) * geom.length_x_m / 120
    zs = (np.arange(60) + 0.5) * z_cover / 60
    ref = 3.0 + 40.0 * xs[None, :] - 70.0 * y + 110.0 * zs[:, None]
    ok = np.isfinite(img)
    assert 0.6 < ok.mean() < 0.98  # holes: channel and air gaps between the cells
    assert np.allclose(img[ok], ref[ok], atol=1e-6)


def test_cell_temperatures_find_the_hot_cell(case: tuple[Any, Any, Any, Any]) -> None:
    _, mesh, disc, geom = case
    temp = 1000.0 * disc.points_m[:, 2]
    in_cell = mesh.cell_of_tet >= 0
    hot_cell = 7
    hot_nodes = np.unique(disc.tets[mesh.cell_of_tet == hot_cell])
    temp[hot_nodes] += 5.0
    mean, peak = cell_temperatures_c(mesh, disc, temp)
    assert mean.shape == peak.shape == (geom.rows * geom.columns,)
    assert int(np.argmax(mean)) == hot_cell
    mid = 1000.0 * (geom.plate_thickness_m + geom.cell_height_m / 2)
    others = np.delete(mean, hot_cell)
    assert np.allclose(others, mid, atol=0.5)  # centroid of a cylinder, nodal quadrature
    assert np.allclose(np.delete(peak, hot_cell), 1000.0 * (geom.plate_thickness_m + geom.cell_height_m))
    assert in_cell.any()


def test_run_thermal_writes_the_field_pictures(tmp_path: Path) -> None:
    cfg = load_thermal_config(ROOT / "examples" / "module_thermal.toml")
    cfg = dataclasses.replace(
        cfg,
        geometry=dataclasses.replace(cfg.geometry, mesh_size_m=0.008),
        simulation=dataclasses.replace(cfg.simulation, duration_s=20.0, dt_s=10.0, cell_heat_w=(3.0,)),
        output=dataclasses.replace(cfg.output, field_every_s=0.0, pictures=1),
    )
    out = tmp_path / "res"
    run_thermal(cfg, out)
    for name in (*FIELD_NAMES, "timeseries.png"):
        _assert_png(out / name, min_bytes=10_000)


def test_write_field_series_with_prefix(case: tuple[Any, Any, Any, Any], tmp_path: Path) -> None:
    import meshio

    from hevsim.thermal.run import write_field_series

    _, mesh, disc, _ = case
    series = [(0.0, _field(disc)), (30.0, _field(disc) + 1.0)]
    pvd = write_field_series(tmp_path, disc, mesh, series, prefix="fem_")
    assert pvd == tmp_path / "fem_temperature.pvd"
    text = pvd.read_text()
    assert 'timestep="30" part="0" file="fields/fem_temperature_0001.vtu"' in text
    m = meshio.read(tmp_path / "fields" / "fem_temperature_0001.vtu")
    assert np.allclose(m.point_data["temperature_c"], series[1][1])
    assert set(m.cell_data) == {"part", "cell"}

"""Turbulent coolant flow through OpenFOAM (issue 19, hevsim.thermal.rans).

References: H. Blasius, Forschungsarbeiten VDI 131 (1913): Darcy friction factor of smooth
ducts f = 0.316 Re^-0.25 (Re 4e3..1e5); V. Gnielinski, Int. Chem. Eng. 16 (1976) 359-368:
Nu = (f/8)(Re - 1000) Pr / (1 + 12.7 (f/8)^0.5 (Pr^(2/3) - 1)) with f = (0.79 ln Re - 1.64)^-2.
Both for circular pipes, applied to the 8 x 4 mm duct on its hydraulic diameter (for aspect
1/2, Jones' laminar-equivalent diameter differs from D_h by 1 %).

The tests that run OpenFOAM (marked slow) skip when it is not installed (``make test`` installs it first,
``make openfoam``); the "OpenFOAM missing" tests run everywhere.
"""

from __future__ import annotations

import json
import math
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest

from hevsim.errors import ConfigError
from hevsim.thermal import rans
from hevsim.thermal.coolant import Coolant
from hevsim.thermal.flow import (
    FlowConfig,
    FlowSection,
    config_channel,
    duct_channel,
    plate_channel,
    solve_flow,
)
from hevsim.thermal.geometry import ModuleGeometry

ROOT = Path(__file__).resolve().parents[1]
MODULE_TOML = ROOT / "examples" / "module_thermal.toml"


def _have_openfoam() -> bool:
    try:
        rans.find_openfoam()
    except ConfigError:
        return False
    return True


needs_openfoam = pytest.mark.skipif(not _have_openfoam(), reason="OpenFOAM not installed (make openfoam)")

#: Water at 50 degC (handbook values, e.g. F. P. Incropera et al., Fundamentals of Heat and Mass
#: Transfer, Table A.6): Pr 3.56, inside Gnielinski's range and with a conduction sublayer the
#: graded P2 mesh resolves; the shipped glycol's Pr 65 needs a far finer wall mesh.
WATER_50C = Coolant(
    conductivity_w_mk=0.643, density_kg_m3=988.0, viscosity_pa_s=5.47e-4, specific_heat_j_kgk=4181.0
)
RE_DUCT = 6000.0
DUCT_LENGTH_M = 0.12  # 22.5 D_h


# --------------------------------------------------------------------------- no OpenFOAM needed
def test_graded_axis_starts_at_the_wall_cell_grows_by_the_ratio_and_keeps_the_breaks() -> None:
    nodes = rans.graded_axis([0.0, 0.004, 0.01], [True, False, True], 5e-4, 2e-5, 1.3)
    assert nodes[0] == 0.0 and nodes[-1] == pytest.approx(0.01)
    assert np.any(np.isclose(nodes, 0.004, rtol=0, atol=1e-15))
    d = np.diff(nodes)
    assert d[0] == pytest.approx(2e-5, rel=0.05) and d[-1] == pytest.approx(2e-5, rel=0.05)
    assert d.max() <= 5e-4 * 1.0001
    grow = d[1:] / d[:-1]
    assert np.all((grow < 1.3 * 1.06) & (grow > 1 / (1.3 * 1.06)))
    # no wall at 0.004 (a break only): the cells meet there at full size
    i = int(np.argmin(np.abs(nodes - 0.004)))
    assert d[i - 1] > 2e-4 and d[i] > 2e-4


def test_wall_planes_of_the_serpentine_exclude_the_inlet_and_outlet_planes() -> None:
    flags = rans.wall_planes(plate_channel(ModuleGeometry()))
    assert flags[0][0] is False and flags[0][-1] is False  # x = 0 (inlet), x = 128 mm (outlet)
    assert all(flags[0][1:-1]) and all(flags[1]) and all(flags[2])


def test_grid_field_reproduces_a_linear_field_and_applies_boundary_values() -> None:
    ch = duct_channel(0.01, 0.008, 0.004)
    grid = rans.channel_grid(ch, 8, 4, 0.0025)  # uniform 2.5 x 1 x 1 mm: vertex means are exact inside
    c = grid.centres()
    lin = 3.0 + 2.0 * c[:, 0] - 5.0 * c[:, 1] + 7.0 * c[:, 2]
    field = rans.GridField.from_cells(grid, lin)
    rng = np.random.default_rng(1)
    pts = rng.uniform([0.0025, 0.001, 0.001], [0.0075, 0.007, 0.003], size=(200, 3))  # hexes off the walls
    expect = 3.0 + 2.0 * pts[:, 0] - 5.0 * pts[:, 1] + 7.0 * pts[:, 2]
    assert np.allclose(field.at(pts)[:, 0], expect, rtol=0, atol=1e-12)
    wall, inlet = rans.boundary_points(grid, ch)
    zero = rans.GridField.from_cells(grid, lin, [(wall, np.zeros(1))])
    on_wall = np.array([[0.005, 0.0, 0.001], [0.005, 0.008, 0.0013], [0.002, 0.001, 0.0]])
    assert np.allclose(zero.at(on_wall), 0.0)
    assert inlet.sum() == (9 - 2) * (5 - 2)  # inlet vertices off the walls: 7 x 3
    with pytest.raises(Exception, match="outside the channel"):
        field.at(np.array([[0.005, 0.009, 0.001]]))


def _no_openfoam(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    empty = tmp_path / "empty_bin"
    empty.mkdir()
    monkeypatch.setenv("PATH", str(empty))
    monkeypatch.delenv(rans.OPENFOAM_ENV, raising=False)
    monkeypatch.delenv("WM_PROJECT_DIR", raising=False)
    monkeypatch.setattr(rans, "KNOWN_BASHRC", ())


def test_openfoam_missing_exits_2_naming_what_to_install_and_writes_nothing(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from hevsim.cli import main

    _no_openfoam(monkeypatch, tmp_path)
    out = tmp_path / "res"
    assert main(["flow", str(MODULE_TOML), "--out", str(out)]) == 2  # 10 L/min: Re 3451 -> RANS
    err = capsys.readouterr().err
    assert "simpleFoam" in err and "apt-get install openfoam" in err and "openfoam.com" in err
    assert not out.exists()


def test_hevsim_openfoam_pointing_nowhere_is_an_error(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    _no_openfoam(monkeypatch, tmp_path)
    monkeypatch.setenv(rans.OPENFOAM_ENV, str(tmp_path))
    with pytest.raises(rans.OpenFoamMissingError, match=r"HEVSIM_OPENFOAM=.*no etc/bashrc"):
        rans.find_openfoam()


def test_debian_layout_is_found_from_path_alone(tmp_path: Path) -> None:
    """``/usr/bin/simpleFoam`` + ``/usr/share/openfoam/etc`` (the Debian package) without a
    sourced environment: hevsim sets WM_PROJECT_DIR itself."""
    if not (
        Path(rans.DEBIAN_PROJECT_DIR, "etc", "controlDict").is_file() and Path("/usr/bin/simpleFoam").exists()
    ):
        pytest.skip("Debian's openfoam package is not installed")
    of = rans.find_openfoam({"PATH": "/usr/bin:/bin"}, known_bashrc=())
    assert of.env["WM_PROJECT_DIR"] == rans.DEBIAN_PROJECT_DIR and of.which("simpleFoam")


# --------------------------------------------------------------------------- OpenFOAM
@needs_openfoam
def test_plate_case_mesh_passes_checkmesh_with_the_channel_volume_and_port_areas(tmp_path: Path) -> None:
    g = ModuleGeometry()
    ch = plate_channel(g)
    grid = rans.channel_grid(ch, 6, 3, 0.004, 3e-4, 1.4)
    rc = rans.RansCase((1.0, 0.0, 0.0), 8e-6, 0.01, 100.0, 0.0, 10, 1e-4, 1)
    counts = rans.write_case(tmp_path, grid, ch, rc)
    of = rans.find_openfoam()
    exe = of.which("checkMesh")
    assert exe is not None
    out = subprocess.run([exe], cwd=tmp_path, env=of.env, capture_output=True, text=True, check=False).stdout
    assert "Mesh OK." in out, out[-3000:]
    assert f"cells:            {counts['cells']}" in out
    vol = float(out.split("Total volume = ")[1].split(".  ")[0])
    boxes = g.channel_boxes_m()
    # the union of the boxes: the tensor cells inside (exact for axis-aligned boxes)
    expected = sum((b[1] - b[0]) * (b[3] - b[2]) * (b[5] - b[4]) for b in boxes)
    overlap = expected - vol
    assert vol > 0 and 0 <= overlap < 0.2 * expected
    _cells, a_in = rans._port_cells(grid, ch.inlet)
    assert a_in.sum() == pytest.approx(g.channel_width_m * g.channel_height_m, rel=1e-12)


@pytest.fixture(scope="module")
def duct_rans() -> tuple[FlowConfig, object]:
    if not _have_openfoam():
        pytest.skip("OpenFOAM not installed (make openfoam)")
    c = WATER_50C
    w, h = 0.008, 0.004
    dh = 2 * w * h / (w + h)
    q = RE_DUCT * c.viscosity_pa_s / c.density_kg_m3 / dh * w * h
    sec = FlowSection(
        channel="duct",
        duct_length_m=DUCT_LENGTH_M,
        model="rans",
        rans_cells_across_width=16,
        rans_cells_across_height=8,
        rans_cell_length_m=0.006,
        rans_wall_cell_m=3e-5,
        growth=1.3,
        rans_tolerance=1e-5,
        cells_across_width=4,
        cells_across_height=2,
        cell_length_m=0.012,
        wall_cell_m=5e-5,
    )
    cfg = FlowConfig("duct", ModuleGeometry(), c, q, sec, inlet_temp_c=15.0, segments=10)
    res = solve_flow(config_channel(cfg), c, q, section=sec, where="duct")
    return cfg, res


@pytest.mark.slow  # OpenFOAM solve (the duct fixture: ~15 s CPU)
@needs_openfoam
def test_turbulent_duct_friction_factor_against_blasius(duct_rans: tuple[FlowConfig, object]) -> None:
    cfg, res = duct_rans
    m = res.metrics  # type: ignore[attr-defined]
    assert m["converged"] == 1.0 and m["reynolds"] == pytest.approx(RE_DUCT)
    assert m["mass_imbalance_rel"] < 1e-3
    assert 0.05 < m["yplus_mean"] < 2.0  # the wall cell resolves the viscous sublayer
    r = res.rans  # type: ignore[attr-defined]
    g = r.grid
    xs = (g.nodes[0][1:] + g.nodes[0][:-1]) / 2
    i = np.nonzero(g.inside)[0]
    vol = np.einsum("i,j,k->ijk", *[np.diff(n) for n in g.nodes])[g.inside]
    p_mean = np.array([np.average(r.pressure_pa[i == k], weights=vol[i == k]) for k in range(len(xs))])
    developed = (xs > 0.5 * DUCT_LENGTH_M) & (xs < 0.9 * DUCT_LENGTH_M)
    gradient = -np.polyfit(xs[developed], p_mean[developed], 1)[0]
    u, dh = m["mean_velocity_mps"], m["hydraulic_diameter_m"]
    f = gradient * dh / (0.5 * cfg.coolant.density_kg_m3 * u**2)
    blasius = 0.316 * RE_DUCT**-0.25
    assert f == pytest.approx(blasius, rel=0.15), (f, blasius)
    # laminar flow at this Re would give f = 62.2 / Re (Shah & London, aspect 1/2): 4x lower
    assert f > 2.5 * 62.2 / RE_DUCT


@pytest.mark.slow  # OpenFOAM solve (the duct fixture: ~15 s CPU)
@needs_openfoam
def test_turbulent_duct_nusselt_on_the_frozen_rans_flow_against_gnielinski(
    duct_rans: tuple[FlowConfig, object], duct_resolved_cht: object
) -> None:
    from hevsim.thermal.cht import run_cht

    cfg, res = duct_rans
    gnielinski = _gnielinski(cfg.coolant.prandtl)
    cht = duct_resolved_cht
    assert cht.metrics["wall_function"] == 0.0  # type: ignore[attr-defined]  # auto: cells resolve it
    # the read-back velocity is projected to be discretely divergence-free: exact energy balance
    assert cht.metrics["energy_imbalance_rel"] < 1e-6  # type: ignore[attr-defined]
    assert cht.metrics["heat_w"] > 0  # type: ignore[attr-defined]
    nu = cht.segments["nusselt"]  # type: ignore[attr-defined]
    developed = float(np.mean(nu[-4:]))  # x = 72-120 mm, 13-22 D_h
    assert developed == pytest.approx(gnielinski, rel=0.15), (nu, gnielinski)
    assert nu[0] > developed  # thermal entry
    # without the eddy diffusivity the same velocity field transfers far less heat
    eddy = res.eddy_diffusivity_m2_s  # type: ignore[attr-defined]
    res.eddy_diffusivity_m2_s = np.zeros_like(eddy)  # type: ignore[attr-defined]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            molecular = run_cht(cfg, res)  # type: ignore[arg-type]
    finally:
        res.eddy_diffusivity_m2_s = eddy  # type: ignore[attr-defined]
    assert float(np.mean(molecular.segments["nusselt"][-4:])) < 0.6 * developed


@pytest.mark.slow  # OpenFOAM solve (the duct fixture: ~15 s CPU)
@needs_openfoam
def test_cli_flow_at_the_shipped_10_l_min_runs_rans_and_keeps_the_case(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The shipped module TOML (Re 3451, model auto) through the RANS path, on a deliberately
    coarse OpenFOAM grid and few iterations (the full solve is benchmarks/bench_flow.py --rans)."""
    from hevsim.cli import main

    cfg = tmp_path / "module.toml"
    cfg.write_text(
        MODULE_TOML.read_text() + "\n[flow]\nrans_cells_across_width = 3\nrans_cells_across_height = 2\n"
        "rans_cell_length_m = 0.008\nrans_wall_cell_m = 0.0\nrans_iterations = 15\n"
    )
    out = tmp_path / "res"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # not converged in 15 iterations; wall node on the centre line
        assert main(["flow", str(cfg), "--thermal", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "RANS k-omega SST" in text and "y+" in text and "Re = 3451" in text
    assert "thermal wall function: y+ of the wall cells" in text
    summary = json.loads((out / "summary.json").read_text())
    assert summary["metadata"]["model"] == "rans"
    assert summary["metrics"]["iterations"] == 15 and summary["metrics"]["pressure_drop_pa"] > 0
    assert (out / "openfoam" / "log.simpleFoam").is_file()
    assert (out / "openfoam" / "constant" / "polyMesh" / "faces").is_file()
    assert (out / "openfoam" / "15" / "U").is_file()
    # the coolant heat transfer at 10 L/min: the wall function on the default coolant mesh
    cht = json.loads((out / "cht_summary.json").read_text())["metrics"]
    assert cht["wall_function"] == 1.0 and cht["energy_imbalance_rel"] < 1e-6 and cht["heat_w"] > 0
    for name in ("cht_segments.csv", "nusselt.png", "temperature.vtu", "coolant_temperature.png", "flow.vtu"):
        assert (out / name).is_file(), name
    # the kept case reads back without OpenFOAM to the same flow
    from hevsim.thermal.flow import load_flow_config

    fc = load_flow_config(cfg)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again = rans.read_rans_case(
            out / "openfoam", config_channel(fc), fc.coolant, fc.flow_m3_s, section=fc.flow
        )
    assert again.metrics["pressure_drop_pa"] == pytest.approx(
        summary["metrics"]["pressure_drop_pa"], rel=1e-12
    )
    assert again.metrics["elements"] == summary["metrics"]["elements"]


@pytest.mark.slow  # OpenFOAM solve (the duct fixture: ~15 s CPU)
@needs_openfoam
def test_coarse_fem_wall_cells_on_a_turbulent_flow_are_refused_with_the_needed_size(
    duct_rans: tuple[FlowConfig, object],
) -> None:
    from types import SimpleNamespace

    from hevsim.thermal.cht import CoolantThermal, channel_axis_m

    cfg, res = duct_rans
    m = res.metrics  # type: ignore[attr-defined]
    assert m["fem_wall_cell_m"] == 5e-5 and m["conduction_sublayer_m"] == pytest.approx(4.35e-5, rel=0.01)
    rans.check_thermal_wall_mesh(res)  # 50 um: fine
    coarse = SimpleNamespace(metrics={**m, "fem_wall_cell_m": 1e-3})  # a uniform 4 x 2 mesh
    with pytest.raises(ConfigError, match=r"no thicker than about 8\.7e-05 m.*flow\.wall_cell_m"):
        rans.check_thermal_wall_mesh(coarse)
    # the coolant model itself checks (as used by hevsim flow --thermal and the CHT participant)
    # when told to resolve the wall layer (flow.thermal_wall = "resolved"; "auto" takes the wall
    # function on such cells)
    res.metrics = {**m, "fem_wall_cell_m": 1e-3}  # type: ignore[attr-defined]
    try:
        with pytest.raises(ConfigError, match=r"conduction sublayer.*thermal_wall"):
            CoolantThermal(
                res,  # type: ignore[arg-type]
                config_channel(cfg),
                cfg.coolant,
                channel_axis_m(cfg),
                4,
                thermal_wall="resolved",
            )
    finally:
        res.metrics = m  # type: ignore[attr-defined]


def _gnielinski(prandtl: float) -> float:
    f = (0.79 * math.log(RE_DUCT) - 1.64) ** -2
    return (f / 8) * (RE_DUCT - 1000) * prandtl / (1 + 12.7 * math.sqrt(f / 8) * (prandtl ** (2 / 3) - 1))


def _on_mesh(duct_rans: tuple[FlowConfig, object], **mesh: object) -> tuple[FlowConfig, object]:
    """The duct's OpenFOAM solution read onto another FEM mesh (no second OpenFOAM run)."""
    import dataclasses

    cfg, res = duct_rans
    sec = dataclasses.replace(cfg.flow, **mesh)  # type: ignore[arg-type]
    cfg2 = dataclasses.replace(cfg, flow=sec)
    return cfg2, rans.on_fem_mesh(res.rans, config_channel(cfg2), res.metrics, sec)  # type: ignore[attr-defined]


@pytest.fixture(scope="module")
def duct_resolved_cht(duct_rans: tuple[FlowConfig, object]) -> object:
    """The resolved CHT (50 um FEM wall cells) on the duct's RANS flow (~30 s CPU, once)."""
    from hevsim.thermal.cht import run_cht

    cfg, res = duct_rans
    return run_cht(cfg, res)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def duct_resolved_nusselt(duct_resolved_cht: object) -> float:
    """Developed Nusselt number of the resolved CHT on the duct (last 4 of 10 segments)."""
    return float(np.mean(duct_resolved_cht.segments["nusselt"][-4:]))  # type: ignore[attr-defined]


@pytest.mark.slow  # OpenFOAM solve (the duct fixture) + the resolved CHT (~30 s CPU)
@needs_openfoam
@pytest.mark.parametrize(
    "mesh",
    [
        {"wall_cell_m": 0.0, "cells_across_width": 8, "cells_across_height": 4},  # uniform 1 x 0.5 mm
        {"wall_cell_m": 3e-4},  # 4 x 2 graded from 0.3 mm
    ],
    ids=["uniform-8x4", "graded-0.3mm"],
)
def test_wall_function_on_coarse_fem_wall_cells_against_gnielinski_and_the_resolved_mesh(
    duct_rans: tuple[FlowConfig, object], duct_resolved_nusselt: float, mesh: dict
) -> None:
    """FEM wall cells 6-10x the conduction sublayer's limit (15-60x fewer tetrahedra than the
    resolved mesh): ``thermal_wall = "auto"`` takes the wall function; developed Nusselt
    within the issue's 15 % of Gnielinski and of the resolved CHT; exact energy balance."""
    from hevsim.thermal.cht import run_cht

    cfg, res = _on_mesh(duct_rans, **mesh)
    assert not rans.wall_cells_resolve_sublayer(res.metrics)  # type: ignore[attr-defined]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the wall cells are inside the law's range: no warning
        cht = run_cht(cfg, res)  # type: ignore[arg-type]
    m = cht.metrics
    assert m["wall_function"] == 1.0 and m["energy_imbalance_rel"] < 1e-6
    assert 5.0 < m["wall_yplus_min"] <= m["wall_yplus_mean"] <= m["wall_yplus_max"] < 300.0
    assert m["wall_beyond_log_layer_fraction"] == 0.0
    developed = float(np.mean(cht.segments["nusselt"][-4:]))
    assert developed == pytest.approx(_gnielinski(cfg.coolant.prandtl), rel=0.15)
    assert developed == pytest.approx(duct_resolved_nusselt, rel=0.15)
    # the same cells without the wall function (the interpolated eddy diffusivity down to the
    # wall: 7x the heat on the plate) are refused
    with pytest.raises(ConfigError, match="conduction sublayer"):
        run_cht(_with_wall(cfg, "resolved"), res)  # type: ignore[arg-type]


def _with_wall(cfg: FlowConfig, mode: str) -> FlowConfig:
    import dataclasses

    return dataclasses.replace(cfg, flow=dataclasses.replace(cfg.flow, thermal_wall=mode))


@pytest.mark.slow  # OpenFOAM solve (the duct fixture) + a CHT on the resolved mesh (~40 s CPU)
@needs_openfoam
def test_wall_function_on_the_resolved_mesh_gives_the_resolved_answer(
    duct_rans: tuple[FlowConfig, object], duct_resolved_nusselt: float
) -> None:
    """Wall cells in the viscous sublayer (y+ < 6): the law of the wall is molecular conduction
    there, the film tends to an imposed wall temperature, and the wall function reproduces the
    resolved model."""
    from hevsim.thermal.cht import run_cht

    cfg, res = duct_rans
    cht = run_cht(_with_wall(cfg, "wall_function"), res)  # type: ignore[arg-type]
    m = cht.metrics
    assert m["wall_function"] == 1.0 and m["wall_yplus_max"] < 6.0
    assert m["wall_yplus_in_viscous_sublayer_fraction"] > 0.9
    developed = float(np.mean(cht.segments["nusselt"][-4:]))
    assert developed == pytest.approx(duct_resolved_nusselt, rel=0.05)


@pytest.mark.slow  # OpenFOAM solve (the duct fixture: ~15 s CPU)
@needs_openfoam
def test_wall_function_warns_when_the_wall_node_is_in_the_core(duct_rans: tuple[FlowConfig, object]) -> None:
    """The 4 x 2 uniform mesh puts the node at the channel's centre line (2 mm = D_h/2.7):
    beyond the log layer; the wall heat comes out ~35 % high there, and the run says so."""
    from hevsim.thermal.cht import WallFunctionWarning, run_cht

    cfg, res = _on_mesh(duct_rans, wall_cell_m=0.0)
    with pytest.warns(WallFunctionWarning, match=r"beyond the log layer.*flow\.wall_cell_m"):
        cht = run_cht(cfg, res)  # type: ignore[arg-type]
    assert cht.metrics["wall_beyond_log_layer_fraction"] > 0.5


@pytest.mark.slow  # a short OpenFOAM run (15 iterations on a coarse grid: ~10 s CPU)
@needs_openfoam
def test_cht_participant_at_the_thesis_10_l_min_takes_the_wall_function(tmp_path: Path) -> None:
    """The co-simulation participant at the shipped 10 L/min: RANS flow (deliberately short
    and coarse here; the full case is examples/cosim_module/run_module_cht.py --flow-l-min 10),
    the thermal wall function on the example's 8 x 4 coolant mesh, the 1-D channel's interface,
    and the steady energy balance: the cooling power is m_dot c_p (T_out - T_in)."""
    import sys

    from hevsim.cosim.coolant import CoolantChannelParticipant
    from hevsim.cosim.coolant_cht import CoolantCHTParticipant

    sys.path.insert(0, str(ROOT / "examples" / "cosim_module"))
    from run_module_cht import TURBULENT_MESH, module_cht_system

    cht = next(c for c in module_cht_system(10.0, "cht", "inprocess", 10.0).components if c.name == "coolant")
    assert cht.parameters["flow_l_min"] == 10.0 and TURBULENT_MESH.items() <= cht.parameters.items()
    cfg = tmp_path / "module.toml"
    cfg.write_text(
        MODULE_TOML.read_text() + "\n[flow]\nrans_cells_across_width = 3\nrans_cells_across_height = 2\n"
        "rans_cell_length_m = 0.008\nrans_wall_cell_m = 0.0\nrans_iterations = 15\n"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # not converged in 15 iterations; bend end walls
        p3 = CoolantCHTParticipant(
            "coolant", cfg, **{k: v for k, v in cht.parameters.items() if k != "config"}
        )
    p1 = CoolantChannelParticipant("coolant", MODULE_TOML)
    assert p3.inputs == p1.inputs and p3.outputs == p1.outputs
    assert p3.flow.rans is not None and p3.model.wall_function is not None
    m = p3.model.wall_metrics()
    assert (
        m["wall_function"] == 1.0 and m["wall_yplus_max"] > m["wall_yplus_mean"] > m["wall_yplus_min"] >= 0.0
    )
    n = p3.n_segments
    area = p3.model.wall_area_m2
    p3.set_inputs(
        {f"wall{i}_temp_k": 303.15 for i in range(n)} | {f"wall{i}_area_m2": area[i] for i in range(n)}
    )
    out = p3.get_outputs()
    t_in = p3.u["inlet_temp_k"]
    assert out["cooling_power_w"] > 0.0
    rise = p3.model.capacity_rate_w_k * (out["outlet_temp_k"] - t_in)
    assert out["cooling_power_w"] == pytest.approx(rise, rel=1e-9)
    wall, _, _ = p3._inputs()
    temp, heat = p3.model.solve(wall, t_in)
    assert p3.model.outlet_temp_k(temp) == pytest.approx(out["outlet_temp_k"], abs=1e-6)  # field vs response
    assert heat.sum() == pytest.approx(out["cooling_power_w"], rel=1e-6)

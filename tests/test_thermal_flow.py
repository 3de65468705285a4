"""Laminar channel flow (hevsim.thermal.flow) against closed forms no one on the project wrote.

References: F. M. White, *Viscous Fluid Flow*, 3rd ed. (2006), eqs. (3-48), (3-49): series
solution for Poiseuille flow in a rectangular duct; R. K. Shah and A. L. London, *Laminar
Flow Forced Convection in Ducts* (1978): fully developed Fanning f Re = 14.227 (square),
15.548 (aspect ratio 1/2), 18.233 (1/4).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("skfem")

from hevsim.errors import ConfigError, HevsimError
from hevsim.thermal.coolant import Coolant
from hevsim.thermal.flow import (
    L_MIN_TO_M3_S,
    FlowSection,
    duct_channel,
    duct_fanning_re,
    duct_flow_m3_s,
    duct_velocity_mps,
    flow_config_from_dict,
    plate_channel,
    run_flow,
    solve_flow,
)
from hevsim.thermal.geometry import ModuleGeometry

W, H = 0.008, 0.004  # the shipped channel's cross-section [m]
COOLANT = Coolant()  # thesis Table 4.4: rho 1056 kg/m^3, mu 8.5 mPa s
MODULE_TOML = Path(__file__).resolve().parents[1] / "examples" / "module_thermal.toml"


@pytest.mark.parametrize(("aspect", "f_re"), [(1.0, 14.227), (0.5, 15.548), (0.25, 18.233)])
def test_series_friction_factor_matches_shah_london(aspect: float, f_re: float) -> None:
    assert duct_fanning_re(1.0, aspect) == pytest.approx(f_re, abs=1.5e-3)
    assert duct_fanning_re(aspect, 1.0) == pytest.approx(f_re, abs=1.5e-3)


def test_series_velocity_integrates_to_series_flow_and_vanishes_at_walls() -> None:
    n = 801
    y, z = np.linspace(-W / 2, W / 2, n), np.linspace(-H / 2, H / 2, n)
    u = duct_velocity_mps(y[:, None], z[None, :], W, H, 1000.0, COOLANT.viscosity_pa_s)
    q = np.trapezoid(np.trapezoid(u, z, axis=1), y)
    assert q == pytest.approx(duct_flow_m3_s(W, H, 1000.0, COOLANT.viscosity_pa_s), rel=1e-4)
    assert np.abs(u[0]).max() < 1e-9 * u.max() and np.abs(u[:, -1]).max() < 1e-9 * u.max()


def _l2_error(res, grad_pa_m: float) -> tuple[float, float]:
    """L2 norm of (u_h - u_exact) and of u_exact over the duct [m/s m^1.5]."""
    from skfem import Functional

    @Functional
    def err2(w):  # type: ignore[no-untyped-def]
        ue = duct_velocity_mps(w.x[1] - W / 2, w.x[2] - H / 2, W, H, grad_pa_m, COOLANT.viscosity_pa_s)
        return (w["u"][0] - ue) ** 2 + w["u"][1] ** 2 + w["u"][2] ** 2

    @Functional
    def ref2(w):  # type: ignore[no-untyped-def]
        return duct_velocity_mps(w.x[1] - W / 2, w.x[2] - H / 2, W, H, grad_pa_m, COOLANT.viscosity_pa_s) ** 2

    ui = res.basis_u.interpolate(res.velocity)
    return math.sqrt(err2.assemble(res.basis_u, u=ui)), math.sqrt(ref2.assemble(res.basis_u))


@pytest.mark.parametrize("streamline_diffusion", [0.0, 1.0])
def test_developed_duct_flow_converges_at_third_order_to_the_series_solution(
    streamline_diffusion: float,
) -> None:
    """Developed inlet + do-nothing outlet: the exact solution is Poiseuille flow everywhere
    (also with the momentum streamline diffusion, which vanishes for developed flow)."""
    q = 5e-6  # Re ~ 100: the Newton iterations carry a convective term
    length = 0.004
    grad = q / duct_flow_m3_s(W, H, 1.0, COOLANT.viscosity_pa_s)  # -dp/dx [Pa/m]
    errors, dp_err = [], []
    sizes = (2, 3, 4)
    for n in sizes:
        sec = FlowSection(
            cells_across_width=2 * n,
            cells_across_height=n,
            cell_length_m=H / n,
            streamline_diffusion=streamline_diffusion,
        )
        res = solve_flow(duct_channel(length, W, H), COOLANT, q, section=sec)
        assert res.metrics["mass_imbalance_rel"] < 1e-9
        e, ref = _l2_error(res, grad)
        errors.append(e / ref)
        dp_err.append(abs(res.metrics["pressure_drop_pa"] / (grad * length) - 1.0))
    rates = [math.log(errors[i] / errors[i + 1]) / math.log(sizes[i + 1] / sizes[i]) for i in range(2)]
    print("L2 errors", errors, "rates", rates, "dp errors", dp_err)
    assert all(r > 2.6 for r in rates), (errors, rates)  # P2 velocity: O(h^3) in L2
    assert errors[-1] < 6e-3  # measured 3.9e-3 at 8 x 4 cells
    dp_rate = math.log(dp_err[0] / dp_err[-1]) / math.log(sizes[-1] / sizes[0])
    assert dp_rate > 1.8 and dp_err[-1] < 1e-2, dp_err  # P1 pressure: O(h^2); measured 0.57 % at 8 x 4


def test_uniform_inlet_develops_to_poiseuille_profile_and_pressure_gradient() -> None:
    """Entrance flow at Re ~ 4: centreline velocity and dp/dx downstream against the series."""
    length, q = 0.024, 2e-7
    sec = FlowSection(
        inlet_profile="uniform", cells_across_width=6, cells_across_height=3, cell_length_m=0.002
    )
    res = solve_flow(duct_channel(length, W, H), COOLANT, q, section=sec)
    grad = q / duct_flow_m3_s(W, H, 1.0, COOLANT.viscosity_pa_s)
    u_max = duct_velocity_mps(np.array(0.0), np.array(0.0), W, H, grad, COOLANT.viscosity_pa_s)
    x1, x2 = 0.6 * length, 0.9 * length
    u, p = [], []
    for x in (x1, x2):
        pt = np.array([[x], [W / 2], [H / 2]])
        u.append(res.basis_u.probes(pt) @ res.velocity)  # (u_x, u_y, u_z)
        p.append(float((res.basis_p.probes(pt) @ res.pressure)[0]))
    print("centreline", [v[0] / u_max for v in u], "dp/dx", (p[0] - p[1]) / (x2 - x1) / grad)
    assert [v[0] for v in u] == pytest.approx([u_max, u_max], rel=0.01)
    assert np.abs(np.array(u)[:, 1:]).max() < 1e-3 * u_max
    assert (p[0] - p[1]) / (x2 - x1) == pytest.approx(grad, rel=0.01)
    # the entrance costs extra pressure: total drop above the developed-flow value
    assert res.metrics["pressure_drop_pa"] > grad * length


def test_serpentine_plate_channel_conserves_mass_and_reports_pressure_drop() -> None:
    g = ModuleGeometry()
    sec = FlowSection(
        cells_across_width=2, cells_across_height=2, cell_length_m=0.004, outlet_pressure_pa=1000.0
    )
    res = solve_flow(plate_channel(g), COOLANT, 0.1 * L_MIN_TO_M3_S, section=sec)
    m = res.metrics
    assert m["inlet_flow_m3_s"] == pytest.approx(0.1 * L_MIN_TO_M3_S, rel=1e-12)
    assert m["mass_imbalance_rel"] < 1e-9
    path = g.channel_path_m()  # centreline length x cross-section, corrected for the corners' overlap
    assert m["channel_volume_m3"] < np.linalg.norm(np.diff(path, axis=0), axis=1).sum() * W * H
    assert m["channel_volume_m3"] > (np.linalg.norm(np.diff(path, axis=0), axis=1).sum() - 4 * W) * W * H
    # the path is longer than three plate lengths: more than three straight ducts of the plate's length
    grad = 0.1 * L_MIN_TO_M3_S / duct_flow_m3_s(W, H, 1.0, COOLANT.viscosity_pa_s)  # developed -dp/dx [Pa/m]
    assert m["pressure_drop_pa"] > 3 * grad * (g.length_x_m - 3 * W)
    assert m["inlet_pressure_pa"] == pytest.approx(1000.0 + m["pressure_drop_pa"])
    assert m["pump_power_w"] == pytest.approx(m["pressure_drop_pa"] * 0.1 * L_MIN_TO_M3_S)
    assert m["reynolds"] == pytest.approx(
        1056 * (0.1 * L_MIN_TO_M3_S / (W * H)) * (2 * W * H / (W + H)) / 0.0085
    )


def _module_data(**flow: object) -> dict:
    from hevsim.schema import read_toml

    data = read_toml(MODULE_TOML)
    data["flow"] = dict(flow)
    return data


def test_shipped_10_l_min_case_is_turbulent_and_refused_with_the_laminar_limit() -> None:
    cfg = flow_config_from_dict(_module_data(model="laminar"), str(MODULE_TOML))  # "auto" takes RANS
    assert cfg.flow_m3_s == pytest.approx(10 * L_MIN_TO_M3_S)
    with pytest.raises(
        ConfigError, match=r"Re = 34\d\d.*laminar solver needs Re <= 2300.*flow_l_min <= 6\.6"
    ):
        run_flow(cfg)


@pytest.mark.parametrize(
    ("flow", "match"),
    [
        ({"flow_l_min": -1.0}, "flow.flow_l_min"),
        ({"inlet_profile": "parabolic"}, "flow.inlet_profile"),
        ({"cells_across_height": 1}, "flow.cells_across_height"),
        ({"pressure": 3.0}, "flow.pressure"),
        ({"channel": "pipe"}, "flow.channel"),
        ({"model": "les"}, "flow.model"),
        ({"thermal_wall": "log_law"}, r"flow\.thermal_wall.*auto.*resolved.*wall_function"),
    ],
)
def test_bad_flow_section_is_a_config_error_naming_the_key(flow: dict, match: str) -> None:
    with pytest.raises(HevsimError, match=match):
        flow_config_from_dict(_module_data(**flow), str(MODULE_TOML))


def test_run_flow_writes_summary_and_vtu(tmp_path: Path) -> None:
    import meshio

    data = _module_data(
        flow_l_min=0.2, channel="duct", duct_length_m=0.01, cells_across_width=2, cell_length_m=0.004
    )
    out = tmp_path / "flow_out"
    res = run_flow(flow_config_from_dict(data, "case.toml"), out)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["metrics"]["pressure_drop_pa"] == pytest.approx(res.metrics["pressure_drop_pa"])
    mesh = meshio.read(out / "flow.vtu")
    assert mesh.point_data["velocity_mps"].shape == (len(mesh.points), 3)
    assert np.allclose(mesh.point_data["pressure_pa"], res.pressure)


def test_cli_flow_refuses_turbulent_case_writes_nothing_and_runs_a_laminar_one(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from hevsim.cli import main

    out = tmp_path / "res"
    assert main(["flow", str(MODULE_TOML), "--model", "laminar", "--out", str(out)]) == 2
    assert "Re = 3451" in capsys.readouterr().err and not out.exists()
    cfg = tmp_path / "duct.toml"
    cfg.write_text(
        MODULE_TOML.read_text()
        + '\n[flow]\nchannel = "duct"\nduct_length_m = 0.008\ncells_across_width = 2\ncell_length_m = 0.004\n'
    )
    (tmp_path / "notes.txt").write_text("mine")
    assert main(["flow", str(cfg), "--flow-l-min", "0.5", "--out", str(tmp_path)]) == 2  # holds user files
    assert main(["flow", str(cfg), "--flow-l-min", "0.5", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "0.5 L/min" in text and "pressure drop" in text
    assert json.loads((out / "summary.json").read_text())["metrics"]["flow_l_min"] == pytest.approx(0.5)


@pytest.mark.slow
def test_serpentine_converges_at_the_top_of_the_laminar_range_with_streamline_diffusion() -> None:
    """Re 2278 (6.6 L/min, just below RE_LAMINAR_MAX = 2300) through a two-pass serpentine on the
    default coolant mesh (cell Re 854): Newton with grad-div alone does not converge (measured:
    last update 0.98 after 40 iterations, also with continuation steps of 1.5); with the
    momentum streamline diffusion it does (29 iterations)."""
    from hevsim.thermal.coolant import RE_LAMINAR_MAX

    g = ModuleGeometry(rows=1, columns=2, channel_passes=2)
    q = 6.6 * L_MIN_TO_M3_S
    sec = FlowSection(grad_div=10.0, streamline_diffusion=1.0, model="laminar")
    res = solve_flow(plate_channel(g), COOLANT, q, section=sec)
    m = res.metrics
    assert 2200 < m["reynolds"] <= RE_LAMINAR_MAX
    assert res.history[-1] < sec.tolerance and m["mass_imbalance_rel"] < 1e-9
    # more than the developed-flow drop of the straight length: entrance and bend losses
    path = g.channel_path_m()
    grad = q / duct_flow_m3_s(W, H, 1.0, COOLANT.viscosity_pa_s)
    assert m["pressure_drop_pa"] > grad * np.linalg.norm(np.diff(path, axis=0), axis=1).sum()

"""Thermal ROM of the module vs the full FEM (issue 12 item 1), on a coarse mesh.

The 1-hour US06-like load and the default mesh are in ``benchmarks/bench_rom.py``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("skfem")
pytest.importorskip("gmsh")

from tests.thermal_helpers import COARSE_TOML

from hevsim.cli import main
from hevsim.errors import ConfigError, InputError
from hevsim.thermal.geometry import build_module_mesh
from hevsim.thermal.rom import (
    RomStepper,
    ThermalRom,
    compare_with_fem,
    full_model,
    load_rom,
    mesh_hash,
    write_rom_fields,
)
from hevsim.thermal.run import KELVIN, load_thermal_config

#: the acceptance bound of issue 12 on every per-cell mean and hot-spot temperature [K]
BOUND_K = 0.2


@pytest.fixture(scope="module")
def case(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    d = tmp_path_factory.mktemp("rom")
    toml = d / "module_coarse.toml"
    toml.write_text(COARSE_TOML)
    out = d / "module.rom.npz"
    assert main(["rom", "build", str(toml), "-o", str(out)]) == 0
    cfg = load_thermal_config(toml)
    mesh = build_module_mesh(cfg.geometry)
    return {"toml": toml, "rom_path": out, "rom": load_rom(out, expected_mesh_hash=mesh_hash(mesh)),
            "cfg": cfg, "mesh": mesh, "dir": d}  # fmt: skip


def test_coarse_case_is_coarse(case: dict[str, Any]) -> None:
    assert case["cfg"].geometry.mesh_size_m == 0.008 and case["cfg"].geometry.curvature_elements == 8
    rom = case["rom"]
    assert rom.n_cells == 12 and 10 <= rom.order < rom.metadata["nodes"] / 10
    assert rom.metadata["error_estimate_k"] <= rom.metadata["options"]["tol_k"]


def test_square_wave_heat_matches_fem(case: dict[str, Any]) -> None:
    """(a) the co-simulation module's square load: per-cell heat alternating every 5 s (discharge
    2 W / charge 0.8 W, cells spread +-20 %), coolant inlet 15 degC, 300 s."""
    spread = np.linspace(0.8, 1.2, 12)

    def heat(t: float) -> np.ndarray:
        return spread * (2.0 if (t % 10.0) < 5.0 else 0.8)

    c = compare_with_fem(case["cfg"], case["mesh"], case["rom"], heat, lambda t: 15.0 + KELVIN, 300)
    assert c.fem_max_k.max() - c.fem_max_k[0].max() > 5.0  # the load really heats the cells
    assert c.mean_error_k < BOUND_K and c.max_error_k < BOUND_K
    assert c.mean_error_k < 0.01  # the projection itself is far tighter than the bound
    assert np.abs(c.rom_wall_heat_w - c.fem_wall_heat_w).max() < 0.01 * np.abs(c.fem_wall_heat_w).max()


def test_coolant_step_matches_fem(case: dict[str, Any]) -> None:
    """(b) a 10 K step of the coolant inlet at 100 s under 1 W per cell."""

    def inlet(t: float) -> float:
        return KELVIN + (15.0 if t < 100.0 else 25.0)

    c = compare_with_fem(case["cfg"], case["mesh"], case["rom"], lambda t: np.ones(12), inlet, 300)
    rise = c.fem_mean_k[-1] - c.fem_mean_k[100]
    assert rise.min() > 1.0  # the step reaches the cells
    assert c.mean_error_k < BOUND_K and c.max_error_k < BOUND_K


@pytest.mark.parametrize("load", ["multisine", "travelling", "chirp"])
def test_moving_hot_spot_within_the_stated_tolerance(case: dict[str, Any], load: str) -> None:
    """Issue 26 item 5: per-cell heat of both signs that moves the hot spot inside the cells (a
    random multi-sine per cell; a heat wave travelling along the cells; a per-cell chirp held out
    from setting the build's margin), load families the ROM was not built with: the reported hot
    spot (the maximum of the reconstructed field over every node of the cell) is within the ROM's
    stated tolerance of the FEM's at every step, and its error estimate is stated. Before, the
    maximum over 34 fixed candidate nodes per cell was up to 0.77 K below the FEM's on the
    multi-sine."""
    from hevsim.thermal.rom import validation_loads

    rom: ThermalRom = case["rom"]
    tol = rom.metadata["options"]["tol_k"]
    assert tol == 0.05 and 0.0 < rom.hot_spot_error_k <= tol
    heat, inlet, steps = validation_loads(rom.n_cells)[load]
    c = compare_with_fem(case["cfg"], case["mesh"], case["rom"], heat, inlet, steps)
    q = np.array([heat(t) for t in c.time_s[1:]])
    assert q.min() < -1.0 and q.max() > 1.0 and np.abs(q).max() <= 5.0 + 1e-9  # both signs, in range
    assert c.max_error_k <= tol, c.max_error_k
    assert c.mean_error_k <= tol


def test_steady_state_is_exact(case: dict[str, Any]) -> None:
    """Moment matching at s = 0: the ROM's steady state equals the FEM's for any heat and fluid."""
    from scipy.sparse.linalg import spsolve

    rom: ThermalRom = case["rom"]
    full, _, _ = full_model(case["cfg"], case["mesh"])
    rng = np.random.default_rng(1)
    # fluid temperatures along the channel in the span of the build's directions (uniform, linear,
    # quadratic in the segment index); arbitrary per-segment values are approximated, not exact
    x = np.linspace(-1.0, 1.0, rom.n_segments)
    q, tf, ta = rng.uniform(0, 3, 12), 290.0 + 3.0 * x - 1.0 * (1.5 * x**2 - 0.5), 305.0
    for h in rom.wall_h_range_w_m2k:
        u = np.concatenate([q, tf, [ta], [1.0]])
        t_full = spsolve(full.stiffness(h), full.inputs(h) @ u)
        z = np.linalg.solve(rom.stiffness(h), rom.inputs(h) @ u)
        mean_full = np.array([np.average(t_full[n], weights=full.node_vol[n]) for n in full.cell_nodes])
        assert np.abs(rom.cell_mean_k(z) - mean_full).max() < 1e-6
        assert np.abs(rom.field_k(z) - t_full).max() < 1e-6


def test_energy_balance_and_uniform_state(case: dict[str, Any]) -> None:
    rom: ThermalRom = case["rom"]
    dt, h = 1.0, rom.wall_h_range_w_m2k[1]
    st = RomStepper(rom, dt, h, 300.0, n_modules=2)
    assert np.allclose(rom.field_k(st.z[0]), 300.0, atol=1e-9)  # uniform fields are exact
    rng = np.random.default_rng(2)
    e0 = rom.stored_j(st.z)
    total_in = total_out = np.zeros(2)
    for _ in range(50):
        q = rng.uniform(0, 4, (2, 12))
        tf = np.full((2, rom.n_segments), 290.0)
        st.step(q, tf, np.array([300.0, 310.0]))
        wall = rom.wall_heat_w(st.z, tf, h).sum(axis=-1)
        amb = rom.ambient_heat_w(st.z, np.array([300.0, 310.0]))
        total_in = total_in + dt * q.sum(axis=1)
        total_out = total_out + dt * (wall + amb)
    stored = rom.stored_j(st.z) - e0
    assert np.all(np.abs(total_in - total_out - stored) < 1e-9 * total_in)


def test_step_matrix_is_the_step(case: dict[str, Any]) -> None:
    """RomStepper.step_matrix (the public accessor the native ROM FMU embeds) is the implicit-Euler
    step [inv/dt | inv B(h)]^T of the current wall film, read-only, and one step is [z, u] @ it."""
    rom: ThermalRom = case["rom"]
    dt = 2.0
    h_lo, h_hi = rom.wall_h_range_w_m2k
    st = RomStepper(rom, dt, h_hi, 300.0)
    for h in (h_hi, h_lo):
        st.set_wall_h(h)
        inv = np.linalg.inv(np.eye(rom.order) / dt + rom.stiffness(h))
        expected = np.vstack([(inv / dt).T, (inv @ rom.inputs(h)).T])
        m = st.step_matrix
        assert m.shape == (rom.order + rom.n_cells + rom.n_segments + 2, rom.order)
        assert np.allclose(m, expected, rtol=1e-10, atol=1e-14 * np.abs(expected).max())
        assert not m.flags.writeable
        q, tf = np.full((1, rom.n_cells), 3.0), np.full((1, rom.n_segments), 290.0)
        zu = np.concatenate([st.z[0], q[0], tf[0], [305.0, 1.0]])
        assert np.array_equal(st.step(q, tf, 305.0)[0], zu @ m)
    with pytest.raises(ValueError):
        st.step_matrix[0, 0] = 1.0


def test_roundtrip_fields_and_refusals(case: dict[str, Any], tmp_path: Path) -> None:
    import meshio

    rom: ThermalRom = case["rom"]
    st = RomStepper(rom, 1.0, rom.wall_h_range_w_m2k[1], 303.15)
    for _ in range(20):
        st.step(np.full((1, 12), 2.0), np.full((1, rom.n_segments), 288.15), 303.15)
    pvd = write_rom_fields(rom, case["toml"], [(20.0, st.z[0])], tmp_path / "fields")
    vtu = next((tmp_path / "fields" / "fields").glob("rom_temperature_*.vtu"))
    assert pvd.is_file()
    data = meshio.read(vtu).point_data["temperature_c"]
    assert np.allclose(data, rom.field_k(st.z[0]) - KELVIN)
    # another mesh: refused with the hash in the message
    with pytest.raises(ConfigError, match="mesh"):
        load_rom(case["rom_path"], expected_mesh_hash="0" * 64)
    other = case["dir"] / "other.toml"
    other.write_text(COARSE_TOML.replace("mesh_size_m = 0.008", "mesh_size_m = 0.009"))
    with pytest.raises(ConfigError, match="mesh"):
        write_rom_fields(rom, other, [(0.0, st.z[0])], tmp_path / "x")
    with pytest.raises(ConfigError, match="wall film"):
        RomStepper(rom, 1.0, 10 * rom.wall_h_range_w_m2k[1], 300.0)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(InputError, match="not a hevsim thermal ROM"):
        load_rom(bad)
    assert main(["rom", "info", str(bad)]) == 2
    assert main(["rom", "info", str(case["rom_path"])]) == 0
    # the CLI refuses to overwrite the input and an existing foreign file
    foreign = tmp_path / "notes.npz"
    foreign.write_text("mine")
    assert main(["rom", "build", str(case["toml"]), "-o", str(case["toml"])]) == 2
    assert main(["rom", "build", str(case["toml"]), "-o", str(foreign)]) == 2
    assert foreign.read_text() == "mine"

"""The coolant channel as its own co-simulation participant (issue 6, item 4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim.cosim import Connection, simulate
from hevsim.cosim.coolant import CoolantChannelParticipant
from hevsim.cosim.fem import FemModuleParticipant
from hevsim.cosim.participant import FunctionParticipant
from hevsim.errors import ConfigError

CONFIG = Path(__file__).resolve().parents[1] / "examples" / "module_thermal.toml"
MESH = 0.008  # coarse: some configured channel segments get no wall facet


def _heat(name: str = "heat") -> FunctionParticipant:
    """4 W per cell for 5 s, then 0.5 W."""

    def step(t: float, h: float, x: None, u: dict[str, float]) -> tuple[None, dict[str, float]]:
        return None, {"cell_heat_w": 4.0 if t + h <= 5.0 else 0.5}

    return FunctionParticipant(
        name, step, None, {"cell_heat_w": 4.0}, inputs={}, outputs={"cell_heat_w": "W"}
    )


def _coupled(duration: float, fluid: bool = False, **options: object) -> tuple[object, int]:
    fem = FemModuleParticipant("fem", CONFIG, mesh_size_m=MESH, coolant="external")
    cool = CoolantChannelParticipant("coolant", CONFIG)
    n = cool.n_segments
    conns = [Connection("heat", "cell_heat_w", "fem", "cell_heat_w")]
    for j in range(n):
        conns += [
            Connection("fem", f"wall{j}_temp_k", "coolant", f"wall{j}_temp_k"),
            Connection("fem", f"wall{j}_area_m2", "coolant", f"wall{j}_area_m2"),
            Connection("coolant", f"wall{j}_heat_flux_w_m2", "fem", f"wall{j}_heat_flux_w_m2"),
            Connection("coolant", f"wall{j}_film_w_m2k", "fem", f"wall{j}_film_w_m2k"),
        ]
        if fluid:
            conns.append(Connection("coolant", f"wall{j}_fluid_temp_k", "fem", f"wall{j}_fluid_temp_k"))
    res = simulate([_heat(), fem, cool], conns, stop_time_s=duration, step_s=1.0,
                   algorithm="gauss-seidel", order=["heat", "fem", "coolant"], **options)  # fmt: skip
    return res, n


def _staggered() -> object:
    """The example with the internal coolant coupled staggered (fluid from the wall at the start
    of the step), as a plate stepped before a separate coolant participant."""
    from dataclasses import replace

    from hevsim.thermal.run import load_thermal_config

    cfg = load_thermal_config(CONFIG)
    return replace(cfg, simulation=replace(cfg.simulation, coupling="staggered"))


@pytest.mark.parametrize("fluid", [False, True], ids=["flux-and-film", "fluid-temperature"])
def test_separate_coolant_reproduces_internal_coupling(fluid: bool) -> None:
    """Plate stepped before the coolant, 1 s exchange = the FEM's step: the separate coolant
    participant gives the internal quasi-steady coupling to round-off, whether the plate gets
    the heat flux and film (thesis) or the fluid temperature and film."""
    duration = 12.0
    res, n = _coupled(duration, fluid)
    ref = simulate([_heat(), FemModuleParticipant("fem", _staggered(), mesh_size_m=MESH)],
                   [Connection("heat", "cell_heat_w", "fem", "cell_heat_w")],
                   stop_time_s=duration, step_s=1.0, algorithm="gauss-seidel",
                   order=["heat", "fem"])  # fmt: skip
    for c in range(12):
        np.testing.assert_allclose(res[f"fem.cell{c}_temp_k"], ref[f"fem.cell{c}_temp_k"], rtol=0, atol=1e-9)
    # the internal channel reports the outlet of the fluid it used over the step (from the wall
    # at the step's start); the coolant participant reports it for the wall at the step's end
    np.testing.assert_allclose(res["coolant.outlet_temp_k"][1:-1], ref["fem.outlet_temp_k"][2:], atol=1e-9)
    np.testing.assert_allclose(
        res["coolant.cooling_power_w"][1:-1], ref["fem.cooling_power_w"][2:], rtol=1e-9
    )
    # before the first exchange the plate does not know the coolant: compare from the first step
    np.testing.assert_allclose(res["fem.wall_heat_w"][1:], ref["fem.wall_heat_w"][1:], rtol=1e-9)
    assert res["coolant.cooling_power_w"][1] > 1.0  # the 30 degC module heats the 15 degC coolant
    areas = np.array([res[f"fem.wall{j}_area_m2"][-1] for j in range(n)])
    assert np.all(areas > 0)


def test_iterated_coupling_closes_the_wall_energy_balance() -> None:
    """Explicit exchange: the heat leaving the plate and the coolant's heat differ by the lag.
    Iterating each step (end-value hold, fluid temperature connected) converges to the
    implicit coupling, where they agree at every communication point."""
    plain, _ = _coupled(6.0, fluid=True)
    lag = np.abs(plain["fem.wall_heat_w"][1:] / plain["coolant.cooling_power_w"][1:] - 1).max()
    assert lag > 1e-3
    res, _ = _coupled(6.0, fluid=True, max_iterations=40, tolerance=1e-12, hold="end")
    np.testing.assert_allclose(res["fem.wall_heat_w"][1:], res["coolant.cooling_power_w"][1:], rtol=1e-6)
    # and it converges to the internal coolant's default (implicit) coupling
    ref = simulate([_heat(), FemModuleParticipant("fem", CONFIG, mesh_size_m=MESH)],
                   [Connection("heat", "cell_heat_w", "fem", "cell_heat_w")],
                   stop_time_s=6.0, step_s=1.0, algorithm="gauss-seidel", order=["heat", "fem"])  # fmt: skip
    np.testing.assert_allclose(res["fem.wall_heat_w"][1:], ref["fem.wall_heat_w"][1:], rtol=1e-6)
    np.testing.assert_allclose(ref["fem.wall_heat_w"][1:], ref["fem.cooling_power_w"][1:], rtol=1e-9)


def test_segments_without_wall_exchange_nothing() -> None:
    """More configured segments than the coarse mesh resolves: the empty ones report no area,
    and whatever the coolant sends for them is ignored."""
    from dataclasses import replace

    from hevsim.thermal.run import load_thermal_config

    cfg = load_thermal_config(CONFIG)
    cfg = replace(cfg, coolant=replace(cfg.coolant, segments=150))
    fem = FemModuleParticipant("fem", cfg, mesh_size_m=MESH, coolant="external")
    fem.setup(0.0)
    out = fem.get_outputs()
    areas = np.array([out[f"wall{j}_area_m2"] for j in range(150)])
    assert (areas == 0).any() and areas.sum() > 0
    empty = int(np.flatnonzero(areas == 0)[0])
    fem.set_inputs({f"wall{j}_film_w_m2k": 500.0 for j in range(150)})
    fem.set_inputs({f"wall{empty}_heat_flux_w_m2": 1e9})  # would be absurd if applied
    fem.do_step(0.0, 1.0)
    assert abs(fem.get_outputs()["cell_mean_temp_k"] - 303.15) < 0.1


def test_coolant_energy_balance_per_segment() -> None:
    """Heat out of the wall (flux x area) equals the coolant's enthalpy rise m c_p dT."""
    cool = CoolantChannelParticipant("coolant", CONFIG, segments=5, inlet_temp_k=288.15)
    wall = np.array([300.0, 305.0, 302.0, 299.0, 289.0])
    area = np.array([1e-3, 2e-3, 0.0, 1.5e-3, 1e-3])
    cool.set_inputs({f"wall{j}_temp_k": wall[j] for j in range(5)})
    cool.set_inputs({f"wall{j}_area_m2": area[j] for j in range(5)})
    out = cool.get_outputs()
    flux = np.array([out[f"wall{j}_heat_flux_w_m2"] for j in range(5)])
    assert float(flux @ area) == pytest.approx(out["cooling_power_w"], rel=1e-12)
    fluid = np.array([out[f"wall{j}_fluid_temp_k"] for j in range(5)])
    assert np.all((fluid >= 288.15) & (fluid < wall))
    assert out["outlet_temp_k"] > 288.15
    film = out["wall0_film_w_m2k"]
    np.testing.assert_allclose(flux, film * (wall - fluid), rtol=1e-12)


def test_coolant_bad_input_is_named() -> None:
    cool = CoolantChannelParticipant("coolant", CONFIG, segments=2)
    with pytest.raises(ConfigError, match="has no input 'wall7_temp_k'"):
        cool.set_inputs({"wall7_temp_k": 300.0})
    cool.set_inputs({"wall0_area_m2": -1.0})
    with pytest.raises(ConfigError, match="not physical"):
        cool.get_outputs()
    with pytest.raises(ConfigError, match="coolant = 'cfd'"):
        FemModuleParticipant("fem", CONFIG, coolant="cfd")

"""Abaqus / CalculiX films with amplitudes (issue 15, item 2): ``*Sfilm, amplitude=`` scales the
sink temperature, ``film amplitude=`` the film coefficient (Abaqus Keywords Reference *FILM /
*SFILM). The imported deck, stepped with ``AbaqusModel.set_loads``, equals the same model built
natively with the film on the channel wall driven step by step through another code path of
the solver (a coolant giving the ramped fluid temperature, ``set_wall_film`` the ramped film
coefficient), and its energy balance closes."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("skfem")

from tests.test_thermal_abaqus_cae import (
    ALU,
    CELL,
    FILM,
    FLUX,
    H_GAP,
    _amplitude,
    native_mesh,
    write_cae_deck,
)

from hevsim.errors import InputError
from hevsim.thermal.abaqus import read_abaqus_inp
from hevsim.thermal.mesh import CHANNEL_WALL
from hevsim.thermal.solver import HeatModel, discretise

SINK_AMP = ([0.0, 6.0, 100.0], [0.5, 2.0, 2.0])  # sink 10 degC -> 40 degC over 6 s
FILM_AMP = ([0.0, 10.0], [1.0, 3.0])  # film 500 -> 1500 W/(m^2 K) over 10 s
AMPLITUDES = "*Amplitude, name=SinkRamp\n0., 0.5, 6., 2., 100., 2.\n*Amplitude, name=HRamp\n0., 1., 10., 3."


def _a(table: tuple[list[float], list[float]], t: float) -> float:
    return float(np.interp(t, table[0], table[1]))


class _RampedFluid:
    """One coolant segment whose fluid temperature [K] follows the sink amplitude at ``time_s``."""

    n_segments = 1

    def __init__(self, ramp_sink: bool) -> None:
        self.time_s = 0.0
        self.ramp_sink = ramp_sink

    def heat_transfer_coefficient_w_m2k(self) -> np.ndarray:
        return np.array([FILM[0]])

    def fluid_temperature_k(self, wall_temp_k: np.ndarray, wall_area_m2: np.ndarray) -> np.ndarray:
        scale = _a(SINK_AMP, self.time_s) if self.ramp_sink else 1.0
        return np.array([FILM[1] * scale + 273.15])


def _deck(tmp_path: Path, options: str) -> Path:
    deck = tmp_path / "Job-1.inp"
    write_cae_deck(deck, extra=AMPLITUDES)
    text = deck.read_text()
    assert text.count("*Sfilm\n") == 1
    deck.write_text(text.replace("*Sfilm\n", f"*Sfilm{options}\n"))
    return deck


def _by_position(disc: object, temp: np.ndarray) -> dict[tuple[int, tuple[float, ...]], float]:
    d: object = disc
    return {
        (int(pp), tuple(np.round(x * 1e6, 3))): float(t)
        for x, pp, t in zip(d.points_m, d.node_part, temp, strict=True)  # type: ignore[attr-defined]
    }


@pytest.mark.parametrize(
    ("options", "ramp_sink", "ramp_film"),
    [
        (", amplitude=SinkRamp", True, False),
        (", film amplitude=HRamp", False, True),
        (", amplitude=SinkRamp, film amplitude=HRamp", True, True),
        (", sink amplitude=sinkramp, film amplitude=hramp", True, True),  # recent *Sfilm name
    ],
)
def test_film_amplitudes_equal_the_film_driven_step_by_step(
    tmp_path: Path, options: str, ramp_sink: bool, ramp_film: bool
) -> None:
    model = read_abaqus_inp(_deck(tmp_path, options), length_scale_m=1e-3)
    (group,) = model.film_amplitude
    assert model.film_amplitude[group] == ("SINKRAMP" if ramp_sink else None, "HRAMP" if ramp_film else None)
    assert model.films[group] == (FILM[0], FILM[1])  # the deck's reference values
    h3, sink3 = model.films_at(3.0)[group]
    assert sink3 == pytest.approx(FILM[1] * (1.25 if ramp_sink else 1.0), rel=1e-15)
    assert h3 == pytest.approx(FILM[0] * (1.6 if ramp_film else 1.0), rel=1e-15)

    disc = model.discretise()
    imported = HeatModel(disc, dt_s=1.0, initial_temp_k=model.initial_temp_k(disc))
    # the native model: the plate's bottom is a channel wall, its fluid and film set every step
    native = native_mesh()
    native = dataclasses.replace(native, facet_groups={CHANNEL_WALL: native.facet_groups["BOTTOM"]})
    ref = discretise(
        native,
        {"plate": ALU, "block": CELL},
        interface_conductance_w_m2k={"block|plate": H_GAP},
        film_w_m2k=0.0,
    )
    fluid = _RampedFluid(ramp_sink)
    other = HeatModel(ref, dt_s=1.0, initial_temp_k=298.15, coolant=fluid)
    stored0 = float(np.sum(imported.capacity @ imported.temp_k))
    heat_in = to_film = 0.0
    for k in range(1, 11):
        t = float(k)
        model.set_loads(imported, imported.time_s + imported.dt_s)
        imported.step()
        rep = imported.report()
        heat_in += rep.heat_in_w * imported.dt_s
        to_film += rep.film_w * imported.dt_s
        fluid.time_s = t
        other.set_cell_heat_w(FLUX * _amplitude(t) * ref.cell_volume_m3)
        other.set_wall_film(np.array([FILM[0] * (_a(FILM_AMP, t) if ramp_film else 1.0)]))
        other.step()
    a, b = _by_position(disc, imported.temp_k), _by_position(ref, other.temp_k)
    assert a.keys() == b.keys()
    rise = max(abs(v - 298.15) for v in b.values())
    assert rise > 1.0
    assert max(abs(a[key] - b[key]) for key in a) <= 1e-9 * rise
    # the amplitudes matter: the same deck with constant films differs by far more
    const = HeatModel(disc, dt_s=1.0, initial_temp_k=model.initial_temp_k(disc))
    for k in range(1, 11):
        const.set_cell_heat_w(model.cell_heat_w(disc.cell_volume_m3, float(k)))
        const.step()
    assert np.abs(const.temp_k - imported.temp_k).max() > 1e-3 * rise
    # energy: heat in - stored - to the film closes (implicit Euler, exact to rounding)
    stored = float(np.sum(imported.capacity @ imported.temp_k)) - stored0
    assert abs(to_film) > 1.0 and heat_in > 1.0
    assert abs(heat_in - stored - to_film) <= 1e-9 * max(heat_in, abs(stored), abs(to_film))
    assert imported.surface_films[group] == pytest.approx(
        (FILM[0] * (3.0 if ramp_film else 1.0), FILM[1] * (2.0 if ramp_sink else 1.0) + 273.15), rel=1e-15
    )


def test_constant_films_are_not_refactorised(tmp_path: Path) -> None:
    """A sink amplitude changes the load only; only a film amplitude refactorises (once a step)."""
    model = read_abaqus_inp(_deck(tmp_path, ", amplitude=SinkRamp"), length_scale_m=1e-3)
    heat = HeatModel(model.discretise(), dt_s=1.0, initial_temp_k=298.15)
    for _ in range(3):
        model.set_loads(heat, heat.time_s + heat.dt_s)
        heat.step()
    assert heat.factorisations == 1
    model = read_abaqus_inp(_deck(tmp_path, ", film amplitude=HRamp"), length_scale_m=1e-3)
    heat = HeatModel(model.discretise(), dt_s=1.0, initial_temp_k=298.15)
    for _ in range(3):
        model.set_loads(heat, heat.time_s + heat.dt_s)
        heat.step()
    assert heat.factorisations == 4


@pytest.mark.parametrize(
    ("options", "match"),
    [
        (", amplitude=NoSuch", r"line \d+: film amplitude 'NOSUCH' is not defined"),
        (", film amplitude=NoSuch", r"line \d+: film amplitude 'NOSUCH' is not defined"),
        (", amplitude=SinkRamp, time delay=2.", r"line \d+: \*Sfilm, time delay= is not supported"),
        (", film amplitude=HRamp, film time delay=2.", r"\*Sfilm, film time delay= is not supported"),
    ],
)
def test_bad_film_amplitudes_are_refused(tmp_path: Path, options: str, match: str) -> None:
    with pytest.raises(InputError, match=match):
        read_abaqus_inp(_deck(tmp_path, options), length_scale_m=1e-3)


def test_step_amplitude_ramp_is_refused(tmp_path: Path) -> None:
    """Abaqus ramps the loads without an amplitude over a step with amplitude=RAMP (the default
    of a transient *Heat Transfer is STEP, what the importer applies): refused, not ignored."""
    deck = _deck(tmp_path, "")
    text = deck.read_text()
    deck.write_text(text.replace("*Step, name=Heat,", "*Step, name=Heat, amplitude=RAMP,"))
    with pytest.raises(InputError, match=r"line \d+: \*Step, amplitude=RAMP: loads without their own"):
        read_abaqus_inp(deck, length_scale_m=1e-3)
    deck.write_text(text.replace("*Step, name=Heat,", "*Step, name=Heat, amplitude=STEP,"))
    assert read_abaqus_inp(deck, length_scale_m=1e-3).films


def test_unknown_surface_film_is_refused(tmp_path: Path) -> None:
    model = read_abaqus_inp(_deck(tmp_path, ""), length_scale_m=1e-3)
    heat = HeatModel(model.discretise(), dt_s=1.0, initial_temp_k=298.15)
    with pytest.raises(Exception, match="surface film 'NOPE' is not one of"):
        heat.set_surface_film("NOPE", 1.0, 300.0)
    (group,) = model.films
    with pytest.raises(Exception, match="expected finite h >= 0"):
        heat.set_surface_film(group, -1.0, 300.0)

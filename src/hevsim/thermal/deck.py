"""Run an Abaqus/CalculiX heat-transfer deck: ``hevsim thermal DECK.inp``.

:func:`run_deck` reads the deck (:func:`hevsim.thermal.abaqus.read_abaqus_inp`), discretises it
(its materials, contact pairs and films; adiabatic elsewhere, as Abaqus) and runs its one
transient *Heat Transfer step with implicit Euler: :class:`~hevsim.thermal.solver.HeatModel`,
or :class:`~hevsim.thermal.solver.NonlinearHeatModel` when a material has temperature tables.
The deck's loads (*Dflux with amplitudes, films with amplitudes) are applied at the end of each
increment.

**Increments.** Without ``deltmx`` (or with ``direct``) the increments are fixed: the initial
increment over the time period (the last one shortened to end on the period), as Abaqus does.
With ``*Heat Transfer, deltmx=D`` the incrementation is automatic, as Abaqus's: the data line
gives the initial increment, the period and optionally the minimum (default ``min(initial,
1e-5 period)``) and maximum increment (default the period). An increment whose largest nodal
temperature change exceeds ``D`` is discarded and retried with ``dt * max(0.25, 0.8 D /
change)``; an accepted one sets the next to ``dt * min(1.5, 0.8 D / change)``, both within the
minimum and maximum. An increment that still exceeds ``D`` at the minimum is an error
(:class:`~hevsim.errors.SimulationError` naming the *Heat Transfer line). A change of the step
size refactorises the linear model.

Written atomically to the results folder: ``summary.json`` (increments, energy: heat in,
stored, to the films and the residual; per-part and per-heat-source minimum, mean and maximum
at the end) and the temperature field of every increment (at most :data:`MAX_FIELDS`, evenly
picked, the last always) as VTU with a ParaView ``temperature.pvd``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import ConfigError, SimulationError

KELVIN = 273.15
#: fields written at most (evenly picked increments, the last always)
MAX_FIELDS = 200
#: growth and cut-back of the automatic increment (module docstring)
_GROW, _CUT, _TARGET = 1.5, 0.25, 0.8


@dataclass
class DeckResult:
    """A deck's run: increment times [s], their largest nodal change [K], metrics and statistics."""

    deck: str
    time_s: np.ndarray
    max_change_k: np.ndarray
    metrics: dict[str, dict[str, Any]]
    parts: dict[str, dict[str, float]]
    sources: dict[str, dict[str, float]]
    metadata: dict[str, Any] = field(default_factory=dict)
    out_dir: Path | None = None


def run_deck(
    path: str | Path,
    out_dir: str | Path | None = None,
    *,
    length_scale_m: float = 1.0,
    bonded_w_m2k: float | None = None,
) -> DeckResult:
    """Run the deck ``path`` (module docstring); ``length_scale_m``: metres per deck length unit
    (1e-3 for a deck in mm); ``bonded_w_m2k``: contact conductance where sections share nodes."""
    from hevsim.thermal.abaqus import read_abaqus_inp
    from hevsim.thermal.solver import HeatModel, NonlinearHeatModel

    t_start = time.perf_counter()
    src = Path(path)
    model = read_abaqus_inp(src, length_scale_m=length_scale_m)
    initial, period, dt_min, dt_max = model.check_increments()
    disc = model.discretise(bonded_w_m2k=bonded_w_m2k)
    nonlinear = any(m.temperature_dependent for m in disc.materials.values())
    cls: Any = NonlinearHeatModel if nonlinear else HeatModel
    heat = cls(disc, dt_s=initial, initial_temp_k=model.initial_temp_k(disc))
    deltmx = model.deltmx_k

    def stored_j() -> float:
        if nonlinear:
            return float(heat.enthalpy_j())
        return float(np.sum(heat.capacity @ heat.temp_k))

    stored0 = stored_j()
    times, changes, fields = [0.0], [0.0], [(0.0, heat.temp_k - KELVIN)]
    heat_in = to_films = 0.0
    cutbacks = 0
    dt = initial
    tiny = 1e-12 * period
    while heat.time_s < period - tiny:
        dt = min(dt, period - heat.time_s)
        heat.set_dt(dt)
        saved = (heat.temp_k.copy(), heat.time_s, heat._f_old.copy())
        model.set_loads(heat, heat.time_s + dt)
        heat.step()
        change = float(np.abs(heat.temp_k - saved[0]).max())
        if deltmx is not None and change > deltmx:
            if dt <= dt_min * (1.0 + 1e-9):
                raise SimulationError(
                    f"{model.heat_transfer_where}: *Heat Transfer, deltmx={deltmx:g}: the temperature "
                    f"changes {change:.4g} K in the minimum increment {dt_min:g} s at t = {saved[1]:g} s; "
                    "expected a smaller minimum increment (third value of the data line) or a larger deltmx."
                )
            heat.temp_k, heat.time_s, heat._f_old = saved
            dt = max(dt_min, dt * max(_CUT, _TARGET * deltmx / change))
            cutbacks += 1
            continue
        rep = heat.report()
        heat_in += dt * rep.heat_in_w
        to_films += dt * rep.film_w
        times.append(heat.time_s)
        changes.append(change)
        fields.append((heat.time_s, heat.temp_k - KELVIN))
        if deltmx is not None:
            grow = _GROW if change <= 0.0 else min(_GROW, _TARGET * deltmx / change)
            dt = min(dt_max, max(dt_min, dt * grow))
    stored = stored_j() - stored0
    residual = heat_in - stored - to_films
    scale = max(abs(heat_in), abs(stored), abs(to_films), 1e-300)
    tc = heat.temp_k - KELVIN
    mesh = model.mesh
    vol = np.zeros(tc.size)
    np.add.at(vol, disc.tets.ravel(), np.repeat(disc.tet_volume_m3 / 4.0, 4))
    parts = {}
    for pi, name in enumerate(mesh.part_names):
        sel = disc.node_part == pi
        if sel.any():
            parts[name] = _stats(tc[sel], vol[sel])
    sources = {}
    source_names = list(model.body_flux_w_m3)
    tet_cell = mesh.cell_of_tet
    for c, name in enumerate(source_names):
        nodes = np.unique(disc.tets[tet_cell == c])
        if nodes.size:
            sources[name] = _stats(tc[nodes], vol[nodes])
    steps = np.diff(times)
    metrics: dict[str, dict[str, Any]] = {
        "time_period_s": {"value": period, "unit": "s"},
        "increments": {"value": len(times) - 1, "unit": "-"},
        "cutbacks": {"value": cutbacks, "unit": "-", "note": "increments discarded for deltmx"},
        "smallest_increment_s": {"value": float(steps.min()) if steps.size else 0.0, "unit": "s"},
        "largest_increment_s": {"value": float(steps.max()) if steps.size else 0.0, "unit": "s"},
        "largest_change_k": {
            "value": float(max(changes)),
            "unit": "K",
            "note": "largest nodal temperature change of an increment",
        },
        "max_temp_c": {"value": float(tc.max()), "unit": "degC"},
        "min_temp_c": {"value": float(tc.min()), "unit": "degC"},
        "heat_in_j": {"value": heat_in, "unit": "J", "note": "*Dflux heat applied"},
        "heat_stored_j": {"value": stored, "unit": "J", "note": "change of sum C T (enthalpy if nonlinear)"},
        "heat_to_films_j": {"value": to_films, "unit": "J", "note": "through the *Film / *Sfilm surfaces"},
        "energy_balance_residual_j": {"value": residual, "unit": "J", "note": "in - stored - to films"},
        "energy_balance_relative": {"value": residual / scale, "unit": "-"},
        "nodes": {"value": int(mesh.points_m.shape[0]), "unit": "-"},
        "tetrahedra": {"value": int(mesh.tets.shape[0]), "unit": "-"},
    }
    metadata = {
        "deck": str(src),
        "solver": "NonlinearHeatModel" if nonlinear else "HeatModel",
        "incrementation": (
            f"automatic, deltmx = {deltmx:g} K" if deltmx is not None else "fixed (initial increment)"
        ),
        "increments_s": {"initial": initial, "minimum": dt_min, "maximum": dt_max},
        "length_scale_m": length_scale_m,
        "unsupported": list(model.unsupported),
        "run_s": time.perf_counter() - t_start,
    }
    result = DeckResult(str(src), np.asarray(times), np.asarray(changes), metrics, parts, sources, metadata)
    if out_dir is not None:
        _write(result, Path(out_dir), disc, mesh, fields)
    return result


def _stats(temp_c: np.ndarray, weights: np.ndarray) -> dict[str, float]:
    w = weights if weights.sum() > 0 else np.ones_like(weights)
    return {
        "min_temp_c": float(temp_c.min()),
        "mean_temp_c": float(np.average(temp_c, weights=w)),
        "max_temp_c": float(temp_c.max()),
    }


def _write(
    result: DeckResult, out: Path, disc: Any, mesh: Any, fields: list[tuple[float, np.ndarray]]
) -> None:
    from hevsim.io import atomic_directory, write_json
    from hevsim.thermal.run import write_field_series

    if len(fields) > MAX_FIELDS:
        pick = np.unique(np.linspace(0, len(fields) - 1, MAX_FIELDS).round().astype(int))
        fields = [fields[i] for i in pick]
    with atomic_directory(out) as tmp:
        write_field_series(tmp, disc, mesh, fields)
        write_json(
            tmp / "summary.json",
            {
                "deck": result.deck,
                "metrics": result.metrics,
                "parts": result.parts,
                "heat_sources": result.sources,
                "increment_times_s": result.time_s.tolist(),
                "increment_max_change_k": result.max_change_k.tolist(),
                "metadata": result.metadata,
            },
        )
    result.out_dir = out


def format_deck(result: DeckResult) -> str:
    """A few lines for the terminal."""
    m = result.metrics
    lines = [
        f"{result.deck}: {m['nodes']['value']} nodes, {m['tetrahedra']['value']} tetrahedra, "
        f"{result.metadata['solver']}, {result.metadata['incrementation']}",
        f"  {m['increments']['value']} increments ({m['cutbacks']['value']} cut back) over "
        f"{m['time_period_s']['value']:g} s, {m['smallest_increment_s']['value']:.4g} to "
        f"{m['largest_increment_s']['value']:.4g} s; largest change {m['largest_change_k']['value']:.4g} K",
        f"  temperature {m['min_temp_c']['value']:.3f} to {m['max_temp_c']['value']:.3f} degC at the end",
    ]
    for key in ("heat_in_j", "heat_stored_j", "heat_to_films_j"):
        lines.append(f"  {key:<26}{m[key]['value']:>12.4f} J")
    lines.append(f"  {'energy_balance_relative':<26}{m['energy_balance_relative']['value']:>12.2e} -")
    for name, st in result.parts.items():
        lines.append(
            f"  part {name}: {st['min_temp_c']:.3f} / {st['mean_temp_c']:.3f} / {st['max_temp_c']:.3f} degC"
        )
    if result.out_dir is not None:
        lines.append(f"results written to {result.out_dir}/ (summary.json, temperature.pvd, fields/)")
    return "\n".join(lines)


def check_deck_options(length_scale_m: float, bonded_w_m2k: float | None) -> None:
    """Refuse non-physical command-line options (ConfigError)."""
    if not (np.isfinite(length_scale_m) and length_scale_m > 0):
        raise ConfigError(f"--length-scale {length_scale_m!r}: expected metres per deck unit, > 0.")
    if bonded_w_m2k is not None and not (np.isfinite(bonded_w_m2k) and bonded_w_m2k > 0):
        raise ConfigError(f"--bonded-w-m2k {bonded_w_m2k!r}: expected a conductance > 0 W/(m^2 K).")


__all__ = ["DeckResult", "check_deck_options", "format_deck", "run_deck"]

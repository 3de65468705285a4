"""Ageing during the drive (issue 12 item 4): every cell of a vehicle's pack ages with the
shipped ageing model (:mod:`hevsim.battery.ageing`: Wang 2011 cycle fade, Schmalstieg 2014
calendar fade and resistance growth) from the stress it saw in the run, and the state carries
from one run to the next.

* :class:`CellStress` accumulates, per cell and per step, the discharged charge, the mean
  absolute current while current flows, the Arrhenius weight of the core temperature, the SOC
  range and the mean SOC and temperature (the stress of :func:`hevsim.battery.ageing.stress_of`,
  vectorised over the cells; the mean OCV is the OCV table at the mean SOC and temperature).
* :class:`PackAgeState` holds one :class:`~hevsim.battery.ageing.AgeingState` per cell, applies
  it to a pack (capacity ``C0 x C/C0``, resistances ``x R/R0``) and advances it after a run
  by ``repetitions`` repetitions of that run's stress (the virtual time/throughput method, exact
  for a repeated stress); :meth:`PackAgeState.save` / :meth:`PackAgeState.load` carry it
  between runs (``--age-state FILE``, written atomically).
* the life over many drives (``hevsim life``) is a vehicle-level study: :mod:`hevsim.sim.life`.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.battery.ageing import (
    SECONDS_PER_HOUR,
    AgeingModel,
    AgeingState,
    Stress,
    advance,
    load_ageing_model,
    soh_capacity,
    soh_impedance,
)
from hevsim.errors import ConfigError, InputError

ACTIVATION_TEMPERATURE_K = 31700.0 / 8.314
"""Ea / R of the Arrhenius-effective temperature [K] (Wang 2011's 31.7 kJ/mol, as
:func:`hevsim.battery.ageing.stress_of`)."""
STATE_FORMAT = "hevsim-pack-age-state-1"
#: rows of :attr:`CellStress.data`: discharged charge [A s], sum of |current| [A], moving
#: steps, sum of ``exp(-Ea/(R T))``, sums of SOC and core temperature [K], SOC range
STRESS_ROWS = (
    "discharged_as", "abs_current_sum", "moving", "arrhenius_sum", "soc_sum", "temp_sum", "soc_min",
    "soc_max",
)  # fmt: skip


class CellStress:
    """Per-cell stress accumulated over the steps of a run (module docstring): the rows of
    :attr:`data` (:data:`STRESS_ROWS`, (8, n_cells)) and :attr:`counts` (steps, duration [s]),
    which the pack's compiled step also accumulates into (:func:`hevsim.battery.pack_run.pack_finish`)."""

    activation_k = ACTIVATION_TEMPERATURE_K

    def __init__(self, n_cells: int) -> None:
        self.data = np.zeros((len(STRESS_ROWS), n_cells))
        self.data[STRESS_ROWS.index("soc_min")] = np.inf
        self.data[STRESS_ROWS.index("soc_max")] = -np.inf
        self.counts = np.zeros(2)

    def __getattr__(self, name: str) -> Any:
        if name in STRESS_ROWS:
            return self.data[STRESS_ROWS.index(name)]
        raise AttributeError(name)

    @property
    def steps(self) -> int:
        return int(self.counts[0])

    @property
    def duration_s(self) -> float:
        return float(self.counts[1])

    def add(self, cells: np.ndarray, dt_s: float) -> None:
        """One step's per-cell record ``cells`` (n_cells, 5: current [A], SOC, core temperature
        [K], port heat [W], voltage [V]) of length ``dt_s`` [s]."""
        from hevsim.battery.pack_run import _stress_add

        cells = np.ascontiguousarray(cells, dtype=float)
        _stress_add(self.data, self.counts, cells, float(dt_s), self.activation_k)

    def stresses(self, pack: Any, soc_initial: np.ndarray, capacity_ah: np.ndarray) -> list[Stress]:
        """One :class:`~hevsim.battery.ageing.Stress` per cell: ``soc_initial`` [-] and the
        cells' present capacities ``capacity_ah`` [A h] (for the C-rate)."""
        if self.steps == 0:
            raise InputError("ageing: the run has no steps; expected at least one.")
        p = pack.params
        mean_soc = self.soc_sum / self.steps
        mean_t = self.temp_sum / self.steps
        ocv = 0.5 * (p.ocv_charge_v + p.ocv_discharge_v)
        col = np.abs(p.temperature_k[None, :] - mean_t[:, None]).argmin(axis=1)
        ocv_mean = np.array([np.interp(s, p.soc, ocv[:, j]) for s, j in zip(mean_soc, col, strict=True)])
        t_eff = -ACTIVATION_TEMPERATURE_K / np.log(self.arrhenius_sum / self.steps)
        c_rate = np.where(
            self.moving > 0, self.abs_current_sum / np.maximum(self.moving, 1) / capacity_ah, 0.0
        )
        lo = np.minimum(self.soc_min, soc_initial)
        hi = np.maximum(self.soc_max, soc_initial)
        return [
            Stress(self.duration_s, float(q / SECONDS_PER_HOUR), float(c), float(t), float(v), float(d))
            for q, c, t, v, d in zip(self.discharged_as, c_rate, t_eff, ocv_mean, hi - lo, strict=True)
        ]


@dataclass
class PackAgeState:
    """Ageing state of every cell of a pack (module docstring), plus the life so far: runs,
    repetitions, distance [m] and time [s] driven."""

    n_cells: int
    model: str = "wang2011_schmalstieg2014"
    cells: list[AgeingState] = field(default_factory=list)
    repetitions: int = 0
    distance_m: float = 0.0
    source: str = ""

    def __post_init__(self) -> None:
        if not self.cells:
            self.cells = [AgeingState() for _ in range(self.n_cells)]
        self._model: AgeingModel | None = None
        self._soc0: np.ndarray | None = None
        self.next_repetitions = 1
        """Repetitions of the next run's stress :meth:`end` adds (:func:`run_life` sets it)."""

    @property
    def ageing_model(self) -> AgeingModel:
        if self._model is None:
            self._model = load_ageing_model(self.model)
        return self._model

    def capacity_fraction(self) -> np.ndarray:
        """C / C0 per cell [-]."""
        return np.array([s.capacity_fraction for s in self.cells])

    def resistance_fraction(self) -> np.ndarray:
        """R / R0 per cell [-]."""
        return np.array([s.resistance_fraction for s in self.cells])

    def soh(self, x_c: float, x_z: float) -> np.ndarray:
        """SOH per cell, eqs 42-44 (SOH_C x SOH_Z) with the cell set's end-of-life fractions."""
        return np.asarray(soh_capacity(self.capacity_fraction(), 1.0, x_c)) * np.asarray(
            soh_impedance(self.resistance_fraction(), 1.0, x_z)
        )

    def _check(self, pack: Any) -> None:
        if pack.n_cells != self.n_cells:
            raise ConfigError(
                f"age state {self.source or '(new)'}: {self.n_cells} cells; the pack {pack.cfg.name} has "
                f"{pack.n_cells} cells; expected the age state of this pack."
            )

    def apply(self, pack: Any) -> None:
        """Age the cells of a fresh pack (its capacities and resistances)."""
        self._check(pack)
        pack.apply_ageing(self.capacity_fraction(), self.resistance_fraction())

    def begin(self, pack: Any) -> None:
        """Start tracking a run's stress (the pack's cells at their initial SOC)."""
        from hevsim.battery.kernel import SOCINI

        self._check(pack)
        self._soc0 = pack.prm[:, SOCINI].copy()
        pack.stress = CellStress(pack.n_cells)

    def end(self, pack: Any, result: Any = None) -> list[Stress]:
        """Advance every cell by :attr:`next_repetitions` repetitions of the run's stress;
        returns the stresses."""
        from hevsim.battery.kernel import SOCINI

        soc0 = self._soc0 if self._soc0 is not None else pack.prm[:, SOCINI]
        nominal = pack.params.nominal_capacity_ah
        cap = nominal * self.capacity_fraction() * pack._c0_new / pack.params.capacity.c0_c
        stresses = pack.stress.stresses(pack, soc0, cap)
        reps = int(self.next_repetitions)
        for state, s in zip(self.cells, stresses, strict=True):
            advance(self.ageing_model, state, s, nominal, reps)
        self.repetitions += reps
        if result is not None:
            self.distance_m += reps * float(result.metrics["distance_m"]["value"])
        pack.stress = None
        return stresses

    # -- files ---------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "format": STATE_FORMAT,
            "n_cells": self.n_cells,
            "model": self.model,
            "repetitions": self.repetitions,
            "distance_m": self.distance_m,
            "cells": {k: [getattr(s, k) for s in self.cells] for k in asdict(AgeingState())},
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "<dict>") -> PackAgeState:
        if not isinstance(data, dict) or data.get("format") != STATE_FORMAT:
            raise InputError(f"{source}: not a pack age state (expected format {STATE_FORMAT!r}).")
        n = int(data["n_cells"])
        cols = data.get("cells", {})
        keys = list(asdict(AgeingState()))
        if sorted(cols) != sorted(keys) or any(len(cols[k]) != n for k in keys):
            raise InputError(f"{source}: key 'cells' must hold {keys} with {n} values each.")
        cells = [AgeingState(**{k: float(cols[k][c]) for k in keys}) for c in range(n)]
        return cls(n, str(data["model"]), cells, int(data["repetitions"]), float(data["distance_m"]), source)

    def save(self, path: str | Path) -> None:
        """Write the state as JSON, atomically."""
        from hevsim.io import write_json

        write_json(path, self.to_dict())

    @classmethod
    def load(cls, path: str | Path) -> PackAgeState:
        """Read a state written by :meth:`save`."""
        p = Path(path)
        try:
            data = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise InputError(f"{p}: cannot read the age state ({exc}).") from exc
        return cls.from_dict(data, str(p))


def load_or_new_age_state(path: str | Path | None, n_cells: int) -> PackAgeState:
    """The age state in ``path`` when the file exists, else a new one (all cells new)."""
    if path is not None and Path(path).is_file():
        return PackAgeState.load(path)
    return PackAgeState(n_cells, source=str(path or ""))


__all__ = [
    "CellStress",
    "PackAgeState",
    "load_or_new_age_state",
]

"""The results of a forward simulation (:class:`SimulationResult`) and of a batch of variants
(:class:`BatchResult`), below every run that makes them (:mod:`hevsim.sim.forward`,
:mod:`hevsim.sim.series_run`, :mod:`hevsim.sim.pack_vehicle`, :mod:`hevsim.sim.simulator`, which
re-exports them)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from hevsim.architectures.series import SeriesHEV
from hevsim.components.engine import Engine
from hevsim.cycles import DriveCycle
from hevsim.figures import plotter
from hevsim.io import atomic_directory, write_json

CSV_AUTO_MAX_ROWS = 50_000
"""Longest time series [rows] that :meth:`SimulationResult.save` also writes as CSV unless
asked otherwise: about 3 s and 25 MB of CSV; longer runs get Parquet only (``--csv`` forces
CSV)."""


class _Deferred:
    """A :class:`SimulationResult` field that holds its value or a function of no arguments
    that makes it: the function runs on the first read and its value replaces it. The series
    kernel's run assembles its pandas time series and events table this way, so a caller
    that reads only metrics does not pay for them (about a third of a UDDS run's time)."""

    def __init__(self, name: str) -> None:
        self.slot = f"_{name}_value"

    def __get__(self, obj: Any, owner: Any = None) -> Any:
        if obj is None:
            return self
        value = obj.__dict__[self.slot]
        if isinstance(value, _Later):
            value = obj.__dict__[self.slot] = value.make()
        return value

    def __set__(self, obj: Any, value: Any) -> None:
        obj.__dict__[self.slot] = value


@dataclass(frozen=True)
class _Later:
    """A value to make on first read (:class:`_Deferred`)."""

    make: Any


@dataclass
class SimulationResult:
    """One forward simulation: time series, scalar metrics, energy audit, events, metadata.

    ``timeseries`` and ``events`` may be handed over as ``_Later(function)``: made on their
    first read (a pickle or copy makes them first)."""

    timeseries: pd.DataFrame
    metrics: dict[str, dict[str, Any]]
    energy_audit: dict[str, float]
    events: pd.DataFrame
    metadata: dict[str, Any]
    model: SeriesHEV
    cycle: DriveCycle
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def engine(self) -> Engine | None:
        """The engine of the simulated vehicle (for operating-point plots)."""
        return self.model.engine

    def value(self, name: str) -> float:
        """Value of metric ``name`` (in its unit)."""
        return float(self.metrics[name]["value"])

    def __getstate__(self) -> dict[str, Any]:
        _ = self.timeseries, self.events  # make the deferred fields: a function may not pickle
        return self.__dict__.copy()

    def save(self, out_dir: str | Path, plots: bool = True, csv: bool | None = None) -> Path:
        """Write the results folder atomically: time series (Parquet, and CSV for short runs
        or on request), metrics.json, energy_audit.json, events.csv, config.json and, with
        ``plots``, the PNG plots and report.md (the ``"simulation"`` plotter of
        :mod:`hevsim.figures`, which :mod:`hevsim.report` registers).

        ``csv`` None writes ``timeseries.csv`` only when the run has at most
        :data:`CSV_AUTO_MAX_ROWS` rows (CSV costs about 60 µs a row, Parquet a twentieth of
        that); True or False forces it on or off. Files are written to a temporary sibling
        folder that is renamed into place, so an interrupted run leaves no partial folder.
        An existing folder is replaced.
        """
        write_csv = len(self.timeseries) <= CSV_AUTO_MAX_ROWS if csv is None else bool(csv)
        with atomic_directory(out_dir) as tmp:
            self.timeseries.to_parquet(tmp / "timeseries.parquet", index=False)
            if write_csv:
                self.timeseries.to_csv(tmp / "timeseries.csv", index=False, float_format="%.6g")
            self.events.to_csv(tmp / "events.csv", index=False)
            write_json(tmp / "metrics.json", self.metrics)
            write_json(
                tmp / "energy_audit.json",
                {k: {"value": v, "unit": "J"} for k, v in self.energy_audit.items()},
            )
            write_json(tmp / "config.json", self.model.config.to_dict())
            write_json(tmp / "metadata.json", self.metadata)
            if plots:  # the report layer's plotter: every plot that applies and report.md
                plotter("simulation")(self, tmp)
        return Path(out_dir)


SimulationResult.timeseries = _Deferred("timeseries")  # type: ignore[assignment]


SimulationResult.events = _Deferred("events")  # type: ignore[assignment]


@dataclass
class BatchResult:
    """Scalar results of a batch of variants: one row per variant."""

    table: pd.DataFrame
    elapsed_s: float

    @property
    def rate_per_s(self) -> float:
        """Variant-cycles simulated per second of wall time."""
        return len(self.table) / self.elapsed_s if self.elapsed_s > 0 else float("inf")

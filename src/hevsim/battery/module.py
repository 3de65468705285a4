"""Modules and packs: n_s groups in series of n_p parallel cells (default 2s6p, thesis fig 4.6).

Parallel cells share the terminal voltage; the branch currents follow from it each step
(:func:`hevsim.battery.kernel.share_current` solves the affine branch relations exactly).
Each cell keeps its own SOC, heat and temperature. Cell-to-cell spread of capacity and
resistance is optional, drawn from a seeded normal distribution (reproducible).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from hevsim.battery import kernel as K
from hevsim.battery.cell import as_profile, check_cell_domain, check_dt
from hevsim.battery.params import CellParameters, load_cell_parameters
from hevsim.errors import InputError
from hevsim.io import atomic_directory, write_json
from hevsim.tables import FloatArray

CELL_CHANNELS = ("current_a", "soc", "temp_k", "heat_w")


@dataclass
class ModuleResult:
    """Module time series, per-cell channels ``cells[k, c, :]`` (:data:`CELL_CHANNELS`), metrics."""

    timeseries: pd.DataFrame
    cells: FloatArray
    metrics: dict[str, float]
    metadata: dict[str, Any] = field(default_factory=dict)

    def cell_frame(self, channel: str) -> pd.DataFrame:
        """One channel of every cell as a frame (columns ``cell_<c>_<channel>``)."""
        if channel not in CELL_CHANNELS:
            raise InputError(f"channel {channel!r} is not known; expected one of {', '.join(CELL_CHANNELS)}.")
        j = CELL_CHANNELS.index(channel)
        data = {f"cell_{c}_{channel}": self.cells[:, c, j] for c in range(self.cells.shape[1])}
        return pd.DataFrame(data, index=self.timeseries["time_s"])

    def save(self, out_dir: str | Path) -> Path:
        """Write ``timeseries.csv``, ``cells_<channel>.csv``, ``metrics.json``, ``metadata.json``."""
        with atomic_directory(out_dir) as tmp:
            self.timeseries.to_csv(tmp / "timeseries.csv", index=False)
            for ch in CELL_CHANNELS:
                self.cell_frame(ch).to_csv(tmp / f"cells_{ch}.csv")
            write_json(tmp / "metrics.json", self.metrics)
            write_json(tmp / "metadata.json", self.metadata)
        return Path(out_dir)


class Module:
    """n_s x n_p cells of one parameter set; cell ``c = s * n_p + b`` (series group s, branch b).

    Args:
        params: parameter set or its name/path.
        n_series, n_parallel: arrangement (default 2s6p).
        soc_initial [-], temp_k [K]: initial state of every cell.
        capacity_spread, resistance_spread: relative standard deviations [-] of C0 and of the
            resistances (R_s and RC) across cells (0 = identical cells).
        seed: random seed of the spread.
    """

    def __init__(
        self,
        params: CellParameters | str | Path,
        n_series: int = 2,
        n_parallel: int = 6,
        soc_initial: float = 1.0,
        temp_k: float = 298.15,
        capacity_spread: float = 0.0,
        resistance_spread: float = 0.0,
        seed: int = 0,
    ) -> None:
        self.params = params if isinstance(params, CellParameters) else load_cell_parameters(params)
        if n_series < 1 or n_parallel < 1:
            raise InputError(f"module: n_series {n_series!r} and n_parallel {n_parallel!r} must be >= 1.")
        for name, v in (("capacity_spread", capacity_spread), ("resistance_spread", resistance_spread)):
            if not 0.0 <= v < 0.3:
                raise InputError(f"module: {name} {v!r} must be in [0, 0.3) (a relative standard deviation).")
        if not 0.0 <= soc_initial <= 1.0:
            raise InputError(f"module: soc_initial {soc_initial!r} must be between 0 and 1.")
        self.n_series, self.n_parallel = int(n_series), int(n_parallel)
        n = self.n_cells
        rng = np.random.default_rng(seed)
        self.c0_scale = 1.0 + capacity_spread * rng.standard_normal(n)
        self.r_scale = 1.0 + resistance_spread * rng.standard_normal(n)
        self.p = np.stack(
            [self.params.vector(soc_initial, r, c) for r, c in zip(self.r_scale, self.c0_scale, strict=False)]
        )
        self.state = np.stack([self.params.initial_state(temp_k) for _ in range(n)])
        self.seed = seed

    @property
    def n_cells(self) -> int:
        """Number of cells."""
        return self.n_series * self.n_parallel

    def simulate(
        self,
        current_profile: npt.ArrayLike,
        dt: float,
        port_temperature: npt.ArrayLike = 298.15,
    ) -> ModuleResult:
        """Simulate the module over ``current_profile`` [A] (module current, discharge > 0).

        ``port_temperature`` [K]: scalar, one value per step, or an array (steps, cells).
        """
        t0 = time.perf_counter()
        dt = check_dt(dt)
        i = np.asarray(current_profile, dtype=float)
        if i.ndim != 1 or i.size == 0:
            raise InputError(f"current_profile: expected a non-empty 1-D array [A], got shape {i.shape}.")
        i = as_profile(i, i.size, "current_profile", "A")
        tp_in = np.asarray(port_temperature, dtype=float)
        if tp_in.ndim == 2:
            if tp_in.shape != (i.size, self.n_cells) or not np.all(np.isfinite(tp_in)):
                raise InputError(
                    f"port_temperature: expected shape ({i.size}, {self.n_cells}) of finite K, "
                    f"got {tp_in.shape}."
                )
            tp = np.ascontiguousarray(tp_in)
        else:
            tp = np.repeat(as_profile(tp_in, i.size, "port_temperature", "K")[:, None], self.n_cells, axis=1)
        self.params.check_temperature_coverage(tp, "the port temperature")
        out_m = np.empty((i.size, 4))
        out_c = np.empty((i.size, self.n_cells, len(CELL_CHANNELS)))
        tabs = self.params.tables()
        K.run_module(  # type: ignore[call-arg]
            self.p, *tabs, self.state, self.n_series, self.n_parallel, i, dt, tp, out_m, out_c
        )
        check_cell_domain(
            f"{self.n_series}s{self.n_parallel}p module of {self.params.name}",
            dt * np.arange(1, i.size + 1),
            i,
            out_m[:, 0],
            out_c[:, :, 2],
            soc=out_c[:, :, 1],
        )
        ts = pd.DataFrame(
            {
                "time_s": dt * np.arange(1, i.size + 1),
                "current_a": i,
                "voltage_v": out_m[:, 0],
                "voltage_avg_v": out_m[:, 1],
                "power_w": out_m[:, 1] * i,
                "heat_w": out_m[:, 2],
                "port_heat_w": out_m[:, 3],
                "max_cell_temp_k": out_c[:, :, 2].max(axis=1),
                "min_cell_soc": out_c[:, :, 1].min(axis=1),
                "max_cell_soc": out_c[:, :, 1].max(axis=1),
            }
        )
        metrics = {
            "duration_s": float(i.size * dt),
            "electrical_energy_out_j": float((out_m[:, 1] * i).sum() * dt),
            "heat_j": float(out_m[:, 2].sum() * dt),
            "min_voltage_v": float(out_m[:, 0].min()),
            "max_cell_temp_k": float(out_c[:, :, 2].max()),
            "final_soc_spread": float(out_c[-1, :, 1].max() - out_c[-1, :, 1].min()),
        }
        meta = {
            "cell": self.params.name,
            "n_series": self.n_series,
            "n_parallel": self.n_parallel,
            "seed": self.seed,
            "dt_s": dt,
            "elapsed_s": time.perf_counter() - t0,
        }
        return ModuleResult(ts, out_c, metrics, meta)

"""Vectorised batch of independent cells (one parallel compiled call)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

from hevsim.battery import kernel as K
from hevsim.battery.cell import check_dt
from hevsim.battery.params import CellParameters
from hevsim.errors import InputError

SUMMARY = (
    "min_voltage_v",
    "max_voltage_v",
    "max_temp_k",
    "electrical_energy_out_j",
    "heat_j",
    "final_voltage_v",
)


def simulate_cells(
    params: CellParameters,
    current: npt.ArrayLike,
    dt: float,
    port_temperature: npt.ArrayLike = 298.15,
    soc_initial: npt.ArrayLike = 1.0,
    temp_k: float = 298.15,
    r_scale: npt.ArrayLike = 1.0,
    c0_scale: npt.ArrayLike = 1.0,
    n_cells: int | None = None,
) -> tuple[pd.DataFrame, np.ndarray]:
    """Simulate many independent cells of one parameter set in parallel.

    ``current`` [A]: (steps,) shared by every cell or (cells, steps); ``port_temperature`` [K]
    scalar, (steps,) or (cells, steps); ``soc_initial``, ``r_scale``, ``c0_scale`` scalar or per
    cell. Returns (per-cell summary frame with columns :data:`SUMMARY`, final states
    (cells, states)).
    """
    dt = check_dt(dt)
    i = np.asarray(current, dtype=float)
    sizes = [np.size(a) for a in (soc_initial, r_scale, c0_scale) if np.ndim(a) > 0]
    n = n_cells or (i.shape[0] if i.ndim == 2 else (sizes[0] if sizes else 1))
    if i.ndim == 1:
        i = np.broadcast_to(i, (n, i.size))
    if i.ndim != 2 or i.shape[0] != n or not np.all(np.isfinite(i)):
        raise InputError(f"current: expected finite values of shape (steps,) or ({n}, steps), got {i.shape}.")
    i = np.ascontiguousarray(i)
    try:
        tp = np.ascontiguousarray(np.broadcast_to(np.asarray(port_temperature, float), i.shape))
        socs = np.broadcast_to(np.asarray(soc_initial, float), (n,))
        rs = np.broadcast_to(np.asarray(r_scale, float), (n,))
        cs = np.broadcast_to(np.asarray(c0_scale, float), (n,))
    except ValueError as exc:
        raise InputError(
            f"simulate_cells: inputs do not broadcast to {n} cells x {i.shape[1]} steps ({exc})."
        ) from exc
    prm = np.stack(
        [params.vector(float(s), float(r), float(c)) for s, r, c in zip(socs, rs, cs, strict=False)]
    )
    x = np.stack([params.initial_state(temp_k)] * n)
    summary = np.empty((n, len(SUMMARY)))
    K.run_batch(prm, *params.tables(), x, i, dt, tp, summary)  # type: ignore[call-arg]
    return pd.DataFrame(summary, columns=list(SUMMARY)), x

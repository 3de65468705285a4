"""Make ``calibration_pulse.csv``: a pulse test of a cell with known parameters, for ``hevsim calibrate``.

The cell is the shipped ``thesis_table_4_1`` set (0.8 A·h) with its stated values
(:data:`TRUTH`), at 23 °C ambient (heat port and initial temperature 296.15 K), from SOC 0.9.
The profile repeats, every 300 s: 60 s of 8 A discharge (10 C), 60 s of 4 A charge, 180 s of
rest, three times (900 one-second steps). The record uses the row convention of
``hevsim cell`` and ``hevsim calibrate`` (row k: the current over (t_k - 1 s, t_k], voltage
and temperature at t_k). Measurement noise is added with a fixed seed: voltage
N(0, :data:`SIGMA_V_V`), temperature N(0, :data:`SIGMA_T_K`).

Run ``python examples/make_calibration_pulse.py`` to rewrite the file (bit for bit the same),
then fit it::

    hevsim calibrate thesis_table_4_1 examples/calibration_pulse.csv --soc-initial 0.9 \\
        --ambient-c 23 --fit c_heat_j_per_k=60,10,500 r_skin_k_per_w=5,0.5,50 \\
        "rc_discharge[0].r_ohm=0.01,0.0001,0.1" "rc_discharge[0].tau_s=40,1,300"
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

CELL = "thesis_table_4_1"
TRUTH = {
    "c_heat_j_per_k": 96.0,
    "r_skin_k_per_w": 10.0,
    "rc_discharge[0].r_ohm": 0.005,
    "rc_discharge[0].tau_s": 20.0,
}
"""The parameters the record is made with (those of the shipped set)."""
SOC_INITIAL = 0.9
AMBIENT_K = 296.15
DT_S = 1.0
SIGMA_V_V = 0.002
SIGMA_T_K = 0.05
SEED = 20261201
OUT = Path(__file__).with_name("calibration_pulse.csv")


def pulse_current_a(n_steps: int = 900) -> np.ndarray:
    """The pulse profile [A], discharge > 0, one value per step of :data:`DT_S`."""
    t = np.arange(n_steps) * DT_S
    phase = t % 300.0
    return np.where(phase < 60.0, 8.0, np.where(phase < 120.0, -4.0, 0.0))


def make_record() -> pd.DataFrame:
    """The noisy test record (columns time_s, current_a, voltage_v, temp_k)."""
    from hevsim.battery import kernel as K
    from hevsim.battery import load_cell_parameters
    from hevsim.battery.cell import Cell

    params = load_cell_parameters(CELL)
    vec = params.vector(SOC_INITIAL)
    assert vec[K.CHEAT] == TRUTH["c_heat_j_per_k"] and vec[K.RSKIN] == TRUTH["r_skin_k_per_w"]
    assert tuple(params.rc_discharge[0]) == (TRUTH["rc_discharge[0].r_ohm"], TRUTH["rc_discharge[0].tau_s"])
    res = Cell(params, soc_initial=SOC_INITIAL, temp_k=AMBIENT_K).simulate(pulse_current_a(), DT_S, AMBIENT_K)
    ts = res.timeseries
    rng = np.random.default_rng(SEED)
    return pd.DataFrame(
        {
            "time_s": ts["time_s"],
            "current_a": ts["current_a"],
            "voltage_v": ts["voltage_v"] + rng.normal(0.0, SIGMA_V_V, len(ts)),
            "temp_k": ts["temp_k"] + rng.normal(0.0, SIGMA_T_K, len(ts)),
        }
    )


def write(path: str | Path = OUT) -> Path:
    """Write the record as CSV (fixed float format, so the file is reproducible)."""
    out = Path(path)
    make_record().to_csv(out, index=False, float_format="%.6f")
    return out


if __name__ == "__main__":
    print(f"written {write()}")

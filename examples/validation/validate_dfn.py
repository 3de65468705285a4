"""Validation study of issue 14 (docs/battery.md, "Validation against a DFN model").

Calibrates hevsim's cell on the DFN pulse test (``dfn_pulse.csv``) and validates it on the
DFN drive-cycle current (``dfn_udds.csv``), for two model structures:

* ``thesis``: the thesis's cell (charge/discharge RC sets switched with the current direction,
  linear resistance, OCV at the start of the step), fitted by the same pipeline;
* ``fidelity``: persistent RC pairs, the Butler-Volmer charge-transfer term and the OCV
  consistent within the step (the issue-14 options).

Run ``python examples/validation/validate_dfn.py [OUT_DIR]``: prints the error table per
current range and, with ``OUT_DIR``, writes both calibrations (``cell.toml``, plots, tables).

``python examples/validation/validate_dfn.py ambients [CELL ...]`` (issue 27): per cell (``nmc``,
``lfp``; the data of ``make_dfn_data.py ambients``) and validation ambient (-10, 10, 35,
45 degC), the UDDS errors per current band of the cell calibrated at 25 degC alone (before:
``calibrate pulse_25c.csv``) and calibrated over the three pulse tests at 0, 25 and 45 degC
(after: ``calibrate pulse_25c.csv --data pulse_0c.csv --data pulse_45c.csv``, the joint
temperature laws; for LFP with ``--robust-mv 2``, :data:`ROBUST_F_SCALE`).
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

from hevsim.battery.calibrate import CellTestRecord
from hevsim.battery.identify import (
    FIDELITY_MODEL,
    Identification,
    fit_temperature,
    fit_temperature_laws,
    identify,
    validate,
)
from hevsim.battery.params import ModelSection

HERE = Path(__file__).resolve().parent
STRUCTURES = {
    "thesis": {"model": ModelSection(), "charge_transfer": False},
    "fidelity": {"model": FIDELITY_MODEL, "charge_transfer": True},
}
SOC_INITIAL = 0.95  # the DFN pulse test starts at SOC 0.95 (make_dfn_data.py)
UDDS_SOC_INITIAL = 0.8  # and the drive cycle at SOC 0.8 (None: from the first voltage)
CAPACITY_AH = 5.0  # Chen2020 nominal capacity
AMBIENT_K = 298.15


def calibrate_and_validate(
    structure: str = "fidelity", n_rc: int = 2, udds_soc: float | None = UDDS_SOC_INITIAL
) -> Identification:
    """Calibrate ``structure`` on the pulse test and validate on the drive cycle started at
    ``udds_soc`` (None: the OCV inverse of its first voltage)."""
    pulse = CellTestRecord.from_csv(HERE / "dfn_pulse.csv")
    res = identify(
        "thesis_table_4_1",  # the base set supplies voltage limits and ageing factors only
        pulse,
        soc_initial=SOC_INITIAL,
        capacity_ah=CAPACITY_AH,
        port_temp_k=AMBIENT_K,
        n_rc=n_rc,
        **STRUCTURES[structure],  # type: ignore[arg-type]
    )
    udds = CellTestRecord.from_csv(HERE / "dfn_udds.csv")
    return validate(res, udds, soc_initial=udds_soc, port_temp_k=AMBIENT_K)


def main(out_dir: str | None = None) -> pd.DataFrame:
    """Error table of both structures (voltage in mV)."""
    rows = []
    for name in STRUCTURES:
        res = calibrate_and_validate(name)
        if out_dir:
            res.save(Path(out_dir) / name)
        assert res.validation_errors is not None
        tab = res.validation_errors.copy()
        tab.insert(0, "model", name)
        tab.insert(1, "fit_rmse_mv", 1e3 * res.rmse["voltage_v"])
        rows.append(tab)
    out = pd.concat(rows, ignore_index=True)
    for col in ("rmse_v", "max_abs_v", "mean_v"):
        out[col.replace("_v", "_mv")] = 1e3 * out.pop(col)
    print(out.to_string(index=False, float_format=lambda x: f"{x:.2f}"))
    return out


AMBIENT_CELLS = {"nmc": 5.0, "lfp": 2.3}
"""Cells of the ambient study and their capacities [A h] (make_dfn_data.CELLS)."""
CAL_AMBIENTS_C = (0, 25, 45)
VAL_AMBIENTS_C = (-10, 10, 35, 45)


def _name(cell: str, kind: str, t_c: int) -> str:
    return f"dfn_{cell}_{kind}_{'m' if t_c < 0 else ''}{abs(t_c)}c.csv"


ROBUST_F_SCALE = {"nmc": None, "lfp": 2.0}
"""Per cell: the joint fit's robust loss scale [in units of sigma_v = 1 mV] (``soft_l1``;
None: plain least squares). The LFP pulse tests' low-SOC knee (the voltage falls 0.5 V below
the lowest rest's OCV, a diffusion-limited response two RC pairs cannot follow; 360 mV error
at 25 degC) otherwise drags the capacity factors, entropic coefficients and initial SOCs."""


def ambient_calibrations(
    cell: str, n_rc: int = 2, rows: int | None = None, every: int = 1
) -> dict[str, Identification]:
    """The cell calibrated at 25 degC alone (``before``) and over 0, 25 and 45 degC
    (``after``); ``rows``: only the first rows of each pulse test (a reduced data set);
    ``every``: one row in ``every`` (the pulse tests' segments last multiples of 10 s, so with
    ``every`` dividing 10 the coarser record holds the same piecewise-constant current)."""

    def rec(kind: str, t_c: int) -> CellTestRecord:
        r = CellTestRecord.from_csv(HERE / _name(cell, kind, t_c))
        if rows is None and every == 1:
            return r
        sel = slice(every - 1, rows, every)
        return CellTestRecord(r.time_s[sel], r.current_a[sel], r.voltage_v[sel], r.temp_k[sel], r.source)

    ref = identify(
        "thesis_table_4_1",
        rec("pulse", 25),
        soc_initial=SOC_INITIAL,
        capacity_ah=AMBIENT_CELLS[cell],
        port_temp_k=298.15,
        n_rc=n_rc,
        **STRUCTURES["fidelity"],  # type: ignore[arg-type]
    )
    others = [rec("pulse", t) for t in CAL_AMBIENTS_C if t != 25]
    f_scale = ROBUST_F_SCALE[cell]
    robust = {} if f_scale is None else {"loss": "soft_l1", "f_scale": f_scale}
    return {"before": ref, "after": fit_temperature_laws(fit_temperature(ref, others), others, **robust)}


def ambient_table(cell: str, fits: dict[str, Identification] | None = None) -> pd.DataFrame:
    """Voltage RMS / max / mean per current band [mV] and temperature RMS [K] on the UDDS at
    each validation ambient, before and after."""
    fits = fits or ambient_calibrations(cell)
    out = []
    for t_c in VAL_AMBIENTS_C:
        udds = CellTestRecord.from_csv(HERE / _name(cell, "udds", t_c))
        for label, res in fits.items():
            val = validate(res, udds, soc_initial=UDDS_SOC_INITIAL, port_temp_k=273.15 + t_c)
            assert val.validation_errors is not None
            tab = val.validation_errors.copy()
            tab.insert(0, "cell", cell)
            tab.insert(1, "ambient_c", t_c)
            tab.insert(2, "calibration", label)
            out.append(tab)
    table = pd.concat(out, ignore_index=True)
    for col in ("rmse_v", "max_abs_v", "mean_v"):
        table[col.replace("_v", "_mv")] = 1e3 * table.pop(col)
    return table


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "ambients":
        pd.set_option("display.width", 200)
        for c in sys.argv[2:] or list(AMBIENT_CELLS):
            print(ambient_table(c).to_string(index=False, float_format=lambda x: f"{x:.2f}"))
    else:
        main(sys.argv[1] if len(sys.argv) > 1 else None)

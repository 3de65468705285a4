"""Validation study of issue 14 (docs/battery.md, "Validation against a DFN model").

Calibrates hevsim's cell on the DFN pulse test (``dfn_pulse.csv``) and validates it on the
DFN drive-cycle current (``dfn_udds.csv``), for two model structures:

* ``thesis``: the thesis's cell (charge/discharge RC sets switched with the current direction,
  linear resistance, OCV at the start of the step), fitted by the same pipeline;
* ``fidelity``: persistent RC pairs, the Butler-Volmer charge-transfer term and the OCV
  consistent within the step (the issue-14 options).

Run ``python examples/validation/validate_dfn.py [OUT_DIR]``: prints the error table per
current range and, with ``OUT_DIR``, writes both calibrations (``cell.toml``, plots, tables).
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

from hevsim.battery.calibrate import CellTestRecord
from hevsim.battery.identify import FIDELITY_MODEL, Identification, identify, validate
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


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)

"""The 2016 Prius's 0.75 kWh Li-ion pack (issue 11 item 5): the assembled 3.6 A·h cell is the
shipped Saft LI7 cell scaled in capacity (its meta.toml states how), and the shipped Prius
carries 56 of them."""

from __future__ import annotations

import csv
import tomllib
from pathlib import Path

import numpy as np
import pytest

from hevsim import config as C
from hevsim.architectures import architecture, build_vehicle

ROOT = Path(__file__).resolve().parents[1]
BATTERIES = ROOT / "src" / "hevsim" / "data" / "components" / "batteries"
ASSEMBLED = BATTERIES / "li_ion_3p6ah_prius_2016_assembled"
SAFT = BATTERIES / "saft_li_ion_6ah_li7"
PRIUS = ROOT / "examples" / "prius_2016_like_power_split.toml"
K = 3.6 / 7.035
"""Capacity factor of the assembly: 3.6 A·h over the Saft cell's 7.035 A·h at 25 degC [-]."""


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize(
    ("file", "column", "factor"),
    [("ocv.csv", "ocv_cell_V", 1.0), ("r_discharge.csv", "r_dis_cell_ohm", 1.0 / K),
     ("r_charge.csv", "r_chg_cell_ohm", 1.0 / K), ("capacity.csv", "max_capacity_Ah", K),
     ("capacity.csv", "coulombic_efficiency", 1.0)],
)  # fmt: skip
def test_assembled_cell_is_the_saft_cell_scaled(file: str, column: str, factor: float) -> None:
    """Every table value = the Saft value x the stated factor (rounded to 10 decimals), on the
    same axes."""
    ours, base = _rows(ASSEMBLED / file), _rows(SAFT / file)
    assert len(ours) == len(base)
    for a, b in zip(ours, base, strict=True):
        for axis in ("temperature_degC", "soc_fraction"):
            assert a.get(axis) == b.get(axis)
        assert float(a[column]) == pytest.approx(float(b[column]) * factor, rel=1e-9, abs=1e-10)


def test_assembled_cell_metadata_states_the_scaling() -> None:
    meta = tomllib.loads((ASSEMBLED / "meta.toml").read_text(encoding="utf-8"))
    asm = meta["assembly"]
    assert asm["base"] == SAFT.name and asm["capacity_ah_25degC"] / asm["base_capacity_ah_25degC"] == K
    assert "ASSEMBLED" in meta["description"] and "license" in meta["source"]
    provenance = (ROOT / "src" / "hevsim" / "data" / "PROVENANCE.md").read_text(encoding="utf-8")
    assert ASSEMBLED.name in provenance


def test_shipped_prius_pack_is_56_cells_of_3p6_ah() -> None:
    """56 x 3.6 A·h: 0.72 kWh by the OCV curve (0.75 kWh rated with 3.7 V cells), about 200 V,
    and the pack resistance is 56 x the cell's (the Saft cell's / K) at 25 degC."""
    cfg = C.load_vehicle_config(PRIUS)
    hev = architecture("power_split").build(cfg)
    pack = hev.battery
    assert cfg.battery.n_series == 56 and cfg.battery.n_parallel == 1
    assert pack.capacity_ah == pytest.approx(3.6, rel=1e-9)
    soc = np.linspace(0.0, 1.0, 2001)
    ocv = np.array([float(pack.ocv(s)) for s in soc])
    energy_kwh = float(np.sum(0.5 * (ocv[1:] + ocv[:-1]) * np.diff(soc))) * 3.6 / 1e3
    assert 0.70 < energy_kwh < 0.76
    assert 195.0 < float(pack.ocv(0.5)) < 205.0
    saft_r = {float(r["soc_fraction"]): float(r["r_dis_cell_ohm"]) for r in _rows(SAFT / "r_discharge.csv")
              if r["temperature_degC"] == "25"}  # fmt: skip
    r_pack = pack.resistance(0.6, 1.0)
    assert float(r_pack) == pytest.approx(56 * saft_r[0.6] / K, rel=1e-6)


def test_full_battery_takes_no_charge_from_any_source() -> None:
    """At ``soc_max`` nothing charges the battery, the engine through MG1 included: an ECMS
    that overvalues charge (s = 3.5) on HWFET stays within one step's charge of soc_max = 0.95
    (it ended at SOC 1.048 before), the compiled run equal to the Python loop; and a run whose
    SOC left [0, 1] would stop with a DomainError (hevsim.sim.forward)."""
    from hevsim.sim.forward import simulate_architecture

    ecms = {"controller.kind": "ecms", "controller.equivalence_factor": 3.5}
    cfg = C.load_vehicle_config(PRIUS).replace(**ecms)
    model = build_vehicle(cfg)
    runs = [simulate_architecture("power_split", model, "hwfet", compiled=c) for c in (True, False)]
    socs = [r.timeseries["soc"].to_numpy() for r in runs]
    assert socs[0].max() >= 0.95  # the case reaches the full battery
    step_charge = 20e3 / (56 * 3.6 * 3600 * 3.3)  # about 20 kW for 1 s on the 0.75 kWh pack
    assert socs[0].max() <= 0.95 + step_charge, socs[0].max()
    np.testing.assert_allclose(socs[0], socs[1], rtol=1e-9, atol=1e-12)

"""Issue 24, "how we know it works": the energy audit closes to round-off for every
architecture x battery model on full UDDS and US06 runs.

The audit (fuel + battery chemical energy = road losses + kinetic energy + brakes + component
losses, :func:`hevsim.sim.metrics` ``energy_audit_residual_pct``) is accumulated with the
same numbers that move the states, so its residual is round-off: below 1e-9 % of the traction
energy on every row, the issue's bound. Rows: the shipped example of each architecture with
its table battery; the same vehicle with a ``cell`` battery (the thesis cell, one RC pair);
the shipped ``*_pack.toml`` vehicle with its whole pack (every cell, module thermal model,
cooling loop, BMS). The conventional car has no traction battery: table row only.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import hevsim

try:
    from tests.test_cell_forward import cell_car
except ImportError:  # pytest put tests/ itself on the path
    from test_cell_forward import cell_car  # type: ignore[no-redef]

EX = Path(__file__).resolve().parents[1] / "examples"
AUDIT_PCT = 1e-9
"""Largest energy-audit residual [% of traction energy] (issue 24)."""

VEHICLES = {  # architecture -> (table-battery example, cell pack n_series x n_parallel, pack example)
    "series": ("series_hev.toml", (100, 6), "series_hev_pack.toml"),
    "parallel_p3": ("parallel_hev.toml", (100, 6), "parallel_hev_pack.toml"),
    "parallel_p2": (
        "high_performance_parallel_hev.toml",
        (100, 6),
        "high_performance_parallel_hev_pack.toml",
    ),
    "power_split": ("prius_like_power_split.toml", (60, 8), "prius_like_power_split_pack.toml"),
    "bev": ("bev.toml", (100, 40), "bev_pack.toml"),
    "fcev": ("fcev.toml", (100, 6), "fcev_pack.toml"),
    "conventional": ("conventional_sedan.toml", None, None),
}
ROWS = [
    (arch, battery, cycle)
    for arch, (_, cell, pack) in VEHICLES.items()
    for battery in ("table", "cell", "pack")
    if battery == "table" or (battery == "cell" and cell) or (battery == "pack" and pack)
    for cycle in ("udds", "us06")
]


@pytest.mark.parametrize(("arch", "battery", "cycle"), ROWS, ids=["-".join(r) for r in ROWS])
def test_energy_audit_closes_for_every_architecture_and_battery_model(
    arch: str, battery: str, cycle: str, tmp_path: Path
) -> None:
    table, cell, pack = VEHICLES[arch]
    if battery == "table":
        path = EX / table
    elif battery == "cell":
        assert cell is not None
        path = cell_car(tmp_path, table, *cell)
    else:
        path = EX / str(pack)
    res = hevsim.simulate(str(path), cycle)
    residual = res.metrics["energy_audit_residual_pct"]["value"]
    assert abs(residual) < AUDIT_PCT, (arch, battery, cycle, residual)
    # the run did the work the audit checks: the whole cycle, a battery that moved
    ts = res.timeseries
    assert float(ts["time_s"].iloc[-1]) > 590.0
    if battery != "table" or arch != "conventional":
        assert ts["soc"].max() - ts["soc"].min() > 1e-4

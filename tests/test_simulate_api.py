"""``hevsim.simulate``: the one entry point (issue 24 item 1) for every architecture, with the
pack's ambient, soak and cooling options."""

from __future__ import annotations

from pathlib import Path

import pytest

import hevsim
from hevsim.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"


def test_top_level_names_are_the_simulator_functions() -> None:
    from hevsim.sim import simulator

    assert hevsim.simulate is simulator.simulate
    assert hevsim.simulate_batch is simulator.simulate_batch
    with pytest.raises(AttributeError, match="no attribute 'simulat'"):
        hevsim.simulat  # noqa: B018


@pytest.mark.parametrize(
    "example", ["series_hev", "parallel_hev", "prius_like_power_split", "conventional_sedan", "bev"]
)
def test_every_architecture_from_a_path(example: str) -> None:
    res = hevsim.simulate(EX / f"{example}.toml", "udds")
    assert type(res).__name__ == "SimulationResult"
    for key in ("mpgge", "l_per_100km", "co2_g_per_km", "energy_audit_residual_pct"):
        assert key in res.metrics, (example, key)
    assert res.metrics["energy_audit_residual_pct"]["value"] < 1e-9
    assert res.timeseries["time_s"].iloc[-1] == pytest.approx(1369.0)


def test_pack_ambient_options_change_the_pack(tmp_path: Path) -> None:
    """The BEV with a pack soaked at 0 degC against 25 degC: a colder pack, the same trace."""
    cold = hevsim.simulate(EX / "bev_pack.toml", "udds", ambient_c=0.0, soak=True)
    warm = hevsim.simulate(EX / "bev_pack.toml", "udds", ambient_c=25.0, soak=True)
    t_cold = cold.metrics["pack_peak_cell_temp_c"]["value"]
    t_warm = warm.metrics["pack_peak_cell_temp_c"]["value"]
    assert t_cold < 5.0 < 25.0 < t_warm
    assert cold.metrics["soc_final"]["value"] < warm.metrics["soc_final"]["value"]  # less capacity cold


def test_pack_options_without_a_pack_are_refused() -> None:
    with pytest.raises(
        ConfigError, match=r"ambient_c=\.\.\.\) sets the pack's .* needs \[battery\] model = 'pack'"
    ):
        hevsim.simulate(EX / "bev.toml", "udds", ambient_c=0.0)

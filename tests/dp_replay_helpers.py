"""Shared check of the DP vehicle tests (test_dp_vehicle_parallel, test_dp_vehicle_series)."""

from __future__ import annotations

import numpy as np

from hevsim.optimal import OptimizationResult


def assert_replay_matches_dp(run: OptimizationResult, fuel: float, soc: np.ndarray) -> None:
    """A forward replay of ``run``'s decisions gives its fuel within 0.5 % (issue 3; in fact
    its DP total cost to 1e-9) and its SOC trace to 1e-9."""
    dp_fuel = float(run.value("fuel_kg"))
    assert abs(fuel - dp_fuel) <= 0.005 * dp_fuel  # issue 3: within 0.5 %
    assert abs(fuel - run.dp.total_cost) <= 1e-9 * dp_fuel  # in fact exact
    assert np.max(np.abs(soc - run.timeseries["soc"].to_numpy())) < 1e-9

"""Mesh-quality overshoot (issue 15, item 5): source-free nodes above their physical bound are
counted in the summary, and algebraic flux correction (stiffness = "afc") removes them."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import scipy.sparse as sp

pytest.importorskip("skfem")
pytest.importorskip("gmsh")

from hevsim.errors import ConfigError
from hevsim.thermal.run import (
    OVERSHOOT_WARN_K,
    dmp_diffusion,
    format_summary,
    run_thermal,
    thermal_config_from_dict,
)


def _run(**sim: Any) -> Any:
    # a 30 degC module without heat on the 15 degC coolant: nothing may exceed 30 degC
    data = {
        "geometry": {"mesh_size_m": 0.01},
        "simulation": {"duration_s": 10.0, "dt_s": 1.0, "cell_heat_w": [0.0], **sim},
        "output": {"field_every_s": 0.0, "pictures": 0},
    }
    return run_thermal(thermal_config_from_dict(data, "over.toml"), None)


def test_overshoot_is_counted_and_flux_correction_removes_it() -> None:
    gal = _run()
    m = gal.metrics
    assert m["overshoot_nodes"]["value"] > 0 and 0.0 < m["overshoot_max_k"]["value"] < OVERSHOOT_WARN_K
    assert m["module_max_temp_c"]["value"] > 30.0 + 1e-3  # the Galerkin overshoot is real
    summary = format_summary(gal)
    assert "overshoot (nodes, max)" in summary and 'stiffness = "afc"' not in summary
    afc = _run(stiffness="afc")
    a = afc.metrics
    assert a["overshoot_nodes"]["value"] == 0 and a["overshoot_max_k"]["value"] <= 1e-7
    assert a["module_max_temp_c"]["value"] <= 30.0 + 1e-9
    assert abs(a["energy_balance_relative"]["value"]) <= 1e-9
    assert 1 <= afc.metadata["afc_max_iterations"] < 1000
    assert a["heat_removed_j"]["value"] > 100.0


def test_summary_suggests_the_correction_above_the_threshold() -> None:
    res = _run(capacity="consistent")  # the consistent capacity overshoots by kelvins
    assert res.metrics["overshoot_max_k"]["value"] > OVERSHOOT_WARN_K
    assert 'stiffness = "afc" removes it' in format_summary(res)


def test_afc_needs_implicit_euler_and_lumped_capacity() -> None:
    for sim in ({"theta": 0.5}, {"capacity": "consistent"}):
        with pytest.raises(ConfigError, match=r"'simulation\.stiffness' = \"afc\" needs theta = 1"):
            thermal_config_from_dict({"simulation": {"stiffness": "afc", **sim}}, "over.toml")
    with pytest.raises(ConfigError, match=r"simulation\.stiffness"):
        thermal_config_from_dict({"simulation": {"stiffness": "upwind"}}, "over.toml")


def test_low_order_diffusion_makes_an_m_matrix_with_the_same_row_sums() -> None:
    rng = np.random.default_rng(3)
    a = sp.random(30, 30, density=0.2, random_state=rng)
    k = sp.csr_matrix(a + a.T) - sp.diags(np.asarray((a + a.T).sum(axis=1)).ravel() * 0.5)
    d = dmp_diffusion(k)
    low = (k + d).toarray()
    off = low - np.diag(np.diag(low))
    assert off.max() <= 0.0 and (k.toarray() - np.diag(k.diagonal())).max() > 0.0
    np.testing.assert_allclose(low.sum(axis=1), k.toarray().sum(axis=1), atol=1e-12)
    np.testing.assert_allclose(d.toarray(), d.toarray().T)
    assert np.linalg.eigvalsh(d.toarray()).min() > -1e-12  # added diffusion: positive semi-definite

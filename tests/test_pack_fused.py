"""The pack's one compiled pass per step (:func:`hevsim.battery.pack.pack_pass_linear` and
:func:`~hevsim.battery.pack.pack_pass`, with the next step's affine pairs formed in the same
pass) against the per-function reference it replaced in :class:`~hevsim.battery.pack.Pack`:
:func:`~hevsim.battery.pack.pack_thevenin` for each direction, then
:func:`~hevsim.battery.pack.pack_step` (``share_current`` + ``cell_step`` per cell). Same
currents, cell records, energies and pairs to 1e-9 (they are the same operations: bit for bit
on one machine), with the linear cells, the nonlinear model options and after the cells' state
was edited (ageing)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hevsim.battery.kernel import CTI0, CTM, HGAMMA, HMAX
from hevsim.battery.pack import Pack, load_pack_config, pack_step, pack_thevenin

EX = Path(__file__).resolve().parents[1] / "examples"


def _pack(n_modules: int = 6) -> Pack:
    cfg = load_pack_config(EX / "vehicle_pack.toml")  # 2s6p modules with capacity and resistance spread
    return Pack(replace(cfg, pack=replace(cfg.pack, n_modules=n_modules)))


def _current(steps: int) -> np.ndarray:
    t = np.arange(float(steps))
    return 90.0 * np.sin(t / 23.0) + 20.0 * np.sign(np.sin(t / 4.0)) * (t % 50 < 35)


def _compare(pack: Pack, steps: int, edit_at: int = -1) -> int:
    """Step ``pack`` (the vehicle's order: both pairs, then the step) and, on copies of its
    arrays, the reference functions; compare every step. Returns the steps whose pairs were
    compared."""
    prm, x = pack.prm.copy(), pack.x.copy()
    tabs, dt = pack.params.tables(), pack.cfg.pack.dt_s
    ng, n_p = pack.n_groups_sim, pack.n_p_sim
    g_new = [np.empty(ng) for _ in range(4)]
    g_ref = [np.empty(ng) for _ in range(4)]
    out_ref, out_new = np.empty((pack.n_cells, 5)), np.empty((pack.n_cells, 5))
    energy_ref = np.zeros(4)
    compared = 0
    for k, i_a in enumerate(_current(steps)):
        if k == edit_at:  # ageing between steps: the stored pairs must follow the new cells
            fade = np.linspace(0.85, 0.95, pack.n_cells)
            pack.apply_ageing(fade, 2.0 - fade)
            prm[:] = pack.prm
        ref = [pack_thevenin(prm, *tabs, x, ng, n_p, dt, d, g_ref[2 * j], g_ref[2 * j + 1])
               for j, d in enumerate((1.0, -1.0))]  # fmt: skip
        new = [pack.thevenin(d, g_new[2 * j], g_new[2 * j + 1]) for j, d in enumerate((1.0, -1.0))]
        np.testing.assert_allclose(new, ref, rtol=1e-9, atol=0)
        for a, b in zip(g_new, g_ref, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=0)
        compared += 1
        start = pack.begin_step()
        port = pack.port_k.copy()
        v_ref = pack_step(prm, *tabs, x, ng, n_p, float(i_a), dt, port, out_ref, energy_ref)
        row, _ = pack.finish_step(start, float(i_a), cells_out=out_new)
        np.testing.assert_allclose([row["voltage_v"], row["voltage_avg_v"]], v_ref, rtol=1e-9, atol=0)
        np.testing.assert_allclose(out_new, out_ref, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(pack._energy_buf, energy_ref, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(pack.x, x, rtol=1e-9, atol=1e-12)
    return compared


def test_linear_pass_equals_reference_functions() -> None:
    """Thesis cells with spread (the linear pass): 300 steps, both directions, rests."""
    pack = _pack()
    assert pack._linear()
    assert _compare(pack, 300) == 300


def test_linear_pass_follows_edited_cells() -> None:
    """Ageing applied between steps (:meth:`Pack.apply_ageing` -> :meth:`Pack.state_changed`)."""
    assert _compare(_pack(), 120, edit_at=60) == 120


@pytest.mark.parametrize("option", ["charge_transfer", "hysteresis"])
def test_nonlinear_cells_use_the_general_pass(option: str) -> None:
    """Nonlinear options: the general pass (share_current relinearises) still equals the reference."""
    pack = _pack(3)
    if option == "charge_transfer":
        pack.prm[:, CTI0], pack.prm[:, CTM] = 2.0, 1.0
    else:
        pack.prm[:, HMAX], pack.prm[:, HGAMMA] = 0.02, 5.0
    pack.state_changed()
    assert not pack._linear()
    assert _compare(pack, 150) == 150

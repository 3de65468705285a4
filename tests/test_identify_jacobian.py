"""The identification's analytic Jacobian (issue 14, speed): the kernel's forward sensitivities
and their mapping to the fitted parameters agree with central finite differences."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hevsim.battery import identify as ID
from hevsim.battery import kernel as K
from hevsim.battery import load_cell_parameters
from hevsim.battery.calibrate import CellTestRecord
from hevsim.battery.params import ChargeTransferSection, ModelSection

T_AMB = 298.15


def _cell(ocv_mode: str, ea: float):
    """Persistent 2-RC cell with a wavy OCV (kinks inside the tested SOC range), charge transfer
    with an activation energy (the temperature path of the voltage) and a short thermal time."""
    p = load_cell_parameters("thesis_table_4_1")
    soc = np.array([0.0, 0.5, 0.7, 0.8, 0.85, 0.9, 1.0])
    ocv = (3.3 + 0.8 * soc + 0.05 * np.sin(9 * soc))[:, None]
    rs = (0.02 + 0.01 * soc)[:, None]
    rc = np.array([[0.01, 20.0], [0.02, 300.0]])
    return dataclasses.replace(
        p, soc=soc, temperature_k=np.array([T_AMB]), capacity_factor=np.ones(1),
        ocv_charge_v=ocv, ocv_discharge_v=ocv.copy(), rs_charge_ohm=rs, rs_discharge_ohm=rs.copy(),
        rc_discharge=rc, rc_charge=rc.copy(),
        model=ModelSection(rc_mode="persistent", ocv_mode=ocv_mode),
        charge_transfer=ChargeTransferSection(i0_a=1.0, scale=1.3, ea_j_per_mol=ea),
        resistance=dataclasses.replace(p.resistance, alpha_rs_per_k=0.0),
        capacity=dataclasses.replace(p.capacity, alpha_c_per_k=0.0),
        thermal=dataclasses.replace(p.thermal, c_heat_j_per_k=20.0, r_skin_k_per_w=5.0),
    )  # fmt: skip


def _record() -> CellTestRecord:
    rng = np.random.default_rng(3)
    cur = np.r_[np.repeat(rng.uniform(-4.0, 4.0, 40), 15), np.zeros(100), np.full(300, 2.5)]
    t = np.arange(1.0, cur.size + 1.0)
    return CellTestRecord(t, cur, t * 0.0, t * 0.0 + T_AMB)


def _tables(p):
    tabs = (p.soc, p.temperature_k, p.ocv_discharge_v, p.rs_discharge_ohm, p.capacity_factor, p.rc_discharge)
    return [a.copy() for a in tabs]


def _run(vec, tabs, rec):
    n = rec.time_s.size
    out = np.empty((n, len(K.RECORD)))
    x = np.zeros(K.N_FIXED_STATES + 2 * tabs[5].shape[0])
    x[K.STEMP], x[K.SDIR] = T_AMB, 1.0
    soc, t_ax, ocv, rs, capf, rc = tabs
    K.run_cell(vec, soc, t_ax, ocv, ocv, rs, rs, capf, rc, rc, x, rec.current_a, 1.0, np.full(n, T_AMB), out)
    return out


@pytest.mark.parametrize(("ocv_mode", "ea"), [("step_consistent", 3.0e4), ("start_of_step", 0.0)])
def test_kernel_sensitivities_match_finite_differences(ocv_mode: str, ea: float) -> None:
    p = _cell(ocv_mode, ea)
    rec = _record()
    vec = p.vector(0.9)
    dv, dtemp = ID._sensitivities(p, rec, 0.9, T_AMB)
    out = _run(vec, _tables(p), rec)
    # the values of the sensitivity run are the plain kernel's, bit for bit
    out_s = np.empty_like(out)
    cols = K.sensitivity_columns(p.soc.size, 2)
    x = p.initial_state(T_AMB)
    soc, t_ax, ocv, rs, capf, rc = _tables(p)
    n = rec.time_s.size
    K.run_cell_sensitivity(vec, soc, t_ax, ocv, rs, capf, rc, x, rec.current_a, 1.0, np.full(n, T_AMB), out_s,
                           np.empty_like(dv), np.empty_like(dv))  # fmt: skip
    assert np.array_equal(out, out_s)

    def perturbation(col: int):  # (where, index, step) of sensitivity column ``col``
        ns = p.soc.size
        if col < ns:
            return 2, (col, 0), 1e-4
        if col < 2 * ns:
            return 3, (col - ns, 0), 1e-6
        if col < 2 * ns + 2:
            return 5, (col - 2 * ns, 0), 1e-6
        if col < 2 * ns + 4:
            return 5, (col - 2 * ns - 2, 1), 1e-3
        scalar = {cols["ct_i0_a"]: K.CTI0, cols["ct_scale"]: K.CTM}
        scalar |= {cols["c_heat_j_per_k"]: K.CHEAT, cols["r_skin_k_per_w"]: K.RSKIN}
        return None, scalar[col], 1e-5

    checked = 0
    for col in range(cols["n"]):
        where, index, h = perturbation(col)
        fd = []
        for sign in (1.0, -1.0):
            v2, tabs = vec.copy(), _tables(p)
            if where is None:
                v2[index] += sign * h
            else:
                tabs[where][index] += sign * h
            fd.append(_run(v2, tabs, rec))
        gv = (fd[0][:, K.RV] - fd[1][:, K.RV]) / (2 * h)
        gt = (fd[0][:, K.RTEMP] - fd[1][:, K.RTEMP]) / (2 * h)
        for analytic, numeric in ((dv[:, col], gv), (dtemp[:, col], gt)):
            scale = max(np.max(np.abs(numeric)), 1e-12)
            assert np.max(np.abs(analytic - numeric)) <= 1e-5 * scale + 1e-12, col
            checked += scale > 1e-9
    assert checked >= 20  # most columns move both the voltage and the temperature


def test_ocv_map_jacobian_matches_finite_differences() -> None:
    axis = np.array([0.0, 0.1, 0.2, 0.4, 0.6, 0.8, 0.9, 1.0])
    idx = np.arange(2, 7)
    init = np.linspace(3.0, 4.2, axis.size)
    ocv_map = ID._OcvMap(init, idx, axis, 2.5, 4.2, extrapolate=True)
    for theta in (np.array([3.4, 3.6, 3.7, 3.9, 4.1]), np.array([3.4, 3.6, 3.55, 3.9, 4.15])):  # 2nd: a dip
        v, g = ocv_map(theta)
        assert np.all(np.diff(v) >= 0) and v.max() <= 4.2
        num = np.empty_like(g)
        for j in range(theta.size):
            e = np.zeros_like(theta)
            e[j] = 1e-7
            num[:, j] = (ocv_map(theta + e)[0] - ocv_map(theta - e)[0]) / 2e-7
        np.testing.assert_allclose(g, num, atol=1e-6)
    assert np.any(g[:2] != 0) and np.all(g[-1] == 0)  # extrapolated low end moves; the top is clipped


@pytest.mark.parametrize("thin", [1, ID.REST_THIN])
def test_identify_jacobian_matches_finite_differences(monkeypatch: pytest.MonkeyPatch, thin: int) -> None:
    """The Jacobian ``identify`` hands to the optimiser, at the initial guess, against central
    differences of its residual: covers the mapping to OCV, log R_s, log RC and log ct; every
    row, and the rests thinned (``thin_rests``)."""
    p = _cell("step_consistent", 0.0)
    seg = [(0.0, 600)]
    for _ in range(3):
        seg += [(5.0, 10), (0.0, 40), (-10.0, 10), (0.0, 40), (5.0, 300), (0.0, 600)]
    cur = np.concatenate([np.full(d, c) for c, d in seg])
    t = np.arange(1.0, cur.size + 1.0)
    v, temp = ID._simulate(p, CellTestRecord(t, cur, t * 0, t * 0 + T_AMB), 0.95, T_AMB, T_AMB)
    rec = CellTestRecord(t, cur, v, temp)
    seen = {}

    class Captured(Exception):
        pass

    def fake(fun, x0, **kw):
        seen.update(fun=fun, x0=x0, jac=kw["jac"])
        raise Captured

    monkeypatch.setattr(ID, "_least_squares", fake)
    with pytest.raises(Captured):
        ID.identify(
            p, rec, soc_initial=0.95, capacity_ah=p.capacity.c0_c / 3600, port_temp_k=T_AMB, thin_rests=thin
        )
    fun, x0, jac = seen["fun"], seen["x0"], seen["jac"]
    analytic = jac(x0)
    rows, w = ID._row_selection(rec, thin=thin)  # thinned: one row in `thin` after 300 s of a rest
    assert analytic.shape == (rows.size, x0.size) and (rows.size < t.size) == (thin > 1)
    np.testing.assert_allclose(np.sum(w**2), t.size, atol=ID.REST_THIN)  # stands for every row
    for j in range(x0.size):
        e = np.zeros_like(x0)
        e[j] = 1e-6
        numeric = (fun(x0 + e) - fun(x0 - e)) / 2e-6
        scale = max(np.max(np.abs(numeric)), 1e-9)
        assert np.max(np.abs(analytic[:, j] - numeric)) <= 1e-4 * scale, j


def test_analytic_jacobian_needs_persistent_rc() -> None:
    from hevsim.errors import InputError

    p = _cell("step_consistent", 0.0)
    rec = _record()
    rec = CellTestRecord(
        rec.time_s, np.r_[np.zeros(400), rec.current_a[400:]], rec.current_a * 0 + 3.7, rec.temp_k
    )
    with pytest.raises(InputError, match="analytic Jacobian needs rc_mode"):
        ID.identify(p, rec, soc_initial=0.9, min_rest_s=60, model=ModelSection(), jacobian="analytic")


def test_row_selection_keeps_every_row_under_current_and_thins_late_rests() -> None:
    """Every row under current and the first minute of each rest, then one row in
    ``REST_THIN`` with weight sqrt(REST_THIN); ``thin = 1`` keeps every row unweighted."""
    cur = np.r_[np.zeros(200), np.full(30, 5.0), np.zeros(95), np.full(7, -2.0), np.zeros(61)]
    t = np.arange(1.0, cur.size + 1.0)
    rec = CellTestRecord(t, cur, t * 0 + 3.7, t * 0 + T_AMB)
    rows, w = ID._row_selection(rec, keep_s=60.0, thin=10)
    kept = np.zeros(cur.size, bool)
    kept[rows] = True
    assert kept[cur != 0].all() and np.all(w[cur[rows] != 0] == 1.0)
    for a, b in ((0, 200), (230, 325), (332, 393)):  # the three rests
        assert kept[a : a + 60].all() and np.all(w[(rows >= a) & (rows < a + 60)] == 1.0)
        late = rows[(rows >= a + 60) & (rows < b)]
        assert np.all(np.diff(late) == 10) and np.allclose(w[np.isin(rows, late)], np.sqrt(10.0))
        assert abs(late.size * 10 - (b - a - 60)) < 10  # the weights stand for the rows skipped
    rows1, w1 = ID._row_selection(rec, thin=1)
    assert np.array_equal(rows1, np.arange(cur.size)) and np.all(w1 == 1.0)

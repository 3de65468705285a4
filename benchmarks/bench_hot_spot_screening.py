"""Screening of the pack's all-nodes ROM hot spot (issue 26 item 5): how many rows each bound evaluates.

Since the slack screening (``[module] hot_spot_slack_k``, :func:`hevsim.battery.pack_run.
_module_hot_spots_within`) the first lines time it against the exact screening (slack 0) in the
same run and check that every hot spot is within the slack below the exact one.

Run from the repository root after building the module ROM of ``examples/pack.toml``::

    .venv/bin/hevsim rom build examples/module_thermal.toml   # results/module_thermal.rom.npz
    .venv/bin/python benchmarks/bench_hot_spot_screening.py [--pack P] [--steps 600] [--kernel-only]

The pack's compiled step (:func:`hevsim.battery.pack_run._module_hot_spots`) takes each module's
hot spot as the maximum of ``G_j w`` over every node row ``j`` of its cells, evaluating only the
rows whose bound can reach the largest value found; those rows are evaluated in single precision
with a rounding bound, and the few that can still be the largest in double. The script first
times ``Pack.simulate`` under US06 with the kernel evaluating the rows in double
(``hs_const[0] = 0``, the screening before the single-precision pass) and as shipped, alternated
in the same run, and checks that every module's hot spot is bit-identical (``--kernel-only``
stops after the next part): it replays the run's modal states through the compiled screening
with the modules screened together (as the pack does: a row's single-precision coefficients
are read once per step for every module) and one module per call (each module reads its rows
itself, as before), checking that both give the same hot spots. Then it keeps the modules'
modal states and replays them offline through other exact screenings, counting the rows each
one evaluates and the multiply-adds per module step relative to the kernel in double
(``rows x order``; the variants add their own per-row work):

* ``anchor``: a full evaluation when the deviation has moved ``thr`` (in |G|max |d - d_a| K)
  from the anchor ``d_a``, rows bounded by ``|G_j| (|d - d_a| + |d_j - d_a|)`` (norm of the
  change instead of the kernel's sum of per-step changes);
* ``modal k``: the ``k`` slowest modes' change since the anchor exact per row (``k`` per row),
  the rest bounded by ``|G_j,fast| |w_fast - w_a,fast|``;
* ``step k``: stateless, from the step itself: ``G w = G p + G diag(c) w_old`` with the input
  part ``p`` exact (``m_in`` per row in a kernel), ``k`` slow modes of the memory part exact and the
  rest bounded by ``|G_j,fast c_fast| |w_old,fast|`` (``c = 1/(1 + lambda dt)``);
* ``float32 pass``: every row in single precision with its rounding bound
  ``(r + 2) 2^-24 sum_i |G_ji d_i|``, then in double the rows whose bound reaches the largest;
* per-cell truncated SVD of the rows (idea: ``T_c ~ U_k S_k W_k^T d``): the singular values and
  the largest ``|d|`` seen, whose product is the added error of a truncation.

Every variant's maximum is checked against the all-rows maximum. The script only reports.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import OtherLoad

ROOT = Path(__file__).resolve().parents[1]


def screen(b: np.ndarray, g: np.ndarray, w: np.ndarray) -> int:
    """Evaluate the row of the largest bound, then every row whose bound exceeds the best value;
    checks the maximum against all rows; returns the rows evaluated."""
    j = int(np.argmax(b))
    best = float(g[j] @ w)
    need = np.nonzero(b > best)[0]
    found = max(best, float((g[need] @ w).max())) if need.size else best
    exact = float((g @ w).max())
    assert abs(found - exact) <= 1e-9 * max(1.0, abs(exact)), (found, exact)
    return 1 + int(need.size)


def replay(cfg, current: np.ndarray) -> tuple[float, float, float, float, float]:  # type: ignore[no-untyped-def]
    """The compiled screening (:func:`hevsim.battery.pack_run._module_hot_spots`) on the modal
    states of a pack run at ``current``: the modules screened together (as the pack does) and
    one module per call with its own arrays (each module reads the rows it needs itself, as
    before the modules were screened together); both give the same hot spots, checked. Returns
    the best of 3 [us per module step], wall and process CPU time, and the rows read per
    module step together."""
    from threadpoolctl import threadpool_limits

    from hevsim.battery import pack_run as R
    from hevsim.battery.pack import Pack

    pack = Pack(cfg)
    states = []
    for i_a in current:
        pack.step(float(i_a))
        states.append(pack.arrays.rom_w.copy())
    n_mod = states[0].shape[0]
    per = len(states) * n_mod

    def fresh() -> list:  # type: ignore[type-arg]
        s = Pack(cfg).arrays
        alone = [
            s._replace(f=s.f.copy(), hs_ub=s.hs_ub[m : m + 1].copy(), hs_prev=s.hs_prev[m : m + 1].copy(),
                       hs_blk=s.hs_blk[m : m + 1].copy(), hs_d32=s.hs_d32[m : m + 1].copy(),
                       hs_cand=s.hs_cand[m : m + 1].copy())
            for m in range(n_mod)
        ]  # fmt: skip
        return [s, alone]

    hot, hot1 = np.empty(n_mod), np.empty(n_mod)
    times: dict[str, list[tuple[float, float]]] = {"together": [], "alone": [], "slack": []}
    reads = 0.0
    for _ in range(3):
        s, alone = fresh()
        t0, c0 = time.perf_counter(), time.process_time()
        for w in states:
            R._module_hot_spots(s, w, hot)
        times["together"].append((time.perf_counter() - t0, time.process_time() - c0))
        reads = s.f[R.F_HSREAD] / per
        t0, c0 = time.perf_counter(), time.process_time()
        for w in states:
            for m in range(n_mod):
                R._module_hot_spots(alone[m], w[m : m + 1], hot1[m : m + 1])
        times["alone"].append((time.perf_counter() - t0, time.process_time() - c0))
        sw = s._replace(f=s.f.copy())
        sw.f[R.F_HSEPS] = cfg.module.hot_spot_slack_k or 0.01
        with threadpool_limits(1, user_api="blas"):  # its basis updates call BLAS (as Pack.simulate)
            t0, c0 = time.perf_counter(), time.process_time()
            for w in states:
                R._module_hot_spots_within(sw, w, hot)
            times["slack"].append((time.perf_counter() - t0, time.process_time() - c0))
    s, alone = fresh()
    for w in states:
        R._module_hot_spots(s, w, hot)
        for m in range(n_mod):
            R._module_hot_spots(alone[m], w[m : m + 1], hot1[m : m + 1])
        assert np.array_equal(hot, hot1), (hot, hot1)
    best = {k: (min(t[0] for t in v) / per * 1e6, min(t[1] for t in v) / per * 1e6) for k, v in times.items()}
    print(f"    slack screening  {best['slack'][0]:6.1f} / {best['slack'][1]:6.1f} us per module step "
          "(R._module_hot_spots_within, its basis shared by the modules)")  # fmt: skip
    return best["together"][0], best["alone"][0], best["together"][1], best["alone"][1], reads


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--pack", default=str(ROOT / "examples" / "pack.toml"))
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--kernel-only", action="store_true", help="only the compiled kernel, double vs single")
    args = ap.parse_args()
    from hevsim.battery import pack_run as R
    from hevsim.battery.pack import Pack, load_pack_config
    from hevsim.battery.profiles import cycle_cell_current
    from hevsim.errors import HevsimError

    try:
        cfg = load_pack_config(args.pack)
        pack = Pack(cfg)
    except HevsimError as exc:
        print(f"bench_hot_spot_screening: {exc}", file=sys.stderr)
        return 2
    rom = pack.rom
    if rom is None:
        msg = f'bench_hot_spot_screening: {args.pack} has no ROM; expected [module] thermal = "rom"'
        print(msg, file=sys.stderr)
        return 2
    steps = args.steps
    current = 6.0 * cycle_cell_current("us06", duration_s=steps, dt_s=cfg.pack.dt_s)
    n_mod = cfg.pack.n_modules
    # the compiled kernel in double (hs_const[0] = 0, the screening before issue 26's single-
    # precision pass), the exact screening (slack 0: single, then double) and the slack screening
    # ([module] hot_spot_slack_k, default 0.01 K: R._module_hot_spots_within), alternated, same run
    modes = ("double", "single", "slack")
    runs: dict[str, list[float]] = {k: [] for k in modes}
    cpu: dict[str, list[float]] = {k: [] for k in modes}
    hots: dict[str, np.ndarray] = {}
    rows: dict[str, tuple[float, float]] = {}
    slack_k = cfg.module.hot_spot_slack_k or 0.01
    basis: dict[str, float] = {}

    def fresh(mode: str) -> Pack:
        p = Pack(cfg)
        p._modal["hs_const"][0] = 0.0 if mode == "double" else p._modal["hs_const"][0]
        p._f[R.F_HSEPS] = slack_k if mode == "slack" else 0.0
        return p

    with OtherLoad() as load:
        for mode in modes + modes:
            fresh(mode).simulate(current[:2])  # compile outside the timing
            p = fresh(mode)
            t0, c0 = time.perf_counter(), time.process_time()
            res = p.simulate(current)
            runs[mode].append(time.perf_counter() - t0)
            cpu[mode].append(time.process_time() - c0)
            ts = res.timeseries
            hots[mode] = ts[[c for c in ts.columns if "hot_spot" in c]].to_numpy()
            per = steps * n_mod
            rows[mode] = (p._f[R.F_HSROWS] / per, p._f[R.F_HSROWS64] / per)
            if mode == "slack":
                basis = {"size": p._f[R.F_HSK], "adds": p._f[R.F_HSADDS], "rebuilds": p._f[R.F_HSREBUILDS],
                         "gap": p._f[R.F_HSGAP], "kept": p._f[R.F_HSREUSE] / per}  # fmt: skip
    diff = hots["single"] - hots["slack"]
    print(
        f"slack screening (hot_spot_slack_k = {slack_k:g} K): {rows['slack'][1]:.2f} rows in double per "
        f"module step, basis {basis['size']:.0f} directions ({basis['adds']:.0f} added, "
        f"{basis['rebuilds']:.0f} rebuilds), {basis['kept']:.3f} of the module steps keep a full screen, "
        f"largest certified gap {basis['gap'] * 1e3:.2f} mK; "
        "vs the exact hot spots: "
        f"{diff.min() * 1e3:.3f} to {diff.max() * 1e3:.3f} mK below (must be 0 to {slack_k * 1e3:g})"
    )
    assert diff.min() >= -1e-9 and diff.max() <= slack_k + 1e-9, (diff.min(), diff.max())
    c_e, c_w = (min(cpu[k]) / (steps * n_mod) * 1e6 for k in ("single", "slack"))
    print(f"  exact (slack 0)    {min(runs['single']):.3f} s, CPU {c_e:5.1f} us per module step")
    print(f"  slack {slack_k:g} K      {min(runs['slack']):.3f} s, CPU {c_w:5.1f} us per module step; "
          f"CPU ratio {c_e / c_w:.2f}x (whole pack step: cells, ROM, loop, hot spot)")  # fmt: skip
    together_us, alone_us, cpu_together_us, cpu_alone_us, reads = replay(cfg, current)
    same = bool(np.array_equal(hots["double"], hots["single"]))
    t_d, t_s = min(runs["double"]), min(runs["single"])
    c_d, c_s = (min(cpu[k]) / (steps * n_mod) * 1e6 for k in ("double", "single"))
    print(
        f"pack.simulate, {steps} s of US06, {n_mod} modules (best of 2; other load "
        f"{load.cores if load.cores is not None else float('nan'):.2f} cores):"
    )
    us_d, us_s = (t / (steps * n_mod) * 1e6 for t in (t_d, t_s))
    print(f"  kernel in double   {t_d:.3f} s = {us_d:6.1f} us (CPU {c_d:5.1f}) per module step, "
          f"{rows['double'][0]:.0f} rows per module step")  # fmt: skip
    print(f"  single then double {t_s:.3f} s = {us_s:6.1f} us (CPU {c_s:5.1f}) per module step, "
          f"{rows['single'][0]:.0f} rows in single and {rows['single'][1]:.1f} in double per module step; "
          f"ratio {t_d / t_s:.2f}x; hot spots identical: {same}")  # fmt: skip
    print("  the screening alone, replaying the run's modal states (best of 3, wall / process CPU):")
    print(f"    modules together {together_us:6.1f} / {cpu_together_us:6.1f} us per module step "
          f"({reads:.0f} single-precision rows read per module step)")  # fmt: skip
    print(f"    one at a time    {alone_us:6.1f} / {cpu_alone_us:6.1f} us per module step (as before); "
          f"ratio {alone_us / together_us:.2f}x (CPU {cpu_alone_us / cpu_together_us:.2f}x)")  # fmt: skip
    if args.kernel_only:
        return 0
    run_s = t_d
    base_rows = rows["double"][0]
    pack = Pack(cfg)
    zs = []
    for k in range(steps):
        pack.step(float(current[k]))
        zs.append(pack.rom_state_z().copy())
    q, decay = pack._modal["q"], pack._modal["rom_decay"]
    r, nc = rom.order, rom.n_cells
    per_cell = [np.unique(p, axis=0) for p in np.asarray(rom.out_candidates).reshape(nc, -1, r)]
    g = np.vstack(per_cell) @ q
    w_all = np.array(zs) @ q  # (steps, modules, r)
    gn = np.linalg.norm(g, axis=1)
    n = g.shape[0]
    m_in = pack._modal["rom_in"].shape[0]
    print(f"ROM order {r}, {n} rows per module, {n_mod} modules, {steps} steps; inputs {m_in}")
    print(
        f"baseline (compiled kernel in double): {base_rows:.0f} rows per module step; simulate {run_s:.3f} s"
    )
    base = base_rows * r

    def report(name: str, rows: float, per_row: float) -> None:
        ratio = (n * per_row + rows * r) / base
        print(f"  {name:<22s} rows evaluated {rows:7.0f}  multiply-adds vs baseline {ratio:5.2f}")

    u_m, e_m = rom.unit_state @ q, rom.energy @ q
    for thr in (0.5, 2.0):
        ev = 0
        for m in range(n_mod):
            y = yt = da = de = None
            for k in range(steps):
                w = w_all[k, m]
                tref = float(e_m @ w / (e_m @ u_m))
                d = w - tref * u_m
                dist = float(np.linalg.norm(d - da)) if da is not None else 0.0
                if y is None or gn.max() * dist > thr:
                    y, yt, da, de = g @ w, np.full(n, tref), d, np.zeros(n)
                    ev += n
                    continue
                b = y + (tref - yt) + gn * (dist + de) + 1e-9
                j = int(np.argmax(b))
                need = np.union1d(np.nonzero(b > float(g[j] @ w))[0], [j])
                ev += screen(b, g, w)
                y[need], yt[need], de[need] = g[need] @ w, tref, dist
        report(f"anchor thr {thr:g} K", ev / steps / n_mod, 0.0)
    for kk in (5, 20):
        gs, gf = g[:, :kk], np.linalg.norm(g[:, kk:], axis=1)
        ev = 0
        for m in range(n_mod):
            wa = None
            for k in range(steps):
                w = w_all[k, m]
                df = float(np.linalg.norm(w[kk:] - wa[kk:])) if wa is not None else 0.0
                if wa is None or gf.max() * df > 0.5:
                    y, wa = g @ w, w.copy()
                    ev += n
                    continue
                ev += screen(y + gs @ (w - wa)[:kk] + gf * df + 1e-9, g, w)
        report(f"modal k {kk}", ev / steps / n_mod, kk)
    c = decay / cfg.pack.dt_s
    for kk in (0, 20):
        gs, gf = g[:, :kk] * c[:kk], np.linalg.norm(g[:, kk:] * c[kk:], axis=1)
        ev = 0
        for m in range(n_mod):
            for k in range(1, steps):
                w0, w = w_all[k - 1, m], w_all[k, m]
                b = g @ (w - c * w0) + gs @ w0[:kk] + gf * float(np.linalg.norm(w0[kk:])) + 1e-9
                ev += screen(b, g, w)
        report(f"step k {kk}", ev / (steps - 1) / n_mod, m_in + kk)
    # every row in single precision with its rounding bound, then the candidates in double
    g32, g_abs, counts, worst = g.astype(np.float32), np.abs(g), [], 0.0
    for w in w_all.reshape(-1, r):
        tref = float(e_m @ w / (e_m @ u_m))
        d = w - tref * u_m
        approx = (g32 @ d.astype(np.float32)).astype(float)
        bound = (r + 2) * 2.0**-24 * (g_abs @ np.abs(d)) * 1.01 + 1e-12
        worst = max(worst, float(bound.max()))
        need = np.nonzero(approx + bound >= float((approx - bound).max()))[0]
        found, exact = tref + float((g[need] @ d).max()), float((g @ w).max())
        assert abs(found - exact) <= 1e-9 * abs(exact), (found, exact)
        counts.append(need.size)
    print(f"  float32 pass           rows in double {np.mean(counts):7.1f} (at most {max(counts)}), "
          f"rounding bound at most {worst:.2g} K; the pass multiplies all {n} rows in float32")  # fmt: skip
    proj = np.eye(r) - np.outer(u_m, e_m) / (e_m @ u_m)
    d_max = max(float(np.linalg.norm(proj @ w)) for w in w_all.reshape(-1, r))
    s = np.linalg.svd(per_cell[0] @ q @ proj, compute_uv=False)
    print(f"  per-cell SVD (cell 0, {s.size} values): s1 {s[0]:.3g}, s10 {s[9]:.3g}, s25 {s[24]:.3g}, "
          f"s50 {s[49]:.3g}; largest |d| {d_max:.3g}: truncation at rank 50 adds up to "
          f"{s[50] * d_max:.3g} K")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""DP refinement tables: states and inputs refined separately, against independent optima.

Issue 26 item 6. Two problems with an optimum known independently of the DP:

* the two-tank benchmark of Elbert et al. (2013) (``tests/test_dp_two_tank_elbert.py``:
  discrete optimum 1.382831 in closed form, checked there by scipy's LP solver), target
  ``x(2) >= (0.5, 0.5)``, level-set method;
* the double integrator ``p' = v, v' = u`` (exact zero-order hold, ``dt = 0.05``, 20 steps)
  moved from rest at 0 to the exact point target ``(p, v) = (0.7, 0)`` with minimum
  ``sum dt u^2``: the discrete optimum is ``dt e' (G G')^-1 e`` with ``G`` the
  controllability matrix of the 20 steps (minimum-norm input, no DP involved).

For each size the error against the optimum, the final state's distance from the target
and the fallback / landing counts are printed. Run it on two trees to compare (the numbers
in ``docs/dp.md`` are ``main`` before issue 26 and the branch after)::

    .venv/bin/python benchmarks/bench_dp_refinement.py [--quick]
    PYTHONPATH=/path/to/other/src .venv/bin/python benchmarks/bench_dp_refinement.py

``--no-fwd-refine`` switches off the forward pass's input refinement in the cell the
level set's admission boundary cuts (``_solver.FWD_REFINE``), to compare with and without
it in one run. Reports and never asserts (exit 0). CPU seconds per solution are printed
(wall time on a shared machine is the load's).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import hevsim
from hevsim.errors import DPInfeasibleError
from hevsim.optimal import DPProblem, FinalTarget, _solver, solve_dp

# --------------------------------------------------------------------------- two tanks
DT_TT = 0.01
N_TT = 200
A_TT = 1.0 - 0.5 * DT_TT


def two_tank_optimum() -> float:
    n = int(np.floor(np.log(0.5) / np.log(A_TT)))
    f = (0.5 - (1.0 - A_TT**n)) / (0.5 * DT_TT * A_TT**n)
    return DT_TT * (n + f)


def two_tank(n_x: int, n_u: int) -> DPProblem:
    u = np.linspace(0.0, 1.0, n_u)

    def model(states, inputs, k, data):  # type: ignore[no-untyped-def]
        x1, x2 = states
        u1, u2 = inputs
        nxt = (x1 + DT_TT * (-0.5 * x1 + u1 * u2), x2 + DT_TT * (-0.5 * x2 + u1 * (1.0 - u2)))
        return nxt, DT_TT * (u1 + 0.1 * np.abs(u2 - 0.5)), None

    grid = np.linspace(0.0, 1.0, n_x)
    return DPProblem(model, [grid, grid], [u, u], N_TT, target=FinalTarget([0.5, 0.5], None))


# ------------------------------------------------------------------ double integrator
N_DI = 20
DT_DI = 1.0 / N_DI
XF_DI = np.array([0.7, 0.0])


def double_integrator_optimum(n_steps: int = N_DI, dt: float = DT_DI) -> float:
    """Minimum ``sum dt u^2`` from rest at 0 to ``XF_DI`` (controllability matrix)."""
    a = np.array([[1.0, dt], [0.0, 1.0]])
    b = np.array([[0.5 * dt * dt], [dt]])
    g = np.hstack([np.linalg.matrix_power(a, n_steps - 1 - k) @ b for k in range(n_steps)])
    u = g.T @ np.linalg.solve(g @ g.T, XF_DI)
    return float(dt * u @ u)


def double_integrator(n_x: int, n_u: int, n_steps: int = N_DI, u_max: float = 5.0) -> DPProblem:
    dt = 1.0 / n_steps

    def model(states, inputs, k, data):  # type: ignore[no-untyped-def]
        p, v = states
        (u,) = inputs
        return (p + dt * v + 0.5 * dt * dt * u, v + dt * u), dt * u * u, None

    grids = [np.linspace(-0.2, 1.0, n_x), np.linspace(-0.5, 1.5, n_x)]
    return DPProblem(
        model, grids, [np.linspace(-u_max, u_max, n_u)], n_steps,
        target=FinalTarget(list(XF_DI), list(XF_DI)), state_names=["p", "v"],
    )  # fmt: skip


def row(label: str, p: DPProblem, x0: list[float], j_star: float, lo: np.ndarray, hi: np.ndarray) -> None:
    c0 = time.process_time()
    try:
        res = solve_dp(p, x0)
    except DPInfeasibleError as exc:
        cpu = time.process_time() - c0
        print(f"{label:>16}  refused ({str(exc)[:90]}...) {cpu:6.1f}", flush=True)
        return
    cpu = time.process_time() - c0
    miss = float(np.max(np.maximum(np.maximum(lo - res.states[-1], res.states[-1] - hi), 0.0)))
    err = 100.0 * (res.total_cost / j_star - 1.0)
    land = getattr(res, "n_landing_steps", "-")
    nums = f"{res.total_cost:10.6f} {err:+9.3f} {miss:9.2e} {res.n_fallback_steps:5d} {land!s:>5}"
    print(f"{label:>16} {nums} {cpu:6.1f}", flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="smaller sizes only")
    ap.add_argument("--no-fwd-refine", action="store_true", help="grid inputs only in the forward pass")
    args = ap.parse_args()
    if args.no_fwd_refine:
        _solver.FWD_REFINE = False
    print(f"hevsim from {hevsim.__file__}; forward input refinement {_solver.FWD_REFINE}")
    head = f"{'grid (states x inputs)':>16} {'cost':>10} {'error %':>9} {'x_N miss':>9} "
    head += f"{'fallb':>5} {'land':>5} {'cpu s':>6}"
    j_tt = two_tank_optimum()
    lo_tt, hi_tt = np.array([0.5, 0.5]), np.array([1.0, 1.0])
    print(f"\ntwo tanks, optimum {j_tt:.6f}: states refined (11 values per input)\n{head}")
    for n in (41, 51) if args.quick else (41, 51, 101, 201):
        row(f"{n}^2 x 11^2", two_tank(n, 11), [0.0, 0.0], j_tt, lo_tt, hi_tt)
    sizes = ((51,),) if args.quick else ((51,), (101,))
    for (n,) in sizes:
        print(f"two tanks: inputs refined ({n}^2 states)\n{head}")
        for m in (11, 21, 41):
            row(f"{n}^2 x {m}^2", two_tank(n, m), [0.0, 0.0], j_tt, lo_tt, hi_tt)
    j_di = double_integrator_optimum()
    print(f"\ndouble integrator to (0.7, 0), optimum {j_di:.6f}: states refined (101 inputs)\n{head}")
    for n in (41, 61) if args.quick else (41, 61, 81):
        row(f"{n}^2 x 101", double_integrator(n, 101), [0.0, 0.0], j_di, XF_DI, XF_DI)
    print(f"double integrator: inputs refined (61^2 states)\n{head}")
    for m in (51, 101) if args.quick else (51, 101, 201):
        row(f"61^2 x {m}", double_integrator(61, m), [0.0, 0.0], j_di, XF_DI, XF_DI)
    if not args.quick:
        print(f"double integrator: the grids of issue 26 (both refined)\n{head}")
        for n, m in ((81, 201), (161, 401)):
            row(f"{n}^2 x {m}", double_integrator(n, m), [0.0, 0.0], j_di, XF_DI, XF_DI)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Study analysis: Pareto fronts and sensitivity rankings (pure numpy).

- :func:`pareto_mask`: the non-dominated rows of a table of objectives.
- :func:`sobol_indices`: first-order and total Sobol indices from a Saltelli design
  (Saltelli et al. 2010, Comput. Phys. Commun. 181: first order ``mean(f_B (f_ABi - f_A)) /
  V``; total, Jansen's ``mean((f_A - f_ABi)^2) / 2V``), with bootstrap standard errors.
- :func:`regression_ranking`: standardized regression coefficients (SRC) of a linear
  least-squares fit, with its R^2 (the ranking is meaningful when R^2 is near 1).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

BOOTSTRAP = 200
"""Bootstrap resamples for the standard errors of Sobol indices [-]."""


def pareto_mask(objectives: np.ndarray, maximize: np.ndarray | None = None) -> np.ndarray:
    """Boolean mask of the non-dominated rows of ``objectives`` (n, k).

    Columns are minimized, except where ``maximize`` (k booleans) is true. A row with a
    non-finite objective is never on the front. Row a dominates row b when it is no worse in
    every objective and better in at least one; equal rows are all kept.
    """
    f = np.asarray(objectives, dtype=np.float64)
    if f.ndim != 2:
        raise ValueError(f"objectives must be 2-D (rows x objectives), got shape {f.shape}")
    if maximize is not None:
        f = np.where(np.asarray(maximize, dtype=bool)[None, :], -f, f)
    ok = np.all(np.isfinite(f), axis=1)
    idx = np.flatnonzero(ok)
    mask = np.zeros(f.shape[0], dtype=bool)
    if idx.size == 0:
        return mask
    order = idx[np.lexsort(f[idx].T[::-1])]  # by first objective, ties by the next ones
    front: list[int] = []
    for i in order.tolist():
        if front:
            kept = f[front]
            dominated = np.any(np.all(kept <= f[i], axis=1) & np.any(kept < f[i], axis=1))
            if dominated:
                continue
        front.append(i)
    mask[front] = True
    return mask


def sobol_indices(
    f_a: np.ndarray, f_b: np.ndarray, f_ab: np.ndarray, *, bootstrap: int = BOOTSTRAP, seed: int = 0
) -> pd.DataFrame:
    """First-order ``S1`` and total ``ST`` Sobol indices of each of the ``d`` inputs.

    Args:
        f_a, f_b: outputs at the A and B matrices (n,). f_ab: outputs at AB_i (d, n).
        bootstrap: resamples for the standard errors ``S1_se``, ``ST_se`` (0: none).

    Returns:
        One row per input (index 0..d-1): S1, S1_se, ST, ST_se.
    """
    fa, fb, fab = (np.asarray(x, dtype=np.float64) for x in (f_a, f_b, f_ab))
    n = fa.size

    def est(sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b, ab = fa[sel], fb[sel], fab[:, sel]
        var = np.var(np.concatenate([a, b]))
        if var == 0.0:
            return np.full(ab.shape[0], np.nan), np.full(ab.shape[0], np.nan)
        s1 = np.mean(b[None, :] * (ab - a[None, :]), axis=1) / var
        st = 0.5 * np.mean((a[None, :] - ab) ** 2, axis=1) / var
        return s1, st

    s1, st = est(np.arange(n))
    out = pd.DataFrame({"S1": s1, "S1_se": np.nan, "ST": st, "ST_se": np.nan})
    if bootstrap > 0 and n > 1:
        rng = np.random.default_rng(seed)
        draws = [est(rng.integers(0, n, n)) for _ in range(bootstrap)]
        out["S1_se"] = np.std([d[0] for d in draws], axis=0, ddof=1)
        out["ST_se"] = np.std([d[1] for d in draws], axis=0, ddof=1)
    return out


def regression_ranking(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """(SRC per column of ``x`` (n, d), R^2) of the least-squares fit of ``y`` on ``x``.

    Columns of ``x`` that do not vary get SRC 0. Non-finite rows are dropped.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    ok = np.isfinite(y) & np.all(np.isfinite(x), axis=1)
    x, y = x[ok], y[ok]
    src = np.zeros(x.shape[1])
    if y.size < 3 or np.std(y) == 0.0:
        return np.full(x.shape[1], np.nan), float("nan")
    sx = np.std(x, axis=0)
    live = sx > 0
    if not np.any(live):
        return src, 0.0
    z = (x[:, live] - x[:, live].mean(axis=0)) / sx[live]
    zy = (y - y.mean()) / np.std(y)
    coef, *_ = np.linalg.lstsq(np.column_stack([z, np.ones(y.size)]), zy, rcond=None)
    src[live] = coef[:-1]
    resid = zy - np.column_stack([z, np.ones(y.size)]) @ coef
    r2 = 1.0 - float(np.sum(resid**2) / np.sum(zy**2))
    return src, r2

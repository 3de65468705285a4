"""Design-of-experiments samples of a study's parameters (pure numpy / scipy.stats.qmc).

Every function returns a ``(n, d)`` float array of parameter values, one row per sample, in
the order of the parameters given. Integer parameters are rounded to the nearest integer
inside their range (their interval is widened by half a unit on each side first, so every
integer is equally likely).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

METHODS = ("grid", "list", "lhs", "sobol", "saltelli")
"""Sampling methods: full-factorial ``grid``, zipped ``list``s, Latin hypercube ``lhs``, a
scrambled Sobol sequence ``sobol`` and the ``saltelli`` design (Sobol-sequence based A, B and
AB_i matrices, from which first-order and total Sobol indices are estimated)."""

CONTINUOUS = ("lhs", "sobol", "saltelli")
"""Methods that sample a box ``{min, max}`` per parameter."""


@dataclass(frozen=True)
class Axis:
    """One varied parameter: its key path, values (grid/list) or bounds (sampled), integer flag."""

    key: str
    values: tuple[float, ...] = ()
    low: float = 0.0
    high: float = 0.0
    integer: bool = False


def full_factorial(axes: Sequence[Axis]) -> np.ndarray:
    """Every combination of the axes' values; the last axis varies fastest."""
    combos = list(itertools.product(*(a.values for a in axes)))
    return np.array(combos, dtype=np.float64).reshape(len(combos), len(axes))


def zipped(axes: Sequence[Axis]) -> np.ndarray:
    """Row i holds value i of every axis (the axes have equal lengths)."""
    return np.column_stack([np.asarray(a.values, dtype=np.float64) for a in axes])


def _scale(unit: np.ndarray, axes: Sequence[Axis]) -> np.ndarray:
    """Map unit-cube points to the axes' boxes (integers rounded, half a unit widened)."""
    out = np.empty_like(unit)
    for j, a in enumerate(axes):
        if a.integer:
            lo, hi = a.low - 0.5, a.high + 0.5
            out[:, j] = np.clip(np.rint(lo + unit[:, j] * (hi - lo)), a.low, a.high)
        else:
            out[:, j] = a.low + unit[:, j] * (a.high - a.low)
    return out


def latin_hypercube(axes: Sequence[Axis], n: int, seed: int) -> np.ndarray:
    """``n`` Latin-hypercube points (scipy.stats.qmc.LatinHypercube, ``seed``)."""
    from scipy.stats import qmc

    return _scale(qmc.LatinHypercube(d=len(axes), seed=seed).random(n), axes)


def sobol_points(axes: Sequence[Axis], n: int, seed: int) -> np.ndarray:
    """``n`` (a power of 2) points of a scrambled Sobol sequence (seeded)."""
    from scipy.stats import qmc

    return _scale(qmc.Sobol(d=len(axes), scramble=True, seed=seed).random_base2(_log2(n)), axes)


def saltelli(axes: Sequence[Axis], n: int, seed: int) -> np.ndarray:
    """The Saltelli (2010) design: blocks A, B, AB_1 .. AB_d of ``n`` rows each.

    A and B are the two halves of a ``2d``-dimensional scrambled Sobol sequence of ``n`` (a
    power of 2) points; AB_i is A with column i taken from B. ``n (d + 2)`` rows in all, in
    block order (see :func:`saltelli_blocks`).
    """
    from scipy.stats import qmc

    d = len(axes)
    base = qmc.Sobol(d=2 * d, scramble=True, seed=seed).random_base2(_log2(n))
    a, b = base[:, :d], base[:, d:]
    blocks = [a, b]
    for i in range(d):
        ab = a.copy()
        ab[:, i] = b[:, i]
        blocks.append(ab)
    return _scale(np.vstack(blocks), axes)


def saltelli_blocks(values: np.ndarray, n: int, d: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split outputs in Saltelli row order into ``(f_A (n,), f_B (n,), f_AB (d, n))``."""
    v = np.asarray(values, dtype=np.float64)
    if v.shape[0] != n * (d + 2):
        raise ValueError(f"expected {n * (d + 2)} values for n = {n}, d = {d}; got {v.shape[0]}")
    return v[:n], v[n : 2 * n], v[2 * n :].reshape(d, n, *v.shape[1:])


def is_power_of_two(n: int) -> bool:
    """True for 1, 2, 4, 8, ..."""
    return n >= 1 and (n & (n - 1)) == 0


def _log2(n: int) -> int:
    if not is_power_of_two(n):
        raise ValueError(f"n = {n} is not a power of 2")
    return n.bit_length() - 1

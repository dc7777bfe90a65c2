"""Successive elimination of candidates over the costs sampled so far (numba, ``cache=True``).

One round per batch of samples, in compiled code rather than some twenty
NumPy calls: at 100 taxis an agent runs about four batches, and the calls
took a tenth of a planning step.  The statistics are NumPy's to the last bit
(``diff.mean(axis=1)`` and ``diff.std(axis=1, ddof=1) / sqrt(n)`` of the
integer paired differences), so the rounds drop what NumPy's rounds dropped:
the sums of integers are exact in any order, and the sum of squared
deviations follows NumPy's pairwise summation (``tests/agents/test_rollout.py``
compares them bit for bit).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: NumPy's block for pairwise summation (``PW_BLOCKSIZE``): shorter runs are summed in 8 interleaved partial sums.
_BLOCK = 128


@njit(cache=True)
def _block_sum(a: np.ndarray, lo: int, n: int) -> float:
    """NumPy's sum of a run of at most :data:`_BLOCK` values: one by one below 8, else 8 interleaved partial sums."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = lo + 8
    whole = lo + n - n % 8
    while i < whole:
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < lo + n:
        res += a[i]
        i += 1
    return res


@njit(cache=True)
def pairwise_sum(a: np.ndarray, lo: int, n: int) -> float:
    """``a[lo:lo+n].sum()`` in NumPy's order (its ``pairwise_sum``): the same rounding as a NumPy reduction.

    NumPy halves a longer run (the first half a multiple of 8) until the
    pieces fit a block, and adds the halves' sums.  The halving is walked
    with explicit stacks: numba's cache mishandles a recursive function.
    """
    if n <= _BLOCK:
        return _block_sum(a, lo, n)
    depth = 3 * 64
    f_lo = np.empty(depth, np.int64)
    f_n = np.empty(depth, np.int64)
    f_join = np.empty(depth, np.bool_)
    sums = np.empty(64, np.float64)
    top, k = 0, 0
    f_lo[0], f_n[0], f_join[0] = lo, n, False
    while top >= 0:
        s_lo, s_n, join = f_lo[top], f_n[top], f_join[top]
        top -= 1
        if join:
            k -= 1
            sums[k - 1] = sums[k - 1] + sums[k]
        elif s_n <= _BLOCK:
            sums[k] = _block_sum(a, s_lo, s_n)
            k += 1
        else:
            half = s_n // 2
            half -= half % 8
            f_lo[top + 1], f_n[top + 1], f_join[top + 1] = s_lo, s_n, True
            f_lo[top + 2], f_n[top + 2], f_join[top + 2] = s_lo + half, s_n - half, False
            f_lo[top + 3], f_n[top + 3], f_join[top + 3] = s_lo, half, False
            top += 3
    return sums[0]


@njit(cache=True)
def best_candidate(costs: np.ndarray, n: int, active: np.ndarray) -> int:
    """The active candidate of least total cost over samples ``0 … n-1``; the first on ties."""
    best = -1
    best_total = 0
    for c in range(costs.shape[0]):
        if not active[c]:
            continue
        total = 0
        for j in range(n):
            total += costs[c, j]
        if best < 0 or total < best_total:
            best, best_total = c, total
    return best


@njit(cache=True)
def paired_stats(costs: np.ndarray, n: int, best: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean of each candidate's paired differences from ``best`` over samples ``0 … n-1``, and its standard error."""
    n_c = costs.shape[0]
    mean = np.empty(n_c)
    se = np.full(n_c, np.nan)
    sq = np.empty(n)
    for c in range(n_c):
        total = 0
        for j in range(n):
            total += costs[c, j] - costs[best, j]
        m = float(total) / n
        mean[c] = m
        if n < 2:
            continue
        for j in range(n):
            d = float(costs[c, j] - costs[best, j]) - m
            sq[j] = d * d
        se[c] = np.sqrt(pairwise_sum(sq, 0, n) / (n - 1)) / np.sqrt(n)
    return mean, se


@njit(cache=True)
def eliminate(costs: np.ndarray, n: int, active: np.ndarray, z: float) -> int:
    """Drop (in ``active``) each candidate whose mean paired difference from the best exceeds ``z`` standard errors; how many are left."""
    best = best_candidate(costs, n, active)
    mean, se = paired_stats(costs, n, best)
    left = 0
    for c in range(costs.shape[0]):
        if active[c] and c != best and mean[c] - z * se[c] > 0:
            active[c] = False
        left += active[c]
    return left

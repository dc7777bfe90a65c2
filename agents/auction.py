"""Bertsekas' forward auction for the assignment problem, with ε-scaling.

Benefits are integers; they are scaled by ``N + 1`` so that a final ε of 1 is
below ``1/N`` of the original scale, which makes the result optimal.  A
rectangular problem is squared with zero-benefit dummy persons, so every real
person is assigned.  Bidding is Gauss–Seidel (one person at a time), compiled
with numba: the oracle solves one such problem per simulated minute.
"""

from __future__ import annotations

import numpy as np
from numba import njit


def auction_assignment(benefit: np.ndarray) -> np.ndarray:
    """Maximise ``Σ benefit[i, a[i]]`` over one-to-one assignments.

    Parameters
    ----------
    benefit : ndarray of int, shape (n_persons, n_objects), ``n_persons <= n_objects``

    Returns
    -------
    ndarray of int, shape (n_persons,)
        The object assigned to each person.
    """
    benefit = np.asarray(benefit)
    n_persons, n = benefit.shape
    if n_persons > n:
        raise ValueError(f"auction: {n_persons} persons for {n} objects; transpose the problem")
    if n_persons == 0:
        return np.empty(0, dtype=np.int64)
    if not np.issubdtype(benefit.dtype, np.integer):
        raise ValueError("auction: benefits must be integers")
    a = np.zeros((n, n), dtype=np.float64)
    a[:n_persons] = benefit.astype(np.float64) * (n + 1)
    eps = max(1.0, np.floor(float(a.max() - a.min()) / 4))
    return _auction(a, eps)[:n_persons]


@njit(cache=True)
def _auction(a: np.ndarray, eps: float) -> np.ndarray:  # pragma: no cover - compiled
    n = a.shape[0]
    prices = np.zeros(n)
    assigned = np.full(n, -1, dtype=np.int64)
    owner = np.full(n, -1, dtype=np.int64)
    queue = np.empty(n, dtype=np.int64)
    while True:
        assigned[:] = -1
        owner[:] = -1
        for i in range(n):
            queue[i] = i
        head, size = 0, n
        while size > 0:
            i = queue[head]
            head = (head + 1) % n
            size -= 1
            best, second, bj = -np.inf, -np.inf, -1
            for j in range(n):
                v = a[i, j] - prices[j]
                if v > best:
                    second = best
                    best = v
                    bj = j
                elif v > second:
                    second = v
            if n == 1:
                second = best
            prices[bj] += best - second + eps
            prev = owner[bj]
            owner[bj] = i
            assigned[i] = bj
            if prev >= 0:
                assigned[prev] = -1
                queue[(head + size) % n] = prev
                size += 1
        if eps <= 1.0:
            return assigned
        eps = max(1.0, np.floor(eps / 4))

"""Bertsekas' forward auction for the assignment problem, with ε-scaling.

Benefits are integers; they are scaled by ``N + 1`` so that a final ε of 1 is
below ``1/N`` of the original scale, which makes the result optimal.  A
rectangular problem is squared with zero-benefit dummy persons, so every real
person is assigned.
"""

from __future__ import annotations

import numpy as np


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
    prices = np.zeros(n)
    span = float(a.max() - a.min())
    eps = max(1.0, np.floor(span / 4))
    while True:
        owner = np.full(n, -1, dtype=np.int64)
        assigned = np.full(n, -1, dtype=np.int64)
        unassigned = np.arange(n)
        while unassigned.size:
            values = a[unassigned] - prices
            best = np.argmax(values, axis=1)
            rows = np.arange(unassigned.size)
            v1 = values[rows, best]
            if n > 1:
                values[rows, best] = -np.inf
                v2 = values.max(axis=1)
            else:
                v2 = v1
            bids = prices[best] + (v1 - v2) + eps
            order = np.lexsort((unassigned, -bids, best))
            first = np.ones(order.size, dtype=bool)
            first[1:] = best[order[1:]] != best[order[:-1]]
            win = order[first]
            objs, persons = best[win], unassigned[win]
            prev = owner[objs]
            assigned[prev[prev >= 0]] = -1
            owner[objs] = persons
            assigned[persons] = objs
            prices[objs] = bids[win]
            unassigned = np.flatnonzero(assigned < 0)
        if eps <= 1.0:
            return assigned[:n_persons]
        eps = max(1.0, np.floor(eps / 4))

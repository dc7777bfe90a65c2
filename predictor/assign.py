"""Demand assignment (paper §4.2.2): sector demand → intersections, and β.

* ρ, δ: ``O(j, h) = Σ_λ n_λ(j) · p_λ(h) · o_λ`` from the world's locale counts
  and the occupancy schedules of :mod:`city.io.occupancy`, normalised over each
  sector's pickup intersections.  The paper uses the same O for pickup and
  drop-off, so ρ = δ here.
* β: relative frequency of drop-off sector given pickup sector in historical
  trips of the training months only (January–June: validation and test months
  never enter).  From a :class:`city.io.trips.TripTable` when one is given (its
  trips requested in the training months); otherwise from the world's own
  requests on ``days`` randomly drawn days of the training months (all 24
  hours of each).  Pickup sectors without trips get a uniform row.
"""

from __future__ import annotations

import datetime as dt

import numpy as np

from city.io.occupancy import day_type, occupancy, sector_distribution
from predictor.dataset import TRAIN_MONTHS


def node_distribution(city, locale_counts: np.ndarray, when: dt.datetime, schedules: dict | None = None) -> np.ndarray:
    """p(ρ = j) = p(δ = j) within each sector, shape ``(n,)``; sums to 1 over each sector.

    ``schedules`` are the world's occupancy schedules (a scenario's ``[occupancy]``), the built-in ones if ``None``.
    """
    weights = occupancy(np.asarray(locale_counts), when.hour, day_type(when.date()), schedules)
    return sector_distribution(weights, np.asarray(city.node_sector), int(city.n_sectors), np.asarray(city.pickup, bool))


def estimate_beta(world, *, days: int = 28, seed: int = 0, trips=None) -> tuple[np.ndarray, dict]:
    """β ``(S, S)`` (rows sum to 1) and a description of where it came from."""
    from city.io.trips import (  # pyarrow: only where β is estimated, never in an agent
        in_months,
        od_frequencies,
    )

    city = world.city
    S = int(city.n_sectors)
    year = int(world.year)
    if trips is not None:
        keep = in_months(trips, range(1, TRAIN_MONTHS + 1), year)
        beta = od_frequencies(trips.pickup_sector[keep], trips.dropoff_sector[keep], S)
        return beta, {"source": "trip table", "trips": int(keep.sum()), "trips_outside_training_months": int((~keep).sum()), "months": f"1-{TRAIN_MONTHS}"}
    first = dt.date(year, 1, 1)
    n_train_days = (dt.date(year, TRAIN_MONTHS + 1, 1) - first).days
    rng = np.random.default_rng(seed)
    picks = sorted(rng.choice(n_train_days, size=min(days, n_train_days), replace=False).tolist())
    pu: list[np.ndarray] = []
    do: list[np.ndarray] = []
    for k in picks:
        date = first + dt.timedelta(days=int(k))
        for hour in range(24):
            req = world.requests(date, hour, minutes=60)
            pu.append(np.asarray(city.node_sector)[np.asarray(req.pickup, np.int64)])
            do.append(np.asarray(city.node_sector)[np.asarray(req.dropoff, np.int64)])
    p = np.concatenate(pu) if pu else np.zeros(0, np.int64)
    d = np.concatenate(do) if do else np.zeros(0, np.int64)
    beta = od_frequencies(p, d, S)
    return beta, {"source": "world requests", "days": len(picks), "trips": int(len(p)), "months": f"1-{TRAIN_MONTHS}"}

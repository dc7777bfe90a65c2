"""Where the forecast puts demand, per node: the end-of-horizon values of the rollout's ``place`` option."""

from __future__ import annotations

import numpy as np

from agents.demand_tables import DemandTables
from city.graph import City

_PLACES: dict[tuple[int, int, bytes], tuple[object, np.ndarray]] = {}


def place_values(city: City, tables: DemandTables, sectors: np.ndarray) -> np.ndarray:
    """Per node, the expected hops (in tenths, rounded) to the next request forecast in ``sectors``.

    A request of sector ``q`` comes with probability ``η_q / Σ η`` and its
    pickup node from the sector's pickup table; without demand, zeros.  Kept
    per (city, tables, sectors): the tables change with the forecast's hour only.
    """
    key = (id(city), id(tables), sectors.tobytes())
    hit = _PLACES.get(key)
    if hit is not None and hit[0] is tables:
        return hit[1]
    eta = tables.eta[sectors]
    values = np.zeros(city.n_nodes)
    if eta.sum() > 0:
        for q, rate in zip(sectors.tolist(), eta.tolist()):
            lo, hi = int(tables.pk_ptr[q]), int(tables.pk_ptr[q + 1])
            if rate <= 0 or hi == lo:
                continue
            w = np.diff(tables.pk_cum[lo:hi], prepend=0.0)
            values += (rate / eta.sum()) * (city.dist[:, tables.pk_node[lo:hi]] @ (w / w.sum()))
    out = np.ascontiguousarray(np.rint(10.0 * values), dtype=np.int64)
    if len(_PLACES) > 512:
        _PLACES.clear()
    _PLACES[key] = (tables, out)
    return out

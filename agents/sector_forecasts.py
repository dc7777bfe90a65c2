"""A taxi's forecasts, sector by sector: which sectors it follows, what it holds, and the demand tables built from them.

The design card has each taxi subscribe to the demand forecasts of its local
sectors.  A rollout with local scope and limited certainty equivalence
(or with ``counts``, its deterministic counts drawn sector by sector)
samples arrivals only in the deciding taxi's sector and the sectors next to
it, and drop-offs anywhere; so the taxi follows ``forecast/<s>`` of those
sectors and the map-wide ``dropoffs``, and builds its demand tables from
them.  The tables then agree with the whole forecast's on every sector the
rollout reads (per-sector tables, per-row β), so the decisions are the
in-process ones.  Standard certainty equivalence draws its pools from one
random stream over every sector in turn, and map scope samples everywhere:
those planners follow every sector.

A taxi that moves follows its new sectors; what it missed of the current
hour (published at the hour's start) it asks the coordinator for, on the
same keys.  A rejoining taxi gets the whole hour's forecast in its snapshot.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.demand_tables import DemandTables
from agents.rollout_config import POOLED_CE, RolloutConfig
from bus.checks import (
    Bounds,
    Rejections,
    check_dropoffs,
    check_forecast,
    check_sector_forecast,
)
from bus.keys import Keys
from bus.session import Inbox
from bus.wire import Dropoffs, ForecastMsg, SectorForecast, decode
from city.forecast import Forecast, SectorSlice, assemble, sector_nodes
from city.graph import City

#: Seconds a taxi waits for the coordinator's answer about a sector it missed.
FETCH_TIMEOUT_S = 5.0


def needed_sectors(city: City, config: RolloutConfig, node: int) -> np.ndarray:
    """The sectors whose forecast a decision at ``node`` reads (ascending).

    The local sectors for local scope without standard certainty
    equivalence's pools; every sector otherwise (see the module docstring).
    """
    if config.scope == "local" and config.ce not in POOLED_CE:
        return city.local_sectors(int(city.node_sector[node]))
    return np.arange(city.n_sectors)


class AgentForecasts:
    """The forecast pieces one taxi holds, by hour, and its subscriptions to sectors.

    Until :meth:`attach` gives it a session (a taxi without a bus, as in the
    unit tests) it only keeps what it is handed.
    """

    def __init__(self, city: City, config: RolloutConfig, bounds: Bounds, rejected: Rejections) -> None:
        self.city, self.config, self.bounds, self.rejected = city, config, bounds, rejected
        self._nodes = [sector_nodes(city, s) for s in range(city.n_sectors)]
        self.slices: dict[int, dict[int, SectorSlice]] = {}
        self.dropoffs: dict[int, np.ndarray] = {}
        self.whole: dict[int, Forecast] = {}
        self._tables: dict[int, tuple[frozenset[int], DemandTables]] = {}
        self._session: Any = None
        self._inbox: Inbox | None = None
        self._keys: Keys | None = None
        self._subs: dict[int, Any] = {}
        #: Pieces that came by query from the coordinator rather than on a subscription.
        self.fetched = 0

    # ------------------------------------------------------------- receiving
    def on_sector(self, payload: bytes, key: str) -> SectorForecast:
        """Check and keep one sector's forecast (a subscription's sample or a query's reply)."""
        msg = check_sector_forecast(decode(payload, SectorForecast, key), key, self.bounds, self._nodes)  # type: ignore[arg-type]
        self.slices.setdefault(msg.hour, {})[msg.sector] = SectorSlice(
            sector=msg.sector, eta=float(msg.eta), nodes=msg.nodes, rho=msg.rho, delta=msg.delta, beta=msg.beta)
        return msg

    def on_dropoffs(self, payload: bytes, key: str) -> None:
        msg = decode(payload, Dropoffs, key)
        self.dropoffs[msg.hour] = check_dropoffs(msg, key, self.bounds).delta  # type: ignore[arg-type]

    def on_whole(self, msg: ForecastMsg, key: str) -> None:
        """A whole hour's forecast, as a snapshot carries it."""
        check_forecast(msg, key, self.bounds)
        self.whole[msg.hour] = Forecast(eta=msg.eta, rho=msg.rho, delta=msg.delta, beta=msg.beta)
        self._tables.pop(msg.hour, None)

    def forget_before(self, hour: int) -> None:
        """Drop what no later minute reads."""
        for store in (self.slices, self.dropoffs, self.whole, self._tables):
            for h in [h for h in store if h < hour]:
                del store[h]

    # ----------------------------------------------------------------- using
    def missing(self, hour: int, sectors: np.ndarray) -> list[int]:
        """The sectors of ``sectors`` whose forecast of ``hour`` is not here."""
        if hour in self.whole:
            return []
        held = self.slices.get(hour, {})
        return [int(s) for s in sectors if int(s) not in held]

    def tables(self, hour: int, sectors: np.ndarray) -> DemandTables | None:
        """Demand tables of ``hour`` exact on ``sectors`` (and on the drop-offs), or ``None`` while a piece is missing."""
        want = frozenset(int(s) for s in sectors)
        cached = self._tables.get(hour)
        if cached is not None and want <= cached[0]:
            return cached[1]
        if hour in self.whole:
            fc, covered = self.whole[hour], frozenset(range(self.city.n_sectors))
        else:
            if self.missing(hour, sectors) or hour not in self.dropoffs:
                return None
            held = self.slices[hour]
            fc, covered = assemble(self.city, held, self.dropoffs[hour]), frozenset(held)
        tables = DemandTables.build(self.city, fc, self.config.ce, self.config.seed)
        self._tables[hour] = (covered, tables)
        return tables

    # ------------------------------------------------------------------- bus
    def attach(self, session: Any, inbox: Inbox, keys: Keys) -> None:
        """Follow sectors on ``session``, their samples going to ``inbox`` tagged ``forecast``."""
        self._session, self._inbox, self._keys = session, inbox, keys

    def follow(self, sectors: np.ndarray, hour: int) -> None:
        """Subscribe to exactly ``sectors``, and fetch what is missing of ``hour`` for the newly followed ones."""
        if self._session is None:
            return
        want = {int(s) for s in sectors}
        for s in [s for s in self._subs if s not in want]:
            self._subs.pop(s).undeclare()
        new = sorted(want - set(self._subs))
        for s in new:
            self._subs[s] = self._inbox.subscribe(self._session, self._keys.forecast(s), "forecast")  # type: ignore[union-attr]
        self.fetch(hour, np.asarray(new, dtype=np.int64))

    def fetch(self, hour: int, sectors: np.ndarray) -> None:
        """Ask the coordinator for the missing sectors of ``hour``, all at once; a bad or late answer is left out."""
        missing = self.missing(hour, sectors)
        if self._session is None or not missing:
            return
        pending = [(self._keys.forecast(s), self._session.get(self._keys.forecast(s), timeout=FETCH_TIMEOUT_S))  # type: ignore[union-attr]
                   for s in missing]
        for key, replies in pending:
            for reply in replies:
                if reply.ok is None:
                    continue
                try:
                    self.on_sector(reply.ok.payload.to_bytes(), key)
                    self.fetched += 1
                except Exception as exc:  # a bad answer: leave it out (the taxi asks once more at its turn)
                    self.rejected.exception("forecast", key, exc)

    def close(self) -> None:
        for sub in self._subs.values():
            sub.undeclare()
        self._subs.clear()

"""Input features of the two demand networks.

Base features f (both networks; paper §4.2.1 "temporal and spatial data"):

* hour of day, one-hot (24)
* day of week, one-hot (7)
* month as a point on the unit circle, ``sin/cos(2π (month-1)/12)`` (2).  A
  one-hot month would leave the test months (Sep–Dec) with untrained weights,
  because the networks train on Jan–Jun only; the cyclic code at least lets
  them interpolate the seasonal trend.
* holiday flag (1): the world's holidays (a scenario's ``[holidays]``), US federal by default
* weather: temperature (°F), precipitation (in), wind (mph), z-scored with the
  training months' mean and standard deviation (3)
* the sector's identity, one-hot (S).  The paper calls weather "spatial"; surge
  adds the sector itself so that one network serves all sectors with their own
  base levels.

Event feature F_s (event network only): ``[ẑ_s, R̂_s]`` of size ``(b+1)·d``,
the mean title+description embedding of the sector's events that count for the
hour, then the mean of their stacked review-cluster means R_w (events without
reviews are left out of the R average; if none has reviews R̂_s is zero).

Which events count for an hour: the paper says "events happening on sector
s": the event overlaps ``[h, h+1h)``.  surge counts an event in its venue's
sector for every hour that overlaps ``[start - LEAD_HOURS, end + LAG_HOURS)``
(recorded in the model; ``surge predictor train --window LEAD,LAG``).  The
default, 0 and 0, is the paper's literal rule, chosen on the validation
months: of the windows 0,0, 1,0, 2,1 and 3,2 it gave the system the lowest
percent error on every sector-hour of July–August, 15–21 h.  A wider window covers more of an event's taxi demand
(arrivals come before the start, departures after the end) but makes the
event network predict many more sector-hours, and it predicts them worse.  Adjacent sectors
(where many arrivals are picked up) are not included: that would make 60 % of
evening sector-hours "event" hours and quadruple the event network's
training set.  Each of
the (b+1)·d columns is z-scored with the training event samples' statistics.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import logging
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from city.calendar import holidays_for
from predictor.spectral import GAMMA, N_CLUSTERS, Q_MAX, review_representation

log = logging.getLogger(__name__)

N_TEMPORAL = 24 + 7 + 2 + 1
WEATHER_NAMES = ("temp_f", "precip_in", "wind_mph")


def temporal_names() -> list[str]:
    return [f"hour_{h}" for h in range(24)] + [f"weekday_{d}" for d in range(7)] + ["month_sin", "month_cos", "holiday"]


def temporal_features(when: dt.datetime, holidays: frozenset[dt.date] | None = None) -> np.ndarray:
    """One hour's temporal features; ``holidays`` is the world's holiday set (default: US federal)."""
    f = np.zeros(N_TEMPORAL, dtype=np.float32)
    f[when.hour] = 1.0
    f[24 + when.weekday()] = 1.0
    ang = 2 * np.pi * (when.month - 1) / 12.0
    f[31] = np.sin(ang)
    f[32] = np.cos(ang)
    f[33] = 1.0 if when.date() in (holidays_for(when.year) if holidays is None else holidays) else 0.0
    return f


def year_hours(year: int) -> list[dt.datetime]:
    start = dt.datetime(year, 1, 1)
    n = (dt.date(year + 1, 1, 1) - dt.date(year, 1, 1)).days * 24
    return [start + dt.timedelta(hours=i) for i in range(n)]


def hour_index(when: dt.datetime, year: int) -> int:
    return (when.date() - dt.date(year, 1, 1)).days * 24 + when.hour


def temporal_matrix(year: int, holidays: frozenset[dt.date] | None = None) -> np.ndarray:
    return np.stack([temporal_features(h, holidays) for h in year_hours(year)])


def weather_matrix(weather, n_hours: int) -> np.ndarray:
    """Raw ``(H, 3)`` weather: temperature, precipitation, wind (NaN → column median)."""
    w = np.column_stack(
        [np.asarray(weather.temp_f, np.float64)[:n_hours], np.asarray(weather.precip_in, np.float64)[:n_hours], np.asarray(weather.wind_mph, np.float64)[:n_hours]]
    )
    if w.shape[0] < n_hours:  # short weather table: repeat the last row
        w = np.vstack([w, np.repeat(w[-1:], n_hours - w.shape[0], axis=0)])
    for k in range(3):
        bad = ~np.isfinite(w[:, k])
        if bad.any():
            w[bad, k] = np.nanmedian(w[:, k]) if (~bad).any() else 0.0
    return w.astype(np.float32)


def weather_at(weather, when: dt.datetime) -> np.ndarray:
    i = (when.timetuple().tm_yday - 1) * 24 + when.hour
    i = min(i, len(weather.temp_f) - 1)
    row = np.array([weather.temp_f[i], weather.precip_in[i], weather.wind_mph[i]], dtype=np.float64)
    return np.where(np.isfinite(row), row, 0.0).astype(np.float32)


def event_text(ev) -> str:
    """The text whose embedding is z_w: title and description."""
    title = (ev.title or "").strip()
    desc = (ev.description or "").strip()
    return f"{title}. {desc}" if desc else title


@dataclass
class EventVectors:
    z: np.ndarray  # (d,)
    R: np.ndarray  # (b, d)
    has_reviews: bool


class EventFeaturizer:
    """Turns events into z_w and R_w, and sets of active events into F_s."""

    def __init__(self, embedder, n_clusters: int = N_CLUSTERS, gamma: float = GAMMA, q_max: int = Q_MAX, seed: int = 0, verbose: bool = False) -> None:
        self.embedder = embedder
        self.b = int(n_clusters)
        self.gamma = float(gamma)
        self.q_max = int(q_max)
        self.seed = int(seed)
        self.verbose = verbose
        self._vectors: dict[str, EventVectors] = {}
        self._cluster_memo: dict[bytes, tuple[np.ndarray, bool]] = {}
        self.timings: dict[str, float] = {"embed_s": 0.0, "cluster_s": 0.0}

    @property
    def d(self) -> int:
        return self.embedder.dim

    @property
    def size(self) -> int:
        return (self.b + 1) * self.d

    def prepare(self, events: Sequence) -> None:
        """Embed (batched, de-duplicated, cached) and cluster every event not yet seen."""
        todo = [ev for ev in events if ev.event_id not in self._vectors]
        if not todo:
            return
        # De-duplicate before embedding: reviews repeat across the events of a venue or show.
        index: dict[str, int] = {}
        for ev in todo:
            index.setdefault(event_text(ev), len(index))
            for r in tuple(ev.reviews)[: self.q_max]:
                index.setdefault(str(r), len(index))
        t0 = time.perf_counter()
        emb = self.embedder.embed(list(index))
        self.timings["embed_s"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        for ev in todo:
            z = emb[index[event_text(ev)]]
            reviews = tuple(str(r) for r in tuple(ev.reviews)[: self.q_max])
            key = hashlib.sha1("\x1f".join(reviews).encode("utf-8")).digest()
            if key not in self._cluster_memo:  # events of one show or venue often share reviews
                rev = emb[[index[r] for r in reviews]].reshape(len(reviews), emb.shape[1])
                self._cluster_memo[key] = review_representation(rev, self.b, self.gamma, self.q_max, self.seed)
            R, has = self._cluster_memo[key]
            self._vectors[ev.event_id] = EventVectors(z=z, R=R, has_reviews=has)
        self.timings["cluster_s"] += time.perf_counter() - t0
        if self.verbose:
            log.info("event features: %d events, %d distinct review sets clustered (embed %.1fs, cluster %.1fs)",
                     len(todo), len(self._cluster_memo), self.timings["embed_s"], self.timings["cluster_s"])

    def vectors(self, ev) -> EventVectors:
        if ev.event_id not in self._vectors:
            self.prepare([ev])
        return self._vectors[ev.event_id]

    def sector_feature(self, events: Sequence, swap: dict[str, object] | None = None) -> np.ndarray:
        """F_s = [ẑ_s, R̂_s] for the events active in one sector and hour.

        ``swap`` maps an event id to the event whose text stands in for it
        (the shuffled-text control of the ablation, :func:`shuffled_texts`).
        """
        d = self.d
        out = np.zeros((self.b + 1) * d, dtype=np.float32)
        if not events:
            return out
        if swap is not None:
            events = [swap.get(ev.event_id, ev) for ev in events]
        vs = [self.vectors(ev) for ev in events]
        out[:d] = np.mean([v.z for v in vs], axis=0)
        with_rev = [v.R for v in vs if v.has_reviews]
        if with_rev:
            out[d:] = np.mean(with_rev, axis=0).ravel()
        return out


def shuffled_texts(events: Sequence, seed: int = 0) -> dict[str, object]:
    """A fixed random permutation of the events' texts: event id -> the event whose text it gets.

    The shuffled-text control keeps every event where and when it is, and keeps
    the distribution of texts, but breaks the link between an event and what
    its text says.
    """
    evs = sorted(events, key=lambda e: e.event_id)
    perm = np.random.default_rng([seed, 7919]).permutation(len(evs))
    return {ev.event_id: evs[int(j)] for ev, j in zip(evs, perm)}


class MetadataFeaturizer:
    """Event metadata of a sector-hour, with no text: the metadata network's input.

    Columns: the number of active events; per category of
    :data:`city.io.events.CATEGORIES` (and one for any other) the number of
    active events; ``log1p`` of the summed and of the largest venue capacity
    of the active events; the number whose venue capacity is unknown.  The
    capacity is the venue's (``world.venues``), announced before the event;
    realised attendance never enters.
    """

    def __init__(self, capacity: dict[str, float] | None = None) -> None:
        from city.io.events import CATEGORIES

        self.categories = tuple(CATEGORIES)
        self.capacity = dict(capacity or {})

    @classmethod
    def from_world(cls, world) -> "MetadataFeaturizer":
        venues = getattr(world, "venues", None) or []
        return cls({str(v.venue_id): float(v.capacity) for v in venues if getattr(v, "capacity", None)})

    @property
    def names(self) -> list[str]:
        return ["n_events"] + [f"n_{c}" for c in self.categories] + ["n_other_category", "log1p_capacity_sum", "log1p_capacity_max", "n_capacity_unknown"]

    @property
    def size(self) -> int:
        return len(self.names)

    def sector_feature(self, events: Sequence) -> np.ndarray:
        K = len(self.categories)
        out = np.zeros(self.size, dtype=np.float32)
        out[0] = len(events)
        caps = []
        for ev in events:
            k = self.categories.index(ev.category) if ev.category in self.categories else K
            out[1 + k] += 1
            cap = self.capacity.get(str(ev.venue_id))
            if cap is None:
                out[K + 4] += 1
            else:
                caps.append(cap)
        if caps:
            out[K + 2] = np.log1p(sum(caps))
            out[K + 3] = np.log1p(max(caps))
        return out


#: Hours before an event's start and after its end in which it counts for its sector (see module notes).
LEAD_HOURS = 0
LAG_HOURS = 0


def active_hours(ev, year: int, n_hours: int, lead: int = 0, lag: int = 0) -> range:
    """Hour indices of ``year`` whose hour overlaps ``[start - lead h, end + lag h)``."""
    start = dt.datetime(year, 1, 1)
    first = int((ev.start - start).total_seconds() // 3600)
    # last hour h with h_start < end
    end_s = (ev.end - start).total_seconds()
    last = int(np.ceil(end_s / 3600.0)) - 1
    if ev.end <= ev.start:
        last = first
    return range(max(first - lead, 0), min(last + lag, n_hours - 1) + 1)


def events_by_hour_sector(events: Sequence, year: int, n_hours: int, n_sectors: int, lead: int = LEAD_HOURS, lag: int = LAG_HOURS) -> dict[tuple[int, int], list]:
    out: dict[tuple[int, int], list] = {}
    for ev in events:
        s = int(ev.sector)
        if not 0 <= s < n_sectors:
            continue
        for h in active_hours(ev, year, n_hours, lead, lag):
            out.setdefault((h, s), []).append(ev)
    return out


def active_events(world, when: dt.datetime, lead: int = LEAD_HOURS, lag: int = LAG_HOURS) -> list:
    """Events that count for the hour beginning at ``when``: overlapping ``[start - lead, end + lag)``."""
    if lead == 0 and lag == 0 and callable(getattr(world, "events_active", None)):
        return list(world.events_active(when))
    hour = when.replace(minute=0, second=0, microsecond=0)
    lo = hour - dt.timedelta(hours=lag)
    hi = hour + dt.timedelta(hours=1 + lead)
    return [ev for ev in world.events if ev.start < hi and ev.end > lo]

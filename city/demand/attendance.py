"""Events from their specs: text written before the event, attendance drawn on the day, and taxi trips.

The order matters and is the point of this module.  :func:`write_events`
turns each :class:`~city.demand.venues.EventSpec` into an
:class:`~city.io.events.Event` whose title, description and reviews use only
what is known before the event: what the organiser announces (category,
headliner, venue and capacity, "sold out", "final day"; the popularity tier
stands for ticket sales) and reviews of the performer's or production's
*earlier* events at venues like this one (``reputation``, and the crowd such
a venue draws for it).  :func:`draw_attendance` then draws the realised
attendance from the same drivers *and* from what no text can know: the
weather at the start and a random draw per event.  No text is a function of
the realised attendance.

Taxi trips are attendance × trips per attendee × the fleet's share of the
market (:data:`TRIPS_PER_ATTENDEE`, :data:`city.demand.profile.FLEET_SHARE`).
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import random

import numpy as np
from scipy.special import gammainc

from city import texts
from city.demand.venues import COMMUNITY_KINDS, EventSpec
from city.io.events import Event, Venue
from city.io.weather import HourlyWeather, hours_in_year

#: Taxi and ride-hail trips per attendee (all operators), arriving and departing, by category.
#: An assumption, not a measurement: about a third of the attendees of ticketed Manhattan events
#: ride a taxi or an app car one way, in parties of about 1.6, which gives ≈ 0.2 trips per attendee
#: each way; a little more leaving (late, tired, raining); conference-goers (business travellers)
#: more, expo visitors and fans (trains to Penn Station) fewer; festival and community crowds
#: are mostly local and walk or take the subway.  See ``i10-README`` notes for the target it gives.
TRIPS_PER_ATTENDEE: dict[str, tuple[float, float]] = {
    "conferences": (0.25, 0.25),
    "expos": (0.15, 0.15),
    "concerts": (0.20, 0.22),
    "festivals": (0.05, 0.06),
    "performing-arts": (0.20, 0.22),
    "community": (0.03, 0.03),
    "sports": (0.15, 0.18),
}
#: Log-normal spread of realised attendance around what the drivers predict (no-shows, walk-ups,
#: a rival attraction): the part of a surge no text carries.
ATTENDANCE_SIGMA = 0.2
#: Outdoor events lose up to this share of their crowd in heavy rain, indoor ones ``INDOOR_RAIN_DROP``.
OUTDOOR_RAIN_DROP = 0.5
INDOOR_RAIN_DROP = 0.08
#: Rain makes attendees take cabs: trips per attendee rise by up to this share.
RAIN_TAXI_LIFT = 0.3
#: Precipitation (inches per hour) at which rain has its full effect.
HEAVY_RAIN_IN = 0.25
#: Spread of an event's standing before it around its own popularity, where the spec gives none.
REPUTATION_SD = 0.1
OUTDOOR_KINDS = frozenset({"festival grounds", "park"})
#: Events longer than this (minutes) spread part of their arrivals and departures over their duration.
LONG_EVENT_MIN = 300
#: Event-hours with fewer market trips than this (≈ 0.001 of the default fleet's) are left out.
MIN_MARKET_TRIPS = 0.05
_UNITS = {"convention center": "visitor", "festival grounds": "visitor", "park": "visitor", "conference center": "person", "community center": "person"}


def fill_rate(popularity: np.ndarray, sentiment: np.ndarray) -> np.ndarray:
    """Share of capacity expected to attend: rises with popularity, and with sentiment."""
    return np.clip(0.05 + np.asarray(popularity) ** 1.1 * (0.65 + 0.4 * np.asarray(sentiment)), 0.03, 1.0)


def reputation(spec: EventSpec, rng: random.Random) -> float:
    """The standing of the event's performer or production before it: given, or its popularity blurred."""
    if spec.reputation is not None:
        return spec.reputation
    return min(1.0, max(0.02, spec.popularity + rng.gauss(0.0, REPUTATION_SD)))


def write_events(specs: list[EventSpec], venues: list[Venue], rng: random.Random) -> tuple[list[Event], list[EventSpec]]:
    """Events with title, description and reviews (no attendance), sorted by start; and their specs in that order.

    Each event's reviews are the venue's own (:func:`city.texts.venue_reviews`,
    written once per venue) followed by those of the performer's earlier
    events.  Reviews of a production or multi-day show are written once,
    from its standing before its run, and shared by all its events.
    """
    group_reviews: dict[int, tuple[str, ...]] = {}
    about_venue: dict[int, tuple[str, ...]] = {}
    events = []
    for s in specs:
        venue = venues[s.venue]
        kind = next((k.lower() for k in COMMUNITY_KINDS if venue.name.endswith(k)), venue.kind)
        if s.venue not in about_venue:
            about_venue[s.venue] = texts.venue_reviews(random.Random(f"{venue.venue_id}-{venue.name}"), venue.name, kind, venue.capacity)
        where = texts.venue_phrase(venue.name, kind, s.capacity, _UNITS.get(venue.kind, "seat"))
        title = texts.title(rng, s.category, s.name, s.popularity, s.cue)
        if s.group < 0 or s.group not in group_reviews:
            rep = reputation(s, rng)
            crowd = float(s.capacity * fill_rate(rep, s.sentiment))
            reviews = texts.reviews(rng, s.category, rep, s.sentiment, crowd)
            if s.group >= 0:
                group_reviews[s.group] = reviews
        else:
            reviews = group_reviews[s.group]
        events.append(
            Event(
                event_id="",
                title=title,
                description=texts.description(rng, s.category, title, where, s.popularity, s.sentiment, s.start),
                category=s.category,
                start=s.start,
                end=s.start + dt.timedelta(minutes=s.minutes),
                sector=venue.sector,
                node=venue.node,
                venue_id=venue.venue_id,
                reviews=(about_venue[s.venue] + reviews)[: texts.MAX_REVIEWS],
            )
        )
    order = sorted(range(len(events)), key=lambda i: (events[i].start, events[i].venue_id, events[i].title))
    return [dataclasses.replace(events[i], event_id=f"E{k:05d}") for k, i in enumerate(order)], [specs[i] for i in order]


def _rain(weather: HourlyWeather, events: list[Event]) -> np.ndarray:
    """Rain intensity in [0, 1] at each event's start hour."""
    origin = dt.datetime(weather.year, 1, 1)
    h = np.array([int((e.start - origin).total_seconds() // 3600) for e in events], dtype=np.int64)
    precip = np.asarray(weather.precip_in)[np.clip(h, 0, len(weather.precip_in) - 1)]
    return np.where(precip >= 0.01, np.minimum(precip / HEAVY_RAIN_IN, 1.0), 0.0)


def draw_attendance(specs: list[EventSpec], events: list[Event], venues: list[Venue], weather: HourlyWeather, seed: int) -> tuple[list[Event], np.ndarray]:
    """Realised attendance of each event, and the events with it filled in.

    ``capacity × fill_rate(popularity, sentiment)`` (what the text carries)
    × a rain loss (larger outdoors) × ``exp(N(0, σ))``, at most the capacity.
    """
    pop = np.array([s.popularity for s in specs])
    sent = np.array([s.sentiment for s in specs])
    cap = np.array([s.capacity for s in specs], dtype=np.float64)
    outdoor = np.array([venues[s.venue].kind in OUTDOOR_KINDS for s in specs])
    rain = _rain(weather, events)
    drop = np.where(outdoor, OUTDOOR_RAIN_DROP, INDOOR_RAIN_DROP) * rain
    noise = np.random.default_rng([seed, 17]).normal(0.0, ATTENDANCE_SIGMA, len(specs))
    attendance = np.round(np.minimum(cap * fill_rate(pop, sent) * (1.0 - drop) * np.exp(noise), cap))
    out = [dataclasses.replace(e, attendance=float(a)) for e, a in zip(events, attendance)]
    return out, attendance


def event_trips(events: list[Event], attendance: np.ndarray, weather: HourlyWeather) -> tuple[np.ndarray, np.ndarray]:
    """Expected taxi and app-car trips of each event, arriving and departing, for the whole market.

    The fleet's part is this × its share of the market (:data:`city.demand.profile.FLEET_SHARE` by default).
    """
    per = np.array([TRIPS_PER_ATTENDEE[e.category] for e in events]).reshape(-1, 2)
    lift = 1.0 + RAIN_TAXI_LIFT * _rain(weather, events)
    base = attendance * lift
    return base * per[:, 0], base * per[:, 1]


def surges(events: list[Event], trips_arr: np.ndarray, trips_dep: np.ndarray, year: int, S: int, scale: float = 1.0):
    """Expected event trips per hour by venue sector, arriving and departing, and per event-hour rows.

    Arrival requests enter 5 + Gamma(2.5, 12) minutes before the start (mean
    35 min), departures 2 + Gamma(1.5, 12) minutes after the end (mean 20
    min).  Events longer than :data:`LONG_EVENT_MIN` (expos, festivals) also
    spread half their arrivals over their first half and 40 % of their
    departures over their second half.  ``trips_arr`` and ``trips_dep`` are
    market trips; ``scale`` (the fleet's share × any demand scale) multiplies
    them after the event-hours are chosen, so it scales the result exactly.

    Returns ``arrivals`` and ``departures`` ``(hours, S)`` by venue sector
    and ``rows = (event index, hour, arrival trips, departure trips)``
    sorted by hour.
    """
    n_hours = hours_in_year(year)
    origin = dt.datetime(year, 1, 1)
    if not events:
        zero = np.zeros((n_hours, S))
        empty = np.zeros(0, dtype=np.int64)
        return zero, zero.copy(), (empty, empty, np.zeros(0), np.zeros(0))
    start = np.array([(e.start - origin).total_seconds() / 60 for e in events])
    dur = np.array([(e.end - e.start).total_seconds() / 60 for e in events])
    sector = np.array([e.sector for e in events])
    long = dur > LONG_EVENT_MIN
    w_pre = np.where(long, 0.5, 1.0)[:, None]
    w_post = np.where(long, 0.6, 1.0)[:, None]
    half = (dur / 2)[:, None]
    s0 = start[:, None]
    e0 = (start + dur)[:, None]

    def g_arr(t):  # share of arrivals entered before minute t
        return w_pre * (1 - gammainc(2.5, np.maximum(s0 - t - 5, 0) / 12.0)) + (1 - w_pre) * np.clip((t - s0) / half, 0, 1)

    def g_dep(t):
        return w_post * gammainc(1.5, np.maximum(t - e0 - 2, 0) / 12.0) + (1 - w_post) * np.clip((t - s0 - half) / half, 0, 1)

    span = int(np.max(np.ceil((start + dur) / 60) - start // 60)) + 4
    hours = (start // 60)[:, None] + np.arange(-4, span + 1)[None, :]
    t0, t1 = hours * 60, hours * 60 + 60
    a = (g_arr(t1) - g_arr(t0)) * trips_arr[:, None]
    d = (g_dep(t1) - g_dep(t0)) * trips_dep[:, None]
    ok = (hours >= 0) & (hours < n_hours) & ((a + d) > MIN_MARKET_TRIPS)
    a, d = a * scale, d * scale
    ev, col = np.nonzero(ok)
    h = hours[ev, col].astype(np.int64)
    arrivals = np.bincount(h * S + sector[ev], weights=a[ev, col], minlength=n_hours * S).reshape(n_hours, S)
    departures = np.bincount(h * S + sector[ev], weights=d[ev, col], minlength=n_hours * S).reshape(n_hours, S)
    order = np.argsort(h, kind="stable")
    rows = (ev[order], h[order], a[ev, col][order], d[ev, col][order])
    return arrivals, departures, rows

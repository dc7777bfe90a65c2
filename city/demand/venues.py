"""Venues and their calendar: a year of events before their text, with what drives attendance.

An :class:`EventSpec` is an event as its organiser plans it: venue, category,
name, time, capacity, the latent popularity and sentiment that drive its
attendance, and the standing of its performer or production before it
(``reputation``), which is all that reviews may speak to.
"""

from __future__ import annotations

import datetime as dt
import itertools
import random
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from city import texts
from city.demand.dates import evaluation_date
from city.demand.geography import random_nodes
from city.graph import City
from city.io.events import Venue
from city.io.weather import hours_in_year

VENUE_PLAN: tuple[tuple[str, int, int, int], ...] = (
    # (kind, count, min capacity, max capacity)
    ("theatre", 40, 500, 1900),
    ("arena", 1, 19000, 19000),
    ("convention center", 1, 20000, 20000),
    ("festival grounds", 1, 40000, 40000),
    ("park", 3, 5000, 15000),
    ("concert hall", 45, 300, 3000),
    ("stage", 10, 150, 800),
    ("conference center", 30, 300, 2500),
    ("community center", 169, 50, 600),
)
#: Venue kinds spread over the whole map (every sector with pickups gets at least one of each kind
#: while there are enough), so that event surges are not confined to midtown.
_SPREAD_KINDS = ("concert hall", "conference center")
_SURNAMES = (
    "Gershwin", "Majestic", "Imperial", "Shubert", "Booth", "Barrymore", "Belasco", "Ambassador", "Lyceum", "Hudson",
    "Palace", "Lunt", "Winter", "Minskoff", "Richard", "August", "Walter", "Eugene", "Neil", "Samuel", "Helen",
    "Hayes", "Nederlander", "Broadhurst", "Golden", "Jacobs", "Longacre", "Marquis", "Cort", "Stein", "Hirschfeld",
    "Lyric", "Vivian", "Circle", "Studio", "Friedman", "Music Box", "Schoenfeld", "Brooks", "Todd",
)
_HALL_NAMES = ("Hall", "Ballroom", "Room", "Music Hall", "Club", "Lounge", "Stage", "Garage", "Loft")
COMMUNITY_KINDS = ("Community Center", "Library", "Church Hall", "Gallery", "Recreation Center", "Settlement House")


def make_venues(city: City, anchors: dict[str, int], busy: np.ndarray, rng: np.random.Generator) -> list[Venue]:
    """About 300 venues: theatres around the theatre anchor, the arena, convention centre and park at
    their anchors, concert halls and conference centres in every sector (more in busy ones),
    everything else spread over sectors in proportion to their busyness."""
    S = city.n_sectors
    has_nodes = np.bincount(city.node_sector[city.pickup], minlength=S) > 0
    p_busy = np.where(has_nodes, busy, 0.0)
    p_busy = p_busy / p_busy.sum()
    theatre_nb = [s for s in city.local_sectors(anchors["theater"]) if s != anchors["theater"] and has_nodes[s]]
    out: list[Venue] = []
    for kind, count, cmin, cmax in VENUE_PLAN:
        if kind == "theatre":
            sectors = np.array([anchors["theater"] if rng.random() < 0.7 or not theatre_nb else rng.choice(theatre_nb) for _ in range(count)])
        elif kind in ("arena", "convention center", "festival grounds"):
            key = {"arena": "arena", "convention center": "expo", "festival grounds": "park"}[kind]
            sectors = np.full(count, anchors[key])
        elif kind in _SPREAD_KINDS:
            p_spread = np.where(has_nodes, np.sqrt(busy), 0.0)
            p_spread = p_spread / p_spread.sum()
            cover = rng.choice(S, size=min(count, int(has_nodes.sum())), replace=False, p=p_spread)
            sectors = np.concatenate([cover, rng.choice(S, size=count - len(cover), p=p_spread)]).astype(np.int64)
        else:
            sectors = rng.choice(S, size=count, p=p_busy)
        nodes = random_nodes(city, sectors, rng)
        caps = np.round(rng.uniform(cmin, cmax, count), -1).astype(int) if cmax > cmin else np.full(count, cmin)
        for i in range(count):
            out.append(
                Venue(
                    venue_id=f"V{len(out):03d}",
                    name=_venue_name(kind, i, city.sector_names[sectors[i]], rng),
                    node=int(nodes[i]),
                    sector=int(sectors[i]),
                    capacity=int(caps[i]),
                    kind=kind,
                )
            )
    return out


def _venue_name(kind: str, i: int, sector_name: str, rng: np.random.Generator) -> str:
    if kind == "theatre":
        return f"{_SURNAMES[i % len(_SURNAMES)]} Theatre"
    if kind == "arena":
        return "Garden Arena"
    if kind == "convention center":
        return "Hudson Convention Center"
    if kind == "festival grounds":
        return "Riverside Festival Grounds"
    if kind == "park":
        return f"{sector_name} Park" if i == 0 else f"Pier {40 + 17 * i}"
    if kind == "concert hall":
        return f"The {texts.BAND_ADJ[i % len(texts.BAND_ADJ)]} {_HALL_NAMES[i % len(_HALL_NAMES)]}"
    if kind == "stage":
        return f"{_SURNAMES[(3 * i + 7) % len(_SURNAMES)]} Playhouse"
    if kind == "conference center":
        return f"{sector_name} Conference Center" if i % 3 == 0 else f"Grand {_SURNAMES[(5 * i) % len(_SURNAMES)]} Hotel"
    return f"{sector_name} {_pick(rng, COMMUNITY_KINDS)}"


@dataclass(frozen=True)
class EventSpec:
    """An event before its text: what drives its attendance, and where and when."""

    venue: int
    category: str
    name: str
    start: dt.datetime
    minutes: int
    popularity: float
    sentiment: float
    capacity: int
    cue: str | None = None
    group: int = -1  # events of one production or multi-day show share their reviews
    #: The performer's or production's standing before this event (what its earlier events drew);
    #: None: the event's own popularity blurred by a draw (see :mod:`city.demand.attendance`).
    reputation: float | None = None


#: Popularity shift by month for stage shows (January slump, holiday peak).
_STAGE_MONTH = (-0.12, -0.08, -0.02, 0.0, 0.02, 0.03, 0.04, 0.03, -0.04, 0.0, 0.04, 0.10)
#: Relative chance that an arena or club event falls on each weekday (Mon … Sun).
_NIGHT_WEIGHT = np.array([0.8, 1.1, 1.1, 0.6, 1.3, 1.3, 1.0])
_CLUB_WEIGHT = np.array([0.5, 0.7, 0.9, 1.0, 1.5, 1.6, 0.8])


def schedule(venues: list[Venue], year: int, rng: np.random.Generator) -> list[EventSpec]:
    """A year of events at the venues, with the evaluation evening's surge guaranteed."""
    by_kind: dict[str, list[int]] = {}
    for i, v in enumerate(venues):
        by_kind.setdefault(v.kind, []).append(i)
    days = [dt.date(year, 1, 1) + dt.timedelta(days=d) for d in range(hours_in_year(year) // 24)]
    eve = evaluation_date(year)
    specs: list[EventSpec] = []
    groups = itertools.count()
    specs += _broadway(venues, by_kind["theatre"], days, rng, groups)
    specs += _arena(venues[by_kind["arena"][0]], by_kind["arena"][0], days, eve, rng)
    specs += _convention(venues[by_kind["convention center"][0]], by_kind["convention center"][0], days, eve, rng, groups)
    specs += _festivals(venues, by_kind["festival grounds"] + by_kind["park"], days, rng)
    specs += _small_events(venues, by_kind, days, year, rng)
    return specs


def _beta(rng: np.random.Generator, a: float, b: float) -> float:
    return float(rng.beta(a, b))


def _pick(rng: np.random.Generator, options: Sequence[str]) -> str:
    return options[int(rng.integers(len(options)))]


def _at(day: dt.date, hour: float) -> dt.datetime:
    return dt.datetime.combine(day, dt.time()) + dt.timedelta(minutes=round(hour * 60))


def _broadway(venues: list[Venue], theatres: list[int], days: list[dt.date], rng: np.random.Generator, groups: Iterator[int]) -> list[EventSpec]:
    """Runs of productions at each theatre; performances Tue–Sun evenings plus Wed/Sat/Sun matinees.

    Ten hits run all year; other productions run 8–40 weeks with dark weeks
    between.  A performance's popularity is its production's, shifted by
    month, weekend, opening night (+0.2) and final week (+0.12).
    """
    hits = list(texts.BROADWAY_HITS)
    others = [str(n) for n in rng.permutation(texts.BROADWAY_SHOWS)]
    specs: list[EventSpec] = []
    n_days = len(days)
    for k, t in enumerate(theatres):
        d = 0 if k < len(hits) else int(rng.integers(-120, 20))
        while d < n_days:
            if k < len(hits):
                name, length = hits[k], n_days
                pop, sent = _beta(rng, 9, 2), _beta(rng, 7, 2)
            else:
                name = others.pop(0) if others else f"{_pick(rng, texts.BROADWAY_SHOWS)} (Revival)"
                length = int(rng.integers(8, 41)) * 7
                pop, sent = _beta(rng, 2.5, 2.5), _beta(rng, 2.5, 1.8)
            first, last = d, d + length - 1
            evening = 19.0 if rng.random() < 0.4 else 20.0
            sunday_evening = rng.random() < 0.3
            wed_matinee = rng.random() < 0.6
            minutes = int(rng.integers(130, 171))
            group = next(groups)
            for day_i in range(max(first, 0), min(last + 1, n_days)):
                day = days[day_i]
                wd = day.weekday()
                slots = []
                if 1 <= wd <= 5 or (wd == 6 and sunday_evening):
                    slots.append(19.0 if wd in (1, 6) else evening)
                if (wd == 2 and wed_matinee) or wd in (5, 6):
                    slots.append(14.0)
                for slot in slots:
                    cue = "Opening Night" if day_i == first and first > 0 and slot > 17 else None
                    if cue is None and last < n_days - 1 and day_i > last - 7:
                        cue = "Final Week"
                    p = pop + _STAGE_MONTH[day.month - 1] + 0.05 * (wd in (4, 5) and slot > 17) - 0.05 * (slot < 17)
                    p += 0.2 * (cue == "Opening Night") + 0.12 * (cue == "Final Week") + rng.normal(0.0, 0.04)
                    specs.append(EventSpec(t, "performing-arts", name, _at(day, slot), minutes, float(np.clip(p, 0.02, 1.0)), sent, venues[t].capacity, cue, group, float(np.clip(pop, 0.02, 1.0))))
            d = last + 1 + int(rng.integers(1, 6)) * 7
    return specs


def _pick_days(rng: np.random.Generator, candidates: list[int], days: list[dt.date], weights: np.ndarray, n: int, taken: set[int]) -> list[int]:
    """``n`` distinct days among ``candidates`` not in ``taken``, weighted by weekday."""
    free = [d for d in candidates if d not in taken]
    if not free or n <= 0:
        return []
    w = np.array([weights[days[d].weekday()] for d in free])
    chosen = rng.choice(free, size=min(n, len(free)), replace=False, p=w / w.sum())
    taken.update(int(c) for c in chosen)
    return sorted(int(c) for c in chosen)


def _arena(venue: Venue, vi: int, days: list[dt.date], eve: dt.date, rng: np.random.Generator) -> list[EventSpec]:
    """Basketball, hockey, summer basketball, concerts, college games and specials: ~3 nights a week.

    The evaluation evening always has a sold-out marquee game (a national-TV 20:00 tip-off).
    """
    n = len(days)
    idx = {day: i for i, day in enumerate(days)}
    season = [i for i, d in enumerate(days) if d <= dt.date(d.year, 4, 10) or d >= dt.date(d.year, 10, 20)]
    summer = [i for i, d in enumerate(days) if dt.date(d.year, 5, 15) <= d <= dt.date(d.year, 9, 15)]
    taken = {idx[eve]}
    specs = [EventSpec(vi, "sports", "Knicks vs. Celtics", _at(eve, 20.0), 150, 0.95, 0.85, venue.capacity)]
    plan = (
        ("basketball", "sports", season, 40, 19.5, 150, (5, 2)),
        ("hockey", "sports", season, 41, 19.0, 165, (5, 2)),
        ("wnba", "sports", summer, 18, 19.5, 140, (3, 3)),
        ("college", "sports", season, 10, 19.0, 130, (2, 3)),
        ("concert", "concerts", list(range(n)), 42, 20.0, 180, (6, 2)),
        ("special", "sports", list(range(n)), 12, 19.5, 180, (3, 2.5)),
    )
    for kind, category, candidates, count, hour, minutes, (a, b) in plan:
        for d in _pick_days(rng, candidates, days, _NIGHT_WEIGHT, count, taken):
            day = days[d]
            if kind in texts.TEAMS:
                home, rivals = texts.TEAMS[kind]
                rival = _pick(rng, rivals)
                name = f"{home} vs. {rival}"
                pop = _beta(rng, a, b) + 0.12 * (rival in texts.MARQUEE)
                cap = venue.capacity if kind in ("basketball", "hockey") else 10000
            elif kind == "concert":
                name, pop, cap = f"The {_pick(rng, texts.BAND_ADJ)} {_pick(rng, texts.BAND_NOUN)}: Arena Tour", _beta(rng, a, b), venue.capacity
            else:
                name, pop, cap = _pick(rng, texts.SPORTS_SPECIALS), _beta(rng, a, b), venue.capacity
            start_h = hour if day.weekday() < 5 or rng.random() < 0.6 else 13.0
            specs.append(EventSpec(vi, category, name, _at(day, start_h), minutes, float(min(pop, 1.0)), _beta(rng, 4, 2), cap))
    return specs


def _convention(venue: Venue, vi: int, days: list[dt.date], eve: dt.date, rng: np.random.Generator, groups: Iterator[int]) -> list[EventSpec]:
    """Expos and conferences of 2–4 days, one at a time, opening 10:00 (conferences 8:30) and closing 17:00–19:00.

    The evaluation date is the closing day of a big tech expo that ends at 19:00.
    """
    idx = {day: i for i, day in enumerate(days)}
    e = idx[eve]
    busy = set(range(e - 3, e + 2))  # the eval show plus a setup day either side
    specs: list[EventSpec] = []
    g = next(groups)
    for k, (pop, hours) in enumerate(((0.72, (10, 18)), (0.78, (10, 18)), (0.93, (10, 19)))):
        cue = "Opening Day" if k == 0 else "Final Day" if k == 2 else None
        day = days[e - 2 + k]
        specs.append(EventSpec(vi, "expos", f"NY Tech Expo {day.year}", _at(day, hours[0]), 60 * (hours[1] - hours[0]), pop, 0.8, 18000, cue, g, 0.8))
    shows = [str(s) for s in rng.permutation(texts.EXPOS) if s != "NY Tech Expo"]
    n_days = len(days)
    for j in range(34):
        conference = j % 4 == 3
        length = int(rng.integers(2, 4 if conference else 5))
        for _ in range(50):  # find a free slot; give up on this show if the calendar is full
            d0 = int(rng.integers(0, n_days - length))
            span = set(range(d0 - 1, d0 + length + 1))
            if not span & busy and (conference or days[d0].weekday() < 5):
                break
        else:
            continue
        busy |= span
        if conference:
            name = f"{_pick(rng, texts.CONF_TOPICS)} {_pick(rng, texts.CONF_FORMATS)} {days[d0].year}"
            category, cap, open_h = "conferences", int(rng.integers(30, 81)) * 100, 8.5
        else:
            name, category, cap, open_h = f"{shows[j % len(shows)]} {days[d0].year}", "expos", int(rng.integers(10, 41)) * 500, 10.0
        base, sent = _beta(rng, 3, 2), _beta(rng, 3, 2)
        close_h = float(rng.choice([17.0, 17.5, 18.0, 19.0]))
        g = next(groups)
        for k in range(length):
            cue = "Opening Day" if k == 0 else "Final Day" if k == length - 1 else None
            pop = float(np.clip(base + 0.05 * (k == length - 1) + rng.normal(0, 0.03), 0.02, 1.0))
            specs.append(EventSpec(vi, category, name, _at(days[d0 + k], open_h), round(60 * (close_h - open_h)), pop, sent, cap, cue, g, base))
    return specs


def _festivals(venues: list[Venue], grounds: list[int], days: list[dt.date], rng: np.random.Generator) -> list[EventSpec]:
    """Weekend festivals May–October at the festival grounds and parks, plus winter markets and lights."""
    specs: list[EventSpec] = []
    for rank, vi in enumerate(grounds):
        venue = venues[vi]
        weekend = [i for i, d in enumerate(days) if d.weekday() >= 5 and 5 <= d.month <= 10]
        share = 0.7 if rank == 0 else 0.2
        for d in weekend:
            if rng.random() < share:
                day = days[d]
                name = _pick(rng, texts.FESTIVALS)
                cap = int(venue.capacity * rng.uniform(0.5, 1.0)) // 500 * 500
                specs.append(EventSpec(vi, "festivals", f"{name} {day.year}", _at(day, 11.0 + rng.integers(0, 3)), int(rng.integers(6, 10)) * 60, _beta(rng, 3, 2), _beta(rng, 4, 2), cap))
        if rank == 0:
            for d in (i for i, dd in enumerate(days) if dd.month == 12 and dd.weekday() >= 5 and dd.day < 25):
                day = days[d]
                name = _pick(rng, texts.WINTER_FESTIVALS)
                specs.append(EventSpec(vi, "festivals", f"{name} {day.year}", _at(day, 12.0), 8 * 60, _beta(rng, 4, 2), _beta(rng, 4, 2), venue.capacity // 2))
    return specs


def _small_events(venues: list[Venue], by_kind: dict[str, list[int]], days: list[dt.date], year: int, rng: np.random.Generator) -> list[EventSpec]:
    """Club concerts, small-stage shows, hotel conferences and talks, and community events.

    These are the irregular events that drive the evening surges: a concert
    hall holds a show on about one day in five and a conference centre an
    event on about two weekdays in five, on days drawn at random, with
    popularity (hence attendance and taxi trips) varying widely from one
    event to the next.  Evening concerts start 19:30–21:00 (arrivals in the
    19 h hour); weekend shows start at 15:00–15:30 (ending around 17:00) or
    18:00; day conferences close at 17:00–17:30 and evening talks and
    receptions start at 18:00–18:30 (arrivals at 17 h, departures around 19 h).
    """
    specs: list[EventSpec] = []
    n = len(days)
    name_rng = random.Random(int(rng.integers(1 << 30)))
    weekdays = [i for i, d in enumerate(days) if d.weekday() < 5]
    weekend = np.array([0.05, 0.05, 0.05, 0.05, 0.1, 1.0, 1.0])
    plan = (
        ("concert hall", "concerts", 60, _CLUB_WEIGHT, (19.5, 20.0, 20.0, 20.5, 21.0), (120, 181), (2, 2.5)),
        ("concert hall", "concerts", 16, weekend, (15.0, 15.5, 18.0, 18.0), (100, 131), (2, 2.5)),
        ("stage", "performing-arts", 60, _CLUB_WEIGHT, (19.0, 19.5, 21.5), (90, 121), (2, 3)),
        ("conference center", "conferences", 24, None, (8.5,), (510, 541), (2, 3)),
        ("conference center", "conferences", 75, None, (18.0, 18.0, 18.5), (60, 101), (2, 2.5)),
        ("community center", "community", 4, np.array([1.0, 1.0, 1.0, 1.0, 0.8, 1.2, 1.0]), (18.0, 18.5, 10.0), (90, 181), (1.3, 4)),
        ("park", "community", 3, np.array([0.5, 0.5, 0.5, 0.5, 0.5, 1.5, 1.5]), (10.0, 11.0), (120, 241), (1.5, 3)),
    )
    for kind, category, per_year, weights, hours, (mlo, mhi), (a, b) in plan:
        for vi in by_kind[kind]:
            venue = venues[vi]
            count = int(rng.poisson(per_year))
            if weights is None:
                chosen = sorted(int(d) for d in rng.choice(weekdays, size=min(count, len(weekdays)), replace=False))
            else:
                chosen = _pick_days(rng, list(range(n)), days, weights, count, set())
            for d in chosen:
                day = days[d]
                hour = float(rng.choice(hours))
                minutes = int(rng.integers(mlo, mhi))
                if category == "concerts":
                    name = texts.concert_name(name_rng)
                elif category == "performing-arts":
                    name = name_rng.choice(texts.SMALL_STAGE)
                elif category == "conferences":
                    name = texts.conference_name(name_rng, year)
                else:
                    name = name_rng.choice(texts.COMMUNITY)
                specs.append(EventSpec(vi, category, name, _at(day, hour), minutes, _beta(rng, a, b), _beta(rng, 3, 2), venue.capacity))
    return specs

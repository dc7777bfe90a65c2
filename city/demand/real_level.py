"""Base demand at the real level of every hour: a city's real hourly trip totals, split over sectors.

With a ``[[trips]] kind = "hourly-totals"`` file (for ``nyc``: the real
count of Manhattan-to-Manhattan trips of every hour of 2022), the base
demand of a date and hour is that hour's real total × share, split over
pickup sectors by :func:`sector_split` and over drop-off sectors by the
zone profile's β.  The real total already holds that hour's weather, holiday
and the day's real events, so no weather or holiday factor is applied.

Events.  The synthetic world's event calendar is not the real one, and the
real total of an hour already holds the demand of the real events of that
hour.  So the real total is read as *base + usual events*: the world's
expected requests of an hour are ``total × share + E(h) − Ē(kind, hour)``,
where ``E(h)`` is the world's event trips that hour and ``Ē`` their mean over
the year's days of the same weekday and hour (the synthetic calendar
schedules events by weekday, holidays included).  Surges then count only
above the usual event level, a quiet hour sits a little below its real
total, and over the year the expected requests of each weekday and hour sum
to the real totals × share exactly (unless the floor below binds).  A world without events gives each hour's real total ×
share.

Split.  Business days use the zone profile's pickup shares of their weekday
and hour.  Saturdays and Sundays/holidays use the profile's Monday–Friday
mean shares times each sector's weekend-to-business-day ratio in a
``zone-hourly`` file (for ``nyc``: January 2022 yellow pickups per zone),
so the company mix of the zone file (yellow cabs only) cancels out and only
its weekend shift is used.  Without a zone-hourly file weekends keep the
weekday-mean shares; without a profile the zone file's shares by day type
are used; with neither, the synthetic map's sector intensity.
"""

from __future__ import annotations

import datetime as dt

import numpy as np

from city.demand.dates import day_kind
from city.demand.profile import REF_RATE

#: Pseudo-count (trips per day and hour) added to both sides of a weekend-to-weekday ratio, so a sector
#: with a handful of trips an hour does not swing its share on noise.
RATIO_PSEUDO_COUNT = 1.0
#: Least share of an hour's real total kept as base demand when the usual event trips are taken out.
BASE_FLOOR = 0.5
#: Months whose business-day 19 h totals set the default share (the training months, January … June).
REFERENCE_MONTHS = range(1, 7)


def day_kinds(year: int, holidays: frozenset[dt.date]) -> np.ndarray:
    """``(days,)`` profile row of every day of ``year``: 0 … 6 = Monday … Sunday, holidays 6 (``frozenset()``: the weekdays)."""
    days = (dt.date(year + 1, 1, 1) - dt.date(year, 1, 1)).days
    return np.array([day_kind(dt.date(year, 1, 1) + dt.timedelta(days=d), holidays) for d in range(days)], dtype=np.int64)


def default_share(totals: np.ndarray, kinds: np.ndarray, year: int) -> float:
    """The share that puts the mean business-day 19 h of January–June at :data:`REF_RATE` requests (a 100-taxi fleet's load).

    Chosen on the training months only, so that no test-month total sets it.
    """
    month = np.array([(dt.date(year, 1, 1) + dt.timedelta(days=int(d))).month for d in range(len(kinds))])
    days = np.flatnonzero((kinds < 5) & np.isin(month, list(REFERENCE_MONTHS)))
    return float(REF_RATE / totals.reshape(-1, 24)[days, 19].mean())


def sector_split(profile_rate: np.ndarray | None, zone_by_type: np.ndarray | None, fallback: np.ndarray) -> np.ndarray:
    """``(7, 24, S)`` pickup shares by day kind and hour, each ``(kind, hour)`` summing to one; see the module docstring.

    ``profile_rate`` is a zone profile's ``(5, 24, S)`` pickups per business
    day, ``zone_by_type`` a zone file's ``(3, 24, S)`` mean pickups per
    business day, Saturday and Sunday/holiday, ``fallback`` ``(24, S)`` the
    synthetic map's shares.
    """
    S = fallback.shape[1]
    out = np.empty((7, 24, S))
    if profile_rate is not None:
        out[:5] = profile_rate
        mean = profile_rate.mean(axis=0)
        for kind, t in ((5, 1), (6, 2)):
            ratio = 1.0 if zone_by_type is None else (zone_by_type[t] + RATIO_PSEUDO_COUNT) / (zone_by_type[0] + RATIO_PSEUDO_COUNT)
            out[kind] = mean * ratio
    elif zone_by_type is not None:
        out[:5] = zone_by_type[0]
        out[5], out[6] = zone_by_type[1], zone_by_type[2]
    else:
        out[:] = fallback
    total = out.sum(axis=2, keepdims=True)
    return np.where(total > 0, out / np.where(total > 0, total, 1.0), 1.0 / S)


def usual_by_kind_hour(values: np.ndarray, kinds: np.ndarray) -> np.ndarray:
    """``(hours,)``: for each hour, the mean of ``values`` over the year's hours of the same day kind and hour of day."""
    per_day = values.reshape(-1, 24)
    means = np.zeros((7, 24))
    for k in range(7):
        if (kinds == k).any():
            means[k] = per_day[kinds == k].mean(axis=0)
    return means[kinds].ravel()


def real_base(totals: np.ndarray, share: float, split: np.ndarray, kinds: np.ndarray,
              event_trips: np.ndarray, weekdays: np.ndarray) -> tuple[np.ndarray, int]:
    """``(hours, S)`` base demand: (real total × share − usual event trips) split over sectors, and the hours floored.

    ``kinds`` ``(days,)`` pick the split's rows (:func:`day_kinds`);
    ``event_trips`` ``(hours,)`` are the world's expected event requests per
    hour (already × share), their usual level taken per ``weekdays``
    ``(days,)`` and hour; the base of an hour keeps at least
    :data:`BASE_FLOOR` of its real total × share.
    """
    level = totals * share
    base = level - usual_by_kind_hour(event_trips, weekdays)
    floor = BASE_FLOOR * level
    floored = int((base < floor).sum())
    base = np.maximum(base, floor)
    hour = np.tile(np.arange(24), len(kinds))
    return base[:, None] * split[np.repeat(kinds, 24), hour], floored

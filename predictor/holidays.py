"""US federal holidays of a year, computed (5 U.S.C. 6103), no extra package.

Both the calendar date and the observed date (Saturday → Friday before,
Sunday → Monday after) of the fixed-date holidays are returned, since demand
reacts to both.  Juneteenth is included from 2021 on.
"""

from __future__ import annotations

import datetime as dt
from functools import lru_cache


def _nth_weekday(year: int, month: int, weekday: int, n: int) -> dt.date:
    d = dt.date(year, month, 1)
    d += dt.timedelta(days=(weekday - d.weekday()) % 7)
    return d + dt.timedelta(weeks=n - 1)


def _last_weekday(year: int, month: int, weekday: int) -> dt.date:
    d = dt.date(year + (month == 12), month % 12 + 1, 1) - dt.timedelta(days=1)
    return d - dt.timedelta(days=(d.weekday() - weekday) % 7)


def _observed(d: dt.date) -> dt.date:
    if d.weekday() == 5:
        return d - dt.timedelta(days=1)
    if d.weekday() == 6:
        return d + dt.timedelta(days=1)
    return d


@lru_cache(maxsize=None)
def us_federal_holidays(year: int) -> dict[dt.date, str]:
    """Dates of the federal holidays of ``year`` (calendar and observed) → name."""
    MON, THU = 0, 3
    fixed = {
        "New Year's Day": dt.date(year, 1, 1),
        "Independence Day": dt.date(year, 7, 4),
        "Veterans Day": dt.date(year, 11, 11),
        "Christmas Day": dt.date(year, 12, 25),
    }
    if year >= 2021:
        fixed["Juneteenth"] = dt.date(year, 6, 19)
    floating = {
        "Martin Luther King Jr. Day": _nth_weekday(year, 1, MON, 3),
        "Washington's Birthday": _nth_weekday(year, 2, MON, 3),
        "Memorial Day": _last_weekday(year, 5, MON),
        "Labor Day": _nth_weekday(year, 9, MON, 1),
        "Columbus Day": _nth_weekday(year, 10, MON, 2),
        "Thanksgiving Day": _nth_weekday(year, 11, THU, 4),
    }
    out: dict[dt.date, str] = {}
    for name, d in fixed.items():
        out[d] = name
        obs = _observed(d)
        if obs.year == year:
            out.setdefault(obs, name + " (observed)")
    # New Year's Day of next year observed on Dec 31 of this year.
    nxt = _observed(dt.date(year + 1, 1, 1))
    if nxt.year == year:
        out.setdefault(nxt, "New Year's Day (observed)")
    for name, d in floating.items():
        out[d] = name
    return dict(sorted(out.items()))


def is_holiday(d: dt.date) -> bool:
    return d in us_federal_holidays(d.year)

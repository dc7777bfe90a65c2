"""The demand world's calendar: its evaluation evening and the holidays that run on a Sunday profile."""

from __future__ import annotations

import datetime as dt
from functools import lru_cache

from city.calendar import holidays_for

#: The paper's evaluation date: a Thursday with Broadway and arena events and an event surge at 7 pm.
EVAL_DATE = dt.date(2022, 11, 17)
#: Country whose public holidays (the ``holidays`` package, observed dates included) the world follows.
HOLIDAY_COUNTRY = "US"


def evaluation_date(year: int) -> dt.date:
    """The world's surge evening: the third Thursday of November (2022-11-17 for 2022)."""
    nov1 = dt.date(year, 11, 1)
    return nov1 + dt.timedelta(days=(3 - nov1.weekday()) % 7 + 14)


@lru_cache(maxsize=None)
def holiday_dates(year: int, country: str = HOLIDAY_COUNTRY, subdiv: str | None = None) -> frozenset[dt.date]:
    """Public holidays of ``year`` with their observed dates, from the ``holidays`` package.

    US federal holidays by default: the days that the real zone profile leaves
    out of its business days.  A scenario file's ``[holidays]`` names another
    country or state.  The world gives them a Sunday profile.
    """
    return frozenset(holidays_for(year, country, subdiv))


def day_kind(date: dt.date, holidays: frozenset[dt.date] | None = None) -> int:
    """Profile row of a date: 0 … 6 for Monday … Sunday, holidays (default: US federal) as Sunday (6)."""
    off = holiday_dates(date.year) if holidays is None else holidays
    return 6 if date in off else date.weekday()

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
def holiday_dates(year: int) -> frozenset[dt.date]:
    """US federal holidays of ``year`` with their observed dates, from the ``holidays`` package.

    They are the days that the real zone profile leaves out of its business
    days, so the world gives them a Sunday profile.
    """
    return frozenset(holidays_for(year, HOLIDAY_COUNTRY))


def day_kind(date: dt.date) -> int:
    """Profile row of a date: 0 … 6 for Monday … Sunday, holidays as Sunday (6)."""
    return 6 if date in holiday_dates(date.year) else date.weekday()

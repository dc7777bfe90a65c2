"""Public holidays of any country or state, from the ``holidays`` package: the one source surge uses.

A scenario names its country (ISO 3166-1 code) and optionally a subdivision
(``subdiv``, e.g. ``NY``); the demand world and the predictor's features both
ask :func:`holidays_for`.  Observed dates (a Saturday holiday on the Friday
before, a Sunday one on the Monday after) are included, since demand reacts
to both.
"""

from __future__ import annotations

import datetime as dt
from functools import lru_cache

from city.errors import ConfigError


@lru_cache(maxsize=None)
def holidays_for(year: int, country: str = "US", subdiv: str | None = None) -> dict[dt.date, str]:
    """Dates of the public holidays of ``year`` (calendar and observed) → name, sorted by date.

    Raises
    ------
    ConfigError
        A country or subdivision the ``holidays`` package does not know.
    """
    import holidays

    known = holidays.list_supported_countries()
    if country not in known:
        raise ConfigError(f"holidays: unknown country {country!r}; use an ISO 3166-1 code such as US, GB or DE")
    if subdiv is not None and subdiv not in known[country]:
        raise ConfigError(f"holidays: {country} has no subdivision {subdiv!r}; it has {', '.join(known[country])}")
    return dict(sorted(holidays.country_holidays(country, subdiv=subdiv, years=year).items()))


def is_holiday(day: dt.date, country: str = "US", subdiv: str | None = None) -> bool:
    return day in holidays_for(day.year, country, subdiv)

"""Hourly weather for a year: temperature, precipitation and wind."""

from __future__ import annotations

import datetime as dt
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from city.errors import DataError


@dataclass(frozen=True)
class HourlyWeather:
    """One row per local hour of ``year``: index ``(day_of_year - 1) * 24 + hour``."""

    year: int
    temp_f: np.ndarray
    precip_in: np.ndarray
    wind_mph: np.ndarray
    source: str

    def index(self, when: dt.datetime) -> int:
        return (when.timetuple().tm_yday - 1) * 24 + when.hour

    def features(self, when: dt.datetime) -> tuple[float, float, float]:
        i = self.index(when)
        return float(self.temp_f[i]), float(self.precip_in[i]), float(self.wind_mph[i])


def hours_in_year(year: int) -> int:
    return (dt.date(year + 1, 1, 1) - dt.date(year, 1, 1)).days * 24


#: Columns of the hourly airport file (nycflights22 ``weather`` table) used by :func:`read_weather_csv`.
AIRPORT_COLUMNS: dict[str, str] = {"temp_f": "temp", "precip_in": "precip", "wind_mph": "wind_speed"}
#: Columns of the generic hourly file (local time, no offset needed).
GENERIC_COLUMNS: tuple[str, ...] = ("time", "temp_f", "precip_in", "wind_mph")


def read_weather_csv(
    path: Path | str, station: str = "LGA", year: int = 2022, columns: dict[str, str] | None = None, timezone: str = "America/New_York"
) -> HourlyWeather:
    """Read hourly weather for one local year from a CSV file.

    Two schemas are accepted: the hourly airport table (``origin, temp,
    precip, wind_speed, time_local_ny``, e.g. ``airports_hourly_2022.csv``),
    filtered to ``station``; or a generic ``time, temp_f, precip_in,
    wind_mph`` table in local time, whose column names ``columns`` may map
    (``{"time": "datetime", "temp_f": "temperature", ...}``). A trailing UTC
    offset on a time is ignored: the wall-clock time as written is the local
    hour.

    Clock changes (of ``timezone``): an hour the clocks skip in spring is
    filled with the previous hour's values; the hour repeated in autumn (01:00) is the mean of
    its readings, as is any other hour read twice. Any other missing hour is
    filled by linear interpolation in time (the nearest reading at the ends
    of the year) and reported with a warning.

    Raises
    ------
    DataError
        Missing columns, non-numeric values or bad times (naming file, row and
        column), or no readings for the station and year.
    """
    from city.io.tables import parse_times, read_csv

    path = Path(path)
    table = read_csv(path, [])
    if table.has("origin") and columns is None:
        table.require(["time_local_ny", *AIRPORT_COLUMNS.values()])
        at_station = np.array(table.col("origin")) == station
        if not at_station.any():
            found = ", ".join(sorted(set(table.col("origin"))))
            raise DataError(f"no rows for station {station!r} (stations: {found})", path=path)
        table = table.subset(at_station)
        time_col, value_cols = "time_local_ny", AIRPORT_COLUMNS
    else:
        names = {c: (columns or {}).get(c, c) for c in GENERIC_COLUMNS}
        table.require(list(names.values()))
        time_col, value_cols = names["time"], {c: names[c] for c in GENERIC_COLUMNS[1:]}

    when = parse_times(table, time_col).astype("datetime64[h]")
    idx = (when - np.datetime64(dt.datetime(year, 1, 1), "h")).astype(np.int64)
    n = hours_in_year(year)
    ok = (idx >= 0) & (idx < n)
    if not ok.any():
        raise DataError(f"no readings in {year} (column '{time_col}')", path=path)
    skipped = _skipped_hours(year, timezone)
    out = {}
    filled = 0
    for name, col in value_cols.items():
        values = table.floats(col, allow_empty=True)
        good = ok & np.isfinite(values)
        total = np.bincount(idx[good], weights=values[good], minlength=n)
        count = np.bincount(idx[good], minlength=n)
        for h in skipped:
            if count[h] == 0 and count[h - 1] > 0:
                total[h], count[h] = total[h - 1], count[h - 1]
        have = np.flatnonzero(count > 0)
        if len(have) == 0:
            raise DataError(f"column '{col}' has no readings in {year}", path=path)
        series = np.interp(np.arange(n), have, total[have] / count[have])
        filled = max(filled, n - len(have))
        out[name] = series
    if filled:
        warnings.warn(f"{path}: {filled} of {n} hours of {year} had no reading and were interpolated", stacklevel=2)
    source = f"{path.name}" + (f" ({station})" if value_cols is AIRPORT_COLUMNS else "")
    return HourlyWeather(year=year, source=source, **out)


def _skipped_hours(year: int, timezone: str) -> list[int]:
    """Indices of the local wall-clock hours of ``year`` that ``timezone``'s clocks skip (spring forward)."""
    from zoneinfo import ZoneInfo

    zone, utc = ZoneInfo(timezone), dt.timezone.utc
    start = dt.datetime(year, 1, 1)
    out = []
    for h in range(1, hours_in_year(year)):
        wall = start + dt.timedelta(hours=h)
        if wall.replace(tzinfo=zone).astimezone(utc).astimezone(zone).replace(tzinfo=None) != wall:
            out.append(h)
    return out

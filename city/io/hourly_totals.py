"""City-wide trips per date and hour: a ``date, hour, count`` table (CSV or parquet), optionally by company.

The layout of ``manhattan_hourly_trips_2019_2024.parquet`` (``date, hour,
trip_count, yellow, uber, lyft, …``) is one instance: a scenario file maps
the logical columns to the file's (``columns = {count = "trip_count"}``).
Hours are local wall-clock hours 0–23 of each date, so every day has 24.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from city.errors import DataError
from city.io.columnar import read_table
from city.io.weather import hours_in_year

#: Logical columns and their default names in the file.
COLUMNS = ("date", "hour", "count")
#: Per-company count columns read when the file has them (and no list is given).
COMPANIES = ("yellow", "green", "uber", "lyft", "via", "juno", "fhv")


@dataclass(frozen=True)
class HourlyTotals:
    """Trips per hour, sorted by hour.

    Attributes
    ----------
    start : ndarray of datetime64[h]
        The hour each count is for (local time).
    count : ndarray of float64
    companies : dict of str to ndarray
        Per-company counts of the same hours (empty cells read as 0).
    source : str
        The file's name.
    """

    start: np.ndarray
    count: np.ndarray
    companies: dict[str, np.ndarray]
    source: str

    def __len__(self) -> int:
        return len(self.start)

    def year(self, year: int) -> np.ndarray:
        """``(hours_in_year,)`` counts of every hour of ``year``; a missing hour raises naming the first."""
        first = np.datetime64(f"{year}-01-01T00", "h")
        lo, hi = np.searchsorted(self.start, [first, first + hours_in_year(year)])
        out = np.full(hours_in_year(year), np.nan)
        out[(self.start[lo:hi] - first).astype(np.int64)] = self.count[lo:hi]
        gap = np.flatnonzero(np.isnan(out))
        if len(gap):
            when = dt.datetime(year, 1, 1) + dt.timedelta(hours=int(gap[0]))
            raise DataError(f"no count for {when:%Y-%m-%d} hour {when.hour} ({len(gap)} of the {len(out)} hours of {year} missing)",
                            path=self.source)
        return out

    def covers(self, year: int) -> bool:
        """Whether every hour of ``year`` has a count."""
        first = np.datetime64(f"{year}-01-01T00", "h")
        lo, hi = np.searchsorted(self.start, [first, first + hours_in_year(year)])
        return hi - lo == hours_in_year(year)


def read_hourly_totals(path: Path | str, *, columns: dict[str, str] | None = None,
                       companies: tuple[str, ...] | None = None) -> HourlyTotals:
    """Read a ``date, hour, count`` table from CSV or parquet.

    Parameters
    ----------
    columns : dict, optional
        The file's names for ``date``, ``hour`` and ``count`` where they differ.
    companies : tuple of str, optional
        Per-company columns to read (each must exist); default: those of
        :data:`COMPANIES` the file has.

    Raises
    ------
    DataError
        A missing column, a date that is not a date, an hour outside 0–23, a
        negative or non-numeric count, or a date and hour given twice; the
        message names the file, the row and the field.
    """
    names = {c: c for c in COLUMNS} | dict(columns or {})
    wanted = list(companies) if companies is not None else []
    table = read_table(path, [names[c] for c in COLUMNS] + wanted, COMPANIES if companies is None else ())
    dates = table.times(names["date"]).astype("datetime64[D]")
    hours = table.numbers(names["hour"], integer=True, lo=0, hi=23)
    count = table.numbers(names["count"], lo=0)
    start = dates.astype("datetime64[h]") + hours.astype("timedelta64[h]")
    order = np.argsort(start, kind="stable")
    twice = np.flatnonzero(start[order][1:] == start[order][:-1])
    if len(twice):
        i, first = int(order[twice[0] + 1]), int(order[twice[0]])
        raise table.error(i, names["hour"], f"{str(dates[i])} hour {hours[i]} is also on row {table.rows[first]}")
    found = [c for c in (wanted or COMPANIES) if c in table.columns and c not in names.values()]
    by_company = {c: table.numbers(c, lo=0, empty=0.0)[order] for c in found}
    return HourlyTotals(start[order], count[order], by_company, Path(path).name)

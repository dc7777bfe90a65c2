"""Trips per zone and hour: a ``time, zone, count`` table (CSV or parquet), e.g. TLC pickups per taxi zone.

The layout of ``yellow_zone_hourly_2022_01.parquet`` (``pickup_hour,
pickup_location_id, rides``) is one instance: a scenario file maps the
logical columns to the file's.  Times are the starts of local hours.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from city.errors import DataError
from city.io.columnar import read_table

#: Logical columns and their default names in the file.
COLUMNS = ("time", "zone", "count")
#: Day types of :meth:`ZoneHourly.by_day_type`: business days, Saturdays, Sundays and holidays.
DAY_TYPES = ("business day", "Saturday", "Sunday or holiday")


@dataclass(frozen=True)
class ZoneHourly:
    """Counts per (hour, zone); ``time`` datetime64[h] local, ``zone`` the file's zone ids (TLC LocationIDs)."""

    time: np.ndarray
    zone: np.ndarray
    count: np.ndarray
    source: str

    def __len__(self) -> int:
        return len(self.time)

    def by_day_type(self, zone_ids: np.ndarray, holidays: frozenset[dt.date]) -> tuple[np.ndarray, np.ndarray]:
        """``(3, 24, S)`` mean counts per day of each type of :data:`DAY_TYPES`, by hour and zone of ``zone_ids``, and the days of each type.

        Zones not in ``zone_ids`` are left out; a day counts once it has any row.
        """
        lookup = {int(z): k for k, z in enumerate(zone_ids)}
        sector = np.array([lookup.get(int(z), -1) for z in self.zone], dtype=np.int64)
        day = self.time.astype("datetime64[D]")
        hour = (self.time - day.astype("datetime64[h]")).astype(np.int64)
        days = np.unique(day)
        kinds = np.array([_day_type(d.astype(dt.date), holidays) for d in days], dtype=np.int64)
        kind = kinds[np.searchsorted(days, day)]
        out = np.zeros((3, 24, len(zone_ids)))
        keep = sector >= 0
        np.add.at(out, (kind[keep], hour[keep], sector[keep]), self.count[keep])
        n_days = np.bincount(kinds, minlength=3)
        return out / np.maximum(n_days, 1)[:, None, None], n_days


def _day_type(date: dt.date, holidays: frozenset[dt.date]) -> int:
    if date in holidays or date.weekday() == 6:
        return 2
    return 1 if date.weekday() == 5 else 0


def read_zone_hourly(path: Path | str, *, columns: dict[str, str] | None = None, timezone: str | None = None) -> ZoneHourly:
    """Read a ``time, zone, count`` table from CSV or parquet.

    ``columns`` gives the file's names for ``time``, ``zone`` and ``count``
    where they differ; ``timezone`` is the wall clock of time-zone-aware
    timestamps.

    Raises
    ------
    DataError
        A missing column, a time that is not a date/time or not the start of
        an hour, a zone id that is not a positive integer, a negative or
        non-numeric count, or a zone and hour given twice; the message names
        the file, the row and the field.
    """
    names = {c: c for c in COLUMNS} | dict(columns or {})
    table = read_table(path, [names[c] for c in COLUMNS])
    when = table.times(names["time"], timezone)
    hour = when.astype("datetime64[h]")
    off = np.flatnonzero(hour.astype("datetime64[s]") != when)
    if len(off):
        i = int(off[0])
        raise table.error(i, names["time"], f"{str(when[i])} is not the start of an hour")
    zone = table.numbers(names["zone"], integer=True, lo=1)
    count = table.numbers(names["count"], lo=0)
    order = np.lexsort((zone, hour))
    twice = np.flatnonzero((hour[order][1:] == hour[order][:-1]) & (zone[order][1:] == zone[order][:-1]))
    if len(twice):
        i, first = int(order[twice[0] + 1]), int(order[twice[0]])
        raise table.error(i, names["zone"], f"zone {zone[i]} at {str(hour[i])}:00 is also on row {table.rows[first]}")
    if not len(table):
        raise DataError("no rows", path=path)
    return ZoneHourly(hour[order], zone[order], count[order], Path(path).name)

"""Occupancy schedules and the demand-assignment weight O(j, h) of the paper (§4.2.2).

O(j, h) = Σ_λ n_λ(j) · p_λ(h) · o_λ, over the locale types retail, restaurant,
hotel and hospital.  Normalised within a sector it gives the pickup and
drop-off intersection distributions ρ and δ.

The schedules are the project's own copy of the few DOE reference-building
numbers it needs (share of maximum occupancy per hour, ASHRAE 90.1 / COMNET
prototypes ``Retail Bldg Occ``, ``FullServiceRestaurant Bldg Occ``,
``LargeHotel Bldg Occ`` and ``Hospital Bldg Occ``).  A user may supply their own
table with :func:`read_occupancy_csv`.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np

from city.errors import DataError

LOCALE_TYPES: tuple[str, ...] = ("retail", "restaurant", "hotel", "hospital")
DAY_TYPES: tuple[str, ...] = ("weekday", "saturday", "sunday")

#: Estimated maximum occupancy o_λ (people) of one locale of each type.
MAX_OCCUPANCY: dict[str, float] = {"retail": 60.0, "restaurant": 90.0, "hotel": 400.0, "hospital": 600.0}

# fmt: off
SCHEDULES: dict[str, dict[str, tuple[float, ...]]] = {
    "retail": {
        "weekday":  (0, 0, 0, 0, 0, 0, 0, .1, .2, .5, .5, .7, .7, .7, .7, .8, .7, .5, .5, .3, .3, 0, 0, 0),
        "saturday": (0, 0, 0, 0, 0, 0, 0, .1, .2, .5, .6, .8, .8, .8, .8, .8, .8, .6, .2, .2, .2, .1, 0, 0),
        "sunday":   (0, 0, 0, 0, 0, 0, 0, 0, 0, .1, .2, .2, .4, .4, .4, .4, .4, .2, .1, 0, 0, 0, 0, 0),
    },
    "restaurant": {
        "weekday":  (.05, 0, 0, 0, 0, .05, .1, .4, .4, .4, .2, .5, .8, .7, .4, .2, .25, .5, .8, .8, .8, .5, .35, .2),
        "saturday": (.05, 0, 0, 0, 0, 0, .05, .5, .5, .4, .2, .45, .5, .5, .35, .3, .3, .3, .7, .9, .7, .65, .55, .35),
        "sunday":   (.05, 0, 0, 0, 0, 0, .05, .5, .5, .2, .2, .3, .5, .5, .3, .2, .25, .35, .55, .65, .7, .35, .2, .2),
    },
    "hotel": {
        "weekday":  (.9, .9, .9, .9, .9, .9, .7, .4, .4, .2, .2, .2, .2, .2, .2, .3, .5, .5, .5, .7, .7, .8, .9, .9),
        "saturday": (.9, .9, .9, .9, .9, .9, .7, .5, .5, .3, .3, .3, .3, .3, .3, .3, .3, .5, .6, .6, .6, .7, .7, .7),
        "sunday":   (.7, .7, .7, .7, .7, .7, .7, .7, .5, .5, .5, .3, .3, .2, .2, .2, .3, .4, .4, .6, .6, .8, .8, .8),
    },
    "hospital": {
        "weekday":  (.05, .05, .05, .05, .2, .2, .5, .9, .9, .9, .9, .9, .9, .9, .9, .9, .9, .9, .5, .5, .2, .2, .05, .05),
        "saturday": (.05, .05, .05, .05, .05, .05, .05, .2, .2, .3, .3, .3, .3, .3, .3, .2, .2, .2, .2, .2, .05, .05, .05, .05),
        "sunday":   (0, 0, 0, 0, 0, 0, 0, 0, .05, .05, .05, .05, .05, .05, .05, .05, .05, 0, 0, 0, 0, 0, 0, 0),
    },
}
# fmt: on

#: Reference schedule names in the DOE table for each locale type (used by the CSV reader).
REFERENCE_NAMES: dict[str, str] = {
    "retail": "Retail Bldg Occ",
    "restaurant": "FullServiceRestaurant Bldg Occ",
    "hotel": "LargeHotel Bldg Occ",
    "hospital": "Hospital Bldg Occ",
}


def day_type(date: dt.date) -> str:
    wd = date.weekday()
    return "saturday" if wd == 5 else "sunday" if wd == 6 else "weekday"


def schedule_matrix(schedules: dict[str, dict[str, tuple[float, ...]]] | None = None) -> np.ndarray:
    """Schedules as an array ``[day_type, hour, locale]``."""
    schedules = SCHEDULES if schedules is None else schedules
    return np.array(
        [[[schedules[loc][d][h] for loc in LOCALE_TYPES] for h in range(24)] for d in DAY_TYPES],
        dtype=np.float64,
    )


def occupancy(
    locale_counts: np.ndarray,
    hour: int,
    day: str,
    schedules: dict[str, dict[str, tuple[float, ...]]] | None = None,
    max_occupancy: dict[str, float] | None = None,
) -> np.ndarray:
    """O(j, h) for every intersection, from ``locale_counts`` of shape ``(n, 4)``."""
    sched = schedule_matrix(schedules)[DAY_TYPES.index(day), hour]
    occ = np.array([(max_occupancy or MAX_OCCUPANCY)[loc] for loc in LOCALE_TYPES])
    return np.asarray(locale_counts, dtype=np.float64) @ (sched * occ)


def sector_distribution(weights: np.ndarray, node_sector: np.ndarray, n_sectors: int, eligible: np.ndarray) -> np.ndarray:
    """Normalise per-node weights within each sector over eligible intersections.

    A sector whose eligible intersections all weigh zero falls back to uniform,
    so every sector's probabilities sum to one.
    """
    w = np.where(eligible, np.asarray(weights, dtype=np.float64), 0.0)
    totals = np.bincount(node_sector, weights=w, minlength=n_sectors)
    counts = np.bincount(node_sector, weights=eligible.astype(np.float64), minlength=n_sectors)
    uniform = eligible / np.maximum(counts[node_sector], 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = np.where(totals[node_sector] > 0, w / totals[node_sector], uniform)
    return p


#: Hour columns of an occupancy table.
HOUR_COLUMNS: tuple[str, ...] = tuple(f"h{h:02d}" for h in range(24))


def read_occupancy_csv(path: Path | str) -> dict[str, dict[str, tuple[float, ...]]]:
    """Read occupancy schedules ``schedule,day_type,h00..h23`` into the shape of :data:`SCHEDULES`.

    For each locale type a row whose ``schedule`` is exactly the locale name
    (``retail``, …) is used, else its DOE reference row (:data:`REFERENCE_NAMES`,
    e.g. ``Retail Bldg Occ``); other schedules in the file are ignored. Every
    locale needs all of :data:`DAY_TYPES`, each with 24 fractions in [0, 1].

    Raises
    ------
    DataError
        Naming the file and row of a bad value, or the locale/day type missing.
    """
    from city.io.tables import read_csv

    path = Path(path)
    table = read_csv(path, ["schedule", "day_type", *HOUR_COLUMNS])
    schedule, day = table.col("schedule"), table.col("day_type")
    out: dict[str, dict[str, tuple[float, ...]]] = {}
    for loc in LOCALE_TYPES:
        name = loc if loc in schedule else REFERENCE_NAMES[loc]
        rows = [i for i, s in enumerate(schedule) if s == name]
        if not rows:
            raise DataError(f"no schedule {loc!r} or {REFERENCE_NAMES[loc]!r}", path=path)
        days: dict[str, tuple[float, ...]] = {}
        for i in rows:
            if day[i] not in DAY_TYPES:
                raise table.error(i, f"column 'day_type': {day[i]!r} is not one of {', '.join(DAY_TYPES)}")
            cells = [table.col(h)[i] for h in HOUR_COLUMNS]
            if not all(cells):
                raise table.error(i, f"expected 24 hourly values h00..h23, found {sum(map(bool, cells))}")
            values = []
            for h, c in zip(HOUR_COLUMNS, cells):
                try:
                    v = float(c)
                except ValueError:
                    v = float("nan")
                if not 0.0 <= v <= 1.0:
                    raise table.error(i, f"column '{h}': {c!r} is not a fraction in [0, 1]")
                values.append(v)
            days[day[i]] = tuple(values)
        missing = [d for d in DAY_TYPES if d not in days]
        if missing:
            raise DataError(f"schedule {name!r} lacks day type(s) {', '.join(missing)}", path=path)
        out[loc] = days
    return out

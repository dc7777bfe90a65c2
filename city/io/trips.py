"""Historical trips: TLC High-Volume FHV parquet files and coordinate-level taxi CSVs.

Trips become a :class:`TripTable` of request minute and pickup/drop-off
sector, from which the demand model takes hourly pickup counts per sector
(:func:`hourly_counts`) and the drop-off sector distribution β
(:func:`od_matrix`).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from city.errors import DataError
from city.graph import City
from city.io.tables import nearest_nodes, parse_times, read_csv
from city.io.weather import hours_in_year

#: Columns of the official HV-FHV schema that the reader needs.
FHVHV_COLUMNS: tuple[str, ...] = ("request_datetime", "pickup_datetime", "PULocationID", "DOLocationID")
#: Parquet rows read at a time; bounds memory on monthly files of ~20 M trips.
BATCH_ROWS = 1 << 20


@dataclass(frozen=True)
class TripTable:
    """Trips inside a city's sectors.

    Attributes
    ----------
    request_time : ndarray of datetime64[m]
        Request minute, naive local time.
    pickup_sector, dropoff_sector : ndarray of int32
        Sector indices in the city (not TLC LocationIDs).
    n_read, n_dropped : int
        Rows read, and rows dropped because a zone or point lay outside the
        city (or a time was missing).
    """

    request_time: np.ndarray
    pickup_sector: np.ndarray
    dropoff_sector: np.ndarray
    n_read: int
    n_dropped: int

    def __len__(self) -> int:
        return len(self.request_time)


def read_fhvhv(paths: Path | str | Iterable[Path | str], city: City) -> TripTable:
    """Read TLC HV-FHV trip records (``fhvhv_tripdata_YYYY-MM.parquet``) for ``city``.

    The request time is ``request_datetime``, or ``pickup_datetime`` where the
    request time is null (rows with neither are dropped). Zone ids map to
    sectors through ``city.sector_ids``; trips starting or ending outside the
    city's zones are dropped.
    """
    if isinstance(paths, (str, Path)):
        paths = [paths]
    lookup = np.full(int(city.sector_ids.max()) + 2, -1, dtype=np.int32)
    lookup[city.sector_ids] = np.arange(city.n_sectors, dtype=np.int32)
    times, pus, dos = [], [], []
    n_read = 0
    for path in map(Path, paths):
        try:
            pfile = pq.ParquetFile(path)
        except (OSError, pa.ArrowException) as exc:
            raise DataError(f"not a readable parquet file ({exc})", path=path) from None
        names = pfile.schema_arrow.names
        for col in FHVHV_COLUMNS:
            if col not in names:
                raise DataError(f"missing column '{col}' (not the TLC HV-FHV schema)", path=path)
        try:
            for batch in pfile.iter_batches(batch_size=BATCH_ROWS, columns=list(FHVHV_COLUMNS)):
                n_read += batch.num_rows
                when = pc.coalesce(*(_local_seconds(batch.column(c), path, c) for c in FHVHV_COLUMNS[:2]))
                ids = [_zone_ids(batch.column(c), path, c) for c in FHVHV_COLUMNS[2:]]
                pu, do = (lookup[np.clip(z, -1, len(lookup) - 1)] for z in ids)
                keep = (pu >= 0) & (do >= 0) & when.is_valid().to_numpy(zero_copy_only=False)
                times.append(when.to_numpy(zero_copy_only=False)[keep].astype("datetime64[m]"))
                pus.append(pu[keep])
                dos.append(do[keep])
        except pa.ArrowException as exc:
            raise DataError(f"cannot read trips ({exc})", path=path) from None
    request = np.concatenate(times) if times else np.array([], dtype="datetime64[m]")
    return TripTable(
        request_time=request,
        pickup_sector=np.concatenate(pus) if pus else np.array([], dtype=np.int32),
        dropoff_sector=np.concatenate(dos) if dos else np.array([], dtype=np.int32),
        n_read=n_read,
        n_dropped=n_read - len(request),
    )


def _local_seconds(column: pa.Array, path: Path, name: str) -> pa.Array:
    """A timestamp column as naive local time in seconds (TLC writes naive local times)."""
    if not pa.types.is_timestamp(column.type):
        raise DataError(f"column '{name}' is {column.type}, expected a timestamp", path=path)
    if column.type.tz is not None:
        column = pc.local_timestamp(column.cast(pa.timestamp(column.type.unit, "America/New_York")))
    return column.cast(pa.timestamp("s"), safe=False)


def _zone_ids(column: pa.Array, path: Path, name: str) -> np.ndarray:
    """A LocationID column as int64, nulls as -1."""
    if not pa.types.is_integer(column.type):
        raise DataError(f"column '{name}' is {column.type}, expected integer zone ids", path=path)
    return pc.fill_null(column.cast(pa.int64()), -1).to_numpy()


def read_yellow_csv(path: Path | str, city: City, max_dist_m: float = 300.0) -> TripTable:
    """Read taxi trips with coordinates (the Kaggle/TLC 2016 yellow-cab columns).

    Needs ``pickup_datetime, pickup_longitude, pickup_latitude,
    dropoff_longitude, dropoff_latitude``. Each end snaps to the nearest city
    node; trips with an end farther than ``max_dist_m`` from the street
    network are dropped.
    """
    cols = ["pickup_datetime", "pickup_longitude", "pickup_latitude", "dropoff_longitude", "dropoff_latitude"]
    table = read_csv(Path(path), cols)
    when = parse_times(table, "pickup_datetime").astype("datetime64[m]")
    pu_node, pu_ok = nearest_nodes(city, table.floats("pickup_longitude"), table.floats("pickup_latitude"), max_dist_m)
    do_node, do_ok = nearest_nodes(city, table.floats("dropoff_longitude"), table.floats("dropoff_latitude"), max_dist_m)
    keep = pu_ok & do_ok
    return TripTable(
        request_time=when[keep],
        pickup_sector=city.node_sector[pu_node[keep]].astype(np.int32),
        dropoff_sector=city.node_sector[do_node[keep]].astype(np.int32),
        n_read=len(table),
        n_dropped=int((~keep).sum()),
    )


def hourly_counts(trips: TripTable, year: int, n_sectors: int) -> np.ndarray:
    """Pickups per local hour of ``year`` and sector, shape ``(hours_in_year, n_sectors)``.

    Rows use :class:`city.io.weather.HourlyWeather`'s index (hours since 1 January
    00:00, wall clock); trips from other years are ignored.
    """
    hours = hours_in_year(year)
    start = np.datetime64(dt.datetime(year, 1, 1), "h")
    idx = (trips.request_time.astype("datetime64[h]") - start).astype(np.int64)
    ok = (idx >= 0) & (idx < hours)
    flat = idx[ok] * n_sectors + trips.pickup_sector[ok]
    return np.bincount(flat, minlength=hours * n_sectors).reshape(hours, n_sectors)


def od_matrix(trips: TripTable, n_sectors: int, months: Iterable[int] | None = None) -> np.ndarray:
    """β: relative frequency of each drop-off sector given the pickup sector, shape ``(S, S)``.

    Rows sum to one. A pickup sector with no trips gets a uniform row: with
    no evidence, no destination is favoured.  ``months`` (1 = January) keeps
    only the trips requested in those months, e.g. the training months, so
    that β holds nothing from the months a model is tested on.
    """
    pu, do = trips.pickup_sector, trips.dropoff_sector
    if months is not None:
        keep = in_months(trips, months)
        pu, do = pu[keep], do[keep]
    return od_frequencies(pu, do, n_sectors)


def in_months(trips: TripTable, months: Iterable[int], year: int | None = None) -> np.ndarray:
    """Which trips were requested in ``months`` (1 = January), of ``year`` only if given."""
    when = trips.request_time.astype("datetime64[M]").astype(np.int64)
    keep = np.isin(when % 12 + 1, np.asarray(list(months), dtype=np.int64))
    return keep if year is None else keep & (when // 12 + 1970 == year)


def od_frequencies(pickup_sector: np.ndarray, dropoff_sector: np.ndarray, n_sectors: int) -> np.ndarray:
    """Relative frequency of each drop-off sector given the pickup sector; a row without trips is uniform."""
    pu = np.asarray(pickup_sector, dtype=np.int64)
    do = np.asarray(dropoff_sector, dtype=np.int64)
    counts = np.bincount(pu * n_sectors + do, minlength=n_sectors * n_sectors).reshape(n_sectors, n_sectors).astype(np.float64)
    totals = counts.sum(axis=1, keepdims=True)
    return np.where(totals > 0, counts / np.maximum(totals, 1.0), 1.0 / n_sectors)


# ------------------------------------------------------------ zone-to-zone profiles
#: Columns of a zone profile (``manhattan_zone_od_15min_2018.csv``).
ZONE_PROFILE_COLUMNS: tuple[str, ...] = ("dow", "t_15min", "puzone", "dozone", "n_trips")
#: Ranges of the integer columns (inclusive): weekday 0 = Monday … 4 = Friday, slot 0 … 95.
_ZONE_RANGES = {"dow": (0, 4), "t_15min": (0, 95), "puzone": (1, 10**6), "dozone": (1, 10**6), "n_trips": (0, 10**12)}


@dataclass(frozen=True)
class ZoneProfile:
    """Trips between a city's sectors per business day, by weekday and 15-minute slot.

    Attributes
    ----------
    trips : ndarray of float64, shape (5, 96, S, S)
        Mean trips per business day of each weekday (Monday … Friday) and
        slot, from pickup sector to drop-off sector, both inside the city.
    business_days : ndarray of int, shape (5,)
        Days each weekday's counts were summed over.
    filled : tuple of int
        Sectors absent from the file, filled by :func:`fill_missing_sectors`.
    n_rows, n_outside : int
        Rows read, and rows with a zone outside the city (ignored).
    source : str
    """

    trips: np.ndarray
    business_days: np.ndarray
    filled: tuple[int, ...]
    n_rows: int
    n_outside: int
    source: str

    def hourly(self) -> np.ndarray:
        """``(5, 24, S, S)`` trips per business day and hour."""
        t = self.trips
        return t.reshape(5, 24, 4, *t.shape[2:]).sum(axis=2)

    def rate(self) -> np.ndarray:
        """η per business day: ``(5, 24, S)`` pickups per hour by pickup sector (the real base rate)."""
        return self.hourly().sum(axis=3)

    def beta(self) -> np.ndarray:
        """β per weekday and hour: ``(5, 24, S, S)``, rows sum to one (uniform where a sector has no trips)."""
        h = self.hourly()
        total = h.sum(axis=3, keepdims=True)
        return np.where(total > 0, h / np.maximum(total, 1e-300), 1.0 / h.shape[3])


def business_days(year: int) -> np.ndarray:
    """Monday … Friday counts of ``year`` that are not US federal holidays (``holidays`` package)."""
    from city.calendar import holidays_for

    off = holidays_for(year)
    out = np.zeros(5, dtype=np.int64)
    day = dt.date(year, 1, 1)
    while day.year == year:
        if day.weekday() < 5 and day not in off:
            out[day.weekday()] += 1
        day += dt.timedelta(days=1)
    return out


def read_zone_profile(path: Path | str, city: City, *, year: int = 2018) -> ZoneProfile:
    """Read a zone-to-zone trip-count profile (``dow,t_15min,puzone,dozone,n_trips``) for ``city``.

    ``n_trips`` is the number of trips of that weekday and slot summed over
    the business days of ``year`` (the format of
    ``manhattan_zone_od_15min_2018.csv``); counts are divided by the business
    days of each weekday (:func:`business_days`).  Zones are TLC LocationIDs
    mapped through ``city.sector_ids``; trips with an end outside the city
    are ignored.  City sectors with no pickups in the file are filled by
    :func:`fill_missing_sectors`, with a warning.

    Raises
    ------
    DataError
        A missing column, or a row with a non-integer or out-of-range field
        (the message names the file, the 1-based line and the field).
    """
    import warnings

    path = Path(path)
    values, n_rows = _zone_profile_columns(path)
    S = city.n_sectors
    lookup = np.full(max(int(city.sector_ids.max()), int(values["puzone"].max()), int(values["dozone"].max())) + 1, -1, dtype=np.int64)
    lookup[city.sector_ids] = np.arange(S)
    pu, do = lookup[values["puzone"]], lookup[values["dozone"]]
    inside = (pu >= 0) & (do >= 0)
    days = business_days(year)
    trips = np.zeros((5, 96, S, S))
    np.add.at(trips, (values["dow"][inside], values["t_15min"][inside], pu[inside], do[inside]), values["n_trips"][inside])
    trips /= days[:, None, None, None]
    missing = tuple(int(s) for s in np.flatnonzero(trips.sum(axis=(0, 1, 3)) == 0))
    if missing:
        trips = fill_missing_sectors(trips, city, missing)
        zones = ", ".join(f"{city.sector_ids[s]} ({city.sector_names[s]})" for s in missing)
        warnings.warn(f"{path}: no trips from zone {zones}; filled from its adjacent zones per intersection", stacklevel=2)
    return ZoneProfile(trips, days, missing, n_rows, int((~inside).sum()), str(path))


def _zone_profile_columns(path: Path) -> tuple[dict[str, np.ndarray], int]:
    """The profile's columns as int64 arrays; the first bad field raises a one-line :class:`DataError`."""
    import pandas as pd

    def fail(exc: Exception) -> DataError:
        return DataError(f"not a readable CSV file ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})", path=path)

    try:
        header = pd.read_csv(path, nrows=0).columns
    except (OSError, UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise fail(exc) from None
    for col in ZONE_PROFILE_COLUMNS:
        if col not in header:
            raise DataError(f"missing column '{col}' (expected {','.join(ZONE_PROFILE_COLUMNS)})", path=path)
    try:  # fast path: every field an integer
        table = pd.read_csv(path, usecols=list(ZONE_PROFILE_COLUMNS), dtype=np.int64)
        numeric = {c: table[c] for c in ZONE_PROFILE_COLUMNS}
        text = None
    except (ValueError, OverflowError):
        try:
            table = pd.read_csv(path, usecols=list(ZONE_PROFILE_COLUMNS), dtype=str, keep_default_na=False)
        except (UnicodeDecodeError, pd.errors.ParserError) as exc:
            raise fail(exc) from None
        text = table
        numeric = {c: pd.to_numeric(table[c].str.strip(), errors="coerce") for c in ZONE_PROFILE_COLUMNS}
    except (UnicodeDecodeError, pd.errors.ParserError) as exc:
        raise fail(exc) from None
    values = {}
    for col in ZONE_PROFILE_COLUMNS:
        num = numeric[col]
        lo, hi = _ZONE_RANGES[col]
        bad = (num.isna() | (num != np.floor(num)) | (num < lo) | (num > hi)).to_numpy()
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            shown = text[col].iloc[i] if text is not None else num.iloc[i]
            raise DataError(f"field '{col}': {shown!r} is not an integer in {lo}..{hi}", path=path, row=i + 2)
        values[col] = num.to_numpy(dtype=np.int64)
    return values, len(table)


def fill_missing_sectors(trips: np.ndarray, city: City, missing: tuple[int, ...]) -> np.ndarray:
    """Fallback for sectors a profile has no trips for: their adjacent sectors' trips per intersection.

    A missing sector's pickups to each destination, and every sector's
    drop-offs into it, are the mean over its adjacent sectors that have data
    of their trips per pickup-eligible intersection, times its own number of
    pickup-eligible intersections.  A missing sector with no such neighbour
    stays empty.
    """
    trips = trips.copy()
    size = np.bincount(city.node_sector[city.pickup], minlength=city.n_sectors).astype(np.float64)
    known = np.ones(city.n_sectors, dtype=bool)
    known[list(missing)] = False
    for m in missing:
        nb = [int(n) for n in np.flatnonzero(city.sector_adj[m]) if known[n] and size[n] > 0 and n != m]
        if not nb:
            continue
        per_node_row = np.mean([trips[:, :, n, :] / size[n] for n in nb], axis=0)
        trips[:, :, m, :] = per_node_row * size[m]
        per_node_col = np.mean([trips[:, :, :, n] / size[n] for n in nb], axis=0)
        trips[:, :, :, m] = per_node_col * size[m]
    return trips

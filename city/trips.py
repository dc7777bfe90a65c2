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
from city.csvio import nearest_nodes, parse_times, read_csv
from city.weather import hours_in_year

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

    Rows use :class:`city.weather.HourlyWeather`'s index (hours since 1 January
    00:00, wall clock); trips from other years are ignored.
    """
    hours = hours_in_year(year)
    start = np.datetime64(dt.datetime(year, 1, 1), "h")
    idx = (trips.request_time.astype("datetime64[h]") - start).astype(np.int64)
    ok = (idx >= 0) & (idx < hours)
    flat = idx[ok] * n_sectors + trips.pickup_sector[ok]
    return np.bincount(flat, minlength=hours * n_sectors).reshape(hours, n_sectors)


def od_matrix(trips: TripTable, n_sectors: int) -> np.ndarray:
    """β: relative frequency of each drop-off sector given the pickup sector, shape ``(S, S)``.

    Rows sum to one. A pickup sector with no trips gets a uniform row: with
    no evidence, no destination is favoured.
    """
    counts = np.bincount(
        trips.pickup_sector.astype(np.int64) * n_sectors + trips.dropoff_sector, minlength=n_sectors * n_sectors
    ).reshape(n_sectors, n_sectors).astype(np.float64)
    totals = counts.sum(axis=1, keepdims=True)
    return np.where(totals > 0, counts / np.maximum(totals, 1.0), 1.0 / n_sectors)

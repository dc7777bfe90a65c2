"""Reading users' CSV files with precise errors, and snapping lon/lat points to the map.

Every loader in ``city/`` reads through :func:`read_csv`, so a malformed file
always yields one :class:`~city.errors.DataError` naming the file and the line
as a text editor shows it.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from city.errors import ConfigError, DataError
from city.graph import City

EARTH_RADIUS_M = 6_371_008.8

def nearest_nodes(city: City, lon: np.ndarray, lat: np.ndarray, max_dist_m: float = 300.0) -> tuple[np.ndarray, np.ndarray]:
    """Nearest city node to each lon/lat point, and whether it lies within ``max_dist_m``.

    Distances use a local equirectangular projection around the city (exact to
    well under 1 % across a city).
    """
    from scipy.spatial import cKDTree

    if city.crs != "lonlat":
        raise ConfigError(f"city {city.name!r} has {city.crs!r} coordinates; lon/lat points need a lon/lat map")
    scale = np.array([math.cos(math.radians(float(np.mean(city.xy[:, 1])))), 1.0]) * math.radians(1) * EARTH_RADIUS_M
    tree = cKDTree(city.xy * scale)
    pts = np.column_stack([np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)])
    finite = np.isfinite(pts).all(axis=1)
    dist = np.full(len(pts), np.inf)
    node = np.zeros(len(pts), dtype=np.int64)
    if finite.any():
        dist[finite], node[finite] = tree.query(pts[finite] * scale)
    return node, dist <= max_dist_m


@dataclass(frozen=True)
class CsvTable:
    """Text columns of a CSV file with the 1-based line on which each record starts."""

    path: Path
    columns: dict[str, list[str]]
    lines: np.ndarray

    def __len__(self) -> int:
        return len(self.lines)

    def has(self, name: str) -> bool:
        return name in self.columns

    def require(self, names: Iterable[str]) -> None:
        """Raise a :class:`DataError` on line 1 unless every column in ``names`` exists."""
        _require_columns(self.path, list(self.columns), names)

    def col(self, name: str) -> list[str]:
        return self.columns[name]

    def subset(self, mask: np.ndarray) -> "CsvTable":
        idx = np.flatnonzero(mask)
        return CsvTable(self.path, {k: [v[i] for i in idx] for k, v in self.columns.items()}, self.lines[idx])

    def error(self, i: int, message: str) -> DataError:
        """A :class:`DataError` for record ``i`` (0-based) of this table."""
        return DataError(message, path=self.path, row=int(self.lines[i]))

    def floats(self, name: str, allow_empty: bool = False) -> np.ndarray:
        """Column ``name`` as float64; empty cells become NaN when ``allow_empty``."""
        values = [v if v or not allow_empty else "nan" for v in self.columns[name]]
        try:
            return np.array(values, dtype=np.float64)
        except ValueError:
            for i, v in enumerate(values):
                try:
                    float(v)
                except ValueError:
                    raise self.error(i, f"column '{name}': {v!r} is not a number") from None
            raise

    def ints(self, name: str) -> np.ndarray:
        """Column ``name`` as int64 (``12.0`` is accepted, ``12.5`` is not)."""
        out = np.empty(len(self), dtype=np.int64)
        for i, v in enumerate(self.columns[name]):
            try:
                out[i] = int(v)
            except ValueError:
                try:
                    f = float(v)
                    if not f.is_integer():
                        raise ValueError
                    out[i] = int(f)
                except (ValueError, OverflowError):
                    raise self.error(i, f"column '{name}': {v!r} is not an integer") from None
        return out


def read_csv(path: Path, required: list[str], *, header: bool = True) -> CsvTable:
    """Read a CSV file as text columns, checking that ``required`` columns exist.

    With ``header=False`` the file has no header line and ``required`` names its
    columns in order. Short records are padded with empty cells; a record with
    more cells than the header raises.
    """
    path = Path(path)
    try:
        fh = open(path, newline="", encoding="utf-8-sig")
    except OSError as exc:
        raise DataError(f"cannot open file ({exc.strerror or exc})", path=path) from None
    with fh:
        reader = csv.reader(fh)
        try:
            if header:
                names = [c.strip() for c in next(reader, [])]
            else:
                names = list(required)
            _require_columns(path, names, required)
            rows: list[list[str]] = []
            lines: list[int] = []
            start = reader.line_num + 1
            for rec in reader:
                if rec and any(cell.strip() for cell in rec):
                    if len(rec) > len(names):
                        raise DataError(f"{len(rec)} fields, but the header has {len(names)}", path=path, row=start)
                    rows.append(rec + [""] * (len(names) - len(rec)))
                    lines.append(start)
                start = reader.line_num + 1
        except (csv.Error, UnicodeDecodeError) as exc:
            raise DataError(f"not a readable CSV file ({exc})", path=path, row=reader.line_num or None) from None
    columns = {name: [r[k].strip() for r in rows] for k, name in enumerate(names)}
    return CsvTable(path, columns, np.array(lines, dtype=np.int64))


def _require_columns(path: Path, found: list[str], names: Iterable[str]) -> None:
    missing = [c for c in names if c not in found]
    if missing:
        raise DataError(f"missing column(s) {', '.join(map(repr, missing))} (found: {', '.join(found) or 'nothing'})", path=path, row=1)


_OFFSET = re.compile(r"(Z|[+-]\d\d:?\d\d)$")


def parse_times(table: CsvTable, name: str, fmt: str | None = None, *, strip_offset: bool = True) -> np.ndarray:
    """Column ``name`` as naive ``datetime64[s]`` wall-clock times.

    A trailing UTC offset (``-05:00``, ``Z``) is dropped when ``strip_offset``,
    so ``2021-12-31 19:00:00-05:00`` reads as 19:00 local time. ``fmt`` is a
    ``strptime`` format; without it ISO 8601 is expected.
    """
    import pandas as pd

    values = [(_OFFSET.sub("", v) if strip_offset else v) for v in table.col(name)]
    parsed = pd.to_datetime(pd.Series(values, dtype=object), format=fmt or "ISO8601", errors="coerce")
    bad = np.flatnonzero(parsed.isna().to_numpy())
    if len(bad):
        i = int(bad[0])
        expected = fmt or "ISO 8601, e.g. 2022-03-01 19:30"
        raise table.error(i, f"column '{name}': {table.col(name)[i]!r} is not a date/time ({expected})")
    return parsed.to_numpy().astype("datetime64[s]")

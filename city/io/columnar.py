"""Columns of a CSV or parquet table, checked one field at a time with errors naming file, row and field.

A CSV row is the line an editor shows (the header is line 1); a parquet row
is the 1-based position of the record in the file, since parquet has no lines.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from city.io.tables import read_csv
from city.errors import DataError

#: File endings read as parquet; anything else is read as CSV.
PARQUET_SUFFIXES = (".parquet", ".pq")


@dataclass(frozen=True)
class Table:
    """Named columns as read (text from CSV, typed from parquet) and the row number of each record."""

    path: Path
    columns: dict[str, np.ndarray]
    rows: np.ndarray

    def __len__(self) -> int:
        return len(self.rows)

    def error(self, i: int, field: str, message: str) -> DataError:
        """A :class:`DataError` naming record ``i`` (0-based) and ``field``."""
        return DataError(f"field '{field}': {message}", path=self.path, row=int(self.rows[i]))

    def numbers(self, name: str, *, integer: bool = False, lo: float | None = None, hi: float | None = None,
                empty: float | None = None) -> np.ndarray:
        """Column ``name`` as float64 (int64 with ``integer``); the first value that is not a number in ``lo..hi`` raises.

        ``empty`` replaces empty cells (nulls); without it they raise.
        """
        import pandas as pd

        raw = pd.Series(self.columns[name])
        blank = raw.isna().to_numpy() | (raw.astype(str).str.strip() == "").to_numpy()
        values = pd.to_numeric(raw.where(~blank, None), errors="coerce").to_numpy(dtype=np.float64)
        if empty is not None:
            values = np.where(blank, empty, values)
        bad = ~np.isfinite(values)
        if integer:
            bad |= values != np.floor(np.where(bad, 0.0, values))
        if lo is not None:
            bad |= values < lo
        if hi is not None:
            bad |= values > hi
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            kind = "an integer" if integer else "a number"
            limits = f" in {lo:g}..{hi:g}" if lo is not None and hi is not None else f" ≥ {lo:g}" if lo is not None else ""
            raise self.error(i, name, f"{raw.iloc[i]!r} is not {kind}{limits}")
        return values.astype(np.int64) if integer else values

    def times(self, name: str, timezone: str | None = None) -> np.ndarray:
        """Column ``name`` as naive local ``datetime64[s]``: ISO 8601 text, dates, or timestamps.

        A timestamp with a time zone is taken to ``timezone``'s wall clock; a
        text offset (``-05:00``) is dropped, the wall clock kept (as
        :func:`city.io.tables.parse_times` reads it).
        """
        import pandas as pd

        raw = pd.Series(self.columns[name])
        if isinstance(raw.dtype, pd.DatetimeTZDtype):
            parsed = raw.dt.tz_convert(timezone or "UTC").dt.tz_localize(None)
        elif pd.api.types.is_datetime64_dtype(raw.dtype):
            parsed = raw
        else:
            text = raw.astype(str).str.strip().str.replace(r"(Z|[+-]\d\d:?\d\d)$", "", regex=True)
            parsed = pd.to_datetime(text.where(raw.notna(), None), format="ISO8601", errors="coerce")
        bad = np.flatnonzero(parsed.isna().to_numpy())
        if len(bad):
            i = int(bad[0])
            raise self.error(i, name, f"{raw.iloc[i]!r} is not a date/time (ISO 8601, e.g. 2022-03-01 or 2022-03-01 19:00)")
        return parsed.to_numpy().astype("datetime64[s]")


def read_table(path: Path | str, required: list[str], optional: list[str] | tuple[str, ...] = ()) -> Table:
    """The ``required`` columns (a missing one raises on row 1) and those of ``optional`` the file has, from CSV or parquet."""
    path = Path(path)
    if path.suffix.lower() not in PARQUET_SUFFIXES:
        csv = read_csv(path, list(required))
        names = [*required, *(c for c in optional if csv.has(c) and c not in required)]
        return Table(path, {c: np.asarray(csv.col(c), dtype=object) for c in names}, csv.lines)
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        pfile = pq.ParquetFile(path)
    except FileNotFoundError:
        raise DataError("cannot open file (no such file)", path=path) from None
    except (OSError, pa.ArrowException) as exc:
        raise DataError(f"not a readable parquet file ({exc})", path=path) from None
    found = pfile.schema_arrow.names
    missing = [c for c in required if c not in found]
    if missing:
        raise DataError(f"missing column(s) {', '.join(map(repr, missing))} (found: {', '.join(found)})", path=path, row=1)
    names = [*required, *(c for c in optional if c in found and c not in required)]
    try:
        table = pfile.read(columns=names)
    except (OSError, pa.ArrowException) as exc:
        raise DataError(f"cannot read columns {', '.join(names)} ({exc})", path=path) from None
    columns = {c: table.column(c).to_pandas().to_numpy() if not _tz_aware(table.column(c).type) else table.column(c).to_pandas()
               for c in names}
    return Table(path, columns, np.arange(1, table.num_rows + 1, dtype=np.int64))


def _tz_aware(kind: object) -> bool:
    import pyarrow as pa

    return pa.types.is_timestamp(kind) and kind.tz is not None

"""The year's demand data as arrays: base features, event features and targets.

Split: train on January–June, validate on July–August, test on
September–December (the paper trains on the first 8 months and tests on the
last 4; surge carves its validation months out of the paper's training
months).  Normalisation statistics, network weights and β come from the
training months; early stopping and every design choice use the validation
months; the test months are touched only by ``surge predictor eval``.

Targets are hourly request counts per sector.  The networks predict on a
normalised scale, ``t = (log1p(y) - μ) / σ`` with μ, σ from the training
months; predictions are mapped back with ``expm1(σ t + μ)`` and clipped at 0.
The log scale makes the MSE weigh relative errors, which is what the paper's
percent-error metric measures, and keeps the large event surges from
dominating the loss of the standard network.
"""

from __future__ import annotations

import datetime as dt
import logging
import time
from dataclasses import dataclass

import numpy as np

from predictor.features import (
    LAG_HOURS,
    LEAD_HOURS,
    EventFeaturizer,
    MetadataFeaturizer,
    events_by_hour_sector,
    shuffled_texts,
    temporal_matrix,
    weather_matrix,
)

log = logging.getLogger(__name__)

#: Months 1..TRAIN_MONTHS train, the next VAL_MONTHS validate, the rest test.
TRAIN_MONTHS = 6
VAL_MONTHS = 2
PARTS = ("train", "val", "test")


@dataclass
class YearData:
    year: int
    n_sectors: int
    temporal: np.ndarray  # (H, T)
    weather: np.ndarray  # (H, 3) raw
    counts: np.ndarray  # (H, S) realised requests
    ev_hour: np.ndarray  # (E,) event samples: hour index
    ev_sector: np.ndarray  # (E,) sector
    ev_F: np.ndarray  # (E, (b+1)d) raw F_s
    ev_n: np.ndarray  # (E,) number of active events
    split_hour: int  # first test hour index (1 September 00:00)
    timings: dict
    val_hour: int = 0  # first validation hour index (1 July 00:00)
    ev_M: np.ndarray | None = None  # (E, M) raw event metadata: counts, categories, capacities
    ev_F_shuffled: np.ndarray | None = None  # (E, (b+1)d) F_s with texts permuted across events
    expected: np.ndarray | None = None  # (H, S) the world's true expected rate λ, where it has one

    @property
    def n_hours(self) -> int:
        return int(self.temporal.shape[0])

    def has_event(self) -> np.ndarray:
        m = np.zeros((self.n_hours, self.n_sectors), dtype=bool)
        m[self.ev_hour, self.ev_sector] = True
        return m

    def hours(self, part: str) -> range:
        """Hour indices of ``part`` (``train``, ``val`` or ``test``)."""
        return split_ranges(self.val_hour, self.split_hour, self.n_hours)[part]

    def event_rows(self, part: str) -> np.ndarray:
        """Indices of the event samples whose hour lies in ``part``."""
        r = self.hours(part)
        return np.flatnonzero((self.ev_hour >= r.start) & (self.ev_hour < r.stop))


def month_hour(year: int, month: int) -> int:
    """Hour index of 1 ``month`` 00:00 (month 13 = the end of the year)."""
    end = dt.date(year + 1, 1, 1) if month == 13 else dt.date(year, month, 1)
    return (end - dt.date(year, 1, 1)).days * 24


def split_hour(year: int) -> int:
    """First test hour: 1 September 00:00."""
    return month_hour(year, TRAIN_MONTHS + VAL_MONTHS + 1)


def val_hour(year: int) -> int:
    """First validation hour: 1 July 00:00."""
    return month_hour(year, TRAIN_MONTHS + 1)


def split_ranges(val_start: int, test_start: int, n_hours: int) -> dict[str, range]:
    return {"train": range(0, val_start), "val": range(val_start, test_start), "test": range(test_start, n_hours)}


def describe_split(year: int) -> dict:
    """The split as recorded in model.json and the evaluation JSON."""
    return {
        "train": f"{year}-01-01 to {year}-{TRAIN_MONTHS:02d} end (months 1-{TRAIN_MONTHS})",
        "validation": f"months {TRAIN_MONTHS + 1}-{TRAIN_MONTHS + VAL_MONTHS} (early stopping, design choices)",
        "test": f"months {TRAIN_MONTHS + VAL_MONTHS + 1}-12 (final figures only)",
        "val_hour": val_hour(year),
        "split_hour": split_hour(year),
    }


def world_expected(world, counts: np.ndarray) -> np.ndarray | None:
    """The world's true expected rate λ, or None where it has none (recorded worlds: λ is the counts)."""
    fn = getattr(world, "expected_rate", None)
    if fn is None:
        return None
    try:
        lam = np.asarray(fn(), dtype=np.float64)
    except (NotImplementedError, AttributeError):
        return None
    if lam.shape != counts.shape or np.array_equal(lam, counts):
        return None
    return lam


def world_counts(world) -> np.ndarray:
    return np.asarray(world.hourly_counts(), dtype=np.float64)


def build_year_data(world, featurizer: EventFeaturizer, *, lead: int = LEAD_HOURS, lag: int = LAG_HOURS, shuffle_seed: int = 0, verbose: bool = False) -> YearData:
    """Arrays of the whole year; ``shuffle_seed`` draws the text permutation of the shuffled-text control."""
    t0 = time.perf_counter()
    year = int(world.year)
    S = int(world.city.n_sectors)
    temporal = temporal_matrix(year, world.holidays)
    H = temporal.shape[0]
    counts = world_counts(world)
    if counts.shape != (H, S):
        raise ValueError(f"world.hourly_counts(): expected shape {(H, S)}, got {counts.shape}")
    weather = weather_matrix(world.weather, H)
    t_counts = time.perf_counter() - t0

    events = list(world.events)
    featurizer.prepare(events)
    groups = events_by_hour_sector(events, year, H, S, lead, lag)
    keys = sorted(groups)
    E = len(keys)
    meta = MetadataFeaturizer.from_world(world)
    swap = shuffled_texts(events, seed=shuffle_seed)
    F = np.zeros((E, featurizer.size), dtype=np.float32)
    F_shuf = np.zeros((E, featurizer.size), dtype=np.float32)
    M = np.zeros((E, meta.size), dtype=np.float32)
    ev_n = np.zeros(E, dtype=np.int32)
    for i, k in enumerate(keys):
        F[i] = featurizer.sector_feature(groups[k])
        F_shuf[i] = featurizer.sector_feature(groups[k], swap)
        M[i] = meta.sector_feature(groups[k])
        ev_n[i] = len(groups[k])
    ev_hour = np.array([k[0] for k in keys], dtype=np.int64)
    ev_sector = np.array([k[1] for k in keys], dtype=np.int64)
    timings = {
        "world_counts_s": round(t_counts, 2),
        "embed_s": round(featurizer.timings["embed_s"], 2),
        "cluster_s": round(featurizer.timings["cluster_s"], 2),
        "total_s": round(time.perf_counter() - t0, 2),
        "n_events": len(events),
        "n_event_samples": E,
        "embedder": dict(getattr(featurizer.embedder, "stats", {})),
    }
    if verbose:
        log.info("data: %d hours x %d sectors, %d events -> %d event sector-hours; features built in %.1fs",
                 H, S, len(events), E, timings["total_s"])
    return YearData(
        year=year,
        n_sectors=S,
        temporal=temporal,
        weather=weather,
        counts=counts,
        ev_hour=ev_hour,
        ev_sector=ev_sector,
        ev_F=F,
        ev_n=ev_n,
        split_hour=split_hour(year),
        timings=timings,
        val_hour=val_hour(year),
        ev_M=M,
        ev_F_shuffled=F_shuf,
        expected=world_expected(world, counts),
    )


@dataclass
class Normaliser:
    """Everything needed to turn raw features and counts into network inputs and back."""

    weather_mean: np.ndarray
    weather_std: np.ndarray
    F_mean: np.ndarray
    F_std: np.ndarray
    y_mean: float
    y_std: float
    M_mean: np.ndarray | None = None
    M_std: np.ndarray | None = None

    @classmethod
    def fit(cls, data: YearData) -> "Normaliser":
        """Statistics of the training months only (validation and test months never enter)."""
        tr = slice(0, data.val_hour)
        w = data.weather[tr].astype(np.float64)
        ly = np.log1p(data.counts[tr].astype(np.float64))
        sel = data.event_rows("train")
        Ftr = data.ev_F[sel].astype(np.float64) if len(sel) else np.zeros((1, data.ev_F.shape[1]))
        M = data.ev_M if data.ev_M is not None else np.zeros((len(data.ev_hour), 0), np.float32)
        Mtr = M[sel].astype(np.float64) if len(sel) else np.zeros((1, M.shape[1]))
        return cls(
            M_mean=Mtr.mean(axis=0),
            M_std=np.maximum(Mtr.std(axis=0), 1e-3),
            weather_mean=w.mean(axis=0),
            weather_std=np.maximum(w.std(axis=0), 1e-6),
            F_mean=Ftr.mean(axis=0),
            F_std=np.maximum(Ftr.std(axis=0), 1e-3),
            y_mean=float(ly.mean()),
            y_std=float(max(ly.std(), 1e-6)),
        )

    def to_json(self) -> dict:
        return {
            "M_mean": None if self.M_mean is None else self.M_mean.tolist(),
            "M_std": None if self.M_std is None else self.M_std.tolist(),
            "weather_mean": self.weather_mean.tolist(),
            "weather_std": self.weather_std.tolist(),
            "F_mean": self.F_mean.tolist(),
            "F_std": self.F_std.tolist(),
            "y_mean": self.y_mean,
            "y_std": self.y_std,
            "target": "(log1p(count) - y_mean) / y_std",
            "weather": "(x - weather_mean) / weather_std",
            "F": "(F - F_mean) / F_std, per column, training event samples",
            "M": "(M - M_mean) / M_std, per column, training event samples",
        }

    @classmethod
    def from_json(cls, d: dict) -> "Normaliser":
        return cls(
            M_mean=None if d.get("M_mean") is None else np.asarray(d["M_mean"]),
            M_std=None if d.get("M_std") is None else np.asarray(d["M_std"]),
            weather_mean=np.asarray(d["weather_mean"]),
            weather_std=np.asarray(d["weather_std"]),
            F_mean=np.asarray(d["F_mean"]),
            F_std=np.asarray(d["F_std"]),
            y_mean=float(d["y_mean"]),
            y_std=float(d["y_std"]),
        )

    def target(self, counts: np.ndarray) -> np.ndarray:
        return ((np.log1p(np.asarray(counts, np.float64)) - self.y_mean) / self.y_std).astype(np.float32)

    def counts(self, t: np.ndarray) -> np.ndarray:
        return np.clip(np.expm1(np.asarray(t, np.float64) * self.y_std + self.y_mean), 0.0, None)

    def base(self, temporal: np.ndarray, weather: np.ndarray, sector: np.ndarray, n_sectors: int) -> np.ndarray:
        """Base features for rows ``(temporal[i], weather[i], sector[i])``."""
        n = len(sector)
        onehot = np.zeros((n, n_sectors), dtype=np.float32)
        onehot[np.arange(n), sector] = 1.0
        w = (np.asarray(weather, np.float64) - self.weather_mean) / self.weather_std
        return np.hstack([np.asarray(temporal, np.float32), w.astype(np.float32), onehot])

    def event(self, F: np.ndarray) -> np.ndarray:
        return ((np.asarray(F, np.float64) - self.F_mean) / self.F_std).astype(np.float32)

    def metadata(self, M: np.ndarray) -> np.ndarray:
        return ((np.asarray(M, np.float64) - self.M_mean) / self.M_std).astype(np.float32)


def base_rows(data: YearData, norm: Normaliser, hours: np.ndarray, sectors: np.ndarray) -> np.ndarray:
    return norm.base(data.temporal[hours], data.weather[hours], sectors, data.n_sectors)


#: What the event-sector networks see besides the base features.
EVENT_INPUTS = ("text", "shuffled_text", "metadata")


def standard_training_set(data: YearData, norm: Normaliser, *, without_events: bool = False, part: str = "train") -> tuple[np.ndarray, np.ndarray]:
    """Every (hour, sector) of ``part``; only those with no active event if ``without_events``.

    The ablation's standard network sees them all.  The system's no-event
    network is only ever asked about sector-hours without an event, so it is
    fitted on exactly those: event surges would otherwise raise its estimate of
    a quiet evening in every sector that hosts events.
    """
    r, S = data.hours(part), data.n_sectors
    hours = np.repeat(np.arange(r.start, r.stop), S)
    sectors = np.tile(np.arange(S), len(r))
    if without_events:
        keep = ~data.has_event()[r.start : r.stop].ravel()
        hours, sectors = hours[keep], sectors[keep]
    X = base_rows(data, norm, hours, sectors)
    y = norm.target(data.counts[hours, sectors])
    return X, y


def event_inputs(data: YearData, norm: Normaliser, rows: np.ndarray, inputs: str = "text") -> np.ndarray:
    """Network inputs of event samples ``rows``: base features plus text, shuffled text or metadata."""
    h, s = data.ev_hour[rows], data.ev_sector[rows]
    base = base_rows(data, norm, h, s)
    if inputs == "text":
        extra = norm.event(data.ev_F[rows])
    elif inputs == "shuffled_text":
        extra = norm.event(data.ev_F_shuffled[rows])
    elif inputs == "metadata":
        extra = norm.metadata(data.ev_M[rows])
    else:
        raise ValueError(f"event inputs {inputs!r}: choose from {', '.join(EVENT_INPUTS)}")
    return np.hstack([base, extra])


def event_training_set(data: YearData, norm: Normaliser, *, part: str = "train", inputs: str = "text") -> tuple[np.ndarray, np.ndarray]:
    """The (hour, sector) samples of ``part`` with at least one active event."""
    rows = data.event_rows(part)
    X = event_inputs(data, norm, rows, inputs)
    y = norm.target(data.counts[data.ev_hour[rows], data.ev_sector[rows]])
    return X, y

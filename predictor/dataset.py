"""The year's demand data as arrays: base features, event features and targets.

Split (paper §5.1): train on the first 8 months (January–August), test on the
last 4 (September–December).

Targets are hourly request counts per sector.  The networks predict on a
normalised scale, ``t = (log1p(y) - μ) / σ`` with μ, σ from the training
months; predictions are mapped back with ``expm1(σ t + μ)`` and clipped at 0.
The log scale makes the MSE weigh relative errors, which is what the paper's
percent-error metric measures, and keeps the large event surges from
dominating the loss of the standard network.
"""

from __future__ import annotations

import datetime as dt
import time
from dataclasses import dataclass

import numpy as np

from predictor.features import (
    LAG_HOURS,
    LEAD_HOURS,
    EventFeaturizer,
    events_by_hour_sector,
    temporal_matrix,
    weather_matrix,
)

TRAIN_MONTHS = 8


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

    @property
    def n_hours(self) -> int:
        return int(self.temporal.shape[0])

    def has_event(self) -> np.ndarray:
        m = np.zeros((self.n_hours, self.n_sectors), dtype=bool)
        m[self.ev_hour, self.ev_sector] = True
        return m


def split_hour(year: int, train_months: int = TRAIN_MONTHS) -> int:
    return (dt.date(year, train_months + 1, 1) - dt.date(year, 1, 1)).days * 24


def world_counts(world) -> np.ndarray:
    return np.asarray(world.hourly_counts(), dtype=np.float64)


def build_year_data(world, featurizer: EventFeaturizer, *, lead: int = LEAD_HOURS, lag: int = LAG_HOURS, verbose: bool = False) -> YearData:
    t0 = time.perf_counter()
    year = int(world.year)
    S = int(world.city.n_sectors)
    temporal = temporal_matrix(year)
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
    F = np.zeros((E, featurizer.size), dtype=np.float32)
    ev_n = np.zeros(E, dtype=np.int32)
    for i, k in enumerate(keys):
        F[i] = featurizer.sector_feature(groups[k])
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
        print(
            f"data: {H} hours x {S} sectors, {len(events)} events -> {E} event sector-hours; "
            f"features built in {timings['total_s']:.1f}s",
            flush=True,
        )
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

    @classmethod
    def fit(cls, data: YearData) -> "Normaliser":
        tr = slice(0, data.split_hour)
        w = data.weather[tr].astype(np.float64)
        ly = np.log1p(data.counts[tr].astype(np.float64))
        sel = data.ev_hour < data.split_hour
        Ftr = data.ev_F[sel].astype(np.float64) if sel.any() else np.zeros((1, data.ev_F.shape[1]))
        return cls(
            weather_mean=w.mean(axis=0),
            weather_std=np.maximum(w.std(axis=0), 1e-6),
            F_mean=Ftr.mean(axis=0),
            F_std=np.maximum(Ftr.std(axis=0), 1e-3),
            y_mean=float(ly.mean()),
            y_std=float(max(ly.std(), 1e-6)),
        )

    def to_json(self) -> dict:
        return {
            "weather_mean": self.weather_mean.tolist(),
            "weather_std": self.weather_std.tolist(),
            "F_mean": self.F_mean.tolist(),
            "F_std": self.F_std.tolist(),
            "y_mean": self.y_mean,
            "y_std": self.y_std,
            "target": "(log1p(count) - y_mean) / y_std",
            "weather": "(x - weather_mean) / weather_std",
            "F": "(F - F_mean) / F_std, per column, training event samples",
        }

    @classmethod
    def from_json(cls, d: dict) -> "Normaliser":
        return cls(
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


def base_rows(data: YearData, norm: Normaliser, hours: np.ndarray, sectors: np.ndarray) -> np.ndarray:
    return norm.base(data.temporal[hours], data.weather[hours], sectors, data.n_sectors)


def standard_training_set(data: YearData, norm: Normaliser, *, without_events: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Every (hour, sector) of the training months; only those with no active event if ``without_events``.

    The ablation's standard network sees them all.  The system's no-event
    network is only ever asked about sector-hours without an event, so it is
    fitted on exactly those: event surges would otherwise raise its estimate of
    a quiet evening in every sector that hosts events.
    """
    H, S = data.split_hour, data.n_sectors
    hours = np.repeat(np.arange(H), S)
    sectors = np.tile(np.arange(S), H)
    if without_events:
        keep = ~data.has_event()[:H].ravel()
        hours, sectors = hours[keep], sectors[keep]
    X = base_rows(data, norm, hours, sectors)
    y = norm.target(data.counts[hours, sectors])
    return X, y


def event_training_set(data: YearData, norm: Normaliser) -> tuple[np.ndarray, np.ndarray]:
    """The (hour, sector) samples of the training months with at least one active event."""
    sel = data.ev_hour < data.split_hour
    h, s = data.ev_hour[sel], data.ev_sector[sel]
    X = np.hstack([base_rows(data, norm, h, s), norm.event(data.ev_F[sel])])
    y = norm.target(data.counts[h, s])
    return X, y

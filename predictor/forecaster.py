"""Serve a trained demand model as the forecast the rollout agents consume.

``ModelForecaster.forecast(world, when)`` gives, for the hour beginning
``when``:

* ``eta`` ``(S,)``: per-minute request rate ŷ_s / 60 (ŷ from the event network
  where the sector has an active event, else the no-event network);
* ``rho``, ``delta`` ``(n,)``: pickup / drop-off intersection probabilities,
  each summing to 1 within every sector (occupancy-based assignment);
* ``beta`` ``(S, S)``: drop-off sector given pickup sector (historical, the
  training months of the data the model was trained with).

Events: a model trained with ``--events FILE`` forecasts from the events of
that file (found again through ``model.json``, its SHA-256 checked), not from
the world's own synthetic events; a model trained on the world's events uses
the world's.

It returns the shared world model's torch-free :class:`city.forecast.Forecast`.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np

from city.errors import ConfigError
from city.forecast import Forecast
from predictor.assign import estimate_beta, node_distribution
from predictor.features import active_events
from predictor.model import DemandModel


class ModelForecaster:
    """Forecasts from a trained :class:`DemandModel` for any world on the same sectors."""

    def __init__(self, model: DemandModel | str | Path, cache_dir: str | None = None) -> None:
        self.model = model if isinstance(model, DemandModel) else DemandModel.load(model)
        self.cache_dir = cache_dir
        self._featurizer = None
        self._beta: dict[int, np.ndarray] = {}
        self._events: dict[int, list | None] = {}

    def events_for(self, world) -> list:
        """The events the model was trained with: the recorded ``--events`` file's, else the world's."""
        key = id(world.city)
        if key not in self._events:
            from predictor.inputs import recorded_events

            directory = self.model.directory if self.model.directory is not None else Path(".")
            self._events[key] = recorded_events(self.model.meta, directory, world.city)
        ev = self._events[key]
        return list(world.events) if ev is None else ev

    @property
    def featurizer(self):
        if self._featurizer is None:
            self._featurizer = self.model.featurizer(self.cache_dir)
        return self._featurizer

    def beta_for(self, world) -> np.ndarray:
        S = int(world.city.n_sectors)
        b = self.model.beta
        if b is not None and b.shape == (S, S):
            return b
        key = id(world)
        if key not in self._beta:
            self._beta[key] = estimate_beta(world, days=7)[0]
        return self._beta[key]

    def predict_counts(self, world, when: dt.datetime) -> tuple[np.ndarray, np.ndarray]:
        """ŷ ``(S,)`` hourly counts and the has-event mask for the hour beginning ``when``."""
        S = int(world.city.n_sectors)
        if S != self.model.n_sectors:
            raise ConfigError(f"model was trained on {self.model.n_sectors} sectors, the world has {S}")
        when = when.replace(minute=0, second=0, microsecond=0)
        by_sector: dict[int, list] = {}
        lead, lag = self.model.window
        for ev in active_events(_Listing(self.events_for(world)), when, lead, lag):
            if 0 <= int(ev.sector) < S:
                by_sector.setdefault(int(ev.sector), []).append(ev)
        has = np.zeros(S, dtype=bool)
        F = np.zeros((S, 0), dtype=np.float32)
        if by_sector:
            fz = self.featurizer
            fz.prepare([ev for evs in by_sector.values() for ev in evs])
            F = np.zeros((S, fz.size), dtype=np.float32)
            for s, evs in by_sector.items():
                F[s] = fz.sector_feature(evs)
                has[s] = True
        y = self.model.predict_hour(when, world.weather, F, has, world.holidays)
        return y, has

    def forecast(self, world, when: dt.datetime):
        y, has = self.predict_counts(world, when)
        p = node_distribution(world.city, world.locale_counts, when, world.schedules)
        return Forecast(
            eta=(y / 60.0).astype(np.float64),
            rho=p,
            delta=p.copy(),
            beta=self.beta_for(world),
        )


class _Listing:
    """Just the ``events`` of a world, for :func:`predictor.features.active_events`."""

    def __init__(self, events: list) -> None:
        self.events = events


def load_forecaster(model_dir: str | Path, cache_dir: str | None = None) -> ModelForecaster:
    return ModelForecaster(Path(model_dir), cache_dir=cache_dir)

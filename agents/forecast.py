"""Demand forecasts for the rollout: per-minute rates and where requests start and end.

A :class:`Forecast` is what a rollout agent needs to sample future requests
(paper §3, §4.1): per sector the per-minute request rate η, the pickup and
drop-off intersection distributions ρ and δ (each summing to one within every
sector) and the drop-off-sector distribution β (row = pickup sector).

Providers turn a demand world and the start of an hour into a forecast:

``previous-hour``
    Garces et al. (2023): η is the previous hour's realised count / 60; ρ, δ
    and β come from the world's demand assignment for the forecast hour.
``true-rate``
    The world's own expected rate λ / 60 for the hour: a perfect forecast,
    an upper bound for ablations.
``model``
    The trained event-informed predictor (``predictor.forecast``), loaded
    lazily from a model directory.

This module must stay importable without torch: only the ``model`` provider
imports the predictor, and only when it is constructed.
"""

from __future__ import annotations

import datetime as dt
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from city.errors import ConfigError


@dataclass(frozen=True)
class Forecast:
    """Demand of one hour as the rollout consumes it.

    Attributes
    ----------
    eta : ndarray of float64, shape (S,)
        Expected requests per minute entering each sector.
    rho : ndarray of float64, shape (n,)
        Pickup-intersection probabilities, summing to one within each sector.
    delta : ndarray of float64, shape (n,)
        Drop-off-intersection probabilities, summing to one within each sector.
    beta : ndarray of float64, shape (S, S)
        Drop-off-sector probabilities given the pickup sector (rows sum to one).
    """

    eta: np.ndarray
    rho: np.ndarray
    delta: np.ndarray
    beta: np.ndarray

    def __post_init__(self) -> None:
        for name in ("eta", "rho", "delta", "beta"):
            arr = np.ascontiguousarray(getattr(self, name), dtype=np.float64)
            if not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ConfigError(f"forecast: {name} must be finite and non-negative")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        S = self.eta.shape[0]
        if self.eta.ndim != 1 or self.beta.shape != (S, S):
            raise ConfigError(f"forecast: eta has shape {self.eta.shape} and beta {self.beta.shape}; expected (S,) and (S, S)")
        if self.rho.ndim != 1 or self.rho.shape != self.delta.shape:
            raise ConfigError(f"forecast: rho {self.rho.shape} and delta {self.delta.shape} must both be (n,)")

    @property
    def n_sectors(self) -> int:
        return int(self.eta.shape[0])


class ForecastProvider(ABC):
    """Makes the forecast of the hour beginning at ``when`` in a demand world."""

    name: ClassVar[str] = ""

    @abstractmethod
    def forecast(self, world: Any, when: dt.datetime) -> Forecast:
        """Forecast of the hour that starts at ``when`` (minutes are ignored)."""


PROVIDERS: dict[str, type[ForecastProvider]] = {}


def register_provider(cls: type[ForecastProvider]) -> type[ForecastProvider]:
    """Class decorator adding a provider to the registry under ``cls.name``."""
    PROVIDERS[cls.name] = cls
    return cls


def make_provider(name: str, model: str | Path | None = None) -> ForecastProvider:
    """Instantiate a forecast provider by name; ``model`` is the predictor directory for ``model``.

    Raises
    ------
    ConfigError
        An unknown name, or ``model`` without a usable trained predictor.
    """
    if name not in PROVIDERS:
        raise ConfigError(f"unknown forecast {name!r}; choose from {', '.join(sorted(PROVIDERS))}")
    if name == ModelForecast.name:
        return ModelForecast(model)
    return PROVIDERS[name]()


def _hour_start(when: dt.datetime) -> dt.datetime:
    return when.replace(minute=0, second=0, microsecond=0)


def _assignment(world: Any, when: dt.datetime, eta: np.ndarray) -> Forecast:
    return Forecast(eta=eta, rho=world.pickup_dist(when), delta=world.dropoff_dist(when), beta=world.od_matrix(when))


@register_provider
class PreviousHour(ForecastProvider):
    """η = realised counts of the hour before / 60 (Garces et al. 2023); ρ, δ, β from the world."""

    name = "previous-hour"

    def forecast(self, world: Any, when: dt.datetime) -> Forecast:
        when = _hour_start(when)
        h = world.hour_index(when)
        if h == 0:
            raise ConfigError(f"forecast 'previous-hour': {when:%Y-%m-%d %H:%M} is the first hour of the world's year")
        counts = np.asarray(world.hourly_counts()[h - 1], dtype=np.float64)
        return _assignment(world, when, counts / 60.0)


@register_provider
class TrueRate(ForecastProvider):
    """η = the world's expected requests of the hour / 60: a perfect forecast."""

    name = "true-rate"

    def forecast(self, world: Any, when: dt.datetime) -> Forecast:
        when = _hour_start(when)
        rate = np.asarray(world.expected_rate()[world.hour_index(when)], dtype=np.float64)
        return _assignment(world, when, rate / 60.0)


@register_provider
class ModelForecast(ForecastProvider):
    """The trained event-informed predictor, ``predictor.forecast.load_forecaster(model_dir)``.

    Parameters
    ----------
    model : str or Path or None
        Directory of a trained predictor (``surge predictor train … --out DIR``).

    Raises
    ------
    ConfigError
        No directory given, the directory is missing, or the predictor package
        is not installed.
    """

    name = "model"

    def __init__(self, model: str | Path | None = None) -> None:
        hint = "forecast 'model' needs a trained predictor: run `surge predictor train …` and pass --model DIR"
        if model is None:
            raise ConfigError(hint)
        if not Path(model).is_dir():
            raise ConfigError(f"{hint} ({model} is not a directory)")
        try:
            from predictor.forecast import load_forecaster
        except ImportError as exc:
            raise ConfigError(f"{hint} (cannot import predictor.forecast: {exc})") from None
        self._forecaster = load_forecaster(model)

    def forecast(self, world: Any, when: dt.datetime) -> Forecast:
        return self._forecaster.forecast(world, when)

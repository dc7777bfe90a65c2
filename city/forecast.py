"""Demand forecasts as the shared world model holds them: the whole map, or one sector at a time.

A :class:`Forecast` is what a rollout agent needs to sample future requests
(paper §3, §4.1): per sector the per-minute request rate η, the pickup and
drop-off intersection distributions ρ and δ (each summing to one within every
sector) and the drop-off-sector distribution β (row = pickup sector).  It
lives here, in ``city/``, because the predictor makes it and the agents
consume it, and neither may import the other.

A :class:`SectorSlice` is one sector's part of a forecast (η, ρ and δ over the
sector's intersections, β's row), what a taxi subscribes to for the sectors it
samples; :func:`assemble` puts slices and the map-wide drop-off distribution
back together.

The providers here need only a demand world:

``previous-hour``
    Garces et al. (2023): η is the previous hour's realised count / 60; ρ, δ
    and β come from the world's demand assignment for the forecast hour.
``true-rate``
    The world's own expected rate λ / 60 for the hour: a perfect forecast,
    an upper bound for ablations.

The trained predictor (``model``) is registered by :mod:`agents.forecast_providers`.
"""

from __future__ import annotations

import datetime as dt
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from city.errors import ConfigError
from city.graph import City


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


@dataclass(frozen=True)
class SectorSlice:
    """One sector's part of a forecast.

    Attributes
    ----------
    sector : int
    eta : float
        Expected requests per minute entering the sector.
    nodes : ndarray of int32
        The sector's intersections, ascending: the layout of ``rho`` and ``delta``.
    rho, delta : ndarray of float64, shaped as ``nodes``
        Pickup and drop-off probabilities of those intersections.
    beta : ndarray of float64, shape (S,)
        Drop-off-sector probabilities of a request picked up in this sector.
    """

    sector: int
    eta: float
    nodes: np.ndarray
    rho: np.ndarray
    delta: np.ndarray
    beta: np.ndarray


def sector_nodes(city: City, sector: int) -> np.ndarray:
    """The intersections of ``sector``, ascending (int32): the layout of a slice's ρ and δ."""
    return np.flatnonzero(np.asarray(city.node_sector) == sector).astype(np.int32)


def slice_sector(forecast: Forecast, city: City, sector: int) -> SectorSlice:
    """Sector ``sector``'s part of ``forecast``."""
    nodes = sector_nodes(city, sector)
    return SectorSlice(sector=int(sector), eta=float(forecast.eta[sector]), nodes=nodes, rho=forecast.rho[nodes].copy(),
                       delta=forecast.delta[nodes].copy(), beta=forecast.beta[sector].copy())


def assemble(city: City, slices: Mapping[int, SectorSlice], delta: np.ndarray) -> Forecast:
    """A whole-map forecast exact on the sectors of ``slices`` and on the map-wide drop-offs ``delta``.

    The other sectors get no demand (η = 0, ρ = 0, an empty β row).  A
    rollout that samples arrivals only in the given sectors, and drop-offs
    anywhere from ``delta``, plans with it exactly as with the whole forecast
    (see :func:`agents.sector_forecasts.needed_sectors`).
    """
    S, n = city.n_sectors, city.n_nodes
    if np.shape(delta) != (n,):
        raise ConfigError(f"forecast: the drop-off distribution has shape {list(np.shape(delta))}, the city has {n} intersections")
    eta, rho, beta = np.zeros(S), np.zeros(n), np.zeros((S, S))
    for s, piece in slices.items():
        eta[s] = piece.eta
        rho[piece.nodes] = piece.rho
        beta[s] = piece.beta
    return Forecast(eta=eta, rho=rho, delta=np.asarray(delta, dtype=np.float64), beta=beta)


class ForecastProvider(ABC):
    """Makes the forecast of the hour beginning at ``when`` in a demand world."""

    name: ClassVar[str] = ""

    @abstractmethod
    def forecast(self, world: Any, when: dt.datetime) -> Forecast:
        """Forecast of the hour that starts at ``when`` (minutes are ignored)."""


#: The providers that need nothing but a demand world, by name.
PROVIDERS: dict[str, type[ForecastProvider]] = {}


def register_provider(cls: type[ForecastProvider]) -> type[ForecastProvider]:
    """Class decorator adding a provider to :data:`PROVIDERS` under ``cls.name``."""
    PROVIDERS[cls.name] = cls
    return cls


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

"""An hour's forecast on the bus, sector by sector: what the predictor service, or the coordinator without one, publishes.

Each sector's part goes to ``forecast/<sector>`` (:class:`~bus.wire.SectorForecast`),
so a taxi receives only the sectors it samples; the map-wide drop-off
distribution goes once to ``dropoffs`` (:class:`~bus.wire.Dropoffs`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from bus.keys import Keys
from bus.session import publisher
from bus.wire import Dropoffs, SectorForecast
from city.forecast import Forecast, slice_sector
from city.graph import City


def sector_message(forecast: Forecast, city: City, hour: int, sector: int) -> SectorForecast:
    """Sector ``sector``'s part of the forecast of hour ``hour``, as sent."""
    piece = slice_sector(forecast, city, sector)
    return SectorForecast(hour=hour, sector=piece.sector, eta=piece.eta, nodes=piece.nodes, rho=piece.rho, delta=piece.delta,
                          beta=piece.beta)


class ForecastPublisher:
    """One publisher per sector and one for the drop-offs, declared once for the run.

    ``wrap`` wraps each publisher (the coordinator counts its traffic with it).
    """

    def __init__(self, session: Any, keys: Keys, city: City, wrap: Callable[[Any], Any] = lambda pub: pub) -> None:
        self.city = city
        self._sectors = [wrap(publisher(session, keys.forecast(s))) for s in range(city.n_sectors)]
        self._dropoffs = wrap(publisher(session, keys.dropoffs))

    def put(self, forecast: Forecast, hour: int) -> None:
        """Publish the forecast of the episode's hour ``hour``: every sector's part, then the drop-offs."""
        for s, pub in enumerate(self._sectors):
            pub.put(sector_message(forecast, self.city, hour, s).encode())
        self._dropoffs.put(Dropoffs(hour=hour, delta=forecast.delta).encode())

"""The forecast providers a rollout policy can use: the world's own (:mod:`city.forecast`) and the trained model.

``model``
    The trained event-informed predictor (``predictor.forecaster``), loaded
    lazily from a model directory.

This module must stay importable without torch: only the ``model`` provider
imports the predictor, and only when it is constructed.  The forecast type
itself lives in :mod:`city.forecast`, so the predictor never imports agents.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path
from typing import Any

from city import forecast as world_forecasts
from city.errors import ConfigError
from city.forecast import Forecast, ForecastProvider


class ModelForecast(ForecastProvider):
    """The trained event-informed predictor, ``predictor.forecaster.load_forecaster(model_dir)``.

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
            from predictor.forecaster import load_forecaster
        except ImportError as exc:
            raise ConfigError(f"{hint} (cannot import predictor.forecaster: {exc})") from None
        self._forecaster = load_forecaster(model)

    def forecast(self, world: Any, when: dt.datetime) -> Forecast:
        return self._forecaster.forecast(world, when)


#: Every provider a policy can name.
PROVIDERS: dict[str, type[ForecastProvider]] = {**world_forecasts.PROVIDERS, ModelForecast.name: ModelForecast}


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

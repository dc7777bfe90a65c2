"""The predictor as a service on the bus: it answers a run's forecast queries.

With it, the coordinator asks for each hour's forecast over zenoh instead of
computing it, so the trained model (and torch) lives in this one process.
The service publishes the hour's forecast sector by sector for the taxis
(:mod:`bus.forecast_messages`), then answers the coordinator with the whole of it,
which the coordinator keeps for snapshots.
Any forecast provider can be served (``model`` is the point; ``true-rate`` and
``previous-hour`` need no training and make the service easy to try).  A bad
request gets an error reply naming the field, and the service keeps serving.
"""

from __future__ import annotations

import datetime as dt
import logging
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bus.forecast_messages import ForecastPublisher
from bus.keys import Keys
from bus.session import Inbox, SessionArgs, open_session
from bus.wire import ENCODING, ForecastMsg, ForecastRequest, decode
from city.errors import ConfigError, SurgeError
from city.forecast import Forecast
from city.logs import inherit

_logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class ServeConfig:
    """Which run to serve, from which demand world, with which provider."""

    run: str
    scenario: str = "synthetic"
    data_dir: str | None = None
    world_seed: int = 0
    forecast: str = "model"
    model: str | None = None


def log(message: str, level: int = logging.INFO) -> None:
    """A line of the predictor service: ``surge predictor: …``."""
    _logger.log(level, "%s", message, extra={"who": "predictor"})


class ForecastService:
    """Answers :class:`~bus.wire.ForecastRequest` queries on ``surge/<run>/predictor``."""

    def __init__(self, config: ServeConfig) -> None:
        from city.scenario import load_scenario

        self.cfg = config
        self.keys = Keys(config.run)
        self.provider = _provider(config.forecast, config.model)
        self.world = load_scenario(config.scenario, config.data_dir, seed=config.world_seed).world
        if config.forecast == "model" and config.model is not None:
            self.world = _world_for_model(config, self.world)
        self.answered = 0

    def answer(self, payload: bytes) -> tuple[int, Forecast]:
        """The episode hour and forecast one encoded request asks for; :class:`SurgeError` for a bad one."""
        req = decode(payload, ForecastRequest, self.keys.predictor)
        return req.hour, self.provider.forecast(self.world, dt.datetime.fromisoformat(req.when))  # type: ignore[attr-defined]

    def run(self, bus: SessionArgs) -> None:
        """Serve until interrupted."""
        with open_session(bus) as session:
            inbox = Inbox()
            queryable = inbox.serve(session, self.keys.predictor, "query")
            sectors = ForecastPublisher(session, self.keys, self.world.city)
            log(f"serving {self.cfg.forecast} forecasts for run {self.cfg.run!r} on {self.keys.predictor}")
            try:
                while True:
                    item = inbox.get(timeout=1.0)
                    if item is None:
                        continue
                    query = item[2]
                    payload = query.payload.to_bytes() if query.payload is not None else b""
                    try:
                        hour, fc = self.answer(payload)
                        sectors.put(fc, hour)
                        whole = ForecastMsg(hour=hour, eta=fc.eta, rho=fc.rho, delta=fc.delta, beta=fc.beta)
                        query.reply(self.keys.predictor, whole.encode(), encoding=ENCODING)
                        self.answered += 1
                    except Exception as exc:  # a bad request, or one the provider cannot answer: refuse it, keep serving
                        why = str(exc) if isinstance(exc, SurgeError) else f"{type(exc).__name__}: {exc}"
                        log(f"refused: {why}")
                        query.reply_err(why.encode())
                    finally:
                        query.drop()  # the querier's get() ends now, not when this object is collected
            finally:
                queryable.undeclare()


def _provider(name: str, model: str | None) -> Any:
    """The provider to serve: the trained model, or one of :mod:`city.forecast`'s (the agents' registry is not imported here)."""
    from city.forecast import PROVIDERS

    if name == "model":
        if model is None or not Path(model).is_dir():
            raise ConfigError(f"forecast 'model' needs a trained predictor: run `surge predictor train …` and pass --model DIR"
                              f"{'' if model is None else f' ({model} is not a directory)'}")
        from predictor.forecaster import load_forecaster

        return load_forecaster(model)
    if name not in PROVIDERS:
        raise ConfigError(f"unknown forecast {name!r}; choose from {', '.join(sorted([*PROVIDERS, 'model']))}")
    return PROVIDERS[name]()


def _world_for_model(config: ServeConfig, world):
    """The served world with the model's recorded events and trips in place of the scenario's own.

    The forecasts come from the model's events anyway (:class:`predictor.forecaster.ModelForecaster`);
    swapping them in here also refuses, in one line, a recorded file that is gone or changed, before
    the first query, and a model trained on another scenario.
    """
    import json

    from predictor.inputs import RealInputsWorld, read_event_file, recorded_paths, trained_timezone

    meta = json.loads((Path(config.model) / "model.json").read_text())
    trained = (meta.get("scenario") or {}).get("name")
    if trained and trained != config.scenario:
        raise ConfigError(f"the model in {config.model} was trained on scenario {trained!r}, not {config.scenario!r}")
    paths = recorded_paths({"inputs": {k: v for k, v in (meta.get("inputs") or {}).items() if k != "trips"}}, config.model)
    if paths["events"] is None:
        return world
    return RealInputsWorld(world, read_event_file(paths["events"], world.city, paths["reviews"], trained_timezone(meta)))


def serve_main(config: ServeConfig, bus: SessionArgs) -> None:
    """Entry point of a spawned predictor process: serve, and report a failure to start as one line."""
    inherit()
    try:
        ForecastService(config).run(bus)
    except SurgeError as exc:
        log(str(exc), logging.ERROR)
        sys.exit(2)
    except KeyboardInterrupt:
        pass

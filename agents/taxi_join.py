"""How a taxi joins a run: it asks the coordinator for the run's spec and accepts it only for this host's own city.

The mixin :class:`Joining` of :class:`agents.taxi.TaxiAgent`; the agent's event loop is in :mod:`agents.taxi`.
"""

from __future__ import annotations

import dataclasses
import logging
import time

from agents.base import policy_class
from agents.rollout import RolloutConfig
from agents.sector_forecasts import AgentForecasts
from bus.checks import Bounds, check_spec
from bus.wire import RunSpec, WireError, decode
from city.errors import ConfigError
from city.fingerprint import city_sha256, code_version

_logger = logging.getLogger("agents.taxi")


def log(index: int, message: str, level: int = logging.INFO) -> None:
    """A line of agent ``index``: ``surge agent 3: …`` (:class:`city.logs.LineFormatter`)."""
    _logger.log(level, "%s", message, extra={"who": f"agent {index}"})


class OtherCity(ConfigError):
    """The coordinator's city is not this host's: the agent refuses to join rather than plan on another map."""


class Joining:
    """Joining a run, for :class:`agents.taxi.TaxiAgent`: the spec, checked, and the city and settings it names."""

    def _fetch_spec(self, session) -> RunSpec:
        """The first acceptable answer on ``spec``; the city is built from it.  A bad answer is dropped and the agent asks again."""
        deadline = time.monotonic() + self.cfg.join_timeout_s
        why = "no answer"
        while time.monotonic() < deadline:
            for reply in session.get(self.keys.spec, timeout=2.0):
                if reply.ok is None:
                    continue
                try:
                    return self._accept_spec(reply.ok.payload.to_bytes())
                except OtherCity:
                    raise
                except Exception as exc:  # a spec this agent cannot run: drop it, ask again
                    why = str(exc)
                    self.rejected.exception("spec", self.keys.spec, exc)
            time.sleep(0.2)
        raise ConfigError(f"agent {self.me}: no acceptable run spec on {self.keys.spec} within {self.cfg.join_timeout_s:.0f} s "
                          f"(last: {why})")

    def _accept_spec(self, payload: bytes) -> RunSpec:
        settings = [f.name for f in dataclasses.fields(RolloutConfig)]
        spec = check_spec(decode(payload, RunSpec, self.keys.spec), self.keys.spec, settings)  # type: ignore[arg-type]
        if spec.run != self.cfg.run:
            raise WireError(f"{self.keys.spec}: the spec of run {spec.run!r}, this agent joins {self.cfg.run!r}")
        if spec.taxis <= self.me:
            raise WireError(f"{self.keys.spec}: run {spec.run!r} has only {spec.taxis} taxis; this is agent {self.me}")
        rollout = RolloutConfig(**spec.rollout)
        where = (spec.scenario, self.cfg.data_dir or spec.data_dir)
        if where not in self._cities:  # build each named city once, even if it fails
            from city.scenario import load_city

            try:
                self._cities[where] = load_city(*where, mmap=True)  # the matrices shared with every agent on this host
            except Exception as exc:
                self._cities[where] = exc
        city = self._cities[where]
        if isinstance(city, Exception):
            raise city
        if city.summary() != spec.city:
            raise WireError(f"{self.keys.spec}: this host's {spec.scenario} city {city.summary()} is not the coordinator's {spec.city}")
        mine = city_sha256(city)
        if mine != spec.city_sha256:
            raise OtherCity(f"agent {self.me} does not join run {spec.run!r}: this host's {spec.scenario} city has content hash "
                            f"{mine[:16]}…, the coordinator's {spec.city_sha256[:16]}… (same sizes, other streets, sectors "
                            f"or pickup intersections; rebuild the city from the same data)")
        if spec.code != code_version():
            log(self.me, f"this host runs {code_version()}, the coordinator {spec.code}; decisions may differ from its reference", logging.WARNING)
        self.city, self.rollout = city, rollout
        self.central = policy_class(spec.policy).central
        bounds = Bounds(taxis=spec.taxis, nodes=city.n_nodes, sectors=city.n_sectors, minutes=spec.minutes)
        self.forecasts = AgentForecasts(city, rollout, bounds, self.rejected)
        return spec

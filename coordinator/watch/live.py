"""The live feed: a read-only ``observer`` session on the run's bus, feeding a :class:`~coordinator.watch.view.FleetView`.

It subscribes key by key (:data:`bus.keys.OBSERVED`; on a secured bus a
subscription to ``surge/<run>/**`` gets nothing), asks ``spec`` for the run,
``forecast/<s>`` for the current hour, and ``snapshot`` when it joins late
or misses a state.  It publishes nothing.  The session lives in its own
thread; callbacks only enqueue (:class:`bus.session.Inbox`).
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import threading
import time
from dataclasses import dataclass

import numpy as np

from bus.keys import OBSERVED, Keys
from bus.session import Inbox, SessionArgs, open_session
from bus.wire import (
    Control,
    ForecastMsg,
    RunSpec,
    SectorForecast,
    Snapshot,
    State,
    Stop,
    Turn,
    decode,
)
from city.errors import ConfigError, SurgeError
from coordinator.watch.citymap import city_map
from coordinator.watch.view import FleetView

_logger = logging.getLogger(__name__)

#: Seconds between two frames the feed renders, at most.
FRAME_S = 0.1


@dataclass(frozen=True)
class LiveConfig:
    """Which run to follow, and what the bus does not say: the episode's date, hour and demand world (for the events layer)."""

    run: str
    date: str = "2022-11-17"
    hour: int = 19
    world_seed: int = 0
    join_timeout_s: float = 120.0


class LiveFeed:
    """Follows a run on the bus in a thread; :meth:`latest` is the newest frame."""

    def __init__(self, cfg: LiveConfig, bus: SessionArgs) -> None:
        self.cfg, self.bus, self.keys = cfg, bus.as_identity("observer"), Keys(cfg.run)
        self.map: dict | None = None
        self.summary: dict = {"run": cfg.run}
        self.ready = threading.Event()
        self.error: str | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._frame = (0, json.dumps({"minute": 0, "waiting_for": "the run's spec"}))
        self._thread = threading.Thread(target=self._main, name="surge-watch-bus", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(10)

    def latest(self) -> tuple[int, str]:
        with self._lock:
            return self._frame

    def _publish(self, view: FleetView) -> None:
        text = json.dumps(view.frame())
        with self._lock:
            self._frame = (self._frame[0] + 1, text)

    def _ask(self, session, key: str, timeout: float = 5.0) -> list[bytes]:
        return [r.ok.payload.to_bytes() for r in session.get(key, timeout=timeout) if r.ok is not None]

    def _main(self) -> None:
        try:
            with open_session(self.bus) as session:
                self._follow(session)
        except SurgeError as exc:
            self.error = str(exc)
            if self.ready.is_set():  # mid-run: the page keeps the last frame; the terminal says why it stopped
                _logger.error("%s", exc, extra={"who": "watch"})
        finally:
            if not self.ready.is_set():  # the page never comes: say why rather than leave the command waiting
                self.error = self.error or "the bus thread stopped before the run's spec came (see the traceback above)"
                self.ready.set()

    def _spec(self, session) -> RunSpec:
        deadline = time.monotonic() + self.cfg.join_timeout_s
        while not self._stop.is_set():
            for payload in self._ask(session, self.keys.spec):
                return decode(payload, RunSpec, self.keys.spec)  # type: ignore[return-value]
            if time.monotonic() > deadline:
                raise ConfigError(f"no answer on {self.keys.spec} within {self.cfg.join_timeout_s:.0f} s: "
                                  f"is run {self.cfg.run!r} running, and does this certificate hold the observer role?")
            time.sleep(0.5)
        raise ConfigError("stopped before the run's spec came")

    def _follow(self, session) -> None:
        from city.scenario import load_scenario

        inbox = Inbox()
        subs = [inbox.subscribe(session, f"{self.keys.root}/{k}", k.split("/")[0]) for k in OBSERVED]
        spec = self._spec(session)
        scen = load_scenario(spec.scenario, spec.data_dir, seed=self.cfg.world_seed)
        if scen.city.summary() != spec.city:
            raise ConfigError(f"run {spec.run!r}: this host's {spec.scenario} city is {scen.city.summary()}, the run's {spec.city}")
        view = FleetView(scen.city, spec.taxis, spec.minutes)
        self.map = city_map(scen.city, scen.world, dt.date.fromisoformat(self.cfg.date), self.cfg.hour, spec.minutes)
        self.summary = {"run": spec.run, "policy": spec.policy, "scenario": spec.scenario, "date": self.cfg.date,
                        "hour": self.cfg.hour, "taxis": spec.taxis, "minutes": spec.minutes}
        for payload in self._ask(session, self.keys.all_forecasts):
            self._sector(view, payload)
        self._publish(view)
        self.ready.set()
        last = time.monotonic()
        while not self._stop.is_set() and not view.done:
            item = inbox.get(FRAME_S)
            changed = item is not None
            if item is not None:
                self._apply(session, view, *item)
            if changed and time.monotonic() - last >= FRAME_S:
                self._publish(view)
                last = time.monotonic()
        self._publish(view)
        del subs

    def _sector(self, view: FleetView, payload: bytes) -> None:
        msg = decode(payload, SectorForecast)
        view.forecast(msg.hour, msg.sector, float(msg.eta))  # type: ignore[attr-defined]

    def _apply(self, session, view: FleetView, tag: str, key: str, payload: bytes) -> None:
        try:
            if tag == "state":
                s: State = decode(payload, State, key)  # type: ignore[assignment]
                if not self._state(view, s):
                    self._snapshot(session, view)
            elif tag == "turn":
                turn: Turn = decode(payload, Turn, key)  # type: ignore[assignment]
                view.turn(turn.t, turn.agent, view.wave_after(turn.t, turn.deps.tolist()))
            elif tag == "committed":
                c: Control = decode(payload, Control, key)  # type: ignore[assignment]
                view.commit(c.t, c.agent, c.control, c.by)
            elif tag == "forecast":
                self._sector(view, payload)
            elif tag == "stop":
                stop: Stop = decode(payload, Stop, key)  # type: ignore[assignment]
                view.stop(stop.t, stop.reason)
        except SurgeError as exc:  # a message that fails its checks is dropped, as every surge process drops it
            _logger.warning("dropped a message on %s: %s", key, exc, extra={"who": "watch"})

    @staticmethod
    def _state(view: FleetView, s: State) -> bool:
        return view.state(s.t, s.full, s.pos, s.tau, (s.new_index, s.new_pickup, s.new_entry), s.picked, s.outstanding)

    def _snapshot(self, session, view: FleetView) -> None:
        for payload in self._ask(session, self.keys.snapshot):
            snap: Snapshot = decode(payload, Snapshot, self.keys.snapshot)  # type: ignore[assignment]
            self._state(view, decode(snap.state, State, self.keys.snapshot))  # type: ignore[arg-type]
            if snap.forecast:
                fc: ForecastMsg = decode(snap.forecast, ForecastMsg, self.keys.snapshot)  # type: ignore[assignment]
                for sector, eta in enumerate(np.asarray(fc.eta).tolist()):
                    view.forecast(fc.hour, sector, eta)
            return

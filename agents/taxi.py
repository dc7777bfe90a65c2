"""One taxi as its own process on the bus: it follows the state, waits for its turn and plans its own control.

The agent fetches the run's :class:`~bus.wire.RunSpec` from the coordinator,
builds the static city once (from its on-disk cache) and refuses to join if
its city's content hash is not the spec's; then it reacts to what arrives:
states and the forecasts of the sectors it follows
(:mod:`agents.sector_forecasts`) update its copy of the world, committed
controls of the agents before it fill in its predecessors' moves, and a
:class:`~bus.wire.Turn` makes it run :func:`agents.rollout.plan_agent`,
exactly the function the in-process policy calls, and publish the result.

Nothing received is used before it is checked against what the agent knows
(:mod:`bus.checks`): the fleet's size, the city's nodes, the current minute,
a predecessor's candidate controls.  A message that fails, or whose handling
raises anything at all, is dropped, and the first of each kind is logged; no
message ends the agent but the run's own stop.

This module must not import torch: forecasts arrive on the bus.
"""

from __future__ import annotations

import dataclasses
import resource
import sys
import time
from dataclasses import dataclass

import numpy as np

from agents.rollout import RolloutConfig, StepContext, candidate_controls, plan_agent, prepare_step, warm_up
from agents.sector_forecasts import AgentForecasts, needed_sectors
from bus.checks import (Bounds, Rejections, check_choice, check_control, check_spec, check_state,
                        check_stop, check_turn)
from bus.delta import StateView
from bus.keys import Keys
from bus.session import Inbox, SessionArgs, open_session, publisher
from bus.wire import Control, ForecastMsg, RunSpec, Snapshot, State, Stop, Turn, WireError, decode
from city.errors import ConfigError, SurgeError
from city.fingerprint import city_sha256, code_version


@dataclass(frozen=True)
class AgentConfig:
    """One agent process: which taxi, which run, how to reach the bus."""

    index: int
    run: str
    bus: SessionArgs
    join_timeout_s: float = 120.0
    #: This host's data directory for real maps, when it is not where the coordinator has it.
    data_dir: str | None = None


def log(index: int, message: str) -> None:
    print(f"surge agent {index}: {message}", file=sys.stderr, flush=True)


class TaxiAgent:
    """The event loop of one taxi; see the module docstring."""

    def __init__(self, config: AgentConfig) -> None:
        self.cfg = config
        self.keys = Keys(config.run)
        self.me = config.index
        self.view = StateView()
        #: Set by the accepted run spec, with the city.
        self.forecasts: AgentForecasts
        self.committed: dict[int, dict[int, int]] = {}
        self.pending: Turn | None = None
        #: The minute whose turn made this taxi ask the coordinator for missing forecast pieces (once a turn).
        self.asked: int | None = None
        self.early: list[tuple[Control, str]] = []
        self.context: StepContext | None = None
        self.decisions = 0
        self.rejected = Rejections(lambda m: log(self.me, m))
        self._cities: dict[tuple[str, str | None], object] = {}

    def run(self) -> int:
        """Join the run and plan until it stops; the number of controls this agent planned."""
        with open_session(self.cfg.bus) as session:
            inbox = Inbox()
            subs = [
                inbox.subscribe(session, self.keys.state, "state"),
                inbox.subscribe(session, self.keys.dropoffs, "dropoffs"),
                inbox.subscribe(session, self.keys.turn(self.me), "turn"),
                inbox.subscribe(session, self.keys.all_committed, "committed"),
                inbox.subscribe(session, self.keys.stop, "stop"),
            ]
            spec = self._fetch_spec(session)
            self.bounds = Bounds(taxis=spec.taxis, nodes=self.city.n_nodes, sectors=self.city.n_sectors, minutes=spec.minutes)
            self.forecasts.attach(session, inbox, self.keys)
            self._warm_up()
            out = publisher(session, self.keys.control(self.me))
            token = session.liveliness().declare_token(self.keys.alive(self.me))
            log(self.me, f"joined run {spec.run!r} ({spec.policy}, {spec.taxis} taxis)")
            try:
                self._loop(session, inbox, out)
            finally:
                token.undeclare()
                self.forecasts.close()
                for s in subs:
                    s.undeclare()
        return self.decisions

    def _warm_up(self) -> None:
        """Load (or build) the compiled kernels before joining, so that a fresh checkout's first turn is not late."""
        warm_up(self.city, self.rollout)

    def _fetch_spec(self, session) -> RunSpec:  # noqa: ANN001
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
                self._cities[where] = load_city(*where)
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
            log(self.me, f"warning: this host runs {code_version()}, the coordinator {spec.code}; decisions may differ from its reference")
        self.city, self.rollout = city, rollout
        bounds = Bounds(taxis=spec.taxis, nodes=city.n_nodes, sectors=city.n_sectors, minutes=spec.minutes)
        self.forecasts = AgentForecasts(city, rollout, bounds, self.rejected)
        return spec

    def _snapshot(self, session) -> None:  # noqa: ANN001
        for reply in session.get(self.keys.snapshot, timeout=5.0):
            if reply.ok is None:
                continue
            try:
                snap = decode(reply.ok.payload.to_bytes(), Snapshot, self.keys.snapshot)
                state = check_state(decode(snap.state, State, self.keys.snapshot), self.keys.snapshot, self.bounds)  # type: ignore[arg-type]
                if not state.full:
                    raise WireError(f"{self.keys.snapshot}: a snapshot's state must be full")
                self._on_forecast(decode(snap.forecast, ForecastMsg, self.keys.snapshot))  # type: ignore[arg-type]
            except Exception as exc:  # a bad snapshot: drop it, try the next answer
                self.rejected.exception("snapshot", self.keys.snapshot, exc)
                continue
            self.view.apply(state)
            self.context = None
            return

    def _on_forecast(self, msg: ForecastMsg) -> None:
        self.forecasts.on_whole(msg, self.keys.snapshot)

    def _follow(self) -> None:
        """Follow the sectors this taxi plans in next: where it is, or where it is free again when busy."""
        obs = self.view.obs
        if obs is None:
            return
        node = int(obs.pos[self.me]) if obs.tau[self.me] == 0 or obs.dest[self.me] < 0 else int(obs.dest[self.me])
        self.forecasts.forget_before(int(obs.t) // 60)
        self.forecasts.follow(needed_sectors(self.city, self.rollout, node), int(obs.t) // 60)

    def _minute(self) -> int | None:
        return None if self.view.obs is None else int(self.view.obs.t)

    def handle(self, session, tag: str, key: str, payload: bytes) -> bool:  # noqa: ANN001
        """Check and apply one message; ``False`` when it is the run's stop."""
        if tag == "stop":
            check_stop(decode(payload, Stop, key), key, self.bounds)  # type: ignore[arg-type]
            return False
        if tag == "state":
            msg = check_state(decode(payload, State, key), key, self.bounds)  # type: ignore[arg-type]
            if not self.view.apply(msg):
                self._snapshot(session)
            self.context = None
            self._follow()
            early, self.early = self.early, []
            for c, k in early:  # commitments that came ahead of their minute's state (those still ahead go back)
                try:
                    self._on_committed(c, k)
                except Exception as exc:
                    self.rejected.exception("committed", k, exc)
        elif tag == "forecast":
            self.forecasts.on_sector(payload, key)
        elif tag == "dropoffs":
            self.forecasts.on_dropoffs(payload, key)
        elif tag == "committed":
            self._on_committed(decode(payload, Control, key), key)  # type: ignore[arg-type]
        elif tag == "turn":
            self.pending = check_turn(decode(payload, Turn, key), key, self.me, self.bounds, self._minute())  # type: ignore[arg-type]
        return True

    def _on_committed(self, c: Control, key: str) -> None:
        """A predecessor's committed control of the current minute, and one of that predecessor's controls."""
        obs = self.view.obs
        if obs is None:
            raise WireError(f"{key}: a committed control before this agent has a state")
        if obs.t < c.t < self.bounds.minutes and len(self.early) < self.bounds.taxis * self.bounds.minutes:
            self.early.append((c, key))  # ahead of its minute's state (zenoh orders per key only): checked once that state is in
            return
        if c.t < obs.t:
            return  # a later agent's commitment of a minute before, overtaken by a newer state: no longer needed
        check_control(c, key, self.bounds, int(obs.t))
        if obs.tau[c.agent] > 0:
            raise WireError(f"{key}: agent {c.agent} is busy at minute {obs.t}; it commits no control")
        check_choice(c, key, candidate_controls(self.city, obs, c.agent))
        self.committed.setdefault(c.t, {})[c.agent] = c.control

    def _loop(self, session, inbox: Inbox, out) -> None:  # noqa: ANN001
        while True:
            item = inbox.get(timeout=1.0)
            if item is None:
                continue
            tag, key, payload = item
            try:
                if not self.handle(session, tag, key, payload):
                    return
                self._prepare()
                self._maybe_plan(out)
            except Exception as exc:  # one bad message never ends the agent: drop it and go on
                self.rejected.exception(tag, key, exc)

    def _prepare(self) -> None:
        """Build the minute's shared context as soon as the state and forecast are in, while earlier agents plan."""
        obs = self.view.obs
        if obs is None or obs.tau[self.me] > 0:
            return
        if self.context is None or self.context.obs.t != obs.t:
            hour, sectors = int(obs.t) // 60, needed_sectors(self.city, self.rollout, int(obs.pos[self.me]))
            tables = self.forecasts.tables(hour, sectors)
            if tables is None and self.pending is not None and self.pending.t == obs.t and self.asked != obs.t:
                self.asked = int(obs.t)
                self.forecasts.fetch(hour, sectors)  # its turn, and a piece it follows never came: ask for it
                tables = self.forecasts.tables(hour, sectors)
            if tables is None:
                return
            self.context = prepare_step(self.city, self.rollout, obs, tables, obs.t % 60)

    def _maybe_plan(self, out) -> None:  # noqa: ANN001
        turn, obs = self.pending, self.view.obs
        if turn is None or obs is None or obs.t != turn.t or self.context is None or self.context.obs.t != turn.t:
            return
        free_before = np.flatnonzero(obs.tau[: self.me] == 0)
        mine = self.committed.get(turn.t, {})
        if any(int(a) not in mine for a in free_before):
            return
        committed = self.context.base_controls[: self.me].copy()
        for a in free_before:
            committed[a] = mine[int(a)]
        t0 = time.perf_counter()
        control = plan_agent(self.context, committed, self.me)
        plan_s = time.perf_counter() - t0
        rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        out.put(Control(t=turn.t, agent=self.me, control=int(control), plan_s=plan_s, rss_mb=rss_mb).encode())
        self.decisions += 1
        self.pending = None
        for t in [t for t in self.committed if t < turn.t]:
            del self.committed[t]


class OtherCity(ConfigError):
    """The coordinator's city is not this host's: the agent refuses to join rather than plan on another map."""


def agent_main(config: AgentConfig) -> int:
    """Entry point of a spawned agent process: run, and report failures as one line."""
    try:
        TaxiAgent(config).run()
    except SurgeError as exc:
        log(config.index, f"error: {exc}")
        return 2
    except KeyboardInterrupt:
        return 130
    return 0

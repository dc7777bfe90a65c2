"""One taxi as its own process on the bus: it follows the state, waits for its turn and plans its own control.

The agent fetches the run's :class:`~bus.wire.RunSpec` from the coordinator,
builds the static city once (from its on-disk cache), then reacts to what
arrives: states and forecasts update its copy of the world, and a
:class:`~bus.wire.Turn`, which carries the committed controls of the
predecessors this agent depends on (:mod:`agents.waves`), makes it run
:func:`agents.rollout.plan_agent`, exactly the function the in-process
policy calls, and publish the result.  It subscribes to no commitments:
only its turn wakes it, and the state brings the minute's base controls, so
a free agent does not recompute them while others plan.

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

from agents.forecast import Forecast
from agents.rollout import DemandTables, RolloutConfig, StepContext, candidate_controls, plan_agent, prepare_step, warm_up
from bus.checks import (Bounds, Rejections, check_choice, check_forecast, check_spec, check_state,
                        check_stop, check_turn)
from bus.delta import StateView
from bus.keys import Keys
from bus.session import Inbox, SessionArgs, open_session, publisher
from bus.wire import Control, ForecastMsg, RunSpec, Snapshot, State, Stop, Turn, WireError, decode
from city.errors import ConfigError, SurgeError


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
        self.tables: dict[int, DemandTables] = {}
        self.pending: Turn | None = None
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
                inbox.subscribe(session, self.keys.forecast, "forecast"),
                inbox.subscribe(session, self.keys.turn(self.me), "turn"),
                inbox.subscribe(session, self.keys.stop, "stop"),
            ]
            spec = self._fetch_spec(session)
            self.bounds = Bounds(taxis=spec.taxis, nodes=self.city.n_nodes, sectors=self.city.n_sectors, minutes=spec.minutes)
            self._warm_up()
            out = publisher(session, self.keys.control(self.me))
            token = session.liveliness().declare_token(self.keys.alive(self.me))
            log(self.me, f"joined run {spec.run!r} ({spec.policy}, {spec.taxis} taxis)")
            try:
                self._loop(session, inbox, out)
            finally:
                token.undeclare()
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
        self.city, self.rollout = city, rollout
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
        check_forecast(msg, self.keys.forecast, self.bounds)
        fc = Forecast(eta=msg.eta, rho=msg.rho, delta=msg.delta, beta=msg.beta)
        self.tables[msg.hour] = DemandTables.build(self.city, fc, self.rollout.ce, self.rollout.seed)

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
        elif tag == "forecast":
            self._on_forecast(decode(payload, ForecastMsg, key))  # type: ignore[arg-type]
            self.context = None
        elif tag == "turn":
            self.pending = check_turn(decode(payload, Turn, key), key, self.me, self.bounds, self._minute())  # type: ignore[arg-type]
        return True

    def _predecessors(self, turn: Turn) -> np.ndarray:
        """The controls of agents ``0 … me-1`` for ``turn``: the state's base controls, with the turn's committed ones put in.

        Each carried control must be a free predecessor's candidate control at
        the turn's minute; a turn that fails is dropped, and the agent waits for
        the coordinator's next.
        """
        obs, key = self.view.obs, self.keys.turn(self.me)
        committed = self.context.base_controls[: self.me].copy()
        for a, c in zip(turn.deps.tolist(), turn.controls.tolist()):
            if obs.tau[a] > 0:
                raise WireError(f"{key}: agent {a} is busy at minute {obs.t}; it commits no control")
            check_choice(Control(t=turn.t, agent=a, control=c), key, candidate_controls(self.city, obs, a))
            committed[a] = c
        return committed

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
        if obs is None or obs.t // 60 not in self.tables or obs.tau[self.me] > 0:
            return
        if self.context is None or self.context.obs.t != obs.t:
            self.context = prepare_step(self.city, self.rollout, obs, self.tables[obs.t // 60], obs.t % 60, base=self.view.base)

    def _maybe_plan(self, out) -> None:  # noqa: ANN001
        turn, obs = self.pending, self.view.obs
        if turn is None or obs is None or obs.t != turn.t or self.context is None or self.context.obs.t != turn.t:
            return
        self.pending = None  # a turn is planned, or dropped, once
        committed = self._predecessors(turn)
        t0 = time.perf_counter()
        control = plan_agent(self.context, committed, self.me)
        plan_s = time.perf_counter() - t0
        rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        out.put(Control(t=turn.t, agent=self.me, control=int(control), plan_s=plan_s, rss_mb=rss_mb).encode())
        self.decisions += 1


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

"""One taxi as its own process on the bus: it follows the state, waits for its turn and plans its own control.

The agent fetches the run's :class:`~bus.wire.RunSpec` from the coordinator,
builds the static city once (from its on-disk cache), then reacts to what
arrives: states and forecasts update its copy of the world, committed
controls of the agents before it fill in its predecessors' moves, and a
:class:`~bus.wire.Turn` makes it run :func:`agents.rollout.plan_agent`,
exactly the function the in-process policy calls, and publish the result.

This module must not import torch: forecasts arrive on the bus.
"""

from __future__ import annotations

import resource
import sys
import time
from dataclasses import dataclass

import numpy as np

from agents.forecast import Forecast
from agents.rollout import DemandTables, RolloutConfig, StepContext, plan_agent, prepare_step, warm_up
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
        self.committed: dict[int, dict[int, int]] = {}
        self.pending: Turn | None = None
        self.context: StepContext | None = None
        self.decisions = 0

    def run(self) -> int:
        """Join the run and plan until it stops; the number of controls this agent planned."""
        with open_session(self.cfg.bus) as session:
            inbox = Inbox()
            subs = [
                inbox.subscribe(session, self.keys.state, "state"),
                inbox.subscribe(session, self.keys.forecast, "forecast"),
                inbox.subscribe(session, self.keys.turn(self.me), "turn"),
                inbox.subscribe(session, self.keys.all_committed, "committed"),
                inbox.subscribe(session, self.keys.stop, "stop"),
            ]
            spec = self._fetch_spec(session)
            from city.scenario import load_city

            self.city = load_city(spec.scenario, self.cfg.data_dir or spec.data_dir)
            if self.city.summary() != spec.city:
                raise ConfigError(f"agent {self.me}: this host's {spec.scenario} city {self.city.summary()} is not the coordinator's {spec.city}")
            if spec.taxis <= self.me:
                raise ConfigError(f"agent {self.me}: run {spec.run!r} has only {spec.taxis} taxis")
            self.rollout = RolloutConfig(**spec.rollout)
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
        deadline = time.monotonic() + self.cfg.join_timeout_s
        while time.monotonic() < deadline:
            for reply in session.get(self.keys.spec, timeout=2.0):
                if reply.ok is not None:
                    return decode(reply.ok.payload.to_bytes(), RunSpec, self.keys.spec)  # type: ignore[return-value]
            time.sleep(0.2)
        raise ConfigError(f"agent {self.me}: no coordinator answered on {self.keys.spec} within {self.cfg.join_timeout_s:.0f} s")

    def _snapshot(self, session) -> None:  # noqa: ANN001
        for reply in session.get(self.keys.snapshot, timeout=5.0):
            if reply.ok is None:
                continue
            snap = decode(reply.ok.payload.to_bytes(), Snapshot, self.keys.snapshot)
            self._on_forecast(decode(snap.forecast, ForecastMsg, self.keys.snapshot))  # type: ignore[arg-type]
            self.view.apply(decode(snap.state, State, self.keys.snapshot))  # type: ignore[arg-type]
            self.context = None
            return

    def _on_forecast(self, msg: ForecastMsg) -> None:
        fc = Forecast(eta=msg.eta, rho=msg.rho, delta=msg.delta, beta=msg.beta)
        self.tables[msg.hour] = DemandTables.build(self.city, fc, self.rollout.ce, self.rollout.seed)

    def _loop(self, session, inbox: Inbox, out) -> None:  # noqa: ANN001
        while True:
            item = inbox.get(timeout=1.0)
            if item is None:
                continue
            tag, key, payload = item
            try:
                if tag == "stop":
                    decode(payload, Stop, key)
                    return
                if tag == "state":
                    msg = decode(payload, State, key)
                    if not self.view.apply(msg):  # type: ignore[arg-type]
                        self._snapshot(session)
                    self.context = None
                elif tag == "forecast":
                    self._on_forecast(decode(payload, ForecastMsg, key))  # type: ignore[arg-type]
                    self.context = None
                elif tag == "committed":
                    c = decode(payload, Control, key)
                    self.committed.setdefault(c.t, {})[c.agent] = c.control  # type: ignore[attr-defined]
                elif tag == "turn":
                    turn = decode(payload, Turn, key)
                    if turn.agent == self.me:  # type: ignore[attr-defined]
                        self.pending = turn  # type: ignore[assignment]
            except WireError as exc:
                log(self.me, f"ignored: {exc}")
                continue
            self._prepare()
            self._maybe_plan(out)

    def _prepare(self) -> None:
        """Build the minute's shared context as soon as the state and forecast are in, while earlier agents plan."""
        obs = self.view.obs
        if obs is None or obs.t // 60 not in self.tables or obs.tau[self.me] > 0:
            return
        if self.context is None or self.context.obs.t != obs.t:
            self.context = prepare_step(self.city, self.rollout, obs, self.tables[obs.t // 60], obs.t % 60)

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

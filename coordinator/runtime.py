"""The coordinator of a distributed run: the clock, the ground-truth world and the order of turns.

Each minute it publishes the state (a delta) and, at each hour, the forecast
sector by sector (unless a predictor service does; it answers a taxi's query
for a sector it missed either way); then it gives the free taxis their turns
one at a time, in agent order, and commits each control it receives so that the agents after it can see it.  A
silent agent (its liveliness token gone, or past the deadline) gets the base
policy's control for that minute, which is what the in-process rollout
assumes for the agents after the decider, and the run goes on.  A restarted
agent rejoins from a snapshot.  With every agent answering, the decisions are
those of the in-process policy of the same seed, bit for bit
(``tests/test_runtime.py``).

A proposed control counts only if it is on its own agent's key, for the
current minute, and one of that agent's candidate controls; anything else is
dropped (the first of each kind logged) and the coordinator keeps waiting
for a good one until the deadline.  No message, and no exception while
handling one, ends the run.
"""

from __future__ import annotations

import datetime as dt
import sys
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from agents.base import EpisodeContext, make_policy, policy_class
from agents.rollout import RolloutConfig, RolloutPolicy, base_controls, candidate_controls
from bus.checks import Bounds, Rejections, check_choice, check_control, check_forecast
from bus.delta import state_message
from bus.forecasts import ForecastPublisher, sector_message
from bus.keys import Keys
from bus.session import Inbox, SessionArgs, open_session, publisher
from bus.wire import ENCODING, Control, ForecastMsg, ForecastRequest, RunSpec, Snapshot, Stop, Turn, WireError, decode
from city.errors import ConfigError
from city.fingerprint import city_sha256, code_version
from city.forecast import Forecast
from city.sim import FleetSim, Observation, Requests, decisions_hash


@dataclass(frozen=True)
class FleetConfig:
    """One distributed episode: the same instance as ``surge evaluate``'s (date, hour, seed)."""

    run: str = "demo"
    scenario: str = "synthetic"
    data_dir: str | None = None
    date: str = "2022-11-17"
    hour: int = 19
    minutes: int = 60
    taxis: int = 8
    seed: int = 0
    world_seed: int = 0
    policy: str = "surge"
    options: dict = field(default_factory=dict)
    deadline_s: float = 30.0
    join_timeout_s: float = 120.0
    #: Least wall time per simulated minute: 0 runs as fast as the agents plan, 60 in real time.
    minute_s: float = 0.0
    #: Ask a ``surge predictor serve`` process on the bus for each hour's forecast instead of computing it here.
    predictor: bool = False

    def instance(self) -> tuple[Any, Requests, np.ndarray, EpisodeContext]:
        """The scenario, requests, start positions and episode context of this run: one place for both runs that must agree."""
        from city.scenario import load_scenario
        from coordinator.evaluate import episode_requests, initial_positions

        scen = load_scenario(self.scenario, self.data_dir, seed=self.world_seed)
        date = dt.date.fromisoformat(self.date)
        context = EpisodeContext(city=scen.city, date=date, hour=self.hour, minutes=self.minutes, seed=self.seed, world=scen.world)
        return scen, episode_requests(scen.world, date, self.hour, self.minutes), initial_positions(scen.city, self.taxis, self.seed), context

    def policy_class(self) -> type[RolloutPolicy]:
        cls = policy_class(self.policy)
        if not issubclass(cls, RolloutPolicy):
            raise ConfigError(f"policy {self.policy!r}: the distributed runtime runs rollout policies (surge, garces2023)")
        return cls

    def forecast_name(self) -> str:
        """The forecast provider the run uses: the ``forecast`` option, or the policy's default."""
        return str(self.options.get("forecast") or self.policy_class().defaults["forecast"])

    def make_policy(self, city) -> RolloutPolicy:  # noqa: ANN001
        """The in-process policy: the reference, and the forecast source when there is no predictor service."""
        self.policy_class()
        return make_policy(self.policy, city, **self.options)  # type: ignore[return-value]

    def rollout_config(self) -> RolloutConfig:
        """The planner settings alone, without loading a forecast (the predictor service has it)."""
        cls = self.policy_class()
        planner = {k: v for k, v in self.options.items() if k not in ("forecast", "model")}
        try:
            return cls.rollout_config(**planner)
        except TypeError as exc:
            raise ConfigError(f"policy {self.policy!r}: {exc}") from None


def log(message: str) -> None:
    print(f"surge coordinator: {message}", file=sys.stderr, flush=True)


class Coordinator:
    """Runs one episode over the bus; :meth:`run` returns its metrics and decisions."""

    def __init__(self, config: FleetConfig, progress: bool = True) -> None:
        self.cfg = config
        self.keys = Keys(config.run)
        self.progress = progress
        scen, requests, start, context = config.instance()
        self.city = scen.city
        self.start = dt.datetime.combine(context.date, dt.time(config.hour))
        self.policy: RolloutPolicy | None = None
        if config.predictor:
            self.rollout = config.rollout_config()
        else:
            self.policy = config.make_policy(self.city)
            self.policy.reset(context)
            self.rollout = self.policy.config
        self.sim = FleetSim(self.city, requests, start)
        self.spec = RunSpec(run=config.run, scenario=config.scenario, data_dir=config.data_dir, city=self.city.summary(), taxis=config.taxis,
                            minutes=config.minutes, policy=config.policy, rollout=asdict(self.rollout),
                            deadline_s=config.deadline_s, city_sha256=city_sha256(self.city), code=code_version())
        self.alive: set[int] = set()
        self.forecast_msg = b""
        #: The current hour and its forecast, for the sector queries of taxis that missed a piece.
        self.hour_forecast: tuple[int, Forecast] | None = None
        self.stale = 0
        self.bounds = Bounds(taxis=config.taxis, nodes=self.city.n_nodes, sectors=self.city.n_sectors, minutes=config.minutes)
        self.rejected = Rejections(log)
        #: The minute being played, against which proposed controls are checked.
        self.obs: Observation | None = None

    # ------------------------------------------------------------------ inbox
    def _handle(self, item: tuple[str, str, object], want: tuple[int, int] | None = None) -> Control | None:
        """Serve queries, track liveliness, and return the control ``want`` = (t, agent) if this item is it.

        Anything wrong with the item, or raised while handling it, drops it.
        """
        tag, key, payload = item
        try:
            return self._handle_one(tag, key, payload, want)
        except Exception as exc:  # one bad message never ends the run
            self.rejected.exception(tag, key, exc)
            return None

    def _handle_one(self, tag: str, key: str, payload: object, want: tuple[int, int] | None) -> Control | None:
        if tag == "alive":
            agent = Keys.agent_of(key)
            if agent is None or not 0 <= agent < self.cfg.taxis:
                raise WireError(f"{key}: a liveliness token of no agent of this run's {self.cfg.taxis}")
            if payload:
                self.alive.add(agent)
            else:
                self.alive.discard(agent)
                log(f"agent {agent} left")
        elif tag in ("spec", "snapshot"):
            try:
                answer = self.spec if tag == "spec" else Snapshot(state=self.full_state(), forecast=self.forecast_msg)
                payload.reply(key, answer.encode(), encoding=ENCODING)  # type: ignore[attr-defined]
            finally:
                payload.drop()  # type: ignore[attr-defined]  # ends the asker's get() now, not when the query is collected
        elif tag == "forecast":
            try:
                payload.reply(key, self._sector_answer(key), encoding=ENCODING)  # type: ignore[attr-defined]
            finally:
                payload.drop()  # type: ignore[attr-defined]
        elif tag == "control":
            c = check_control(decode(payload, Control, key), key, self.bounds)  # type: ignore[arg-type]
            if c.by != "agent":
                raise WireError(f"{key}: a proposed control must say by='agent', not {c.by!r}")
            if self.obs is not None and c.t == self.obs.t:
                check_choice(c, key, candidate_controls(self.city, self.obs, c.agent))
            if want is not None and (c.t, c.agent) == want:
                return c
            self.stale += 1
        return None

    def _sector_answer(self, key: str) -> bytes:
        """The current hour's forecast of the sector a query's key names."""
        sector = Keys.agent_of(key)
        if self.hour_forecast is None or sector is None or not 0 <= sector < self.city.n_sectors:
            raise WireError(f"{key}: a query for the forecast of one sector 0..{self.city.n_sectors - 1}, once the run has begun")
        hour, forecast = self.hour_forecast
        return sector_message(forecast, self.city, hour, sector).encode()

    def full_state(self) -> bytes:
        return state_message(self.sim.observe(), None).encode()

    # ------------------------------------------------------------------- run
    def run(self, bus: SessionArgs) -> dict:
        with open_session(bus) as session:
            inbox = Inbox()
            decls = [
                inbox.serve(session, self.keys.spec, "spec"),
                inbox.serve(session, self.keys.snapshot, "snapshot"),
                inbox.serve(session, self.keys.all_forecasts, "forecast"),
                inbox.subscribe(session, self.keys.all_controls, "control"),
                inbox.watch_liveliness(session, self.keys.all_alive, "alive"),
            ]
            try:
                return self._run(session, inbox)
            finally:
                for d in decls:
                    d.undeclare()

    def _wait_for_agents(self, inbox: Inbox) -> None:
        deadline = time.monotonic() + self.cfg.join_timeout_s
        while len(self.alive) < self.cfg.taxis:
            left = deadline - time.monotonic()
            if left <= 0:
                missing = sorted(set(range(self.cfg.taxis)) - self.alive)
                raise ConfigError(f"run {self.cfg.run!r}: {len(self.alive)} of {self.cfg.taxis} agents joined within "
                                  f"{self.cfg.join_timeout_s:.0f} s; missing {', '.join(map(str, missing[:10]))}")
            item = inbox.get(timeout=min(left, 1.0))
            if item is not None:
                self._handle(item)
        log(f"all {self.cfg.taxis} agents joined run {self.cfg.run!r}")

    def _run(self, session, inbox: Inbox) -> dict:  # noqa: ANN001
        cfg, keys = self.cfg, self.keys
        pub_state, pub_stop = (publisher(session, k) for k in (keys.state, keys.stop))
        pub_forecast = ForecastPublisher(session, keys, self.city) if self.policy is not None else None
        turn_pub = {a: publisher(session, keys.turn(a)) for a in range(cfg.taxis)}
        commit_pub = {a: publisher(session, keys.committed(a)) for a in range(cfg.taxis)}
        self._wait_for_agents(inbox)
        controls = np.zeros((cfg.minutes, cfg.taxis), dtype=np.int32)
        costs, step_s, plan_s = [], [], []
        planned = np.zeros(cfg.taxis, dtype=np.int64)
        fallbacks = np.zeros(cfg.taxis, dtype=np.int64)
        rss = np.zeros(cfg.taxis)
        previous = None
        t_start = time.perf_counter()
        for t in range(cfg.minutes):
            t0 = time.perf_counter()
            obs = self.obs = self.sim.observe()
            if t % 60 == 0:
                self.forecast_msg = self._forecast(session, inbox, t // 60)
                self._hold_forecast(pub_forecast, t // 60)
            pub_state.put(state_message(obs, previous).encode())
            previous = np.asarray(obs.req_index)
            base = base_controls(self.city, self.rollout, obs)
            u = base.copy()
            for agent in np.flatnonzero(obs.tau == 0).tolist():
                got = self._turn(inbox, turn_pub[agent], t, agent)
                if got is None:
                    fallbacks[agent] += 1
                    u[agent] = base[agent]
                    commit = Control(t=t, agent=agent, control=int(base[agent]), by="base")
                else:
                    u[agent] = got.control
                    planned[agent] += 1
                    plan_s.append(got.plan_s)
                    rss[agent] = max(rss[agent], got.rss_mb)
                    commit = got
                commit_pub[agent].put(commit.encode())
            controls[t] = u
            costs.append(self.sim.step(u))
            step_s.append(time.perf_counter() - t0)
            if self.progress:
                free = int((obs.tau == 0).sum())
                log(f"minute {t + 1}/{cfg.minutes}: {free} free {'taxi' if free == 1 else 'taxis'} took turns, "
                    f"{costs[-1]} requests waiting ({step_s[-1]:.2f} s)")
            self._pace(inbox, t0 + cfg.minute_s)
        pub_stop.put(Stop(t=cfg.minutes).encode())
        res = self.sim.result(costs, controls, step_s)
        return {
            "run": cfg.run,
            "policy": cfg.policy,
            "taxis": cfg.taxis,
            "minutes": cfg.minutes,
            "total_cost": res.total_cost,
            "outstanding_end": res.outstanding_end,
            "served": res.served,
            "requests": res.n_requests,
            "decisions_sha256": decisions_hash(controls),
            "fallbacks": int(fallbacks.sum()),
            "planned_per_agent": planned.tolist(),
            "fallbacks_per_agent": fallbacks.tolist(),
            "controls": controls.tolist(),
            "stale_messages": self.stale,
            "rejected_messages": dict(self.rejected.counts),
            "step_seconds": {"median": float(np.median(step_s)), "max": float(np.max(step_s))},
            "agent_plan_seconds": {"median": float(np.median(plan_s)) if plan_s else None,
                                   "max": float(np.max(plan_s)) if plan_s else None},
            "agent_peak_rss_mb": float(rss.max()),
            "wall_seconds": time.perf_counter() - t_start,
        }

    def _hold_forecast(self, pub: ForecastPublisher | None, hour: int) -> None:
        """Keep the hour's forecast for snapshots and sector queries; publish it sector by sector unless the predictor did."""
        msg = decode(self.forecast_msg, ForecastMsg)
        forecast = Forecast(eta=msg.eta, rho=msg.rho, delta=msg.delta, beta=msg.beta)  # type: ignore[attr-defined]
        self.hour_forecast = (hour, forecast)
        if pub is not None:
            pub.put(forecast, hour)

    def _forecast(self, session, inbox: Inbox, hour: int) -> bytes:  # noqa: ANN001
        """The encoded forecast of the episode's hour ``hour``: computed here, or asked of the predictor service."""
        if self.policy is not None:
            fc = self.policy.forecast(hour)
            return ForecastMsg(hour=hour, eta=fc.eta, rho=fc.rho, delta=fc.delta, beta=fc.beta).encode()
        when = self.start + dt.timedelta(hours=hour)
        request = ForecastRequest(hour=hour, when=when.isoformat()).encode()
        deadline = time.monotonic() + self.cfg.join_timeout_s
        last = "no answer"
        while time.monotonic() < deadline:
            for reply in session.get(self.keys.predictor, payload=request, encoding=ENCODING, timeout=10.0):
                if reply.ok is None:
                    why = reply.err.payload.to_bytes().decode(errors="replace")
                    if why != "Timeout":
                        last = f"the predictor refused hour {when:%Y-%m-%d %H}:00: {why}"
                        self.rejected.drop("predictor: refused", f"{self.keys.predictor}: {last}; asking again")
                    continue
                try:
                    payload = reply.ok.payload.to_bytes()
                    msg = check_forecast(decode(payload, ForecastMsg, self.keys.predictor), self.keys.predictor, self.bounds)  # type: ignore[arg-type]
                    if msg.hour != hour:
                        raise WireError(f"{self.keys.predictor}: field 'hour' is {msg.hour}, asked for hour {hour}")
                    return payload
                except Exception as exc:  # a bad answer: drop it, ask again
                    last = str(exc)
                    self.rejected.exception("predictor", self.keys.predictor, exc)
            self._pace(inbox, time.perf_counter() + 0.5)
        raise ConfigError(f"run {self.cfg.run!r}: no acceptable forecast on {self.keys.predictor} within "
                          f"{self.cfg.join_timeout_s:.0f} s (last: {last})")

    def _pace(self, inbox: Inbox, until: float) -> None:
        """Wait out the rest of the minute, still serving joins and snapshots."""
        while (left := until - time.perf_counter()) > 0:
            item = inbox.get(timeout=left)
            if item is not None:
                self._handle(item)

    def _turn(self, inbox: Inbox, pub, t: int, agent: int) -> Control | None:  # noqa: ANN001
        """Give ``agent`` its turn and wait for one of its controls until the deadline or its departure."""
        if agent not in self.alive:
            return None
        pub.put(Turn(t=t, agent=agent).encode())
        deadline = time.monotonic() + self.cfg.deadline_s
        while agent in self.alive:
            left = deadline - time.monotonic()
            if left <= 0:
                log(f"minute {t}: agent {agent} silent for {self.cfg.deadline_s:g} s; base control used")
                return None
            item = inbox.get(timeout=left)
            if item is not None:
                got = self._handle(item, want=(t, agent))
                if got is not None:
                    return got
        log(f"minute {t}: agent {agent} is gone; base control used")
        return None


def coordinator_main(config: FleetConfig, bus: SessionArgs, result_path: str | None = None) -> dict:
    """Run the coordinator; with ``result_path``, write the result there as JSON (for a launcher)."""
    import json
    from pathlib import Path

    result = Coordinator(config).run(bus)
    if result_path is not None:
        Path(result_path).write_text(json.dumps(result, indent=1))
    return result

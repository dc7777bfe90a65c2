"""The coordinator of a distributed run: the clock, the ground-truth world and the order of turns.

Each minute it publishes the state (a delta, with the minute's base
controls) and, at each hour, the forecast sector by sector (unless a
predictor service does; it answers a taxi's query for a sector it missed
either way); then it releases the free taxis' turns by their dependency
graph (:func:`agents.waves.plan_waves`, the same graph the in-process policy
plans by): an agent gets its turn, with the committed controls of the
predecessors it depends on, as soon as those have committed, so no agent
waits for a wave's slowest member it does not depend on.  A
silent agent (its liveliness token gone, or past the deadline) gets the base
policy's control for that minute, which is what the in-process rollout
assumes for the agents after the decider, and the run goes on.  A restarted
agent rejoins from a snapshot.  With every agent answering, the decisions are
those of the in-process policy of the same seed, bit for bit
(``tests/coordinator/test_runtime.py``).

It survives faults (``tests/coordinator/test_faults.py``, ``test_recovery.py``): it holds a liveliness token
that agents watch, publishes :class:`~bus.wire.Stop` with the reason on
every way out, checkpoints each minute to its run directory
(:mod:`coordinator.checkpoint`, ``--resume``), and tells a partition from
single failures and a hung agent from a live one (:mod:`coordinator.faults`).

One coordinator drives a run (:mod:`coordinator.claim`): a coordinator that
finds another's token alive refuses to start, or with ``takeover`` fences it
by a higher run epoch; one that sees a higher epoch's token stops.  The run
directory is locked (:func:`checkpoint.locked`) while a coordinator plays from it.

A proposed control counts only if it is on its own agent's key, for the
current minute, and one of that agent's candidate controls; anything else is
dropped (the first of each kind logged) and the coordinator keeps waiting
for a good one until the deadline.  No message, and no exception while
handling one, ends the run.
"""

from __future__ import annotations

import datetime as dt
import os
import time
from contextlib import ExitStack
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import Policy
from agents.rollout_inputs import candidate_controls
from agents.waves import Waves, plan_waves
from bus.checks import Bounds, Rejections, check_ack, check_choice, check_control, check_forecast
from bus.delta import state_message
from bus.forecast_messages import ForecastPublisher, sector_message
from bus.keys import Keys
from bus.session import Inbox, SessionArgs, open_session, publisher
from bus.wire import ENCODING, Ack, Control, ForecastMsg, ForecastRequest, RunSpec, Snapshot, Stop, WireError, decode
from city.errors import ConfigError
from city.fingerprint import city_sha256, code_version
from city.forecast import Forecast
from city.logs import steps
from city.sim import FleetSim, Observation, decisions_hash
from coordinator import checkpoint
from coordinator.run_config import FleetConfig
from coordinator.claim import TAKEOVER_WAIT_S, TakenOver, claim, epoch_time, taken_over
from coordinator.faults import Health
from coordinator.metrics import Counted
from coordinator.minute_base import MinuteBase
from coordinator.turns import TurnTaking, log


#: How long the run's stop is put again, every ``STOP_RESEND_S``, while agents' tokens remain.
STOP_WAIT_S = 5.0
STOP_RESEND_S = 0.25


class Coordinator(TurnTaking):
    """Runs one episode over the bus; :meth:`run` returns its metrics and decisions."""

    def __init__(self, config: FleetConfig, progress: bool = True, run_dir: str | Path | None = None, resume: bool = False,
                 takeover: bool = False) -> None:
        self.cfg = config
        self.resume, self.takeover = resume, takeover
        #: This coordinator's run epoch (set when it claims the run), and a higher one that took the run over.
        self.epoch = 0
        self.fenced_by: int | None = None
        self.keys = Keys(config.run)
        self.progress = progress
        scen, requests, start, context = config.instance()
        self.city = scen.city
        self.start = dt.datetime.combine(context.date, dt.time(config.hour))
        self.policy: Policy | None = None
        #: A centrally computed policy (:attr:`agents.base.Policy.central`): its joint control is the state's base controls.
        self.central = config.policy_class().central
        if config.predictor:
            self.rollout = config.rollout_config()
        else:
            self.policy = config.make_policy(self.city)
            self.policy.reset(context)
            self.rollout = config.rollout_config() if self.central else self.policy.config
        self.sim = FleetSim(self.city, requests, start)
        self.spec = RunSpec(run=config.run, scenario=config.scenario, data_dir=config.data_dir, city=self.city.summary(), taxis=config.taxis,
                            minutes=config.minutes, policy=config.policy, rollout=asdict(self.rollout),
                            deadline_s=config.deadline_s, city_sha256=city_sha256(self.city), code=code_version())
        self.health = Health(config.taxis, log)
        self.forecast_msg = b""
        #: The current hour and its forecast, for the sector queries of taxis that missed a piece.
        self.hour_forecast: tuple[int, Forecast] | None = None
        #: Where the run's checkpoint is written each minute (``None``: nowhere).
        self.run_dir = None if run_dir is None else Path(run_dir)
        self.tally = checkpoint.Tally.fresh(config.minutes, config.taxis)
        if resume:
            if self.run_dir is None:
                raise ConfigError("resuming a run needs its run directory")
            self._restore()  # a bad or finished checkpoint is one line before the bus; read again once the run directory is locked
        #: Whether every agent has joined once: later token changes are departures and returns.
        self.running = False
        self.bounds = Bounds(taxis=config.taxis, nodes=self.city.n_nodes, sectors=self.city.n_sectors, minutes=config.minutes)
        self.rejected = Rejections(log)
        #: The minute being played, against which proposed controls are checked.
        self.obs: Observation | None = None
        #: ``(minute, base controls)`` of the last minute whose base was computed (:meth:`base`).
        self.bases = MinuteBase(self.city, self.rollout, self.policy if self.central else None)
        #: The agents of the wave being released whose controls are still awaited, and those that came.
        self.waiting: set[int] = set()
        self.arrived: dict[int, Control] = {}

    def _restore(self) -> None:
        assert self.run_dir is not None
        self.tally = checkpoint.restore(self.run_dir, self.sim, self.cfg.minutes)
        if self.sim.state.t >= self.cfg.minutes:
            raise ConfigError(f"{self.run_dir / checkpoint.CHECKPOINT}: run {self.cfg.run!r} finished "
                              f"(minute {self.cfg.minutes} of {self.cfg.minutes}); nothing to resume")

    # ------------------------------------------------------------------ inbox
    def _handle(self, item: tuple[str, str, object], want: set[tuple[int, int]] | None = None) -> Control | None:
        """Serve queries, track liveliness, and return the control if this item is one of ``want``'s (t, agent).

        Anything wrong with the item, or raised while handling it, drops it.
        A higher coordinator's token raises :class:`TakenOver`.
        """
        tag, key, payload = item
        try:
            out = self._handle_one(tag, key, payload, want)
        except Exception as exc:  # one bad message never ends the run
            self.rejected.exception(tag, key, exc)
            out = None
        if self.fenced_by is not None:
            raise taken_over(self.cfg.run, self.fenced_by, self.epoch, int(self.sim.state.t))
        return out

    def _handle_one(self, tag: str, key: str, payload: object, want: set[tuple[int, int]] | None) -> Control | None:
        current = None if self.obs is None else int(self.obs.t)
        if tag == "alive":
            agent = Keys.agent_of(key)
            if agent is None or not 0 <= agent < self.cfg.taxis:
                raise WireError(f"{key}: a liveliness token of no agent of this run's {self.cfg.taxis}")
            self.health.token(agent, bool(payload), self.running)
        elif tag == "coordinator":
            epoch = Keys.agent_of(key)
            if payload and epoch is not None and epoch > self.epoch:
                self.fenced_by = epoch
        elif tag == "ack":
            self.tally.traffic.received(payload)  # type: ignore[arg-type]
            msg = check_ack(decode(payload, Ack, key), key, self.bounds)  # type: ignore[arg-type]
            self.health.ack(msg.agent, msg.t, current)
        elif tag in ("spec", "snapshot"):
            try:
                answer = self.spec if tag == "spec" else self._snapshot()
                payload.reply(key, answer.encode(), encoding=ENCODING)  # type: ignore[attr-defined]
            finally:
                payload.drop()  # type: ignore[attr-defined]  # ends the asker's get() now, not when the query is collected
        elif tag == "forecast":
            try:
                answer = self._sector_answer(key)
                if answer is not None:
                    payload.reply(key, answer, encoding=ENCODING)  # type: ignore[attr-defined]
            finally:
                payload.drop()  # type: ignore[attr-defined]
        elif tag == "control":
            self.tally.traffic.received(payload)  # type: ignore[arg-type]
            c = check_control(decode(payload, Control, key), key, self.bounds)  # type: ignore[arg-type]
            if c.by != "agent":
                raise WireError(f"{key}: a proposed control must say by='agent', not {c.by!r}")
            now = self.obs is not None and c.t == self.obs.t
            if now:
                check_choice(c, key, candidate_controls(self.city, self.obs, c.agent))  # type: ignore[union-attr]
            if c.epoch != self.epoch:
                raise WireError(f"{key}: a control for run epoch {c.epoch}, this coordinator's is {self.epoch}")
            if now:
                self.health.ack(c.agent, c.t, current)
            if want is not None and (c.t, c.agent) in want:
                return c
            self.tally.stale += 1
        return None

    def _sector_answer(self, key: str) -> bytes | None:
        """The current hour's forecast of the sector a query's key names; ``None`` before the run's first forecast.

        A taxi that joins asks for the sectors it follows at once; before the first minute there is
        nothing to send yet, and the pieces come on its subscriptions when the run begins.
        """
        sector = Keys.agent_of(key)
        if sector is None or not 0 <= sector < self.city.n_sectors:
            raise WireError(f"{key}: a query for the forecast of one sector 0..{self.city.n_sectors - 1}")
        if self.hour_forecast is None:
            return None
        hour, forecast = self.hour_forecast
        return sector_message(forecast, self.city, hour, sector).encode()

    def base_and_home(self, obs: Observation) -> tuple[np.ndarray, np.ndarray]:
        """The minute's base controls and the ``rebalance`` base's targets (:class:`coordinator.minute_base.MinuteBase`)."""
        return self.bases.of(obs, self.hour_forecast)

    def waves(self, obs: Observation) -> Waves:
        """The minute's turns: by the rollout's dependencies, or all at once for a central policy (each answers its own entry)."""
        if not self.central:
            return plan_waves(self.city, obs, self.rollout.prune)
        free = np.flatnonzero(obs.tau == 0)
        return Waves(agents=free, wave=np.zeros(free.size, dtype=np.int64), depends=[np.empty(0, dtype=np.int64) for _ in free])

    def full_state(self) -> bytes:
        obs = self.sim.observe()
        base, home = self.base_and_home(obs)
        return state_message(obs, None, base, self.epoch, home).encode()

    def _snapshot(self) -> Snapshot:
        """The full state (with its base controls) and the hour's forecast: all a (re)joining agent needs (a turn brings its commitments)."""
        return Snapshot(state=self.full_state(), forecast=self.forecast_msg)

    # ------------------------------------------------------------------- run
    def run(self, bus: SessionArgs) -> dict:
        """Play the episode; ``Stop`` goes out on every way out (done, an error, SIGTERM, Ctrl-C), with the reason."""
        with open_session(bus) as session, ExitStack() as stack:
            inbox = Inbox()
            resumed = checkpoint.epoch_of(self.run_dir) if self.resume and self.run_dir is not None else 0
            claimed = claim(session, self.keys, stack, resume=self.resume, takeover=self.takeover, resumed_epoch=resumed)
            self.epoch, fenced = claimed.epoch, claimed.fenced
            if self.run_dir is not None:  # after a takeover, wait for the fenced coordinator to let go of it
                stack.enter_context(checkpoint.locked(self.run_dir, self.cfg.run, self.epoch, TAKEOVER_WAIT_S if fenced else 0.0))
            if self.resume:
                self._restore()  # what the run directory holds now: a fenced coordinator may have played on
                log(f"resuming run {self.cfg.run!r} at minute {self.sim.state.t} from {self.run_dir / checkpoint.CHECKPOINT}")
            pub_stop = publisher(session, self.keys.stop)
            decls = [
                inbox.serve(session, self.keys.spec, "spec"),
                inbox.serve(session, self.keys.snapshot, "snapshot"),
                inbox.serve(session, self.keys.all_forecasts, "forecast"),
                inbox.subscribe(session, self.keys.all_controls, "control"),
                inbox.subscribe(session, self.keys.all_acks, "ack"),
                inbox.watch_liveliness(session, self.keys.all_alive, "alive"),
                inbox.watch_liveliness(session, self.keys.all_coordinators, "coordinator"),
            ]
            if not fenced:  # a takeover's token is out already: it is the fence
                token = session.liveliness().declare_token(self.keys.coordinator(self.epoch))  # once the snapshot it stands for is served
                stack.callback(token.undeclare)
            log(f"run {self.cfg.run!r}: this coordinator is run epoch {self.epoch} (since {epoch_time(self.epoch)})")
            reason: str | None = "the coordinator failed"
            try:
                result = self._run(session, inbox)
                reason = "done"
                return result
            except TakenOver:
                reason = None  # the run goes on under the new coordinator: no stop
                raise
            except SystemExit as exc:
                reason = f"the coordinator was stopped (exit {exc.code})"
                raise
            except KeyboardInterrupt:
                reason = "the coordinator was interrupted"
                raise
            except Exception as exc:
                reason = f"the coordinator failed: {exc}"[:300]
                raise
            finally:
                if reason is not None:
                    stop = Stop(t=self.cfg.minutes if reason == "done" else int(self.sim.state.t), epoch=self.epoch,
                                reason=reason).encode()
                    pub_stop.put(stop)
                    self._see_agents_off(inbox, pub_stop, stop)
                if reason not in ("done", None):
                    log(f"published stop at minute {self.sim.state.t}: {reason}")
                for d in decls:
                    d.undeclare()

    def _see_agents_off(self, inbox: Inbox, pub_stop: Any, stop: bytes) -> None:
        """Put the stop again until every agent's token has gone (each leaves on it), for at most ``STOP_WAIT_S``.

        A put just before the session closes may never leave this process, and an
        agent that missed the stop would wait out its grace period and fail.
        """
        alive = set(self.health.alive)
        now = time.monotonic()
        deadline, resend = now + STOP_WAIT_S, now + STOP_RESEND_S
        while alive and (left := deadline - now) > 0:
            item = inbox.get(timeout=max(0.0, min(left, resend - now)))
            if item is not None and item[0] == "alive" and item[2] is False:
                alive.discard(Keys.agent_of(item[1]))
            now = time.monotonic()
            if now >= resend:  # on a clock, so that a steady stream of other messages cannot hold the re-send back
                pub_stop.put(stop)
                resend = now + STOP_RESEND_S

    def _wait_for_agents(self, inbox: Inbox) -> None:
        deadline = time.monotonic() + self.cfg.join_timeout_s
        alive = self.health.alive
        while len(alive) < self.cfg.taxis:
            left = deadline - time.monotonic()
            if left <= 0:
                missing = sorted(set(range(self.cfg.taxis)) - alive)
                raise ConfigError(f"run {self.cfg.run!r}: {len(alive)} of {self.cfg.taxis} agents joined within "
                                  f"{self.cfg.join_timeout_s:.0f} s; missing {', '.join(map(str, missing[:10]))}")
            item = inbox.get(timeout=min(left, 1.0))
            if item is not None:
                self._handle(item)
        self.running = True
        log(f"all {self.cfg.taxis} agents joined run {self.cfg.run!r}")

    def _run(self, session, inbox: Inbox) -> dict:
        cfg, keys = self.cfg, self.keys
        def counted(pub: Any) -> Counted:  # every message the coordinator sends is counted
            return Counted(pub, self.tally.traffic)

        pub_state = counted(publisher(session, keys.state))
        pub_forecast = ForecastPublisher(session, keys, self.city, wrap=counted) if self.policy is not None and not self.central else None
        turn_pub = {a: counted(publisher(session, keys.turn(a))) for a in range(cfg.taxis)}
        commit_pub = {a: counted(publisher(session, keys.committed(a))) for a in range(cfg.taxis)}
        self._wait_for_agents(inbox)
        joined_at = time.time()
        tally = self.tally
        controls, costs, step_s, plan_s = tally.controls, tally.costs, tally.step_s, tally.plan_s
        planned, fallbacks, rss = tally.planned, tally.fallbacks, tally.rss
        previous = None
        first = int(self.sim.state.t)
        t_start = time.perf_counter()
        with steps(cfg.minutes - first if self.progress else 0, "minute", f"run {cfg.run}") as minutes:
            for t in range(first, cfg.minutes):
                t0 = time.perf_counter()
                if self.health.partitioned():
                    self._partition(inbox, t)  # the clock does not run while most of the fleet is cut off
                obs = self.obs = self.sim.observe()
                if (t % 60 == 0 or t == first) and not self.central:
                    self.forecast_msg = self._forecast(session, inbox, t // 60)
                    self._hold_forecast(pub_forecast, t // 60)
                base, home = self.base_and_home(obs)
                pub_state.put(state_message(obs, previous, base, self.epoch, home).encode())
                previous = np.asarray(obs.req_index)
                u = base.copy()
                waves = self.waves(obs)
                tally.waves.append(self._turns(inbox, turn_pub, commit_pub, t, waves, base, u))
                controls[t] = u
                costs.append(self.sim.step(u))
                step_s.append(time.perf_counter() - t0)
                if self.run_dir is not None:
                    checkpoint.save(self.run_dir, asdict(cfg), self.sim, tally, self.epoch)
                if self.progress:
                    free = int((obs.tau == 0).sum())
                    log(f"minute {t + 1}/{cfg.minutes}: {free} free {'taxi' if free == 1 else 'taxis'} took turns, "
                        f"{costs[-1]} requests waiting ({step_s[-1]:.2f} s)")
                self._pace(inbox, t0 + cfg.minute_s)
                minutes.update()
        res = self.sim.result(costs, controls, step_s)
        from city.scenario import SHARE_ENV

        return {
            "run": cfg.run,
            "policy": cfg.policy,
            "taxis": cfg.taxis,
            "minutes": cfg.minutes,
            "config": asdict(cfg),
            # the demand share the run's world was built with ($SURGE_SHARE; None: the default), for a replay
            "share": float(os.environ[SHARE_ENV]) if os.environ.get(SHARE_ENV) else None,
            "total_cost": res.total_cost,
            "outstanding_end": res.outstanding_end,
            "served": res.served,
            "requests": res.n_requests,
            "decisions_sha256": decisions_hash(controls),
            "fallbacks": int(fallbacks.sum()),
            "planned_per_agent": planned.tolist(),
            "fallbacks_per_agent": fallbacks.tolist(),
            "fallback_turns": tally.fallen,
            "controls": controls.tolist(),
            "stale_messages": tally.stale,
            "rejected_messages": dict(self.rejected.counts),
            "step_seconds": {"median": float(np.median(step_s)), "max": float(np.max(step_s))},
            "minute_seconds": step_s,
            "agent_plan_seconds": {"median": float(np.median(plan_s)) if plan_s else None,
                                   "max": float(np.max(plan_s)) if plan_s else None},
            "agent_peak_rss_mb": float(rss.max()),
            "wall_seconds": time.perf_counter() - t_start,
            "critical_path": [len(w) for w in tally.waves],
            "free_per_minute": [sum(len(wave["agents"]) for wave in w) for w in tally.waves],
            "waves": tally.waves,
            "joined_at": joined_at,
            "traffic": tally.traffic.summary(cfg.minutes),
            "resumed_at_minute": first if first else None,
            "partitions": tally.partitions,
        }

    def _hold_forecast(self, pub: ForecastPublisher | None, hour: int) -> None:
        """Keep the hour's forecast for snapshots and sector queries; publish it sector by sector unless the predictor did."""
        msg = decode(self.forecast_msg, ForecastMsg)
        forecast = Forecast(eta=msg.eta, rho=msg.rho, delta=msg.delta, beta=msg.beta)  # type: ignore[attr-defined]
        self.hour_forecast = (hour, forecast)
        if pub is not None:
            pub.put(forecast, hour)

    def _forecast(self, session, inbox: Inbox, hour: int) -> bytes:
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


def coordinator_main(config: FleetConfig, bus: SessionArgs, result_path: str | None = None, run_dir: str | None = None,
                     resume: bool = False, takeover: bool = False) -> dict:
    """Run the coordinator (checkpointing to ``run_dir``, resuming from it); with ``result_path``, write the result there as JSON.

    ``takeover`` fences a live coordinator of the same run instead of refusing to start.
    """
    import json

    result = Coordinator(config, run_dir=run_dir, resume=resume, takeover=takeover).run(bus)
    if result_path is not None:
        Path(result_path).write_text(json.dumps(result, indent=1))
    return result

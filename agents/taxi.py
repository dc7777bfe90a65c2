"""One taxi as its own process on the bus: it follows the state, waits for its turn and plans its own control.

The agent fetches the run's :class:`~bus.wire.RunSpec` from the coordinator,
builds the static city once (from its on-disk cache) and refuses to join if
its city's content hash is not the spec's; then it reacts to what arrives:
states and the forecasts of the sectors it follows
(:mod:`agents.sector_forecasts`) update its copy of the world, and a
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

Faults (:mod:`coordinator.faults` has the coordinator's side): the agent
takes a snapshot before it declares its token, so a rejoining agent holds
the minute's state when its turn comes (the turn brings the commitments).
It acknowledges each minute's state (:class:`~bus.wire.Ack`), which is how
a suspect agent gets waited for again.  It watches the coordinator's token:
when the token comes back (a restarted router, a resumed coordinator) it
takes a snapshot, since what was published meanwhile is lost; when the
token has been gone longer than the grace period it leaves, in one line.  A turn it cannot start for
want of its minute's state, or one it already answered, tells it what was
lost: it takes a snapshot, or sends its control again.

Fencing: every state, turn and stop carries its coordinator's run epoch, and
each coordinator holds the token ``coordinator/<epoch>``.  The agent follows
the highest epoch it has seen and drops whatever comes from a lower one, so
a coordinator that another took over (``--takeover``) steers nothing; its
control answers a turn with the turn's epoch.

This module must not import torch: forecasts arrive on the bus.
"""

from __future__ import annotations

import dataclasses
import logging
import resource
import time
from dataclasses import dataclass

import numba
import numpy as np

from agents.cores import CoreShare
from agents.kernel_threads import set_kernel_threads
from agents.rollout import (
    StepContext,
    plan_agent,
    prepare_step,
    warm_up,
)
from agents.rollout_inputs import candidate_controls
from agents.sector_forecasts import AgentForecasts, needed_sectors
from agents.taxi_join import Joining, log
from bus.checks import (
    Bounds,
    Rejections,
    check_choice,
    check_state,
    check_stop,
    check_turn,
)
from bus.delta import StateView
from bus.keys import Keys
from bus.session import Inbox, SessionArgs, open_session, publisher
from bus.wire import (
    Ack,
    Control,
    ForecastMsg,
    Snapshot,
    State,
    Stop,
    Turn,
    WireError,
    decode,
)
from city.errors import ConfigError, SurgeError
from city.logs import inherit


@dataclass(frozen=True)
class AgentConfig:
    """One agent process: which taxi, which run, how to reach the bus."""

    index: int
    run: str
    bus: SessionArgs
    join_timeout_s: float = 120.0
    #: This host's data directory for real maps, when it is not where the coordinator has it.
    data_dir: str | None = None
    #: Seconds to wait for a vanished coordinator (a restart, a resume) before leaving.
    grace_s: float = 30.0
    #: Threads of this agent's rollout kernel: ``"share"`` (the host's cores split among the agents of
    #: the run planning on it at the time, :mod:`agents.cores`), ``"all"`` (every core) or a number.
    threads: int | str = "share"


class CoordinatorGone(SurgeError):
    """The coordinator's token has been gone for longer than the grace period."""


#: Seconds a turn may wait for its minute's state before the agent takes a snapshot.
STALL_S = 1.0
#: Seconds the coordinator's token must stay gone before the agent says so: at a normal end the token
#: may vanish a moment before the run's ``Stop`` arrives (they travel on different paths).
GONE_NOTICE_S = 1.0


class TaxiAgent(Joining):
    """The event loop of one taxi; see the module docstring."""

    def __init__(self, config: AgentConfig) -> None:
        self.cfg = config
        self.keys = Keys(config.run)
        self.me = config.index
        self.view = StateView()
        #: Set by the accepted run spec, with the city.
        self.forecasts: AgentForecasts
        self.pending: Turn | None = None
        #: The minute whose turn made this taxi ask the coordinator for missing forecast pieces (once a turn).
        self.asked: int | None = None
        self.context: StepContext | None = None
        #: Whether the view is a snapshot taken before the coordinator held its minute's forecast: its base controls are
        #: stand-ins (every free taxi stays) until the minute's published state replaces them, and no turn is planned on it.
        self.provisional = False
        self.decisions = 0
        #: Whether the run's policy is computed by the coordinator (:attr:`agents.base.Policy.central`); set by the spec.
        self.central = False
        self.rejected = Rejections(lambda m: log(self.me, m))
        self._cities: dict[tuple[str, str | None], object] = {}
        #: The last control this agent sent, and its predecessors' controls it was planned with: a repeated turn gets it again.
        self.sent: Control | None = None
        self.sent_with = np.empty(0, dtype=np.int32)
        #: Publisher of this agent's acks (``None`` without a bus).
        self.ack_pub = None
        #: Since when the coordinator's token is missing (monotonic seconds; ``None``: present, or not watched).
        self.coordinator_gone: float | None = None
        self.coordinator_seen = False
        #: Whether the coordinator's current absence has been logged.
        self.gone_logged = False
        #: The highest run epoch seen (a coordinator's token, state, turn or stop): lower ones are fenced.
        self.epoch = 0
        #: The run epochs whose coordinator tokens are present.
        self.live: set[int] = set()
        #: Since when the pending turn waits for its state.
        self.stalled: float | None = None
        #: This host's cores, shared with the run's other agents planning at the same time (``threads="share"``).
        self.share: CoreShare | None = None
        if isinstance(config.threads, int):
            set_kernel_threads(config.threads)
        elif config.threads == "share":
            self.share = CoreShare(config.run, numba.config.NUMBA_NUM_THREADS)
        elif config.threads != "all":
            raise ConfigError(f"agent threads: {config.threads!r} is not 'share', 'all' or a number")

    def run(self) -> int:
        """Join the run and plan until it stops; the number of controls this agent planned."""
        with open_session(self.cfg.bus) as session:
            inbox = Inbox()
            subs = [
                inbox.subscribe(session, self.keys.state, "state"),
                inbox.subscribe(session, self.keys.dropoffs, "dropoffs"),
                inbox.subscribe(session, self.keys.turn(self.me), "turn"),
                inbox.subscribe(session, self.keys.stop, "stop"),
            ]
            spec = self._fetch_spec(session)
            self.bounds = Bounds(taxis=spec.taxis, nodes=self.city.n_nodes, sectors=self.city.n_sectors, minutes=spec.minutes)
            self.forecasts.attach(session, inbox, self.keys)
            self._warm_up()
            out = publisher(session, self.keys.control(self.me))
            self.ack_pub = publisher(session, self.keys.ack(self.me))
            self.coordinator_gone = time.monotonic()  # until its token is seen
            subs.append(inbox.watch_liveliness(session, self.keys.all_coordinators, "coordinator"))
            self._snapshot(session)  # before the token: a rejoining agent holds the minute when its turn comes
            token = session.liveliness().declare_token(self.keys.alive(self.me))
            log(self.me, f"joined run {spec.run!r} ({spec.policy}, {spec.taxis} taxis)")
            try:
                self._loop(session, inbox, out)
            finally:
                token.undeclare()
                self.forecasts.close()
                if self.share is not None:
                    self.share.close()
                for s in subs:
                    s.undeclare()
        return self.decisions

    def _warm_up(self) -> None:
        """Load (or build) the compiled kernels before joining, so that a fresh checkout's first turn is not late."""
        if not self.central:
            warm_up(self.city, self.rollout)

    def _snapshot(self, session) -> None:
        """Take the coordinator's snapshot: the full state, with its base controls, and the hour's forecast."""
        key = self.keys.snapshot
        for reply in session.get(key, timeout=5.0):
            if reply.ok is None:
                continue
            try:
                snap = decode(reply.ok.payload.to_bytes(), Snapshot, key)
                state = check_state(decode(snap.state, State, key), key, self.bounds)  # type: ignore[arg-type]
                self._current(state.epoch, key, "snapshot")
                if not state.full:
                    raise WireError(f"{key}: a snapshot's state must be full")
                forecast = decode(snap.forecast, ForecastMsg, key) if snap.forecast else None  # none before the run's first minute
                if forecast is not None:
                    self._on_forecast(forecast)  # type: ignore[arg-type]
            except Exception as exc:  # a bad snapshot: drop it, try the next answer
                self.rejected.exception("snapshot", key, exc)
                continue
            self.view.apply(state)
            self.context = None
            self.provisional = not self.central and (forecast is None or forecast.hour != state.t // 60)  # type: ignore[attr-defined]
            self._follow()
            self._ack()
            return

    def _ack(self) -> None:
        """Tell the coordinator which minute this agent holds."""
        if self.ack_pub is not None and self.view.obs is not None:
            self.ack_pub.put(Ack(t=int(self.view.obs.t), agent=self.me).encode())

    def _on_forecast(self, msg: ForecastMsg) -> None:
        self.forecasts.on_whole(msg, self.keys.snapshot)

    def _follow(self) -> None:
        """Follow the sectors this taxi plans in next: where it is, or where it is free again when busy."""
        obs = self.view.obs
        if obs is None or self.central:
            return
        node = int(obs.pos[self.me]) if obs.tau[self.me] == 0 or obs.dest[self.me] < 0 else int(obs.dest[self.me])
        self.forecasts.forget_before(int(obs.t) // 60)
        self.forecasts.follow(needed_sectors(self.city, self.rollout, node), int(obs.t) // 60)

    def _minute(self) -> int | None:
        return None if self.view.obs is None else int(self.view.obs.t)

    def _current(self, epoch: int, key: str, what: str) -> None:
        """Drop a message of a fenced coordinator (an epoch below the highest seen); a higher epoch is followed from now on."""
        if epoch < self.epoch:
            raise WireError(f"{key}: a {what} of run epoch {epoch}, whose coordinator was taken over by epoch {self.epoch}")
        self.epoch = epoch

    def handle(self, session, tag: str, key: str, payload: bytes) -> bool:
        """Check and apply one message; ``False`` when it is the run's stop."""
        if tag == "stop":
            stop = check_stop(decode(payload, Stop, key), key, self.bounds)  # type: ignore[arg-type]
            self._current(stop.epoch, key, "stop")
            if stop.reason != "done":
                log(self.me, f"the coordinator ended the run at minute {stop.t}: {stop.reason}")
            return False
        if tag == "coordinator":
            self._on_coordinator(session, key, bool(payload))
            return True
        if tag == "state":
            msg = check_state(decode(payload, State, key), key, self.bounds)  # type: ignore[arg-type]
            self._current(msg.epoch, key, "state")
            if self.view.apply(msg):
                self.provisional = False
                self._follow()
                self._ack()
            else:
                self._snapshot(session)
            self.context = None
        elif tag == "forecast":
            self.forecasts.on_sector(payload, key)
        elif tag == "dropoffs":
            self.forecasts.on_dropoffs(payload, key)
        elif tag == "turn":
            turn = decode(payload, Turn, key)
            self._current(turn.epoch, key, "turn")  # type: ignore[attr-defined]
            minute = self._minute()
            if minute is not None and max(0, minute - 60) <= turn.t < minute and turn.agent == self.me:  # type: ignore[attr-defined]
                return True  # a turn of a minute the run has left behind (queued while this agent was stopped)
            self.pending = check_turn(turn, key, self.me, self.bounds, minute)  # type: ignore[arg-type]
        return True

    def _on_coordinator(self, session, key: str, present: bool) -> None:
        """A coordinator's token came or went.

        The coordinator is present while a token of the highest epoch seen is.
        When it comes back, or a higher epoch takes the run over, what was
        published meanwhile is lost or fenced: take a snapshot.
        """
        epoch = Keys.agent_of(key)
        if epoch is None:
            raise WireError(f"{key}: a coordinator token without a run epoch")
        (self.live.add if present else self.live.discard)(epoch)
        if epoch < self.epoch:
            return  # a fenced coordinator's token
        newer = present and epoch > self.epoch
        if newer and self.coordinator_seen:
            log(self.me, f"the coordinator of run epoch {epoch} took the run over from epoch {self.epoch}; "
                         f"the older one's messages are dropped from now on")
        if present:
            self.epoch = epoch
        here = any(e >= self.epoch for e in self.live)
        if not self.coordinator_seen:
            self.coordinator_seen, self.coordinator_gone = here, None if here else self.coordinator_gone
            return
        if not here:
            if self.coordinator_gone is None:
                self.coordinator_gone, self.gone_logged = time.monotonic(), False
            return
        was_gone, self.coordinator_gone = self.coordinator_gone, None
        if was_gone is not None and self.view.obs is not None:
            log(self.me, f"the coordinator is back after {time.monotonic() - was_gone:.1f} s; taking a snapshot")
        if (was_gone is not None or newer) and self.view.obs is not None:
            self._snapshot(session)

    def _check_health(self, session) -> None:
        """Leave when the coordinator is gone past the grace period; take a snapshot when a turn is stuck on something lost."""
        now = time.monotonic()
        if self.coordinator_seen and self.coordinator_gone is not None and not self.gone_logged \
                and now - self.coordinator_gone > GONE_NOTICE_S:
            self.gone_logged = True
            log(self.me, f"the coordinator's token is gone; waiting up to {self.cfg.grace_s:g} s in all for it to return")
        if self.coordinator_gone is not None and now - self.coordinator_gone > self.cfg.grace_s:
            raise CoordinatorGone(f"the coordinator of run {self.cfg.run!r} has been gone for more than {self.cfg.grace_s:g} s "
                                  f"(the grace period); leaving")
        if self.pending is None:
            self.stalled = None
        elif self.stalled is None:
            self.stalled = now
        elif now - self.stalled > STALL_S and self.coordinator_gone is None:
            self.stalled = now
            self._snapshot(session)

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
            check_choice(Control(t=turn.t, agent=a, control=c, epoch=turn.epoch), key, candidate_controls(self.city, obs, a))
            committed[a] = c
        return committed

    def _loop(self, session, inbox: Inbox, out) -> None:
        while True:
            self._check_health(session)
            item = inbox.get(timeout=0.25)
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
        if obs is None or obs.tau[self.me] > 0 or self.central or self.provisional:
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
            self.context = prepare_step(self.city, self.rollout, obs, tables, obs.t % 60, base=self.view.base, home=self.view.home)

    def _maybe_plan(self, out) -> None:
        turn, obs = self.pending, self.view.obs
        if turn is not None and turn.epoch < self.epoch:
            self.pending = None  # a turn of a coordinator taken over since it came
            return
        if turn is not None and obs is not None and turn.t < obs.t:
            self.pending = None  # the run has moved on without this agent's answer
            return
        if turn is None or obs is None or obs.t != turn.t:
            return
        if not self.central and (self.context is None or self.context.obs.t != turn.t):
            return
        self.pending = None  # a turn is planned, answered again, or dropped, once
        committed = np.empty(0, dtype=np.int32) if self.central else self._predecessors(turn)
        if self.sent is not None and self.sent.t == turn.t and np.array_equal(self.sent_with, committed):
            # a repeated turn, with the same predecessors (perhaps from a coordinator that took over): the first answer may have been lost
            out.put(dataclasses.replace(self.sent, epoch=turn.epoch).encode())
            return
        t0 = time.perf_counter()
        if self.central:
            control = int(self.view.base[self.me])  # the coordinator computed the joint control; this taxi's entry is its own
        elif self.share is None:
            control = plan_agent(self.context, committed, self.me)
        else:
            with self.share.planning():
                control = plan_agent(self.context, committed, self.me, threads=self.share.threads)
        plan_s = time.perf_counter() - t0
        rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        self.sent = Control(t=turn.t, agent=self.me, control=int(control), epoch=turn.epoch, plan_s=plan_s, rss_mb=rss_mb)
        self.sent_with = committed
        out.put(self.sent.encode())
        self.decisions += 1


def agent_main(config: AgentConfig) -> int:
    """Entry point of a spawned agent process: run, and report failures as one line."""
    inherit()
    try:
        TaxiAgent(config).run()
    except SurgeError as exc:
        log(config.index, str(exc), logging.ERROR)
        return 2
    except KeyboardInterrupt:
        return 130
    return 0

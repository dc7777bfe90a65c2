"""The coordinator's minute without a bus: who is healthy, which turns it waits for, and when the turns go out."""

from __future__ import annotations

import time

import numpy as np
import pytest

from bus.session import Inbox
from coordinator.faults import Health

pytestmark = pytest.mark.usefixtures("compiled_kernels")


def test_health_tells_a_partition_from_single_departures() -> None:
    said: list[str] = []
    h = Health(4, said.append)
    for a in range(4):
        h.token(a, True, running=False)
    h.token(3, False, running=True)
    assert not h.partitioned() and said == ["agent 3 left"]
    h.departed[3] -= 60  # long gone: not one of the partition's
    h.token(2, False, running=True)
    assert not h.partitioned()
    h.token(1, False, running=True)
    assert h.partitioned() and h.partition() == {0, 1, 2}
    assert h.healed({0, 1, 2}, 5) == (False, False)
    h.token(1, True, running=True)
    h.token(2, True, running=True)
    assert h.healed({0, 1, 2}, 5) == (True, False)
    for a in (0, 1, 2):
        h.ack(a, 5, current=5)
    assert h.healed({0, 1, 2}, 5) == (True, True) and "agent 1 is back" in said
    sent = time.monotonic()
    assert not h.lost_since(1, sent) and h.lost_since(3, sent)  # 1 is back from before the turn went out; 3 is gone
    h.token(1, False, running=True)
    h.token(1, True, running=True)
    assert h.lost_since(1, sent) and not h.lost_since(1, time.monotonic())  # it left after: the turn went with it
    h.missed({2}, 6, 1.5)
    h.ack(2, 5, current=6)
    assert 2 in h.suspect
    h.ack(2, 6, current=6)
    assert 2 not in h.suspect and said[-1] == "agent 2 acknowledged minute 6; its turns are waited for again"


def _turn_rig(taxis: int, deadline_s: float):
    """A coordinator without a bus, and publishers that log the turns and commits it sends, in order."""
    from bus.wire import Control, Turn, decode
    from coordinator.run_config import FleetConfig
    from coordinator.runtime import Coordinator

    cfg = FleetConfig(run="w", taxis=taxis, minutes=2, deadline_s=deadline_s, options={"forecast": "true-rate", "samples": 4})
    coord = Coordinator(cfg, progress=False)
    coord.obs = coord.sim.observe()
    coord.health.alive = set(range(taxis))
    events: list[tuple[str, object]] = []

    class Pub:
        def __init__(self, kind: str, cls: type) -> None:
            self.kind, self.cls = kind, cls

        def put(self, payload: bytes) -> None:
            events.append((self.kind, decode(payload, self.cls)))

    turns = {a: Pub("turn", Turn) for a in range(taxis)}
    commits = {a: Pub("commit", Control) for a in range(taxis)}
    return coord, turns, commits, events


def test_a_turn_waits_for_its_live_dependencies_only_and_resends_unanswered_turns(capsys: pytest.CaptureFixture) -> None:
    """Three independent agents: agent 1 answers at once, agent 2 is suspect (its turn is sent, not waited for), agent 0 is hung."""
    from agents.rollout_inputs import candidate_controls
    from agents.waves import Waves
    from bus.wire import Control
    from coordinator import faults

    coord, turns, commits, events = _turn_rig(3, faults.RESEND_S + 0.5)
    coord.health.suspect = {2}
    none = np.zeros(0, dtype=np.int64)
    waves = Waves(agents=np.array([0, 1, 2]), wave=np.zeros(3, dtype=np.int64), depends=[none, none, none])
    base = np.array([7, 8, 9], dtype=np.int32)
    ok = int(candidate_controls(coord.city, coord.obs, 1)[0])
    inbox = Inbox()
    inbox.put("control", coord.keys.control(1), Control(t=0, agent=1, control=ok, epoch=0).encode())
    u = base.copy()
    out = coord._turns(inbox, turns, commits, 0, waves, base, u)
    assert [(k, m.agent) for k, m in events if k == "turn"] == [("turn", 0), ("turn", 1), ("turn", 2), ("turn", 0)]  # 0 again after RESEND_S
    committed = {m.agent: (m.control, m.by) for k, m in events if k == "commit"}
    assert committed == {0: (7, "base"), 1: (ok, "agent"), 2: (9, "base")} and u.tolist() == [7, ok, 9]
    assert coord.health.suspect == {0, 2} and coord.tally.fallbacks.tolist() == [1, 0, 1]
    assert capsys.readouterr().err.count("silent for") == 1
    assert len(out) == 1 and out[0]["agents"] == [0, 1, 2] and out[0]["plan_s"][0] is None and out[0]["seconds"] >= faults.RESEND_S


def test_a_turn_goes_out_once_its_dependencies_commit_without_waiting_for_their_wave() -> None:
    """Agent 1 depends on agent 0 only: its turn, with 0's control, goes out before agent 2 of 0's wave answers."""
    from agents.rollout_inputs import candidate_controls
    from agents.waves import Waves
    from bus.wire import Control

    coord, turns, commits, events = _turn_rig(3, 5.0)
    waves = Waves(agents=np.array([0, 1, 2]), wave=np.array([0, 1, 0]),
                  depends=[np.zeros(0, dtype=np.int64), np.array([0]), np.zeros(0, dtype=np.int64)])
    pick = {a: int(candidate_controls(coord.city, coord.obs, a)[-1]) for a in range(3)}
    inbox = Inbox()
    for a in range(3):
        inbox.put("control", coord.keys.control(a), Control(t=0, agent=a, control=pick[a], epoch=0).encode())
    u = np.full(3, -5, dtype=np.int32)
    out = coord._turns(inbox, turns, commits, 0, waves, u.copy(), u)
    assert [(k, m.agent) for k, m in events] == [("turn", 0), ("turn", 2), ("commit", 0), ("turn", 1), ("commit", 1), ("commit", 2)]
    turn1 = next(m for k, m in events if k == "turn" and m.agent == 1)
    assert turn1.deps.tolist() == [0] and turn1.controls.tolist() == [pick[0]]
    assert u.tolist() == [pick[0], pick[1], pick[2]] and coord.tally.fallbacks.sum() == 0
    assert [w["agents"] for w in out] == [[0, 2], [1]] and all(w["seconds"] >= 0 for w in out)


def test_the_stop_is_put_again_on_a_clock_while_other_messages_keep_coming() -> None:
    import threading

    from coordinator.run_config import FleetConfig
    from coordinator.runtime import STOP_RESEND_S, Coordinator

    coord = Coordinator(FleetConfig(run="w", taxis=2, minutes=1, options={"forecast": "true-rate"}), progress=False)
    coord.health.alive = {0, 1}
    inbox, puts = Inbox(), []

    class Pub:
        def put(self, payload: bytes) -> None:
            puts.append(time.monotonic())

    def chatter() -> None:  # a message every 20 ms, never a quiet spell of STOP_RESEND_S, then both agents leave
        end = time.monotonic() + 6 * STOP_RESEND_S
        while time.monotonic() < end:
            inbox.put("state", coord.keys.state, b"")
            time.sleep(0.02)
        for a in (0, 1):
            inbox.put("alive", coord.keys.alive(a), False)

    feeder = threading.Thread(target=chatter)
    t0 = time.monotonic()
    feeder.start()
    coord._see_agents_off(inbox, Pub(), b"stop")
    feeder.join()
    assert 4 <= len(puts) <= 8 and puts[0] - t0 < 2 * STOP_RESEND_S
    assert time.monotonic() - t0 < 10 * STOP_RESEND_S  # it left once both tokens had gone

"""Hostile clients for tests/bus/test_security.py: an outsider's program that uses only zenoh and msgpack.

``python tests/bus/hostile.py probe|attack JSON`` prints one JSON line with what
it saw (``attack`` also prints ``fuzzed N`` once its fuzz is sent).  It
imports nothing from surge: it is what someone with a stolen (or no)
certificate could run against a fleet.
"""

from __future__ import annotations

import json
import math
import queue
import random
import sys
import time

import msgpack
import zenoh


def config(endpoint: str, certs: str | None = None, name: str | None = None, ca: str | None = None) -> zenoh.Config:
    """A client config: ``name``'s certificate from ``certs`` (none: TLS without a client certificate)."""
    c = zenoh.Config()
    c.insert_json5("mode", '"client"')
    c.insert_json5("connect/endpoints", json.dumps([endpoint]))
    c.insert_json5("scouting/multicast/enabled", "false")
    if endpoint.startswith("tls/"):
        tls = {"root_ca_certificate": ca or f"{certs}/ca.pem"}
        if name is not None:
            tls.update(connect_certificate=f"{certs}/{name}.pem", connect_private_key=f"{certs}/{name}.key", enable_mtls=True)
        c.insert_json5("transport/link/tls", json.dumps(tls))
    return c


def try_open(conf: zenoh.Config):
    try:
        return zenoh.open(conf)
    except Exception:  # refused: what the tests expect of most identities
        return None


#: The wire version of docs/PROTOCOL.md: what an outsider writes from the document.
WIRE = 4


def control(t: int, agent: int, value: int, **extra) -> bytes:
    return msgpack.packb({"v": WIRE, "kind": "control", "t": t, "agent": agent, "control": value, "epoch": 0, "by": "agent",
                          "plan_s": 0.0, "rss_mb": 0.0, **extra}, use_bin_type=True)


# ------------------------------------------------------------------ probe
def probe(a: dict) -> dict:
    """Each forbidden act of taxi 3 (and control/3, ack/3 from every other identity) against observers with the roles' certificates."""
    ep, certs, root = a["endpoint"], a["certs"], f"surge/{a['run']}"
    out: dict = {"connects": {}, "seen": [], "answers": {}}
    out["connects"]["no-cert"] = try_open(config(ep, certs)) is not None
    out["connects"]["plain-tcp"] = try_open(config(a["tcp_endpoint"])) is not None
    out["connects"]["rogue-ca-taxi-3"] = try_open(config(ep, a["rogue"], "taxi-3", ca=f"{certs}/ca.pem")) is not None
    out["connects"]["router-cert"] = try_open(config(ep, certs, "router")) is not None
    s = {n: zenoh.open(config(ep, certs, n)) for n in ("coordinator", "predictor", "taxi-0", "taxi-3", "taxi-4")}
    seen: queue.SimpleQueue = queue.SimpleQueue()

    def watch(who: str):
        return lambda sample: seen.put((who, str(sample.key_expr), sample.payload.to_bytes().decode(errors="replace")))

    def answer(text: str):
        return lambda q: (q.reply(q.key_expr, text.encode()), q.drop())

    co, t0, t3, t4, pr = s["coordinator"], s["taxi-0"], s["taxi-3"], s["taxi-4"], s["predictor"]
    keep = [co.declare_subscriber(f"{root}/control/*", watch("coordinator")),
            co.declare_subscriber(f"{root}/ack/*", watch("coordinator")),
            t0.liveliness().declare_subscriber(f"{root}/coordinator/*", lambda x: seen.put(("taxi-0", str(x.key_expr), "token")),
                                               history=True),
            co.liveliness().declare_subscriber(f"{root}/alive/*", lambda x: seen.put(("coordinator", str(x.key_expr), "token")),
                                               history=True),
            co.declare_queryable(f"{root}/spec", answer("coordinator")),
            co.declare_queryable(f"{root}/snapshot", answer("coordinator")),
            pr.declare_queryable(f"{root}/predictor", answer("predictor")),
            t4.declare_subscriber(f"{root}/turn/4", watch("taxi-4"))]
    keep += [t0.declare_subscriber(f"{root}/{k}", watch("taxi-0")) for k in ("state", "forecast/0", "dropoffs", "committed/*", "stop", "turn/0")]
    keep += [t3.declare_queryable(f"{root}/{k}", answer("forged")) for k in ("spec", "snapshot", "predictor", "forecast/0")]
    keep.append(co.declare_queryable(f"{root}/forecast/*", answer("coordinator")))
    keep += [t3.liveliness().declare_token(f"{root}/alive/4"), t3.liveliness().declare_token(f"{root}/alive/3"),
             t3.liveliness().declare_token(f"{root}/coordinator/9")]
    time.sleep(1.0)
    for k in ("control/4", "ack/4", "committed/0", "committed/3", "state", "forecast/0", "dropoffs", "turn/0", "turn/4", "stop"):
        t3.put(f"{root}/{k}", f"forged by taxi-3 on {k}".encode())
    others = {n: zenoh.open(config(ep, certs, n)) for n in ("coordinator", "predictor", "taxi-0", "taxi-4")}  # not the observers:
    time.sleep(0.5)  # a session delivers its own puts to itself without the router
    for name, other in others.items():
        other.put(f"{root}/control/3", f"forged by {name} on control/3".encode())
        other.put(f"{root}/ack/3", f"forged by {name} on ack/3".encode())
    t3.put(f"{root}/control/3", b"taxi-3 on its own key")
    t3.put(f"{root}/ack/3", b"taxi-3 acks on its own key")
    co.put(f"{root}/state", b"the coordinator's state")
    deadline = time.monotonic() + 15
    got = []
    while time.monotonic() < deadline:
        try:
            got.append(seen.get(timeout=0.2))
        except queue.Empty:
            if {"taxi-3 on its own key", "taxi-3 acks on its own key", "the coordinator's state"} <= {g[2] for g in got}:
                break
    time.sleep(1.0)  # anything still in flight from the forbidden acts
    while not seen.empty():
        got.append(seen.get())
    out["seen"] = got
    real = co.liveliness().declare_token(f"{root}/coordinator/1")  # the observer hears the coordinator's own token
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and "coordinator token" not in out:
        try:
            if seen.get(timeout=0.2)[1].endswith("/coordinator/1"):
                out["coordinator token"] = "seen"
        except queue.Empty:
            pass
    real.undeclare()
    for who, k in (("taxi-0", "spec"), ("taxi-0", "snapshot"), ("coordinator", "predictor"), ("taxi-4", "spec"), ("taxi-0", "forecast/0")):
        replies = s[who].get(f"{root}/{k}", timeout=3.0)
        out["answers"][f"{who} {k}"] = sorted(r.ok.payload.to_bytes().decode() for r in replies if r.ok is not None)
    del keep
    for x in [*s.values(), *others.values()]:
        x.close()
    return out


# ----------------------------------------------------------------- attack
def junk(rng: random.Random, depth: int = 0):
    """A random msgpack-able value."""
    pick = rng.randrange(8 if depth < 3 else 5)
    if pick == 0:
        return rng.randrange(-2**63, 2**63)
    if pick == 1:
        return rng.choice([0.0, -1.0, math.nan, math.inf, 1e308, rng.random()])
    if pick == 2:
        return rng.randbytes(rng.randrange(0, 64))
    if pick == 3:
        return "".join(rng.choice("abc/kindtv{}0") for _ in range(rng.randrange(0, 12)))
    if pick == 4:
        return rng.choice([None, True, False])
    if pick == 5:
        return [junk(rng, depth + 1) for _ in range(rng.randrange(0, 5))]
    keys = ["v", "kind", "t", "agent", "control", "by", "plan_s", "rss_mb", "pos", "x"]
    return {rng.choice(keys): junk(rng, depth + 1) for _ in range(rng.randrange(0, 6))}


def fuzz_payload(rng: random.Random, agent: int, now: int, epoch: int) -> bytes:
    """Random structure, or a well-formed control whose values are out of range for the receiver."""
    kind = rng.randrange(4)
    if kind == 0:
        return rng.randbytes(rng.randrange(0, 200))
    if kind == 1:
        return msgpack.packb(junk(rng), use_bin_type=True)
    if kind == 2:  # well-formed, the right minute and agent, a control that no taxi has
        return control(now, agent, rng.choice([-2**40, -5, -2, 2**31 - 1, 2**40, 10**6]), epoch=epoch)
    fields = {"t": rng.choice([now, -1, 10**9, 2**40]), "agent": rng.choice([agent, agent + 1, -1, 2**31, 99]),
              "control": rng.choice([-7, 2**40, 10**6]), "by": rng.choice(["agent", "base", "x"]),
              "plan_s": rng.choice([0.0, -1.0, math.nan, math.inf]), "rss_mb": rng.choice([0.0, 1e300, -3.0]),
              "epoch": rng.choice([epoch, epoch, epoch - 1, -1, 2**64 - 1])}
    return msgpack.packb({"v": rng.choice([2, 3, 3, 4]), "kind": rng.choice(["control", "control", "turn"]), **fields},
                         use_bin_type=True)


def attack(a: dict) -> dict:
    """Answer taxi 3's turns with "stay" from every identity but taxi 3's, while fuzzing every key a taxi may write."""
    ep, certs, root, victim = a["endpoint"], a["certs"], f"surge/{a['run']}", a["victim"]
    rng = random.Random(a.get("seed", 0))
    inbox: queue.SimpleQueue = queue.SimpleQueue()
    out: dict = {"connects": {"no-cert": try_open(config(ep, certs)) is not None,
                              "router-cert": try_open(config(ep, certs, "router")) is not None},
                 "forged": {}, "turns_seen": {}, "fuzzed": 0, "fuzz_controls": 0}
    sessions = {n: zenoh.open(config(ep, certs, n)) for n in sorted(set(a["attackers"]) | set(a["fuzzers"]))}
    keep = []
    for name in a["attackers"]:
        s = sessions[name]
        out["forged"][name] = out["turns_seen"][name] = 0
        for k in ("state", f"turn/{victim}", "committed/*", "stop"):
            keep.append(s.declare_subscriber(f"{root}/{k}", lambda x, n=name: inbox.put((n, str(x.key_expr), x.payload.to_bytes()))))
    block = zenoh.CongestionControl.BLOCK
    pubs = {n: sessions[n].declare_publisher(f"{root}/control/{int(n.split('-')[1])}", congestion_control=block) for n in a["fuzzers"]}
    forge = {n: sessions[n].declare_publisher(f"{root}/control/{victim}", congestion_control=block) for n in a["attackers"]}
    now, stay, stopped, answered = 0, 0, False, set()
    # the run epoch, as a taxi learns it: from the coordinator's token (and then from every state)
    tokens = sessions[a["fuzzers"][0]].liveliness().get(f"{root}/coordinator/*", timeout=5.0)
    epoch = max([int(str(r.ok.key_expr).rsplit("/", 1)[1]) for r in tokens if r.ok is not None], default=0)

    def forge_all(t: int) -> None:
        for n, p in forge.items():
            p.put(control(t, victim, stay, epoch=epoch))
            out["forged"][n] += 1

    def drain() -> None:
        nonlocal now, stay, epoch, stopped
        while True:
            try:
                who, k, payload = inbox.get_nowait()
            except queue.Empty:
                return
            if k.endswith("/stop"):
                stopped = True
                continue
            msg = msgpack.unpackb(payload)
            if k.endswith("/state"):
                now, epoch = msg["t"], msg["epoch"]
                stay = int.from_bytes(msg["pos"][4 * victim: 4 * victim + 4], "little", signed=True)
                if now not in answered:  # each attacker hears each state: answer a minute once
                    answered.add(now)
                    for name, pub in pubs.items():  # on time whatever the flood's backlog: a control no taxi has, this minute
                        pub.put(control(now, int(name.split("-")[1]), 10**6, epoch=epoch))
                        out["fuzz_controls"] += 1
            elif "/turn/" in k:
                out["turns_seen"][who] += 1
            forge_all(msg["t"])  # on every state, turn and commitment: before taxi 3 can answer

    deadline = time.monotonic() + a["max_s"]
    t0 = time.monotonic()
    while out["fuzzed"] < a["fuzz"] and time.monotonic() < deadline:
        drain()
        forge_all(now)
        for name in a["fuzzers"]:
            s, me = sessions[name], int(name.split("-")[1])
            for _ in range(25):
                roll = rng.random()
                if roll < 0.85:
                    pubs[name].put(fuzz_payload(rng, me, now, epoch))
                    out["fuzz_controls"] += 1
                elif roll < 0.95:
                    s.get(f"{root}/{rng.choice(['spec', 'snapshot'])}", payload=fuzz_payload(rng, me, now, epoch), timeout=1.0)
                else:
                    s.liveliness().declare_token(f"{root}/alive/{me}").undeclare()
                out["fuzzed"] += 1
    out["fuzz_s"] = time.monotonic() - t0
    print(f"fuzzed {out['fuzzed']}", flush=True)
    while not stopped and time.monotonic() < deadline:
        drain()
        forge_all(now)
        time.sleep(0.02)
    del keep
    for s in sessions.values():
        s.close()
    return out


if __name__ == "__main__":
    args = json.loads(sys.argv[2])
    print(json.dumps(probe(args) if sys.argv[1] == "probe" else attack(args)), flush=True)

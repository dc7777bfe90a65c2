"""A third party's observer of a surge run, written from docs/PROTOCOL.md alone: zenoh and msgpack, nothing of surge.

usage: outside_client.py ENDPOINT RUN OUT.json [CERTS_DIR IDENTITY]

It asks for the run's spec, follows every minute's state (rebuilding the
outstanding requests from the deltas, asking for a snapshot after a gap),
notes every committed control, checks that each free taxi's committed move
is where the next state puts it, and writes what it saw when the run stops.
"""

import json
import sys
import time

import msgpack
import zenoh

WIRE = 4
ENCODING = "application/msgpack"


def session_config(endpoint: str, certs: str | None, name: str | None) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("client"))
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    if certs is not None:
        conf.insert_json5("transport/link/protocols", json.dumps(["tls"]))
        conf.insert_json5("transport/link/tls", json.dumps({
            "root_ca_certificate": f"{certs}/ca.pem", "enable_mtls": True,
            "connect_certificate": f"{certs}/{name}.pem", "connect_private_key": f"{certs}/{name}.key"}))
    return conf


def unpack(payload: bytes, kind: str) -> dict:
    msg = msgpack.unpackb(payload, raw=False)
    if msg.get("v") != WIRE or msg.get("kind") != kind:
        raise SystemExit(f"outside client: expected a version {WIRE} {kind}, got {msg.get('v')!r} {msg.get('kind')!r}")
    return msg


def i32(raw: bytes) -> list[int]:
    return [int.from_bytes(raw[i:i + 4], "little", signed=True) for i in range(0, len(raw), 4)]


def ask(session: zenoh.Session, key: str, kind: str, patience_s: float = 60.0) -> dict:
    deadline = time.monotonic() + patience_s
    while time.monotonic() < deadline:
        for reply in session.get(key, timeout=5.0):
            if reply.ok is not None:
                if str(reply.ok.encoding) != ENCODING:
                    raise SystemExit(f"outside client: {key} answered with encoding {reply.ok.encoding}")
                return unpack(reply.ok.payload.to_bytes(), kind)
        time.sleep(0.2)
    raise SystemExit(f"outside client: no answer on {key}")


def main() -> None:
    endpoint, run, out = sys.argv[1], sys.argv[2], sys.argv[3]
    certs, name = (sys.argv[4], sys.argv[5]) if len(sys.argv) > 5 else (None, None)
    root = f"surge/{run}"
    with zenoh.open(session_config(endpoint, certs, name)) as session:
        states = session.declare_subscriber(f"{root}/state", zenoh.handlers.FifoChannel(1024))
        commits = session.declare_subscriber(f"{root}/committed/*", zenoh.handlers.FifoChannel(65536))
        stop = session.declare_subscriber(f"{root}/stop", zenoh.handlers.FifoChannel(4))
        spec = ask(session, f"{root}/spec", "spec")
        print("ready", flush=True)
        requests: dict[int, tuple[int, int, int]] = {}
        seen = {"taxis": spec["taxis"], "minutes": spec["minutes"], "city_sha256": spec["city_sha256"],
                "positions": {}, "outstanding": {}, "committed": {}, "snapshots": 0, "moves_checked": 0}
        last = None

        def apply(state: dict) -> bool:
            nonlocal last
            if state["full"]:
                requests.clear()
            elif last is None or state["t"] != last + 1:
                return False
            for r in i32(state["picked"]):
                requests.pop(r, None)
            for r, p, d, e in zip(*(i32(state[f]) for f in ("new_index", "new_pickup", "new_dropoff", "new_entry"))):
                requests[r] = (p, d, e)
            if len(requests) != state["outstanding"]:
                return False
            last = state["t"]
            seen["positions"][str(state["t"])] = i32(state["pos"])
            seen["outstanding"][str(state["t"])] = len(requests)
            return True

        while True:
            sample = states.try_recv()
            if sample is None:
                if stop.try_recv() is not None:
                    break
                time.sleep(0.01)
                continue
            if str(sample.encoding) != ENCODING:
                raise SystemExit(f"outside client: a state with encoding {sample.encoding}")
            state = unpack(sample.payload.to_bytes(), "state")
            if not apply(state):
                snap = ask(session, f"{root}/snapshot", "snapshot")
                seen["snapshots"] += 1
                if not apply(unpack(snap["state"], "state")):
                    raise SystemExit("outside client: a snapshot that does not add up")
        while (c := commits.try_recv()) is not None:
            msg = unpack(c.payload.to_bytes(), "control")
            seen["committed"].setdefault(str(msg["t"]), {})[str(msg["agent"])] = msg["control"]
        for t, controls in seen["committed"].items():
            now, after = seen["positions"].get(t), seen["positions"].get(str(int(t) + 1))
            for agent, control in controls.items():
                if now is None or after is None or control < 0:
                    continue
                if after[int(agent)] != control:
                    raise SystemExit(f"outside client: taxi {agent} committed {control} at minute {t} but is at {after[int(agent)]}")
                seen["moves_checked"] += 1
    with open(out, "w") as fh:
        json.dump(seen, fh)


if __name__ == "__main__":
    main()

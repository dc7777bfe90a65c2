"""Forecast traffic per taxi: one whole-map message an hour against its local sectors' pieces, on the decisions of a real episode.

usage: python benchmarks/forecast-bytes.py [--scenario nyc --data ../shared/data] [--taxis 100] [--minutes 20]
                                           [--policy surge] [--forecast true-rate] [--samples N] --json OUT

Runs the episode in-process (the distributed run makes the same decisions),
then replays what each taxi would receive under the two schemes: the whole
hour's ``ForecastMsg`` at every hour start, or ``agents.taxi``'s rule: the
pieces of the sectors it follows at each hour start, the ``Dropoffs``, and
each newly followed sector's piece fetched from the coordinator when it
moves.  Sizes are the encoded payloads (zenoh's framing not counted).
Counts bytes, not time, so it can run on a busy machine.
"""
import argparse
import datetime as dt
import json
import sys

import numpy as np

from agents.sector_forecasts import needed_sectors
from bus.forecasts import sector_message
from bus.wire import Dropoffs, ForecastMsg
from city.sim import FleetSim
from coordinator.evaluate import run_episode
from coordinator.runtime import FleetConfig

p = argparse.ArgumentParser()
p.add_argument("--scenario", default="synthetic")
p.add_argument("--data", default=None)
p.add_argument("--taxis", type=int, default=100)
p.add_argument("--minutes", type=int, default=20)
p.add_argument("--hour", type=int, default=19)
p.add_argument("--policy", default="surge")
p.add_argument("--forecast", default="true-rate")
p.add_argument("--samples", type=int, default=None)
p.add_argument("--json", required=True)
a = p.parse_args()
options = {"forecast": a.forecast} if a.policy == "surge" else {}
if a.samples:
    options["samples"] = a.samples
cfg = FleetConfig(scenario=a.scenario, data_dir=a.data, taxis=a.taxis, minutes=a.minutes, hour=a.hour, policy=a.policy, options=options)
scen, requests, start, context = cfg.instance()
city = scen.city
policy = cfg.make_policy(city)
print(f"in-process {a.policy} episode: {a.taxis} taxis, {a.minutes} min on {a.scenario}", file=sys.stderr, flush=True)
res = run_episode(city, policy, requests, start, context)
policy.reset(context)
rollout = policy.config

whole_bytes, piece_bytes, drop_bytes = {}, {}, {}
sim = FleetSim(city, requests, start)
followed = [set() for _ in range(a.taxis)]
per_minute = []
tot = {"whole": [0, 0], "sectors": [0, 0], "fetched": [0, 0]}  # [messages, bytes]
followed_sizes = []
for t in range(a.minutes):
    obs = sim.observe()
    h = t // 60
    if h not in whole_bytes:
        fc = policy.forecast(h)
        whole_bytes[h] = len(ForecastMsg(hour=h, eta=fc.eta, rho=fc.rho, delta=fc.delta, beta=fc.beta).encode())
        piece_bytes[h] = [len(sector_message(fc, city, h, s).encode()) for s in range(city.n_sectors)]
        drop_bytes[h] = len(Dropoffs(hour=h, delta=fc.delta).encode())
    minute = {"whole": [0, 0], "sectors": [0, 0], "fetched": [0, 0]}
    if t % 60 == 0:
        minute["whole"] = [a.taxis, a.taxis * whole_bytes[h]]
        got = sum(len(f) for f in followed)
        minute["sectors"] = [got + a.taxis, sum(piece_bytes[h][s] for f in followed for s in f) + a.taxis * drop_bytes[h]]
        held = [set(f) for f in followed]
    for i in range(a.taxis):
        node = int(obs.pos[i]) if obs.tau[i] == 0 or obs.dest[i] < 0 else int(obs.dest[i])
        want = set(needed_sectors(city, rollout, node).tolist())
        new = want - held[i]
        minute["fetched"][0] += len(new)
        minute["fetched"][1] += sum(piece_bytes[h][s] for s in new)
        held[i] |= want
        followed[i] = want
    followed_sizes.append(float(np.mean([len(f) for f in followed])))
    for k in tot:
        tot[k][0] += minute[k][0]
        tot[k][1] += minute[k][1]
    per_minute.append(minute)
    sim.step(res.controls[t])

hours = (a.minutes + 59) // 60
doc = {
    "format": "surge.forecast-bytes/1",
    "command": " ".join(sys.argv),
    "scenario": a.scenario, "taxis": a.taxis, "minutes": a.minutes, "hour": a.hour, "policy": a.policy,
    "rollout": {"scope": rollout.scope, "ce": rollout.ce},
    "city": city.summary(),
    "decisions_sha256": res.decisions_sha256,
    "whole_map": {"messages": tot["whole"][0], "bytes": tot["whole"][1], "bytes_per_message": whole_bytes[0]},
    "per_sector": {"messages": tot["sectors"][0] + tot["fetched"][0], "bytes": tot["sectors"][1] + tot["fetched"][1],
                   "published_to_followers": {"messages": tot["sectors"][0], "bytes": tot["sectors"][1]},
                   "fetched_on_moving": {"messages": tot["fetched"][0], "bytes": tot["fetched"][1]},
                   "piece_bytes": {"min": min(piece_bytes[0]), "median": float(np.median(piece_bytes[0])), "max": max(piece_bytes[0])},
                   "dropoffs_bytes": drop_bytes[0]},
    "sectors_followed_per_taxi": {"mean": float(np.mean(followed_sizes)), "of": city.n_sectors},
    "per_minute": per_minute,
}
ratio = doc["per_sector"]["bytes"] / doc["whole_map"]["bytes"]
doc["per_sector_over_whole_bytes"] = ratio
print(f"{a.taxis} taxis, {a.minutes} min ({hours} h) on {a.scenario}, {a.policy} ({rollout.scope} scope, {rollout.ce} CE):")
print(f"  whole-map forecast: {doc['whole_map']['messages']} messages, {doc['whole_map']['bytes'] / 1e6:.2f} MB")
print(f"  per-sector:         {doc['per_sector']['messages']} messages, {doc['per_sector']['bytes'] / 1e6:.2f} MB "
      f"({tot['fetched'][0]} pieces fetched on moving); {ratio:.3f} of the bytes")
print(f"  sectors followed per taxi: {doc['sectors_followed_per_taxi']['mean']:.1f} of {city.n_sectors}")
with open(a.json, "w") as fh:
    json.dump(doc, fh, indent=1)
print(f"wrote {a.json}")

"""The route-planning oracle on the instances of benchmarks/quality-synthetic.json, against every recorded policy."""
import datetime as dt, json, sys, time
import numpy as np
from city.scenario import load_scenario
from coordinator.evaluate import episode_requests, initial_positions, run_episode, write_json
from agents.base import EpisodeContext, make_policy
doc = json.load(open("benchmarks/quality-synthetic.json"))
scen = load_scenario("synthetic"); city = scen.city
date = dt.date(2022, 11, 17)
out_path = sys.argv[1]
try:
    done = json.load(open(out_path))["instances"]
except FileNotFoundError:
    done = []
have = {(r["hour"], r["seed"]) for r in done}
by = {}
for e in doc["episodes"]:
    by.setdefault((e["hour"], e["seed"]), {})[e["policy"]] = e["total_cost"]
order = sorted(by, key=lambda k: (k[1], k[0]))
for hour, seed in order:
    if (hour, seed) in have:
        continue
    req = episode_requests(scen.world, date, hour, 60)
    start = initial_positions(city, 100, seed)
    ctx = EpisodeContext(city=city, date=date, hour=hour, minutes=60, seed=seed, world=scen.world)
    pol = make_policy("oracle", city)
    t0 = time.process_time()
    r = run_episode(city, pol, req, start, ctx)
    cpu = time.process_time() - t0
    rec = by[(hour, seed)]
    rec = {("oracle-auction" if k == "oracle" else k): v for k, v in rec.items()}
    done.append({"hour": hour, "seed": seed, "oracle": r.total_cost, "chosen": pol.chosen, "plan_cost": pol.costs["plan"],
                 "cpu_seconds": cpu, "recorded": rec, "lowest": r.total_cost <= min(rec.values())})
    write_json({"schema": "surge.oracle-check/1", "source": "benchmarks/quality-synthetic.json", "instances": done}, out_path)
    print(hour, seed, r.total_cost, rec, f"{cpu:.1f}s cpu", flush=True)

"""Paired episodes of rollout variants and baselines on validation instances, resumable.

One instance is (scenario, date, hour, seed): the requests of the demand world
for that date and hour, and the fleet's start drawn from ``seed``, exactly as
``surge evaluate`` builds them (same helpers, same per-instance rollout seed).
Unlike ``surge evaluate`` it takes any seed range (validation seeds 100+) and
runs no oracle, and it records each episode's per-minute stage costs, so the
first 20 minutes and minutes 20-60 can be told apart.

    python benchmarks/rollout-variants/run.py --json F --scenario synthetic \
        --dates 2022-08-02 --hours 17 19 --seeds 100 101 102 103 104 \
        --policies ia garces2023 surge:forecast=previous-hour

Each finished episode is appended to ``F`` at once; rerunning skips them.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import platform
import sys
import time
from pathlib import Path

from agents.base import EpisodeContext, make_policy, parse_policy
from city.episode import episode_requests, initial_positions, run_episode
from city.scenario import load_scenario
from coordinator.experiments import evaluate as E
from coordinator.experiments.results import demand_source


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", required=True)
    p.add_argument("--scenario", default="synthetic")
    p.add_argument("--data", default=None)
    p.add_argument("--dates", nargs="+", required=True)
    p.add_argument("--hours", nargs="+", type=int, required=True)
    p.add_argument("--seeds", nargs="+", type=int, required=True)
    p.add_argument("--taxis", type=int, default=100)
    p.add_argument("--minutes", type=int, default=60)
    p.add_argument("--policies", nargs="+", required=True)
    a = p.parse_args()
    path = Path(a.json)
    doc = json.loads(path.read_text()) if path.exists() else {
        "schema": "surge.rollout-variants/1",
        "command": " ".join(["python"] + sys.argv),
        "date": dt.date.today().isoformat(),
        "machine": f"{platform.machine()}, 2 vCPU shared",
        "scenario": a.scenario, "taxis": a.taxis, "minutes": a.minutes,
        "episodes": [],
    }
    scen = load_scenario(a.scenario, a.data)
    source = demand_source(scen.world)
    if doc.setdefault("demand_source", source) != source:
        raise SystemExit(f"{path}: was written with demand source {doc['demand_source']!r}, this run has {source!r}")
    done = {(e["date"], e["hour"], e["seed"], e["policy"]) for e in doc["episodes"]}
    for seed in a.seeds:
        for date_text in a.dates:
            for hour in a.hours:
                date = dt.date.fromisoformat(date_text)
                requests = episode_requests(scen.world, date, hour, a.minutes)
                start = initial_positions(scen.city, a.taxis, seed)
                ctx = EpisodeContext(city=scen.city, date=date, hour=hour, minutes=a.minutes, seed=seed, world=scen.world)
                for label in a.policies:
                    if (date_text, hour, seed, label) in done:
                        continue
                    name, options = parse_policy(label)
                    if "seed" not in options and E.takes_rollout_seed(name):
                        options["seed"] = E.instance_seed(date, hour, seed)
                    policy = make_policy(name, scen.city, **options)
                    t0 = time.perf_counter()
                    r = run_episode(scen.city, policy, requests, start, ctx)
                    doc["episodes"].append({
                        "date": date_text, "hour": hour, "seed": seed, "policy": label,
                        "total_cost": r.total_cost, "served": r.served, "outstanding_end": r.outstanding_end,
                        "stage_costs": list(map(int, r.stage_costs)),
                        "plan_seconds_per_step": sum(r.plan_seconds) / max(len(r.plan_seconds), 1), "decisions_sha256": r.decisions_sha256,
                    })
                    path.write_text(json.dumps(doc, indent=0))
                    print(f"{a.scenario} {date_text} {hour}h seed {seed} {label}: {r.total_cost} "
                          f"({time.perf_counter() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main()

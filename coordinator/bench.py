"""``surge bench``: measure, print and write JSON; never assert a number."""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import statistics
import time
from pathlib import Path

import numpy as np


def _stats(xs: list[float]) -> dict:
    return {"median": statistics.median(xs), "min": min(xs), "max": max(xs)}


def peak_rss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="benchmarks: city build, simulator speed, planning time")
    bsub = p.add_subparsers(dest="bench", required=True, metavar="BENCH")

    c = bsub.add_parser("city", help="time to build each city (all-pairs shortest paths included) and to load it")
    c.add_argument("--data", default=None, help="also build the nyc map from this data directory")
    c.add_argument("--repeat", type=int, default=3)
    c.add_argument("--json", default=None)
    c.set_defaults(func=bench_city)

    s = bsub.add_parser("sim", help="simulator steps per second with the greedy policy")
    s.add_argument("--scenario", default="synthetic")
    s.add_argument("--data", default=None)
    s.add_argument("--taxis", type=int, default=100)
    s.add_argument("--hour", type=int, default=19)
    s.add_argument("--date", default="2022-11-17")
    s.add_argument("--episodes", type=int, default=3)
    s.add_argument("--json", default=None)
    s.set_defaults(func=bench_sim)


def bench_city(args: argparse.Namespace) -> int:
    from city.scenario import check_scenario
    from city.synthetic import synthetic_city
    from city.graph import City

    builders = {"synthetic": synthetic_city}
    if args.data:
        from city.nyc import load_nyc_city

        data = check_scenario("nyc", args.data)
        builders["nyc"] = lambda: load_nyc_city(data)
    out: dict = {"schema": "surge.bench.city/1", "cpus": os.cpu_count(), "cities": {}}
    for name, build in builders.items():
        times, loads = [], []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            city = build()
            times.append(time.perf_counter() - t0)
        path = Path(f"/tmp/surge-bench-{name}-{os.getpid()}.npz")
        city.save(path)
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            City.load(path)
            loads.append(time.perf_counter() - t0)
        size = path.stat().st_size / 2**20
        path.unlink()
        out["cities"][name] = {"city": city.summary(), "build_seconds": _stats(times), "load_seconds": _stats(loads), "file_mb": size}
        s = city.summary()
        print(f"{name:<10} {s['intersections']:>5} nodes {s['streets']:>5} edges {s['sectors']:>3} sectors  "
              f"build {statistics.median(times):6.2f} s (min {min(times):.2f})  load {statistics.median(loads) * 1e3:6.1f} ms  file {size:.1f} MB")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0


def bench_sim(args: argparse.Namespace) -> int:
    from agents.base import EpisodeContext, make_policy
    from city.scenario import load_scenario
    from city.sim import FleetSim
    from coordinator.evaluate import episode_requests, initial_positions

    scen = load_scenario(args.scenario, args.data)
    date = dt.date.fromisoformat(args.date)
    requests = episode_requests(scen.world, date, args.hour, 60)
    policy = make_policy("greedy", scen.city)
    act, step, total = [], [], []
    for seed in range(args.episodes):
        sim = FleetSim(scen.city, requests, initial_positions(scen.city, args.taxis, seed))
        policy.reset(EpisodeContext(scen.city, date, args.hour, 60, seed, scen.world))
        t_ep = time.perf_counter()
        for _ in range(60):
            obs = sim.observe()
            t0 = time.perf_counter()
            u = policy.act(obs)
            t1 = time.perf_counter()
            sim.step(u)
            t2 = time.perf_counter()
            act.append(t1 - t0)
            step.append(t2 - t1)
        total.append(60 / (time.perf_counter() - t_ep))
    out = {
        "schema": "surge.bench.sim/1",
        "city": scen.city.summary(),
        "taxis": args.taxis,
        "requests": len(requests),
        "steps_per_second": _stats(total),
        "policy_ms_per_step": float(np.mean(act) * 1e3),
        "transition_ms_per_step": float(np.mean(step) * 1e3),
    }
    print(f"{args.scenario}: {args.taxis} taxis, {len(requests)} requests at {args.hour}:00 — "
          f"{statistics.median(total):.0f} steps/s (greedy {out['policy_ms_per_step']:.2f} ms + transition {out['transition_ms_per_step']:.2f} ms per step)")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0

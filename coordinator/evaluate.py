"""The evaluation harness: replay city-hours under several policies and compare them.

One instance is (date, hour, seed): the requests come from the demand world
for that date and hour, and the seed draws the fleet's initial placement.
Every policy runs on the same instances, and the oracle always runs too,
because wait overhead per served request is measured against it.
"""

from __future__ import annotations

import datetime as dt
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from agents.base import EpisodeContext, Policy, make_policy
from city.graph import City
from city.sim import EpisodeResult, FleetSim, Requests

RESULTS_SCHEMA = "surge.results/1"
METRICS = ("total_cost", "outstanding_end", "served", "wait_overhead_per_served", "plan_seconds_per_step")


@dataclass
class EvalConfig:
    scenario: str = "synthetic"
    data_dir: str | None = None
    date: str = "2022-11-17"
    hours: list[int] = field(default_factory=lambda: [15, 17, 19, 21])
    seeds: int = 25
    taxis: int = 100
    minutes: int = 60
    policies: list[str] = field(default_factory=lambda: ["greedy", "ia", "oracle"])
    policy_options: dict[str, dict] = field(default_factory=dict)
    world_seed: int = 0
    jobs: int = 1


def initial_positions(city: City, n_taxis: int, seed: int) -> np.ndarray:
    """A random placement of the fleet on pickup-eligible intersections (the paper's initial state)."""
    rng = np.random.default_rng(seed)
    return rng.choice(np.flatnonzero(city.pickup), size=n_taxis, replace=True).astype(np.int32)


def episode_requests(world, date: dt.date, hour: int, minutes: int) -> Requests:
    """Requests for ``minutes`` minutes from ``hour``, spanning as many hours as needed."""
    parts = []
    for k in range((minutes + 59) // 60):
        when = dt.datetime.combine(date, dt.time()) + dt.timedelta(hours=hour + k)
        r = world.requests(when.date(), when.hour, min(60, minutes - 60 * k))
        parts.append((r.pickup, r.dropoff, r.entry + 60 * k))
    return Requests.sorted(*(np.concatenate(x) for x in zip(*parts)))


def run_episode(
    city: City,
    policy: Policy,
    requests: Requests,
    start: np.ndarray,
    context: EpisodeContext,
) -> EpisodeResult:
    """Run one policy for ``context.minutes`` steps and collect its metrics and controls."""
    sim = FleetSim(city, requests, start)
    if policy.clairvoyant:
        context = replace(context, future=requests)
    policy.reset(context)
    costs: list[int] = []
    plan: list[float] = []
    controls = np.zeros((context.minutes, len(start)), dtype=np.int32)
    for t in range(context.minutes):
        obs = sim.observe()
        t0 = time.perf_counter()
        u = policy.act(obs)
        plan.append(time.perf_counter() - t0)
        controls[t] = u
        costs.append(sim.step(u))
    return sim.result(costs, controls, plan)


def _instance(cfg: EvalConfig, hour: int, seed: int) -> list[dict]:
    """All policies (and the oracle) on one instance; rows for the requested policies."""
    scen = _scenario_cache(cfg)
    date = dt.date.fromisoformat(cfg.date)
    requests = episode_requests(scen.world, date, hour, cfg.minutes)
    start = initial_positions(scen.city, cfg.taxis, seed)
    context = EpisodeContext(city=scen.city, date=date, hour=hour, minutes=cfg.minutes, seed=seed, world=scen.world)
    names = list(dict.fromkeys(cfg.policies + ["oracle"]))
    results: dict[str, EpisodeResult] = {}
    for name in names:
        policy = make_policy(name, scen.city, **cfg.policy_options.get(name, {}))
        results[name] = run_episode(scen.city, policy, requests, start, context)
    oracle_cost = results["oracle"].total_cost
    rows = []
    for name in cfg.policies:
        r = results[name]
        rows.append(
            {
                "hour": hour,
                "seed": seed,
                "policy": name,
                "total_cost": r.total_cost,
                "outstanding_end": r.outstanding_end,
                "served": r.served,
                "requests": r.n_requests,
                "wait_overhead_per_served": (r.total_cost - oracle_cost) / max(r.served, 1),
                "plan_seconds_per_step": float(np.mean(r.plan_seconds)),
                "decisions_sha256": r.decisions_sha256,
            }
        )
    return rows


_SCENARIOS: dict = {}


def _scenario_cache(cfg: EvalConfig):
    from city.scenario import load_scenario

    key = (cfg.scenario, cfg.data_dir, cfg.world_seed)
    if key not in _SCENARIOS:
        _SCENARIOS[key] = load_scenario(cfg.scenario, cfg.data_dir, seed=cfg.world_seed)
    return _SCENARIOS[key]


def evaluate(cfg: EvalConfig, progress: Callable[[str], None] | None = None) -> dict:
    """Run every (hour, seed) instance and return the ``surge.results/1`` document."""
    progress = progress or (lambda msg: print(msg, file=sys.stderr, flush=True))
    scen = _scenario_cache(cfg)
    tasks = [(h, s) for h in cfg.hours for s in range(cfg.seeds)]
    episodes: list[dict] = []
    t0 = time.perf_counter()

    def report(done: int, rows: list[dict]) -> None:
        head = rows[0]
        costs = " ".join(f"{r['policy']}={r['total_cost']}" for r in rows)
        progress(f"[{done}/{len(tasks)}] hour {head['hour']} seed {head['seed']}: {costs} ({time.perf_counter() - t0:.1f} s)")

    if cfg.jobs > 1:
        import multiprocessing as mp
        import os

        # Workers share the cores: each gets its slice for the compiled rollout kernels.
        os.environ.setdefault("NUMBA_NUM_THREADS", str(max(1, (os.cpu_count() or 1) // cfg.jobs)))

        with ProcessPoolExecutor(max_workers=cfg.jobs, mp_context=mp.get_context("spawn")) as pool:
            futures = [pool.submit(_instance, cfg, h, s) for h, s in tasks]
            for k, fut in enumerate(futures, 1):
                rows = fut.result()
                episodes.extend(rows)
                report(k, rows)
    else:
        for k, (h, s) in enumerate(tasks, 1):
            rows = _instance(cfg, h, s)
            episodes.extend(rows)
            report(k, rows)
    return {
        "schema": RESULTS_SCHEMA,
        "scenario": cfg.scenario,
        "city": scen.city.summary(),
        "config": asdict(cfg),
        "episodes": episodes,
    }


def summarize(doc: dict) -> list[dict]:
    """Mean and standard deviation of every metric per (hour, policy)."""
    out = []
    eps = doc["episodes"]
    hours = sorted({e["hour"] for e in eps})
    policies = list(dict.fromkeys(e["policy"] for e in eps))
    for h in hours:
        for p in policies:
            sel = [e for e in eps if e["hour"] == h and e["policy"] == p]
            if not sel:
                continue
            row = {"hour": h, "policy": p, "n": len(sel)}
            for m in METRICS:
                vals = np.array([e[m] for e in sel], dtype=float)
                row[m] = (float(vals.mean()), float(vals.std()))
            out.append(row)
    return out


def format_table(summary: Iterable[dict]) -> str:
    head = f"{'hour':>4}  {'policy':<12}{'total cost':>20}{'outstanding end':>18}{'served':>16}{'wait overhead/served':>22}{'plan ms/step':>14}"
    lines = [head, "-" * len(head)]
    for r in summary:
        tc, oe, sv, wo, ps = (r[m] for m in METRICS)
        lines.append(
            f"{r['hour']:>4}  {r['policy']:<12}"
            f"{tc[0]:>11.1f} ± {tc[1]:<6.1f}"
            f"{oe[0]:>9.1f} ± {oe[1]:<6.1f}"
            f"{sv[0]:>8.1f} ± {sv[1]:<5.1f}"
            f"{wo[0]:>13.2f} ± {wo[1]:<6.2f}"
            f"{ps[0] * 1e3:>12.2f}"
        )
    return "\n".join(lines)


def write_json(doc: dict, path: str | Path) -> None:
    Path(path).write_text(json.dumps(doc, indent=1))

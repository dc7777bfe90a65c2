"""The evaluation harness: replay city-hours under several policies and compare them.

One instance is (date, hour, seed): the requests come from the demand world
for that date and hour, and the seed draws the fleet's initial placement.
Every policy runs on the same instances, and the oracle always runs too,
because wait overhead per served request is measured against it.

A policy is named as in the registry, optionally with options:
``surge:forecast=true-rate,samples=500``; the whole string labels its rows,
so one run can compare a policy under several settings.  Long runs resume:
with a results file, finished instances are kept and each new one is written
as soon as it ends.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import json
import signal
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from agents.base import EpisodeContext, Policy, make_policy, parse_policy
from city.errors import ConfigError, DataError
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
    cluster: str | None = None


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
    labels = list(dict.fromkeys(cfg.policies + ["oracle"]))
    results: dict[str, EpisodeResult] = {}
    for label in labels:
        name, options = parse_policy(label)
        policy = make_policy(name, scen.city, **{**cfg.policy_options.get(label, {}), **options})
        results[label] = run_episode(scen.city, policy, requests, start, context)
    oracle_cost = results["oracle"].total_cost
    greedy_cost = results["greedy"].total_cost if "greedy" in results else None
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
                "oracle_cost": oracle_cost,
                "greedy_cost": greedy_cost,
                "plan_seconds_per_step": float(np.mean(r.plan_seconds)),
                "decisions_sha256": r.decisions_sha256,
            }
        )
    return rows


def _instance_task(task: tuple[EvalConfig, int, int]) -> list[dict]:
    return _instance(*task)


_SCENARIOS: dict = {}


def _scenario_cache(cfg: EvalConfig):
    from city.scenario import load_scenario

    key = (cfg.scenario, cfg.data_dir, cfg.world_seed)
    if key not in _SCENARIOS:
        _SCENARIOS[key] = load_scenario(cfg.scenario, cfg.data_dir, seed=cfg.world_seed)
    return _SCENARIOS[key]


_RESUME_FREE = ("seeds", "jobs", "cluster")


_EPISODE_FIELDS = ("hour", "seed", "policy", "oracle_cost", *METRICS)


def read_results(path: str | Path) -> dict:
    """A ``surge.results/1`` document, checked down to every episode's fields."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise DataError(f"not JSON ({exc})", path=path) from exc
    if not isinstance(doc, dict) or doc.get("schema") != RESULTS_SCHEMA:
        found = doc.get("schema") if isinstance(doc, dict) else type(doc).__name__
        raise DataError(f"schema {found!r}, expected {RESULTS_SCHEMA!r}", path=path)
    for key in ("config", "city", "episodes"):
        if key not in doc:
            raise DataError(f"no {key!r} field", path=path)
    for k, ep in enumerate(doc["episodes"]):
        missing = [f for f in _EPISODE_FIELDS if not isinstance(ep, dict) or f not in ep]
        if missing:
            raise DataError(f"episode {k} has no {missing[0]!r} field", path=path)
    return doc


def load_finished(cfg: EvalConfig, path: str | Path) -> list[dict]:
    """Episodes of an earlier run of the same configuration (any seed count), to resume from."""
    doc = read_results(path)
    mine = {k: v for k, v in asdict(cfg).items() if k not in _RESUME_FREE}
    theirs = {k: v for k, v in doc.get("config", {}).items() if k not in _RESUME_FREE}
    for key in mine:
        if mine[key] != theirs.get(key):
            raise DataError(f"was written with {key}={theirs.get(key)!r}, this run has {mine[key]!r}; use another --json", path=path)
    return list(doc["episodes"])


def evaluate(
    cfg: EvalConfig,
    progress: Callable[[str], None] | None = None,
    *,
    checkpoint: str | Path | None = None,
    resume: bool = False,
) -> dict:
    """Run every (hour, seed) instance and return the ``surge.results/1`` document.

    With ``checkpoint``, the results file is rewritten after every finished
    instance; with ``resume`` too, the instances it already holds are kept,
    not rerun.
    """
    progress = progress or (lambda msg: print(msg, file=sys.stderr, flush=True))
    scen = _scenario_cache(cfg)
    for label in dict.fromkeys(cfg.policies):  # fail on a bad name or option now, not in a worker an hour in
        name, options = parse_policy(label)
        make_policy(name, scen.city, **{**cfg.policy_options.get(label, {}), **options})
    episodes: list[dict] = []
    if resume and checkpoint is not None and Path(checkpoint).exists():
        wanted = {(h, s) for h in cfg.hours for s in range(cfg.seeds)}
        episodes = [e for e in load_finished(cfg, checkpoint) if (e["hour"], e["seed"]) in wanted]
        if episodes:
            progress(f"resuming from {checkpoint}: {len({(e['hour'], e['seed']) for e in episodes})} instances done")
    done = {(e["hour"], e["seed"]) for e in episodes}
    # Seed by seed across the hours, so that a run cut short has every hour at the same depth.
    tasks = [(h, s) for s in range(cfg.seeds) for h in cfg.hours if (h, s) not in done]
    t0 = time.perf_counter()

    def document() -> dict:
        order = {(h, s): k for k, (h, s) in enumerate((h, s) for h in cfg.hours for s in range(cfg.seeds))}
        return {
            "schema": RESULTS_SCHEMA,
            "scenario": cfg.scenario,
            "city": scen.city.summary(),
            "config": asdict(cfg),
            "episodes": sorted(episodes, key=lambda e: order[(e["hour"], e["seed"])]),
        }

    def report(k: int, rows: list[dict]) -> None:
        episodes.extend(rows)
        if checkpoint is not None:
            write_json(document(), checkpoint)
        head = rows[0]
        costs = " ".join(f"{r['policy']}={r['total_cost']}" for r in rows)
        progress(f"[{k}/{len(tasks)}] hour {head['hour']} seed {head['seed']}: {costs} ({time.perf_counter() - t0:.1f} s)")

    with contextlib.closing(run_instances(cfg, tasks)) as results:  # closed at once on any error: workers stop
        for k, rows in enumerate(results, 1):
            report(k, rows)
    return document()


def run_instances(cfg: EvalConfig, tasks: list[tuple[int, int]]) -> Iterator[list[dict]]:
    """The rows of each ``(hour, seed)`` instance, in task order: in this process, in a pool of
    ``cfg.jobs`` worker processes, or on the Dask cluster at ``cfg.cluster``."""
    work = [(cfg, h, s) for h, s in tasks]
    if cfg.cluster:
        from coordinator.cluster import run_on_cluster

        yield from run_on_cluster(cfg.cluster, _instance_task, work)
    elif cfg.jobs > 1:
        import multiprocessing as mp
        import os

        # Workers share the cores: each gets its slice for the compiled rollout kernels.
        os.environ.setdefault("NUMBA_NUM_THREADS", str(max(1, (os.cpu_count() or 1) // cfg.jobs)))
        # A Pool, not a ProcessPoolExecutor: leaving the block for any reason (an error,
        # Ctrl-C, SIGTERM turned into SystemExit by the CLI) terminates the workers at once
        # instead of waiting for their instances or leaving them orphaned. Workers ignore
        # SIGINT so that Ctrl-C reaches only this process, which then stops them.
        with mp.get_context("spawn").Pool(cfg.jobs, initializer=signal.signal, initargs=(signal.SIGINT, signal.SIG_IGN)) as pool:
            yield from pool.imap(_instance_task, work)
    else:
        yield from map(_instance_task, work)


def summarize(doc: dict) -> list[dict]:
    """Mean and standard deviation of every metric per (hour, policy).

    ``gap_closed`` is the share of the greedy→oracle gap in mean total cost
    that the policy closes, (greedy - policy) / (greedy - oracle), where the
    run included greedy (the paper's yardstick).
    """
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
            row["gap_closed"] = None
            if all(e.get("greedy_cost") is not None for e in sel):
                greedy = np.mean([e["greedy_cost"] for e in sel])
                gap = greedy - np.mean([e["oracle_cost"] for e in sel])
                if gap > 0:
                    row["gap_closed"] = float((greedy - row["total_cost"][0]) / gap)
            out.append(row)
    return out


def complete_seeds(doc: dict) -> dict:
    """The document restricted to seeds finished at every hour, so that hours compare like for like.

    A run cut short (or still going) leaves its last seed at some hours only.
    """
    eps = doc["episodes"]
    hours = {e["hour"] for e in eps}
    at = {}
    for e in eps:
        at.setdefault(e["seed"], set()).add(e["hour"])
    keep = {s for s, hs in at.items() if hs == hours}
    return {**doc, "episodes": [e for e in eps if e["seed"] in keep]}


def compare(doc: dict, policy: str) -> list[dict]:
    """``policy`` against every other non-oracle policy, paired instance by instance, per hour.

    ``wins`` counts the instances where ``policy`` has the lower total cost;
    ``overhead_reduction`` is 1 - its mean wait overhead per served request
    over the other's, and ``served_change`` its mean served over the other's,
    minus 1 (the paper's two headline comparisons).  ``below_oracle`` counts
    instances where ``policy`` beat the oracle, which is a receding-horizon
    auction, not a proven optimum.
    """
    by = {(e["hour"], e["seed"], e["policy"]): e for e in doc["episodes"]}
    policies = list(dict.fromkeys(e["policy"] for e in doc["episodes"]))
    if policy not in policies:
        raise ConfigError(f"policy {policy!r} is not in the results; they hold {', '.join(policies)}")
    out = []
    for other in (p for p in policies if p not in (policy, "oracle")):
        for h in sorted({e["hour"] for e in doc["episodes"]}):
            pairs = [(by[k], by[(k[0], k[1], other)]) for k in by
                     if k[0] == h and k[2] == policy and (k[0], k[1], other) in by]
            if not pairs:
                continue
            mine, theirs = (np.array([[a[m] for a in side] for m in METRICS[:4]]) for side in zip(*pairs))
            out.append({
                "hour": h,
                "policy": policy,
                "against": other,
                "n": len(pairs),
                "wins": int((mine[0] < theirs[0]).sum()),
                "cost_difference": float((mine[0] - theirs[0]).mean()),
                "overhead_reduction": float(1 - mine[3].mean() / theirs[3].mean()) if theirs[3].mean() > 0 else None,
                "served_change": float(mine[2].mean() / theirs[2].mean() - 1),
                "below_oracle": int(sum(a["total_cost"] < a["oracle_cost"] for a, _ in pairs)),
            })
    return out


def format_comparison(rows: Iterable[dict]) -> str:
    rows = list(rows)
    if not rows:
        return ""
    width = max([10] + [len(r["against"]) + 2 for r in rows])
    head = f"{'hour':>4}  {'against':<{width}}{'wins':>10}{'cost diff':>12}{'overhead Δ':>12}{'served Δ':>10}"
    policy = rows[0]["policy"]
    lines = [f"{policy} paired with each policy on the same instances (wins: lower total cost)", head, "-" * len(head)]
    for r in rows:
        red = f"{-100 * r['overhead_reduction']:>+11.1f}%" if r["overhead_reduction"] is not None else f"{'—':>12}"
        lines.append(
            f"{r['hour']:>4}  {r['against']:<{width}}{r['wins']:>5} / {r['n']:<3}"
            f"{r['cost_difference']:>+11.1f}{red}{100 * r['served_change']:>+9.1f}%"
        )
    per_hour = {r["hour"]: r for r in rows}.values()
    below, n = sum(r["below_oracle"] for r in per_hour), sum(r["n"] for r in per_hour)
    lines.append(f"{policy} cost less than the oracle (a receding-horizon auction) in {below} of {n} instances")
    return "\n".join(lines)


def format_table(summary: Iterable[dict]) -> str:
    summary = list(summary)
    width = max([12] + [len(r["policy"]) + 2 for r in summary])
    head = f"{'hour':>4}  {'policy':<{width}}{'total cost':>20}{'outstanding end':>18}{'served':>16}{'wait overhead/served':>22}{'plan ms/step':>14}{'gap closed':>12}"
    lines = [head, "-" * len(head)]
    for r in summary:
        tc, oe, sv, wo, ps = (r[m] for m in METRICS)
        lines.append(
            f"{r['hour']:>4}  {r['policy']:<{width}}"
            f"{tc[0]:>11.1f} ± {tc[1]:<6.1f}"
            f"{oe[0]:>9.1f} ± {oe[1]:<6.1f}"
            f"{sv[0]:>8.1f} ± {sv[1]:<5.1f}"
            f"{wo[0]:>13.2f} ± {wo[1]:<6.2f}"
            f"{ps[0] * 1e3:>12.2f}"
            + (f"{100 * r['gap_closed']:>11.1f}%" if r.get("gap_closed") is not None else f"{'—':>12}")
        )
    return "\n".join(lines)


def plot(summary: list[dict], path: str | Path, title: str = "") -> None:
    """Grouped bars of mean total cost (± std) per hour and policy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hours = sorted({r["hour"] for r in summary})
    policies = list(dict.fromkeys(r["policy"] for r in summary))
    by = {(r["hour"], r["policy"]): r["total_cost"] for r in summary}
    width = 0.8 / len(policies)
    fig, ax = plt.subplots(figsize=(max(6.0, 1.6 * len(hours) + 0.4 * len(policies)), 4.0), dpi=110)
    for k, pol in enumerate(policies):
        xs = [i + (k - (len(policies) - 1) / 2) * width for i, h in enumerate(hours) if (h, pol) in by]
        vals = [by[h, pol] for h in hours if (h, pol) in by]
        ax.bar(xs, [v[0] for v in vals], width, yerr=[v[1] for v in vals], capsize=2, label=pol)
    ax.set_xticks(range(len(hours)))
    ax.set_xticklabels([f"{h}h" for h in hours])
    ax.set_ylabel("total cost (request-minutes waited)")
    ax.grid(axis="y", alpha=0.3)
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi * 1.22)  # headroom, so the legend never covers the tallest bars
    ax.legend(fontsize=8, ncol=min(len(policies), 3), loc="upper left")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def write_json(doc: dict, path: str | Path) -> None:
    """Write atomically, so an interrupted run never leaves half a results file."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(doc, indent=1))
    tmp.replace(path)

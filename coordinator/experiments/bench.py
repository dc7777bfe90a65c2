"""``surge bench``: measure, print and write JSON; never assert a number."""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import os
import statistics
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from agents.shortcuts import Shortcuts
from city.logs import echo, steps

if TYPE_CHECKING:
    from agents.base import EpisodeContext
    from city.scenario import Scenario
    from city.sim import FleetSim


@dataclasses.dataclass(frozen=True)
class CityBench:
    """``surge bench city``: build and load each city ``repeat`` times (the nyc map where ``data`` is given)."""

    data: str | None = None
    repeat: int = 3
    json: str | None = None


@dataclasses.dataclass(frozen=True)
class SimBench:
    """``surge bench sim``: simulator steps per second under ``greedy``."""

    scenario: str = "synthetic"
    data: str | None = None
    taxis: int = 100
    hour: int = 19
    date: str = "2022-11-17"
    episodes: int = 3
    json: str | None = None


@dataclasses.dataclass(frozen=True)
class PlanBench:
    """``surge bench plan``: planning seconds per step of each policy label, from a mid-episode state."""

    scenario: str = "synthetic"
    data: str | None = None
    date: str = "2022-11-17"
    hour: int = 19
    taxis: int = 100
    horizon: int | None = None
    samples: int | None = None
    steps: int = 5
    #: Runs of every policy, taken in turn (A, B, A, B, …), each in a fresh process; their steps are pooled.
    rounds: int = 1
    warmup: int = 25
    seed: int = 0
    policies: tuple[str, ...] = ("surge", "garces2023")
    forecast: str | None = None
    threads: int | None = None
    workers: int = 1
    variants: tuple[str, ...] = ("all",)
    #: Each policy name's options from the rollout flags (``--horizon``, ``--samples``, ``--forecast``, ``--model``).
    policy_options: dict = dataclasses.field(default_factory=dict)
    json: str | None = None


def _stats(xs: list[float]) -> dict:
    return {"median": statistics.median(xs), "min": min(xs), "max": max(xs)}


def peak_rss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


#: TLC LocationIDs of Manhattan except 103–105 (zone 103's polygon covers 103–105 in the TLC shapefile).
MANHATTAN_ZONES = (4, 12, 13, 24, 41, 42, 43, 45, 48, 50, 68, 74, 75, 79, 87, 88, 90, 100, 107, 113, 114, 116, 120, 125,
                   127, 128, 137, 140, 141, 142, 143, 144, 148, 151, 152, 153, 158, 161, 162, 163, 164, 166, 170, 186, 194,
                   202, 209, 211, 224, 229, 230, 231, 232, 233, 234, 236, 237, 238, 239, 243, 244, 246, 249, 261, 262, 263)


SHORTCUT_NAMES = tuple(f.name for f in dataclasses.fields(Shortcuts))


def shortcut_variant(name: str):
    """``all`` (the defaults), ``none``, ``no-NAME`` or ``with-NAME`` as :class:`agents.shortcuts.Shortcuts`.

    ``with-NAME`` turns on a saving that is off by default (``minute_lists``); a bad name is a :class:`ConfigError`.
    """
    from city.errors import ConfigError

    if name == "all":
        return Shortcuts()
    if name == "none":
        return Shortcuts.none()
    if name.startswith("no-") and name[3:] in SHORTCUT_NAMES:
        return Shortcuts(**{name[3:]: False})
    if name.startswith("with-") and name[5:] in SHORTCUT_NAMES:
        return Shortcuts(**{name[5:]: True})
    raise ConfigError(f"--variants: unknown variant {name!r}; choose all, none, no-NAME or with-NAME for NAME in {', '.join(SHORTCUT_NAMES)}")


def bench_city(cfg: CityBench) -> int:
    from city.graph import City
    from city.scenario import check_scenario
    from city.synthetic import synthetic_city

    builders = {"synthetic": synthetic_city}
    if cfg.data:
        from city.io.street_map import load_nyc_city

        data = check_scenario("nyc", cfg.data)
        builders["nyc"] = lambda: load_nyc_city(data)
    out: dict = {"schema": "surge.bench.city/1", "cpus": os.cpu_count(), "cities": {}}
    with steps(2 * cfg.repeat * len(builders), "run", "bench city") as bar:
        for name, build in builders.items():
            times, loads = [], []
            for _ in range(cfg.repeat):
                t0 = time.perf_counter()
                city = build()
                times.append(time.perf_counter() - t0)
                bar.update()
            path = Path(f"/tmp/surge-bench-{name}-{os.getpid()}.npz")
            city.save(path)
            for _ in range(cfg.repeat):
                t0 = time.perf_counter()
                City.load(path)
                loads.append(time.perf_counter() - t0)
                bar.update()
            size = path.stat().st_size / 2**20
            path.unlink()
            s = city.summary()
            out["cities"][name] = {"city": s, "build_seconds": _stats(times), "load_seconds": _stats(loads), "file_mb": size}
            echo(f"{name:<10} {s['intersections']:>5} nodes {s['streets']:>5} edges {s['sectors']:>3} sectors  "
                 f"build {statistics.median(times):6.2f} s (min {min(times):.2f})  load {statistics.median(loads) * 1e3:6.1f} ms  file {size:.1f} MB")
    if cfg.json:
        Path(cfg.json).write_text(json.dumps(out, indent=1))
    return 0


def bench_sim(cfg: SimBench) -> int:
    from agents.base import EpisodeContext, make_policy
    from city.episode import episode_requests, initial_positions
    from city.scenario import load_scenario
    from city.sim import FleetSim

    scen = load_scenario(cfg.scenario, cfg.data)
    date = dt.date.fromisoformat(cfg.date)
    requests = episode_requests(scen.world, date, cfg.hour, 60)
    policy = make_policy("greedy", scen.city)
    act, step, total = [], [], []
    with steps(cfg.episodes, "episode", "bench sim") as bar:
        for seed in range(cfg.episodes):
            sim = FleetSim(scen.city, requests, initial_positions(scen.city, cfg.taxis, seed))
            policy.reset(EpisodeContext(scen.city, date, cfg.hour, 60, seed, scen.world))
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
            bar.update()
    out = {
        "schema": "surge.bench.sim/1",
        "city": scen.city.summary(),
        "taxis": cfg.taxis,
        "requests": len(requests),
        "steps_per_second": _stats(total),
        "policy_ms_per_step": float(np.mean(act) * 1e3),
        "transition_ms_per_step": float(np.mean(step) * 1e3),
    }
    print(f"{cfg.scenario}: {cfg.taxis} taxis, {len(requests)} requests at {cfg.hour}:00 — "
          f"{statistics.median(total):.0f} steps/s (greedy {out['policy_ms_per_step']:.2f} ms + transition {out['transition_ms_per_step']:.2f} ms per step)")
    if cfg.json:
        Path(cfg.json).write_text(json.dumps(out, indent=1))
    return 0


def plan_state(scenario: str, data: str | None, date: dt.date, hour: int, taxis: int, seed: int, warmup: int,
               steps: int) -> tuple[Scenario, FleetSim, EpisodeContext]:
    """The mid-episode state that ``surge bench plan`` times: ``warmup`` minutes of greedy play from the seeded fleet.

    Returns the scenario, the simulator at the first timed step, and the
    episode's context (``warmup + steps + 1`` minutes) to reset a policy with.
    """
    from agents.base import EpisodeContext
    from agents.greedy import greedy_controls
    from city.episode import episode_requests, initial_positions
    from city.scenario import load_scenario
    from city.sim import FleetSim

    scen = load_scenario(scenario, data)
    minutes = warmup + steps + 1
    sim = FleetSim(scen.city, episode_requests(scen.world, date, hour, minutes), initial_positions(scen.city, taxis, seed))
    for _ in range(warmup):
        sim.step(greedy_controls(scen.city, sim.observe()))
    return scen, sim, EpisodeContext(scen.city, date, hour, minutes, seed, scen.world)


def _plan_child(cfg: PlanBench, label: str) -> dict:
    """Time ``label``'s planning in this (fresh) process; see :func:`bench_plan`."""
    import hashlib

    import numba

    from agents.base import make_policy, parse_policy
    from agents.waves import plan_waves
    from city.logs import inherit
    from coordinator.experiments.results import demand_source

    inherit()  # the parent's log level and one-line warnings, in this spawned process too
    if cfg.threads:
        numba.set_num_threads(cfg.threads)
    scen, sim, episode = plan_state(cfg.scenario, cfg.data, dt.date.fromisoformat(cfg.date), cfg.hour, cfg.taxis,
                                    cfg.seed, cfg.warmup, cfg.steps)
    name, own = parse_policy(label)
    options = {**cfg.policy_options.get(name, {}), **own}
    if cfg.workers > 1:
        options["workers"] = cfg.workers
    policy = make_policy(name, scen.city, **options)
    policy.reset(episode)
    rollout = getattr(policy, "config", None)
    variants = {v: shortcut_variant(v) for v in cfg.variants}
    # One untimed call loads the compiled kernels from numba's cache (or compiles them).
    t0 = time.perf_counter()
    policy.act(sim.observe())
    first = time.perf_counter() - t0
    per_variant: dict[str, dict] = {v: {"plan_seconds": [], "cpu_seconds": [], "settled_share": [], "shadow_share": [],
                                        "hashes": []} for v in variants}
    free, outstanding, critical = [], [], []
    for _ in range(cfg.steps):
        obs = sim.observe()
        n_free = int((obs.tau == 0).sum())
        free.append(n_free)
        outstanding.append(int(obs.req_index.size))
        # A central policy (match, rebalance) computes the joint control at once: one wave.
        critical.append(plan_waves(scen.city, obs, rollout.prune).critical_path if rollout else 1)
        applied = None
        for v, shortcuts in variants.items():
            policy.shortcuts = shortcuts
            t0, c0 = time.perf_counter(), time.process_time()
            u = policy.act(obs)
            rec = per_variant[v]
            rec["plan_seconds"].append(time.perf_counter() - t0)
            rec["cpu_seconds"].append(time.process_time() - c0)
            st = getattr(policy, "last_stats", None)
            rec["settled_share"].append(st.settled / st.decisions if st and st.decisions else 0.0)
            total = st.cand_samples + st.shadowed if st else 0
            rec["shadow_share"].append(st.shadowed / total if total else 0.0)
            rec["hashes"].append(hashlib.sha256(np.asarray(u, np.int32).tobytes()).hexdigest()[:16])
            if applied is None:
                applied = u
        sim.step(applied)
    out_variants = {}
    for v, rec in per_variant.items():
        per_free = [t / f if f else 0.0 for t, f in zip(rec["plan_seconds"], free)]
        out_variants[v] = {**rec, "plan_seconds_per_step": _stats(rec["plan_seconds"]),
                           "cpu_seconds_per_step": _stats(rec["cpu_seconds"]), "seconds_per_free_taxi": per_free}
    first_v = next(iter(out_variants.values()))
    return {
        **first_v,
        "variants": out_variants,
        "free_taxis": free,
        "outstanding_requests": outstanding,
        "critical_path": critical,
        "first_call_seconds": first,
        "threads": numba.get_num_threads(),
        "workers": cfg.workers,
        "peak_rss_mb": peak_rss_mb(),
        "rollout": dataclasses.asdict(rollout) if rollout else None,
        "approximations": rollout.approximations() if rollout else "exact",
        "city": scen.city.summary(),
        "demand_source": demand_source(scen.world),
    }


def pool_rounds(runs: list[dict]) -> dict:
    """One policy's runs of :func:`_plan_child` on the same states, pooled: every timed step of every run.

    ``round_medians`` keeps each run's median seconds per step, so a reader sees
    how far runs of one command differ on a noisy machine; ``same_in_every_round``
    whether every run made the first run's decisions.
    """
    res = {**runs[0], "variants": {}}
    for v, first in runs[0]["variants"].items():
        recs = [r["variants"][v] for r in runs]
        rec = {k: [x for r in recs for x in r[k]] for k in ("plan_seconds", "cpu_seconds", "settled_share", "shadow_share",
                                                            "seconds_per_free_taxi")}
        rec.update(hashes=first["hashes"], same_in_every_round=all(r["hashes"] == first["hashes"] for r in recs),
                   plan_seconds_per_step=_stats(rec["plan_seconds"]), cpu_seconds_per_step=_stats(rec["cpu_seconds"]),
                   round_medians=[r["plan_seconds_per_step"]["median"] for r in recs])
        res["variants"][v] = rec
    res.update(next(iter(res["variants"].values())))
    res["peak_rss_mb"] = max(r["peak_rss_mb"] for r in runs)
    return res


def bench_plan(cfg: PlanBench) -> int:
    """Planning seconds per step of each policy (rollout or central), each in a fresh ``spawn`` process.

    The fleet plays greedy for ``--warmup`` minutes from a seeded placement at
    ``--date --hour`` to reach a mid-episode state; then the policy plans
    ``--steps`` consecutive steps, which are applied.  Peak RSS is that of the
    planning process (scenario loading included).  With ``--rounds N`` every
    policy runs N times, the policies in turn, so that a slow spell of a shared
    machine falls on all of them; the steps of its runs are pooled.
    """
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    from agents.base import parse_policy, policy_names
    from city.errors import ConfigError
    from city.scenario import check_scenario

    check_scenario(cfg.scenario, cfg.data)
    for v in cfg.variants:
        shortcut_variant(v)
    unknown = [p for p in cfg.policies if parse_policy(p)[0] not in policy_names()]
    if unknown:
        raise ConfigError(f"unknown policy {unknown[0]!r}; choose from {', '.join(policy_names())}")
    out: dict = {
        "schema": "surge.bench.plan/1",
        "cpus": os.cpu_count(),
        "config": {k: getattr(cfg, k) for k in ("scenario", "date", "hour", "taxis", "horizon", "samples", "steps", "rounds", "warmup",
                                                 "seed", "forecast", "workers", "variants")},
        "policies": {},
    }
    runs: dict[str, list[dict]] = {name: [] for name in cfg.policies}
    with steps(cfg.rounds * len(cfg.policies), "run", "bench plan") as bar:
        for _ in range(cfg.rounds):
            for name in cfg.policies:
                with ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("spawn")) as pool:
                    runs[name].append(pool.submit(_plan_child, cfg, name).result())
                bar.update()
    for name in cfg.policies:
        res = pool_rounds(runs[name])
        out["city"] = res.pop("city")
        out["demand_source"] = res.pop("demand_source")
        out["policies"][name] = res
        plan = res["rollout"]
        what = f"{plan['base']} base, H={plan['horizon']}, {plan['samples']} samples, {res['approximations']}" if plan else "central"
        echo(f"{name} ({what}): free taxis {res['free_taxis']}, critical path {res['critical_path']} waves, "
             f"peak RSS {res['peak_rss_mb']:.0f} MB, first call {res['first_call_seconds']:.2f} s")
        for v, rec in res["variants"].items():
            st = rec["plan_seconds_per_step"]
            per_free = statistics.median(rec["seconds_per_free_taxi"]) * 1e3
            same = "same decisions" if rec["hashes"] == res["hashes"] and rec["same_in_every_round"] else "DIFFERENT decisions"
            rounds = f"  run medians {', '.join(f'{m:.3f}' for m in rec['round_medians'])}" if cfg.rounds > 1 else ""
            echo(f"  {v:<16} {st['median']:8.3f} s/step median (min {st['min']:.3f}, max {st['max']:.3f})  "
                 f"{per_free:6.2f} ms per free taxi  cpu {rec['cpu_seconds_per_step']['median']:.3f} s  "
                 f"settled {statistics.mean(rec['settled_share']):5.1%} of decisions, "
                 f"{statistics.mean(rec['shadow_share']):5.1%} of candidate samples  {same}{rounds}")
    pol = out["policies"]
    if "garces2023" in pol:
        for label in (p for p in pol if parse_policy(p)[0] == "surge"):
            ratio = pol["garces2023"]["plan_seconds_per_step"]["median"] / pol[label]["plan_seconds_per_step"]["median"]
            out.setdefault("garces2023_over", {})[label] = ratio
            print(f"garces2023 / {label} median time ratio: {ratio:.2f} ({label}: {pol[label]['approximations']}; "
                  f"garces2023: {pol['garces2023']['approximations']})")
    c = out["city"]
    flags = "".join(f", {k} {v} for every rollout policy" for k, v in (("H", cfg.horizon), ("samples", cfg.samples)) if v is not None)
    print(f"{cfg.scenario}: {c['intersections']} intersections, {cfg.taxis} taxis{flags}, "
          f"{cfg.date} {cfg.hour}:00 + {cfg.warmup} min, {os.cpu_count()} cpus, {cfg.workers} planning worker(s)")
    if cfg.json:
        Path(cfg.json).write_text(json.dumps(out, indent=1))
    return 0

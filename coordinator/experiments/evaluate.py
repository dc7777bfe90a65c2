"""The evaluation harness: replay city-hours under several policies and compare them.

One instance is (date, hour, seed): the requests come from the demand world
for that date and hour, and the seed draws the fleet's initial placement.
The rollout policies' random seed (and with it ``garces2023``'s
certainty-equivalence pools) is derived from the instance too
(:func:`instance_seed`), unless a policy spec fixes ``seed``.  Every policy
runs on the same instances, and both oracles always run too: wait overhead
per served request is measured against ``oracle`` (the reference oracle), and
the gap closed is reported against ``oracle`` and ``oracle-auction``.

Results files written before ``oracle`` became the route planner (they have
no ``reference_oracle`` field) are read with their ``oracle`` rows renamed
``oracle-auction``, which is what they ran; their wait overheads are then
measured against the auction, and the document says so.  Files written
before ``surge`` planned with approximations by default (they have no
``surge_defaults`` field) are read with the exact settings they planned with
pinned in every ``surge`` label's options (:func:`pin_surge_defaults`), so
that a run of today's defaults never resumes from, or borrows, their rows.
Results files record the world's ``demand_source`` (e.g. the real hourly
totals and zone profile it was built from, and the share); a run resumes
from, or borrows, rows of the same demand source only
(:func:`~coordinator.experiments.results.same_demand`).

A policy is named as in the registry, optionally with options:
``surge:forecast=true-rate,samples=500``; the whole string labels its rows,
so one run can compare a policy under several settings.  Long runs resume:
with a results file, finished instances are kept and each new one is written
as soon as it ends; the finished episodes of an unfinished instance wait
beside it (:func:`episode_dir`), so that an interrupted instance resumes
from them.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import hashlib
import inspect
import json
import logging
import signal
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from agents.base import make_policy, parse_policy
from city.episode import (
    EpisodeContext,
    episode_requests,
    initial_positions,
    run_episode,
)
from city.errors import DataError
from city.fingerprint import machine
from city.logs import inherit, steps
from city.scenario import scenario_spec
from city.sim import EpisodeResult
from coordinator.experiments.warm_start import warm_start_positions, warm_up_hour
from coordinator.experiments.results import (
    EPISODE_FIELDS,
    ORACLES,
    RESULTS_SCHEMA,
    by_instance,
    demand_source,
    episode_dir,
    episode_file,
    instance_key,
    instance_prefix,
    missing_field,
    pin_surge_defaults,
    read_results,
    recorded_source,
    same_demand,
    surge_defaults,
    write_json,
)

log = logging.getLogger(__name__)


@dataclass
class EvalConfig:
    scenario: str = "synthetic"
    data_dir: str | None = None
    dates: list[str] = field(default_factory=lambda: ["2022-11-17"])
    hours: list[int] = field(default_factory=lambda: [15, 17, 19, 21])
    seeds: int = 25
    taxis: int = 100
    minutes: int = 60
    policies: list[str] = field(default_factory=lambda: ["greedy", "ia", "oracle"])
    policy_options: dict[str, dict] = field(default_factory=dict)
    world_seed: int = 0
    jobs: int = 1
    cluster: str | None = None
    #: Each policy starts where its own previous hour left the fleet (:mod:`coordinator.experiments.warm_start`).
    warm_start: bool = False


def instance_seed(date: str | dt.date, hour: int, seed: int) -> int:
    """A 31-bit seed of the instance (date, hour, seed), so that instances draw independent random numbers."""
    text = f"{dt.date.fromisoformat(str(date)).isoformat()}|{int(hour)}|{int(seed)}"
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:4], "little") & 0x7FFFFFFF


def takes_rollout_seed(name: str) -> bool:
    from agents.base import policy_class

    return "seed" in inspect.signature(getattr(policy_class(name), "rollout_config", lambda: None)).parameters


def _instance(cfg: EvalConfig, date_text: str, hour: int, seed: int, known: dict[str, dict] | None = None,
              keep_to: str | None = None) -> list[dict]:
    """All policies (and both oracles) on one instance; rows for the requested policies.

    ``known`` holds rows of this instance already computed under the same
    settings (:func:`borrowable`): they are kept as they are, and with them the
    oracles' costs, so neither those policies nor the oracles run again.  The
    oracles and ``greedy`` run first, so that every other episode's row is
    whole when it ends: with ``keep_to`` (see :func:`episode_dir`) it is written
    there at once, and an interrupted instance resumes from its finished episodes.
    """
    known = dict(known or {})
    date = dt.date.fromisoformat(date_text)
    scen = _scenario_cache(cfg, date.year)
    requests = episode_requests(scen.world, date, hour, cfg.minutes)
    start = initial_positions(scen.city, cfg.taxis, seed)
    context = EpisodeContext(city=scen.city, date=date, hour=hour, minutes=cfg.minutes, seed=seed, world=scen.world)
    first = ([] if known else list(ORACLES)) + (["greedy"] if "greedy" in cfg.policies else [])
    labels = [p for p in dict.fromkeys(first + cfg.policies) if p not in known]
    runs_first = [p for p in dict.fromkeys(first) if p not in known]
    results: dict[str, EpisodeResult] = {}

    def total(label: str) -> int:
        return known[label]["total_cost"] if label in known else results[label].total_cost

    for label in labels:
        t0 = time.perf_counter()
        begin = start
        if cfg.warm_start:
            wdate = warm_up_hour(date, hour)[0]
            begin = warm_start_positions(scen.city, _scenario_cache(cfg, wdate.year).world,
                                         lambda d, h, label=label: _policy(cfg, label, scen.city, d, h, seed),
                                         date, hour, cfg.taxis, seed)
        results[label] = run_episode(scen.city, _policy(cfg, label, scen.city, date, hour, seed), requests, begin, context)
        log.info("  %s hour %d seed %d: %s %d (%.0f s)", date_text, hour, seed, label, results[label].total_cost, time.perf_counter() - t0)
        if any(p not in results for p in runs_first):
            continue  # a row carries both oracles' costs and greedy's
        some = next(iter(known.values()), None)
        oracles = (some["oracle_cost"], some["oracle_auction_cost"]) if some else (total("oracle"), total("oracle-auction"))
        greedy = total("greedy") if "greedy" in cfg.policies else None
        for done in [p for p in results if p in cfg.policies and p not in known]:
            known[done] = _row(date_text, hour, seed, done, results[done], *oracles, greedy)
            if keep_to is not None:
                write_json({"config": asdict(cfg), "surge_defaults": surge_defaults(),
                            "demand_source": demand_source(_scenario_cache(cfg).world), "row": known[done]},
                           Path(keep_to) / episode_file(date_text, hour, seed, done))
    return [dict(known[name]) for name in cfg.policies]


def _policy(cfg: EvalConfig, label: str, city: object, date: dt.date, hour: int, seed: int) -> object:
    """The policy of ``label`` with the run's options, its rollout seed drawn from the instance unless the label fixes one."""
    name, options = parse_policy(label)
    options = {**cfg.policy_options.get(label, {}), **options}
    if "seed" not in options and takes_rollout_seed(name):
        options["seed"] = instance_seed(date, hour, seed)
    return make_policy(name, city, **options)


def _row(date_text: str, hour: int, seed: int, name: str, r: EpisodeResult, oracle_cost: int, auction_cost: int,
         greedy_cost: int | None) -> dict:
    return {
        "date": date_text,
        "hour": hour,
        "seed": seed,
        "policy": name,
        "total_cost": r.total_cost,
        "outstanding_end": r.outstanding_end,
        "served": r.served,
        "requests": r.n_requests,
        "wait_overhead_per_served": (r.total_cost - oracle_cost) / max(r.served, 1),
        "oracle_cost": oracle_cost,
        "oracle_auction_cost": auction_cost,
        "greedy_cost": greedy_cost,
        "plan_seconds_per_step": float(np.mean(r.plan_seconds)),
        "plan_cpu_seconds_per_step": float(np.mean(r.plan_cpu_seconds)),
        "machine": machine(),
        "decisions_sha256": r.decisions_sha256,
    }


def _instance_task(task: tuple) -> list[dict]:
    return _instance(*task)


_SAME_EPISODES = ("scenario", "data_dir", "taxis", "minutes", "world_seed")


def _data_path_matters(cfg: EvalConfig) -> bool:
    """Whether ``cfg``'s rows depend on its ``--data`` path: the synthetic city reads no data, so its rows do not."""
    return scenario_spec(cfg.scenario, cfg.data_dir, validate=False) is not None


def borrowable(cfg: EvalConfig, doc: dict) -> dict[tuple[str, int, int], dict[str, dict]]:
    """Rows of the results document ``doc`` that ``cfg`` would compute identically, by instance and policy label.

    Episodes are deterministic in (instance, label, options), so a row can be
    reused when the scenario, fleet, episode length, start rule and world are the same,
    the label's options are the same, and so are both oracles' (every row
    carries their costs).  Nothing is borrowed otherwise.
    """
    theirs = doc["config"]
    if any(getattr(cfg, k) != theirs.get(k) for k in _SAME_EPISODES if k != "data_dir"):
        return {}
    if cfg.data_dir != theirs.get("data_dir") and _data_path_matters(cfg):
        return {}
    if cfg.warm_start != bool(theirs.get("warm_start", False)):
        return {}
    if not same_demand(recorded_source(doc), demand_source(_scenario_cache(cfg).world)):
        return {}
    opts = theirs.get("policy_options", {})
    if any(cfg.policy_options.get(o) != opts.get(o) for o in ORACLES):
        return {}
    labels = {p for p in cfg.policies if p in theirs.get("policies", []) and cfg.policy_options.get(p) == opts.get(p)}
    return by_instance(e for e in doc["episodes"] if e["policy"] in labels)


_SCENARIOS: dict = {}


def _scenario_cache(cfg: EvalConfig, year: int | None = None):
    """The scenario with its demand world for ``year`` (default: the first date's), built once per process."""
    from city.scenario import load_scenario

    year = year if year is not None else dt.date.fromisoformat(cfg.dates[0]).year
    key = (cfg.scenario, cfg.data_dir, cfg.world_seed, year)
    if key not in _SCENARIOS:
        _SCENARIOS[key] = load_scenario(cfg.scenario, cfg.data_dir, year=year, seed=cfg.world_seed)
    return _SCENARIOS[key]


_RESUME_FREE = ("seeds", "jobs", "cluster")


def load_finished(cfg: EvalConfig, path: str | Path) -> list[dict]:
    """Episodes of an earlier run of the same configuration (any seed count), to resume from.

    The run may add policies to the earlier one's: its instances then keep
    their rows and run only the new labels.  It may not drop any, so that
    resuming never discards a finished row.
    """
    doc = read_results(path)
    mine = {k: v for k, v in asdict(cfg).items() if k not in _RESUME_FREE}
    theirs = {k: v for k, v in doc.get("config", {}).items() if k not in _RESUME_FREE}
    if doc.get("reference_oracle") != "oracle":
        raise DataError("was written when 'oracle' was the auction; use another --json", path=path)
    if cfg.warm_start != bool(theirs.get("warm_start", False)):
        kinds = {True: "warm-start", False: "cold-start"}
        raise DataError(f"holds {kinds[not cfg.warm_start]} results, this run is {kinds[cfg.warm_start]}; "
                        "they do not mix: use another --json", path=path)
    theirs["warm_start"] = cfg.warm_start
    if not _data_path_matters(cfg):
        theirs["data_dir"] = mine["data_dir"]
    ours = demand_source(_scenario_cache(cfg).world)
    if not same_demand(recorded_source(doc), ours):
        raise DataError(f"was written with demand source {recorded_source(doc)!r}, this run has {ours!r}; use another --json", path=path)
    old = theirs.get("policies", [])
    if set(old) <= set(mine["policies"]):
        theirs["policies"] = mine["policies"]
        mine["policy_options"] = {p: o for p, o in mine["policy_options"].items() if p in old or p in ORACLES}
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
    borrow: dict | None = None,
) -> dict:
    """Run every (hour, seed) instance and return the ``surge.results/1`` document.

    With ``checkpoint``, the results file is rewritten after every finished
    instance; with ``resume`` too, the instances it already holds are kept,
    not rerun.  ``borrow``, another results document, lends the rows it holds
    under the same settings (:func:`borrowable`) instead of running them again.
    """
    progress = progress or log.info
    scen = _scenario_cache(cfg)
    for label in dict.fromkeys(cfg.policies):  # fail on a bad name or option now, not in a worker an hour in
        name, options = parse_policy(label)
        make_policy(name, scen.city, **{**cfg.policy_options.get(label, {}), **options})
    episodes: list[dict] = []
    grid = [(d, h, s) for d in cfg.dates for h in cfg.hours for s in range(cfg.seeds)]
    # Instances of the checkpoint that lack some policies' rows (see coordinator.experiments.reproduce's
    # --refresh-model) keep the rows they have and run only the rest.
    pending: dict[tuple[str, int, int], dict[str, dict]] = {}
    # Rows of the checkpoint outside this run's instances (more seeds than it asks for) stay in the file.
    beyond: list[dict] = []
    if resume and checkpoint is not None and Path(checkpoint).exists():
        wanted = set(grid)
        finished = load_finished(cfg, checkpoint)
        beyond = [e for e in finished if instance_key(e) not in wanted]
        held = by_instance(e for e in finished if instance_key(e) in wanted)
        for key, rows in held.items():
            if set(cfg.policies) <= rows.keys():
                episodes.extend(rows.values())
            else:
                pending[key] = rows
        if held:
            progress(f"resuming from {checkpoint}: {len(held) - len(pending)} instances done"
                     + (f", {len(pending)} with some of their rows" if pending else ""))
    done = {instance_key(e) for e in episodes}
    # Seed by seed across the dates and hours, so that a run cut short has every hour at the same depth.
    tasks = [(d, h, s) for s in range(cfg.seeds) for d in cfg.dates for h in cfg.hours if (d, h, s) not in done]
    lent = borrowable(cfg, borrow) if borrow else {}
    keep_to = episode_dir(checkpoint) if checkpoint is not None and not cfg.cluster else None
    kept = kept_episodes(cfg, keep_to, progress) if keep_to is not None and resume else {}
    if any(t in kept for t in tasks):
        progress(f"{sum(len(kept[t]) for t in tasks if t in kept)} finished episodes of unfinished instances are kept ({keep_to})")
    for key, rows in [*kept.items(), *pending.items()]:
        lent[key] = {**lent.get(key, {}), **rows}
    lent_rows = sum(len(lent.get(t, {})) for t in tasks)
    if lent_rows:
        progress(f"{lent_rows} rows of the {len(tasks)} instances to run are known already (same settings): they are not run again")
    log.debug("%d instances to run (%d done), %s", len(tasks), len(done),
              f"on the Dask cluster at {cfg.cluster}" if cfg.cluster else f"{cfg.jobs} worker process(es)")
    t0 = time.perf_counter()

    def document() -> dict:
        order = {k: i for i, k in enumerate(grid)}
        return {
            "schema": RESULTS_SCHEMA,
            "scenario": cfg.scenario,
            "reference_oracle": "oracle",
            "warm_start": cfg.warm_start,
            "surge_defaults": surge_defaults(),
            "demand_source": demand_source(scen.world),
            "city": scen.city.summary(),
            "config": asdict(cfg),
            "episodes": sorted(episodes + [e for rows in pending.values() for e in rows.values()], key=lambda e: order[instance_key(e)]) + beyond,
        }

    def report(k: int, rows: list[dict]) -> None:
        pending.pop(instance_key(rows[0]), None)
        episodes.extend(rows)
        head = rows[0]
        if checkpoint is not None:
            write_json(document(), checkpoint)
            if keep_to is not None:
                for path in keep_to.glob(instance_prefix(head["date"], head["hour"], head["seed"]) + "*.json"):
                    path.unlink()
        costs = " ".join(f"{r['policy']}={r['total_cost']}" for r in rows)
        progress(f"[{k}/{len(tasks)}] {head['date']} hour {head['hour']} seed {head['seed']}: {costs} ({time.perf_counter() - t0:.1f} s)")

    if keep_to is not None:
        keep_to.mkdir(parents=True, exist_ok=True)
    with contextlib.closing(run_instances(cfg, tasks, lent, keep_to)) as results, \
            steps(len(tasks), "instance", "evaluate") as bar:  # closed at once on any error: workers stop
        for k, rows in enumerate(results, 1):
            report(k, rows)
            bar.update()
    if keep_to is not None:
        with contextlib.suppress(OSError):
            keep_to.rmdir()  # all finished; a file it still holds (another run's) keeps it
    return document()


def run_instances(cfg: EvalConfig, tasks: list[tuple[str, int, int]], known: dict | None = None,
                  keep_to: Path | None = None) -> Iterator[list[dict]]:
    """The rows of each ``(date, hour, seed)`` instance, in task order: in this process, in a pool of
    ``cfg.jobs`` worker processes, or on the Dask cluster at ``cfg.cluster``; ``known`` rows by instance are kept,
    and each finished episode is written to ``keep_to`` (not on a cluster, whose workers may be other machines)."""
    known = known or {}
    keep = None if keep_to is None or cfg.cluster else str(keep_to)
    work = [(cfg, *t, known.get(t), keep) for t in tasks]
    if cfg.cluster:
        from coordinator.experiments.sweeps import run_on_cluster

        yield from run_on_cluster(cfg.cluster, _instance_task, work)
    elif cfg.jobs > 1:
        import multiprocessing as mp
        import os

        # Workers share the cores: each gets its slice for the compiled rollout kernels. The
        # variable is set only while the workers are spawned (they inherit it): numba re-reads
        # it in this process at its next compile and refuses a change once its threads run.
        previous = os.environ.get("NUMBA_NUM_THREADS")
        os.environ["NUMBA_NUM_THREADS"] = previous or str(max(1, (os.cpu_count() or 1) // cfg.jobs))
        # A Pool, not a ProcessPoolExecutor: leaving the block for any reason (an error,
        # Ctrl-C, SIGTERM turned into SystemExit by the CLI) terminates the workers at once
        # instead of waiting for their instances or leaving them orphaned. Workers ignore
        # SIGINT so that Ctrl-C reaches only this process, which then stops them (_worker_init).
        try:
            pool = mp.get_context("spawn").Pool(cfg.jobs, initializer=_worker_init)
        finally:
            if previous is None:
                del os.environ["NUMBA_NUM_THREADS"]
        with pool:
            yield from pool.imap(_instance_task, work)
    else:
        yield from map(_instance_task, work)




def _worker_init() -> None:
    """A pool worker: Ctrl-C reaches only the parent, which stops the pool; messages at the parent's level, one line each."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    inherit()


def kept_episodes(cfg: EvalConfig, folder: Path, warn: Callable[[str], None]) -> dict[tuple[str, int, int], dict[str, dict]]:
    """The rows in ``folder`` that ``cfg`` would compute identically (:func:`borrowable`), by instance; a broken file is named and skipped."""
    out: dict[tuple[str, int, int], dict[str, dict]] = {}
    for path in sorted(folder.glob("*.json")) if folder.is_dir() else []:
        try:
            saved = json.loads(path.read_text())
            doc = {"config": pin_surge_defaults(saved["config"], saved.get("surge_defaults")), "episodes": [saved["row"]],
                   **({"demand_source": saved["demand_source"]} if "demand_source" in saved else {})}
            missing = missing_field(saved["row"], ("date", *EPISODE_FIELDS))
            if missing:
                raise KeyError(missing)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            warn(f"{path}: not a finished episode ({type(exc).__name__}: {exc}); it runs again")
            continue
        for key, rows in borrowable(cfg, doc).items():
            out.setdefault(key, {}).update(rows)
    return out

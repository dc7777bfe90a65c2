"""``surge reproduce``: the paper's experiment end to end, resumable, with its report.

Steps, each showing progress on stderr:

1. train the demand predictor (or reuse one already trained in ``OUT/model``);
2. the predictor's percent-error comparison (``surge predictor eval``);
3. the main comparison on the paper's date 2022-11-17: hours 15, 17, 19 and
   21, 25 initial states, 100 taxis, 60 minutes: greedy, ia, garces2023
   (previous-hour demand), the practical baselines match and rebalance
   (rebalance with surge's forecast), surge (the trained model), oracle
   and oracle-auction;
4. the same policies at 17 and 19 h on further weekdays of the test months
   with evening events, 10 initial states each;
5. the ablations on 10 seeds at 17 and 19 h: both rollout policies with the
   same information (previous hour, the model, true rates), surge with base
   ``ia``, surge sampling the whole map, garces2023 with the model and each
   part of surge's certainty equivalence (:data:`CE_LABELS`), and pruning off for both (pruned and
   unpruned at the protocol's ``prune_samples``); the main
   policies' rows and the oracles of these instances are taken from step 3;
6. ``OUT/REPORT.md`` with its figures (:mod:`coordinator.report_md`).

Both rollout policies plan exactly, as the paper's do: every ``surge`` label
turns ``surge``'s default approximations off (:func:`_policy_options`).

Every evaluation checkpoints its ``surge.results/1`` file under ``OUT`` after
each instance and resumes from it, so an interrupted run continues where it
stopped.  ``--quick`` runs 5 seeds on the paper's date only, fewer ablation
seeds, 100 rollout samples and a small predictor.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime as dt
import hashlib
import json
import os
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

from city.errors import ConfigError

PAPER_DATE = "2022-11-17"


@dataclass(frozen=True)
class Protocol:
    """The sizes of a reproduction run."""

    hours: tuple[int, ...] = (15, 17, 19, 21)
    seeds: int = 25
    other_dates: int = 2
    other_hours: tuple[int, ...] = (17, 19)
    other_seeds: int = 10
    ablation_hours: tuple[int, ...] = (17, 19)
    ablation_seeds: int = 10
    taxis: int = 100
    minutes: int = 60
    samples: int | None = None
    oracle_iters: int | None = None
    epochs: int = 100
    event_epochs: int | None = None
    #: Reviews read per event by the predictor (the paper's Q_max; None: the default, 100).
    max_reviews: int | None = None
    #: Hidden widths of the standard and event-sector networks (None: the paper's 256,256 and 4096,4096).
    hidden: tuple[int, ...] | None = None
    event_hidden: tuple[int, ...] | None = None
    #: Rollout samples of the pruning ablation, pruned and unpruned alike. Unpruned, ``garces2023``
    #: samples the whole map for every decision: about 250 s of planning per episode at 100 samples
    #: on 2 cores, so some 40 minutes at the default 1,000, for each of the 20 ablation instances.
    prune_samples: int = 100
    predictor: bool = True
    jobs: int = 1
    gif_minutes: int = 60


FULL = Protocol()
#: The small predictor reads 5 reviews per event (half the texts to embed) and has the widths of the
#: full run's committed predictor (128,128 and 512,512). The pruning pair runs at 30 samples: unpruned
#: ``garces2023`` at 100 samples alone took about 250 s per episode, the quick run's longest step.
QUICK = Protocol(seeds=5, other_dates=0, ablation_hours=(19,), ablation_seeds=2, samples=100, epochs=5, event_epochs=1, max_reviews=5,
                 hidden=(128, 128), event_hidden=(512, 512), prune_samples=30, gif_minutes=30)
#: Seconds' worth, for the CI smoke test: no predictor (training embeds a year of event texts), so
#: ``surge`` plans with the true rates there and the report says so.
SMOKE = Protocol(hours=(19,), seeds=1, other_dates=0, ablation_hours=(19,), ablation_seeds=1, taxis=8, minutes=6,
                 samples=4, oracle_iters=20, epochs=1, predictor=False, gif_minutes=4)

#: ``match`` and ``rebalance`` are the practical baselines; ``rebalance`` plans with ``surge``'s forecast (:func:`_policy_options`).
MAIN_POLICIES = ("greedy", "ia", "garces2023", "match", "rebalance", "surge")
#: ``garces2023`` with the model, its standard certainty equivalence changed in both parts and in one: random counts
#: and places drawn from the distributions (``limited``, ``surge``'s), and only the places (``counts``). Between them,
#: ``garces2023:forecast=model`` and ``surge:base=ia``, the pools, the counts and the sampling scope are told apart.
CE_LABELS = ("garces2023:forecast=model,ce=limited", "garces2023:forecast=model,ce=counts")
ABLATIONS = (
    "surge:forecast=previous-hour",
    "surge:forecast=true-rate",
    "garces2023:forecast=model",
    "garces2023:forecast=true-rate",
    "surge:base=ia",
    "surge:scope=map",
    *CE_LABELS,
)


def pruning_pairs(protocol: Protocol) -> list[tuple[str, str]]:
    """``(unpruned, pruned)`` labels of the pruning ablation for both rollout policies, at the protocol's ``prune_samples`` or fewer."""
    n = protocol.prune_samples
    if protocol.samples is not None and protocol.samples <= n:
        return [(f"{p}:prune=none", p) for p in ("surge", "garces2023")]
    return [(f"{p}:prune=none,samples={n}", f"{p}:samples={n}") for p in ("surge", "garces2023")]


@dataclass
class Run:
    """Where a reproduction writes, and what it has done."""

    out: Path
    scenario: str
    data: str | None
    protocol: Protocol
    model_dir: Path | None = None
    #: The command line as the user gave it, for the report.
    command: str | None = None
    log: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    #: Each step's seconds summed over the earlier invocations on this ``out`` (a resumed step costs little the second time).
    earlier: dict[str, float] = field(default_factory=dict)

    def say(self, msg: str) -> None:
        print(f"reproduce: {msg}", file=sys.stderr, flush=True)
        self.log.append(msg)

    def summed(self) -> dict[str, float]:
        """Each step's seconds over every invocation on ``out``, this one included."""
        return {k: self.earlier.get(k, 0.0) + self.timings.get(k, 0.0) for k in dict.fromkeys([*self.earlier, *self.timings])}

    @property
    def model(self) -> Path:
        return self.model_dir or self.out / "model"

    @property
    def forecast(self) -> str:
        """What ``surge`` plans with where a label names no forecast: the trained model, or the true rates without a predictor."""
        return "model" if self.protocol.predictor else "true-rate"


def evening_event_dates(world, n: int, exclude: str = PAPER_DATE, year: int = 2022) -> list[str]:
    """``n`` weekdays of the test months (September–December) with an event active at 19 h, spread evenly.

    Holidays are skipped; the choice looks only at the event calendar, never
    at demand or results.
    """
    if n <= 0:
        return []
    from city.calendar import holidays_for

    off = holidays_for(year)
    days = []
    d = dt.date(year, 9, 1)
    while d.year == year:
        if d.weekday() < 5 and d not in off and d.isoformat() != exclude:
            if world.events_active(dt.datetime.combine(d, dt.time(19))):
                days.append(d)
        d += dt.timedelta(days=1)
    if len(days) < n:
        raise ConfigError(f"only {len(days)} weekdays of Sep-Dec {year} have an evening event; {n} wanted")
    step = len(days) / n
    return [days[int(step * k + step / 2)].isoformat() for k in range(n)]


def _policy_options(run: Run, labels: list[str]) -> dict[str, dict]:
    """Per-label options: the trained model for every forecast=model (surge's default), the run's sample count, exact planning.

    ``rebalance`` plans with ``surge``'s forecast where its label names none,
    so that ``surge`` meets the practical baseline with the same information.

    Every ``surge`` label plans exactly (:data:`agents.rollout_policy.EXACT`),
    as the paper's method does and as ``garces2023`` does, so that the
    comparisons are like with like; ``surge``'s default approximations are
    measured apart (BENCHMARKS.md).
    """
    from agents.rollout_policy import pinned_options
    from coordinator.evaluate import parse_policy

    out = {}
    for label in labels:
        name, opts = parse_policy(label)
        o: dict = pinned_options(label)
        if name in ("surge", "garces2023", "rebalance"):
            if run.protocol.samples is not None and name != "rebalance":
                o["samples"] = run.protocol.samples
            forecast = opts.get("forecast", run.forecast if name in ("surge", "rebalance") else None)
            if forecast == "model":
                o["model"] = str(run.model)
            elif name in ("surge", "rebalance") and "forecast" not in opts:
                o["forecast"] = forecast
        if name == "oracle" and run.protocol.oracle_iters is not None:
            o["iters"] = run.protocol.oracle_iters
        if o:
            out[label] = o
    return out


def _evaluate(run: Run, name: str, dates: list[str], hours: tuple[int, ...], seeds: int, labels: list[str], borrow: dict | None = None) -> dict:
    from coordinator.evaluate import EvalConfig, evaluate

    p = run.protocol
    cfg = EvalConfig(scenario=run.scenario, data_dir=run.data, dates=dates, hours=list(hours), seeds=seeds, taxis=p.taxis,
                     minutes=p.minutes, policies=labels, policy_options=_policy_options(run, labels + ["oracle"]), jobs=p.jobs)
    path = run.out / f"results-{name}.json"
    run.say(f"{name}: {len(dates)} date(s) x {len(hours)} hour(s) x {seeds} seeds, {len(labels)} policies + both oracles -> {path}")
    with _timed(run, name):
        return evaluate(cfg, progress=lambda msg: run.say(f"{name} {msg}"), checkpoint=path, resume=True, borrow=borrow)


def _predictor_parser() -> argparse.ArgumentParser:
    """The ``predictor`` subcommands alone, so that reproduce drives them without importing the CLI."""
    from predictor.cli import add_parser

    parser = argparse.ArgumentParser(prog="surge")
    add_parser(parser.add_subparsers(dest="command", required=True))
    return parser


def _train(run: Run) -> None:
    if not run.protocol.predictor:
        run.say("no predictor in this protocol: surge plans with the true rates (an upper bound)")
        return
    if (run.model / "model.json").exists():
        run.say(f"reusing the trained predictor in {run.model}")
        return
    run.say(f"training the predictor ({run.protocol.epochs} epochs) into {run.model}")
    argv = ["predictor", "train", "--scenario", run.scenario, "--out", str(run.model), "--epochs", str(run.protocol.epochs)]
    if run.protocol.event_epochs is not None:
        argv += ["--event-epochs", str(run.protocol.event_epochs)]
    if run.protocol.max_reviews is not None:
        argv += ["--max-reviews", str(run.protocol.max_reviews)]
    for flag, widths in (("--hidden", run.protocol.hidden), ("--event-hidden", run.protocol.event_hidden)):
        if widths is not None:
            argv += [flag, ",".join(map(str, widths))]
    if run.data:
        argv += ["--data", run.data]
    args = _predictor_parser().parse_args(argv)
    with _timed(run, "train"):
        args.func(args)


def model_fingerprint(model: Path) -> str:
    """SHA-256 of a trained predictor's weights (its ``.pt`` and ``.npy`` files, not ``model.json``'s timestamps).

    The same training command gives the same bytes on one machine; another
    machine's arithmetic can give slightly different weights, and so different
    ``surge`` rows.
    """
    h = hashlib.sha256()
    for f in sorted(model.iterdir()):
        if f.is_file() and f.suffix in (".pt", ".npy"):
            h.update(f.name.encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


def _check_model(run: Run, refresh: bool) -> None:
    """Refuse to mix rows computed with two predictors: ``OUT/model.sha256`` names the one the results hold.

    With ``refresh``, the rows of every policy that plans with the model (and
    the predictor's evaluation) are dropped, so that only they run again with
    the predictor now in use; every other row is kept.
    """
    if not run.protocol.predictor:
        return
    path = run.out / "model.sha256"
    now = model_fingerprint(run.model)
    before = path.read_text().strip() if path.exists() else None
    results = sorted(run.out.glob("results-*.json"))
    if before != now and (before is not None or results):
        if not refresh:
            said = f"recorded {before[:12]}" if before else "not recorded"
            raise ConfigError(f"{run.out}: its results were computed with another predictor ({said}; {run.model} is {now[:12]}); "
                              "pass --refresh-model to rerun only the rows that use the predictor")
        _drop_model_rows(run, results)
    path.write_text(now + "\n")


def _drop_model_rows(run: Run, results: list[Path]) -> None:
    from coordinator.evaluate import read_results, write_json

    for path in results:
        doc = read_results(path)
        opts = doc["config"].get("policy_options", {})
        uses = {label for label in doc["config"]["policies"] if "model" in opts.get(label, {})}
        keep = [e for e in doc["episodes"] if e["policy"] not in uses]
        write_json({**doc, "episodes": keep}, path)
        run.say(f"{path.name}: dropped {len(doc['episodes']) - len(keep)} rows of {', '.join(sorted(uses)) or 'no policy'} (--refresh-model)")
    for name in ("predictor-eval.json", "fig-predictor-pe.png"):
        (run.out / name).unlink(missing_ok=True)


def _predictor_eval(run: Run) -> dict | None:
    if not run.protocol.predictor:
        return None
    path = run.out / "predictor-eval.json"
    if not path.exists():
        run.say("predictor percent error per hour (surge predictor eval)")
        args = _predictor_parser().parse_args(["predictor", "eval", "--model", str(run.model), "--json", str(path),
                                          "--plot", str(run.out / "fig-predictor-pe.png")])
        with _timed(run, "predictor_eval"):
            args.func(args)
    return json.loads(path.read_text())


def _steps(run: Run, dates: list[str]) -> dict[str, tuple[list[str], tuple[int, ...], int, list[str]]]:
    """Each evaluation step: its dates, hours, seeds and policy labels."""
    p = run.protocol
    ablations = [a for a in ABLATIONS if p.predictor or "forecast=model" not in a]
    ablations += [label for pair in pruning_pairs(p) for label in pair if label not in MAIN_POLICIES]
    steps = {"main": ([PAPER_DATE], p.hours, p.seeds, list(MAIN_POLICIES))}
    if dates:
        steps["dates"] = (dates, p.other_hours, p.other_seeds, list(MAIN_POLICIES))
    steps["ablation"] = ([PAPER_DATE], p.ablation_hours, p.ablation_seeds, list(MAIN_POLICIES) + ablations)
    return steps


def instances_done(doc: dict, labels: list[str]) -> int:
    """How many instances of a results document hold a row of every one of ``labels``."""
    from coordinator.evaluate import instance_key

    have: dict[tuple, set] = {}
    for e in doc["episodes"]:
        have.setdefault(instance_key(e), set()).add(e["policy"])
    return sum(1 for got in have.values() if set(labels) <= got)


def _interim_docs(run: Run, steps: dict) -> tuple[dict, list[str] | None]:
    """The results files as they stand, and one status line per step (instances done of those the protocol asks for); no status when all are done."""
    from coordinator.evaluate import read_results

    docs, status, complete = {}, [], True
    for name, (dates, hours, seeds, labels) in steps.items():
        path = run.out / f"results-{name}.json"
        planned = len(dates) * len(hours) * seeds
        if not path.exists():
            if name == "main":
                raise ConfigError(f"{path}: no results yet; run `surge reproduce` without --report-only first")
            docs[name] = {"episodes": [], "config": {"dates": dates}}
            status.append(f"{name}: 0 of {planned} instances (not started)")
            complete = False
            continue
        docs[name] = read_results(path)
        done = instances_done(docs[name], labels)
        status.append(f"{name}: {done} of {planned} instances")
        complete = complete and done == planned
    return docs, None if complete else status


def _save_timings(run: Run) -> None:
    from coordinator.evaluate import write_json

    write_json({"this invocation": run.timings, "all invocations": run.summed()}, run.out / "timings.json")


@contextlib.contextmanager
def _timed(run: Run, step: str) -> Iterator[None]:
    """Count a step's seconds in ``OUT/timings.json`` even when it stops midway (Ctrl-C, SIGTERM, an error): its finished work is kept, so its time is part of the run's."""
    t0 = time.perf_counter()
    try:
        yield
    finally:
        run.timings[step] = time.perf_counter() - t0
        _save_timings(run)


def reproduce(run: Run, refresh_model: bool = False, report_only: bool = False) -> Path:
    """Run every step (resuming what is done) and write ``OUT/REPORT.md``; returns its path.

    ``report_only`` runs nothing: it writes an interim report from the
    results files as they stand, which says how far each step has come.
    """
    from city.scenario import load_scenario
    from coordinator import report_md

    timings = run.out / "timings.json"
    if timings.exists():
        run.earlier = json.loads(timings.read_text()).get("all invocations", {})
    p = run.protocol
    t_all = time.perf_counter()
    status = None
    if report_only:
        if p.predictor and not (run.model / "model.json").exists():
            raise ConfigError(f"{run.model}: no trained predictor; the report's figures plan with it (pass --model)")
        _check_model(run, refresh=False)
        path = run.out / "predictor-eval.json"
        pe = json.loads(path.read_text()) if path.exists() else None
        scen = load_scenario(run.scenario, run.data)
        docs, status = _interim_docs(run, _steps(run, evening_event_dates(scen.world, p.other_dates)))
    else:
        run.out.mkdir(parents=True, exist_ok=True)
        _train(run)
        _check_model(run, refresh_model)
        pe = _predictor_eval(run)
        scen = load_scenario(run.scenario, run.data)
        docs = {}
        for name, (dates, hours, seeds, labels) in _steps(run, evening_event_dates(scen.world, p.other_dates)).items():
            docs[name] = _evaluate(run, name, dates, hours, seeds, labels, borrow=docs["main"] if name == "ablation" else None)
    run.say("figures and REPORT.md" + (" (interim)" if status else ""))
    t0 = time.perf_counter()
    report = report_md.write_report(run, scen, docs, pe, status)
    run.timings["report"] = time.perf_counter() - t0
    run.timings["total"] = time.perf_counter() - t_all
    if not report_only:
        _save_timings(run)
    run.say(f"wrote {report} in {run.timings['total']:.0f} s")
    return report


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("reproduce", help="the paper's experiment end to end (resumable), with OUT/REPORT.md")
    p.add_argument("--scenario", default="synthetic", help="synthetic (embedded) or nyc (needs --data)")
    p.add_argument("--data", default=None, help="data directory laid out like shared/data (for --scenario nyc)")
    p.add_argument("--out", default="reproduce-out", help="output directory; a rerun resumes from what it holds")
    p.add_argument("--quick", action="store_true", help="5 seeds, one date, 2 ablation seeds at 19 h, 100 samples (the pruning pair 30), small predictor (5 reviews per event)")
    p.add_argument("--smoke", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--jobs", type=int, default=None, help="worker processes for the evaluations (default: one per core)")
    p.add_argument("--model", default=None, help="reuse this trained predictor directory instead of training OUT/model")
    p.add_argument("--report-only", action="store_true",
                   help="run nothing: write OUT/REPORT.md from the results so far, saying how far each step has come")
    p.add_argument("--refresh-model", action="store_true",
                   help="the predictor changed since OUT's results: rerun only the rows that plan with it, keep the rest")
    p.set_defaults(func=cmd_reproduce)


def cmd_reproduce(args: argparse.Namespace) -> int:
    from city.scenario import check_scenario

    check_scenario(args.scenario, args.data)
    if args.jobs is not None and args.jobs < 1:
        raise ConfigError(f"--jobs must be at least 1, got {args.jobs}")
    jobs = args.jobs or (1 if args.smoke else os.cpu_count() or 1)
    protocol = SMOKE if args.smoke else QUICK if args.quick else FULL
    model = Path(args.model) if args.model else None
    if model is not None and not (model / "model.json").exists():
        raise ConfigError(f"--model {model}: no model.json there (train one with surge predictor train)")
    flags = [("--data", args.data), ("--out", args.out), ("--quick", args.quick), ("--smoke", args.smoke),
             ("--jobs", args.jobs), ("--model", args.model)]
    command = " ".join(["surge reproduce --scenario", args.scenario] + [f if v is True else f"{f} {v}" for f, v in flags if v])
    run = Run(out=Path(args.out), scenario=args.scenario, data=args.data, protocol=replace(protocol, jobs=jobs), model_dir=model,
              command=command)
    if args.report_only and args.refresh_model:
        raise ConfigError("--report-only runs nothing, so it cannot --refresh-model: choose one")
    print(reproduce(run, refresh_model=args.refresh_model, report_only=args.report_only))
    return 0

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
6. ``OUT/REPORT.md`` with its figures (:mod:`coordinator.experiments.report`).

Both rollout policies plan exactly, as the paper's do: every ``surge`` label
turns ``surge``'s default approximations off (:func:`policy_options`).

Every evaluation checkpoints its ``surge.results/1`` file under ``OUT`` after
each instance and resumes from it, so an interrupted run continues where it
stopped.  ``--quick`` runs 5 seeds on the paper's date only, fewer ablation
seeds, 100 rollout samples and a small predictor.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import hashlib
import json
import time
from collections.abc import Iterator
from pathlib import Path

from city.errors import ConfigError
from city.logs import steps
from coordinator.experiments.analysis import complete_seeds, plot, summarize
from coordinator.experiments.protocol import (
    ABLATIONS,
    MAIN_POLICIES,
    PAPER_DATE,
    Run,
    policy_options,
    pruning_pairs,
)


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


def _evaluate(run: Run, name: str, dates: list[str], hours: tuple[int, ...], seeds: int, labels: list[str], borrow: dict | None = None) -> dict:
    from coordinator.experiments.evaluate import EvalConfig, evaluate

    p = run.protocol
    cfg = EvalConfig(scenario=run.scenario, data_dir=run.data, dates=dates, hours=list(hours), seeds=seeds, taxis=p.taxis,
                     minutes=p.minutes, policies=labels, policy_options=policy_options(run, labels + ["oracle"]), jobs=p.jobs)
    path = run.out / f"results-{name}.json"
    run.say(f"{name}: {len(dates)} date(s) x {len(hours)} hour(s) x {seeds} seeds, {len(labels)} policies + both oracles -> {path}")
    with _timed(run, name):
        return evaluate(cfg, progress=lambda msg: run.say(f"{name} {msg}"), checkpoint=path, resume=True, borrow=borrow)


def _train(run: Run) -> None:
    if not run.protocol.predictor:
        run.say("no predictor in this protocol: surge plans with the true rates (an upper bound)")
        return
    if (run.model / "model.json").exists():
        run.say(f"reusing the trained predictor in {run.model}")
        return
    run.say(f"training the predictor ({run.protocol.epochs} epochs) into {run.model}")
    from predictor.jobs import TrainJob, train

    p = run.protocol
    job = TrainJob(out=str(run.model), scenario=run.scenario, data=run.data, epochs=p.epochs, event_epochs=p.event_epochs,
                   max_reviews=p.max_reviews, hidden=p.hidden, event_hidden=p.event_hidden)
    with _timed(run, "train"):
        train(job)


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
    from coordinator.experiments.results import read_results, write_json

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
        from predictor.jobs import EvalJob, evaluate_model

        with _timed(run, "predictor_eval"):
            evaluate_model(EvalJob(model=str(run.model), json=str(path), plot=str(run.out / "fig-predictor-pe.png")))
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
    from coordinator.experiments.results import instance_key

    have: dict[tuple, set] = {}
    for e in doc["episodes"]:
        have.setdefault(instance_key(e), set()).add(e["policy"])
    return sum(1 for got in have.values() if set(labels) <= got)


def _interim_docs(run: Run, steps: dict) -> tuple[dict, list[str] | None]:
    """The results files as they stand, and one status line per step (instances done of those the protocol asks for); no status when all are done."""
    from coordinator.experiments.results import read_results

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
    from coordinator.experiments.results import write_json

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
    from coordinator.experiments.report import write_report

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
        scen = load_scenario(run.scenario, run.data)
        todo = _steps(run, evening_event_dates(scen.world, p.other_dates))
        docs = {}
        with steps(2 + len(todo), "step", "reproduce") as bar:
            _train(run)
            _check_model(run, refresh_model)
            bar.update()
            pe = _predictor_eval(run)
            bar.update()
            for name, (dates, hours, seeds, labels) in todo.items():
                docs[name] = _evaluate(run, name, dates, hours, seeds, labels, borrow=docs["main"] if name == "ablation" else None)
                bar.update()
    run.say("figures and REPORT.md" + (" (interim)" if status else ""))
    t0 = time.perf_counter()
    report = write_report(run, scen, docs, pe, paper_figures(run, scen, complete_seeds(docs["main"])), status)
    run.timings["report"] = time.perf_counter() - t0
    run.timings["total"] = time.perf_counter() - t_all
    if not report_only:
        _save_timings(run)
    run.say(f"wrote {report} in {run.timings['total']:.0f} s")
    return report




def paper_figures(run, scen, main: dict) -> dict[str, str]:
    """Bars, the surge map and the GIF, in ``run.out``; returns their file names."""
    from agents.base import EpisodeContext, make_policy
    from city.episode import episode_requests, initial_positions
    from coordinator.experiments import figures
    from coordinator.experiments.evaluate import instance_seed

    out = run.out
    summary = summarize(main)
    plot(summary, out / "fig-total-cost.png", title=f"{run.scenario} {PAPER_DATE}: total cost")
    plot(summary, out / "fig-wait-overhead.png", title=f"{run.scenario} {PAPER_DATE}: wait overhead per served request (vs oracle)",
         metric="wait_overhead_per_served", ylabel="minutes per served request")
    city, world = scen.city, scen.world
    date, hour, seed, p = dt.date.fromisoformat(PAPER_DATE), 19, 0, run.protocol
    minutes = min(p.gif_minutes, p.minutes)
    req = episode_requests(world, date, hour, minutes)
    start = initial_positions(city, p.taxis, seed)
    ctx = EpisodeContext(city=city, date=date, hour=hour, minutes=minutes, seed=seed, world=world)
    opts = {**policy_options(run, ["surge"]).get("surge", {}), "seed": instance_seed(date, hour, seed)}
    tracks = [figures.track(city, make_policy("surge", city, **opts), req, start, ctx, "surge"),
              figures.track(city, make_policy("greedy", city), req, start, ctx, "greedy")]
    figures.surge_map(city, world, date, hour, tracks[0].pos[len(tracks[0].pos) // 2], out / "fig-surge-map.png")
    figures.surge_gif(city, req, tracks, out / "surge-vs-greedy.gif", f"{run.scenario} {PAPER_DATE} {hour}:00, {p.taxis} taxis, seed {seed}")
    return {"cost": "fig-total-cost.png", "overhead": "fig-wait-overhead.png", "map": "fig-surge-map.png", "gif": "surge-vs-greedy.gif"}

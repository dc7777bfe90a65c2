"""Training and evaluating the predictor as jobs: a dataclass in, files out.

The CLI (``surge predictor train|eval``) and ``surge reproduce`` both build a
:class:`TrainJob` or :class:`EvalJob` and run it here, so neither drives the
other's argument parser.  Nothing heavy is imported until a job runs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from city.errors import ConfigError


@dataclass(frozen=True)
class TrainJob:
    """What ``surge predictor train`` trains: the world it reads, the networks' sizes and the training settings."""

    out: str
    scenario: str = "synthetic"
    data: str | None = None
    epochs: int = 100
    event_epochs: int | None = None
    patience: int = 10
    hidden: tuple[int, ...] | None = None
    event_hidden: tuple[int, ...] | None = None
    window: tuple[int, int] | None = None
    max_reviews: int | None = None
    no_ablation: bool = False
    device: str = "auto"
    encoder: str | None = None
    seed: int = 0
    world_seed: int = 0
    year: int = 2022
    cache: str | None = None
    events: str | None = None
    reviews: str | None = None
    trips: tuple[str, ...] | None = None

    def check(self) -> None:
        """Every setting's error, before any world is built."""
        if self.epochs < 0:
            raise ConfigError("--epochs must be >= 0")
        if self.patience < 0:
            raise ConfigError("--patience must be >= 0")
        if self.max_reviews is not None and self.max_reviews < 1:
            raise ConfigError(f"--max-reviews must be at least 1, got {self.max_reviews}")
        if self.reviews and not self.events:
            raise ConfigError("--reviews needs --events (the reviews are of those events)")


@dataclass(frozen=True)
class EvalJob:
    """What ``surge predictor eval`` scores: a trained model on the test (or validation) months."""

    model: str
    json: str | None = None
    plot: str | None = None
    data: str | None = None
    cache: str | None = None
    bootstrap: int = 1000
    seed: int = 0
    part: str = "test"

    def check(self) -> None:
        if self.bootstrap < 1:
            raise ConfigError("--bootstrap must be >= 1")


def input_lines(world, trips, job, timezone: str) -> list[str]:
    """What training read, one line each: the events and the trips (files, rows kept and dropped) or the world's own."""
    if job.events:
        events = f"events: {len(world.events)} from {job.events}" + (f" with reviews from {job.reviews}" if job.reviews else "")
        events += f", local times in {timezone}"
    else:
        events = f"events: the scenario world's own ({len(world.events)})"
    if trips is not None:
        files = ", ".join(str(p) for p in job.trips)
        line = f"trips: {len(trips):,} kept of {trips.n_read:,} rows read from {files} ({trips.n_dropped:,} dropped: outside the city or without a time)"
    else:
        line = "trips: none read; hourly counts are the scenario world's own"
    return [events, line]


def train(job: TrainJob) -> None:
    """Embed the events and train every network of a predictor into ``job.out`` (resumable)."""
    from city.scenario import check_scenario, scenario_timezone
    from predictor.features import LAG_HOURS, LEAD_HOURS
    from predictor.inputs import load_world, record_inputs
    from predictor.model import train_model
    from predictor.nets import EVENT_HIDDEN, STANDARD_HIDDEN
    from predictor.spectral import Q_MAX
    from predictor.train import TrainConfig, log_line

    job.check()
    check_scenario(job.scenario, job.data)
    t0 = time.perf_counter()
    trip_files = list(job.trips) if job.trips else None
    world, trips = load_world(job.scenario, job.data, seed=job.world_seed, year=job.year, events=job.events, reviews=job.reviews, trips=trip_files)
    timezone = scenario_timezone(job.scenario, job.data)
    log_line(f"world: scenario {job.scenario}, {world.city.n_sectors} sectors, {len(world.events)} events, built in {time.perf_counter() - t0:.1f}s")
    for line in input_lines(world, trips, job, timezone):
        log_line(line)
    scenario = {
        "name": job.scenario,
        "data_dir": str(Path(job.data).resolve()) if job.data else None,
        "world_seed": job.world_seed,
        "year": job.year,
        "timezone": timezone,
    }
    Path(job.out).mkdir(parents=True, exist_ok=True)
    inputs = record_inputs(job.out, events=job.events, reviews=job.reviews, trips=trip_files)
    cfg = TrainConfig(epochs=job.epochs, seed=job.seed, patience=job.patience, device=job.device)
    lead, lag = job.window or (LEAD_HOURS, LAG_HOURS)
    train_model(
        world,
        job.out,
        cfg=cfg,
        encoder=job.encoder,
        cache_dir=job.cache,
        scenario=scenario,
        inputs=inputs,
        trips=trips,
        standard_hidden=job.hidden or STANDARD_HIDDEN,
        event_hidden=job.event_hidden or EVENT_HIDDEN,
        event_epochs=job.event_epochs,
        lead_hours=lead,
        lag_hours=lag,
        ablation=not job.no_ablation,
        q_max=job.max_reviews or Q_MAX,
        log=log_line,
    )


def evaluate_model(job: EvalJob) -> dict:
    """Percent error per hour of every network and baseline, with 95 % CIs; prints the table and writes what ``job`` asks."""
    from predictor.dataset import build_year_data
    from predictor.evaluate import evaluate, format_table, plot, write_json
    from predictor.inputs import world_for_model
    from predictor.model import DemandModel

    job.check()
    model = DemandModel.load(job.model)
    sc = model.meta.get("scenario") or {}
    world, _ = world_for_model(model.meta, job.model, job.data)
    lead, lag = model.window
    data = build_year_data(world, model.featurizer(job.cache), lead=lead, lag=lag, verbose=False)
    result = evaluate(model, data, part=job.part, n_boot=job.bootstrap, seed=job.seed)
    result["model"] = str(Path(job.model).resolve())
    result["scenario"] = sc
    result["inputs"] = model.meta.get("inputs") or {}
    print(format_table(result))
    if job.json:
        write_json(result, job.json)
        print(f"wrote {job.json}")
    if job.plot:
        months = "test months Sep-Dec" if job.part == "test" else "validation months Jul-Aug"
        plot(result, job.plot, title=f"Demand prediction PE, {sc['name']}, {months} {data.year}")
        print(f"wrote {job.plot}")
    return result


@dataclass(frozen=True)
class CeilingJob:
    """What ``surge predictor ceiling`` measures: a trained model's text against the ceiling of its world's drivers."""

    model: str
    json: str | None = None
    data: str | None = None
    cache: str | None = None
    bootstrap: int = 1000
    seed: int = 0
    #: Seed of the metadata, ceiling and reader networks' training (``None``: the model's).
    train_seed: int | None = None

    def check(self) -> None:
        if self.bootstrap < 1:
            raise ConfigError("--bootstrap must be >= 1")
        if self.train_seed is not None and self.train_seed < 0:
            raise ConfigError(f"--train-seed must be >= 0, got {self.train_seed}")

    def command(self) -> str:
        parts = ["surge predictor ceiling", "--model", self.model]
        parts += ["--json", self.json] if self.json else []
        parts += ["--data", self.data] if self.data else []
        parts += ["--bootstrap", str(self.bootstrap)] if self.bootstrap != 1000 else []
        parts += ["--seed", str(self.seed)] if self.seed else []
        parts += ["--train-seed", str(self.train_seed)] if self.train_seed is not None else []
        return " ".join(parts)


def text_ceiling(job: CeilingJob) -> dict:
    """Train the ceiling and text-reader networks beside a trained model, score all on the test months, print and write the table."""
    import datetime as dt
    import json
    import os
    import platform

    from predictor.ceiling import format_table, measure
    from predictor.dataset import build_year_data
    from predictor.inputs import world_for_model
    from predictor.model import DemandModel
    from predictor.train import log_line

    job.check()
    model = DemandModel.load(job.model)
    world, _ = world_for_model(model.meta, job.model, job.data)
    lead, lag = model.window
    featurizer = model.featurizer(job.cache, verbose=True)
    data = build_year_data(world, featurizer, lead=lead, lag=lag, verbose=True)
    result = {"question": "How much of what the event text could add does the event network, or a simpler reader, reach?",
              "command": job.command(), "date": dt.date.today().isoformat(), "machine": f"{os.cpu_count()}-vCPU {platform.machine()}",
              "scenario": model.meta.get("scenario") or {}, "model": str(Path(job.model)),
              **measure(model, world, data, featurizer, n_boot=job.bootstrap, seed=job.seed, train_seed=job.train_seed, log=log_line)}
    print(format_table(result))
    if job.json:
        Path(job.json).parent.mkdir(parents=True, exist_ok=True)
        Path(job.json).write_text(json.dumps(result, indent=1) + "\n")
        print(f"wrote {job.json}")
    return result

"""``surge predictor train|eval|serve``.  Nothing heavy is imported at module import time."""

from __future__ import annotations

import time
from pathlib import Path

from city.errors import ConfigError


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("predictor", help="train and evaluate the event-informed demand predictor")
    sub = p.add_subparsers(dest="predictor_command", required=True, metavar="{train,eval,serve}")

    t = sub.add_parser("train", help="embed events, train the no-event, event and standard networks (resumable)")
    t.add_argument("--scenario", default="synthetic", help="synthetic, nyc, manhattan or a scenario .toml file")
    t.add_argument("--data", default=None, help="data directory laid out like shared/data (for nyc, manhattan)")
    t.add_argument("--out", required=True, help="model directory to write (and resume from)")
    t.add_argument("--epochs", type=int, default=100, help="cap on the epochs of every network (paper: 100); each stops earlier on validation loss")
    t.add_argument("--event-epochs", type=int, default=None, help="epoch cap of the event-sector networks only (default: --epochs)")
    t.add_argument("--patience", type=int, default=10, help="stop a network this many epochs after its best validation loss (0: run the whole cap, keep the best epoch)")
    t.add_argument("--hidden", type=_widths, default=None, help="hidden widths of the standard and no-event networks, e.g. 256,256 (the paper's default)")
    t.add_argument("--event-hidden", type=_widths, default=None, help="hidden widths of the event-sector networks, e.g. 4096,4096 (the paper's default)")
    t.add_argument("--window", type=_window, default=None,
                   help="hours before an event's start and after its end in which it counts for its sector, LEAD,LAG (default 0,0, "
                        "chosen on the validation months)")
    t.add_argument("--max-reviews", type=int, default=None,
                   help="reviews read per event, the paper's Q_max (default 100); fewer embed faster, for a small predictor")
    t.add_argument("--no-ablation", action="store_true", help="train only the system's networks (skip the metadata and shuffled-text networks)")
    t.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"), help="embedding and training device (auto: CUDA where present)")
    t.add_argument("--encoder", default=None, help="sentence-transformers model name or path (default: bundled all-MiniLM-L6-v2)")
    t.add_argument("--seed", type=int, default=0, help="torch seed (initialisation and shuffles)")
    t.add_argument("--world-seed", type=int, default=0, help="seed of the synthetic demand world")
    t.add_argument("--year", type=int, default=2022)
    t.add_argument("--cache", default=None, help="cache root for embeddings (default $SURGE_CACHE or ~/.cache/surge)")
    t.add_argument("--events", default=None, help="event listing replacing the world's events: CSV/JSON (city.events.read_events) or NYC permitted-events CSV")
    t.add_argument("--reviews", default=None, help="reviews CSV (event_id,review) for --events")
    t.add_argument("--trips", nargs="+", default=None, help="HV-FHV trip parquet files: real hourly counts and β instead of the world's")
    t.set_defaults(func=train_main)

    e = sub.add_parser("eval", help="the ablation on the test months: percent error per hour 15-21 h of every network and baseline, with 95% CIs")
    e.add_argument("--model", required=True, help="trained model directory")
    e.add_argument("--json", default=None, help="write results as JSON here")
    e.add_argument("--plot", default=None, help="write a PNG line chart here")
    e.add_argument("--data", default=None, help="override the data directory recorded in the model")
    e.add_argument("--cache", default=None, help="embedding cache root")
    e.add_argument("--bootstrap", type=int, default=1000, help="bootstrap resamples of test days for the 95%% intervals")
    e.add_argument("--seed", type=int, default=0, help="seed of the bootstrap")
    e.add_argument("--part", choices=("test", "val"), default="test", help="months to score: test (Sep-Dec, the figures) or val (Jul-Aug, for design choices)")
    e.set_defaults(func=eval_main)

    from bus.session import add_session_args

    v = sub.add_parser("serve", help="answer a distributed run's forecast queries on the bus (torch stays in this process)")
    add_session_args(v)
    v.add_argument("--run", default="demo", help="run name (as the coordinator's --run)")
    v.add_argument("--scenario", default="synthetic", help="synthetic, nyc, manhattan or a scenario .toml file")
    v.add_argument("--data", default=None, help="data directory laid out like shared/data (for nyc, manhattan)")
    v.add_argument("--world-seed", type=int, default=0, help="seed of the demand world (as the coordinator's)")
    v.add_argument("--forecast", default="model", help="provider to serve: model (default), true-rate or previous-hour")
    v.add_argument("--model", default=None, help="trained model directory for --forecast model")
    v.set_defaults(func=serve_cmd)


def serve_cmd(args) -> int:
    from bus.session import session_args
    from predictor.serve import ForecastService, ServeConfig

    cfg = ServeConfig(run=args.run, scenario=args.scenario, data_dir=args.data, world_seed=args.world_seed,
                      forecast=args.forecast, model=args.model)
    ForecastService(cfg).run(session_args(args, identity="predictor"))
    return 0


def _widths(text: str) -> tuple[int, ...]:
    import argparse

    try:
        out = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of widths") from None
    if not out or min(out) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: widths must be positive integers")
    return out


def _window(text: str) -> tuple[int, int]:
    import argparse

    parts = text.split(",")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise argparse.ArgumentTypeError(f"{text!r} is not LEAD,LAG (two whole numbers of hours, e.g. 2,1)")
    lead, lag = (int(p) for p in parts)
    if lead > 6 or lag > 6:
        raise argparse.ArgumentTypeError(f"{text!r}: lead and lag are at most 6 hours")
    return lead, lag


# ---------------------------------------------------------------- handlers
def train_main(args) -> int:
    from city.scenario import check_scenario, scenario_timezone
    from predictor.inputs import load_world, record_inputs
    from predictor.cluster import Q_MAX
    from predictor.features import LAG_HOURS, LEAD_HOURS
    from predictor.model import train_model
    from predictor.nets import EVENT_HIDDEN, STANDARD_HIDDEN
    from predictor.train import TrainConfig, log_line

    if args.epochs < 0:
        raise ConfigError("--epochs must be >= 0")
    if args.patience < 0:
        raise ConfigError("--patience must be >= 0")
    if args.max_reviews is not None and args.max_reviews < 1:
        raise ConfigError(f"--max-reviews must be at least 1, got {args.max_reviews}")
    if args.reviews and not args.events:
        raise ConfigError("--reviews needs --events (the reviews are of those events)")
    check_scenario(args.scenario, args.data)
    t0 = time.perf_counter()
    world, trips = load_world(args.scenario, args.data, seed=args.world_seed, year=args.year, events=args.events, reviews=args.reviews, trips=args.trips)
    timezone = scenario_timezone(args.scenario, args.data)
    log_line(f"world: scenario {args.scenario}, {world.city.n_sectors} sectors, {len(world.events)} events, built in {time.perf_counter() - t0:.1f}s")
    for line in input_lines(world, trips, args, timezone):
        log_line(line)
    scenario = {
        "name": args.scenario,
        "data_dir": str(Path(args.data).resolve()) if args.data else None,
        "world_seed": args.world_seed,
        "year": args.year,
        "timezone": timezone,
    }
    Path(args.out).mkdir(parents=True, exist_ok=True)
    inputs = record_inputs(args.out, events=args.events, reviews=args.reviews, trips=args.trips)
    cfg = TrainConfig(epochs=args.epochs, seed=args.seed, patience=args.patience, device=args.device)
    lead, lag = args.window or (LEAD_HOURS, LAG_HOURS)
    train_model(
        world,
        args.out,
        cfg=cfg,
        encoder=args.encoder,
        cache_dir=args.cache,
        scenario=scenario,
        inputs=inputs,
        trips=trips,
        standard_hidden=args.hidden or STANDARD_HIDDEN,
        event_hidden=args.event_hidden or EVENT_HIDDEN,
        event_epochs=args.event_epochs,
        lead_hours=lead,
        lag_hours=lag,
        ablation=not args.no_ablation,
        q_max=args.max_reviews or Q_MAX,
        log=log_line,
    )
    return 0


def input_lines(world, trips, args, timezone: str) -> list[str]:  # noqa: ANN001 - a demand world, a TripTable, parsed flags
    """What training read, one line each: the events and the trips (files, rows kept and dropped) or the world's own."""
    if args.events:
        events = f"events: {len(world.events)} from {args.events}" + (f" with reviews from {args.reviews}" if args.reviews else "")
        events += f", local times in {timezone}"
    else:
        events = f"events: the scenario world's own ({len(world.events)})"
    if trips is not None:
        files = ", ".join(str(p) for p in args.trips)
        line = f"trips: {len(trips):,} kept of {trips.n_read:,} rows read from {files} ({trips.n_dropped:,} dropped: outside the city or without a time)"
    else:
        line = "trips: none read; hourly counts are the scenario world's own"
    return [events, line]


def eval_main(args) -> int:
    from predictor.dataset import build_year_data
    from predictor.evaluate import evaluate, format_table, plot, write_json
    from predictor.inputs import world_for_model
    from predictor.model import DemandModel

    if args.bootstrap < 1:
        raise ConfigError("--bootstrap must be >= 1")
    model = DemandModel.load(args.model)
    sc = model.meta.get("scenario") or {}
    world, _ = world_for_model(model.meta, args.model, args.data)
    lead, lag = model.window
    data = build_year_data(world, model.featurizer(args.cache), lead=lead, lag=lag, verbose=False)
    result = evaluate(model, data, part=args.part, n_boot=args.bootstrap, seed=args.seed)
    result["model"] = str(Path(args.model).resolve())
    result["scenario"] = sc
    result["inputs"] = model.meta.get("inputs") or {}
    print(format_table(result))
    if args.json:
        write_json(result, args.json)
        print(f"wrote {args.json}")
    if args.plot:
        months = "test months Sep-Dec" if args.part == "test" else "validation months Jul-Aug"
        plot(result, args.plot, title=f"Demand prediction PE, {sc['name']}, {months} {data.year}")
        print(f"wrote {args.plot}")
    return 0

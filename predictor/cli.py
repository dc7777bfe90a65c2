"""``surge predictor train|eval|serve``.  Nothing heavy is imported at module import time."""

from __future__ import annotations

import time
from pathlib import Path

from city.errors import ConfigError


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("predictor", help="train and evaluate the event-informed demand predictor")
    sub = p.add_subparsers(dest="predictor_command", required=True, metavar="{train,eval,serve}")

    t = sub.add_parser("train", help="embed events, train the no-event, event and standard networks (resumable)")
    t.add_argument("--scenario", choices=("synthetic", "nyc"), default="synthetic")
    t.add_argument("--data", default=None, help="data directory laid out like shared/data (needed for nyc)")
    t.add_argument("--out", required=True, help="model directory to write (and resume from)")
    t.add_argument("--epochs", type=int, default=100, help="epochs for every network (paper: 100)")
    t.add_argument("--event-epochs", type=int, default=None, help="epochs for the event network only (default: --epochs)")
    t.add_argument("--encoder", default=None, help="sentence-transformers model name or path (default: bundled all-MiniLM-L6-v2)")
    t.add_argument("--seed", type=int, default=0, help="torch seed (initialisation and shuffles)")
    t.add_argument("--world-seed", type=int, default=0, help="seed of the synthetic demand world")
    t.add_argument("--year", type=int, default=2022)
    t.add_argument("--cache", default=None, help="cache root for embeddings (default $SURGE_CACHE or ~/.cache/surge)")
    t.add_argument("--events", default=None, help="event listing replacing the world's events: CSV/JSON (city.events.read_events) or NYC permitted-events CSV")
    t.add_argument("--reviews", default=None, help="reviews CSV (event_id,review) for --events")
    t.add_argument("--trips", nargs="+", default=None, help="HV-FHV trip parquet files: real hourly counts and β instead of the world's")
    t.set_defaults(func=train_main)

    e = sub.add_parser("eval", help="percent error per hour 15-21 h: the event system vs the standard NN vs previous hour")
    e.add_argument("--model", required=True, help="trained model directory")
    e.add_argument("--json", default=None, help="write results as JSON here")
    e.add_argument("--plot", default=None, help="write a PNG line chart here")
    e.add_argument("--data", default=None, help="override the data directory recorded in the model")
    e.add_argument("--cache", default=None, help="embedding cache root")
    e.set_defaults(func=eval_main)

    from bus.session import add_session_args

    v = sub.add_parser("serve", help="answer a distributed run's forecast queries on the bus (torch stays in this process)")
    add_session_args(v)
    v.add_argument("--run", default="demo", help="run name (as the coordinator's --run)")
    v.add_argument("--scenario", choices=("synthetic", "nyc"), default="synthetic")
    v.add_argument("--data", default=None, help="data directory laid out like shared/data (needed for nyc)")
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


# ----------------------------------------------------------------- worlds
class _RealInputsWorld:
    """A demand world whose events and/or hourly counts come from user files."""

    def __init__(self, base, events=None, trips=None) -> None:
        self._base = base
        self._events = events
        self._trips = trips

    def __getattr__(self, name):
        return getattr(self._base, name)

    @property
    def events(self):
        return self._events if self._events is not None else self._base.events

    def events_active(self, when):
        if self._events is None:
            return self._base.events_active(when)
        return [ev for ev in self._events if ev.active(when)]

    def hourly_counts(self):
        if self._trips is None:
            return self._base.hourly_counts()
        from city.trips import hourly_counts

        return hourly_counts(self._trips, int(self._base.year), int(self._base.city.n_sectors))


def load_world(scenario: str, data_dir: str | None, *, seed: int = 0, year: int = 2022, events: str | None = None, reviews: str | None = None, trips=None):
    from city.scenario import load_scenario

    world = load_scenario(scenario, data_dir, year=year, seed=seed).world
    ev = tr = None
    if events:
        ev = read_event_file(Path(events), world.city, Path(reviews) if reviews else None)
    if trips:
        from city.trips import read_fhvhv

        tr = read_fhvhv([Path(p) for p in trips], world.city)
    if ev is not None or tr is not None:
        world = _RealInputsWorld(world, ev, tr)
    return world, tr


def read_event_file(path: Path, city, reviews: Path | None = None) -> list:
    """Events from a user file: the NYC permitted-events CSV, or surge's CSV/JSON listing."""
    from city.events import read_events, read_permitted_events

    if not path.is_file():
        raise ConfigError(f"--events: {path} does not exist")
    with open(path, encoding="utf-8", errors="replace") as fh:
        head = fh.readline()
    if "Event ID" in head and "Event Borough" in head:
        return read_permitted_events(path, city)
    return read_events(path, city, reviews)


# ---------------------------------------------------------------- handlers
def train_main(args) -> int:
    from predictor.model import train_model
    from predictor.train import TrainConfig, log_line

    if args.epochs < 0:
        raise ConfigError("--epochs must be >= 0")
    t0 = time.perf_counter()
    world, trips = load_world(args.scenario, args.data, seed=args.world_seed, year=args.year, events=args.events, reviews=args.reviews, trips=args.trips)
    log_line(f"world: scenario {args.scenario}, {world.city.n_sectors} sectors, {len(world.events)} events, built in {time.perf_counter() - t0:.1f}s")
    scenario = {
        "name": args.scenario,
        "data_dir": str(Path(args.data).resolve()) if args.data else None,
        "world_seed": args.world_seed,
        "year": args.year,
        "events": str(Path(args.events).resolve()) if args.events else None,
        "reviews": str(Path(args.reviews).resolve()) if args.reviews else None,
        "trips": [str(Path(p).resolve()) for p in args.trips] if args.trips else None,
    }
    cfg = TrainConfig(epochs=args.epochs, seed=args.seed)
    model = train_model(
        world,
        args.out,
        cfg=cfg,
        encoder=args.encoder,
        cache_dir=args.cache,
        scenario=scenario,
        event_epochs=args.event_epochs,
        log=log_line,
    )
    if trips is not None:
        from predictor.assign import estimate_beta

        model.beta, info = estimate_beta(world, trips=trips)
        model.meta["beta"] = info
        model.save(Path(args.out))
    return 0


def eval_main(args) -> int:
    from predictor.dataset import build_year_data
    from predictor.evaluate import evaluate, format_table, plot, write_json
    from predictor.model import DemandModel

    model = DemandModel.load(args.model)
    sc = model.meta.get("scenario") or {}
    if not sc.get("name"):
        raise ConfigError(f"{args.model}: model.json records no scenario to evaluate on")
    world, _ = load_world(
        sc["name"], args.data or sc.get("data_dir"), seed=int(sc.get("world_seed", 0)), year=int(sc.get("year", 2022)), events=sc.get("events"), reviews=sc.get("reviews"), trips=sc.get("trips")
    )
    lead, lag = model.window
    data = build_year_data(world, model.featurizer(args.cache), lead=lead, lag=lag, verbose=False)
    result = evaluate(model, data)
    result["model"] = str(Path(args.model).resolve())
    result["scenario"] = sc
    print(format_table(result))
    if args.json:
        write_json(result, args.json)
        print(f"wrote {args.json}")
    if args.plot:
        plot(result, args.plot, title=f"Demand prediction PE, {sc['name']} test months Sep-Dec {data.year}")
        print(f"wrote {args.plot}")
    return 0

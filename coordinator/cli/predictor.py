"""``surge predictor train|eval|serve``.  Nothing heavy is imported at module import time."""

from __future__ import annotations

from coordinator.cli.options import forecast_name, model_dir


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
    t.add_argument("--events", default=None, help="event listing replacing the world's events: CSV/JSON (city.io.events.read_events) or NYC permitted-events CSV")
    t.add_argument("--reviews", default=None, help="reviews CSV (event_id,review) for --events")
    t.add_argument("--trips", nargs="+", default=None, help="HV-FHV trip parquet files: real hourly counts and β instead of the world's")
    t.set_defaults(func=train_main)

    e = sub.add_parser("eval", help="the ablation on the test months: percent error per hour 15-21 h of every network and baseline, with 95%% CIs")
    e.add_argument("--model", type=model_dir, required=True, help="trained model directory")
    e.add_argument("--json", default=None, help="write results as JSON here")
    e.add_argument("--plot", default=None, help="write a PNG line chart here")
    e.add_argument("--data", default=None, help="override the data directory recorded in the model")
    e.add_argument("--cache", default=None, help="embedding cache root")
    e.add_argument("--bootstrap", type=int, default=1000, help="bootstrap resamples of test days for the 95%% intervals")
    e.add_argument("--seed", type=int, default=0, help="seed of the bootstrap")
    e.add_argument("--part", choices=("test", "val"), default="test", help="months to score: test (Sep-Dec, the figures) or val (Jul-Aug, for design choices)")
    e.set_defaults(func=eval_main)

    c = sub.add_parser("ceiling", help="how much can the event text tell: the metadata network plus the world's announced attendance "
                       "drivers (the ceiling), a ridge reader of the text, and the event network, on the test months with 95%% CIs")
    c.add_argument("--model", type=model_dir, required=True, help="trained model directory (synthetic world, with its ablation networks)")
    c.add_argument("--json", default=None, help="write results as JSON here")
    c.add_argument("--data", default=None, help="override the data directory recorded in the model")
    c.add_argument("--cache", default=None, help="embedding cache root")
    c.add_argument("--bootstrap", type=int, default=1000, help="bootstrap resamples of test days for the 95%% intervals")
    c.add_argument("--seed", type=int, default=0, help="seed of the bootstrap and of the reader's folds")
    c.add_argument("--train-seed", type=int, default=None, help="seed of the metadata, ceiling and reader networks' training "
                   "(default: the model's; another seed retrains the metadata network too, to measure training noise)")
    c.set_defaults(func=ceiling_main)

    from coordinator.cli.options import add_session_args

    v = sub.add_parser("serve", help="answer a distributed run's forecast queries on the bus (torch stays in this process)")
    add_session_args(v)
    v.add_argument("--run", default="demo", help="run name (as the coordinator's --run)")
    v.add_argument("--scenario", default="synthetic", help="synthetic, nyc, manhattan or a scenario .toml file")
    v.add_argument("--data", default=None, help="data directory laid out like shared/data (for nyc, manhattan)")
    v.add_argument("--world-seed", type=int, default=0, help="seed of the demand world (as the coordinator's)")
    v.add_argument("--forecast", type=forecast_name, default="model", help="provider to serve: model (default), true-rate or previous-hour")
    v.add_argument("--model", type=model_dir, default=None, help="trained model directory for --forecast model")
    v.set_defaults(func=serve_cmd)


def serve_cmd(args) -> int:
    from coordinator.cli.options import session_args
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
    from predictor.jobs import TrainJob, train

    train(TrainJob(**{f: getattr(args, f) for f in TrainJob.__dataclass_fields__}))
    return 0


def eval_main(args) -> int:
    from predictor.jobs import EvalJob, evaluate_model

    evaluate_model(EvalJob(**{f: getattr(args, f) for f in EvalJob.__dataclass_fields__}))
    return 0


def ceiling_main(args) -> int:
    from predictor.jobs import CeilingJob, text_ceiling

    text_ceiling(CeilingJob(**{f: getattr(args, f) for f in CeilingJob.__dataclass_fields__}))
    return 0

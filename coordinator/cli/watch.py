"""``surge watch``: the subcommand's flags and what it runs."""

from __future__ import annotations

import argparse
import logging

from city.errors import ConfigError

_logger = logging.getLogger(__name__)


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``watch`` subcommand: live on a run's bus, or ``--replay RESULTS.json``."""
    from coordinator.cli.options import add_session_args, hour, iso_date, scenario_args

    p = sub.add_parser("watch", help="a live map of a running fleet in the browser, or a finished run played back (--replay)")
    p.add_argument("--replay", default=None, metavar="RESULTS.json",
                   help="play back a finished run from its results (surge fleet/coordinator --json, surge demo); no bus")
    p.add_argument("--run", default="demo", help="live: the run to follow (as the coordinator's --run)")
    p.add_argument("--date", type=iso_date, default="2022-11-17",
                   help="the episode's date, for the events layer (live; a replay reads it from the results)")
    p.add_argument("--hour", type=hour, default=19, help="the episode's hour, for the events layer (live)")
    p.add_argument("--world-seed", type=int, default=0, help="the demand world's seed, for the events layer (live)")
    p.add_argument("--seed", type=int, default=0, help="replay of a results file that records no config: the episode seed")
    p.add_argument("--forecast", default=None,
                   help="replay of a results file that records no config: the forecast provider its map shows (default: the policy's)")
    scenario_args(p)
    p.add_argument("--join-timeout", type=float, default=120.0, help="live: seconds to wait for the run's spec")
    p.add_argument("--http", default="127.0.0.1:8050", metavar="HOST:PORT",
                   help="where the page is served (default 127.0.0.1:8050; loopback unless you mean to share it)")
    add_session_args(p)
    p.set_defaults(func=cmd_watch)


def _http(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigError(f"--http {text!r}: expected HOST:PORT, e.g. 127.0.0.1:8050")
    return host, int(port)


def cmd_watch(args: argparse.Namespace) -> int:
    try:
        import uvicorn
    except ImportError:
        raise ConfigError("surge watch needs its web server: pip install 'surge[watch]' (starlette, uvicorn, websockets)") from None

    from coordinator.run_config import FleetConfig
    from coordinator.watch.server import make_app

    host, port = _http(args.http)
    if args.replay is not None:
        from coordinator.watch.replay import build_replay

        fallback = FleetConfig(scenario=args.scenario, data_dir=args.data, date=args.date, hour=args.hour, seed=args.seed,
                               world_seed=args.world_seed, options={"forecast": args.forecast} if args.forecast else {})
        feed = build_replay(args.replay, fallback)
        what = f"replay of {args.replay}"
    else:
        from coordinator.cli.options import session_args
        from coordinator.watch.live import LiveConfig, LiveFeed

        bus = session_args(args, identity="observer")
        feed = LiveFeed(LiveConfig(run=args.run, date=args.date, hour=args.hour, world_seed=args.world_seed,
                                   join_timeout_s=args.join_timeout), bus)
        feed.start()
        feed.ready.wait()
        if feed.error is not None:
            raise ConfigError(feed.error)
        what = f"live: run {args.run!r} as a read-only observer"
    _logger.info("http://%s:%d/ (%s); Ctrl-C stops it", host, port, what, extra={"who": "watch"})
    config = uvicorn.Config(make_app(feed, what), host=host, port=port, log_level="warning", ws="websockets-sansio")
    try:
        uvicorn.Server(config).run()
    finally:
        if args.replay is None:
            feed.close()
    return 0

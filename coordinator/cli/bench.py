"""``surge bench``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from coordinator.cli.options import forecast_name, hour, iso_date, model_dir, positive, rollout_options, scenario_args
from coordinator.experiments.bench import SHORTCUT_NAMES, CityBench, PlanBench, SimBench, bench_city, bench_plan, bench_sim


def _job(cls: type, args: argparse.Namespace, **extra: object) -> object:
    """The dataclass of a bench from the parsed flags of the same names."""
    return cls(**{f: getattr(args, f) for f in cls.__dataclass_fields__ if hasattr(args, f)}, **extra)


def cmd_city(args: argparse.Namespace) -> int:
    return bench_city(_job(CityBench, args))


def cmd_sim(args: argparse.Namespace) -> int:
    return bench_sim(_job(SimBench, args))


def cmd_plan(args: argparse.Namespace) -> int:
    from agents.base import split_policy

    names = [split_policy(label)[0] for label in args.policies]
    return bench_plan(_job(PlanBench, args, policy_options=rollout_options(args, names)))


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="benchmarks: city build, simulator speed, planning time, the distributed fleet")
    bsub = p.add_subparsers(dest="bench", required=True, metavar="BENCH")

    c = bsub.add_parser("city", help="time to build each city (all-pairs shortest paths included) and to load it")
    c.add_argument("--data", default=None, help="also build the nyc map from this data directory")
    c.add_argument("--repeat", type=int, default=3)
    c.add_argument("--json", default=None)
    c.set_defaults(func=cmd_city)

    s = bsub.add_parser("sim", help="simulator steps per second with the greedy policy")
    scenario_args(s)
    s.add_argument("--taxis", type=positive, default=100)
    s.add_argument("--hour", type=hour, default=19)
    s.add_argument("--date", type=iso_date, default="2022-11-17")
    s.add_argument("--episodes", type=positive, default=3)
    s.add_argument("--json", default=None)
    s.set_defaults(func=cmd_sim)

    pl = bsub.add_parser("plan", help="rollout planning time per step from mid-episode states, one fresh process per policy")
    scenario_args(pl)
    pl.add_argument("--date", type=iso_date, default="2022-11-17")
    pl.add_argument("--hour", type=hour, default=19, help="episode hour (default: the 7 pm surge)")
    pl.add_argument("--taxis", type=positive, default=100)
    pl.add_argument("--horizon", type=positive, default=None, help="rollout horizon H of every rollout policy (default: each policy's)")
    pl.add_argument("--samples", type=positive, default=None, help="rollout samples of every rollout policy (default: each policy's)")
    pl.add_argument("--steps", type=positive, default=5, help="consecutive planning steps timed")
    pl.add_argument("--rounds", type=positive, default=1,
                    help="runs of every policy, the policies in turn, each in a fresh process; their steps are pooled (default 1)")
    pl.add_argument("--warmup", type=int, default=25, help="minutes of greedy play before timing (a mid-episode state)")
    pl.add_argument("--seed", type=int, default=0, help="seed of the fleet's initial placement")
    pl.add_argument("--policies", nargs="+", default=["surge", "garces2023"])
    pl.add_argument("--forecast", type=forecast_name, default=None, help="forecast provider for surge (garces2023 keeps previous-hour)")
    pl.add_argument("--model", type=model_dir, default=None, help="trained predictor directory for surge's --forecast model")
    pl.add_argument("--threads", type=int, default=None, help="compiled-kernel threads (default: all cores)")
    pl.add_argument("--workers", type=int, default=1, help="threads planning independent agents at once (agents.waves)")
    pl.add_argument("--variants", nargs="+", default=["all"], metavar="VARIANT",
                    help="exact-shortcut settings timed side by side on each step, in one process: all (the defaults), none, "
                         f"no-NAME or with-NAME for NAME in {', '.join(SHORTCUT_NAMES)} (the first variant's controls are applied)")
    pl.add_argument("--json", default=None)
    pl.set_defaults(func=cmd_plan)


    add_fleet_parser(bsub)


def add_fleet_parser(bsub: argparse._SubParsersAction) -> None:
    from coordinator.cli.fleet import fleet_args, threads_arg
    from coordinator.cli.options import add_security_args

    f = bsub.add_parser("fleet", help="the distributed runtime against sequential in-process turns, side by side: decisions, "
                                      "minute times, agents' memory, readiness, traffic, critical paths and projections")
    fleet_args(f, taxis=100, minutes=20, samples=None)
    f.add_argument("--hosts", nargs="+", type=int, default=[4, 10], help="host counts to project the minute for (default: 4 10)")
    f.add_argument("--restart-router-after", type=int, default=None, metavar="MINUTE",
                   help="kill the router once this minute is checkpointed and start it again: the clock's pause is reported")
    f.add_argument("--router-down", type=float, default=1.0, metavar="SECONDS",
                   help="seconds the router stays down with --restart-router-after (default 1)")
    threads_arg(f)
    add_security_args(f)
    f.set_defaults(func=cmd_bench_fleet)


def cmd_bench_fleet(args: argparse.Namespace) -> int:
    from bus.session import warn_insecure
    from city.errors import ConfigError
    from coordinator.cli.fleet import fleet_config
    from coordinator.experiments.bench_fleet import PssSampler, fleet_report, print_report, sequential_in_process
    from coordinator.fleet import RouterRestart, run_local_fleet

    cfg = fleet_config(args)
    if args.certs is not None and args.insecure:
        raise ConfigError("--certs and --insecure: choose one")
    if any(h < 1 for h in args.hosts):
        raise ConfigError(f"--hosts {' '.join(map(str, args.hosts))}: host counts must be at least 1")
    after = args.restart_router_after
    if after is not None and not 1 <= after < cfg.minutes:
        raise ConfigError(f"--restart-router-after {after}: the run has minutes 1 to {cfg.minutes - 1} to restart the router after")
    if args.router_down < 0:
        raise ConfigError(f"--router-down {args.router_down:g}: seconds must not be negative")
    restart = RouterRestart(after, args.router_down) if after is not None else None
    if args.insecure:
        warn_insecure()
    print(f"bench fleet: {cfg.taxis} agent processes over a loopback router, then the same instance in-process", flush=True)
    sampler = PssSampler()
    dist = run_local_fleet(cfg, secure=not args.insecure, certs=args.certs, watch=sampler, agent_threads=args.threads,
                           restart=restart)
    seq = sequential_in_process(cfg)
    rep = fleet_report(cfg, dist, seq, sampler.summary(), args.hosts, args.threads,
                       restart.summary() if restart is not None else None)
    print_report(rep)
    if args.json:
        Path(args.json).write_text(json.dumps(rep, indent=1))
        print(f"wrote {args.json}")
    return 0

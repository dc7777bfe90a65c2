"""``surge fleet``, ``router``, ``coordinator``, ``agents`` and ``certs``: the distributed runtime's commands."""

from __future__ import annotations

import argparse
import json
import logging
import os
import time
from pathlib import Path

import numpy as np

from bus.certs import make_certs, taxi_name
from bus.keys import Keys
from bus.router import router_main
from city.errors import ConfigError
from coordinator.cli.options import (
    forecast_name,
    hour,
    iso_date,
    model_dir,
    positive,
    rollout_options,
    scenario_args,
    tcp_port,
)
from coordinator.fleet import (
    agent_context,
    agent_entry,
    in_process,
    resumed_config,
    run_local_fleet,
)
from coordinator.run_config import FleetConfig

_logger = logging.getLogger(__name__)


def fleet_args(p, *, taxis: int, minutes: int, samples: int | None) -> None:
    p.add_argument("--run", default="demo", help="run name: the key-expression prefix surge/<run>/ (default: demo)")
    scenario_args(p)
    p.add_argument("--date", type=iso_date, default="2022-11-17")
    p.add_argument("--hour", type=hour, default=19, help="episode hour (default: the 7 pm surge)")
    p.add_argument("--minutes", type=positive, default=minutes)
    p.add_argument("--taxis", type=positive, default=taxis, help="taxis, one agent process each")
    p.add_argument("--seed", type=int, default=0, help="initial placement seed (as surge evaluate's seeds)")
    p.add_argument("--world-seed", type=int, default=0)
    p.add_argument("--policy", default="surge",
                   help="rollout policy (surge, garces2023) or centrally computed one (match, rebalance), with options as in evaluate")
    p.add_argument("--forecast", type=forecast_name, default=None,
                   help="forecast provider of the policy (true-rate, previous-hour, model): surge's, or rebalance's")
    p.add_argument("--model", type=model_dir, default=None, help="trained predictor directory for --forecast model")
    p.add_argument("--horizon", type=positive, default=None)
    p.add_argument("--samples", type=positive, default=samples)
    p.add_argument("--deadline", type=float, default=30.0, help="seconds an agent has for its turn before the base control is used")
    p.add_argument("--join-timeout", type=float, default=120.0, help="seconds to wait for every agent to join")
    p.add_argument("--minute-seconds", type=float, default=0.0,
                   help="least wall seconds per simulated minute (default 0: as fast as the agents plan; 60: real time)")
    p.add_argument("--predictor", action="store_true",
                   help="take each hour's forecast from a `surge predictor serve` process on the bus (surge fleet starts one)")
    p.add_argument("--partition-timeout", type=float, default=120.0,
                   help="seconds the clock waits for most of the fleet to come back after a partition before the run ends")
    p.add_argument("--json", default=None, help="write the run's result here")


def _checkpoint_args(p, verb: str) -> None:
    p.add_argument("--run-dir", default=None, metavar="DIR",
                   help="checkpoint the run here after each minute, so that `--resume DIR` can continue it; one coordinator "
                        "at a time holds it (a lock file) (default: a new runs/<run>-<UTC time>-<pid> in surge's cache, "
                        "$SURGE_CACHE or ~/.cache/surge)")
    extra = "; a new router and new agents start" if verb == "fleet" else ""
    p.add_argument("--resume", default=None, metavar="RUN_DIR",
                   help=f"continue the run checkpointed in RUN_DIR (its settings come from the checkpoint; the bus flags apply{extra})")


def _grace_arg(p) -> None:
    p.add_argument("--grace", type=float, default=30.0,
                   help="seconds an agent waits for a vanished coordinator (a restart, `--resume`) before it leaves")


def fleet_config(args) -> FleetConfig:
    from agents.base import parse_policy
    from city.scenario import check_scenario

    Keys(args.run)  # a bad run name is an error before anything starts
    check_scenario(args.scenario, args.data)
    name, options = parse_policy(args.policy)
    FleetConfig(policy=name).policy_class()
    options = {**rollout_options(args, [args.policy]).get(args.policy, {}), **options}
    if args.deadline <= 0 or args.join_timeout <= 0 or args.minute_seconds < 0:
        raise ConfigError("--deadline and --join-timeout must be positive, --minute-seconds not negative")
    if args.partition_timeout <= 0 or getattr(args, "grace", 1.0) <= 0:
        raise ConfigError("--partition-timeout and --grace must be positive")
    return FleetConfig(run=args.run, scenario=args.scenario, data_dir=args.data, date=args.date, hour=args.hour,
                       minutes=args.minutes, taxis=args.taxis, seed=args.seed, world_seed=args.world_seed, policy=name,
                       options=options, deadline_s=args.deadline, join_timeout_s=args.join_timeout,
                       minute_s=args.minute_seconds, predictor=args.predictor, partition_timeout_s=args.partition_timeout,
                       grace_s=getattr(args, "grace", 30.0))


def _print_result(result: dict, path: str | None) -> None:
    print(f"run {result['run']!r}: {result['policy']}, {result['taxis']} taxis, {result['minutes']} min: total cost "
          f"{result['total_cost']}, served {result['served']} of {result['requests']}, {result['fallbacks']} base-control fallbacks")
    if "secured" in result:
        print("  bus: " + ("mutual TLS, access control at the router (default deny, one writer per key)" if result["secured"]
                           else "INSECURE (no TLS, no access control)"))
    plan = result["agent_plan_seconds"]["median"]
    print(f"  minute wall time median {result['step_seconds']['median']:.3f} s, max {result['step_seconds']['max']:.3f} s; "
          f"agent plan median {plan if plan is None else f'{plan:.3f} s'}; agent peak RSS {result['agent_peak_rss_mb']:.0f} MB")
    if result.get("critical_path"):
        print(f"  turns in dependency waves: median {np.median(result['critical_path']):g} waves a minute for a median "
              f"{np.median(result['free_per_minute']):g} free taxis (the critical path; {result['traffic']['messages_per_minute']:.0f} "
              f"messages a minute through the coordinator)")
    print(f"  decisions sha256 {result['decisions_sha256']}")
    if path:
        Path(path).write_text(json.dumps(result, indent=1))
        print(f"wrote {path}")


def _run_dir(args) -> tuple[FleetConfig, str]:
    """The run's config and checkpoint directory: from the checkpoint with ``--resume``, else from the flags."""
    if args.resume is not None:
        cfg, run_dir = resumed_config(args.resume), args.resume
    else:
        from city.scenario import cache_dir

        cfg = fleet_config(args)
        run_dir = args.run_dir or str(cache_dir() / "runs" / default_run_dir_name(cfg.run))
    return cfg, run_dir


def default_run_dir_name(run: str) -> str:
    """A run directory's name unique to this run, not shared by every run of the same name: ``<run>-<UTC time>-<pid>``."""
    return f"{run}-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}-{os.getpid()}"


def _say_checkpoint(run_dir: str, verb: str) -> None:
    """Once every flag has been checked: a bad flag stays a one-line error."""
    from coordinator.runtime import log

    log(f"checkpointing each minute to {run_dir}; `surge {verb} --resume {run_dir}` continues the run")


def cmd_fleet(args) -> int:
    from bus.session import warn_insecure

    cfg, run_dir = _run_dir(args)
    if args.certs is not None and args.insecure:
        raise ConfigError("--certs and --insecure: choose one")
    _say_checkpoint(run_dir, "fleet")
    roles = "a router, a predictor service, a coordinator" if cfg.predictor else "a router, a coordinator"
    if args.insecure:
        warn_insecure()
        how = "without TLS or access control"
    else:
        how = (f"secured: mutual TLS and access control, with the credentials in {args.certs}" if args.certs else
               "secured: mutual TLS and access control, with credentials made for this run")
    _logger.info("starting %s and %d agent processes on loopback, %s", roles, cfg.taxis, how)
    result = run_local_fleet(cfg, secure=not args.insecure, certs=args.certs, run_dir=run_dir, resume=args.resume is not None,
                             agent_threads=args.threads, port=args.port)
    if args.check:
        _logger.info("running the same instance in-process to compare decisions")
        ref = in_process(cfg)
        result["in_process"] = ref
        result["same_decisions"] = ref["decisions_sha256"] == result["decisions_sha256"]
    _print_result(result, args.json)
    if args.check:
        ref = result["in_process"]
        print(f"  in-process run of the same seed: total cost {ref['total_cost']}, planning median "
              f"{ref['step_seconds']['median']:.3f} s a minute; decisions {'identical' if result['same_decisions'] else 'DIFFERENT'}")
        return 0 if result["same_decisions"] or result["fallbacks"] else 1
    return 0


def cmd_router(args) -> int:
    from coordinator.cli.options import session_args

    bus = session_args(args, identity="router", run=args.run)
    if args.print_config:
        print(json.dumps(_nested(bus.overrides()), indent=1))
        return 0
    router_main(bus, announce=True)
    return 0


def _nested(overrides: dict) -> dict:
    """``{"a/b": v}`` -> ``{"a": {"b": v}}``: a zenoh config file of the given entries."""
    out: dict = {}
    for path, value in overrides.items():
        *parents, last = path.split("/")
        node = out
        for p in parents:
            node = node.setdefault(p, {})
        node[last] = value
    return out


def cmd_coordinator(args) -> int:
    from coordinator.cli.options import session_args
    from coordinator.runtime import coordinator_main

    cfg, run_dir = _run_dir(args)
    bus = session_args(args, identity="coordinator")
    _say_checkpoint(run_dir, "coordinator")
    result = coordinator_main(cfg, bus, run_dir=run_dir, resume=args.resume is not None, takeover=args.takeover)
    _print_result(result, args.json)
    return 0


def parse_ids(text: str) -> list[int]:
    """``"0-3,7"`` -> ``[0, 1, 2, 3, 7]``."""
    out: list[int] = []
    for part in filter(None, text.split(",")):
        lo, dash, hi = part.partition("-")
        try:
            a, b = int(lo), int(hi) if dash else int(lo)
        except ValueError:
            raise ConfigError(f"--ids {text!r}: {part!r} is not N or N-M") from None
        if a < 0 or b < a:
            raise ConfigError(f"--ids {text!r}: {part!r} is not an ascending range of non-negative ids")
        out.extend(range(a, b + 1))
    if not out:
        raise ConfigError(f"--ids {text!r}: no agent ids")
    return sorted(set(out))


def cmd_agents(args) -> int:
    from coordinator.cli.options import session_args

    if args.grace <= 0:
        raise ConfigError("--grace must be positive")
    ids = parse_ids(args.ids)
    bus = session_args(args)
    for i in ids:
        bus.as_identity(taxi_name(i)).overrides()  # every agent's credentials are here, before any starts
    from agents.rollout import warm_up

    warm_up()  # compile once here, not in every agent at once
    ctx = agent_context()
    procs = [ctx.Process(target=agent_entry, args=(i, args.run, bus.as_identity(taxi_name(i)), args.join_timeout, args.data,
                                                    args.grace, args.threads), name=f"surge-agent-{i}") for i in ids]
    _logger.info("starting %d agent processes for run %r", len(procs), args.run)
    for p in procs:
        p.start()
    try:
        for p in procs:
            p.join()
    finally:
        for p in procs:
            if p.is_alive():
                p.terminate()
    failed = [i for i, p in zip(ids, procs) if p.exitcode != 0]
    if failed:
        _logger.error("agents %s exited with an error", ", ".join(map(str, failed)))
        return 1
    return 0


def cmd_certs(args) -> int:
    from bus.certs import ROLES

    written = make_certs(args.out, args.taxis, args.host or None, args.days)
    out = Path(args.out)
    print(f"wrote the credentials of a {args.taxis}-taxi fleet to {out}/ (keys mode 0600):")
    print(f"  certificate authority  {out / 'ca.pem'}  (its key {out / 'ca.key'}: keep it off the fleet hosts)")
    for name in ROLES:
        print(f"  {name:<22} {out / (name + '.pem')}, {out / (name + '.key')}")
    last = taxi_name(args.taxis - 1)
    print(f"  taxis                  {out / 'taxi-0.pem'} … {out / (last + '.pem')}, each with its .key (common names taxi-<i>)")
    print(f"  manifest               {out / 'fleet.json'}  (the router reads the fleet size from it)")
    hosts = ", ".join(args.host or ["127.0.0.1", "localhost"])
    print(f"{len(written)} files. Clients must reach the router as one of: {hosts}. Every host needs ca.pem, its own "
          f"certificate and key; the router also fleet.json. Run with --certs {out}.")
    return 0


def threads_arg(p) -> None:
    """``--agent-threads``: what a host running many agents gives each one's kernel.

    The default, ``share``, splits the host's cores among the agents of the run
    planning on it at the time (:mod:`agents.cores`): a lone agent plans on
    every core, and independent turns side by side take one share each. A
    fixed count was measured at 100 agents on 2 cores:
    one thread each was slower than every core, since most turns wait on a
    predecessor and a lone agent then plans on one core.
    """
    p.add_argument("--agent-threads", dest="threads", type=_threads, default="share", metavar="N",
                   help="rollout kernel threads of each agent process: 'share' (default: the host's cores split among the "
                        "agents planning at the time), 'all' (every core) or a number; decisions do not depend on it")


def _threads(text: str) -> int | str:
    if text in ("share", "all"):
        return text
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: 'share', 'all' or a positive number of threads")
    return n


def add_parser(sub) -> None:
    from coordinator.cli.options import add_security_args, add_session_args

    p = sub.add_parser("fleet", help="the local multi-process fleet: router, coordinator and one process per taxi on loopback")
    fleet_args(p, taxis=8, minutes=20, samples=None)
    _grace_arg(p)
    p.add_argument("--check", action="store_true", help="also run the instance in-process and compare the decisions")
    p.add_argument("--port", type=tcp_port, default=None, help="the loopback router's TCP port (default: a free one)")
    threads_arg(p)
    _checkpoint_args(p, "fleet")
    add_security_args(p)
    p.set_defaults(func=cmd_fleet)

    k = sub.add_parser("certs", help="make a fleet's credentials: a CA, router, coordinator, predictor and one certificate per taxi")
    k.add_argument("--out", required=True, help="directory to write them to (created; must not hold credentials already)")
    k.add_argument("--taxis", type=positive, required=True, help="taxis, one certificate each (common names taxi-0 …)")
    k.add_argument("--host", action="append", default=[], metavar="NAME",
                   help="a name or address clients reach the router by (repeatable; default 127.0.0.1 and localhost)")
    k.add_argument("--days", type=positive, default=365, help="days the certificates are valid (default 365)")
    k.set_defaults(func=cmd_certs)

    r = sub.add_parser("router", help="a zenoh router for runs across machines")
    add_session_args(r, mode="router")
    r.add_argument("--run", default=None, help="scope the access rules to this run's keys (default: every run)")
    r.add_argument("--print-config", action="store_true",
                   help="print the router's generated zenoh config (TLS and access control) as JSON and exit, e.g. for zenohd")
    r.set_defaults(func=cmd_router)

    c = sub.add_parser("coordinator", help="the clock and world of a distributed run; agents join it over zenoh")
    add_session_args(c)
    fleet_args(c, taxis=8, minutes=60, samples=None)
    _checkpoint_args(c, "coordinator")
    c.add_argument("--takeover", action="store_true",
                   help="if the run has a live coordinator (one whose host is unreachable rather than dead), fence it and take "
                        "the run over: the agents drop its turns from then on (without this, a second coordinator is refused)")
    c.set_defaults(func=cmd_coordinator)

    a = sub.add_parser("agents", help="start agent processes (one per taxi) that join a run over zenoh")
    add_session_args(a)
    a.add_argument("--run", default="demo", help="run name (as the coordinator's --run)")
    a.add_argument("--ids", required=True, help="taxi indices to run here, e.g. 0-49 or 0-3,8")
    a.add_argument("--join-timeout", type=float, default=120.0, help="seconds to wait for the coordinator")
    a.add_argument("--data", default=None, help="this host's copy of the data directory, if not at the coordinator's path")
    threads_arg(a)
    _grace_arg(a)
    a.set_defaults(func=cmd_agents)

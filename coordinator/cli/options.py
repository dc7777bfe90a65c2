"""Argument helpers shared by every ``surge`` subcommand, as zenoh's examples share one.

Every subcommand's module in :mod:`coordinator.cli` imports its argument
types and the common option groups (scenario, rollout, zenoh session and
security flags) from here; library code takes the dataclasses they build.
"""

from __future__ import annotations

import argparse
import datetime as dt
from pathlib import Path

from bus.session import (
    DEFAULT_ENDPOINT,
    DEFAULT_TLS_ENDPOINT,
    MODES,
    SessionArgs,
    warn_insecure,
)
from city.errors import ConfigError

class DefaultsFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows each option's default, except where there is none to show (None, off) or the help already says it."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if action.default in (None, False, [], argparse.SUPPRESS) or "default" in text.lower():
            return action.help
        return super()._get_help_string(action)


class SurgeParser(argparse.ArgumentParser):
    """Every ``surge`` parser and subparser: defaults shown in ``--help``, and ``-q``/``-v`` before or after a command."""

    def __init__(self, *args, formatter_class: type = DefaultsFormatter, **kwargs) -> None:
        super().__init__(*args, formatter_class=formatter_class, **kwargs)
        verbosity_args(self)


def verbosity_args(p: argparse.ArgumentParser) -> None:
    """``-q/--quiet`` and ``-v/--verbose``; unset unless given, so that a subcommand's parser keeps the top level's."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                   help="warnings and errors only: no progress lines or bars")
    g.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help="debug messages too")


def forecast_name(text: str) -> str:
    """An argparse type: a forecast provider's name, checked whichever policies run."""
    from agents.forecast_providers import PROVIDERS

    if text not in PROVIDERS:
        raise argparse.ArgumentTypeError(f"unknown forecast {text!r}; choose from {', '.join(sorted(PROVIDERS))}")
    return text


def tcp_port(text: str) -> int:
    """An argparse type: a TCP port, 1..65535."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid port {text!r}") from None
    if not 1 <= v <= 65535:
        raise argparse.ArgumentTypeError(f"port {v} is outside 1..65535")
    return v


def model_dir(text: str) -> str:
    """An argparse type: a trained predictor's directory (it holds model.json), checked whichever policies run."""
    if not (Path(text) / "model.json").is_file():
        raise argparse.ArgumentTypeError(f"{text}: not a trained predictor directory (no model.json; make one with surge predictor train)")
    return text


SCENARIO_HELP = "synthetic (embedded), nyc or manhattan (shipped scenario files, need --data), or a scenario .toml file"


def scenario_args(p: argparse.ArgumentParser) -> None:
    """``--scenario`` and ``--data``: which city and demand world, and where its data lie."""
    p.add_argument("--scenario", default="synthetic", help=SCENARIO_HELP)
    p.add_argument("--data", default=None,
                   help="data directory laid out like shared/data, for scenario files that read from it (nyc, manhattan)")
    p.add_argument("--share", type=share, default=None,
                   help="the fleet's share of real taxi demand: scales base demand and event trips (default: with real hourly "
                        "totals, as on nyc and manhattan, the share that puts a mean business-day 19 h of January-June at 290 "
                        "requests; otherwise 0.0171, city.demand.profile.FLEET_SHARE)")


def share(text: str) -> float:
    """An argparse type: a share of real demand in (0, 1]."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid share {text!r}") from None
    if not 0 < v <= 1:
        raise argparse.ArgumentTypeError(f"share {v} must be in (0, 1]")
    return v


def iso_date(text: str) -> str:
    """An argparse type: a ``YYYY-MM-DD`` date, kept as text."""
    try:
        dt.date.fromisoformat(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid date {text!r}; use YYYY-MM-DD") from None
    return text


def hour(text: str) -> int:
    """An argparse type: an hour of the day, 0..23."""
    try:
        h = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid hour {text!r}") from None
    if not 0 <= h <= 23:
        raise argparse.ArgumentTypeError(f"hour {h} is outside 0..23")
    return h


def positive(text: str) -> int:
    """An argparse type: a count of at least 1."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid count {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"{v} must be at least 1")
    return v


def rollout_options(args: argparse.Namespace, names: list[str]) -> dict[str, dict]:
    """Per-policy options from the rollout and forecast flags, for the policies that take them.

    ``--horizon`` and ``--samples`` go to both rollout policies.  ``--forecast``
    and ``--model`` go to every policy that declares a ``forecast`` option
    (``surge``, ``rebalance``), so that they plan with the same information,
    except ``garces2023``, which keeps its previous-hour demand (the baseline
    as the paper ran it; ``garces2023:forecast=…`` sets it).
    """
    from agents.base import policy_class, split_policy

    shared = {k: v for k, v in (("horizon", args.horizon), ("samples", args.samples)) if v is not None}
    own = {k: v for k, v in (("forecast", args.forecast), ("model", getattr(args, "model", None))) if v is not None}
    out = {}
    for label in names:
        name = split_policy(label)[0]
        opts = dict(shared) if name in ("surge", "garces2023") else {}
        if name != "garces2023" and own and any(o.name == "forecast" for o in policy_class(name).options):
            opts.update(own)
        if opts:
            out[label] = opts
    return out


def add_session_args(p: argparse.ArgumentParser, mode: str = "client") -> None:
    """``--mode``, ``--connect``, ``--listen``, ``--config`` and ``--multicast``, as zenoh's examples take them."""
    p.add_argument("--mode", choices=MODES, default=mode, help=f"zenoh session mode (default: {mode})")
    p.add_argument("--connect", "-e", action="append", default=[], metavar="ENDPOINT", help="endpoint to connect to, e.g. tcp/10.0.0.1:7447")
    p.add_argument("--listen", "-l", action="append", default=[], metavar="ENDPOINT", help="endpoint to listen on")
    p.add_argument("--config", default=None, help="zenoh JSON5 config file (the flags above override it)")
    p.add_argument("--multicast", action="store_true", help="allow multicast scouting (off: endpoints are explicit)")
    add_security_args(p)


def add_security_args(p: argparse.ArgumentParser) -> None:
    """``--certs DIR`` (mutual TLS and access control, the default way to run) and ``--insecure``."""
    p.add_argument("--certs", default=None, metavar="DIR",
                   help="the fleet's credentials (made by `surge certs`): mutual TLS, and access control at the router")
    p.add_argument("--insecure", action="store_true",
                   help="run the bus without TLS or access control (anyone who reaches the router can steer the fleet)")


def security(args: argparse.Namespace) -> str | None:
    """The credentials directory of ``--certs``, or ``None`` under ``--insecure`` (after its warning); neither is an error."""
    certs, insecure = getattr(args, "certs", None), getattr(args, "insecure", False)
    if certs is not None and insecure:
        raise ConfigError("--certs and --insecure: choose one")
    if certs is None and not insecure:
        raise ConfigError("the bus runs with mutual TLS and access control: pass --certs DIR "
                          "(make it with `surge certs --out DIR --taxis N`), or --insecure to run without")
    if insecure:
        warn_insecure()
    return certs


def session_args(args: argparse.Namespace, identity: str | None = None, run: str | None = None) -> SessionArgs:
    """Session settings from the shared flags, presenting ``identity``'s credentials (a router may scope its rules to ``run``).

    A client with no ``--connect`` (or a router with no ``--listen``) uses the default endpoint.
    """
    SessionArgs(mode=args.mode, connect=list(args.connect), listen=list(args.listen))  # the flags' own errors first
    if args.config is not None and not Path(args.config).is_file():
        raise ConfigError(f"zenoh config {args.config}: no such file")
    certs = security(args)
    default = DEFAULT_ENDPOINT if certs is None else DEFAULT_TLS_ENDPOINT
    connect, listen = list(args.connect), list(args.listen)
    if args.mode == "client" and not connect and args.config is None:
        connect = [default]
    if args.mode == "router" and not listen and args.config is None:
        listen = [default]
    out = SessionArgs(mode=args.mode, connect=connect, listen=listen, config=args.config, multicast=args.multicast,
                      certs=certs, identity=identity if certs is not None else None, run=run)
    if certs is not None and identity is not None:
        out.overrides()  # a missing credential file is one line now, not a failure in a spawned process
    return out

"""Argument helpers shared by every ``surge`` subcommand, as zenoh's examples share one.

Every module that builds a parser (:mod:`coordinator.cli`,
:mod:`coordinator.fleet`, :mod:`coordinator.bench`)
imports its argument types and the common option groups from here, so the
CLI imports those modules and none of them imports the CLI back.
"""

from __future__ import annotations

import argparse
import datetime as dt

SCENARIO_HELP = "synthetic (embedded), nyc or manhattan (shipped scenario files, need --data), or a scenario .toml file"


def scenario_args(p: argparse.ArgumentParser) -> None:
    """``--scenario`` and ``--data``: which city and demand world, and where its data lie."""
    p.add_argument("--scenario", default="synthetic", help=SCENARIO_HELP)
    p.add_argument("--data", default=None,
                   help="data directory laid out like shared/data, for scenario files that read from it (nyc, manhattan)")
    p.add_argument("--share", type=share, default=None,
                   help="the fleet's share of real taxi demand: scales base demand (the real zone profile on nyc) and event trips "
                        "(default 0.0171, city.demand.profile.FLEET_SHARE)")


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

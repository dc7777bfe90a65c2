"""The ``surge`` command line: one module per subcommand, each with ``add_parser(sub)``.

Every subcommand reports bad input as one line on stderr and exits with
status 2; long work prints progress on stderr and results on stdout.
argparse lives only in this package.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import warnings

from city.errors import SurgeError
from coordinator.cli import (
    bench,
    city,
    demand,
    demo,
    evaluate,
    fleet,
    predictor,
    report,
    reproduce,
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="surge", description="Event-aware routing for autonomous taxi fleets.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in (evaluate, report, city, demand, demo, bench, fleet, reproduce, predictor):
        module.add_parser(sub)
    return parser


def _warn_one_line(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001
    print(f"surge: warning: {message}", file=sys.stderr)


def _terminated(signum: int, frame: object) -> None:
    """SIGTERM unwinds like Ctrl-C: worker pools are stopped and finished results stay written."""
    print("surge: terminated", file=sys.stderr)
    raise SystemExit(128 + signum)


def main(argv: list[str] | None = None) -> int:
    warnings.showwarning = _warn_one_line
    signal.signal(signal.SIGTERM, _terminated)
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "share", None) is not None:
        from city.scenario import SHARE_ENV

        os.environ[SHARE_ENV] = repr(args.share)  # read by every load_scenario, worker processes included
    try:
        return int(args.func(args) or 0)
    except SurgeError as exc:
        print(f"surge: error: {exc}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"surge: error: {exc.filename}: no such file", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("surge: interrupted", file=sys.stderr)
        return 130


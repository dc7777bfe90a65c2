"""``surge evaluate``."""

from __future__ import annotations

import argparse

from city.errors import SurgeError
from coordinator.cli.options import (
    forecast_name,
    hour,
    iso_date,
    model_dir,
    positive,
    rollout_options,
    scenario_args,
)


def add_parser(sub: argparse._SubParsersAction) -> None:
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
    p.add_argument("--forecast", type=forecast_name, default=None,
                   help="forecast provider (true-rate, previous-hour, model) of every policy that reads one (surge, rebalance); "
                        "garces2023 keeps previous-hour")
    p.add_argument("--model", type=model_dir, default=None, help="trained predictor directory for --forecast model")
    p.add_argument("--horizon", type=positive, default=None, help="rollout horizon H")
    p.add_argument("--samples", type=positive, default=None, help="rollout Monte-Carlo samples")
    p.add_argument("--world-seed", type=int, default=0, help="seed of the synthetic demand world")
    p.add_argument("--jobs", type=positive, default=1, help="worker processes")
    p.add_argument("--cluster", default=None, metavar="ADDRESS",
                   help="run the instances on the Dask scheduler at ADDRESS (tcp://host:8786) instead; needs surge[cluster]")
    p.add_argument("--json", default=None, help="write surge.results/1 JSON here, updated after every instance")
    p.add_argument("--plot", default=None, help="write a PNG bar chart of total cost per hour and policy here")
    p.add_argument("--resume", action="store_true", help="keep the instances already in --json and run only the rest")
    p.add_argument("--warm-start", action="store_true",
                   help="each policy starts where it left the fleet after driving the previous hour from the seed's random start "
                        "(busy taxis at their drop-off, free; the previous hour's waiting requests dropped)")
    p.add_argument("--borrow", default=None, metavar="RESULTS",
                   help="a results file whose rows of the same settings (fleet, start, options, demand) are kept instead of run again")
    p.set_defaults(func=cmd_evaluate)


def cmd_evaluate(args: argparse.Namespace) -> int:
    from agents.base import check_options, parse_policy
    from city.scenario import check_scenario
    from coordinator.experiments.evaluate import EvalConfig, evaluate

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
        warm_start=args.warm_start,
    )
    lend = None
    if args.borrow:
        from coordinator.experiments.results import read_results

        lend = read_results(args.borrow)
    doc = evaluate(cfg, checkpoint=args.json, resume=args.resume, borrow=lend)
    if args.json:
        print(f"wrote {args.json}")
    print_results(doc, plot_path=args.plot)
    return 0


def print_results(doc: dict, *, policy: str | None = None, plot_path: str | None = None) -> dict:
    """The summary table, the paired comparison of ``policy`` (default: the first surge label) and the plot."""
    from agents.base import split_policy
    from coordinator.experiments.analysis import (
        compare,
        format_comparison,
        format_table,
        oracle_exceptions,
        plot,
        summarize,
    )

    cfg, c = doc["config"], doc["city"]
    seeds = sorted({e["seed"] for e in doc["episodes"]})
    print(f"{doc['scenario']}: {c['intersections']} intersections, {c['streets']} streets, {c['sectors']} sectors; "
          f"{cfg['taxis']} taxis, {cfg['minutes']} min, {len(seeds)} seeds, dates {' '.join(cfg['dates'])}; "
          f"{'warm start (each policy from its own previous hour)' if doc.get('warm_start') else 'cold start (random positions)'}; "
          f"wait overhead measured against {doc['reference_oracle']}")
    summary = summarize(doc)
    print(format_table(summary))
    labels = list(dict.fromkeys(e["policy"] for e in doc["episodes"]))
    policy = policy or next((p for p in labels if split_policy(p)[0] == "surge"), None)
    comparison = compare(doc, policy) if policy else []
    if comparison:
        print()
        print(format_comparison(comparison))
        from coordinator.experiments.practice import against_practice, verdict_lines

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

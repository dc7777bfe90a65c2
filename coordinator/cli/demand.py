"""``surge demand``."""

from __future__ import annotations

import argparse
import datetime as dt
import json
from pathlib import Path

from coordinator.cli.options import hour, iso_date, positive, scenario_args


def add_parser(sub: argparse._SubParsersAction) -> None:
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

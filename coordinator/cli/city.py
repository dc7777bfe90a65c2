"""``surge city``."""

from __future__ import annotations

import argparse
import time

from coordinator.cli.options import scenario_args


def add_parser(sub: argparse._SubParsersAction) -> None:
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

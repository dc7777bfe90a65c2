"""``surge demo``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from coordinator.cli.options import hour, positive, share

#: The demo's fleet: as many agent processes as a laptop holds (about 215 MB each).
DEMO_TAXIS = 40


def add_parser(sub: argparse._SubParsersAction) -> None:
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
    from coordinator.cli import build_parser
    from coordinator.cli.fleet import cmd_fleet, fleet_config
    from coordinator.experiments.demo import surge_vs_greedy

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

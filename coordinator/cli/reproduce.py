"""``surge reproduce``."""

from __future__ import annotations

import argparse
import os
from dataclasses import replace
from pathlib import Path

from city.errors import ConfigError
from coordinator.experiments.protocol import FULL, QUICK, SMOKE, Run
from coordinator.experiments.reproduce import reproduce


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("reproduce", help="the paper's experiment end to end (resumable), with OUT/REPORT.md")
    p.add_argument("--scenario", default="synthetic", help="synthetic (embedded) or nyc (needs --data)")
    p.add_argument("--data", default=None, help="data directory laid out like shared/data (for --scenario nyc)")
    p.add_argument("--out", default="reproduce-out", help="output directory; a rerun resumes from what it holds")
    p.add_argument("--quick", action="store_true", help="5 seeds, one date, 2 ablation seeds at 19 h, 100 samples (the pruning pair 30), small predictor (5 reviews per event)")
    p.add_argument("--smoke", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--jobs", type=int, default=None, help="worker processes for the evaluations (default: one per core)")
    p.add_argument("--model", default=None, help="reuse this trained predictor directory instead of training OUT/model")
    p.add_argument("--report-only", action="store_true",
                   help="run nothing: write OUT/REPORT.md from the results so far, saying how far each step has come")
    p.add_argument("--refresh-model", action="store_true",
                   help="the predictor changed since OUT's results: rerun only the rows that plan with it, keep the rest")
    p.set_defaults(func=cmd_reproduce)


def cmd_reproduce(args: argparse.Namespace) -> int:
    from city.scenario import check_scenario

    check_scenario(args.scenario, args.data)
    if args.jobs is not None and args.jobs < 1:
        raise ConfigError(f"--jobs must be at least 1, got {args.jobs}")
    jobs = args.jobs or (1 if args.smoke else os.cpu_count() or 1)
    protocol = SMOKE if args.smoke else QUICK if args.quick else FULL
    model = Path(args.model) if args.model else None
    if model is not None and not (model / "model.json").exists():
        raise ConfigError(f"--model {model}: no model.json there (train one with surge predictor train)")
    flags = [("--data", args.data), ("--out", args.out), ("--quick", args.quick), ("--smoke", args.smoke),
             ("--jobs", args.jobs), ("--model", args.model)]
    command = " ".join(["surge reproduce --scenario", args.scenario] + [f if v is True else f"{f} {v}" for f, v in flags if v])
    run = Run(out=Path(args.out), scenario=args.scenario, data=args.data, protocol=replace(protocol, jobs=jobs), model_dir=model,
              command=command)
    if args.report_only and args.refresh_model:
        raise ConfigError("--report-only runs nothing, so it cannot --refresh-model: choose one")
    print(reproduce(run, refresh_model=args.refresh_model, report_only=args.report_only))
    return 0

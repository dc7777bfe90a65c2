"""The state of `surge bench plan` for the scripts beside this file: 2022-11-17, seed 0, 25 minutes of greedy play.

Run those scripts from the repository root (``PYTHONPATH=. python benchmarks/<script>.py``), which puts this folder
on the path.
"""
import argparse
import datetime as dt

from agents.base import Policy, make_policy, parse_policy
from city.graph import City
from city.sim import FleetSim
from coordinator.bench import plan_state

DATE = dt.date(2022, 11, 17)
WARMUP = 25


def state_args(ap: argparse.ArgumentParser) -> None:
    """The options that pick the state: map, data, fleet, minutes planned and hour."""
    ap.add_argument("--scenario", default="nyc")
    ap.add_argument("--data", default=None)
    ap.add_argument("--taxis", type=int, default=100)
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--hour", type=int, default=19)


def bench_state(args: argparse.Namespace, label: str) -> tuple[City, FleetSim, Policy]:
    """The city, the simulator after the greedy warm-up, and the policy ``label`` (true-rate forecast) reset for the episode."""
    scen, sim, episode = plan_state(args.scenario, args.data, DATE, args.hour, args.taxis, 0, WARMUP, args.steps)
    name, own = parse_policy(label)
    policy = make_policy(name, scen.city, **{"forecast": "true-rate", **own})
    policy.reset(episode)
    return scen.city, sim, policy

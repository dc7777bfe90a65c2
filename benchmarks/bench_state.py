"""The state of `surge bench plan` for the scripts beside this file: 2022-11-17, seed 0, 25 minutes of greedy play.

Run those scripts from the repository root (``PYTHONPATH=. python benchmarks/<script>.py``), which puts this folder
on the path.
"""
import argparse
import datetime as dt
import time
from collections.abc import Callable

import numba

import agents.rollout as R
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


def replay_args(doc: str, example: str, rounds: int) -> argparse.Namespace:
    """The command line of a script that replays captured kernel calls: the policy, the state, rounds and JSON file."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--label", required=True, help=f"policy label, e.g. {example}")
    state_args(ap)
    ap.add_argument("--rounds", type=int, default=rounds)
    ap.add_argument("--json", default=None)
    return ap.parse_args()


def bench_state(args: argparse.Namespace, label: str) -> tuple[City, FleetSim, Policy]:
    """The city, the simulator after the greedy warm-up, and the policy ``label`` (true-rate forecast) reset for the episode."""
    scen, sim, episode = plan_state(args.scenario, args.data, DATE, args.hour, args.taxis, 0, WARMUP, args.steps)
    name, own = parse_policy(label)
    policy = make_policy(name, scen.city, **{"forecast": "true-rate", **own})
    policy.reset(episode)
    return scen.city, sim, policy


def captured_calls(args: argparse.Namespace, label: str, fill_lists: bool = False) -> list[tuple]:
    """Every rollout-kernel call of ``args.steps`` minutes of ``label`` at the state, as ``agents.rollout._run``'s arguments.

    The policy plans one untimed minute first (loading the compiled kernels).
    With ``fill_lists`` each call's nearest-request lists are filled before it
    runs, so that replays with any kernel read the same lists.
    """
    import agents._kernels as K

    _, sim, policy = bench_state(args, label)
    policy.act(sim.observe())
    calls = []
    run = R._run

    def capture(ctx, inp, lo, hi, active, serial=False):  # noqa: ANN001, ANN202
        if fill_lists:
            a = inp.args
            K.fill_lists(a[8], a[9], a[6], a[21])
        calls.append((ctx, inp, lo, hi, active.copy(), serial))
        return run(ctx, inp, lo, hi, active, serial)

    R._run = capture
    try:
        for _ in range(args.steps):
            sim.step(policy.act(sim.observe()))
    finally:
        R._run = run
    return calls


def replay(calls: list[tuple], kernel, chunks: Callable[[int], int] | None = None) -> float:  # noqa: ANN001
    """Seconds to run captured ``calls`` again with ``kernel`` (either rollout kernel).

    ``chunks`` gives a call's chunk count from its number of samples; by
    default 8 per kernel thread, as ``agents.rollout._run`` runs the parallel
    kernel, which gets one group of chunks per kernel thread too.
    """
    import agents._kernels as K

    groups = (numba.get_num_threads(),) if kernel is K.rollout_costs else ()
    t0 = time.perf_counter()
    for ctx, inp, lo, hi, active, _ in calls:
        n = chunks(hi - lo) if chunks else 8 * numba.get_num_threads()
        kernel(*R.kernel_args(ctx, inp, lo, hi, active), n, *groups)
    return time.perf_counter() - t0

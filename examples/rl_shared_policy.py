"""Train one policy shared by every taxi with Stable-Baselines3's PPO and compare it with greedy.

    pip install 'surge[rl]'
    python examples/rl_shared_policy.py --timesteps 300000 --out benchmarks/rl-training

writes ``rl-training.json`` (the learning curve, every evaluation instance's
cost, paired differences against greedy and stay) and ``rl-training.png``
(the learning curve).  See :mod:`coordinator.experiments.rl_train` and docs/rl.md.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from coordinator.experiments.rl_train import TrainConfig, train, write
from coordinator.terminal import configure


def main(argv: list[str] | None = None) -> None:
    d = TrainConfig()
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--scenario", default=d.scenario)
    p.add_argument("--taxis", type=int, default=d.taxis)
    p.add_argument("--minutes", type=int, default=d.minutes, help="episode length")
    p.add_argument("--timesteps", type=int, default=d.timesteps, help="agent-steps to train (one taxi-minute each)")
    p.add_argument("--eval-every", type=int, default=d.eval_every, help="agent-steps between points of the learning curve")
    p.add_argument("--eval-seeds", type=int, default=len(d.eval_seeds), help="evaluation instances per date (seeds 500 and up)")
    p.add_argument("--seed", type=int, default=d.seed, help="PPO's seed")
    p.add_argument("--out", type=Path, default=Path("rl-training"), help="folder for rl-training.json and rl-training.png")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar and no learning-curve lines, warnings only")
    args = p.parse_args(argv)
    configure(quiet=args.quiet)  # a bar with ETA on a terminal, the learning curve's points as log lines
    for name in ("taxis", "minutes", "timesteps", "eval_every", "eval_seeds"):
        if getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')} must be at least 1")
    cfg = TrainConfig(scenario=args.scenario, taxis=args.taxis, minutes=args.minutes, timesteps=args.timesteps,
                      eval_every=args.eval_every, eval_seeds=tuple(range(500, 500 + args.eval_seeds)), seed=args.seed)
    command = shlex.join(["python", "examples/rl_shared_policy.py", *(sys.argv[1:] if argv is None else argv)])
    _, doc = train(cfg, command=command)
    json_path, png_path = write(doc, args.out)
    mean = doc["mean_total_cost"]
    vs = doc["ppo_vs_greedy"]
    print(f"mean total cost: PPO {mean['ppo']:.1f}, greedy {mean['greedy']:.1f}, stay {mean['stay']:.1f}; "
          f"PPO - greedy {vs['mean_diff']:+.1f} [{vs['ci95'][0]:+.1f}, {vs['ci95'][1]:+.1f}], PPO wins {vs['wins']}/{vs['n']}")
    print(f"wrote {json_path} and {png_path}")


if __name__ == "__main__":
    main()

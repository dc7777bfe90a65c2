"""How far the cap reaches: the hops to the taxis a cap of 12 or 24 keeps, at 100 and at 1,000 taxis (issue 15).

At `surge bench plan`'s state (seed 0, 25 minutes of greedy play) the fleet
plans with `surge:adaptive=2,batch=50,cap=24` for a few minutes.  For every
decision, the taxis the cap ranks (those that can pick up within the horizon,
inside the pruning radius) are ranked again without the cap
(:func:`agents.rollout.cap_ranking`), and their hops from the agent are
recorded: how many there are, how many stand at the agent's own node, and
how far away the 11th and the 23rd nearest are (the farthest that a cap of 12 or 24 keeps besides the agent).

    PYTHONPATH=. python benchmarks/s30-cap-reach.py --scenario nyc --data ../shared/data --taxis 100 --steps 5 --hour 19
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import numpy as np

import agents.rollout as R
from bench_state import bench_state, state_args

POLICY = "surge:adaptive=2,batch=50,cap=24"


def quantiles(xs: list[int]) -> dict | None:
    if not xs:
        return None
    return {"n": len(xs), "p10": float(np.percentile(xs, 10)), "median": float(np.median(xs)), "p90": float(np.percentile(xs, 90))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    state_args(ap)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    city, sim, policy = bench_state(args, POLICY)
    horizon = policy.config.horizon
    seen: list[np.ndarray] = []
    rank = R.cap_ranking

    def recording(*a: object) -> tuple[np.ndarray, np.ndarray]:
        order, d = rank(*a)
        seen.append(d[order])
        return order, d

    rows = []
    for _ in range(args.steps):
        obs = sim.observe()
        ctx = policy.step_context(obs)
        probe = dataclasses.replace(ctx, config=dataclasses.replace(ctx.config, cap=1))
        u = ctx.base_controls.copy()
        for agent in np.flatnonzero(obs.tau == 0).tolist():
            seen.clear()
            R.cap_ranking = recording
            try:
                R._decision_inputs(probe, u[:agent], agent)
            finally:
                R.cap_ranking = rank
            d = seen[0] if seen else np.empty(0, np.int64)
            rows.append({"others": int(d.size), "within_h": int((d <= horizon).sum()), "same_node": int((d == 0).sum()),
                         "hops_11th": int(d[10]) if d.size > 10 else None, "hops_23rd": int(d[22]) if d.size > 22 else None})
            u[agent] = R.plan_agent(ctx, u[:agent], agent)
        sim.step(u)
    out = {
        "scenario": args.scenario, "taxis": args.taxis, "hour": args.hour, "steps": args.steps, "decisions": len(rows),
        "policy": POLICY, "horizon": horizon, "prune": policy.config.prune,
        "ranked_taxis": quantiles([r["others"] for r in rows]),
        "ranked_within_horizon_hops": quantiles([r["within_h"] for r in rows]),
        "ranked_at_the_agents_node": quantiles([r["same_node"] for r in rows]),
        "cap12_binds": float(np.mean([r["others"] > 11 for r in rows])),
        "cap24_binds": float(np.mean([r["others"] > 23 for r in rows])),
        "hops_to_11th": quantiles([r["hops_11th"] for r in rows if r["hops_11th"] is not None]),
        "hops_to_23rd": quantiles([r["hops_23rd"] for r in rows if r["hops_23rd"] is not None]),
    }
    print(json.dumps(out, indent=1))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()

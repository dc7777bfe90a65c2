"""Helpers of the paired-comparison scripts beside this file: rows of committed results files, paired per hour.

Run those scripts from the repository root (``python benchmarks/<script>.py``), which puts this folder on the path.
"""
import numpy as np

from coordinator.analysis import bootstrap_ci, compare_pair
from coordinator.evaluate import instance_key, read_results

FULL = "benchmarks/reproduce-full-synthetic/"


def rows(doc: dict | str) -> dict:
    """A results document's (or file's) episodes by (instance, policy label)."""
    return {(instance_key(e), e["policy"]): e for e in (read_results(doc) if isinstance(doc, str) else doc)["episodes"]}


def relative_change(costs: list[tuple[float, float]]) -> tuple[np.ndarray, tuple[float, float]]:
    """(approximation − exact) ÷ exact per (approximation, exact) cost pair, and the 95 % bootstrap CI of its mean."""
    rel = np.array([(a - e) / e for a, e in costs])
    return rel, bootstrap_ci(rel)


def pooled(costs: list[tuple[int, int]], policy: str, against: str, where: str, label: str | None = None) -> dict:
    """The row over several hours: the mean of the instances' relative differences of (policy, against) costs, with its CI."""
    rel, (lo, hi) = relative_change(costs)
    wins = int((rel < 0).sum())
    print(f"  all  {label or policy:36s} − {against}  n={len(rel)} cheaper {wins}  "
          f"relative Δ {100 * rel.mean():+.2f} % [{100 * lo:+.2f}, {100 * hi:+.2f}]")
    return {"hour": "all", "policy": policy, "against": against, "n": len(rel), "file": where, "wins": wins,
            "mean_relative_difference": float(rel.mean()), "ci95_relative": [lo, hi]}


def compare(path: str, doc: dict, ref: dict, borrowed: dict, pairs: tuple) -> list[dict]:
    """Pair ``pairs`` per hour over ``doc``'s instances, with rows of ``ref`` added under new labels (``borrowed``)."""
    inst = sorted({instance_key(e) for e in doc["episodes"]})
    same = sum(ref[(instance_key(e), "greedy")]["total_cost"] == e["total_cost"] for e in doc["episodes"] if e["policy"] == "greedy")
    print(f"{path}: greedy equal to the reference's in {same} of {len(inst)}")
    eps = doc["episodes"] + [{**ref[(k, theirs)], "policy": mine} for k in inst for theirs, mine in borrowed.items()]
    out = []
    for h in sorted({k[1] for k in inst}):
        for a, b in pairs:
            r = {**compare_pair({**doc, "episodes": eps}, a, b, h), "file": path}
            out.append(r)
            print(f"  {h} h {r['dates']} date(s) {a:45s} − {b:45s} n={r['n']} wins {r['wins']} "
                  f"Δ {r['cost_difference']:+.1f} [{r['ci95'][0]:+.1f}, {r['ci95'][1]:+.1f}] ({100 * r['relative_difference']:+.1f} %)")
    return out

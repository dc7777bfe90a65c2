"""Paired comparisons of surge with the paper-width predictor (BENCHMARKS, sessions 18-19) against the full
protocol's committed rows on the same instances. Run from the repository root: python benchmarks/s19-paper-width-pairs.py"""
import json

from coordinator.analysis import compare_pair
from coordinator.evaluate import instance_key, read_results

P, R = "surge:model=runs/pred-paper-s18", "surge (reduced model)"
G, GR = "garces2023:forecast=model,model=runs/pred-paper-s18", "garces2023:forecast=model (reduced model)"
FULL = "benchmarks/reproduce-full-synthetic/"


def rows(path: str) -> dict:
    """A results file's episodes by (instance, policy label)."""
    return {(instance_key(e), e["policy"]): e for e in read_results(path)["episodes"]}


def compare(path: str, doc: dict, ref: dict, borrowed: dict, pairs: tuple) -> list[dict]:
    """Pair ``pairs`` per hour over ``doc``'s instances, with rows of ``ref`` added under new labels (``borrowed``)."""
    inst = sorted({instance_key(e) for e in doc["episodes"]})
    same = sum(ref[(instance_key(e), "greedy")]["total_cost"] == e["total_cost"] for e in doc["episodes"] if e["policy"] == "greedy")
    print(f"{path}: greedy equal to the full protocol's in {same} of {len(inst)}")
    eps = doc["episodes"] + [{**ref[(k, theirs)], "policy": mine} for k in inst for theirs, mine in borrowed.items()]
    out = []
    for h in sorted({k[1] for k in inst}):
        for a, b in pairs:
            r = {**compare_pair({**doc, "episodes": eps}, a, b, h), "file": path}
            out.append(r)
            print(f"  {h} h {r['dates']} date(s) {a:45s} − {b:45s} n={r['n']} wins {r['wins']} "
                  f"Δ {r['cost_difference']:+.1f} [{r['ci95'][0]:+.1f}, {r['ci95'][1]:+.1f}] ({100 * r['relative_difference']:+.1f} %)")
    return out


out = []
for path, ref in (("benchmarks/s19-paper-width-routing-main.json", "results-main.json"),
                  ("benchmarks/s19-paper-width-routing-dates.json", "results-dates.json")):
    out += compare(path, read_results(path), rows(FULL + ref), {"surge": R, "garces2023": "garces2023"},
                   ((P, R), (P, "garces2023"), (R, "garces2023"), (P, "greedy")))
# The same-information comparison: garces2023 with the paper-width model too, on the ablation's instances,
# with surge's paper-width rows from the main run.
path = "benchmarks/s19-paper-width-garces-model.json"
gar, main = read_results(path), rows("benchmarks/s19-paper-width-routing-main.json")
gar["episodes"] += [main[(instance_key(e), P)] for e in gar["episodes"] if e["policy"] == "greedy"]
out += compare(path, gar, rows(FULL + "results-ablation.json"), {"garces2023:forecast=model": GR, "surge": R},
               ((G, GR), (P, G), (R, GR)))
json.dump(out, open("benchmarks/s19-paper-width-routing-pairs.json", "w"), indent=1)

"""Paired comparisons of surge with the paper-width predictor (BENCHMARKS, sessions 18-19) against the full
protocol's committed rows on the same instances. Run from the repository root: python benchmarks/s19-paper-width-pairs.py"""
import json

from coordinator.evaluate import instance_key, read_results
from pairs import FULL, compare, rows

P, R = "surge:model=runs/pred-paper-s18", "surge (reduced model)"
G, GR = "garces2023:forecast=model,model=runs/pred-paper-s18", "garces2023:forecast=model (reduced model)"

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

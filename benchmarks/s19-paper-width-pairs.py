"""Paired comparisons of surge with the paper-width predictor (BENCHMARKS, sessions 18-19) against the full
protocol's committed rows on the same instances. Run from the repository root: python benchmarks/s19-paper-width-pairs.py"""
import json
from coordinator.analysis import compare_pair
P, R = "surge:model=runs/pred-paper-s18", "surge (reduced model)"
key = lambda e: (e["date"], e["hour"], e["seed"])
out = []
for new_path, ref_path in (("benchmarks/s19-paper-width-routing-main.json", "results-main.json"),
                           ("benchmarks/s19-paper-width-routing-dates.json", "results-dates.json")):
    new = json.load(open(new_path))
    ref = {(key(e), e["policy"]): e for e in json.load(open("benchmarks/reproduce-full-synthetic/" + ref_path))["episodes"]}
    mine = [e for e in new["episodes"] if e["policy"] in ("greedy", P)]
    inst = [key(e) for e in mine if e["policy"] == "greedy"]
    same = sum(ref[(k, "greedy")]["total_cost"] == e["total_cost"] for k, e in zip(inst, [e for e in mine if e["policy"] == "greedy"]))
    print(f"{new_path}: greedy equal to the full protocol's in {same} of {len(inst)}")
    eps = mine + [{**ref[(k, "surge")], "policy": R} for k in inst] + [ref[(k, "garces2023")] for k in inst]
    doc = {**new, "episodes": eps}
    for h in sorted({k[1] for k in inst}):
        for a, b in ((P, R), (P, "garces2023"), (R, "garces2023"), (P, "greedy")):
            r = compare_pair(doc, a, b, h)
            r["file"] = new_path
            out.append(r)
            print(f"  {h} h {r['dates']} date(s) {a.split('=')[-1]:22s} − {b.split('=')[-1]:22s} n={r['n']} wins {r['wins']} "
                  f"Δ {r['cost_difference']:+.1f} [{r['ci95'][0]:+.1f}, {r['ci95'][1]:+.1f}] ({100 * r['relative_difference']:+.1f} %)")

# The same-information comparison: garces2023 with the paper-width model too, on the ablation's instances.
G, GR = "garces2023:forecast=model,model=runs/pred-paper-s18", "garces2023:forecast=model (reduced model)"
gar = json.load(open("benchmarks/s19-paper-width-garces-model.json"))
abl = {(key(e), e["policy"]): e for e in json.load(open("benchmarks/reproduce-full-synthetic/results-ablation.json"))["episodes"]}
main = {(key(e), e["policy"]): e for e in json.load(open("benchmarks/s19-paper-width-routing-main.json"))["episodes"]}
inst = [key(e) for e in gar["episodes"] if e["policy"] == "greedy"]
print(f"{len(inst)} ablation instances; greedy equal to the ablation's in "
      f"{sum(abl[(k, 'greedy')]['total_cost'] == main[(k, 'greedy')]['total_cost'] for k in inst)}")
eps = [e for e in gar["episodes"] if e["policy"] == G] + [main[(k, P)] for k in inst]
eps += [{**abl[(k, "garces2023:forecast=model")], "policy": GR} for k in inst] + [{**abl[(k, "surge")], "policy": R} for k in inst]
doc = {**gar, "episodes": eps}
for h in sorted({k[1] for k in inst}):
    for a, b in ((G, GR), (P, G), (R, GR)):
        r = compare_pair(doc, a, b, h)
        r["file"] = "benchmarks/s19-paper-width-garces-model.json"
        out.append(r)
        print(f"  {h} h {a:45s} − {b:45s} n={r['n']} wins {r['wins']} "
              f"Δ {r['cost_difference']:+.1f} [{r['ci95'][0]:+.1f}, {r['ci95'][1]:+.1f}] ({100 * r['relative_difference']:+.1f} %)")
json.dump(out, open("benchmarks/s19-paper-width-routing-pairs.json", "w"), indent=1)

"""Session 29: which part of the fast approximation costs total wait at 1,000 taxis, the cap or the adaptive sampling.

Run from the repository root: ``python benchmarks/s29-approx-decompose.py``. The named approximations differ in two
parts: ``adaptive=3,cap=24`` and ``adaptive=2,batch=50,cap=12``. ``adaptive=2,batch=50,cap=24`` shares its sampling
with the second and its cap with the first, so two paired comparisons on the same instances split the difference:

* ``adaptive=2,batch=50,cap=24`` − ``adaptive=3,cap=24``: the sampling alone (cap 24 in both);
* ``adaptive=2,batch=50,cap=12`` − ``adaptive=2,batch=50,cap=24``: the cap alone (the same sampling in both).

Where a file holds them, it also pairs cap 16 with cap 24, and ``adaptive=2,batch=50,cap=24`` with exact ``surge``;
and (session 30) the node cap ``adaptive=2,batch=50,cap_nodes=10`` with exact ``surge`` and with caps 12 and 24.
``--pool`` adds one row per pair over the instances of every file given (files of one map at different hours).

Each is listed per hour (wins, mean difference, 95 % paired bootstrap CI) and over both hours as a mean relative
difference with its CI, for every results file given (default: the 1,000-taxi and 100-taxi runs of session 29).
It writes ``benchmarks/s29-approx-decompose.json``.
"""
import argparse
import json
from pathlib import Path

from coordinator.analysis import compare_pair, paired
from coordinator.evaluate import instance_key, read_results
from pairs import pooled

FILES = ("benchmarks/s29-approx-manhattan-1000-60min-b50cap24.json", "benchmarks/s29-approx-fast-synthetic-25.json",
         "benchmarks/s29-approx-fast-nyc-25.json")
PAIRS = (
    ("surge:adaptive=2,batch=50,cap=24", "surge:adaptive=3,cap=24", "sampling: adaptive=2,batch=50 against adaptive=3"),
    ("surge:adaptive=2,batch=50,cap=12", "surge:adaptive=2,batch=50,cap=24", "cap: 12 against 24"),
    ("surge:adaptive=2,batch=50,cap=16", "surge:adaptive=2,batch=50,cap=24", "cap: 16 against 24"),
    ("surge:adaptive=2,batch=50,cap=24", "surge", "adaptive=2,batch=50,cap=24 against exact"),
    ("surge:adaptive=2,batch=50,cap_nodes=10", "surge", "adaptive=2,batch=50,cap_nodes=10 against exact"),
    ("surge:adaptive=2,batch=50,cap_nodes=10", "surge:adaptive=2,batch=50,cap=12", "cap: 10 nodes against 12 taxis"),
    ("surge:adaptive=2,batch=50,cap_nodes=10", "surge:adaptive=2,batch=50,cap=24", "cap: 10 nodes against 24 taxis"),
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", nargs="+", default=list(FILES))
    ap.add_argument("--out", default="benchmarks/s29-approx-decompose.json")
    ap.add_argument("--pool", action="store_true", help="also one row per pair over the instances of every file")
    args = ap.parse_args()
    out = []
    every: dict[tuple[str, str, str], list[tuple[int, int]]] = {}
    for path in args.files:
        doc = read_results(path)
        labels = set(doc["config"]["policies"])
        print(f"{path}: {len({instance_key(e) for e in doc['episodes']})} instances")
        for a, b, what in PAIRS:
            if a not in labels or b not in labels:
                continue
            both = []
            for h in doc["config"]["hours"]:
                r = compare_pair(doc, a, b, h)
                if r is None:
                    continue
                out.append({**r, "file": path, "part": what})
                both += [(x["total_cost"], y["total_cost"]) for x, y in paired(doc, a, b, h)]
                print(f"  {h} h  {what:45s} n={r['n']:2d} cheaper {r['wins']:2d} ties {r['ties']:2d}  "
                      f"Δ {r['cost_difference']:+7.1f} [{r['ci95'][0]:+7.1f}, {r['ci95'][1]:+7.1f}]")
            if not both:
                continue
            every.setdefault((a, b, what), []).extend(both)
            out.append({**pooled(both, a, b, path, label=what), "part": what})
    if args.pool:
        print(f"{len(args.files)} files pooled")
        out += [{**pooled(both, a, b, " + ".join(args.files), label=what), "part": what} for (a, b, what), both in every.items()]
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

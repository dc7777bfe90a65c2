"""Session 21: the fast approximations against exact `surge`, approximation − exact per hour, and their planning CPU ratios.

Run from the repository root: ``python benchmarks/s21-approx-fast-pairs.py``. It reads the committed results files,
prints one line per pair and writes ``benchmarks/s21-approx-fast-pairs.json``. ``--files`` and ``--out`` pair other
results files of the same policies (session 22's 1,000-taxi run). Each label also gets a row over all hours (``"hour": "all"``):
the mean of the instances' relative differences, (approximation − exact) ÷ exact, with its 95 % paired bootstrap CI;
``--pool`` adds one such row over the instances of every file (files of one map at different hours).
"""
import argparse
import json
import statistics
from pathlib import Path

from coordinator.analysis import compare_pair, paired
from coordinator.evaluate import instance_key, read_results
from pairs import pooled, rows

FILES = ("benchmarks/s21-approx-fast-synthetic.json", "benchmarks/s21-approx-fast-nyc.json",
         "benchmarks/s21-approx-manhattan-1000-20min.json")
OUT = "benchmarks/s21-approx-fast-pairs.json"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", nargs="+", default=list(FILES))
    ap.add_argument("--out", default=OUT)
    ap.add_argument("--pool", action="store_true", help="also one row per label over the instances of every file")
    args = ap.parse_args()
    out = []
    every: dict[str, list[tuple[int, int]]] = {}
    for path in args.files:
        doc = read_results(path)
        table = rows(doc)
        labels = [p for p in doc["config"]["policies"] if p.startswith("surge:")]
        done = {instance_key(e) for e in doc["episodes"]}
        print(f"{path}: {len(done)} instances")
        for h in sorted({k[1] for k in done}):
            for label in labels:
                both = paired(doc, label, "surge", h)
                ratio = [exact["plan_cpu_seconds_per_step"] / approx["plan_cpu_seconds_per_step"] for approx, exact in both]
                c = {"median": statistics.median(ratio), "min": min(ratio), "max": max(ratio)}
                same = sum(approx["decisions_sha256"] == exact["decisions_sha256"] for approx, exact in both)
                r = {**compare_pair(doc, label, "surge", h), "file": path, "same_decisions": same, "cpu_ratio_exact_over_approx": c}
                out.append(r)
                print(f"  {h} h {label:36s} − surge  n={r['n']} cheaper {r['wins']} ties {r['ties']}  "
                      f"Δ {r['cost_difference']:+.1f} [{r['ci95'][0]:+.1f}, {r['ci95'][1]:+.1f}] ({100 * r['relative_difference']:+.1f} %)"
                      f"  same decisions {same}  CPU exact/approx {c['median']:.2f}× ({c['min']:.2f}–{c['max']:.2f})")
        for label in labels:
            both = [(table[(k, label)]["total_cost"], table[(k, "surge")]["total_cost"]) for k in sorted(done)]
            every.setdefault(label, []).extend(both)
            out.append(pooled(both, label, "surge", path))
    if args.pool:
        print(f"{len(args.files)} files pooled")
        out += [pooled(both, label, "surge", " + ".join(args.files)) for label, both in every.items()]
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()

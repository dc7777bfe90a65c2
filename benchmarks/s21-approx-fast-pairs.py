"""Session 21: the fast approximations against exact `surge`, approximation − exact per hour, and their planning CPU ratios.

Run from the repository root: ``python benchmarks/s21-approx-fast-pairs.py``. It reads the committed results files,
prints one line per pair and writes ``benchmarks/s21-approx-fast-pairs.json``. A file whose run has not finished
(the 1,000-taxi one) is paired over the instances it holds.
"""
import json
import statistics
import sys
from pathlib import Path

from coordinator.analysis import compare_pair
from coordinator.evaluate import instance_key, read_results

sys.path.insert(0, str(Path(__file__).parent))
from pairs import rows  # noqa: E402

FILES = ("benchmarks/s21-approx-fast-synthetic.json", "benchmarks/s21-approx-fast-nyc.json",
         "benchmarks/s21-approx-manhattan-1000-20min.json")
OUT = "benchmarks/s21-approx-fast-pairs.json"


def cpu_ratio(table: dict, exact: str, approx: str, hour: int) -> dict:
    """Median and range over the hour's instances of exact's planning CPU per step over the approximation's."""
    r = [table[(k, exact)]["plan_cpu_seconds_per_step"] / table[(k, approx)]["plan_cpu_seconds_per_step"]
         for k, p in table if p == approx and k[1] == hour and (k, exact) in table]
    return {"median": statistics.median(r), "min": min(r), "max": max(r)} if r else {}


def main() -> None:
    out = []
    for path in FILES:
        if not Path(path).exists():
            continue
        doc = read_results(path)
        table = rows(doc)
        labels = [p for p in doc["config"]["policies"] if p.startswith("surge:")]
        done = {instance_key(e) for e in doc["episodes"]}
        print(f"{path}: {len(done)} instances")
        for h in sorted({k[1] for k in done}):
            for label in labels:
                r = compare_pair(doc, label, "surge", h)
                if r is None:
                    continue
                same = sum(table[(k, label)]["decisions_sha256"] == table[(k, "surge")]["decisions_sha256"]
                           for k in done if k[1] == h and (k, label) in table and (k, "surge") in table)
                r = {**r, "file": path, "same_decisions": same, "cpu_ratio_exact_over_approx": cpu_ratio(table, "surge", label, h)}
                out.append(r)
                c = r["cpu_ratio_exact_over_approx"]
                print(f"  {h} h {label:36s} − surge  n={r['n']} cheaper {r['wins']} ties {r['ties']}  "
                      f"Δ {r['cost_difference']:+.1f} [{r['ci95'][0]:+.1f}, {r['ci95'][1]:+.1f}] ({100 * r['relative_difference']:+.1f} %)"
                      f"  same decisions {same}  CPU exact/approx {c['median']:.2f}× ({c['min']:.2f}–{c['max']:.2f})")
    Path(OUT).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()

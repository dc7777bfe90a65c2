"""Session 25: what each planning approximation buys (planning CPU) and costs (total wait), at every fleet size measured.

Run from the repository root: ``python benchmarks/s25-approx-tradeoff.py``. It reads the committed results files of
issue 15's quality runs, pairs every approximation with exact ``surge`` instance by instance, and writes
``benchmarks/s25-approx-tradeoff.json`` and ``benchmarks/s25-approx-tradeoff.png``. Per setting and approximation:

* the mean over instances of (approximation − exact) ÷ exact total cost, both hours together, with its 95 % paired
  bootstrap CI and the instances where the approximation was cheaper;
* the planning CPU per step of exact ``surge`` ÷ the approximation's, median over the same instances, as that run
  measured it (runs of different sessions used different code and machines: compare ratios, not seconds). Runs that
  recorded no CPU seconds (session 6's) give the ratio of planning wall seconds, and ``ratio_of`` says so.

A setting whose run has fewer than :data:`MIN_SEEDS` instances at some hour is listed as incomplete and not plotted.
"""
import argparse
import json
import statistics
from collections import Counter
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from coordinator.analysis import paired
from coordinator.evaluate import instance_key, read_results
from pairs import relative_change

MIN_SEEDS = 10
SETTINGS = (
    ("synthetic city, 100 taxis", ("benchmarks/i15-approx-synthetic-current.json", "benchmarks/s29-approx-fast-synthetic-25.json")),
    ("real mid/lower-Manhattan map, 100 taxis", ("benchmarks/i15-approx-nyc.json", "benchmarks/s29-approx-fast-nyc-25.json")),
    ("all of Manhattan, 300 taxis", ("benchmarks/i15-approx-manhattan-300.json",)),
    ("all of Manhattan, 1,000 taxis, 20-minute episodes",
     ("benchmarks/s22-approx-manhattan-1000-20min.json", "benchmarks/s22-approx-manhattan-1000-20min-17h.json")),
    ("all of Manhattan, 1,000 taxis, 60-minute episodes", ("benchmarks/s29-approx-manhattan-1000-60min-b50cap24.json",)),
)
MARKERS = {"surge:adaptive=3": "^", "surge:cap=24": "v", "surge:adaptive=3,cap=24": "D",
           "surge:adaptive=2,batch=50,cap=24": "P",
           "surge:adaptive=2,batch=50,cap=16": "s", "surge:adaptive=2,batch=50,cap=12": "o"}


def setting_rows(name: str, files: tuple[str, ...]) -> list[dict]:
    """One row per approximation of a setting, its instances pooled over the setting's files and hours."""
    pairs: dict[str, list[tuple[dict, dict]]] = {}
    for path in files:
        doc = read_results(path)
        for label in (p for p in doc["config"]["policies"] if p.startswith("surge:")):
            both = [pair for h in doc["config"]["hours"] for pair in paired(doc, label, "surge", h)]
            pairs.setdefault(label, []).extend(sorted(both, key=lambda pair: instance_key(pair[0])))
    out = []
    for label, both in pairs.items():
        per_hour = Counter(a["hour"] for a, _ in both)
        rel, (lo, hi) = relative_change([(a["total_cost"], e["total_cost"]) for a, e in both])
        # Session 6's run recorded wall seconds only; their ratio is of wall time.
        clock = "plan_cpu_seconds_per_step" if all("plan_cpu_seconds_per_step" in a and "plan_cpu_seconds_per_step" in e
                                                   for a, e in both) else "plan_seconds_per_step"
        cpu = [e[clock] / a[clock] for a, e in both]
        complete = min(per_hour.values()) >= MIN_SEEDS
        out.append({"setting": name, "files": list(files), "policy": label, "against": "surge",
                    "instances_per_hour": {str(h): n for h, n in sorted(per_hour.items())}, "complete": complete,
                    "n": len(rel), "cheaper": int((rel < 0).sum()), "mean_relative_difference": float(rel.mean()),
                    "ci95_relative": [lo, hi] if complete else None,
                    "ratio_of": clock, "cpu_ratio_exact_over_approx": {"median": statistics.median(cpu), "min": min(cpu), "max": max(cpu)}})
        r = out[-1]
        ci = f"[{100 * lo:+.2f}, {100 * hi:+.2f}]" if complete else f"(incomplete: {r['instances_per_hour']} of {MIN_SEEDS} per hour, no CI)"
        print(f"{name:52s} {label:34s} n={r['n']:3d} cheaper {r['cheaper']:3d}  Δ {100 * r['mean_relative_difference']:+.2f} % {ci}"
              f"  {'CPU' if clock.startswith('plan_cpu') else 'wall'} exact/approx {r['cpu_ratio_exact_over_approx']['median']:.2f}×")
    return out


def plot(table: list[dict], path: str) -> None:
    fig, ax = plt.subplots(figsize=(9, 5.5))
    colours = dict(zip((s for s, _ in SETTINGS), plt.get_cmap("tab10").colors))
    for r in (r for r in table if r["complete"]):
        x, y = r["cpu_ratio_exact_over_approx"]["median"], 100 * r["mean_relative_difference"]
        lo, hi = (100 * v for v in r["ci95_relative"])
        ax.errorbar(x, y, yerr=[[y - lo], [hi - y]], fmt=MARKERS.get(r["policy"], "x"), color=colours[r["setting"]],
                    capsize=3, ms=7)
    ax.axhline(0, color="grey", lw=0.8)
    ax.set_xscale("log", base=2)
    ax.set_xticks([1, 2, 4, 8, 16], ["1×", "2×", "4×", "8×", "16×"])
    ax.set_xlabel("planning CPU per step, exact ÷ approximation (median over instances; wall time for session 6's runs)")
    ax.set_ylabel("total cost, approximation vs exact (%), 95 % CI")
    ax.set_title("What the named approximations of `surge` buy and cost (17 and 19 h pooled)")
    shown = {r["setting"] for r in table if r["complete"]}
    handles = [plt.Line2D([], [], color=colours[s], marker="o", ls="", label=s) for s, _ in SETTINGS if s in shown]
    handles += [plt.Line2D([], [], color="black", marker=m, ls="", label=p.removeprefix("surge:"))
                for p, m in MARKERS.items() if any(r["policy"] == p and r["complete"] for r in table)]
    ax.legend(handles=handles, fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="benchmarks/s25-approx-tradeoff", help="path without suffix: .json and .png are written")
    args = ap.parse_args()
    table = [r for name, files in SETTINGS for r in setting_rows(name, files)]
    Path(args.out + ".json").write_text(json.dumps(table, indent=1) + "\n")
    plot(table, args.out + ".png")
    print(f"wrote {args.out}.json and {args.out}.png")


if __name__ == "__main__":
    main()

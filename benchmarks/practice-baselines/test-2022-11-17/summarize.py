"""surge − rebalance and surge − match (and the other pairs) per map, date and hour from the results files, seeds finished at every hour.

Run from the repository root: python benchmarks/practice-baselines/test-2022-11-17/summarize.py

``KEEP`` is the default ``surge``, named in full; ``FAST`` is it without ``keep`` (the files record no ``keep``, so
it reads as ``surge:keep=none``), ``S1000`` that with 1,000 samples. A bare ``surge`` in these files is the greedy
rollout (``surge:base=greedy,scope=local,horizon=10,samples=1000,cap=24,adaptive=2,keep=none``), as the files record
(``surge_defaults``).
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

from city.fingerprint import machine
from coordinator.experiments.analysis import common_instances, compare_pair, complete_seeds, summarize
from coordinator.experiments.evaluate import read_results, write_json
from coordinator.experiments.practice import against_practice

HERE = Path(__file__).parent
#: Each results file, by the name the summary gives it.
FILES = {
    "synthetic, 10 seeds at 17 and 19 h": HERE / "results-synthetic.json",
    "nyc (real 2022 level), 10 seeds at 4 hours": HERE / "results-nyc-real-level.json",
    "synthetic, main table, surge:keep=none": HERE / "fast-synthetic.json",
    "nyc (real 2022 level), main table, surge:keep=none": HERE / "fast-nyc.json",
    "synthetic, main table, the greedy rollout": HERE / "main-synthetic.json",
    "nyc (real 2022 level), main table, the greedy rollout": HERE / "main-nyc.json",
    "synthetic, 20-minute rollout over rebalance at 4 hours": HERE / "h20-synthetic.json",
    "nyc (real 2022 level), 20-minute rollout over rebalance at 4 hours": HERE / "h20-nyc.json",
    "nyc (real 2022 level), main table, garces2023 at 17 and 19 h": HERE / "garces-nyc.json",
    "synthetic, main table, surge:keep=none with 1,000 samples": HERE / "samples1000-synthetic.json",
    "nyc (real 2022 level), main table, surge:keep=none with 1,000 samples": HERE / "samples1000-nyc.json",
    "synthetic, main table, surge": HERE / "keep-synthetic.json",
    "nyc (real 2022 level), main table, surge": HERE / "keep-nyc.json",
    "synthetic, further test dates": HERE.parent / "test-dates" / "results-synthetic.json",
    "nyc (real 2022 level), further test dates": HERE.parent / "test-dates" / "results-nyc.json",
    "synthetic, further test dates, 20-minute rollout over rebalance": HERE.parent / "test-dates" / "h20-synthetic.json",
    "nyc (real 2022 level), further test dates, 20-minute rollout over rebalance": HERE.parent / "test-dates" / "h20-nyc.json",
    "synthetic, further test dates, surge": HERE.parent / "test-dates" / "keep-synthetic.json",
    "nyc (real 2022 level), further test dates, surge": HERE.parent / "test-dates" / "keep-nyc.json",
}
H10, H20 = "surge:base=rebalance,scope=map", "surge:base=rebalance,scope=map,horizon=20"
FAST = H20 + ",samples=200,cap=12,adaptive=1"
S1000 = H20 + ",samples=1000,cap=12,adaptive=1"
KEEP = FAST + ",keep=2"
PAIRS = ((FAST, "rebalance"), (FAST, "match"), (FAST, "surge"), (FAST, H20), ("surge", "rebalance"), ("surge", "match"), (H20, "rebalance"),
         (H20, "match"), (H20, "surge"), (H20, H10), (H10, "rebalance"), (H10, "surge"), ("surge", "ia"), ("rebalance", "match"), ("match", "ia"),
         (FAST, "garces2023"), (S1000, "rebalance"), (S1000, "match"), (S1000, FAST),
         (KEEP, "rebalance"), (KEEP, "match"), (KEEP, FAST))
GAP = ("surge", "rebalance", "match", H10, H20, FAST, "garces2023", S1000, KEEP)


def main() -> None:
    out: dict = {"command": "the run*.sh scripts beside this file and in ../test-dates; "
                            "python benchmarks/practice-baselines/test-2022-11-17/summarize.py",
                 "date": dt.date.today().isoformat(), "machine": machine(), "files": {}}
    for name, path in FILES.items():
        if not path.exists():
            continue
        whole = complete_seeds(read_results(path))
        entry: dict = {"file": str(path.relative_to(HERE.parent)), "dates": {}}
        for date in sorted({e["date"] for e in whole["episodes"]}):
            doc = {**whole, "episodes": [e for e in whole["episodes"] if e["date"] == date]}
            hours = sorted({e["hour"] for e in doc["episodes"]})
            pairs = [p for p in (compare_pair(doc, a, b, h) for a, b in PAIRS for h in hours) if p]
            # Each share over the instances where every GAP policy of the file ran, as on the results page.
            common = complete_seeds(common_instances(doc, GAP))
            gap = {f"{r['hour']} {r['policy']}": r["gap_closed"] for r in summarize(common) if r["policy"] in GAP}
            entry["dates"][date] = {"seeds": sorted({e["seed"] for e in doc["episodes"]}), "pairs": pairs,
                                    "verdicts": {p: against_practice(doc, p) for p in ("surge", FAST, KEEP) if p in doc["config"]["policies"]}, "gap_closed": gap}
            for r in pairs:
                print(f"{name} {date} {r['hour']}h {r['policy']} − {r['against']}: {r['cost_difference']:+.1f} "
                      f"[{r['ci95'][0]:+.1f}, {r['ci95'][1]:+.1f}], wins {r['wins']}/{r['n']}")
            for k, v in gap.items():
                print(f"{name} {date} gap closed {k}: " + (f"{100 * v:.1f} %" if v is not None else "—"))
        out["files"][name] = entry
    write_json(out, HERE / "summary.json")


if __name__ == "__main__":
    main()

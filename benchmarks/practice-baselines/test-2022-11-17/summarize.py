"""surge − rebalance and surge − match (and the other pairs) per map and hour from the results files, seeds finished at every hour.

Run from the repository root: python benchmarks/practice-baselines/test-2022-11-17/summarize.py
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

from city.fingerprint import machine
from coordinator.experiments.analysis import compare_pair, complete_seeds, summarize
from coordinator.experiments.evaluate import read_results, write_json
from coordinator.experiments.practice import against_practice

HERE = Path(__file__).parent
PAIRS = (("surge", "rebalance"), ("surge", "match"), ("surge:base=rebalance,scope=map", "rebalance"), ("surge:base=rebalance,scope=map", "surge"), ("surge", "ia"), ("rebalance", "match"), ("match", "ia"))


def main() -> None:
    out: dict = {"command": "benchmarks/practice-baselines/test-2022-11-17/run.sh; python benchmarks/practice-baselines/test-2022-11-17/summarize.py",
                 "date": dt.date.today().isoformat(), "machine": machine(), "maps": {}}
    for m in ("synthetic", "nyc"):
        path = HERE / f"results-{m}.json"
        if not path.exists():
            continue
        doc = complete_seeds(read_results(path))
        seeds = sorted({e["seed"] for e in doc["episodes"]})
        pairs = [compare_pair(doc, a, b, h) for a, b in PAIRS for h in (17, 19)]
        gap = {f"{r['hour']} {r['policy']}": r["gap_closed"] for r in summarize(doc) if r["policy"] in ("surge", "rebalance", "match", "surge:base=rebalance,scope=map")}
        cpu = {p: 1e3 * sum(e["plan_cpu_seconds_per_step"] for e in doc["episodes"] if e["policy"] == p)
               / sum(1 for e in doc["episodes"] if e["policy"] == p) for p in dict.fromkeys(e["policy"] for e in doc["episodes"])}
        out["maps"][m] = {"seeds": seeds, "pairs": [p for p in pairs if p], "verdicts": against_practice(doc, "surge"),
                          "gap_closed": gap, "plan_cpu_ms_per_step": cpu}
        print(f"{m} planning CPU ms per step: " + ", ".join(f"{p} {v:.2f}" for p, v in cpu.items()))
        for r in out["maps"][m]["pairs"]:
            print(f"{m} {r['hour']}h {r['policy']} − {r['against']}: {r['cost_difference']:+.1f} "
                  f"[{r['ci95'][0]:+.1f}, {r['ci95'][1]:+.1f}], wins {r['wins']}/{r['n']}")
        for k, v in gap.items():
            print(f"{m} gap closed {k}: {100 * v:.1f} %" if v is not None else f"{m} gap closed {k}: —")
    write_json(out, HERE / "summary.json")


if __name__ == "__main__":
    main()

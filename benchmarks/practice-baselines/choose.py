"""The settings of match and rebalance chosen on the validation grid: least mean total cost over both maps, hours and seeds.

Reads grid-synthetic.json and grid-nyc.json (written by grid.sh) and writes choice.json.
Run from the repository root: python benchmarks/practice-baselines/choose.py
"""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import numpy as np

from city.fingerprint import machine
from coordinator.experiments.evaluate import write_json

HERE = Path(__file__).parent
MAPS = ("synthetic", "nyc")


def main() -> None:
    costs: dict[str, dict[str, list[float]]] = {}
    cpu: dict[str, list[float]] = {}
    for m in MAPS:
        for e in json.loads((HERE / f"grid-{m}.json").read_text())["episodes"]:
            costs.setdefault(e["policy"], {}).setdefault(f"{m} {e['hour']}h", []).append(e["total_cost"])
            cpu.setdefault(e["policy"], []).append(e["plan_cpu_seconds_per_step"])
    table = {p: {**{k: float(np.mean(v)) for k, v in by.items()}, "all": float(np.mean(sum(by.values(), []))),
                 "instances": sum(len(v) for v in by.values()), "plan_cpu_ms_per_step": 1e3 * float(np.mean(cpu[p]))}
             for p, by in costs.items()}
    best = {name: min((p for p in table if p.split(":")[0] == name), key=lambda p: table[p]["all"]) for name in ("match", "rebalance")}
    write_json({"command": "benchmarks/practice-baselines/grid.sh; python benchmarks/practice-baselines/choose.py",
                "date": dt.date.today().isoformat(), "machine": machine(),
                "rule": "least mean total cost over 2022-08-02 (a validation date), hours 17 and 19, seeds 0-4, both maps; 100 taxis, 60 minutes, previous-hour demand",
                "chosen": best, "mean_total_cost": table}, HERE / "choice.json")
    for p, r in sorted(table.items(), key=lambda kv: kv[1]["all"]):
        print(f"{p:36s} {r['all']:8.1f}  " + "  ".join(f"{k} {r[k]:7.1f}" for k in r if k.endswith("h")) + f"  {r['plan_cpu_ms_per_step']:.2f} ms")
    print("chosen:", best)


if __name__ == "__main__":
    main()

"""Paired differences of the rollout variants against the baselines, from the episode files of this folder.

    python benchmarks/rollout-variants/pairs.py [--json pairs.json]

For each map and each pair (variant, reference) on the instances both ran:
the mean of variant − reference in total cost with a 95 % t interval, the
wins (variant cheaper), and the same split into minutes 0-19 and 20-59
(sums of the stage costs).  Negative means the variant is better.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy import stats

HERE = Path(__file__).parent
#: The rollout over ``rebalance`` chosen here; its cheaper approximations are paired with it too.
H20 = "surge:forecast=previous-hour,base=rebalance,scope=map,horizon=20"
#: Its fast variant, ``surge:keep=none`` (``surge`` is it with ``keep=2``): the variants with one approximation off and those
#: with ``keep`` are paired with it too.
FAST = H20 + ",samples=200,cap=12,adaptive=1"
#: How the results page names the 20-minute rollout's variants: by the approximation each turns off.
NAMES = {H20: "the full rollout", FAST: "`surge:keep=none` (all three)", H20 + ",samples=1000,cap=12,adaptive=1": "samples=1000 (not 200)",
         H20 + ",samples=200,cap=24,adaptive=1": "cap=24 (not 12)", H20 + ",samples=200,cap=12,adaptive=2": "adaptive=2 (not 1)"}


#: The four hours of the validation runs of ``keep`` (the others ran at 17 and 19 h).
ALL_HOURS = (15, 17, 19, 21)


def load() -> dict[str, dict[tuple, dict]]:
    """Per map, episode rows keyed by (date, hour, seed, policy)."""
    out: dict[str, dict[tuple, dict]] = defaultdict(dict)
    for f in sorted(HERE.glob("*.json")):
        doc = json.loads(f.read_text())
        if doc.get("schema") != "surge.rollout-variants/1":
            continue
        # The real map at its real 2022 hourly level is another world than at its 2018 zone-profile level.
        world = doc["scenario"] + (" (real level)" if doc.get("demand_source", "").startswith("hourly-totals") else "")
        for e in doc["episodes"]:
            # An episode that two files ran (the same costs: runs are deterministic) is read from the first.
            out[world].setdefault((e["date"], e["hour"], e["seed"], e["policy"]), e)
    return out


def ci(d: np.ndarray) -> tuple[float, float, float]:
    m = float(d.mean())
    if d.size < 2:
        return m, float("nan"), float("nan")
    h = float(stats.t.ppf(0.975, d.size - 1) * d.std(ddof=1) / np.sqrt(d.size))
    return m, m - h, m + h


def pair(rows: dict[tuple, dict], a: str, b: str, hours: tuple[int, ...] | None = None) -> dict | None:
    keys = sorted({k[:3] for k in rows if k[3] == a} & {k[:3] for k in rows if k[3] == b})
    if hours is not None:
        keys = [k for k in keys if k[1] in hours]
    if not keys or (hours is not None and {k[1] for k in keys} != set(hours)):
        return None  # pooled over every hour asked for, or not at all
    res: dict = {"variant": a, "reference": b, "n": len(keys)}
    for part, lo, hi in (("total", 0, None), ("minutes_0_19", 0, 20), ("minutes_20_59", 20, None)):
        d = np.array([sum(rows[k + (a,)]["stage_costs"][lo:hi]) - sum(rows[k + (b,)]["stage_costs"][lo:hi]) for k in keys], float)
        m, low, high = ci(d)
        res[part] = {"mean": round(m, 1), "ci95": [round(low, 1), round(high, 1)], "wins": int((d < 0).sum())}
    res["plan_seconds_per_step"] = round(float(np.mean([rows[k + (a,)]["plan_seconds_per_step"] for k in keys])), 4)
    return res


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json")
    a = p.parse_args()
    data = load()
    out = []
    for scen, rows in sorted(data.items()):
        labels = sorted({k[3] for k in rows})
        refs = [r for r in labels if r.startswith(("rebalance", "match"))] + [r for r in ("surge:forecast=previous-hour", "ia", H20, FAST) if r in labels]
        for hours in ((17, 19), (17,), (19,), ALL_HOURS, (15,), (21,)):
            for v in labels:
                variant_of_h20 = v.startswith(H20 + ",")
                for r in refs:
                    if v == r or (r == FAST and not variant_of_h20):
                        continue
                    res = pair(rows, v, r, hours)
                    if res is None:
                        continue
                    res.update(scenario=scen, hours=list(hours))
                    if v.startswith(FAST + ",keep="):
                        res.update(family="keep", reference_name=NAMES.get(r, f"`{r.split(':')[0]}`"), variant_name=v[len(FAST) + 1:])
                    elif variant_of_h20 and r in (H20, FAST):
                        res.update(family="approximations", reference_name=NAMES[r], variant_name=NAMES.get(v, v[len(H20) + 1:]))
                    out.append(res)
                    t, f, s = res["total"], res["minutes_0_19"], res["minutes_20_59"]
                    print(f"{scen:9} {'+'.join(map(str, hours)):5} {v:45} − {r:33} n={res['n']:2}  total {t['mean']:+7.1f} "
                          f"[{t['ci95'][0]:+.1f}, {t['ci95'][1]:+.1f}] wins {t['wins']}/{res['n']}   0-19 {f['mean']:+6.1f}   "
                          f"20-59 {s['mean']:+6.1f} [{s['ci95'][0]:+.1f}, {s['ci95'][1]:+.1f}]")
    if a.json:
        Path(a.json).write_text(json.dumps({"command": " ".join(["python"] + sys.argv), "pairs": out}, indent=1))


if __name__ == "__main__":
    main()

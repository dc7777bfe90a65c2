"""``surge`` against the state of practice: the strongest practical baseline per hour, and the computed verdict.

The practical baselines are what fleet operators and simulators run:
``match`` (optimal batched matching) and ``rebalance`` (``match`` plus
forecast-driven rebalancing), each possibly under several labels.  Per hour,
the strongest is the one with the least mean total cost over the instances
it shares with the ``surge`` label; only baselines that plan with the same
forecast as ``surge`` (or with none, like ``match``) compete, so the
comparison is like with like.  The verdict "beats the strongest practical
baseline" is *yes* at an hour when ``surge`` − strongest has its 95 % CI
(paired bootstrap) below zero over at least :data:`MIN_CLEAR` instances.
"""

from __future__ import annotations

import numpy as np

from agents.base import policy_class, split_policy
from coordinator.experiments.analysis import compare_pair, paired

#: The registry names of the practical baselines.
PRACTICAL = ("match", "rebalance")
#: Instances an hour needs before its verdict can be *yes*.
MIN_CLEAR = 5


def forecast_of(doc: dict, label: str) -> str | None:
    """The forecast a label of ``doc`` planned with (its options, the run's, or the policy's default); ``None`` if it reads none."""
    name, own = split_policy(label)
    cls = policy_class(name)
    if not any(o.name == "forecast" for o in cls.options):
        return None
    opts = {**doc.get("config", {}).get("policy_options", {}).get(label, {}), **own}
    return opts.get("forecast") or getattr(cls, "defaults", {}).get("forecast")


def practical_labels(doc: dict, policy: str) -> list[str]:
    """The labels of ``doc`` that are practical baselines planning with ``policy``'s forecast or with none."""
    mine = forecast_of(doc, policy)
    labels = dict.fromkeys(e["policy"] for e in doc["episodes"])
    return [p for p in labels if split_policy(p)[0] in PRACTICAL and forecast_of(doc, p) in (None, mine)]


def against_practice(doc: dict, policy: str) -> list[dict]:
    """Per hour: the strongest practical baseline, ``policy`` − it (wins, mean, 95 % CI) and the verdict (``beats``)."""
    out = []
    labels = practical_labels(doc, policy)
    for h in sorted({e["hour"] for e in doc["episodes"]}):
        means = {}
        for p in labels:
            pairs = paired(doc, policy, p, h)
            if pairs:
                means[p] = float(np.mean([b["total_cost"] for _, b in pairs]))
        if not means:
            continue
        best = min(means, key=lambda p: (means[p], p))
        r = compare_pair(doc, policy, best, h)
        out.append({**r, "strongest": best, "forecast": forecast_of(doc, policy), "candidates": means,
                    "beats": bool(r["n"] >= MIN_CLEAR and r["ci95"][1] < 0)})
    return out


def verdict_lines(rows: list[dict]) -> list[str]:
    """One line per hour: ``beats the strongest practical baseline: yes/no``, with the numbers it rests on."""
    lines = []
    for r in rows:
        few = f"; fewer than {MIN_CLEAR} instances: not judged" if r["n"] < MIN_CLEAR else ""
        lines.append(f"{r['hour']} h: {r['policy']} beats the strongest practical baseline: {'yes' if r['beats'] else 'no'} "
                     f"(strongest {r['strongest']}, forecast {r['forecast'] or 'none'}; difference {r['cost_difference']:+.1f} "
                     f"[{r['ci95'][0]:+.1f}, {r['ci95'][1]:+.1f}], {r['wins']}/{r['n']} wins{few})")
    return lines


def report_section(doc: dict, policy: str = "surge", heading: str = "## Against the state of practice") -> list[str]:
    """The REPORT.md section under ``heading``: a table per hour and the verdict lines, computed from ``doc``."""
    rows = against_practice(doc, policy)
    lines = [heading, "",
             f"`{policy}` paired with the strongest practical baseline of each hour (`match`: optimal batched matching; "
             "`rebalance`: `match` plus forecast-driven rebalancing of idle taxis), among those planning with the same "
             f"forecast as `{policy}` or with none. Verdict *yes*: the 95 % CI of the mean difference is below zero "
             f"(at least {MIN_CLEAR} instances).", ""]
    if not rows:
        return lines + ["No practical baseline shares instances with this policy in these results.", ""]
    lines += ["| hour | strongest | its mean cost | `" + policy + "` − it | 95 % CI | wins | beats it |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['hour']}h | `{r['strongest']}` | {r['candidates'][r['strongest']]:.1f} | {r['cost_difference']:+.1f} | "
                     f"[{r['ci95'][0]:+.1f}, {r['ci95'][1]:+.1f}] | {r['wins']} / {r['n']} | {'yes' if r['beats'] else 'no'} |")
    return lines + [""] + [f"- {line}" for line in verdict_lines(rows)] + [""]

"""Tables, paired comparisons with confidence intervals, and plots of a ``surge.results/1`` document.

Every paired comparison is made instance by instance, (date, hour, seed), per
hour: wins out of instances, the mean cost difference, and its 95 %
confidence interval by the paired percentile bootstrap (10,000 resamples of
the instances' differences, seeded, so a document gives one interval).
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

import numpy as np

from city.errors import ConfigError
from coordinator.experiments.results import METRICS, ORACLES, instance_key
from coordinator.experiments.tables import text_table

BOOTSTRAP_RESAMPLES = 10_000


def select(doc: dict, dates: Iterable[str] | None = None, hours: Iterable[int] | None = None) -> dict:
    """The document restricted to some dates and hours."""
    dates = None if dates is None else set(dates)
    hours = None if hours is None else set(hours)
    eps = [e for e in doc["episodes"] if (dates is None or e["date"] in dates) and (hours is None or e["hour"] in hours)]
    return {**doc, "episodes": eps}


def summarize(doc: dict) -> list[dict]:
    """Mean and standard deviation of every metric per (hour, policy), over all dates and seeds.

    ``gap_closed`` is the share of the greedy→oracle gap in mean total cost
    that the policy closes, (greedy - policy) / (greedy - oracle), where the
    run included greedy (the paper's yardstick); ``gap_closed_auction`` is the
    same against ``oracle-auction``.
    """
    out = []
    eps = doc["episodes"]
    for h in sorted({e["hour"] for e in eps}):
        for p in dict.fromkeys(e["policy"] for e in eps):
            sel = [e for e in eps if e["hour"] == h and e["policy"] == p]
            if not sel:
                continue
            row = {"hour": h, "policy": p, "n": len(sel)}
            for m in METRICS:
                vals = np.array([e[m] for e in sel], dtype=float)
                row[m] = (float(vals.mean()), float(vals.std()))
            for name, field in (("gap_closed", "oracle_cost"), ("gap_closed_auction", "oracle_auction_cost")):
                row[name] = None
                if all(e.get("greedy_cost") is not None and e.get(field) is not None for e in sel):
                    greedy = np.mean([e["greedy_cost"] for e in sel])
                    gap = greedy - np.mean([e[field] for e in sel])
                    if gap > 0:
                        row[name] = float((greedy - row["total_cost"][0]) / gap)
            out.append(row)
    return out


def common_instances(doc: dict, policies: list[str] | tuple[str, ...]) -> dict:
    """The document restricted to the instances on which every one of ``policies`` that it holds ran, so that they compare like for like."""
    held = {e["policy"] for e in doc["episodes"]} & set(policies)
    ran: dict[tuple, set] = {}
    for e in doc["episodes"]:
        ran.setdefault((e["date"], e["hour"], e["seed"]), set()).add(e["policy"])
    return {**doc, "episodes": [e for e in doc["episodes"] if ran[(e["date"], e["hour"], e["seed"])] >= held]}


def complete_seeds(doc: dict) -> dict:
    """The document restricted to (date, seed) pairs finished at every hour of their date, so that hours compare like for like.

    A run cut short (or still going) leaves its last seed at some hours only.
    """
    eps = doc["episodes"]
    hours: dict[str, set] = {}
    at: dict[tuple, set] = {}
    for e in eps:
        hours.setdefault(e["date"], set()).add(e["hour"])
        at.setdefault((e["date"], e["seed"]), set()).add(e["hour"])
    keep = {k for k, hs in at.items() if hs == hours[k[0]]}
    return {**doc, "episodes": [e for e in eps if (e["date"], e["seed"]) in keep]}


def bootstrap_ci(diffs: np.ndarray, level: float = 0.95, resamples: int = BOOTSTRAP_RESAMPLES, seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean of paired differences."""
    diffs = np.asarray(diffs, dtype=float)
    if diffs.size == 0:
        return (float("nan"), float("nan"))
    rng = np.random.default_rng(seed)
    means = diffs[rng.integers(0, diffs.size, size=(resamples, diffs.size))].mean(axis=1)
    lo, hi = np.quantile(means, [(1 - level) / 2, (1 + level) / 2])
    return (float(lo), float(hi))


def paired(doc: dict, policy: str, other: str, hour: int) -> list[tuple[dict, dict]]:
    """``(policy, other)`` episode pairs of one hour, instance by instance."""
    by = {(*instance_key(e), e["policy"]): e for e in doc["episodes"]}
    return [(e, by[(*instance_key(e), other)]) for e in doc["episodes"]
            if e["hour"] == hour and e["policy"] == policy and (*instance_key(e), other) in by]


def compare_pair(doc: dict, policy: str, other: str, hour: int) -> dict | None:
    """``policy`` against ``other`` at one hour: wins, mean difference with its 95 % CI, overhead and served changes."""
    pairs = paired(doc, policy, other, hour)
    if not pairs:
        return None
    mine, theirs = (np.array([[a[m] for a in side] for m in METRICS[:4]], dtype=float) for side in zip(*pairs))
    diff = mine[0] - theirs[0]
    lo, hi = bootstrap_ci(diff)
    return {
        "hour": hour,
        "policy": policy,
        "against": other,
        "n": len(pairs),
        "dates": len({a["date"] for a, _ in pairs}),
        "wins": int((diff < 0).sum()),
        "ties": int((diff == 0).sum()),
        "cost_difference": float(diff.mean()),
        "ci95": [lo, hi],
        "relative_difference": float(diff.mean() / theirs[0].mean()) if theirs[0].mean() > 0 else None,
        "overhead_reduction": float(1 - mine[3].mean() / theirs[3].mean()) if theirs[3].mean() > 0 else None,
        "served_change": float(mine[2].mean() / theirs[2].mean() - 1),
        "reference_oracle": doc.get("reference_oracle", "oracle"),
        "below_oracle": int(sum(a["total_cost"] < a["oracle_cost"] for a, _ in pairs)),
        "below_oracle_auction": int(sum(a["total_cost"] < a.get("oracle_auction_cost", -1) for a, _ in pairs)),
    }


def compare(doc: dict, policy: str, against: Iterable[str] | None = None) -> list[dict]:
    """``policy`` paired with every other non-oracle policy (or those of ``against``), per hour."""
    policies = list(dict.fromkeys(e["policy"] for e in doc["episodes"]))
    if policy not in policies:
        raise ConfigError(f"policy {policy!r} is not in the results; they hold {', '.join(policies)}")
    others = [p for p in policies if p != policy and p not in ORACLES] if against is None else list(against)
    out = []
    for other in others:
        for h in sorted({e["hour"] for e in doc["episodes"]}):
            row = compare_pair(doc, policy, other, h)
            if row is not None:
                out.append(row)
    return out


def oracle_exceptions(doc: dict) -> tuple[int, list[dict]]:
    """Instances, and the episodes of the other policies that cost less than the reference oracle there."""
    instances = {instance_key(e) for e in doc["episodes"]}
    below = [e for e in doc["episodes"] if e["policy"] not in ORACLES and e["total_cost"] < e["oracle_cost"]]
    return len(instances), below


def format_comparison(rows: Iterable[dict]) -> str:
    rows = list(rows)
    if not rows:
        return ""
    policy = rows[0]["policy"]
    cells = [[str(r["hour"]), r["against"], f"{r['wins']} / {r['n']}", f"{r['cost_difference']:+.1f}",
              f"[{r['ci95'][0]:+.1f}, {r['ci95'][1]:+.1f}]",
              f"{-100 * r['overhead_reduction']:+.1f}%" if r["overhead_reduction"] is not None else "—",
              f"{100 * r['served_change']:+.1f}%"] for r in rows]
    columns = [("hour", "right"), ("against", "left"), ("wins", "right"), ("cost diff", "right"), ("95% CI", "right"),
               ("overhead Δ", "right"), ("served Δ", "right")]
    lines = [f"{policy} paired with each policy on the same instances (wins: lower total cost; CI: paired bootstrap)",
             text_table(columns, cells)]
    per_hour = {r["hour"]: r for r in rows}.values()
    n = sum(r["n"] for r in per_hour)
    below = sum(r["below_oracle"] for r in per_hour)
    below_a = sum(r["below_oracle_auction"] for r in per_hour)
    if rows[0]["reference_oracle"] == "oracle":
        lines.append(f"{policy} cost less than oracle in {below} and less than oracle-auction in {below_a} of {n} instances "
                     "(both are heuristics with full information, not proven optima)")
    else:  # a results file from before the route planner: its only oracle is the auction
        lines.append(f"{policy} cost less than oracle-auction (the only oracle of this file) in {below_a} of {n} instances")
    return "\n".join(lines)


def format_table(summary: Iterable[dict]) -> str:
    """Mean ± standard deviation of each metric per hour and policy; the gap closed between greedy and the oracles."""
    summary = list(summary)
    columns = [("hour", "right"), ("policy", "left"), ("total cost", "right"), ("outstanding end", "right"), ("served", "right"),
               ("wait overhead/served", "right"), ("plan ms/step", "right"), ("gap closed", "right"), ("(auction)", "right")]
    spread = {}
    for metric, digits in zip(METRICS[:4], (1, 1, 1, 2)):
        sds = [f"{r[metric][1]:.{digits}f}" for r in summary]
        width = max(map(len, sds), default=0)
        spread[metric] = [f"{r[metric][0]:.{digits}f} ± {sd:>{width}}" for r, sd in zip(summary, sds)]  # the ± signs line up
    rows = [[str(r["hour"]), r["policy"], *(spread[m][k] for m in METRICS[:4]), f"{r[METRICS[4]][0] * 1e3:.2f}",
             *(f"{100 * r[g]:.1f}%" if r.get(g) is not None else "—" for g in ("gap_closed", "gap_closed_auction"))]
            for k, r in enumerate(summary)]
    return text_table(columns, rows)


def plot(summary: list[dict], path: str | Path, title: str = "", metric: str = "total_cost", ylabel: str = "total cost (request-minutes waited)") -> None:
    """Grouped bars of a metric's mean (± std) per hour and policy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hours = sorted({r["hour"] for r in summary})
    policies = list(dict.fromkeys(r["policy"] for r in summary))
    by = {(r["hour"], r["policy"]): r[metric] for r in summary}
    width = 0.8 / len(policies)
    fig, ax = plt.subplots(figsize=(max(6.0, 1.6 * len(hours) + 0.4 * len(policies)), 4.0), dpi=110)
    for k, pol in enumerate(policies):
        xs = [i + (k - (len(policies) - 1) / 2) * width for i, h in enumerate(hours) if (h, pol) in by]
        vals = [by[h, pol] for h in hours if (h, pol) in by]
        ax.bar(xs, [v[0] for v in vals], width, yerr=[v[1] for v in vals], capsize=2, label=pol)
    ax.set_xticks(range(len(hours)))
    ax.set_xticklabels([f"{h}h" for h in hours])
    ax.set_ylabel(ylabel)
    ax.grid(axis="y", alpha=0.3)
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi * 1.22)  # headroom, so the legend never covers the tallest bars
    ax.legend(fontsize=8, ncol=min(len(policies), 3), loc="upper left")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)

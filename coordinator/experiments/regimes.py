"""``surge`` against the strongest practical baseline per regime (map × hour × fleet size × start), and its forecasts.

A regime is one hour of one results file: its map, its fleet size and its
start rule (cold: random positions; warm: each policy from its own previous
hour).  Per regime the table gives ``surge`` − the strongest practical
baseline (:func:`coordinator.experiments.practice.against_practice`: the one
of least mean cost under the same forecast), with its paired 95 % CI and
wins, the share of the greedy→oracle gap each closes, and, for every other
``surge`` label that differs in its forecast only, that label − ``surge``
(e.g. true rates − previous-hour demand) on the same instances.  Only seeds
finished at every hour of a file count (:func:`complete_seeds`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from agents.base import split_policy
from coordinator.experiments.analysis import compare_pair, complete_seeds, summarize
from coordinator.experiments.practice import against_practice, forecast_of
from coordinator.experiments.results_page import Section, fmt, renderer, table


def forecast_labels(doc: dict, policy: str) -> dict[str, str]:
    """The labels of ``doc`` that run ``policy``'s policy with another forecast and otherwise its options, by forecast."""
    name, own = split_policy(policy)
    base = {k: v for k, v in own.items() if k not in ("forecast", "model")}
    out = {}
    for label in dict.fromkeys(e["policy"] for e in doc["episodes"]):
        n, o = split_policy(label)
        if label != policy and n == name and {k: v for k, v in o.items() if k not in ("forecast", "model")} == base:
            f = forecast_of(doc, label)
            if f is not None and f != forecast_of(doc, policy):
                out.setdefault(f, label)
    return out


def regime_rows(docs: list[dict], policy: str = "surge") -> list[dict]:
    """One row per regime of the results documents ``docs`` (see the module's docstring)."""
    rows = []
    for raw in docs:
        doc = complete_seeds(raw)
        if not doc["episodes"]:
            continue
        gap = {(r["hour"], r["policy"]): r["gap_closed"] for r in summarize(doc)}
        others = forecast_labels(doc, policy)
        mine = forecast_of(doc, policy)
        for r in against_practice(doc, policy):
            h = r["hour"]
            means = {mine: float(np.mean([e["total_cost"] for e in doc["episodes"] if e["hour"] == h and e["policy"] == policy]))}
            diffs = []
            for f, label in others.items():
                c = compare_pair(doc, label, policy, h)
                if c is not None:
                    means[f] = float(np.mean([e["total_cost"] for e in doc["episodes"] if e["hour"] == h and e["policy"] == label]))
                    diffs.append({"forecast": f, "against": mine, "label": label, "cost_difference": c["cost_difference"],
                                  "ci95": c["ci95"], "wins": c["wins"], "n": c["n"]})
            rows.append({
                "scenario": doc["scenario"], "hour": h, "taxis": doc["config"]["taxis"], "warm_start": bool(doc.get("warm_start", False)),
                "seeds": sorted({e["seed"] for e in doc["episodes"] if e["hour"] == h}), "policy": policy,
                "strongest": r["strongest"], "strongest_mean_cost": r["candidates"][r["strongest"]],
                "policy_mean_cost": means[mine], "cost_difference": r["cost_difference"], "ci95": r["ci95"],
                "wins": r["wins"], "n": r["n"], "beats": r["beats"],
                "gap_closed": {"policy": gap.get((h, policy)), "strongest": gap.get((h, r["strongest"]))},
                "forecast": mine, "forecast_mean_cost": means, "forecast_differences": diffs,
            })
    return sorted(rows, key=lambda r: (r["scenario"], r["warm_start"], r["hour"], r["taxis"]))


def _ci(r: dict) -> str:
    return f"{r['cost_difference']:+.1f} [{r['ci95'][0]:+.1f}, {r['ci95'][1]:+.1f}] {r['wins']}/{r['n']}"


def _gap(r: dict) -> str:
    """The gap closed by the policy / by the strongest baseline, in percent."""
    return " / ".join("—" if r["gap_closed"][p] is None else f"{100 * r['gap_closed'][p]:.0f}%" for p in ("policy", "strongest"))


def format_regimes(rows: list[dict]) -> str:
    """The terminal table: one line per regime."""
    forecasts = list(dict.fromkeys(d["forecast"] for r in rows for d in r["forecast_differences"]))
    head = (f"{'map':<10} {'start':<5} {'hour':>4} {'taxis':>5} {'n':>3}  {'strongest':<10} {'surge − strongest, 95% CI, wins':<34} beats  {'gap closed':<13}  "
            + "  ".join(f"{f + ' − ' + (rows[0]['forecast'] if rows else ''):<34}" for f in forecasts))
    lines = [head, "-" * len(head)]
    for r in rows:
        by = {d["forecast"]: d for d in r["forecast_differences"]}
        lines.append(f"{r['scenario']:<10} {'warm' if r['warm_start'] else 'cold':<5} {r['hour']:>4} {r['taxis']:>5} {r['n']:>3}  "
                     f"{r['strongest']:<10} {_ci(r):<34} {'yes' if r['beats'] else 'no':<5}  {_gap(r):<13}  "
                     + "  ".join(f"{_ci(by[f]) if f in by else '—':<34}" for f in forecasts))
    return "\n".join(lines)


def plot_regimes(rows: list[dict], path: str | Path, title: str = "") -> None:
    """Per map (columns): ``surge`` − strongest baseline against fleet size (top), and each forecast − the policy's (bottom), 95 % CIs.

    Without another forecast in ``rows`` the figure is the top row alone.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    maps = list(dict.fromkeys(r["scenario"] for r in rows))
    n_rows = 2 if any(r["forecast_differences"] for r in rows) else 1
    fig, axes = plt.subplots(n_rows, len(maps), figsize=(5.2 * len(maps), 3.5 * n_rows), dpi=110, squeeze=False, sharex=True)
    for j, m in enumerate(maps):
        mine = [r for r in rows if r["scenario"] == m]
        for k, h in enumerate(sorted({r["hour"] for r in mine})):
            at = sorted((r for r in mine if r["hour"] == h), key=lambda r: r["taxis"])
            _errorbars(axes[0, j], at, f"{h} h", k)
            for i, f in enumerate(dict.fromkeys(d["forecast"] for r in at for d in r["forecast_differences"])):
                pts = [{"taxis": r["taxis"], **d} for r in at for d in r["forecast_differences"] if d["forecast"] == f]
                _errorbars(axes[1, j], pts, f"{f} − {at[0]['forecast']}, {h} h", 2 * k + i, marker="os^v"[i % 4])
        axes[0, j].set_title(m)
        axes[0, j].set_ylabel("surge − strongest practical baseline\n(total cost, mean and 95 % CI)")
        if n_rows > 1:
            axes[1, j].set_ylabel("surge with another forecast − surge\n(total cost, mean and 95 % CI)")
        axes[-1, j].set_xlabel("taxis")
        for ax in axes[:, j]:
            ax.axhline(0, color="black", linewidth=0.8)
            ax.grid(alpha=0.3)
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=7)
            sizes = sorted({r["taxis"] for r in mine})
            ax.set_xticks(sizes)
            ax.set_xlim(sizes[0] - 25, sizes[-1] + 25)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _errorbars(ax, pts: list[dict], label: str, k: int, marker: str = "o") -> None:
    if not pts:
        return
    x = np.array([p["taxis"] for p in pts], dtype=float) + 2.5 * (k - 1)  # side by side, not on top of each other
    y = np.array([p["cost_difference"] for p in pts])
    err = np.abs(np.array([p["ci95"] for p in pts]).T - y)
    ax.errorbar(x, y, yerr=err, marker=marker, capsize=3, label=label)


@renderer("regimes")
def render_regimes(sec: Section) -> list[str]:
    """The results page's table of ``surge report --regimes`` JSON files: one row per regime, a column per other forecast.

    ``name``, when given, is what the table calls the paired policy (default: `` `surge` ``).
    """
    rows = [r for f in sec.need("files") if f.endswith(".json") for r in sec.load(f)["regimes"]]
    forecasts = list(dict.fromkeys(d["forecast"] for r in rows for d in r["forecast_differences"]))
    base = rows[0]["forecast"] if rows else ""
    out = []
    for r in rows:
        by = {d["forecast"]: d for d in r["forecast_differences"]}
        gap = " / ".join(fmt(None if r["gap_closed"][k] is None else 100 * r["gap_closed"][k], "{:.0f} %") for k in ("policy", "strongest"))
        out.append([r["scenario"], "warm" if r["warm_start"] else "cold", f"{r['hour']} h", str(r["taxis"]), str(r["n"]),
                    f"`{r['strongest']}`", fmt(r["cost_difference"], "{:+.1f}") + " " + fmt(r["ci95"], "{:+.1f}"),
                    f"{r['wins']} / {r['n']}", fmt(r["beats"]), gap,
                    *(fmt(by[f]["cost_difference"], "{:+.1f}") + " " + fmt(by[f]["ci95"], "{:+.1f}") + f", {by[f]['wins']} / {by[f]['n']}"
                      if f in by else "—" for f in forecasts)])
    name = sec.get("name", "`surge`")
    head = ["map", "start", "hour", "taxis", "instances", "strongest baseline", f"{name} − it, 95 % CI", f"{name} wins", "beats it",
            f"gap closed: {name} / it", *(f"{name} {f} − {base}, 95 % CI, wins" for f in forecasts)]
    return table(head, out)

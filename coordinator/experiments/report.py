"""``OUT/REPORT.md`` of ``surge reproduce``: the paper's tables beside ours, paired comparisons, verdicts, figures.

Every number and verdict is computed here from the results files; nothing is
written by hand.  The paper's published numbers (Garces & Gil, AAMAS 2024)
are quoted from its Tables 1–4 for comparison; the data differ, so the
ratios to greedy and to the oracle are the comparable figures.
"""

from __future__ import annotations

import datetime as dt
import json
import math
from pathlib import Path

import numpy as np

from coordinator.experiments.analysis import (
    compare_pair,
    complete_seeds,
    oracle_exceptions,
    paired,
    summarize,
)
from coordinator.experiments.practice import report_section
from coordinator.experiments.results import instance_key

HOURS = (15, 17, 19, 21)
#: Table 1 of the paper, average total cost (mean, std) per hour.
PAPER_TOTAL_COST = {
    "greedy": {15: (6671.2, 269.0), 17: (11795.7, 202.6), 19: (17199.8, 187.7), 21: (12102.4, 143.1)},
    "ia": {15: (6670.6, 193.9), 17: (11848.0, 165.1), 19: (17432.2, 187.0), 21: (12460.4, 107.4)},
    "garces2023": {15: (6563.9, 243.5), 17: (11667.9, 174.5), 19: (18070.6, 210.6), 21: (13147.4, 217.5)},
    "surge": {15: (6121.5, 217.5), 17: (11291.7, 169.2), 19: (16868.2, 141.2), 21: (12020.6, 154.6)},
    "oracle": {15: (5732.1, 165.4), 17: (11082.0, 134.7), 19: (16573.4, 103.8), 21: (11552.6, 80.7)},
}
#: Table 2 of the paper, outstanding requests at the end of the hour.
PAPER_OUTSTANDING = {
    "greedy": {15: (241.92, 7.87), 17: (434.00, 4.07), 19: (626.23, 5.15), 21: (471.14, 5.71)},
    "ia": {15: (240.92, 3.75), 17: (433.33, 3.52), 19: (630.15, 5.49), 21: (474.93, 3.63)},
    "garces2023": {15: (238.42, 4.66), 17: (426.83, 4.76), 19: (632.38, 4.89), 21: (479.79, 3.53)},
    "surge": {15: (230.17, 4.30), 17: (422.58, 4.25), 19: (611.46, 3.71), 21: (467.14, 5.04)},
    "oracle": {15: (230.25, 3.25), 17: (426.75, 3.24), 19: (620.92, 2.81), 21: (465.36, 2.78)},
}
#: Table 3 of the paper, planning seconds per step.
PAPER_PLAN_SECONDS = {"garces2023": (153.42, 7.65), "surge": (56.47, 5.40)}
#: Table 4 of the paper, our approach's total cost with each base policy (as printed; its scale differs from Table 1).
PAPER_BASE = {"ia": {15: (103.73, 3.32), 17: (189.25, 3.23), 19: (279.37, 2.47), 21: (202.84, 2.36)},
              "greedy": {15: (102.57, 3.34), 17: (189.03, 2.12), 19: (280.88, 2.79), 21: (201.79, 2.06)}}
NAMES = {"greedy": "Greedy", "ia": "Inst. Assign.", "garces2023": "Garces et al.", "surge": "Our approach (surge)",
         "match": "Optimal matching", "rebalance": "Matching + rebalancing",
         "oracle": "Oracle (route planner)", "oracle-auction": "Oracle (paper's auction)"}
FEASIBLE = ("greedy", "ia", "garces2023")


def _ms(v: tuple[float, float] | None, digits: int = 1) -> str:
    return "—" if v is None else f"{v[0]:.{digits}f} ± {v[1]:.{digits}f}"


def _pct(x: float | None) -> str:
    return "—" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{100 * x:+.1f} %"


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + ["| " + " | ".join(r) + " |" for r in rows]


def _by(summary: list[dict]) -> dict:
    return {(r["hour"], r["policy"]): r for r in summary}


def _oracle_rows(doc: dict) -> list[dict]:
    """Each oracle's episodes as rows, from the oracle costs every episode carries."""
    seen, rows = set(), []
    for e in doc["episodes"]:
        k = instance_key(e)
        if k in seen:
            continue
        seen.add(k)
        for name, field in (("oracle", "oracle_cost"), ("oracle-auction", "oracle_auction_cost")):
            rows.append({**e, "policy": name, "total_cost": e[field], "outstanding_end": float("nan"), "served": float("nan"),
                         "wait_overhead_per_served": 0.0 if name == "oracle" else float("nan"), "plan_seconds_per_step": float("nan")})
    return rows


def cost_tables(doc: dict, metric: str, paper: dict, digits: int) -> list[str]:
    """Ours beside the paper's, with ratios to greedy and to the oracle (ours: route planner; paper: its auction)."""
    full = {**doc, "episodes": doc["episodes"] + (_oracle_rows(doc) if metric == "total_cost" else [])}
    by = _by(summarize(full))
    policies = ["greedy", "ia", "garces2023", "match", "rebalance", "surge"] + (["oracle", "oracle-auction"] if metric == "total_cost" else [])
    hours = sorted({e["hour"] for e in doc["episodes"]})
    head = ["hour", "policy", "ours", "paper", "ours / greedy", "paper / greedy"] + (["ours / oracle", "ours / oracle-auction", "paper / oracle"] if metric == "total_cost" else [])
    rows = []
    for h in hours:
        g = by.get((h, "greedy"))
        for p in policies:
            r = by.get((h, p))
            if r is None:
                continue
            ours = r[metric]
            pp = None if p == "oracle" and metric == "total_cost" else paper.get("oracle" if p == "oracle-auction" else p, {}).get(h)
            pg = paper.get("greedy", {}).get(h)
            row = [f"{h}h", NAMES[p], _ms(ours, digits), _ms(pp, digits),
                   f"{ours[0] / g[metric][0]:.3f}" if g else "—", f"{pp[0] / pg[0]:.3f}" if pp and pg else "—"]
            if metric == "total_cost":
                o, a, po = by[(h, "oracle")][metric][0], by[(h, "oracle-auction")][metric][0], paper["oracle"].get(h)
                row += [f"{ours[0] / o:.3f}", f"{ours[0] / a:.3f}", f"{pp[0] / po[0]:.3f}" if pp and po else "—"]
            rows.append(row)
    return _table(head, rows)


def paired_rows(doc: dict, pairs: list[tuple[str, str]]) -> list[str]:
    rows = []
    for a, b in pairs:
        for h in sorted({e["hour"] for e in doc["episodes"]}):
            r = compare_pair(doc, a, b, h)
            if r is None:
                continue
            rows.append([f"{h}h", f"`{a}` − `{b}`", f"{r['wins']} / {r['n']}", f"{r['cost_difference']:+.1f}",
                         f"[{r['ci95'][0]:+.1f}, {r['ci95'][1]:+.1f}]", _pct(r["relative_difference"]),
                         _pct(-r["overhead_reduction"] if r["overhead_reduction"] is not None else None), _pct(r["served_change"])])
    return _table(["hour", "pair (a − b)", "a wins", "mean cost diff", "95 % CI (paired bootstrap)", "relative", "wait overhead/served", "served"], rows)


#: Instances an hour needs before a paired effect there is judged clear: a bootstrap over fewer resamples a handful of values.
MIN_CLEAR = 5


def _effect(doc: dict, a: str, b: str) -> tuple[str, list[bool]]:
    """``a`` − ``b`` at each hour as text, and per hour whether ``a`` is better with its 95 % CI below zero
    over at least :data:`MIN_CLEAR` instances."""
    parts, better = [], []
    for h in sorted({e["hour"] for e in doc["episodes"]}):
        r = compare_pair(doc, a, b, h)
        if r is None:
            continue
        few = f" (fewer than {MIN_CLEAR}: not judged)" if r["n"] < MIN_CLEAR else ""
        parts.append(f"{h} h {_pct(r['relative_difference'])} [{r['ci95'][0]:+.0f}, {r['ci95'][1]:+.0f}], {r['wins']}/{r['n']} wins{few}")
        better.append(r["n"] >= MIN_CLEAR and r["ci95"][1] < 0)
    return "; ".join(parts) or "no instance yet", better


def ia_explanation(abl: dict, limited_label: str, counts_label: str) -> list[str]:
    """Why rollout over ``ia`` gains little, read from the ablation: each of ``garces2023``'s differences from
    ``surge:base=ia`` (information, the two parts of certainty equivalence, sampling scope) as a paired effect,
    and which of them is clear (CI below zero at every ablation hour)."""
    steps = [("the forecast (model against previous hour)", "garces2023:forecast=model", "garces2023"),
             ("places drawn from the distributions (against standard certainty equivalence's fixed pools)", counts_label,
              "garces2023:forecast=model"),
             ("random counts (against standard certainty equivalence's deterministic means)", limited_label, counts_label),
             ("local sampling (against the whole map)", "surge:base=ia", limited_label)]
    lines = ["Finding, computed from the rows above: `garces2023` and `surge:base=ia` share the base `ia` and differ in "
             "four things. Each row changes one of them (relative change of total cost, 95 % CI of the mean cost difference, wins):", ""]
    clear = []
    for what, a, b in steps:
        text, better = _effect(abl, a, b)
        lines.append(f"- {what}: `{a}` − `{b}`: {text}.")
        if better and all(better):
            clear.append(what)
    text, gain = _effect(abl, "surge:base=ia", "ia")
    lines += [f"- rollout planning as `surge` does, against its base: `surge:base=ia` − `ia`: {text}.", ""]
    named = f"clear at every ablation hour: {', '.join(clear)}" if clear else "none of the four differences is clear at every hour"
    if not gain:
        lines.append("No instance has these rows yet.")
    elif all(gain):
        lines.append(f"Rollout over `ia` gains clearly when it plans as `surge` does, so the base policy is not what holds "
                     f"`garces2023` back; {named}.")
    else:
        lines.append(f"Rollout over `ia` does not gain clearly at every hour even when it plans as `surge` does; {named}.")
    return lines


def verdicts(doc: dict, docs: dict) -> list[tuple[str, bool, str]]:
    """The paper's three claims, each held or not held by the numbers of ``doc`` (the main run; planning time: :func:`planning_ratio` of ``docs``)."""
    hours = sorted({e["hour"] for e in doc["episodes"]})
    reds, served = [], []
    for h in hours:
        for other in FEASIBLE:
            r = compare_pair(doc, "surge", other, h)
            if r is None:
                continue
            reds.append((h, other, r["overhead_reduction"]))
            served.append((h, other, r["served_change"]))
    out = []
    vals = [x for _, _, x in reds if x is not None]
    lo = min(vals) if vals else float("nan")
    out.append(("25–75 % less wait overhead per served request than every other feasible policy, at every hour",
                bool(vals) and lo >= 0.25,
                f"smallest reduction {100 * lo:.1f} % (" + ", ".join(f"{h}h vs {o}: {100 * x:.0f} %" for h, o, x in reds if x is not None) + ")"))
    vals = [x for _, _, x in served]
    lo = min(vals) if vals else float("nan")
    out.append(("1–4 % more requests served than every other feasible policy, at every hour", bool(vals) and lo >= 0.01,
                f"smallest change {100 * lo:+.2f} % (" + ", ".join(f"{h}h vs {o}: {100 * x:+.1f} %" for h, o, x in served) + ")"))
    ratio, why = planning_ratio(docs)
    out.append(("about a third of garces2023's planning time per step (held: ratio ≤ 0.5)", ratio <= 0.5,
                f"{why}: ratio {ratio:.2f} (paper: {56.47 / 153.42:.2f})"))
    return out


#: The pairs whose planning seconds the verdict may compare, in order of preference: (step, `surge` row, `garces2023` row).
PLAN_PAIRS = (("main", "surge", "garces2023"),
              ("ablation", "surge:forecast=true-rate", "garces2023:forecast=true-rate"),
              ("ablation", "surge:forecast=previous-hour", "garces2023"),
              ("ablation", "surge", "garces2023:forecast=model"))


def planning_ratio(docs: dict) -> tuple[float, str]:
    """``surge``'s planning seconds per step over ``garces2023``'s, and where they come from.

    A ratio of timings taken on different machines measures the machines, and
    a resumed run may take its rows on several.  So the ratio is taken over
    the instances whose two rows were timed on the same recorded machine, in
    the pair of :data:`PLAN_PAIRS` with the most of them.  Wall seconds count
    the time a shared or paused run waited for the processor and CPU seconds
    do not, so where some of those instances have CPU seconds in both rows
    (older rows have none) the ratio is theirs, and says how many they are.
    Without instances of one machine (older files record no machine) it is
    the ratio of all the main run's rows, and says that it may compare machines.
    """
    best: tuple[int, str, str, str, list] = (0, "", "", "", [])
    for step, a, b in PLAN_PAIRS:
        doc = docs.get(step, {"episodes": []})
        pairs = [pair for h in sorted({e["hour"] for e in doc["episodes"]}) for pair in paired(doc, a, b, h)]
        same = [(x, y) for x, y in pairs if x.get("machine") and x.get("machine") == y.get("machine")]
        if len(same) > best[0]:
            best = (len(same), step, a, b, same)
    n, step, a, b, same = best
    if n:
        cpu = [pair for pair in same if all("plan_cpu_seconds_per_step" in e for e in pair)]
        key, kind, used = ("plan_cpu_seconds_per_step", "CPU s", cpu) if cpu else ("plan_seconds_per_step", "s", same)
        ta, tb = (float(np.mean([pair[i][key] for pair in used])) for i in (0, 1))
        machines = ", ".join(sorted({pair[0]["machine"] for pair in used}))
        which = f"the {n} instances" if len(used) == n else f"the {len(used)} of {n} instances with CPU seconds"
        return ta / tb, (f"`{a}` {ta:.3f} {kind}, `{b}` {tb:.3f} {kind} per step, over {which} of the {step} step "
                         f"whose two rows were timed on one machine ({machines})")
    main = docs["main"]["episodes"]
    ta, tb = (float(np.mean([e["plan_seconds_per_step"] for e in main if e["policy"] == p])) for p in ("surge", "garces2023"))
    return ta / tb if tb > 0 else float("nan"), (f"surge {ta:.3f} s, garces2023 {tb:.3f} s per step over the main run; no instance "
                                                 "had both rows timed on one recorded machine, so this may compare machines")


def _provenance(scen) -> list[str]:
    city, world = scen.city, scen.world
    kind = type(world).__name__
    lines = [f"- Street graph: `{city.name}`, {city.n_nodes} intersections, {city.n_edges} streets, {city.n_sectors} sectors"
             + (" (real map from the data directory)" if city.name != "synthetic" else " (synthetic, embedded in the package)") + "."]
    if kind == "SyntheticWorld":
        notes = list(getattr(world, "notes", None) or [])
        real_base = world.base_source.startswith(("zone profile", "real hourly totals"))
        level = " at the **real** level of every hour (see docs/real-demand.md)" if world.base_source.startswith("real hourly totals") else ""
        lines += [f"- Events, their texts and attendance, and every request: **synthetic** (the package's demand world, world seed "
                  f"{world.seed}); nothing in it is computed from the routing outcomes.",
                  f"- Base demand: {'**real** trip counts' + level if real_base else '**synthetic**, shaped by the real hourly profile'}: "
                  f"{world.base_source}.",
                  "- Weather: " + ("**synthetic**" if any(n.startswith("weather:") for n in notes) else f"**real** ({world.weather.source})") + ".",
                  "- Points of interest: " + ("**synthetic**" if any(n.startswith("points of interest:") for n in notes)
                                              else f"**real** ({len(world.pois.kind)} from the data directory)") + "."]
    else:
        lines.append(f"- Demand world: `{kind}`; see its notes below for which inputs are real.")
    for note in getattr(world, "notes", None) or []:
        lines.append(f"  - {note}")
    return lines


def _model_lines(run) -> list[str]:
    """Which predictor ``surge`` planned with: its directory, widths and where each network stopped."""
    meta = json.loads((run.model / "model.json").read_text())
    how = "reused (`--model`)" if run.model_dir is not None else "trained by this run"
    lines = [f"The model: `{run.model}`, {how}. Early stopping on the validation months; epoch cap "
             f"{meta['training']['epochs']} (event-sector networks {meta['training'].get('event_epochs') or meta['training']['epochs']}); "
             f"{meta['features']['q_max']} reviews read per event (the paper's Q_max: 100).", "",
             "| network | hidden widths | epochs run | best epoch | stopped early |", "|---|---|---|---|---|"]
    for name, net in meta["networks"].items():
        widths = "×".join(str(w) for w in net["hidden"])
        lines.append(f"| {name} | {widths} | {net['epochs_run']} | {net['best_epoch']} | {'yes' if net['stopped_early'] else 'no (cap)'} |")
    return lines


def write_report(run, scen, docs: dict, pe: dict | None, figs: dict[str, str], status: list[str] | None = None) -> Path:
    """Figures and ``REPORT.md`` in ``run.out``; returns the report's path.

    ``status`` (one line per step: instances done of those planned) marks an
    interim report, written from the results of a run still under way.
    """
    from coordinator.experiments.protocol import CE_LABELS, pruning_pairs

    out = run.out
    main = complete_seeds(docs["main"])
    lines = [f"# surge reproduce: {run.scenario}", "",
             f"Written {dt.datetime.now(dt.timezone.utc):%Y-%m-%d %H:%M} UTC by `"
             + (run.command or f"surge reproduce --scenario {run.scenario}" + (f" --data {run.data}" if run.data else "") + f" --out {out}")
             + "`; protocol: "
             + ", ".join(f"{k}={v}" for k, v in vars(run.protocol).items()) + ".",
             "Every number below is computed from the results files beside this report (`surge.results/1`).", ""]
    if status:
        lines += ["## Status: interim", "", "Written with `--report-only` while the protocol is under way. Each table uses the "
                  "instances finished so far (seeds finished at every hour of their date); `surge reproduce` with the same "
                  "`--out` resumes the rest and writes the final report.", ""] + [f"- {line}" for line in status] + [""]
    info = ("`surge` with the trained model" if run.forecast == "model"
            else "**no predictor in this protocol: `surge` planned with the true rates, an upper bound, not the paper's comparison**")
    lines += ["## Verdicts on the paper's claims", "",
              f"Computed from the main run (the paper's date; {info}, `garces2023` with previous-hour demand).", ""]
    for claim, held, why in verdicts(main, docs):
        lines.append(f"- **{'held' if held else 'not held'}**: {claim}. {why}.")
    lines += [""] + report_section(main)
    lines += ["## Table 1: total cost (paper Table 1)", "",
              "Ours: mean ± std over the seeds of the paper's date. Oracle: `oracle` is our route planner with chaining; "
              "`oracle-auction` is the paper's auction, the one its Table 1 reports. Neither is a proven optimum.", ""]
    lines += cost_tables(main, "total_cost", PAPER_TOTAL_COST, 1)
    lines += ["", "## Table 2: outstanding requests at the end (paper Table 2)", ""]
    lines += cost_tables(main, "outstanding_end", PAPER_OUTSTANDING, 2)
    lines += ["", "## Wait overhead per served request (paper Fig. 4)", "",
              "(policy's total cost − oracle's) / requests the policy served, in minutes, against the route-planning oracle.", "",
              f"![wait overhead]({figs['overhead']})", "", f"![total cost]({figs['cost']})", ""]
    by = _by(summarize(main))
    shown, closers = ("greedy", "ia", "garces2023", "match", "rebalance", "surge"), ("surge", "rebalance", "garces2023")
    lines += _table(["hour"] + [NAMES[p] for p in shown] + ["gap closed by surge (oracle)", "(oracle-auction)"]
                    + [f"gap closed by {p} (oracle)" for p in closers[1:]],
                    [[f"{h}h"] + [_ms(by[(h, p)]["wait_overhead_per_served"], 2) if (h, p) in by else "—" for p in shown]
                     + [_pct(by.get((h, "surge"), {}).get("gap_closed")), _pct(by.get((h, "surge"), {}).get("gap_closed_auction"))]
                     + [_pct(by.get((h, p), {}).get("gap_closed")) for p in closers[1:]]
                     for h in sorted({e["hour"] for e in main["episodes"]})])
    lines += ["", "## Table 3: planning seconds per step (paper Table 3)", ""]
    rows = []
    for doc_name, doc in (("main", main), ("ablation", docs["ablation"])):
        for p in dict.fromkeys(e["policy"] for e in doc["episodes"]):
            if not p.startswith(("surge", "garces2023")) or (doc_name == "ablation" and p in ("surge", "garces2023")):
                continue  # the ablation's own surge and garces2023 rows are the main run's, lent
            eps = [e for e in doc["episodes"] if e["policy"] == p]
            v = np.array([e["plan_seconds_per_step"] for e in eps])
            c = np.array([e["plan_cpu_seconds_per_step"] for e in eps if "plan_cpu_seconds_per_step" in e])
            paper = PAPER_PLAN_SECONDS.get(p)
            machines = ", ".join(sorted({e.get("machine") or "not recorded" for e in eps}))
            cpu = f"{c.mean():.3f} ± {c.std():.3f} ({len(c)} of {len(eps)})" if len(c) else "not recorded"
            rows.append([f"`{p}`", doc_name, f"{v.mean():.3f} ± {v.std():.3f}", cpu, _ms(paper, 2), machines])
    lines += ["Both rollout policies plan exactly here, as in the paper: every `surge` row turns off the approximations "
              "`surge` plans with by default (`adaptive=none,cap=none`; their speed and cost are measured in docs/results.md). "
              "Timings of different machines are not comparable; the verdict compares rows timed on one machine (see above). "
              "Wall seconds include any time the run waited for the processor; CPU seconds (not recorded in older rows) do not, "
              "so the verdict uses the pairs whose two rows have them.", ""]
    lines += _table(["policy", "run", "ours (s/step)", "ours (CPU s/step)", "paper (s/step)", "machines"], rows)
    lines += ["", "## Paired comparisons (instance by instance; 95 % CI by paired bootstrap, 10,000 resamples)", "",
              f"### Headline: `surge` ({'trained model' if run.forecast == 'model' else 'true rates: no predictor in this protocol'}) "
              "against `garces2023` (previous hour), the paper's comparison", ""]
    lines += paired_rows(main, [("surge", "garces2023"), ("surge", "ia"), ("surge", "greedy"), ("garces2023", "ia"),
                                ("surge", "rebalance"), ("surge", "match"), ("rebalance", "match")])
    if "dates" in docs:
        d = complete_seeds(docs["dates"])
        lines += ["", f"### Further dates: {', '.join(d['config']['dates'])} (weekdays of the test months with evening events)", ""]
        lines += paired_rows(d, [("surge", "garces2023"), ("surge", "ia"), ("garces2023", "ia"), ("surge", "rebalance"), ("surge", "match")])
        lines += [""] + report_section(d, heading="#### Against the state of practice on these dates")
    abl = complete_seeds(docs["ablation"])
    lines += ["", "## Ablations (paper Table 4 and more)", "",
              "### Same information for both rollout policies (true-rate is an upper bound, never the headline)", ""]
    lines += paired_rows(abl, [("surge:forecast=previous-hour", "garces2023"), ("surge", "garces2023:forecast=model"),
                               ("surge:forecast=true-rate", "garces2023:forecast=true-rate")])
    lines += ["", "### Base policy (paper Table 4), whole-map sampling, pruning off", ""]
    lines += paired_rows(abl, [("surge:base=ia", "surge"), ("surge:scope=map", "surge"), *pruning_pairs(run.protocol)])
    lines += ["", "### What rollout gains over its own base policy, by the information it plans with", "",
              "Rollout over `ia` (`garces2023`: whole-map sampling; `surge:base=ia`: local sampling) and over `greedy` "
              "(`surge`), each against its base policy on the same instances. Where rollout over `ia` gains with the model "
              "or the true rates but not with previous-hour demand, the information limits it, not the base.", ""]
    lines += paired_rows(abl, [("garces2023", "ia"), ("garces2023:forecast=model", "ia"), ("garces2023:forecast=true-rate", "ia"),
                               ("surge:base=ia", "ia"), ("surge", "greedy"), ("surge:forecast=true-rate", "greedy")])
    limited, counts = CE_LABELS
    lines += ["", f"`{counts}` changes one part of `garces2023`'s certainty equivalence (places drawn from the distributions, "
              f"not fixed pools) and `{limited}` both (random counts as well), so these pairs split its gap to `surge:base=ia`:", ""]
    lines += paired_rows(abl, [(counts, "garces2023:forecast=model"), (limited, counts), ("surge:base=ia", limited)])
    lines += [""] + ia_explanation(abl, *CE_LABELS)
    ab = _by(summarize(abl))
    lines += ["", "Table 4 beside the paper's (total cost of our approach with each base policy; the paper's printed scale differs from its Table 1, so compare the ratio):", ""]
    lines += _table(["hour", "ours: base ia", "ours: base greedy", "ours ia / greedy", "paper: base ia", "paper: base greedy", "paper ia / greedy"],
                    [[f"{h}h", _ms(ab[(h, "surge:base=ia")]["total_cost"]), _ms(ab[(h, "surge")]["total_cost"]),
                      f"{ab[(h, 'surge:base=ia')]['total_cost'][0] / ab[(h, 'surge')]['total_cost'][0]:.3f}",
                      _ms(PAPER_BASE["ia"][h], 2), _ms(PAPER_BASE["greedy"][h], 2), f"{PAPER_BASE['ia'][h][0] / PAPER_BASE['greedy'][h][0]:.3f}"]
                     for h in sorted({e["hour"] for e in abl["episodes"]}) if (h, "surge:base=ia") in ab and (h, "surge") in ab])
    lines += ["", "## The oracle's bound", ""]
    for name, doc in [("main", main)] + [(k, complete_seeds(v)) for k, v in docs.items() if k != "main"]:
        n, below = oracle_exceptions(doc)
        bad = {instance_key(e) for e in below}
        lines.append(f"- {name}: `oracle` had the lowest total cost of all policies in {n - len(bad)} of {n} instances"
                     + (f" ({100 * (n - len(bad)) / n:.1f} %)" if n else "") + ".")
        for e in below:
            lines.append(f"  - exception: {e['date']} {e['hour']}h seed {e['seed']}: `{e['policy']}` {e['total_cost']} < oracle {e['oracle_cost']}")
    lines += ["", "## Demand prediction: percent error per hour (paper Fig. 5)", ""]
    if not pe:
        lines.append("Not run in this protocol (no predictor).")
    else:
        lines += _model_lines(run) + ["", "![predictor PE](fig-predictor-pe.png)", ""]
        lines += _table(["hour", "event NN (ours)", "standard NN", "previous hour", "n"],
                        [[f"{r['hour']}h", f"{100 * r['pe_event_nn']:.1f} %", f"{100 * r['pe_standard_nn']:.1f} %",
                          f"{100 * r['pe_previous_hour']:.1f} %", str(r["n"])] for r in pe["rows"]])
    lines += ["", "## The 7 pm surge", "", f"![surge map]({figs['map']})", "", f"![surge vs greedy]({figs['gif']})", "",
              "## Data provenance", ""] + _provenance(scen)
    lines += ["", "## Wall time (this machine; a resumed step costs little the second time)", "",
              "| step | this invocation | every invocation on this directory |", "|---|---|---|"]
    lines += [f"| {k} | {run.timings.get(k, 0.0):.0f} s | {v:.0f} s |" for k, v in run.summed().items()]
    planned, counted = {}, set()
    for name, doc in docs.items():
        planned[name] = 0.0
        for e in doc["episodes"]:
            key = (*instance_key(e), e["policy"])
            if key not in counted:  # rows lent by an earlier step (the ablation borrows main's) ran once
                counted.add(key)
                planned[name] += e["plan_seconds_per_step"] * run.protocol.minutes
    lines += ["", "Planning seconds summed over the episodes of the results, each counted once, whichever invocation and machine ran them "
              "(the table counts only the invocations that recorded their time): "
              + ", ".join(f"{name} {v:,.0f} s" for name, v in planned.items()) + f"; {sum(planned.values()) / 3600:.1f} hours in all."]
    path = out / "REPORT.md"
    path.write_text("\n".join(lines) + "\n")
    return path



"""``docs/results.md``, generated from the committed result files (``surge report --results-page``).

The page holds current figures only, each with its command, the date it ran,
the machine kind and links to its result files, so it cannot drift from the
data: a test regenerates it and fails if the committed page differs.

Every folder ``benchmarks/<question>/`` may contribute sections by holding a
``page.toml`` with one or more ``[[section]]`` tables::

    [[section]]
    title = "Planning time per step"        # the section's heading
    kind = "fields"                         # a registered renderer (below)
    files = ["nyc-100.json"]                # result files in this folder
    command = "surge bench plan ..."        # how they were made  } each may be left out where every
    date = "2026-12-06"                     # when it ran         } JSON result file carries it as a
    machine = "2-vCPU x86_64"               # the machine kind    } top-level field of its own
    order = 20                              # place on the page (default 100), then the folder's name
    text = "One paragraph that says what the table answers."
    module = "some.module"                  # optional: imported first, to register its own kind

Kinds: ``fields`` (a table of values read from the files by dotted paths; no
code needed), ``paired-results`` (paired comparisons of ``surge.results/1``
files), ``paired-runs`` (two sets of runs compared minute by minute), ``gap-closed``
(the share of the greedy→oracle gap each policy closes; both it and
``paired-results`` split a file by date with ``by_date = true``, and ``name``
or ``names`` call a policy something other than its label) and
``cluster-rounds`` (timed rounds of one sweep two ways). A new kind is a
function ``(Section) -> list[str]`` of Markdown lines registered with
:func:`renderer`, in any module a ``page.toml`` names.
"""

from __future__ import annotations

import importlib
import json
import re
import statistics
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from city.errors import ConfigError

RENDERERS: dict[str, Callable[[Section], list[str]]] = {}
REQUIRED = ("title", "kind", "files")
HEADER = ["# Results", "",
          "Current figures only, generated from the committed result files by `surge report --results-page`;",
          "do not edit this page by hand. Each section names its command, the date it ran, the machine kind",
          "and its result files. Timings compare only within a section (one machine); costs, decisions and",
          "percent errors do not depend on the machine.", "",
          "`surge` is the default rollout (over `rebalance`, 20 minutes, 200 samples, `cap=12`, `adaptive=1`,",
          "`keep=2`). A results file records the `surge` defaults it ran with and reads with them: where they",
          "were those of the *greedy rollout* (the paper's configuration: greedy base, 10 minutes, local",
          "sampling, 1,000 samples, `cap=24`, `adaptive=2`), a `surge` label names what it changes from the",
          "greedy rollout; where they had no `keep`, a label without it planned as `keep=none`.", ""]


def renderer(kind: str) -> Callable[[Callable[[Section], list[str]]], Callable[[Section], list[str]]]:
    """Register a section renderer under ``kind`` (the ``kind`` key of a ``page.toml`` section)."""
    def register(fn: Callable[[Section], list[str]]) -> Callable[[Section], list[str]]:
        RENDERERS[kind] = fn
        return fn
    return register


@dataclass(frozen=True)
class Section:
    """One ``[[section]]`` of a folder's ``page.toml``."""

    folder: Path
    spec: dict
    where: str  # "benchmarks/<question>/page.toml, section N", for errors

    def get(self, key: str, default: Any = None) -> Any:
        return self.spec.get(key, default)

    def need(self, key: str) -> Any:
        if key not in self.spec:
            raise ConfigError(f"{self.where}: key {key!r} is missing")
        return self.spec[key]

    def path(self, name: str) -> Path:
        p = self.folder / name
        if not p.is_file():
            raise ConfigError(f"{self.where}: result file {name!r} does not exist in {self.folder}")
        return p

    def load(self, name: str) -> Any:
        try:
            return json.loads(self.path(name).read_text())
        except json.JSONDecodeError as e:
            raise ConfigError(f"{self.where}: {name}: not JSON ({e})") from None


def sections(root: Path) -> list[Section]:
    """Every section of every ``<root>/*/page.toml``, in page order."""
    out = []
    for toml in sorted(root.glob("*/page.toml")):
        rel = f"{root.name}/{toml.parent.name}/page.toml"
        try:
            doc = tomllib.loads(toml.read_text())
        except tomllib.TOMLDecodeError as e:
            raise ConfigError(f"{rel}: {e}") from None
        specs = doc.get("section")
        if not isinstance(specs, list) or not specs:
            raise ConfigError(f"{rel}: expected one or more [[section]] tables")
        for i, spec in enumerate(specs, 1):
            sec = Section(toml.parent, spec, f"{rel}, section {i}")
            for key in REQUIRED:
                sec.need(key)
            if spec.get("module"):
                importlib.import_module(spec["module"])
            if spec["kind"] not in RENDERERS:
                raise ConfigError(f"{sec.where}: unknown kind {spec['kind']!r}; known: {', '.join(sorted(RENDERERS))}")
            out.append(sec)
    return sorted(out, key=lambda s: (int(s.get("order", 100)), s.folder.name))


def _provenance(sec: Section, rel: str) -> list[str]:
    """The section's command, date, machine kind and result files.

    A section's own ``command``, ``date`` and ``machine`` come first; where it
    leaves one out, every JSON result file must carry that field itself.
    """
    docs = [sec.load(f) for f in sec.need("files") if f.endswith(".json")]
    values = {}
    for key in ("command", "date", "machine"):
        if sec.get(key):
            values[key] = str(sec.get(key)).strip()
            continue
        own = sorted({str(d.get(key)) for d in docs if isinstance(d, dict) and d.get(key)})
        if not docs or len(own) == 0 or not all(isinstance(d, dict) and d.get(key) for d in docs):
            raise ConfigError(f"{sec.where}: key {key!r} is missing, and not every result file carries it")
        values[key] = "\n".join(own) if key == "command" else ", ".join(own)
    links = ", ".join(f"[`{f}`]({rel}/{sec.folder.name}/{f})" for f in sec.need("files"))
    return ["", f"Ran {values['date']} on a {values['machine']}. Result files: {links}.", "",
            "```sh", values["command"], "```", ""]


def render(root: Path, rel: str = "../benchmarks") -> str:
    """The whole page as Markdown; ``rel`` is the benchmarks folder as seen from the page."""
    lines = list(HEADER)
    for sec in sections(root):
        lines += [f"## {sec.need('title')}", ""]
        if sec.get("text"):
            lines += [" ".join(sec.get("text").split()), ""]
        lines += RENDERERS[sec.need("kind")](sec)
        lines += _provenance(sec, rel)
        lines += [f"See [`benchmarks/{sec.folder.name}/`]({rel}/{sec.folder.name}/README.md).", ""]
    return "\n".join(lines).rstrip() + "\n"


def write(root: Path, out: Path) -> bool:
    """Write the page to ``out``; whether it changed."""
    text = render(root, rel=_relative(root, out.parent))
    changed = not out.exists() or out.read_text() != text
    if changed:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
    return changed


def _relative(target: Path, start: Path) -> str:
    import os

    return Path(os.path.relpath(target.resolve(), start.resolve())).as_posix()


# ------------------------------------------------------------------ formatting
def table(head: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table."""
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + ["| " + " | ".join(r) + " |" for r in rows]


def fmt(value: Any, spec: str = "{}") -> str:
    """``value`` by a ``str.format`` spec; a pair of numbers as an interval, None as a dash, minus as a real minus."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (list, tuple)) and len(value) == 2 and all(isinstance(v, (int, float)) for v in value):
        return "[" + ", ".join(fmt(v, spec) for v in value) + "]"
    return spec.format(value).replace("-", "−") if isinstance(value, (int, float)) else spec.format(value)


def lookup(doc: Any, path: str, where: str) -> Any:
    """The value at a dotted ``path`` (list indices as numbers); a missing key is an error naming it."""
    cur = doc
    for part in path.split("."):
        if isinstance(cur, list) and re.fullmatch(r"-?\d+", part):
            cur = cur[int(part)]
        elif isinstance(cur, dict) and part in cur:
            cur = cur[part]
        else:
            raise ConfigError(f"{where}: path {path!r}: no {part!r}")
    return cur


AGGREGATES: dict[str, Callable[[list], float]] = {
    "median": statistics.median, "mean": statistics.fmean, "min": min, "max": max, "len": len}


def _column(sec: Section, col: dict, row: Any, label: str, file: str) -> str:
    path = col.get("path")
    if path == "$label":
        return label
    if path == "$file":
        return f"`{file}`"
    where = f"{sec.where}, file {file}"
    value = lookup(row, path, where)
    if col.get("agg"):
        value = AGGREGATES[col["agg"]](value)
    if col.get("divide"):
        other = lookup(row, col["divide"], where)
        value = value / (AGGREGATES[col["agg"]](other) if col.get("agg") else other)
    if col.get("scale") is not None and value is not None:
        value = value * col["scale"] if not isinstance(value, list) else [v * col["scale"] for v in value]
    return fmt(value, col.get("fmt", "{}"))


@renderer("fields")
def render_fields(sec: Section) -> list[str]:
    """A table: one row per file (or per element of each file's ``rows`` list or mapping, filtered by ``where``).

    ``limit`` keeps the first rows only. ``columns`` is a list of ``{head, path, fmt, agg, divide, scale}``: ``path`` is dotted
    (``$label`` for the file's entry in ``labels``, ``$file`` for its name, ``$key`` for a mapping
    row's key); ``agg`` one of
    median, mean, min, max, len over a list; ``divide`` a second path the value is divided by.
    """
    cols = sec.need("columns")
    labels = sec.get("labels", sec.need("files"))
    rows = []
    for file, label in zip(sec.need("files"), labels):
        doc = sec.load(file)
        items = lookup(doc, sec.get("rows"), sec.where) if sec.get("rows") else (doc if isinstance(doc, list) else [doc])
        if isinstance(items, dict):
            items = [{**value, "$key": key} for key, value in items.items()]
        for item in items:
            if any(item.get(k) != v for k, v in sec.get("where", {}).items()):
                continue
            rows.append([_column(sec, c, item, label, file) for c in cols])
    if sec.get("limit"):
        rows = rows[: int(sec.get("limit"))]
    return table([c["head"] for c in cols], rows)


@renderer("paired-results")
def render_paired_results(sec: Section) -> list[str]:
    """``policy`` against ``against`` per hour in ``surge.results/1`` files, instance by instance, with 95 % CIs.

    ``name``, when given, is what the table calls ``policy`` (a label whose meaning
    the file pins, such as a bare ``surge`` written under other defaults).
    """
    from coordinator.experiments.analysis import compare_pair, complete_seeds
    from coordinator.experiments.results import read_results

    policy, against = sec.need("policy"), sec.need("against")
    labels = sec.get("labels", sec.need("files"))
    rows = []
    for file, label in zip(sec.need("files"), labels):
        for name, doc in _by_date(complete_seeds(read_results(sec.path(file))), label, sec.get("by_date", False)):
            for hour in sorted({e["hour"] for e in doc["episodes"]}):
                r = compare_pair(doc, policy, against, hour)
                if r is None:
                    continue
                overhead = None if r["overhead_reduction"] is None else -r["overhead_reduction"]
                rows.append([name, f"{hour} h", f"{r['wins']} / {r['n']}", fmt(r["cost_difference"], "{:+.1f}"),
                             fmt(r["ci95"], "{:+.1f}"), fmt(100 * r["relative_difference"], "{:+.1f} %"),
                             fmt(100 * overhead if overhead is not None else None, "{:+.1f} %"),
                             fmt(100 * r["served_change"], "{:+.1f} %")])
    head = ["", "hour", sec.get("name", "`" + policy + "`") + " wins", "mean difference", "95 % CI", "relative",
            "wait overhead per served", "served"]
    return table(head, rows)


def _by_date(doc: dict, label: str, by_date: bool) -> list[tuple[str, dict]]:
    """The document whole under ``label``, or (``by_date``) one part a date, labelled ``label, date``."""
    if not by_date:
        return [(label, doc)]
    dates = sorted({e["date"] for e in doc["episodes"]})
    return [(f"{label}, {d}", {**doc, "episodes": [e for e in doc["episodes"] if e["date"] == d]}) for d in dates]


@renderer("gap-closed")
def render_gap_closed(sec: Section) -> list[str]:
    """The share of the greedy→oracle gap in mean total cost that each of ``policies`` closes, per file and hour.

    Each row holds the instances on which every one of ``policies`` that the
    file has ran, so that its shares compare like with like.  ``names``, when
    given, head the policies' columns instead of their labels.
    """
    from coordinator.experiments.analysis import common_instances, complete_seeds, summarize
    from coordinator.experiments.results import read_results

    policies = sec.need("policies")
    labels = sec.get("labels", sec.need("files"))
    rows = []
    for file, label in zip(sec.need("files"), labels):
        common = common_instances(read_results(sec.path(file)), policies)
        for name, part in _by_date(complete_seeds(common), label, sec.get("by_date", False)):
            gap = {(r["hour"], r["policy"]): r["gap_closed"] for r in summarize(part)}
            eps = part["episodes"]
            seeds = {h: len({(e["date"], e["seed"]) for e in eps if e["hour"] == h}) for h in {e["hour"] for e in eps}}
            for hour in sorted(seeds):
                cells = [gap.get((hour, p)) for p in policies]
                rows.append([name, f"{hour} h", str(seeds[hour])] + [fmt(None if g is None else 100 * g, "{:.1f} %") for g in cells])
    names = sec.get("names", [f"`{p}`" for p in policies])
    return table(["", "hour", "instances"] + list(names), rows)


def _bootstrap(diffs: list[float]) -> tuple[float, float]:
    from coordinator.experiments.analysis import bootstrap_ci

    return bootstrap_ci(np.asarray(diffs, dtype=float))


@renderer("paired-runs")
def render_paired_runs(sec: Section) -> list[str]:
    """Pairs of runs of one instance, ``a`` against ``b``: each pair's median, and the paired difference per step, pooled.

    ``pairs`` lists ``[a_file, b_file]``; ``metric`` is the dotted path of a per-step list;
    ``names`` names the two sides.
    """
    a_name, b_name = sec.get("names", ["a", "b"])
    metric = sec.need("metric")
    rows, diffs = [], []
    labels = sec.get("labels", [f"pair {i}" for i in range(1, len(sec.need("pairs")) + 1)])
    for (fa, fb), label in zip(sec.need("pairs"), labels):
        a = lookup(sec.load(fa), metric, f"{sec.where}, file {fa}")
        b = lookup(sec.load(fb), metric, f"{sec.where}, file {fb}")
        if len(a) != len(b):
            raise ConfigError(f"{sec.where}: {fa} and {fb} hold {len(a)} and {len(b)} steps")
        diffs += [x - y for x, y in zip(a, b)]
        ma, mb = statistics.median(a), statistics.median(b)
        rows.append([label, fmt(ma, "{:.3f}"), fmt(mb, "{:.3f}"), fmt(ma / mb, "{:.2f}")])
    lo, hi = _bootstrap(diffs)
    rows.append([f"all pairs, paired per step (n = {len(diffs)})", "", "",
                 f"{fmt(statistics.fmean(diffs), '{:+.4f}')} s {fmt((lo, hi), '{:+.4f}')}"])
    return table(["", f"{a_name}, median s", f"{b_name}, median s", f"{a_name} ÷ {b_name} (last row: {a_name} − {b_name}, 95 % CI)"], rows)


def _episode(e: dict) -> tuple:
    return (e["date"], e["hour"], e["seed"], e["policy"])


@renderer("cluster-rounds")
def render_cluster_rounds(sec: Section) -> list[str]:
    """Rounds of one sweep two ways: ``times`` lines ``round N WAY SECONDS``; ``pairs`` of results files that must agree."""
    times: dict[int, dict[str, float]] = {}
    for line in sec.path(sec.need("times")).read_text().splitlines():
        if line.strip():
            _, n, way, secs = line.split()
            times.setdefault(int(n), {})[way] = float(secs)
    ways = sec.need("ways")
    heads = sec.get("way_names", ways)
    rows = [[str(n), *(fmt(t[w], "{:.1f} s") for w in ways), fmt(t[ways[1]] / t[ways[0]], "{:.2f}")]
            for n, t in sorted(times.items())]
    means = [statistics.fmean(t[w] for t in times.values()) for w in ways]
    rows.append(["mean", *(fmt(m, "{:.1f} s") for m in means), fmt(means[1] / means[0], "{:.2f}")])
    same = 0
    pairs = sec.need("pairs")
    for fa, fb in pairs:
        ea = {_episode(e): e["decisions_sha256"] for e in sec.load(fa)["episodes"]}
        eb = {_episode(e): e["decisions_sha256"] for e in sec.load(fb)["episodes"]}
        same += ea == eb
    return table(["round", *heads, f"{heads[1]} ÷ {heads[0]}"], rows) + [
        "", f"Same decisions in every episode: {same} of {len(pairs)} rounds."]


@renderer("relative-change")
def render_relative_change(sec: Section) -> list[str]:
    """``policy`` against ``against`` over the instances of each group of ``surge.results/1`` files, pooled over hours.

    Per instance the relative change (policy − against) ÷ against in total cost; the row gives the
    mean with its 95 % paired bootstrap CI, how often ``policy`` was cheaper, and the median ratio
    of planning CPU seconds per step, against ÷ policy. ``groups`` is a list of ``{label, files}``.
    """
    from coordinator.experiments.results import instance_key, read_results

    policy, against = sec.need("policy"), sec.need("against")
    rows = []
    for group in sec.need("groups"):
        rel, cpu = [], []
        for file in group["files"]:
            by = {(instance_key(e), e["policy"]): e for e in read_results(sec.path(file))["episodes"]}
            for (key, label), e in sorted(by.items()):
                other = by.get((key, against))
                if label != policy or other is None:
                    continue
                rel.append((e["total_cost"] - other["total_cost"]) / other["total_cost"])
                if e.get("plan_cpu_seconds_per_step") and other.get("plan_cpu_seconds_per_step"):
                    cpu.append(other["plan_cpu_seconds_per_step"] / e["plan_cpu_seconds_per_step"])
        if not rel:
            raise ConfigError(f"{sec.where}: group {group['label']!r}: no instance holds both {policy!r} and {against!r}")
        lo, hi = _bootstrap(rel)
        rows.append([group["label"], str(len(rel)), str(sum(r < 0 for r in rel)),
                     fmt(100 * statistics.fmean(rel), "{:+.2f} %"), fmt((100 * lo, 100 * hi), "{:+.2f}"),
                     fmt(statistics.median(cpu), "{:.1f}×") if cpu else "—"])
    names = sec.get("names", [policy, against])
    return table(["instances", "n", f"{names[0]} cheaper", f"mean change in total cost, {names[0]} vs {names[1]}",
                  "95 % CI (%)", f"planning CPU, {names[1]} ÷ {names[0]} (median)"], rows)

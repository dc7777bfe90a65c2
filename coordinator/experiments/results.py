"""The ``surge.results/1`` file: its fields, reading older files as they were run, atomic writes, and finished episodes.

A results file is the evaluation's checkpoint and its record: every row
carries the instance, the policy label, its metrics and the SHA-256 of its
decisions, so a rerun can be checked decision for decision.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from city.errors import DataError

if TYPE_CHECKING:
    pass


RESULTS_SCHEMA = "surge.results/1"


ORACLES = ("oracle", "oracle-auction")


METRICS = ("total_cost", "outstanding_end", "served", "wait_overhead_per_served", "plan_seconds_per_step")


#: The demand source of a results file written before the field existed.
UNRECORDED_SOURCE = "not recorded (written before real hourly totals)"


def demand_source(world: object) -> str:
    """What a world's demand is made of (e.g. the real hourly totals and zone profile, and the share), as results files record it."""
    return str(getattr(world, "demand_source", type(world).__name__))


def recorded_source(doc: dict) -> str:
    """The demand source a results document records (:data:`UNRECORDED_SOURCE` for one written before the field)."""
    return str(doc.get("demand_source", UNRECORDED_SOURCE))


def same_demand(recorded: str, current: str) -> bool:
    """Whether rows recorded under ``recorded`` are rows of a world of ``current`` demand source.

    A file without the field was written before real hourly totals could be
    used: only a world without them accepts its rows.
    """
    return recorded == current or (recorded == UNRECORDED_SOURCE and not current.startswith("hourly-totals"))


def episode_dir(checkpoint: str | Path) -> Path:
    """Where the finished episodes of a results file's unfinished instances wait, one small file each, beside it."""
    checkpoint = Path(checkpoint)
    return checkpoint.with_name(f"{checkpoint.stem}.episodes")


def instance_prefix(date_text: str, hour: int, seed: int) -> str:
    """The start of every kept-episode file name of one instance."""
    return f"{date_text}-{hour}-{seed}-"


def episode_file(date_text: str, hour: int, seed: int, label: str) -> str:
    return f"{instance_prefix(date_text, hour, seed)}{hashlib.sha256(label.encode()).hexdigest()[:12]}.json"


EPISODE_FIELDS = ("hour", "seed", "policy", "oracle_cost", *METRICS)


def missing_field(ep: object, fields: tuple[str, ...] = EPISODE_FIELDS) -> str | None:
    """The first of ``fields`` that episode row ``ep`` lacks, if any."""
    return next((f for f in fields if not isinstance(ep, dict) or f not in ep), None)


#: The type each episode field must have, and how an error names it (None is allowed for the oracle's cost).
EPISODE_TYPES: dict[str, tuple[tuple[type, ...], str]] = {
    "date": ((str,), "a YYYY-MM-DD string"), "hour": ((int,), "an integer"), "seed": ((int,), "an integer"), "policy": ((str,), "a string"),
    "oracle_cost": ((int, float, type(None)), "a number"),
    **{m: ((int, float), "a number") for m in METRICS},
}


def mistyped_field(ep: dict) -> str | None:
    """The first field of episode row ``ep`` whose value has the wrong type (booleans are not numbers)."""
    return next((f for f, (types, _) in EPISODE_TYPES.items() if f in ep and (isinstance(ep[f], bool) or not isinstance(ep[f], types))), None)


def surge_defaults() -> dict:
    """The planner options a ``surge`` label plans with when it does not set them (those :data:`agents.rollout_policy.PAPER` fixes); results files record them."""
    from agents.rollout_policy import PAPER, Surge

    return {k: Surge.defaults[k] for k in PAPER}


def pin_surge_defaults(config: dict, recorded: dict | None) -> dict:
    """``config`` (a results file's) with the ``surge`` defaults it ``recorded`` pinned in its labels' options, where they differ from today's.

    ``recorded`` is the file's ``surge_defaults``; ``None`` (a file written
    before the field) means exact planning, :data:`agents.rollout_policy.EXACT`.
    An option it does not record has the value of
    :data:`agents.rollout_policy.GREEDY_ROLLOUT`: a file that records only
    the approximations planned the greedy rollout.
    """
    from agents.rollout_policy import EXACT, GREEDY_ROLLOUT, pinned_options

    recorded = {**GREEDY_ROLLOUT, **(EXACT if recorded is None else recorded)}
    if recorded == surge_defaults():
        return config
    options = dict(config.get("policy_options", {}))
    for label in config.get("policies", []):
        pinned = pinned_options(label, recorded)
        if pinned:
            options[label] = {**pinned, **options.get(label, {})}
    return {**config, "policy_options": options}


def by_instance(episodes: Iterable[dict]) -> dict[tuple[str, int, int], dict[str, dict]]:
    """Rows grouped by instance, then by policy label."""
    out: dict[tuple[str, int, int], dict[str, dict]] = {}
    for e in episodes:
        out.setdefault(instance_key(e), {})[e["policy"]] = e
    return out


def instance_key(e: dict) -> tuple[str, int, int]:
    """The instance an episode row belongs to: its date, hour and seed."""
    return (e["date"], e["hour"], e["seed"])


def read_results(path: str | Path) -> dict:
    """A ``surge.results/1`` document, checked down to every episode's fields, in the current layout.

    Older documents are brought up to date: one ``date`` becomes ``dates``,
    episodes get their date, and a document without ``reference_oracle``
    (written when ``oracle`` was the auction) has its ``oracle`` rows renamed
    ``oracle-auction`` and ``reference_oracle: "oracle-auction"``; the
    ``surge`` defaults a document planned with are pinned in its labels'
    options where they are not today's (:func:`pin_surge_defaults`).
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise DataError(f"not JSON ({exc})", path=path) from exc
    if not isinstance(doc, dict) or doc.get("schema") != RESULTS_SCHEMA:
        found = doc.get("schema") if isinstance(doc, dict) else type(doc).__name__
        raise DataError(f"schema {found!r}, expected {RESULTS_SCHEMA!r}", path=path)
    for key in ("config", "city", "episodes"):
        if key not in doc:
            raise DataError(f"no {key!r} field", path=path)
    if not isinstance(doc["episodes"], list) or not isinstance(doc["config"], dict):
        raise DataError("'episodes' must be a list and 'config' an object", path=path)
    for k, ep in enumerate(doc["episodes"]):
        missing = missing_field(ep)
        if missing:
            raise DataError(f"episode {k} has no {missing!r} field", path=path)
        wrong = mistyped_field(ep)
        if wrong:
            raise DataError(f"episode {k}: field {wrong!r} is {ep[wrong]!r}, not {EPISODE_TYPES[wrong][1]}", path=path)
    try:
        return upgrade(doc)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise DataError(f"not a readable results document ({type(exc).__name__}: {exc})", path=path) from exc


def upgrade(doc: dict) -> dict:
    """``doc`` in the current layout (see :func:`read_results`); a current document is returned as it is."""
    cfg = dict(doc["config"])
    if "dates" not in cfg:
        cfg["dates"] = [cfg.pop("date", "2022-11-17")]
    episodes = [{"date": cfg["dates"][0], **e} for e in doc["episodes"]]
    out = {**doc, "config": cfg, "episodes": episodes}
    if "reference_oracle" not in doc:
        rename = {"oracle": "oracle-auction"}
        cfg["policies"] = [rename.get(p, p) for p in cfg.get("policies", [])]
        out["episodes"] = [{**e, "policy": rename.get(e["policy"], e["policy"]), "oracle_auction_cost": e["oracle_cost"]} for e in episodes]
        out["reference_oracle"] = "oracle-auction"
    out["config"] = pin_surge_defaults(cfg, doc.get("surge_defaults"))
    out["surge_defaults"] = surge_defaults()
    return out


def write_json(doc: dict, path: str | Path) -> None:
    """Write atomically, so an interrupted run never leaves half a results file."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(doc, indent=1))
    tmp.replace(path)

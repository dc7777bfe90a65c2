"""The paper protocol's settings: its sizes, policies, ablations, and the options every label runs with.

:mod:`coordinator.experiments.reproduce` runs it and
:mod:`coordinator.experiments.report` writes its report; both read it here.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

PAPER_DATE = "2022-11-17"

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Protocol:
    """The sizes of a reproduction run."""

    hours: tuple[int, ...] = (15, 17, 19, 21)
    seeds: int = 25
    other_dates: int = 2
    other_hours: tuple[int, ...] = (17, 19)
    other_seeds: int = 10
    ablation_hours: tuple[int, ...] = (17, 19)
    ablation_seeds: int = 10
    taxis: int = 100
    minutes: int = 60
    samples: int | None = None
    oracle_iters: int | None = None
    epochs: int = 100
    event_epochs: int | None = None
    #: Reviews read per event by the predictor (the paper's Q_max; None: the default, 100).
    max_reviews: int | None = None
    #: Hidden widths of the standard and event-sector networks (None: the paper's 256,256 and 4096,4096).
    hidden: tuple[int, ...] | None = None
    event_hidden: tuple[int, ...] | None = None
    #: Rollout samples of the pruning ablation, pruned and unpruned alike. Unpruned, ``garces2023``
    #: samples the whole map for every decision: about 250 s of planning per episode at 100 samples
    #: on 2 cores, so some 40 minutes at the default 1,000, for each of the 20 ablation instances.
    prune_samples: int = 100
    predictor: bool = True
    jobs: int = 1
    gif_minutes: int = 60


FULL = Protocol()


#: The small predictor reads 5 reviews per event (half the texts to embed) and has the widths of the
#: full run's committed predictor (128,128 and 512,512). The pruning pair runs at 30 samples: unpruned
#: ``garces2023`` at 100 samples alone took about 250 s per episode, the quick run's longest step.
QUICK = Protocol(seeds=5, other_dates=0, ablation_hours=(19,), ablation_seeds=2, samples=100, epochs=5, event_epochs=1, max_reviews=5,
                 hidden=(128, 128), event_hidden=(512, 512), prune_samples=30, gif_minutes=30)


#: Seconds' worth, for the CI smoke test: no predictor (training embeds a year of event texts), so
#: ``surge`` plans with the true rates there and the report says so.
SMOKE = Protocol(hours=(19,), seeds=1, other_dates=0, ablation_hours=(19,), ablation_seeds=1, taxis=8, minutes=6,
                 samples=4, oracle_iters=20, epochs=1, predictor=False, gif_minutes=4)


#: ``match`` and ``rebalance`` are the practical baselines; ``rebalance`` plans with ``surge``'s forecast (:func:`policy_options`).
MAIN_POLICIES = ("greedy", "ia", "garces2023", "match", "rebalance", "surge")


#: ``garces2023`` with the model, its standard certainty equivalence changed in both parts and in one: random counts
#: and places drawn from the distributions (``limited``, ``surge``'s), and only the places (``counts``). Between them,
#: ``garces2023:forecast=model`` and ``surge:base=ia``, the pools, the counts and the sampling scope are told apart.
CE_LABELS = ("garces2023:forecast=model,ce=limited", "garces2023:forecast=model,ce=counts")


ABLATIONS = (
    "surge:forecast=previous-hour",
    "surge:forecast=true-rate",
    "garces2023:forecast=model",
    "garces2023:forecast=true-rate",
    "surge:base=ia",
    "surge:scope=map",
    *CE_LABELS,
)


def pruning_pairs(protocol: Protocol) -> list[tuple[str, str]]:
    """``(unpruned, pruned)`` labels of the pruning ablation for both rollout policies, at the protocol's ``prune_samples`` or fewer."""
    n = protocol.prune_samples
    if protocol.samples is not None and protocol.samples <= n:
        return [(f"{p}:prune=none", p) for p in ("surge", "garces2023")]
    return [(f"{p}:prune=none,samples={n}", f"{p}:samples={n}") for p in ("surge", "garces2023")]


@dataclass
class Run:
    """Where a reproduction writes, and what it has done."""

    out: Path
    scenario: str
    data: str | None
    protocol: Protocol
    model_dir: Path | None = None
    #: The command line as the user gave it, for the report.
    command: str | None = None
    log: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    #: Each step's seconds summed over the earlier invocations on this ``out`` (a resumed step costs little the second time).
    earlier: dict[str, float] = field(default_factory=dict)

    def say(self, msg: str) -> None:
        log.info("reproduce: %s", msg)
        self.log.append(msg)

    def summed(self) -> dict[str, float]:
        """Each step's seconds over every invocation on ``out``, this one included."""
        return {k: self.earlier.get(k, 0.0) + self.timings.get(k, 0.0) for k in dict.fromkeys([*self.earlier, *self.timings])}

    @property
    def model(self) -> Path:
        return self.model_dir or self.out / "model"

    @property
    def forecast(self) -> str:
        """What ``surge`` plans with where a label names no forecast: the trained model, or the true rates without a predictor."""
        return "model" if self.protocol.predictor else "true-rate"


def policy_options(run: Run, labels: list[str]) -> dict[str, dict]:
    """Per-label options: the trained model for every forecast=model (surge's default), the run's sample count, exact planning.

    ``rebalance`` plans with ``surge``'s forecast where its label names none,
    so that ``surge`` meets the practical baseline with the same information.

    Every ``surge`` label plans in the paper's configuration where it does
    not set an option (:data:`agents.rollout_policy.PAPER`: greedy base,
    H = 10, local sampling, planned exactly, as ``garces2023`` is), so that
    the protocol reproduces the paper; ``surge``'s defaults are measured
    apart (docs/results.md).
    """
    from agents.rollout_policy import pinned_options
    from agents.base import parse_policy, policy_class

    out = {}
    for label in labels:
        name, opts = parse_policy(label)
        o: dict = pinned_options(label)
        if name in ("surge", "garces2023", "rebalance"):
            if run.protocol.samples is not None and name != "rebalance":
                o["samples"] = run.protocol.samples
            forecast = opts.get("forecast", run.forecast if name in ("surge", "rebalance") else None)
            if forecast == "model":
                o["model"] = str(run.model)
            if name in ("surge", "rebalance") and "forecast" not in opts and forecast != policy_class(name).defaults["forecast"]:
                o["forecast"] = forecast  # named unless it is the policy's own default (rebalance's is previous-hour)
        if name == "oracle" and run.protocol.oracle_iters is not None:
            o["iters"] = run.protocol.oracle_iters
        if o:
            out[label] = o
    return out

"""The exact savings of the rollout, switchable, and the counters of what they settled (see :mod:`agents.rollout`)."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from city.graph import City


@dataclass(frozen=True)
class Shortcuts:
    """The exact savings of the rollout; none changes a decision, and each can be switched off to show it.

    Attributes
    ----------
    skip : bool
        Greedy base: no simulation when no candidate can reach any possible
        pickup within the horizon (every rollout is then the same; the agent stays).
    shadow : bool
        Greedy base: replay each non-pickup candidate for the agent alone
        against the reference candidate's pickups, and take the cost of the
        candidate it provably equals (no pickup by the agent in either, or
        trajectories merged); only the others are simulated in full.
    reach : bool
        Greedy base: leave out taxis that cannot reach any possible pickup
        within the horizon; they never pick up, so no cost changes.
    minute_lists : bool
        The nearest-request lists once per minute over every outstanding
        request (the pruned ones marked gone), not once per agent.  Off by
        default: building them per agent is cheap, and a per-agent list of the
        tracked requests alone was faster to search on all of Manhattan.
    rows : bool
        Contiguous transposed distance rows for the arrival checks.
    share : bool
        Greedy base: taxis that look for their nearest request from the same
        node in the same step share one search (a herd with one target soon
        moves in lockstep).
    lazy_lists : bool
        A decision's nearest-request lists are made for the nodes its taxis
        search from, when they first do, instead of for every node of the map
        beforehand.  Both kernels; the parallel one's threads each list into
        a copy of their own (:func:`agents._kernels.rollout_costs`).
    """

    skip: bool = True
    shadow: bool = True
    reach: bool = True
    minute_lists: bool = False
    rows: bool = True
    share: bool = True
    lazy_lists: bool = True

    @classmethod
    def none(cls) -> Shortcuts:
        return cls(skip=False, shadow=False, reach=False, minute_lists=False, rows=False, share=False, lazy_lists=False)


#: Nearest requests listed per node in the per-minute lists (a deeper list: pruned requests are in it).
MINUTE_NEAR_K = 16


class PlanStats:
    """Counters of one minute's planning: decisions, those the shortcuts settled, simulations run and avoided."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.decisions = 0
        self.skipped = 0
        self.settled = 0
        self.cand_samples = 0
        self.shadowed = 0

    def add(self, skipped: bool, settled: bool, cand_samples: int, shadowed: int) -> None:
        with self._lock:
            self.decisions += 1
            self.skipped += int(skipped)
            self.settled += int(settled or skipped)
            self.cand_samples += cand_samples
            self.shadowed += shadowed

    def as_dict(self) -> dict:
        return {"decisions": self.decisions, "skipped": self.skipped, "settled": self.settled,
                "candidate_samples": self.cand_samples, "shadow_settled": self.shadowed}


_TRANSPOSED: dict[int, tuple[City, np.ndarray, np.ndarray]] = {}
_TRANSPOSED_LOCK = threading.Lock()


def transposed(city: City) -> tuple[np.ndarray, np.ndarray]:
    """``city.dist`` and ``city.next_hop`` transposed and contiguous, made once per city.

    The rollout reads distances *to* an arrival's pickup from many taxis and
    walks many taxis *towards* one target: with the target's row contiguous
    those reads stay in cache (``Shortcuts.rows``).  Costs one more copy of
    each matrix per process, unless the city was mapped from its file, which
    holds them (``City.load(mmap=True)``).
    """
    if city.dist_t is not None and city.next_hop_t is not None:
        return city.dist_t, city.next_hop_t
    with _TRANSPOSED_LOCK:
        hit = _TRANSPOSED.get(id(city))
        if hit is None or hit[0] is not city:
            hit = (city, np.ascontiguousarray(city.dist.T), np.ascontiguousarray(city.next_hop.T))
            _TRANSPOSED[id(city)] = hit
    return hit[1], hit[2]

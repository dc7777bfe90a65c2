"""The settings of a rollout planner, checked once: what :mod:`agents.rollout` plans with."""

from __future__ import annotations

from dataclasses import dataclass

from agents import _kernels as K
from city.errors import ConfigError

#: Base policies by name and the kernel that simulates each: ``rebalance`` is the ``ia`` simulation with each
#: taxi's rebalancing target of the decision minute (:func:`agents._iasim.simulate_ia`).
BASES = {"greedy": K.GREEDY, "ia": K.IA, "rebalance": K.IA}
SCOPES = ("local", "map")
#: Certainty equivalence by name, and the arrival counts each samples.
CE_MODES = {"limited": K.LIMITED_CE, "standard": K.STANDARD_CE, "counts": K.STANDARD_CE}
#: The certainty equivalences that draw places from fixed per-sector pools (one random stream over every sector).
POOLED_CE = ("standard",)
#: Nearest tracked requests listed per node; searches past them scan all tracked requests.
NEAR_K = 8


@dataclass(frozen=True)
class RolloutConfig:
    """Parameters of a rollout planner.

    Attributes
    ----------
    horizon : int
        H, minutes of base policy after the decision minute.
    samples : int
        Monte-Carlo samples per agent decision.
    base : str
        Base policy: ``greedy``, ``ia`` or ``rebalance``.  ``rebalance`` plays
        the ``rebalance`` policy (default settings) at the decision minute;
        in the minutes it simulates, the taxis follow instantaneous
        assignment, and a free taxi left unmatched heads for the rebalancing
        target it was given at the decision minute (computed once per real
        minute, not per sample).
    scope : str
        Where future requests are sampled: ``local`` (the agent's sector and
        its adjacent sectors) or ``map`` (every sector).
    ce : str
        Certainty equivalence: ``limited`` (surge) or ``standard`` (Garces et
        al.: deterministic counts, places from fixed per-sector pools).
        ``counts`` takes standard's deterministic counts and limited's places
        (drawn from ρ and δ), to tell the two parts apart.
    seed : int
        Seed of every decision's random numbers.
    prune : int or None
        Leave out taxis and requests farther than this many hops (either
        direction) from the deciding agent; ``None`` simulates the whole map.
    cap : int or None
        Approximation, off here (the ``surge`` policy's default is 12): simulate at most this many taxis, the
        agent and its nearest (in hops, either direction), besides the radius.
        With the greedy base only taxis that can reach a possible pickup within
        the horizon are ranked (the others never change a cost), so the exact
        shortcuts stay exact under the cap.
    adaptive : float or None
        Approximation, off here (the ``surge`` policy's default is 1, in batches of 50): run the samples in batches of
        ``batch`` and drop a candidate once its mean paired difference from
        the best candidate (common random numbers) exceeds ``adaptive``
        standard errors; the decision is the best of those left.
    batch : int
        Samples per batch of ``adaptive``.
    tail : int
        Minutes after the horizon valued by a fluid terminal cost (0, the
        default, values none): the requests still waiting at the horizon wait
        ``tail`` more minutes, less what the simulated taxis serve, each from
        the time it can reach the nearest of them, one per ``cycle`` minutes
        (:func:`agents._kernels._with_tail`).  Sees past the horizon what the
        base policy's end state is worth: a taxi left far from demand, or
        busy long after the horizon, serves less.  With a tail the exact
        shortcuts that leave out taxis unable to pick up, or replay the agent
        alone, are off.
    cycle : int
        Minutes per pickup of a taxi in the tail (trip plus approach).
    place : int
        Tenths of a request-minute per hop that each simulated taxi free after the
        horizon costs where it stands, by its expected hops to the next request
        forecast in the sampled sectors (:func:`agents.place_values.place_values`);
        0, the default, values none.  Rewards ending the horizon where the
        forecast puts demand.  An alternative to ``tail``; with either the
        exact shortcuts that leave out taxis unable to pick up, or replay the
        agent alone, are off.
    keep : float or None
        Keep the base policy's control unless the best candidate beats it by
        more than ``keep`` standard errors of their mean paired difference
        (over the samples both ran); ``None``, the default here (the paper's;
        the ``surge`` policy's is 2), takes the best candidate whatever the
        margin.  A rollout's Monte-Carlo minimum is biased low: with a few
        hundred samples a candidate can look better than the base's control
        by chance, and following the base where the samples cannot tell them
        apart keeps the rollout from doing worse than its base through noise
        alone.
    """

    horizon: int = 10
    samples: int = 1000
    base: str = "greedy"
    scope: str = "local"
    ce: str = "limited"
    seed: int = 0
    prune: int | None = None
    cap: int | None = None
    adaptive: float | None = None
    batch: int = 100
    tail: int = 0
    cycle: int = 10
    place: int = 0
    keep: float | None = None

    def __post_init__(self) -> None:
        if self.horizon < 1 or self.samples < 1:
            raise ConfigError(f"rollout: horizon and samples must be at least 1, got {self.horizon} and {self.samples}")
        if self.base not in BASES:
            raise ConfigError(f"rollout: unknown base policy {self.base!r}; choose from {', '.join(BASES)}")
        if self.scope not in SCOPES:
            raise ConfigError(f"rollout: unknown scope {self.scope!r}; choose from {', '.join(SCOPES)}")
        if self.ce not in CE_MODES:
            raise ConfigError(f"rollout: unknown certainty equivalence {self.ce!r}; choose from {', '.join(CE_MODES)}")
        if self.prune is not None and self.prune < 0:
            raise ConfigError(f"rollout: prune radius must be non-negative, got {self.prune}")
        if self.cap is not None and self.cap < 1:
            raise ConfigError(f"rollout: cap must be at least 1 taxi, got {self.cap}")
        if self.adaptive is not None and not self.adaptive > 0:
            raise ConfigError(f"rollout: adaptive must be a positive number of standard errors, got {self.adaptive}")
        if self.tail < 0 or self.cycle < 1:
            raise ConfigError(f"rollout: tail must be non-negative and cycle at least 1 minute, got {self.tail} and {self.cycle}")
        if self.place < 0:
            raise ConfigError(f"rollout: place must be non-negative, got {self.place}")
        if self.place and self.tail:
            raise ConfigError("rollout: tail and place are alternatives; set one of them")
        if self.keep is not None and not self.keep >= 0:
            raise ConfigError(f"rollout: keep must be a non-negative number of standard errors, got {self.keep}")
        if self.batch < 2:
            raise ConfigError(f"rollout: batch must be at least 2 samples, got {self.batch}")

    def approximations(self) -> str:
        """The approximations in words, for tables and logs (``"adaptive=2 in batches of 50, cap=24"``), or ``"exact"``."""
        parts = []
        if self.adaptive is not None:
            parts.append(f"adaptive={self.adaptive:g} in batches of {self.batch}")
        if self.cap is not None:
            parts.append(f"cap={self.cap}")
        return ", ".join(parts) or "exact"


def default_prune(horizon: int) -> int:
    """The default pruning radius: twice the hops a taxi covers in a rollout, ``2 (H + 1)``."""
    return 2 * (horizon + 1)

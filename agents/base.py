"""The policy interface and the registry of policies by name."""

from __future__ import annotations

import datetime as dt
import inspect
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from city.errors import ConfigError
from city.graph import City
from city.sim import PICKUP, Observation, Requests


@dataclass(frozen=True)
class EpisodeContext:
    """What a policy is told when an episode starts.

    ``future`` (every request of the episode, including those not yet entered)
    is filled in only for clairvoyant policies such as the oracle.
    """

    city: City
    date: dt.date
    hour: int
    minutes: int
    seed: int
    world: Any = None
    future: Requests | None = None


class Policy(ABC):
    """A joint routing policy: one control per taxi per minute.

    Controls are node ids (move to an out-neighbour, or stay with the current
    node) or ``city.sim.PICKUP``; a busy taxi's control must be its next hop.
    """

    name: ClassVar[str] = ""
    clairvoyant: ClassVar[bool] = False

    def __init__(self, city: City, **options: Any) -> None:
        if options:
            raise ConfigError(f"policy {self.name!r}: unknown options {sorted(options)}")
        self.city = city

    def reset(self, context: EpisodeContext) -> None:
        """Start a new episode; the default keeps no per-episode state."""

    @abstractmethod
    def act(self, obs: Observation) -> np.ndarray:
        """Return the joint control for minute ``obs.t``."""


POLICIES: dict[str, type[Policy]] = {}


def register(cls: type[Policy]) -> type[Policy]:
    """Class decorator adding a policy to the registry under ``cls.name``."""
    POLICIES[cls.name] = cls
    return cls


#: Where each built-in policy is defined; its module is imported on first use.
_LAZY: dict[str, str] = {
    "greedy": "agents.greedy",
    "ia": "agents.ia",
    "oracle": "agents.oracle",
    "oracle-auction": "agents.oracle",
    "surge": "agents.rollout",
    "garces2023": "agents.rollout",
}


def policy_names() -> list[str]:
    return sorted(set(POLICIES) | set(_LAZY))


def policy_class(name: str) -> type[Policy]:
    """The registered class of ``name``, importing its module on first use; an unknown name is a :class:`ConfigError`."""
    if name not in POLICIES and name in _LAZY:
        import importlib

        importlib.import_module(_LAZY[name])
    if name not in POLICIES:
        raise ConfigError(f"unknown policy {name!r}; choose from {', '.join(policy_names())}")
    return POLICIES[name]


def make_policy(name: str, city: City, **options: Any) -> Policy:
    """Instantiate a registered policy; an unknown name or option is a :class:`ConfigError`."""
    cls = policy_class(name)
    try:
        inspect.signature(cls).bind(city, **options)
    except TypeError as exc:
        raise ConfigError(f"policy {name!r}: {exc}") from exc
    return cls(city, **options)


def busy_next_hops(city: City, obs: Observation) -> np.ndarray:
    """Controls with every busy taxi's forced next hop and every free taxi staying put."""
    return np.where(obs.tau > 0, city.next_hop[obs.pos, np.maximum(obs.dest, 0)], obs.pos).astype(np.int32)


def head_for(city: City, pos: np.ndarray, target: np.ndarray, can_pick: np.ndarray) -> np.ndarray:
    """Controls that move each taxi one hop toward ``target`` and pick up on arrival.

    ``can_pick`` says whether the target request has entered; a taxi already at
    a target that has not entered yet waits there.
    """
    step = city.next_hop[pos, target].astype(np.int32)
    arrived = pos == target
    return np.where(arrived, np.where(can_pick, PICKUP, pos), step).astype(np.int32)


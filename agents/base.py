"""The policy interface and the registry of policies by name."""

from __future__ import annotations

import math
import os
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from city.episode import EpisodeContext
from city.errors import ConfigError
from city.graph import City
from city.sim import PICKUP, Observation


@dataclass(frozen=True)
class Option:
    """One declared option of a policy: its type, its range or choices, and named special values.

    ``kind`` is ``int``, ``float`` or ``str``; ``low``/``high`` bound numbers
    (inclusive; ``low`` exclusive with ``open_low``); ``choices`` lists the accepted strings; ``words`` maps
    accepted words (``auto``, ``none``) to the values they stand for; ``noun``
    says what a free text is (``a directory``).
    """

    name: str
    kind: type
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    choices: tuple[str, ...] | None = None
    words: dict[str, Any] = field(default_factory=dict)
    help: str = ""
    noun: str = "a text"

    def accepts(self) -> str:
        """What this option accepts, in words, for error messages and help."""
        if self.kind is str:
            text = f"one of {', '.join(self.choices)}" if self.choices else self.noun
        else:
            noun = "an integer" if self.kind is int else "a number"
            if self.low is not None and self.high is not None:
                text = f"{noun} from {_num(self.low)} to {_num(self.high)}"
            elif self.low is not None:
                text = f"{noun} {'above' if self.open_low else 'of at least'} {_num(self.low)}"
            elif self.high is not None:
                text = f"{noun} of at most {_num(self.high)}"
            else:
                text = noun
        return text + "".join(f" or {w}" for w in self.words)

    def parse(self, value: Any) -> Any:
        """The option's value from text (``"10"``) or an already typed value; ``ValueError`` if not accepted."""
        if isinstance(value, str) and value.strip().lower() in self.words:
            return self.words[value.strip().lower()]
        if value is None:
            if any(v is None for v in self.words.values()):
                return None
            raise ValueError(value)
        if self.kind is str:
            if isinstance(value, os.PathLike) and not self.choices:
                value = os.fspath(value)
            if not isinstance(value, str) or (self.choices and value not in self.choices):
                raise ValueError(value)
            return value
        if isinstance(value, bool):
            raise ValueError(value)
        if self.kind is int:
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            out = int(value.strip()) if isinstance(value, str) else value
            if not isinstance(out, int):
                raise ValueError(value)
        else:
            out = float(value)
            if not math.isfinite(out):
                raise ValueError(value)
        too_low = self.low is not None and (out <= self.low if self.open_low else out < self.low)
        if too_low or (self.high is not None and out > self.high):
            raise ValueError(value)
        return out


def _num(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else f"{x:,}"


class Policy(ABC):
    """A joint routing policy: one control per taxi per minute.

    Controls are node ids (move to an out-neighbour, or stay with the current
    node) or ``city.sim.PICKUP``; a busy taxi's control must be its next hop.
    ``options`` declares every keyword the constructor takes after ``city``;
    :func:`check_options` enforces it before the policy is built.
    ``central`` marks a policy computed whole by one process (an assignment
    over the fleet): in a distributed run the coordinator computes its joint
    control and sends it with the state, and each taxi's turn answers its own
    entry, so the decisions are the in-process ones.
    """

    name: ClassVar[str] = ""
    clairvoyant: ClassVar[bool] = False
    central: ClassVar[bool] = False
    options: ClassVar[tuple[Option, ...]] = ()

    def __init__(self, city: City) -> None:
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
    "surge": "agents.rollout_policy",
    "garces2023": "agents.rollout_policy",
    "match": "agents.match",
    "rebalance": "agents.rebalance",
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


def check_options(name: str, options: dict[str, Any]) -> dict[str, Any]:
    """``options`` parsed and checked against what policy ``name`` declares.

    Raises
    ------
    ConfigError
        An unknown policy, an option it does not declare, or a value outside
        the option's type and range; one line naming policy, option, value
        and what is accepted.
    """
    cls = policy_class(name)
    declared = {o.name: o for o in cls.options}
    out: dict[str, Any] = {}
    for key, value in options.items():
        if key not in declared:
            known = f"its options are {', '.join(declared)}" if declared else "it takes no options"
            raise ConfigError(f"policy {name!r}: unknown option {key!r}; {known}")
        opt = declared[key]
        try:
            out[key] = opt.parse(value)
        except (TypeError, ValueError):
            raise ConfigError(f"policy {name!r}: option {key}={value!r} is not accepted; {key} takes {opt.accepts()}") from None
    return out


def split_policy(spec: str) -> tuple[str, dict[str, str]]:
    """``"name:key=value,key=value"`` → ``(name, {key: value})``, the values still text and unchecked."""
    name, _, rest = spec.partition(":")
    raw: dict[str, str] = {}
    for item in filter(None, rest.split(",")):
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise ConfigError(f"policy {spec!r}: option {item!r} is not key=value")
        raw[key.strip()] = value.strip()
    return name.strip(), raw


def parse_policy(spec: str) -> tuple[str, dict[str, Any]]:
    """``"name:key=value,key=value"`` → ``(name, options)``, each option parsed and checked (:func:`check_options`)."""
    name, raw = split_policy(spec)
    return name, check_options(name, raw)


def make_policy(name: str, city: City, **options: Any) -> Policy:
    """Instantiate a registered policy; an unknown name or option, or a bad value, is a :class:`ConfigError`."""
    return policy_class(name)(city, **check_options(name, options))


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


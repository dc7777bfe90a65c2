"""Which agents of a minute can plan at the same time: the dependency graph of one-agent-at-a-time rollout.

Agent ``j`` plans with the controls committed by every agent before it, but
with pruning (a radius ``R`` in hops) its rollout looks only at the nodes
within ``R`` of it (:func:`agents.rollout_inputs.relevant_nodes`): it simulates the
taxis whose next position lies there and tracks the requests waiting there.
A free predecessor ``i`` can change ``j``'s costs only through its *footprint*:
the node it stands on, its out-neighbours (where a move takes it), and the
pickup and drop-off nodes of the requests waiting at its node (where a
pickup takes it, or another taxi there when ``i`` took the request first).
When the footprint misses ``j``'s relevant nodes, ``j``'s costs, and so its
decision, are the same whatever ``i`` commits, and ``j`` does not wait for it.

The waves are the levels of this graph: an agent's wave is one more than the
latest wave among the predecessors it depends on.  Agents of one wave can
plan concurrently once the earlier waves are committed, and the result is
the same as strictly sequential turns (``tests/agents/test_planning_speed.py``,
``tests/agents/test_waves.py``).  The number of waves is the critical path of the
minute.  This module is the one place that decides it, for the in-process
policy (threads, ``workers``) and for the distributed coordinator, which
releases each agent's turn as soon as its ``depends`` have committed and
sends it their commitments.  Busy taxis are not planned and constrain nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from city.graph import City
from city.sim import Observation


@dataclass(frozen=True)
class Waves:
    """The dependency structure of one minute's free agents.

    Attributes
    ----------
    agents : ndarray (F,)
        The free agents in turn order.
    wave : ndarray (F,)
        Each agent's wave, from 0.
    depends : list of ndarray
        For each agent, the earlier free agents whose commitments it must see.
    """

    agents: np.ndarray
    wave: np.ndarray
    depends: list[np.ndarray]

    @property
    def critical_path(self) -> int:
        """Number of waves: the longest chain of agents that must plan one after another."""
        return int(self.wave.max()) + 1 if self.wave.size else 0

    def dependents(self) -> dict[int, list[int]]:
        """For each agent, the later agents that depend on it: the graph read forward, to release turns as commits come."""
        out: dict[int, list[int]] = {int(a): [] for a in self.agents}
        for a, deps in zip(self.agents.tolist(), self.depends):
            for d in deps.tolist():
                out[d].append(a)
        return out

    def groups(self) -> list[np.ndarray]:
        """The agents of each wave, in turn order within a wave."""
        return [self.agents[self.wave == w] for w in range(self.critical_path)]


def footprint(city: City, obs: Observation, agent: int) -> np.ndarray:
    """Nodes through which a free ``agent``'s control can reach another agent's rollout."""
    here = int(obs.pos[agent])
    waiting = obs.req_pickup == here
    nodes = np.concatenate([[here], city.neighbors(here), obs.req_dropoff[waiting]])
    return np.unique(nodes.astype(np.int64))


def plan_waves(city: City, obs: Observation, prune: int | None) -> Waves:
    """The waves of the free agents of ``obs`` for a rollout pruned at radius ``prune`` (``None``: one agent per wave).

    Parameters
    ----------
    city : City
    obs : Observation
    prune : int or None
        The rollout's pruning radius in hops (``RolloutConfig.prune``).
    """
    agents = np.flatnonzero(obs.tau == 0)
    F = agents.size
    if prune is None:
        return Waves(agents, np.arange(F), [agents[:j] for j in range(F)])
    here = obs.pos[agents]
    relevant = (city.dist[here] <= prune) | (city.dist[:, here].T <= prune)  # (F, n)
    prints = [footprint(city, obs, int(a)) for a in agents]
    touch = np.zeros((F, F), dtype=bool)
    if F:
        starts = np.concatenate([[0], np.cumsum([p.size for p in prints])[:-1]])
        # touch[j, i]: agent i's footprint meets agent j's relevant nodes.
        touch = np.logical_or.reduceat(relevant[:, np.concatenate(prints)], starts, axis=1)
    wave = np.zeros(F, dtype=np.int64)
    depends = []
    for j in range(F):
        deps = np.flatnonzero(touch[j, :j])
        depends.append(agents[deps])
        if deps.size:
            wave[j] = wave[deps].max() + 1
    return Waves(agents, wave, depends)

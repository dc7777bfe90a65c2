"""PettingZoo environments of the fleet, for reinforcement-learning research (``pip install surge[rl]``).

Both run the episode on :class:`city.sim.FleetSim`, the simulator every
other part of surge uses, on the same instances as ``surge evaluate``:
requests from the scenario's demand world for ``date`` and ``hour``, and the
fleet's initial placement drawn from the ``reset(seed=…)`` seed exactly as
evaluate's seeds draw it.  The module lives in :mod:`coordinator`, beside
:mod:`coordinator.experiments.evaluate`, because like it the environment owns the clock
and the world and drives the simulator from outside; the policies stay in
:mod:`agents`.

:class:`FleetAECEnv` is the paper's one-agent-at-a-time rollout order as
PettingZoo's AEC model: in every minute ``agent_selection`` walks the free
taxis in index order; each sees its predecessors' committed controls; when
the last free taxi has acted, the joint control (busy taxis take their next
hop) is applied and the minute's stage cost is every agent's reward, with a
minus sign.  Minutes in which no taxi is free are played through at once.

:class:`FleetParallelEnv` lets every taxi choose at once, one step a minute.

Actions are slots of a taxi's control set: 0 stays (a busy taxi: its forced
next hop), 1 picks up the oldest request waiting at the taxi's
intersection, ``2 + k`` moves to its ``k``-th out-neighbour in ascending node
order.  The observation's ``action_mask`` marks the slots that exist; a
masked slot is played as 0.  The observation vector (``observation``) is,
all non-negative::

    [0:6]    x, y (0..1 over the map), minutes until free / max hops, free,
             destination x, y (0 while free)
    [6:18]   the NEAR_REQUESTS outstanding requests nearest in hops:
             (hops / max hops, minutes waited / 60, present) each
    [18:18+K]  for each slot, the predecessors this minute whose committed
             control ends at that slot's node (slot 1: picking up here) / fleet size
    [18+K:]  the forecast rate η (requests a minute) of the taxi's sector and
             the sum over its local sectors (itself and adjacent ones)

Example::

    from coordinator.rl_env import FleetAECEnv

    env = FleetAECEnv(taxis=20, minutes=30)
    env.reset(seed=0)
    for agent in env.agent_iter():
        obs, reward, terminated, truncated, info = env.last()
        action = None if terminated or truncated else env.action_space(agent).sample(obs["action_mask"])
        env.step(action)
"""

from __future__ import annotations

import datetime as dt
import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

try:
    import gymnasium
    from pettingzoo import AECEnv, ParallelEnv
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError("coordinator.rl_env needs PettingZoo: pip install 'surge[rl]'") from exc

from agents.forecast_providers import make_provider
from city.episode import episode_requests, initial_positions
from city.sim import PICKUP, FleetSim

STAY, PICK = 0, 1
NEAR_REQUESTS = 4
OWN_FEATURES = 6
FORECAST_FEATURES = 2


@dataclass(frozen=True)
class EnvConfig:
    """The instance family: a scenario, a city-hour, a fleet size and the forecast agents see."""

    scenario: str = "synthetic"
    data_dir: str | None = None
    date: str = "2022-11-17"
    hour: int = 19
    minutes: int = 60
    taxis: int = 20
    world_seed: int = 0
    forecast: str = "previous-hour"


@functools.lru_cache(maxsize=4)
def _load_scenario(name: str, data_dir: str | None, world_seed: int):  # noqa: ANN202
    """Scenarios built once per process: environments are made and remade many times (vectorised envs, tests)."""
    from city.scenario import load_scenario

    return load_scenario(name, data_dir, seed=world_seed)


class _Episode:
    """One episode's simulator, control sets and observations, shared by both environments."""

    def __init__(self, config: EnvConfig) -> None:
        self.config = config
        scen = _load_scenario(config.scenario, config.data_dir, config.world_seed)
        self.city, self.world = scen.city, scen.world
        self.date = dt.date.fromisoformat(config.date)
        self.requests = episode_requests(self.world, self.date, config.hour, config.minutes)
        self.provider = make_provider(config.forecast)
        degree = np.diff(self.city.indptr)
        self.n_slots = 2 + int(degree.max())
        self.obs_size = OWN_FEATURES + 3 * NEAR_REQUESTS + self.n_slots + FORECAST_FEATURES
        self.max_hops = float(max(1, int(self.city.dist.max())))
        lo, hi = self.city.xy.min(axis=0), self.city.xy.max(axis=0)
        self.unit_xy = (self.city.xy - lo) / np.where(hi > lo, hi - lo, 1.0)
        self._eta_hour: int | None = None
        self.sim: FleetSim | None = None

    def start(self, seed: int) -> None:
        self.sim = FleetSim(self.city, self.requests, initial_positions(self.city, self.config.taxis, seed))
        self.obs = self.sim.observe()
        self.total_cost = 0

    @property
    def minute(self) -> int:
        assert self.sim is not None
        return self.sim.state.t

    def done(self) -> bool:
        return self.minute >= self.config.minutes

    def targets(self, i: int) -> np.ndarray:
        """Node of each slot of taxi ``i`` (``PICKUP`` for slot 1, -2 where the slot does not exist)."""
        obs = self.obs
        out = np.full(self.n_slots, -2, dtype=np.int64)
        here = int(obs.pos[i])
        if obs.tau[i] > 0:
            out[STAY] = int(self.city.next_hop[here, obs.dest[i]])
            return out
        out[STAY] = here
        if np.any(obs.req_pickup == here):
            out[PICK] = PICKUP
        nbrs = np.unique(self.city.neighbors(here))
        out[2 : 2 + len(nbrs)] = nbrs
        return out

    def mask(self, i: int) -> np.ndarray:
        return (self.targets(i) != -2).astype(np.int8)

    def control(self, i: int, action: Any) -> int:
        """The control of slot ``action`` for taxi ``i``; a slot that does not exist plays as slot 0."""
        targets = self.targets(i)
        a = int(action) if action is not None else STAY
        return int(targets[a] if 0 <= a < self.n_slots and targets[a] != -2 else targets[STAY])

    def action_of(self, i: int, control: int) -> int:
        """The slot of taxi ``i`` that plays ``control`` (the inverse of :meth:`control`)."""
        hits = np.flatnonzero(self.targets(i) == control)
        if hits.size == 0:
            raise ValueError(f"control {control} is not in taxi {i}'s control set")
        return int(hits[0])

    def eta(self) -> np.ndarray:
        """Forecast requests per minute per sector for the episode's current hour."""
        hour = self.minute // 60
        if self._eta_hour != hour:
            when = dt.datetime.combine(self.date, dt.time()) + dt.timedelta(hours=self.config.hour + hour)
            self._eta = np.asarray(self.provider.forecast(self.world, when).eta, dtype=np.float64)
            self._eta_hour = hour
        return self._eta

    def observe(self, i: int, committed: dict[int, int]) -> dict[str, np.ndarray]:
        obs, city = self.obs, self.city
        here = int(obs.pos[i])
        v = np.zeros(self.obs_size, dtype=np.float32)
        v[0:2] = self.unit_xy[here]
        v[2] = obs.tau[i] / self.max_hops
        v[3] = float(obs.tau[i] == 0)
        if obs.tau[i] > 0:
            v[4:6] = self.unit_xy[obs.dest[i]]
        if obs.req_pickup.size:
            hops = city.dist[here, obs.req_pickup].astype(np.float64)
            order = np.lexsort((obs.req_index, hops))[:NEAR_REQUESTS]
            for k, r in enumerate(order):
                base = OWN_FEATURES + 3 * k
                v[base : base + 3] = (min(hops[r] / self.max_hops, 1.0), (obs.t - obs.req_entry[r]) / 60.0, 1.0)
        slots = OWN_FEATURES + 3 * NEAR_REQUESTS
        targets = self.targets(i)
        for j, u in committed.items():
            if j == i:
                continue
            if u == PICKUP:
                if int(obs.pos[j]) == here and obs.tau[i] == 0:
                    v[slots + PICK] += 1.0
            else:
                v[slots + np.flatnonzero(targets == u)] += 1.0
        v[slots : slots + self.n_slots] /= max(1, len(obs.pos))
        eta = self.eta()
        sector = int(city.node_sector[here])
        v[-2] = eta[sector]
        v[-1] = eta[city.local_sectors(sector)].sum()
        return {"observation": v, "action_mask": self.mask(i)}

    def step(self, controls: np.ndarray) -> int:
        """Apply one joint control (busy taxis' entries replaced by their next hop); the stage cost."""
        assert self.sim is not None
        obs = self.obs
        u = np.where(obs.tau > 0, self.sim.busy_controls(), controls).astype(np.int32)
        cost = self.sim.step(u)
        self.total_cost += cost
        self.obs = self.sim.observe()
        return cost

    def spaces(self) -> tuple[gymnasium.spaces.Space, gymnasium.spaces.Space]:
        obs = gymnasium.spaces.Dict({
            "observation": gymnasium.spaces.Box(0.0, np.inf, (self.obs_size,), np.float32),
            "action_mask": gymnasium.spaces.Box(0, 1, (self.n_slots,), np.int8),
        })
        return obs, gymnasium.spaces.Discrete(self.n_slots)


def _agents(n: int) -> list[str]:
    return [f"taxi_{i}" for i in range(n)]


class FleetAECEnv(AECEnv):
    """The fleet as an AEC game: free taxis act one at a time, in index order, every minute; see the module docstring."""

    metadata = {"name": "surge_fleet_aec_v0", "render_modes": [], "is_parallelizable": True}

    def __init__(self, config: EnvConfig | None = None, **kwargs: Any) -> None:
        super().__init__()
        self.config = config or EnvConfig(**kwargs)
        self.episode = _Episode(self.config)
        self.possible_agents = _agents(self.config.taxis)
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        obs_space, act_space = self.episode.spaces()
        self.observation_spaces = {a: obs_space for a in self.possible_agents}
        self.action_spaces = {a: act_space for a in self.possible_agents}
        self.render_mode = None

    def observation_space(self, agent: str) -> gymnasium.spaces.Space:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> gymnasium.spaces.Space:
        return self.action_spaces[agent]

    @property
    def sim(self) -> FleetSim:
        assert self.episode.sim is not None, "reset() first"
        return self.episode.sim

    @property
    def total_cost(self) -> int:
        """Requests waiting summed over the minutes played so far (minus the sum of the shared rewards)."""
        return self.episode.total_cost

    def action_of(self, agent: str, control: int) -> int:
        """The action that plays ``control`` (a node id or ``city.sim.PICKUP``) for ``agent`` now."""
        return self.episode.action_of(self._index[agent], control)

    def reset(self, seed: int | None = None, options: dict | None = None) -> None:
        self.episode.start(0 if seed is None else int(seed))
        self.agents = list(self.possible_agents)
        self.rewards = {a: 0.0 for a in self.agents}
        self._cumulative_rewards = {a: 0.0 for a in self.agents}
        self.terminations = {a: False for a in self.agents}
        self.truncations = {a: False for a in self.agents}
        self.infos = {a: {} for a in self.agents}
        self._begin_minute()

    def _begin_minute(self) -> None:
        """Play through minutes with no free taxi; then queue this minute's free taxis in index order."""
        ep = self.episode
        while not ep.done() and not (ep.obs.tau == 0).any():
            self._add_cost(ep.step(ep.obs.pos.copy()))
        if ep.done():
            self.truncations = {a: True for a in self.agents}
            self.agent_selection = self.agents[0]
            return
        self._queue = [self.possible_agents[i] for i in np.flatnonzero(ep.obs.tau == 0)]
        self._committed: dict[int, int] = {}
        self.agent_selection = self._queue[0]

    def _add_cost(self, cost: int) -> None:
        for a in self.agents:
            self.rewards[a] -= float(cost)

    def observe(self, agent: str) -> dict[str, np.ndarray]:
        return self.episode.observe(self._index[agent], self._committed if hasattr(self, "_committed") else {})

    def step(self, action: Any) -> None:
        agent = self.agent_selection
        if self.terminations[agent] or self.truncations[agent]:
            self._was_dead_step(action)
            if self.agents:
                self.agent_selection = self.agents[0]
            return
        self._clear_rewards()
        self._cumulative_rewards[agent] = 0.0
        i = self._index[agent]
        self._committed[i] = self.episode.control(i, action)
        self._queue.pop(0)
        if self._queue:
            self.agent_selection = self._queue[0]
        else:
            ep = self.episode
            controls = ep.obs.pos.copy()
            for j, u in self._committed.items():
                controls[j] = u
            self._add_cost(ep.step(controls))
            self._begin_minute()
        self._accumulate_rewards()

    def close(self) -> None:
        pass


class FleetParallelEnv(ParallelEnv):
    """The fleet with every taxi choosing at once, one step a minute; see the module docstring."""

    metadata = {"name": "surge_fleet_parallel_v0", "render_modes": []}

    def __init__(self, config: EnvConfig | None = None, **kwargs: Any) -> None:
        self.config = config or EnvConfig(**kwargs)
        self.episode = _Episode(self.config)
        self.possible_agents = _agents(self.config.taxis)
        obs_space, act_space = self.episode.spaces()
        self.observation_spaces = {a: obs_space for a in self.possible_agents}
        self.action_spaces = {a: act_space for a in self.possible_agents}
        self.render_mode = None
        self.agents: list[str] = []

    def observation_space(self, agent: str) -> gymnasium.spaces.Space:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> gymnasium.spaces.Space:
        return self.action_spaces[agent]

    @property
    def total_cost(self) -> int:
        return self.episode.total_cost

    def _observations(self) -> dict[str, dict[str, np.ndarray]]:
        return {a: self.episode.observe(i, {}) for i, a in enumerate(self.possible_agents)}

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        self.episode.start(0 if seed is None else int(seed))
        self.agents = list(self.possible_agents)
        return self._observations(), {a: {} for a in self.agents}

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        ep = self.episode
        controls = np.array([ep.control(i, actions.get(a)) for i, a in enumerate(self.possible_agents)], dtype=np.int32)
        reward = -float(ep.step(controls))
        agents = self.agents
        truncated = ep.done()
        obs = self._observations()
        rewards = {a: reward for a in agents}
        terminations = {a: False for a in agents}
        truncations = {a: truncated for a in agents}
        infos = {a: {} for a in agents}
        if truncated:
            self.agents = []
        return obs, rewards, terminations, truncations, infos

    def close(self) -> None:
        pass


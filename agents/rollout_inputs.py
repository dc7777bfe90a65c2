"""A rollout's inputs: what the agents of one minute share, and one decision's control set, taxis, requests and arrays.

What :func:`agents.rollout.plan_agent` hands the compiled kernel (:mod:`agents._kernels`) for one free agent: the
minute's controls with the agent's candidates, the nodes within the pruning radius, the taxis kept (those that can
pick up, at most ``cap``) and the tracked requests with their nearest-request lists.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from agents import _kernels as K
from agents.demand_tables import DemandTables
from agents.place_values import place_values
from agents.rollout_config import CE_MODES, NEAR_K, RolloutConfig
from agents.shortcuts import PlanStats, Shortcuts, transposed
from city.graph import City
from city.sim import PICKUP, Observation

#: No rebalancing targets (bases other than ``rebalance``).
NO_HOME = np.empty(0, dtype=np.int32)


@dataclass(frozen=True)
class StepContext:
    """Everything the agents of one minute share; a pure function of the observation and forecast.

    Attributes
    ----------
    city : City
    config : RolloutConfig
    obs : Observation
    base_controls : ndarray (m,)
        The base policy's joint control for this minute (busy taxis: their next hop).
    tables : DemandTables
        The forecast of the minute's hour.
    minute0 : int
        Minutes since the forecast hour began.
    shortcuts : Shortcuts
        Exact savings in use (all by default).
    near, near_d : ndarray or None
        The minute's nearest-request lists over every outstanding request (``shortcuts.minute_lists``).
    stats : PlanStats
        What the minute's decisions cost and what the shortcuts settled.
    arrival_spots : dict
        Per set of sampled sectors, the nodes where an arrival within the
        horizon can be picked up (:func:`agents.rollout_inputs.pickup_spots`): agents of one area share it.
    home : ndarray of int32 (m,) or (0,)
        With the ``rebalance`` base, each taxi's rebalancing target of the
        minute (-1: none), which the simulated taxis keep; empty otherwise.
    """

    city: City
    config: RolloutConfig
    obs: Observation
    base_controls: np.ndarray
    tables: DemandTables
    minute0: int
    shortcuts: Shortcuts = field(default_factory=Shortcuts)
    near: np.ndarray | None = None
    near_d: np.ndarray | None = None
    stats: PlanStats = field(default_factory=PlanStats)
    arrival_spots: dict[bytes, np.ndarray] = field(default_factory=dict, repr=False)
    home: np.ndarray = field(default_factory=lambda: NO_HOME)


def candidate_controls(city: City, obs: Observation, agent: int) -> np.ndarray:
    """Agent's control set in tie-break order: stay, pickup (if a request waits here), out-neighbours ascending."""
    here = int(obs.pos[agent])
    cands = [here]
    if np.any(obs.req_pickup == here):
        cands.append(PICKUP)
    cands.extend(sorted(int(v) for v in city.neighbors(here)))
    return np.asarray(cands, dtype=np.int32)


def relevant_nodes(city: City, config: RolloutConfig, here: int, dist_t: np.ndarray | None = None) -> np.ndarray:
    """Nodes a decision at ``here`` looks at: within the pruning radius in either direction (all without pruning).

    ``dist_t``, ``city.dist`` transposed, when at hand, gives the distances to ``here`` as one row
    (contiguous when it is :func:`transposed`'s copy).
    """
    if config.prune is None:
        return np.ones(city.n_nodes, dtype=bool)
    to_here = city.dist[:, here] if dist_t is None else dist_t[here]
    return (city.dist[here] <= config.prune) | (to_here <= config.prune)


@dataclass
class DecisionInputs:
    """One decision's kernel inputs (see :func:`agents.rollout.agent_costs`): its candidates, whether it can be skipped, and the kernel's arrays."""

    cands: np.ndarray
    skip: bool
    args: tuple
    ag: int
    shadow: np.ndarray
    place: np.ndarray
    home: np.ndarray


def decision_inputs(ctx: StepContext, committed: np.ndarray, agent: int) -> DecisionInputs:
    """Free ``agent``'s kernel inputs, after the controls ``committed`` by the agents before it; a pure function of them and ``ctx``."""
    city, cfg, obs, sc = ctx.city, ctx.config, ctx.obs, ctx.shortcuts
    if obs.tau[agent] > 0:
        raise ValueError(f"agent {agent} is busy; its only control is its next hop")
    committed = np.asarray(committed, dtype=np.int32)
    if committed.shape != (agent,):
        raise ValueError(f"committed: expected {agent} controls, got {committed.shape}")
    H = cfg.horizon
    greedy = cfg.base == "greedy"
    here = int(obs.pos[agent])
    cands = candidate_controls(city, obs, agent)
    controls = np.repeat(ctx.base_controls[None, :], cands.size, axis=0)
    controls[:, :agent] = committed
    controls[:, agent] = cands
    req_pick = np.ascontiguousarray(obs.req_pickup, dtype=np.int32)
    req_drop = np.ascontiguousarray(obs.req_dropoff, dtype=np.int32)
    alive0, pos1, tfree1 = K.step_zero(controls, obs.pos, obs.tau, obs.dest, req_pick, req_drop, city.dist)

    dist_t, hop_t = transposed(city) if sc.rows else (city.dist.T, city.next_hop.T)
    rel_node = relevant_nodes(city, cfg, here, dist_t)
    if cfg.scope == "local":
        sectors = city.local_sectors(int(city.node_sector[here]))
    else:
        sectors = np.arange(city.n_sectors)
    if cfg.prune is not None:
        sectors = sectors[np.bincount(city.node_sector[rel_node], minlength=city.n_sectors)[sectors] > 0]
    tab = ctx.tables
    mode = CE_MODES[cfg.ce]
    keep = (tfree1.min(axis=0) <= H) & rel_node[pos1].any(axis=0)
    keep[agent] = True
    rel_req = rel_node[req_pick]
    skip = False
    taxis = np.flatnonzero(keep)
    useful = np.ones(taxis.size, dtype=bool)
    capped = cfg.cap is not None and taxis.size > cfg.cap
    # With a tail or place values every simulated taxi's end position is part of the cost: none is left out
    # for not reaching a pickup.
    if greedy and not cfg.tail and not cfg.place and (sc.reach or sc.skip or capped):
        # Where a pickup can happen within the horizon: tracked requests and possible arrivals.
        spots = pickup_spots(ctx, sectors, rel_node, req_pick[rel_req & alive0.any(axis=0)])
        if sc.skip and PICKUP not in cands:
            skip = not K.reaches(cands, np.ones(cands.size, np.int64), spots, H, city.dist).any()
        if (sc.reach or capped) and not skip:
            others = taxis != agent
            useful[others] = K.reaches(pos1[0, taxis[others]], tfree1[0, taxis[others]].astype(np.int64), spots, H, city.dist)
    # The cap ranks only taxis that can pick up (greedy base): the others never change a cost, so
    # ``reach``, which leaves them out, stays exact under the cap.
    chosen = useful.copy()
    if cfg.cap is not None and chosen.sum() > cfg.cap:
        ranked = np.flatnonzero(useful & (taxis != agent))
        order, _ = cap_ranking(city, obs, here, taxis[ranked])
        chosen[ranked[order[cfg.cap - 1:]]] = False
    taxis = taxis[chosen | (~useful & (not sc.reach))]
    ag = int(np.searchsorted(taxis, agent))
    if sc.minute_lists and ctx.near is not None:
        e_pick, e_drop = req_pick, req_drop
        a0 = np.ascontiguousarray(alive0 & rel_req[None, :])
        near, near_d = ctx.near, ctx.near_d
    else:
        tracked = np.flatnonzero(rel_req)
        e_pick, e_drop = req_pick[tracked], req_drop[tracked]
        a0 = np.ascontiguousarray(alive0[:, tracked])
        if sc.lazy_lists:
            near, near_d = K.unfilled_lists(city.n_nodes, e_pick.size, NEAR_K)
        else:
            near, near_d = K.nearest_lists(city.dist, e_pick, NEAR_K)
    args = (
        np.uint64(K.stream_key(cfg.seed, int(obs.t), agent)), ctx.minute0, mode,
        a0, np.ascontiguousarray(pos1[:, taxis]), np.ascontiguousarray(tfree1[:, taxis]),
        e_pick, e_drop, near, near_d, rel_node,
        sectors.astype(np.int64), tab.eta, tab.pk_ptr, tab.pk_node, tab.pk_cum, tab.dk_ptr, tab.dk_node, tab.dk_cum,
        tab.beta_cum, max_arrivals(tab.eta[sectors], mode, ctx.minute0, H), city.dist, dist_t, hop_t,
    )
    # With a tail the agent's end position is part of every cost: no candidate's cost is another's.
    shadow = (cands != PICKUP) & (sc.shadow and greedy and not cfg.tail and not cfg.place)
    place = place_values(city, tab, sectors) if cfg.place else _NO_PLACE
    home = np.ascontiguousarray(ctx.home[taxis]) if ctx.home.size else NO_HOME
    return DecisionInputs(cands=cands, skip=skip, args=args, ag=ag, shadow=np.ascontiguousarray(shadow), place=place, home=home)


_NO_PLACE = np.empty(0, dtype=np.int64)


def cap_ranking(city: City, obs: Observation, here: int, taxis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The order in which the cap keeps ``taxis``, nearest to ``here`` first (hops, either direction; lower id on ties), and their hops."""
    d = np.minimum(city.dist[here, obs.pos[taxis]], city.dist[obs.pos[taxis], here])
    return np.lexsort((taxis, d)), d


def pickup_spots(ctx: StepContext, sectors: np.ndarray, rel_node: np.ndarray, tracked_pickups: np.ndarray) -> np.ndarray:
    """Nodes where a rollout can pick up: the tracked requests' and every possible arrival's (relevant) pickup node.

    Only whether a taxi reaches one of them matters (:func:`K.reaches`), so
    the list may repeat a node; the arrivals' nodes are found once per minute
    and set of sectors.
    """
    key = sectors.tobytes()
    arrivals = ctx.arrival_spots.get(key)
    if arrivals is None:
        tab, minute0 = ctx.tables, ctx.minute0
        eta = tab.eta[sectors]
        if CE_MODES[ctx.config.ce] == K.LIMITED_CE:
            live = sectors[eta > 0]
        else:
            m = minute0 + ctx.config.horizon
            live = sectors[np.floor(eta * (m + 1) + 0.5) - np.floor(eta * (minute0 + 1) + 0.5) > 0]
        parts = [tab.pk_node[tab.pk_ptr[q] : tab.pk_ptr[q + 1]] for q in live]
        arrivals = np.unique(np.concatenate(parts).astype(np.int32)) if parts else np.empty(0, np.int32)
        ctx.arrival_spots[key] = arrivals
    nodes = np.concatenate((tracked_pickups.astype(np.int32), arrivals))
    return np.ascontiguousarray(nodes[rel_node[nodes]])


def max_arrivals(eta: np.ndarray, mode: int, minute0: int, horizon: int) -> int:
    """An upper bound on one sample's arrivals from sectors with rates ``eta``."""
    if mode == K.LIMITED_CE:
        per_minute = np.where(eta >= 1.0, np.floor(eta + 0.5), 1.0)
        return int(per_minute.sum()) * horizon
    m = minute0 + horizon
    return int((np.floor(eta * (m + 1) + 0.5) - np.floor(eta * (minute0 + 1) + 0.5)).sum())

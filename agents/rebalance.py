"""``rebalance``: ``match`` plus forecast-driven rebalancing of the idle taxis toward sector deficits.

Each minute the free taxis are first matched to the outstanding requests
exactly as ``match`` does (:func:`agents.match.match_requests`); matched taxis
keep that control.  The free taxis left over (idle) are then sent to sectors
by a second minimum-cost assignment, a transport problem over sector
*slots*, in the manner of real-time rebalancing (Pavone et al. 2012; Zhang &
Pavone 2016), of MATSim DRT's min-cost-flow rebalancing toward forecast
demand, and of Wallar et al. (2018)'s rebalancing of idle vehicles to regions
by predicted demand:

- the demand of sector ``s`` over the next ``lookahead`` minutes is Poisson
  with mean ``μ_s = η_s · lookahead`` (the forecast provider's rate);
- taxis that will be free in ``s`` within the look-ahead already cover the
  first ``c_s`` requests: busy taxis whose drop-off is in ``s`` and whose
  remaining trip is at most ``lookahead`` minutes, and matched taxis whose
  pickup and trip end in ``s`` within it;
- the ``k``-th further taxi in ``s`` is worth ``value · P(N_s ≥ c_s + k)`` hops:
  the chance that it will have a request to serve there;
- an idle taxi costs ``hops`` to reach sector ``s``'s anchor (the intersection
  with the least ρ-weighted pickup distance to the sector's demand), and may
  stay where it is for nothing.

The assignment (``scipy.optimize.linear_sum_assignment`` over taxis × (slots
+ one stay column per taxi)) is exact; an idle taxi assigned to a slot moves
one hop toward the sector's anchor, one assigned to stay does not move.  It
never changes a matched or busy taxi's control.  The forecast is that of the
hour being played, as ``surge`` reads it: a look-ahead that runs past the
hour keeps the hour's rates (a ``previous-hour`` forecast of the next hour
would read counts of minutes not yet played).

Options
-------
forecast : ``model`` | ``previous-hour`` | ``true-rate`` (default ``previous-hour``)
    The forecast provider, as ``surge``'s; ``model`` needs ``model=DIR``.
lookahead : int minutes (default 6)
    Horizon of the demand the slots are valued by.
value : float hops (default 2000)
    What a slot whose demand is certain is worth, in hops of driving.  The
    default is far above any drive, so the slots with the likeliest demand
    are filled first and the drive decides between equally likely ones.

The defaults (with ``match``'s ``cost=sqrt``) have the least total cost of a
grid over ``lookahead`` and ``value`` on validation data (a July–August date
only): ``benchmarks/practice-baselines/``.
cost, wait_weight :
    The matching's, as ``match``'s.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.special import pdtrc

from agents.base import Option, Policy, register
from agents.forecast_providers import PROVIDERS, make_provider
from agents.match import Matching, match_options, match_requests, matched_controls
from city.episode import EpisodeContext
from city.errors import ConfigError
from city.forecast import Forecast, ForecastProvider
from city.graph import City
from city.sim import Observation


def sector_anchors(city: City, rho: np.ndarray) -> np.ndarray:
    """Per sector, the intersection with the least ρ-weighted shortest-path distance to the sector's pickups."""
    out = np.zeros(city.n_sectors, dtype=np.int64)
    for s in range(city.n_sectors):
        nodes = np.flatnonzero(city.node_sector == s)
        w = rho[nodes]
        if w.sum() <= 0:
            w = np.ones(nodes.size)
        spread = city.dist[nodes[:, None], nodes[None, :]].astype(np.float64) @ w
        out[s] = nodes[int(np.argmin(spread))]
    return out


def covered(city: City, obs: Observation, m: Matching, lookahead: int) -> np.ndarray:
    """Per sector, the taxis other than the idle ones that will be free there within ``lookahead`` minutes."""
    c = np.zeros(city.n_sectors, dtype=np.int64)
    busy = np.flatnonzero((obs.tau > 0) & (obs.tau <= lookahead) & (obs.dest >= 0))
    np.add.at(c, city.node_sector[obs.dest[busy]], 1)
    if m.size:
        pick, drop = obs.req_pickup[m.requests], obs.req_dropoff[m.requests]
        done = city.dist[obs.pos[m.taxis], pick].astype(np.int64) + np.maximum(1, city.dist[pick, drop])
        np.add.at(c, city.node_sector[drop[done <= lookahead]], 1)
    return c


def slot_values(mu: np.ndarray, cover: np.ndarray, n_idle: int, value: float) -> tuple[np.ndarray, np.ndarray]:
    """Sector and worth (hops) of every slot: the ``k``-th extra taxi in ``s`` is worth ``value · P(N_s ≥ cover_s + k)``.

    At most ``n_idle`` slots per sector, and only slots worth more than
    ``1e-9`` hops (the others can never beat staying).
    """
    S = mu.size
    k = np.arange(1, n_idle + 1)[None, :]
    need = cover[:, None] + k
    worth = value * pdtrc(need - 1, np.maximum(mu, 1e-12)[:, None])  # P(N ≥ need) = P(N > need - 1)
    keep = worth > 1e-9
    sectors = np.broadcast_to(np.arange(S)[:, None], keep.shape)[keep]
    return sectors, worth[keep]


def rebalance_targets(city: City, pos: np.ndarray, anchors: np.ndarray, sectors: np.ndarray, worth: np.ndarray) -> np.ndarray:
    """Each idle taxi's target intersection (its own position: stay) by the slot assignment."""
    n = pos.size
    if n == 0 or sectors.size == 0:
        return pos.copy()
    travel = city.dist[pos[:, None], anchors[sectors][None, :]].astype(np.float64)
    cost = np.hstack([travel - worth[None, :], np.zeros((n, n))])
    rows, cols = linear_sum_assignment(cost)
    target = pos.copy()
    to_slot = cols < sectors.size
    target[rows[to_slot]] = anchors[sectors[cols[to_slot]]]
    return target


@register
class Rebalance(Policy):
    """``match`` plus forecast-driven rebalancing of idle taxis to sector slots (see the module docstring)."""

    name = "rebalance"
    central = True
    options = (
        Option("forecast", str, choices=tuple(sorted(PROVIDERS)), help="forecast provider (default previous-hour)"),
        Option("model", str, noun="a directory", help="trained predictor directory for forecast=model"),
        Option("lookahead", int, low=1, high=60, help="minutes of forecast demand the slots are valued by (default 6)"),
        Option("value", float, low=0, help="hops a slot of certain demand is worth (default 2000)"),
        *match_options(),
    )
    defaults = {"forecast": "previous-hour", "lookahead": 6, "value": 2000.0}

    def __init__(self, city: City, forecast: str | None = None, model: str | Path | None = None, lookahead: int = 6,
                 value: float = 2000.0, cost: str = "sqrt", wait_weight: float = 0.1) -> None:
        super().__init__(city)
        self.provider: ForecastProvider = make_provider(forecast or self.defaults["forecast"], model)
        self.lookahead, self.value = int(lookahead), float(value)
        self.cost, self.wait_weight = cost, float(wait_weight)
        self.context: EpisodeContext | None = None
        self._hours: dict[int, tuple[Forecast, np.ndarray]] = {}
        self.last_matching: Matching | None = None
        self.last_targets: np.ndarray | None = None

    def reset(self, context: EpisodeContext) -> None:
        if context.world is None:
            raise ConfigError(f"policy {self.name!r} needs the episode's demand world for its forecasts")
        self.context, self._hours = context, {}

    def forecast(self, hour_offset: int = 0) -> Forecast:
        """The provider's forecast of the hour ``hour_offset`` hours after the episode's start."""
        ctx = self.context
        if ctx is None:
            raise ConfigError(f"policy {self.name!r}: reset() must be called before act()")
        when = dt.datetime.combine(ctx.date, dt.time()) + dt.timedelta(hours=ctx.hour + hour_offset)
        return self.provider.forecast(ctx.world, when)

    def hour_data(self, hour_offset: int) -> tuple[Forecast, np.ndarray]:
        """The forecast of the episode's hour ``hour_offset`` and its sectors' anchors, computed once an hour."""
        if hour_offset not in self._hours:
            fc = self.forecast(hour_offset)
            self._hours = {hour_offset: (fc, sector_anchors(self.city, fc.rho))}
        return self._hours[hour_offset]

    def act(self, obs: Observation) -> np.ndarray:
        fc, anchors = self.hour_data(obs.t // 60)
        u, home, m = rebalance_plan(self.city, obs, fc.eta, anchors, self.lookahead, self.value, self.cost, self.wait_weight)
        self.last_matching = m
        idle = np.flatnonzero((obs.tau == 0) & (home >= 0))
        self.last_targets = None if idle.size == 0 else home[idle]
        return u


def rebalance_plan(city: City, obs: Observation, eta: np.ndarray, anchors: np.ndarray, lookahead: int = 6, value: float = 2000.0,
                   cost: str = "sqrt", wait_weight: float = 0.1) -> tuple[np.ndarray, np.ndarray, Matching]:
    """``rebalance``'s joint control of a minute, each taxi's rebalancing target, and the matching.

    Returns
    -------
    controls : ndarray of int32 (m,)
    home : ndarray of int32 (m,)
        The target intersection of each idle taxi (one left free after the
        matching; its own node when it stays), -1 for every other taxi.  The
        rollout base ``rebalance`` keeps these targets for the minutes it
        simulates (:mod:`agents._iasim`).
    matching : Matching
    """
    m = match_requests(city, obs, cost, wait_weight)
    u = matched_controls(city, obs, m).astype(np.int32)
    home = np.full(obs.pos.size, -1, dtype=np.int32)
    idle = np.setdiff1d(np.flatnonzero(obs.tau == 0), m.taxis)
    if idle.size == 0:
        return u, home, m
    sectors, worth = slot_values(np.asarray(eta, dtype=np.float64) * lookahead, covered(city, obs, m, lookahead), idle.size, value)
    target = rebalance_targets(city, obs.pos[idle], anchors, sectors, worth)
    home[idle] = target
    u[idle] = city.next_hop[obs.pos[idle], target]
    return u, home, m

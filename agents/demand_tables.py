"""A forecast laid out for the rollout's sampling kernel: per-sector node tables or pools."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agents.rollout_config import POOLED_CE
from city.errors import ConfigError
from city.forecast import Forecast
from city.graph import City


@dataclass(frozen=True)
class DemandTables:
    """A forecast laid out for the sampling kernel.

    Attributes
    ----------
    eta : ndarray (S,)
        Per-minute rate (zero for sectors without pickup intersections).
    pk_ptr, pk_node, pk_cum : ndarray
        Per sector (CSR by ``pk_ptr``), the pickup nodes and their cumulative weights.
    dk_ptr, dk_node, dk_cum : ndarray
        The same for drop-off nodes.
    beta_cum : ndarray (S, S)
        Cumulative drop-off-sector weights per pickup sector.
    """

    eta: np.ndarray
    pk_ptr: np.ndarray
    pk_node: np.ndarray
    pk_cum: np.ndarray
    dk_ptr: np.ndarray
    dk_node: np.ndarray
    dk_cum: np.ndarray
    beta_cum: np.ndarray

    @classmethod
    def build(cls, city: City, forecast: Forecast, ce: str, seed: int) -> DemandTables:
        """Tables of ``forecast``: per-sector pools under standard CE, the distributions themselves otherwise (``limited``, ``counts``)."""
        S, n = city.n_sectors, city.n_nodes
        if forecast.n_sectors != S or forecast.rho.shape[0] != n:
            raise ConfigError(f"forecast has {forecast.n_sectors} sectors and {forecast.rho.shape[0]} nodes; the city has {S} and {n}")
        eligible = np.asarray(city.pickup, dtype=bool)
        has_nodes = np.bincount(city.node_sector[eligible], minlength=S) > 0
        eta = np.where(has_nodes, forecast.eta, 0.0)
        beta = np.where(has_nodes[None, :], forecast.beta, 0.0)
        beta = np.where(beta.sum(1, keepdims=True) > 0, beta, has_nodes[None, :].astype(np.float64))
        if ce in POOLED_CE:
            rng = np.random.default_rng([seed, 2023])
            drop_expect = 60.0 * (eta @ (beta / beta.sum(1, keepdims=True)))
            pick = _pools(city, forecast.rho, np.maximum(1, np.rint(60.0 * eta)).astype(np.int64), rng)
            drop = _pools(city, forecast.delta, np.maximum(1, np.rint(drop_expect)).astype(np.int64), rng)
        else:
            pick = _tables(city, forecast.rho)
            drop = _tables(city, forecast.delta)
        return cls(eta=np.ascontiguousarray(eta, dtype=np.float64), pk_ptr=pick[0], pk_node=pick[1], pk_cum=pick[2],
                   dk_ptr=drop[0], dk_node=drop[1], dk_cum=drop[2], beta_cum=np.ascontiguousarray(np.cumsum(beta, axis=1)))


def _weights(city: City, p: np.ndarray) -> np.ndarray:
    """``p`` on eligible nodes, uniform within sectors where it has no mass."""
    eligible = np.asarray(city.pickup, dtype=bool)
    w = np.where(eligible, p, 0.0)
    mass = np.bincount(city.node_sector, weights=w, minlength=city.n_sectors)
    return np.where(mass[city.node_sector] > 0, w, eligible.astype(np.float64))


def _tables(city: City, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    w = _weights(city, p)
    nodes = np.flatnonzero(w > 0)
    nodes = nodes[np.argsort(city.node_sector[nodes], kind="stable")]
    sec = city.node_sector[nodes]
    ptr = np.searchsorted(sec, np.arange(city.n_sectors + 1)).astype(np.int64)
    cum = np.empty(nodes.size, dtype=np.float64)
    for s in range(city.n_sectors):
        cum[ptr[s] : ptr[s + 1]] = np.cumsum(w[nodes[ptr[s] : ptr[s + 1]]])
    return ptr, nodes.astype(np.int32), cum


def _pools(city: City, p: np.ndarray, sizes: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A pool of ``sizes[s]`` nodes per sector drawn from ``p``, as uniform-weight tables."""
    ptr, nodes, cum = _tables(city, p)
    parts, counts = [], np.zeros(city.n_sectors, dtype=np.int64)
    for s in range(city.n_sectors):
        lo, hi = ptr[s], ptr[s + 1]
        if hi == lo:
            continue
        idx = np.searchsorted(cum[lo:hi], rng.random(int(sizes[s])) * cum[hi - 1], side="right")
        parts.append(nodes[lo + np.minimum(idx, hi - lo - 1)])
        counts[s] = sizes[s]
    pool = np.concatenate(parts).astype(np.int32)
    pool_ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    pool_cum = np.concatenate([np.arange(1, c + 1, dtype=np.float64) for c in counts if c])
    return pool_ptr, pool, pool_cum

"""Random numbers and sampled arrivals of the rollout (numba, ``cache=True``).

A counter-based generator keyed by ``(key, sample, minute, sector)``: a
sample's requests do not depend on the thread that draws them, on the order
samples are drawn in, or on which other sectors are drawn (pruning skips
sectors without changing the rest).  The constants name the base policies and
certainty-equivalence modes shared by every kernel.
"""

from __future__ import annotations

import numpy as np
from numba import njit

PICKUP = -1
GREEDY = 0
IA = 1
LIMITED_CE = 0
STANDARD_CE = 1

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0
BIG_HOPS = 1 << 30


@njit(cache=True, inline="always", _nrt=False)
def _mix(z: np.uint64) -> np.uint64:
    """The splitmix64 finaliser."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True, _nrt=False)
def stream_key(seed: int, t: int, agent: int) -> np.uint64:
    """The 64-bit random key of one agent's decision at minute ``t``."""
    z = _mix(np.uint64(seed & 0x7FFFFFFFFFFFFFFF) + _GOLDEN)
    z = _mix(z ^ (np.uint64(t & 0x7FFFFFFFFFFFFFFF) + _GOLDEN))
    return _mix(z ^ (np.uint64(agent & 0x7FFFFFFFFFFFFFFF) + _GOLDEN))


@njit(cache=True, inline="always", _nrt=False)
def _stream(key: np.uint64, sample: int, minute: int, sector: int) -> np.uint64:
    z = _mix(key ^ (np.uint64(sample) * _M1 + _GOLDEN))
    z = _mix(z ^ (np.uint64(minute) * _M2 + _GOLDEN))
    return _mix(z ^ (np.uint64(sector) * _M1 + _M2))


@njit(cache=True, inline="always", _nrt=False)
def _next(state: np.uint64) -> tuple[np.uint64, float]:
    state = state + _GOLDEN
    return state, float(_mix(state) >> _S11) * _INV53


@njit(cache=True, inline="always", _nrt=False)
def _search(cum: np.ndarray, lo: int, hi: int, u: float) -> int:
    """First index ``i`` in ``[lo, hi)`` with ``cum[i] > u · cum[hi-1]`` (inverse CDF)."""
    x = u * cum[hi - 1]
    a, b = lo, hi - 1
    while a < b:
        mid = (a + b) >> 1
        if cum[mid] > x:
            b = mid
        else:
            a = mid + 1
    return a


@njit(cache=True, _nrt=False)
def arrival_count(mode: int, rate: float, minute: int, u: float) -> int:
    """Requests entering a sector in one minute under certainty equivalence.

    ``LIMITED_CE`` (surge): ``round(rate)`` when ``rate ≥ 1`` (halves round up),
    else one request with probability ``rate``.  ``STANDARD_CE`` (Garces et
    al.): deterministic mean arrivals, one request each time the rounded
    cumulative mean ``⌊rate · m + ½⌋`` steps up, ``m`` counting minutes from
    the forecast hour's start.
    """
    if mode == LIMITED_CE:
        if rate >= 1.0:
            return int(np.floor(rate + 0.5))
        return 1 if u < rate else 0
    return int(np.floor(rate * (minute + 1) + 0.5) - np.floor(rate * minute + 0.5))


@njit(cache=True, _nrt=False)
def sample_arrivals(
    key: np.uint64,
    sample: int,
    horizon: int,
    minute0: int,
    mode: int,
    sectors: np.ndarray,
    eta: np.ndarray,
    pk_ptr: np.ndarray,
    pk_node: np.ndarray,
    pk_cum: np.ndarray,
    dk_ptr: np.ndarray,
    dk_node: np.ndarray,
    dk_cum: np.ndarray,
    beta_cum: np.ndarray,
    rel_node: np.ndarray,
    out_pick: np.ndarray,
    out_drop: np.ndarray,
    out_step: np.ndarray,
) -> int:
    """Draw one sample's future requests for steps ``1 … horizon``; return how many were kept.

    For each step ``k`` and each sector ``q`` of ``sectors`` (ascending), the
    stream ``(key, sample, k, q)`` gives first the count draw, then three
    uniforms per request: pickup node (inverse CDF of ``pk_*`` in ``q``),
    drop-off sector (row ``q`` of ``beta_cum``) and drop-off node (``dk_*``).
    Requests whose pickup is not in ``rel_node`` are drawn but not kept.
    ``minute0`` is the decision step's minute since the forecast hour began.
    """
    n = 0
    for k in range(1, horizon + 1):
        for qi in range(sectors.shape[0]):
            q = sectors[qi]
            st = _stream(key, sample, k, q)
            st, u = _next(st)
            cnt = arrival_count(mode, eta[q], minute0 + k, u)
            for _ in range(cnt):
                st, u1 = _next(st)
                st, u2 = _next(st)
                st, u3 = _next(st)
                p = pk_node[_search(pk_cum, pk_ptr[q], pk_ptr[q + 1], u1)]
                if not rel_node[p]:
                    continue
                q2 = _search(beta_cum[q], 0, beta_cum.shape[1], u2)
                out_pick[n] = p
                out_drop[n] = dk_node[_search(dk_cum, dk_ptr[q2], dk_ptr[q2 + 1], u3)]
                out_step[n] = k
                n += 1
    return n

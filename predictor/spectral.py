"""Spectral clustering of an event's review embeddings into the stacked cluster means R_w.

Paper §4.2.1: a fully connected similarity graph with the Gaussian RBF
``s(e_q, e_h) = exp(-γ ||e_q - e_h||²)``, γ = 1, spectral clustering into b = 3
clusters with the CPQR label assignment of Damle et al. (scikit-learn's
``assign_labels="cluster_qr"``), then the mean of each cluster, stacked.

Ordering and small events (the paper leaves these open; surge fixes them so
that R_w is a well-defined function of the review list):

* At most ``Q`` (= 100) reviews are used: the first ``Q`` in the order given.
* Clusters are ordered by size (largest first), ties broken by the position
  of their first member in the review list.  Cluster labels from the
  clustering are arbitrary; this ordering makes slot 1 "the majority opinion".
* 0 reviews: ``R_w`` is all zeros and the event's mask is False; sector
  averages of R skip such events (their title embedding still counts).
* ``1 ≤ q ≤ b`` reviews: clustering is undefined, so each review is its own
  cluster (in review order) and the remaining slots repeat the mean of all
  reviews.
* All reviews identical (a degenerate similarity graph): one cluster; the
  remaining slots repeat the mean.
* A cluster that comes back empty from the solver is filled with the mean of
  all reviews (after the non-empty ones in the ordering).
"""

from __future__ import annotations

import warnings

import numpy as np

Q_MAX = 100
N_CLUSTERS = 3
GAMMA = 1.0


def spectral_labels(emb: np.ndarray, n_clusters: int = N_CLUSTERS, gamma: float = GAMMA, seed: int = 0) -> np.ndarray:
    """Spectral-clustering labels (RBF affinity, CPQR assignment) of ``emb`` ``(q, d)``."""
    from sklearn.cluster import SpectralClustering

    emb = np.asarray(emb, dtype=np.float64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = SpectralClustering(
            n_clusters=n_clusters,
            affinity="rbf",
            gamma=gamma,
            assign_labels="cluster_qr",
            random_state=seed,
        )
        return model.fit_predict(emb)


def order_clusters(labels: np.ndarray) -> list[np.ndarray]:
    """Member indices of each cluster, largest first, ties by first member."""
    labels = np.asarray(labels)
    groups = [np.flatnonzero(labels == lab) for lab in np.unique(labels)]
    groups.sort(key=lambda g: (-len(g), int(g[0])))
    return groups


def review_representation(
    emb: np.ndarray,
    n_clusters: int = N_CLUSTERS,
    gamma: float = GAMMA,
    q_max: int = Q_MAX,
    seed: int = 0,
) -> tuple[np.ndarray, bool]:
    """``(R_w, has_reviews)`` with ``R_w`` of shape ``(n_clusters, d)``; see the module notes."""
    emb = np.asarray(emb, dtype=np.float32)
    if emb.ndim != 2:
        raise ValueError(f"review embeddings must be 2-D, got shape {emb.shape}")
    d = emb.shape[1]
    emb = emb[:q_max]
    q = emb.shape[0]
    out = np.zeros((n_clusters, d), dtype=np.float32)
    if q == 0:
        return out, False
    mean = emb.mean(axis=0)
    if q <= n_clusters:
        out[:q] = emb
        out[q:] = mean
        return out, True
    uniq = np.unique(emb, axis=0)
    if len(uniq) == 1:
        out[:] = mean
        return out, True
    if len(uniq) < n_clusters:
        # Fewer distinct points than clusters: the distinct points are the clusters.
        inv = np.unique(emb, axis=0, return_inverse=True)[1].ravel()
        labels = inv
    else:
        labels = spectral_labels(emb, n_clusters=n_clusters, gamma=gamma, seed=seed)
    groups = order_clusters(labels)
    for slot in range(n_clusters):
        out[slot] = emb[groups[slot]].mean(axis=0) if slot < len(groups) else mean
    return out, True

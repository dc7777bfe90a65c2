"""How event texts become vectors: the sentence embedding (packaged model, offline) with its cache on disk, and the reviews' spectral representation."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.predictor.test_predictor import TinyWorld


def test_embedding_offline_and_cached(tmp_path: Path) -> None:
    from predictor.embed import Embedder

    emb = Embedder(None, tmp_path)
    v = emb.embed(["The Knicks beat the Celtics at the Garden", "A quiet poetry reading in a small bookstore", "The Knicks beat the Celtics at the Garden"])
    assert v.shape == (3, 384) and v.dtype == np.float32
    assert not np.allclose(v[0], v[1])
    assert np.array_equal(v[0], v[2])
    assert emb.stats["embedded"] == 2  # de-duplicated
    again = Embedder(None, tmp_path)
    w = again.embed(["A quiet poetry reading in a small bookstore"])
    assert again.stats["embedded"] == 0 and again._model is None  # served from disk, model never loaded
    assert np.array_equal(w[0], v[1])


def test_an_embedding_does_not_depend_on_the_texts_encoded_with_it(tmp_path: Path) -> None:
    """A predictor trained with one seed must not depend on what the embedding cache held before."""
    from predictor.embed import BATCH_ROWS, Embedder

    text = "The Knicks beat the Celtics at the Garden"
    others = [f"Event number {i}: a {'very ' * (i % 7)}long evening of jazz on the waterfront" for i in range(BATCH_ROWS + 5)]
    alone = Embedder(None, tmp_path / "a").embed([text])[0]
    crowded = Embedder(None, tmp_path / "b").embed([*others[:9], text, *others[9:]])
    assert np.array_equal(alone, crowded[9])
    plain = Embedder(None, use_cache=False).model.encode([text, *others], convert_to_numpy=True)
    assert np.allclose(crowded[[9, 0, 20]], plain[[0, 1, 20]], atol=1e-5)  # the encoder's own output, up to rounding


def test_gpu_vectors_are_cached_apart_from_the_cpus(tmp_path: Path) -> None:
    """A GPU's vectors differ from the CPU's in the last bits: a model trained on one never reads the other's."""
    from predictor.embed import Embedder

    cpu, cuda, cuda0 = (Embedder(None, tmp_path, device=d).cache.dir for d in ("cpu", "cuda", "cuda:0"))
    assert cpu.name.endswith(".rows64-pad8") and cuda == cuda0 == cpu.with_name(cpu.name + "-cuda")


def test_max_reviews_limits_the_texts_embedded() -> None:
    from predictor.embed import Embedder
    from predictor.features import EventFeaturizer

    counts = {}
    for q in (1, 100):
        feat = EventFeaturizer(Embedder(None, use_cache=False), q_max=q)
        feat.prepare(TinyWorld().events)
        counts[q] = feat.embedder.stats["embedded"]
    assert counts == {1: 4, 100: 8}  # two event texts, then the first review of each set or all three distinct ones


def test_cache_keeps_digests_ending_in_nul(tmp_path: Path) -> None:
    from predictor.embed import EmbeddingCache

    keys = [bytes(range(1, 20)) + b"\0", b"\0" * 20, bytes(range(20, 40))]
    vecs = np.arange(6, dtype=np.float32).reshape(3, 2)
    EmbeddingCache(tmp_path).put(keys, vecs)
    found, missing = EmbeddingCache(tmp_path).get(keys)
    assert missing == []
    assert all(np.array_equal(found[k], v) for k, v in zip(keys, vecs))


def test_spectral_clustering_recovers_planted_clusters() -> None:
    from predictor.spectral import review_representation, spectral_labels

    rng = np.random.default_rng(1)
    centres = rng.normal(size=(3, 384))
    centres /= np.linalg.norm(centres, axis=1, keepdims=True)
    sizes = [12, 10, 8]
    pts = np.vstack([c + 0.02 * rng.normal(size=(n, 384)) for c, n in zip(centres, sizes)])
    truth = np.repeat([0, 1, 2], sizes)
    perm = rng.permutation(len(pts))
    pts, truth = pts[perm], truth[perm]
    labels = spectral_labels(pts)
    from sklearn.metrics import adjusted_rand_score

    assert adjusted_rand_score(truth, labels) == 1.0
    R, has = review_representation(pts.astype(np.float32))
    assert has and R.shape == (3, 384)
    for slot, c in enumerate([0, 1, 2]):  # largest cluster first
        assert np.allclose(R[slot], pts[truth == c].mean(axis=0), atol=1e-5)
    # fewer reviews than clusters: each its own cluster, then the mean
    R2, has2 = review_representation(pts[:2].astype(np.float32))
    assert has2 and np.allclose(R2[0], pts[0]) and np.allclose(R2[2], pts[:2].mean(axis=0), atol=1e-6)
    R0, has0 = review_representation(np.zeros((0, 384), np.float32))
    assert not has0 and not R0.any()

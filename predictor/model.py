"""A trained demand model on disk, and the end-to-end training run (torch).

Model directory layout::

    model.json          schema, scenario, inputs (paths + hashes), split, features, normalisation,
                        settings, losses (train and validation), versions
    no_event.pt         state_dict of the system's no-event network (2 x 256)
    event.pt            state_dict of the event network (2 x 4096)
    standard.pt         state_dict of the ablation's standard network (2 x 256)
    metadata.pt         ablation: event-sector network on event metadata, no text (2 x 4096)
    event_shuffled.pt   ablation: the event network trained on texts shuffled across events
    beta.npy            β: drop-off sector given pickup sector, (S, S), from the training months
    checkpoints/*.pt    per-epoch checkpoints (for resume; safe to delete once trained)
"""

from __future__ import annotations

import datetime as dt
import json
import os
import time
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from city.errors import ConfigError, DataError
from predictor.dataset import (
    Normaliser,
    YearData,
    build_year_data,
    describe_split,
    event_training_set,
    standard_training_set,
)
from predictor.embed import Embedder
from predictor.features import (
    LAG_HOURS,
    LEAD_HOURS,
    N_TEMPORAL,
    WEATHER_NAMES,
    EventFeaturizer,
    MetadataFeaturizer,
    temporal_features,
    temporal_names,
    weather_at,
)
from predictor.nets import EVENT_HIDDEN, STANDARD_HIDDEN, DemandMLP, configure_threads
from predictor.spectral import GAMMA, N_CLUSTERS, Q_MAX
from predictor.train import TrainConfig, fit, predict, resolve_device, versions

SCHEMA = "surge.predictor.model/2"
NETWORKS = ("standard", "no_event", "event", "metadata", "event_shuffled")
#: Event-sector networks and the inputs they get besides the base features (predictor.dataset.event_inputs).
EVENT_NETWORKS = {"event": "text", "metadata": "metadata", "event_shuffled": "shuffled_text"}


class DemandModel:
    """The paper's two networks, the ablation's standard network, and their normalisation.

    The system predicts with ``event`` where a sector has an active event and
    with ``no_event`` elsewhere; both temporal/weather networks have the same
    shape, but ``no_event`` is fitted only on sector-hours without events,
    ``standard`` on all of them (it is the ablation's baseline, the best a
    network without event knowledge can do).
    """

    def __init__(self, meta: dict, norm: Normaliser, standard: DemandMLP, no_event: DemandMLP, event: DemandMLP | None, beta: np.ndarray | None = None, directory: Path | None = None, ablation: dict[str, DemandMLP] | None = None) -> None:
        self.meta = meta
        self.norm = norm
        self.standard = standard
        self.no_event = no_event
        self.event = event
        #: the ablation's extra event-sector networks (``metadata``, ``event_shuffled``) where trained
        self.ablation = dict(ablation or {})
        self.beta = beta
        self.directory = directory
        self.n_sectors = int(meta["n_sectors"])

    # ------------------------------------------------------------ prediction
    def base_features(self, temporal: np.ndarray, weather: np.ndarray, sectors: np.ndarray) -> np.ndarray:
        return self.norm.base(temporal, weather, np.asarray(sectors, np.int64), self.n_sectors)

    def predict_standard(self, temporal: np.ndarray, weather: np.ndarray, sectors: np.ndarray) -> np.ndarray:
        return self.norm.counts(predict(self.standard, self.base_features(temporal, weather, sectors)))

    def predict_no_event(self, temporal: np.ndarray, weather: np.ndarray, sectors: np.ndarray) -> np.ndarray:
        return self.norm.counts(predict(self.no_event, self.base_features(temporal, weather, sectors)))

    def predict_event(self, temporal: np.ndarray, weather: np.ndarray, sectors: np.ndarray, F: np.ndarray) -> np.ndarray:
        if self.event is None:
            return self.predict_no_event(temporal, weather, sectors)
        X = np.hstack([self.base_features(temporal, weather, sectors), self.norm.event(F)])
        return self.norm.counts(predict(self.event, X))

    def network(self, name: str) -> DemandMLP | None:
        return {"standard": self.standard, "no_event": self.no_event, "event": self.event, **self.ablation}.get(name)

    def predict_inputs(self, name: str, X: np.ndarray) -> np.ndarray:
        """ŷ (counts) of network ``name`` on prepared, normalised inputs ``X``."""
        net = self.network(name)
        if net is None:
            raise ConfigError(f"the model has no {name!r} network (train it with `surge predictor train`)")
        return self.norm.counts(predict(net, X, batch=int(self.meta.get("training", {}).get("eval_batch", 8192))))

    def predict_hour(self, when: dt.datetime, weather, F: np.ndarray, has_event: np.ndarray,
                     holidays: frozenset[dt.date] | None = None) -> np.ndarray:
        """ŷ for every sector in the hour beginning ``when`` (event network where ``has_event``, else no-event)."""
        S = self.n_sectors
        tf = np.repeat(temporal_features(when, holidays)[None, :], S, axis=0)
        wf = np.repeat(weather_at(weather, when)[None, :], S, axis=0)
        sectors = np.arange(S)
        y = self.predict_no_event(tf, wf, sectors)
        if has_event.any() and self.event is not None:
            sel = np.flatnonzero(has_event)
            y[sel] = self.predict_event(tf[sel], wf[sel], sectors[sel], F[sel])
        return y

    # ------------------------------------------------------------------ I/O
    def save(self, directory: Path) -> None:
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        for name in NETWORKS:
            net = self.network(name)
            if net is not None:
                _atomic_torch(net.state_dict(), directory / f"{name}.pt")
        if self.beta is not None:
            tmp = directory / f"beta.{os.getpid()}.tmp.npy"
            np.save(tmp, self.beta)
            os.replace(tmp, directory / "beta.npy")
        meta = dict(self.meta)
        meta["normalisation"] = self.norm.to_json()
        tmp = directory / f"model.json.{os.getpid()}.tmp"
        tmp.write_text(json.dumps(meta, indent=1))
        os.replace(tmp, directory / "model.json")

    @classmethod
    def load(cls, directory: str | Path) -> "DemandModel":
        directory = Path(directory)
        meta_path = directory / "model.json"
        if not meta_path.exists():
            raise ConfigError(f"{directory}: not a trained predictor (no model.json); run `surge predictor train` first")
        try:
            meta = json.loads(meta_path.read_text())
        except json.JSONDecodeError as exc:
            raise DataError(f"not valid JSON ({exc})", path=meta_path) from exc
        if meta.get("schema") != SCHEMA:
            raise DataError(f"schema {meta.get('schema')!r}, expected {SCHEMA!r}", path=meta_path)
        configure_threads()
        norm = Normaliser.from_json(meta["normalisation"])
        nets = meta["networks"]
        loaded = {name: _load_net(directory, name, nets[name]) for name in NETWORKS if name in nets and (directory / f"{name}.pt").exists()}
        for name in ("standard", "no_event"):
            if name not in loaded:
                raise DataError(f"network file {name}.pt is missing", path=directory)
        beta = np.load(directory / "beta.npy") if (directory / "beta.npy").exists() else None
        ablation = {k: loaded[k] for k in ("metadata", "event_shuffled") if k in loaded}
        return cls(meta, norm, loaded["standard"], loaded["no_event"], loaded.get("event"), beta, directory, ablation)

    @property
    def window(self) -> tuple[int, int]:
        f = self.meta["features"]
        return int(f.get("lead_hours", 0)), int(f.get("lag_hours", 0))

    def featurizer(self, cache_dir: str | None = None, verbose: bool = False) -> EventFeaturizer:
        f = self.meta["features"]
        # Texts are embedded on the kind of device the model was trained on where this machine has it, so a
        # GPU-trained model reads the vectors its training wrote; elsewhere on the CPU.
        trained_on = torch.device(self.meta.get("training", {}).get("device_used", "cpu")).type
        device = resolve_device("auto").type if trained_on == "cuda" else "cpu"
        emb = Embedder(self.meta["encoder"]["name"], cache_dir or self.meta.get("cache_dir"), device=device, verbose=verbose)
        if emb.model_key != self.meta["encoder"]["model_key"]:
            raise ConfigError(
                f"encoder {self.meta['encoder']['name']!r} resolves to {emb.model_key}, but the model was trained with {self.meta['encoder']['model_key']}"
            )
        return EventFeaturizer(emb, n_clusters=f["n_clusters"], gamma=f["gamma"], q_max=f["q_max"], seed=f["cluster_seed"], verbose=verbose)


def _load_net(directory: Path, name: str, spec: dict) -> DemandMLP:
    net = DemandMLP(int(spec["n_in"]), tuple(spec["hidden"]))
    net.load_state_dict(torch.load(directory / f"{name}.pt", map_location="cpu", weights_only=True))
    net.eval()
    return net


def _atomic_torch(obj, path: Path) -> None:
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def train_model(
    world,
    out: str | Path,
    *,
    cfg: TrainConfig | None = None,
    encoder: str | None = None,
    cache_dir: str | None = None,
    scenario: dict | None = None,
    standard_hidden: tuple[int, ...] = STANDARD_HIDDEN,
    event_hidden: tuple[int, ...] = EVENT_HIDDEN,
    n_clusters: int = N_CLUSTERS,
    gamma: float = GAMMA,
    q_max: int = Q_MAX,
    event_epochs: int | None = None,
    beta_days: int = 28,
    lead_hours: int = LEAD_HOURS,
    lag_hours: int = LAG_HOURS,
    ablation: bool = True,
    trips=None,
    inputs: dict | None = None,
    log: Callable[[str], None] | None = print,
    data: YearData | None = None,
) -> DemandModel:
    """Build features from ``world``, train the networks, save everything to ``out``.

    Every network trains on January–June and stops early on July–August
    (:class:`TrainConfig`).  With ``ablation`` the metadata network and the
    shuffled-text event network are trained too (same samples, width and
    settings as the event network).  β comes from the training months of
    ``trips`` when given, else of the world's requests.
    """
    from predictor.assign import estimate_beta

    cfg = cfg or TrainConfig()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    configure_threads()
    torch.manual_seed(cfg.seed)
    np.random.seed(cfg.seed)
    t_start = time.perf_counter()
    device = resolve_device(cfg.device)
    embedder = Embedder(encoder, cache_dir, verbose=log is not None, device=str(device))
    featurizer = EventFeaturizer(embedder, n_clusters=n_clusters, gamma=gamma, q_max=q_max, seed=0, verbose=log is not None)
    if data is None:
        data = build_year_data(world, featurizer, lead=lead_hours, lag=lag_hours, verbose=log is not None)
    norm = Normaliser.fit(data)

    Xs, ys = standard_training_set(data, norm)
    Xsv, ysv = standard_training_set(data, norm, part="val")
    Xq, yq = standard_training_set(data, norm, without_events=True)
    Xqv, yqv = standard_training_set(data, norm, without_events=True, part="val")
    if log:
        log(
            f"training (Jan–Jun {data.year}, validation Jul–Aug): standard network on {len(ys)} sector-hours ({len(ysv)} validation), "
            f"no-event network on the {len(yq)} without events ({len(yqv)}), event-sector networks on the "
            f"{len(data.event_rows('train'))} with events ({len(data.event_rows('val'))})"
        )
    ck = out / "checkpoints"
    results, seconds, shapes = {}, {}, {}
    t0 = time.perf_counter()
    results["standard"] = fit("standard", Xs, ys, standard_hidden, cfg, X_val=Xsv, y_val=ysv, checkpoint=ck / "standard.pt", log=log)
    seconds["standard"] = time.perf_counter() - t0
    shapes["standard"] = (Xs.shape[1], len(ys), standard_hidden)
    t0 = time.perf_counter()
    results["no_event"] = fit("no_event", Xq, yq, standard_hidden, cfg, X_val=Xqv, y_val=yqv, checkpoint=ck / "no_event.pt", log=log)
    seconds["no_event"] = time.perf_counter() - t0
    shapes["no_event"] = (Xq.shape[1], len(yq), standard_hidden)
    del Xs, ys, Xsv, ysv, Xq, yq, Xqv, yqv
    ecfg = cfg if event_epochs is None else TrainConfig(**{**cfg.to_json(), "epochs": event_epochs})
    names = list(EVENT_NETWORKS) if ablation else ["event"]
    for name in names:
        Xe, ye = event_training_set(data, norm, inputs=EVENT_NETWORKS[name])
        Xev, yev = event_training_set(data, norm, inputs=EVENT_NETWORKS[name], part="val")
        t0 = time.perf_counter()
        results[name] = fit(name, Xe, ye, event_hidden, ecfg, X_val=Xev, y_val=yev, checkpoint=ck / f"{name}.pt", log=log)
        seconds[name] = time.perf_counter() - t0
        shapes[name] = (Xe.shape[1], len(ye), event_hidden)

    t0 = time.perf_counter()
    beta, beta_info = estimate_beta(world, days=beta_days, seed=cfg.seed, trips=trips)
    t_beta = time.perf_counter() - t0
    meta_feats = MetadataFeaturizer.from_world(world)

    meta = {
        "schema": SCHEMA,
        "created": dt.datetime.now().isoformat(timespec="seconds"),
        "scenario": scenario or {},
        "inputs": inputs or {},
        "year": data.year,
        "n_sectors": data.n_sectors,
        "sector_names": list(getattr(world.city, "sector_names", [])),
        "split": describe_split(data.year),
        "encoder": {"name": embedder.encoder, "model_key": embedder.model_key, "dim": int(featurizer.d)},
        "cache_dir": str(cache_dir) if cache_dir else None,
        "features": {
            "temporal": temporal_names(),
            "n_temporal": N_TEMPORAL,
            "weather": list(WEATHER_NAMES),
            "sector_onehot": data.n_sectors,
            "n_base": int(shapes["standard"][0]),
            "event_feature": "[mean title+description embedding, mean stacked review-cluster means] over active events",
            "n_event_feature": int(featurizer.size),
            "metadata_feature": meta_feats.names,
            "shuffled_text": "each event's text (z, R) replaced by that of another event, by a fixed permutation (seed 0)",
            "n_clusters": n_clusters,
            "gamma": gamma,
            "q_max": q_max,
            "cluster_seed": 0,
            "lead_hours": lead_hours,
            "lag_hours": lag_hours,
            "event_window": "an event counts for its venue's sector in every hour overlapping [start - lead_hours, end + lag_hours)",
            "clustering": "SpectralClustering(affinity='rbf', gamma, assign_labels='cluster_qr'); clusters ordered by size, then first member",
        },
        "networks": {
            name: {"n_in": int(shapes[name][0]), "hidden": list(shapes[name][2]), "n_train": int(shapes[name][1]), "epochs": len(r.losses), **r.to_json(), "seconds": round(seconds[name], 1)}
            for name, r in results.items()
        },
        "training": {**cfg.to_json(), "event_epochs": ecfg.epochs, "loss": "MSE", "optimizer": "Adam (fused)", "threads": torch.get_num_threads(), "device_used": str(device),
                     "early_stopping": "keep the epoch with the lowest validation MSE (July-August); stop `patience` epochs after it; `epochs` is the cap"},
        "beta": beta_info,
        "timings": {**{("features_s" if k == "total_s" else k): v for k, v in data.timings.items()}, **{f"train_{k}_s": round(v, 1) for k, v in seconds.items()}, "beta_s": round(t_beta, 1), "total_s": round(time.perf_counter() - t_start, 1)},
        "versions": versions(),
    }
    has_event = shapes["event"][1] > 0
    ablation_nets = {k: results[k].net for k in ("metadata", "event_shuffled") if k in results and shapes[k][1] > 0}
    model = DemandModel(meta, norm, results["standard"].net, results["no_event"].net, results["event"].net if has_event else None, beta, out, ablation_nets)
    model.save(out)
    if log:
        log(f"saved model to {out} ({meta['timings']['total_s']:.0f}s in all)")
    return model

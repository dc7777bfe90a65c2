"""A trained demand model on disk, and the end-to-end training run (torch).

Model directory layout::

    model.json          schema, scenario, features, normalisation, settings, losses, versions
    no_event.pt         state_dict of the system's no-event network (2 x 256)
    event.pt            state_dict of the event network (2 x 4096)
    standard.pt         state_dict of the ablation's standard network (2 x 256)
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
from predictor.cluster import GAMMA, N_CLUSTERS, Q_MAX
from predictor.dataset import (
    TRAIN_MONTHS,
    Normaliser,
    YearData,
    build_year_data,
    event_training_set,
    standard_training_set,
)
from predictor.embed import Embedder
from predictor.features import LAG_HOURS, LEAD_HOURS, EventFeaturizer, N_TEMPORAL, WEATHER_NAMES, temporal_features, temporal_names, weather_at
from predictor.nets import EVENT_HIDDEN, STANDARD_HIDDEN, DemandMLP, configure_threads
from predictor.train import TrainConfig, fit, predict, versions

SCHEMA = "surge.predictor.model/2"
NETWORKS = ("standard", "no_event", "event")


class DemandModel:
    """The paper's two networks, the ablation's standard network, and their normalisation.

    The system predicts with ``event`` where a sector has an active event and
    with ``no_event`` elsewhere; both temporal/weather networks have the same
    shape, but ``no_event`` is fitted only on sector-hours without events,
    ``standard`` on all of them (it is the ablation's baseline, the best a
    network without event knowledge can do).
    """

    def __init__(self, meta: dict, norm: Normaliser, standard: DemandMLP, no_event: DemandMLP, event: DemandMLP | None, beta: np.ndarray | None = None, directory: Path | None = None) -> None:
        self.meta = meta
        self.norm = norm
        self.standard = standard
        self.no_event = no_event
        self.event = event
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

    def predict_hour(self, when: dt.datetime, weather, F: np.ndarray, has_event: np.ndarray) -> np.ndarray:
        """ŷ for every sector in the hour beginning ``when`` (event network where ``has_event``, else no-event)."""
        S = self.n_sectors
        tf = np.repeat(temporal_features(when)[None, :], S, axis=0)
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
        _atomic_torch(self.standard.state_dict(), directory / "standard.pt")
        _atomic_torch(self.no_event.state_dict(), directory / "no_event.pt")
        if self.event is not None:
            _atomic_torch(self.event.state_dict(), directory / "event.pt")
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
        loaded = {name: _load_net(directory, name, nets[name]) for name in NETWORKS if (directory / f"{name}.pt").exists()}
        for name in ("standard", "no_event"):
            if name not in loaded:
                raise DataError(f"network file {name}.pt is missing", path=directory)
        beta = np.load(directory / "beta.npy") if (directory / "beta.npy").exists() else None
        return cls(meta, norm, loaded["standard"], loaded["no_event"], loaded.get("event"), beta, directory)

    @property
    def window(self) -> tuple[int, int]:
        f = self.meta["features"]
        return int(f.get("lead_hours", 0)), int(f.get("lag_hours", 0))

    def featurizer(self, cache_dir: str | None = None, verbose: bool = False) -> EventFeaturizer:
        f = self.meta["features"]
        emb = Embedder(self.meta["encoder"]["name"], cache_dir or self.meta.get("cache_dir"), verbose=verbose)
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
    log: Callable[[str], None] | None = print,
    data: YearData | None = None,
) -> DemandModel:
    """Build features from ``world``, train the three networks, save everything to ``out``."""
    from predictor.assign import estimate_beta

    cfg = cfg or TrainConfig()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    configure_threads()
    torch.manual_seed(cfg.seed)
    np.random.seed(cfg.seed)
    t_start = time.perf_counter()
    embedder = Embedder(encoder, cache_dir, verbose=log is not None)
    featurizer = EventFeaturizer(embedder, n_clusters=n_clusters, gamma=gamma, q_max=q_max, seed=0, verbose=log is not None)
    if data is None:
        data = build_year_data(world, featurizer, lead=lead_hours, lag=lag_hours, verbose=log is not None)
    norm = Normaliser.fit(data)

    Xs, ys = standard_training_set(data, norm)
    Xq, yq = standard_training_set(data, norm, without_events=True)
    Xe, ye = event_training_set(data, norm)
    if log:
        log(
            f"training (Jan–Aug {data.year}): standard network on {len(ys)} sector-hours, "
            f"no-event network on the {len(yq)} without events, event network on the {len(ye)} with events"
        )
    ck = out / "checkpoints"
    t0 = time.perf_counter()
    rs = fit("standard", Xs, ys, standard_hidden, cfg, checkpoint=ck / "standard.pt", log=log)
    t_std = time.perf_counter() - t0
    t0 = time.perf_counter()
    rq = fit("no_event", Xq, yq, standard_hidden, cfg, checkpoint=ck / "no_event.pt", log=log)
    t_quiet = time.perf_counter() - t0
    ecfg = cfg if event_epochs is None else TrainConfig(**{**cfg.to_json(), "epochs": event_epochs})
    t0 = time.perf_counter()
    re_ = fit("event", Xe, ye, event_hidden, ecfg, checkpoint=ck / "event.pt", log=log)
    t_ev = time.perf_counter() - t0

    t0 = time.perf_counter()
    beta, beta_info = estimate_beta(world, days=beta_days, seed=cfg.seed)
    t_beta = time.perf_counter() - t0

    meta = {
        "schema": SCHEMA,
        "created": dt.datetime.now().isoformat(timespec="seconds"),
        "scenario": scenario or {},
        "year": data.year,
        "n_sectors": data.n_sectors,
        "sector_names": list(getattr(world.city, "sector_names", [])),
        "split": {"train_months": TRAIN_MONTHS, "split_hour": data.split_hour, "test": "September-December"},
        "encoder": {"name": embedder.encoder, "model_key": embedder.model_key, "dim": int(featurizer.d)},
        "cache_dir": str(cache_dir) if cache_dir else None,
        "features": {
            "temporal": temporal_names(),
            "n_temporal": N_TEMPORAL,
            "weather": list(WEATHER_NAMES),
            "sector_onehot": data.n_sectors,
            "n_base": int(Xs.shape[1]),
            "event_feature": "[mean title+description embedding, mean stacked review-cluster means] over active events",
            "n_event_feature": int(featurizer.size),
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
            "standard": {"n_in": int(Xs.shape[1]), "hidden": list(standard_hidden), "n_train": int(len(ys)), "epochs": len(rs.losses), "losses": rs.losses, "seconds": round(t_std, 1)},
            "no_event": {"n_in": int(Xq.shape[1]), "hidden": list(standard_hidden), "n_train": int(len(yq)), "epochs": len(rq.losses), "losses": rq.losses, "seconds": round(t_quiet, 1)},
            "event": {"n_in": int(Xe.shape[1]), "hidden": list(event_hidden), "n_train": int(len(ye)), "epochs": len(re_.losses), "losses": re_.losses, "seconds": round(t_ev, 1)},
        },
        "training": {**cfg.to_json(), "event_epochs": ecfg.epochs, "loss": "MSE", "optimizer": "Adam", "threads": torch.get_num_threads()},
        "beta": beta_info,
        "timings": {**data.timings, "train_standard_s": round(t_std, 1), "train_no_event_s": round(t_quiet, 1), "train_event_s": round(t_ev, 1), "beta_s": round(t_beta, 1), "total_s": round(time.perf_counter() - t_start, 1)},
        "versions": versions(),
    }
    model = DemandModel(meta, norm, rs.net, rq.net, re_.net if len(ye) else None, beta, out)
    model.save(out)
    if log:
        log(f"saved model to {out} ({meta['timings']['total_s']:.0f}s in all)")
    return model

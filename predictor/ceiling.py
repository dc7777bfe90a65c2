"""How much can the event text tell?  The ceiling of what text could add, and a simpler reader of it (torch).

The synthetic world writes each event's text from the drivers of its
attendance that are known before the event (:mod:`city.demand.attendance`):
the event's capacity, its popularity (ticket sales, announced as "Sold-Out",
"Limited Engagement" … tiers), the sentiment of its reviews, and an
"Opening Night/Day" or "Final Week/Day" cue.  Realised attendance is
``capacity × fill_rate(popularity, sentiment)`` times a rain loss and a random
draw no text carries.  The world records those drivers
(``SyntheticWorld.event_specs``); here they become structured features.

Three event-sector networks are set against the metadata network (base
features + event count, categories and venue capacities, no text), all of
the metadata network's width and training settings, on the same samples:

* ``ceiling``: metadata + the announced drivers read from the world's records
  (:data:`FEATURES`, aggregated over a sector-hour's active events).  No text
  pipeline can give more than this: it is what a perfect reader of the text
  would know.
* ``reader``: metadata + the same features with every event's drivers
  *estimated from its text* by a ridge regression on the event's text vector
  (title/description embedding and review-cluster means, the event network's
  own inputs).  The ridge trains on the training months' events (out of fold
  for the samples the network trains on), its penalty is chosen on the
  validation months' events.
* the event network of ``surge predictor train`` (base + averaged text
  vectors, no metadata), as trained.

The share of the ceiling a row reaches is ``(PE_metadata − PE_row) /
(PE_metadata − PE_ceiling)`` on the test months' event sector-hours, 15–21 h,
with percentile intervals over resampled test days
(:func:`predictor.evaluate.bootstrap_weights`, the ablation's own).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from city.errors import ConfigError
from predictor.dataset import YearData, event_inputs
from predictor.evaluate import HOURS, bootstrap_weights, percentile_ci, pooled_metric, predictions
from predictor.features import events_by_hour_sector

#: Per-event drivers, as the world records them (``log`` columns are log1p).
DRIVERS = ("log_expected_attendance", "popularity", "sentiment", "log_capacity", "opening", "final")
#: Per sector-hour features built from the drivers of its active events.
FEATURES = ("log1p_expected_attendance_sum", "log1p_expected_attendance_max", "popularity_mean", "popularity_max",
            "sentiment_mean", "log1p_capacity_sum", "n_opening", "n_final")
#: Ridge penalties tried on the validation months' events.
ALPHAS = (1.0, 10.0, 100.0, 1e3, 1e4, 1e5)
FOLDS = 5
#: Rows of the table, in display order: key, label.
ROWS = (("metadata_nn", "Metadata NN (no text)"), ("ceiling_nn", "Metadata + announced drivers (ceiling)"),
        ("event_nn", "Event NN (text, as trained)"), ("reader_nn", "Metadata + drivers read from text (ridge)"),
        ("shuffled_text_nn", "Event NN, shuffled text"), ("true_rate", "True rate λ (the world's own)"))


def event_drivers(world, events) -> np.ndarray:
    """``(N, len(DRIVERS))`` drivers of ``events`` from the world's records; refused where it keeps none."""
    from city.demand.attendance import fill_rate

    specs = getattr(world, "event_specs", None)
    if not specs:
        raise ConfigError("the text ceiling needs a world that records its events' attendance drivers (the synthetic world "
                          "does; a world with --events or recorded demand does not)")
    out = np.zeros((len(events), len(DRIVERS)))
    for i, ev in enumerate(events):
        s = specs.get(ev.event_id)
        if s is None:
            raise ConfigError(f"event {ev.event_id} has no record of its attendance drivers in the world")
        expected = float(s.capacity * fill_rate(s.popularity, s.sentiment))
        cue = (s.cue or "").lower()
        out[i] = (np.log1p(expected), s.popularity, s.sentiment, np.log1p(s.capacity), cue.startswith("opening"), cue.startswith("final"))
    return out


def aggregate(rows: np.ndarray) -> np.ndarray:
    """A sector-hour's :data:`FEATURES` from the driver rows of its active events (zeros without events)."""
    out = np.zeros(len(FEATURES), dtype=np.float32)
    if len(rows) == 0:
        return out
    att = np.expm1(np.clip(rows[:, 0], 0.0, None))
    out[:] = (np.log1p(att.sum()), np.log1p(att.max()), rows[:, 1].mean(), rows[:, 1].max(), rows[:, 2].mean(),
              np.log1p(np.expm1(np.clip(rows[:, 3], 0.0, None)).sum()), rows[:, 4].sum(), rows[:, 5].sum())
    return out


def sector_features(hours: np.ndarray, sectors: np.ndarray, groups: dict[tuple[int, int], list], drivers: dict[str, np.ndarray]) -> np.ndarray:
    """``(len(hours), len(FEATURES))``: :func:`aggregate` for each sector-hour, from per-event ``drivers`` by event id."""
    out = np.zeros((len(hours), len(FEATURES)), dtype=np.float32)
    for i, (h, s) in enumerate(zip(np.asarray(hours).tolist(), np.asarray(sectors).tolist())):
        out[i] = aggregate(np.array([drivers[ev.event_id] for ev in groups.get((h, s), [])]).reshape(-1, len(DRIVERS)))
    return out


# ------------------------------------------------------------------ the reader
@dataclass
class TextReader:
    """Ridge regression from an event's text vector to its standardised drivers."""

    x_mean: np.ndarray
    x_std: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray
    coef: np.ndarray  # (p, k)
    alpha: float

    @classmethod
    def fit(cls, X: np.ndarray, Y: np.ndarray, alpha: float) -> "TextReader":
        xm, xs = X.mean(axis=0), np.maximum(X.std(axis=0), 1e-6)
        ym, ys = Y.mean(axis=0), np.maximum(Y.std(axis=0), 1e-6)
        Z, T = (X - xm) / xs, (Y - ym) / ys
        coef = np.linalg.solve(Z.T @ Z + alpha * np.eye(Z.shape[1]), Z.T @ T)
        return cls(xm, xs, ym, ys, coef, float(alpha))

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Drivers of each row, kept in their ranges (log sizes ≥ 0; shares and cues in [0, 1])."""
        Y = ((np.asarray(X, np.float64) - self.x_mean) / self.x_std) @ self.coef * self.y_std + self.y_mean
        Y[:, [0, 3]] = np.clip(Y[:, [0, 3]], 0.0, None)
        Y[:, [1, 2, 4, 5]] = np.clip(Y[:, [1, 2, 4, 5]], 0.0, 1.0)
        return Y


def r2(Y: np.ndarray, P: np.ndarray) -> np.ndarray:
    """R² of each column."""
    ss = ((Y - Y.mean(axis=0)) ** 2).sum(axis=0)
    return 1.0 - ((Y - P) ** 2).sum(axis=0) / np.maximum(ss, 1e-12)


def choose_alpha(X: np.ndarray, Y: np.ndarray, X_val: np.ndarray, Y_val: np.ndarray, alphas=ALPHAS) -> tuple[float, dict[str, float]]:
    """The penalty with the highest mean R² over the drivers on the validation events, and every penalty's."""
    scores = {f"{a:g}": float(np.mean(r2(Y_val, TextReader.fit(X, Y, a).predict(X_val)))) for a in alphas}
    best = max(alphas, key=lambda a: scores[f"{a:g}"])
    return float(best), scores


def out_of_fold(X: np.ndarray, Y: np.ndarray, alpha: float, folds: int = FOLDS, seed: int = 0) -> np.ndarray:
    """Each row's prediction by a reader fitted without its fold, so the network never trains on in-sample readings."""
    fold = np.random.default_rng([seed, 48]).permutation(len(X)) % folds
    out = np.zeros_like(Y, dtype=np.float64)
    for k in range(folds):
        out[fold == k] = TextReader.fit(X[fold != k], Y[fold != k], alpha).predict(X[fold == k])
    return out


def text_vectors(featurizer, events) -> np.ndarray:
    """``(N, (b+1)·d)``: each event's title/description embedding and review-cluster means, as the event network reads them."""
    return np.stack([np.concatenate([v.z, v.R.ravel()]) for v in (featurizer.vectors(ev) for ev in events)]).astype(np.float64)


def read_drivers(data: YearData, events, X: np.ndarray, Y: np.ndarray, seed: int = 0) -> tuple[np.ndarray, dict]:
    """Each event's drivers estimated from its text; and the reader's penalty and R² per part.

    Events starting in the training months get out-of-fold estimates, the
    others those of a reader fitted on all training events.
    """
    origin = np.datetime64(f"{data.year}-01-01T00")
    hour = np.array([(np.datetime64(ev.start, "h") - origin).astype(np.int64) for ev in events])
    part = np.where(hour < data.val_hour, 0, np.where(hour < data.split_hour, 1, 2))
    tr, va, te = (part == k for k in range(3))
    if tr.sum() < 2 * FOLDS or not va.any():
        raise ConfigError(f"the text reader needs events in the training and validation months (found {int(tr.sum())} and {int(va.sum())})")
    alpha, scores = choose_alpha(X[tr], Y[tr], X[va], Y[va])
    reader = TextReader.fit(X[tr], Y[tr], alpha)
    P = reader.predict(X)
    P[tr] = out_of_fold(X[tr], Y[tr], alpha, seed=seed)
    info = {"alpha": alpha, "alpha_chosen_on": "validation events (July-August): highest mean R2 over the drivers",
            "validation_mean_r2_by_alpha": scores, "events": {"train": int(tr.sum()), "validation": int(va.sum()), "test": int(te.sum())},
            "r2": {name: {d: round(float(v), 4) for d, v in zip(DRIVERS, r2(Y[sel], P[sel]))} for name, sel in
                   (("train_out_of_fold", tr), ("validation", va), ("test", te)) if sel.any()}}
    return P, info


# ------------------------------------------------------------------ training and scoring
def train_extra(name: str, model, data: YearData, extra: np.ndarray, checkpoint: Path | None, log: Callable[[str], None] | None,
                seed: int | None = None):
    """An event-sector network on base + metadata + ``extra`` (z-scored on training samples), as the metadata network was trained.

    ``seed`` overrides the model's training seed; with no ``extra`` columns it trains a metadata network.
    """
    from predictor.train import TrainConfig, fit

    meta_net = model.meta["networks"]["metadata"]
    tr = model.meta["training"]
    cfg = TrainConfig(epochs=int(tr.get("event_epochs") or tr["epochs"]), lr=tr["lr"], weight_decay=tr["weight_decay"],
                      batch_size=tr["batch_size"], seed=tr["seed"] if seed is None else seed, patience=tr["patience"], device="cpu", eval_batch=tr.get("eval_batch", 8192))
    rows = {p: data.event_rows(p) for p in ("train", "val", "test")}
    mu = extra[rows["train"]].mean(axis=0)
    sd = np.maximum(extra[rows["train"]].std(axis=0), 1e-3)

    def inputs(r: np.ndarray) -> np.ndarray:
        return np.hstack([event_inputs(data, model.norm, r, "metadata"), ((extra[r] - mu) / sd).astype(np.float32)])

    def target(r: np.ndarray) -> np.ndarray:
        return model.norm.target(data.counts[data.ev_hour[r], data.ev_sector[r]])

    res = fit(name, inputs(rows["train"]), target(rows["train"]), tuple(meta_net["hidden"]), cfg,
              X_val=inputs(rows["val"]), y_val=target(rows["val"]), checkpoint=checkpoint, log=log)
    return res, inputs


def _paired(boot: dict[str, np.ndarray], point: dict[str, float], ref: str = "metadata_nn", top: str = "ceiling_nn") -> dict:
    """PE with CI per row; each row minus the metadata row; each row's share of the ceiling's gain."""
    gain = point[ref] - point[top]
    gain_b = boot[ref] - boot[top]
    out = {}
    for k in boot:
        d = boot[k] - boot[ref]
        row = {"pe": point[k], "ci": percentile_ci(boot[k]), "minus_metadata": point[k] - point[ref], "minus_metadata_ci": percentile_ci(d),
               "share_of_resamples_below_metadata": float(np.mean(d < 0))}
        row["share_of_ceiling"] = row["share_of_ceiling_ci"] = None  # by definition 0 and 1 for the two ends
        if k not in (ref, top):
            with np.errstate(invalid="ignore", divide="ignore"):
                row["share_of_ceiling"] = float((point[ref] - point[k]) / gain) if gain != 0 else None
                row["share_of_ceiling_ci"] = percentile_ci((boot[ref] - boot[k]) / gain_b)
        out[k] = row
    return out


def score(data: YearData, preds: dict[str, np.ndarray], part: str = "test", hours=HOURS, n_boot: int = 1000, seed: int = 0) -> dict:
    """PE on the event sector-hours of ``hours`` pooled and per hour, paired against the metadata network over resampled days.

    ``rows``: against the realised counts (the ablation's PE).  ``rows_vs_rate``
    (where the world has λ): |λ − ŷ| / λ, the same error against the world's
    expected rate, which takes out the Poisson draw no forecast can know, so
    what the drivers add is not hidden under the counts' noise.
    """
    r, S = data.hours(part), data.n_sectors
    D = (r.stop - r.start) // 24
    has = data.has_event()[r.start : r.stop].reshape(D, 24, S)
    W = bootstrap_weights(D, n_boot, seed)
    targets = {"rows": data.counts}
    if data.expected is not None:
        targets["rows_vs_rate"] = data.expected
    P = {k: preds[k].reshape(D, 24, S) for k, _ in ROWS if k in preds}

    def block(hrs: list[int]) -> dict:
        out: dict = {}
        for key, target in targets.items():
            yy = np.asarray(target[r.start : r.stop], np.float64).reshape(D, 24, S)[:, hrs]
            ok = (yy > 0) & has[:, hrs]
            safe = np.where(ok, yy, 1.0)
            cnt = ok.reshape(D, -1).astype(np.float64)
            point, boot = {}, {}
            for k, p in P.items():
                if key == "rows_vs_rate" and k == "true_rate":
                    continue
                err = np.where(ok, np.abs(yy - p[:, hrs]) / safe, 0.0).reshape(D, -1)
                point[k] = float(pooled_metric(err, cnt, None)[0])
                boot[k] = pooled_metric(err, cnt, W)
            out["n" if key == "rows" else "n_vs_rate"] = int(ok.sum())
            out[key] = _paired(boot, point)
        return out

    return {"pooled": {"hours": f"{hours[0]}-{hours[-1]}", **block(list(hours))}, "by_hour": {str(h): block([h]) for h in hours},
            "days": int(D), "intervals": f"95% percentile bootstrap over the {D} {part} days ({n_boot} resamples, seed {seed}); "
                                          "a day keeps all its sectors and hours; differences and shares on the same resamples"}


def measure(model, world, data: YearData, featurizer, *, n_boot: int = 1000, seed: int = 0, train_seed: int | None = None,
            log: Callable[[str], None] | None = print) -> dict:
    """Train the ceiling and reader networks beside ``model``'s and score them all on the test months; see the module notes.

    ``train_seed`` (default: the model's) seeds their training; another seed than the model's also retrains the
    metadata network with it, so that the rows each is measured against are one seed's.  The event network stays
    the model's.  Run with several seeds, the rows' spread is the training noise the differences must clear.
    """
    from predictor.train import predict

    if "metadata" not in model.meta.get("networks", {}) or model.network("metadata") is None or model.event is None:
        raise ConfigError("the model has no metadata or event network: train it without --no-ablation")
    lead, lag = model.window
    groups = events_by_hour_sector(world.events, data.year, data.n_hours, data.n_sectors, lead, lag)
    events = list(world.events)
    Y = event_drivers(world, events)
    X = text_vectors(featurizer, events)
    P, reader_info = read_drivers(data, events, X, Y, seed=seed)
    true = {ev.event_id: Y[i] for i, ev in enumerate(events)}
    read = {ev.event_id: P[i] for i, ev in enumerate(events)}
    ck = Path(model.directory) / "checkpoints" if model.directory is not None else None
    preds = predictions(model, data, "test")
    r = data.hours("test")
    rows = data.event_rows("test")
    own_seed = int(model.meta["training"]["seed"])
    train_seed = own_seed if train_seed is None else int(train_seed)
    tag = "" if train_seed == own_seed else f"-seed{train_seed}"
    trained = [("ceiling", sector_features(data.ev_hour, data.ev_sector, groups, true)),
               ("reader", sector_features(data.ev_hour, data.ev_sector, groups, read))]
    if tag:
        trained.insert(0, ("metadata", np.zeros((data.ev_hour.size, 0), np.float32)))
    nets = {"metadata": {k: model.meta["networks"]["metadata"][k] for k in ("hidden", "n_in", "epochs_run", "best_epoch")}}
    base = preds["metadata_nn"]
    for name, extra in trained:
        res, inputs = train_extra(f"text_{name}", model, data, extra, ck / f"text_{name}{tag}.pt" if ck is not None else None, log,
                                  seed=train_seed)
        p = base.copy()
        p[data.ev_hour[rows] - r.start, data.ev_sector[rows]] = model.norm.counts(predict(res.net, inputs(rows)))
        preds[f"{name}_nn"] = p
        nets[name] = {"hidden": list(res.net.hidden), "n_in": int(res.net.n_in), "seed": train_seed,
                      **{k: v for k, v in res.to_json().items() if k not in ("losses", "val_losses")}}
    result = score(data, preds, n_boot=n_boot, seed=seed)
    result["networks"] = {"event": {k: model.meta["networks"]["event"][k] for k in ("hidden", "n_in", "epochs_run", "best_epoch")}, **nets}
    result["train_seed"] = train_seed
    result["reader"] = reader_info
    result["drivers"] = list(DRIVERS)
    result["features"] = list(FEATURES)
    pooled = result["pooled"]
    vs_rate = pooled.get("rows_vs_rate", {})
    result["rows"] = [{"key": k, "label": label, **pooled["rows"][k],
                       **{f"{f}_vs_rate": vs_rate.get(k, {}).get(f) for f in pooled["rows"][k]}} for k, label in ROWS if k in pooled["rows"]]
    return result


def format_table(result: dict) -> str:
    """The terminal tables: PE [CI], minus metadata [CI], share of the ceiling [CI], pooled over the event sector-hours."""
    out = []
    for title, suffix in (("PE against the realised counts", ""), ("error against the world's expected rate λ", "_vs_rate")):
        rows = [(r["label"], {f: r[f + suffix] for f in ("pe", "ci", "minus_metadata", "minus_metadata_ci", "share_of_ceiling", "share_of_ceiling_ci")})
                for r in result["rows"] if r.get("pe" + suffix) is not None]
        if not rows:
            continue
        out += [f"{title}, test months' event sector-hours, {result['pooled']['hours']} h (n = {result['pooled']['n']})",
                f"{'row':<44}{'PE [95% CI]':>24}{'minus metadata [95% CI]':>30}{'share of ceiling [95% CI]':>30}"]
        for label, r in rows:
            share = "" if r.get("share_of_ceiling") is None else f"{r['share_of_ceiling']:+.2f} [{r['share_of_ceiling_ci'][0]:+.2f},{r['share_of_ceiling_ci'][1]:+.2f}]"
            out.append(f"{label:<44}{r['pe']:>9.3f} [{r['ci'][0]:.3f},{r['ci'][1]:.3f}]"
                       f"{r['minus_metadata']:>+13.3f} [{r['minus_metadata_ci'][0]:+.3f},{r['minus_metadata_ci'][1]:+.3f}]{share:>30}")
        out.append("")
    rd = result["reader"]
    out.append(f"reader: ridge alpha {rd['alpha']:g}; R2 of the drivers read from text, test events: "
               + ", ".join(f"{k} {v:.2f}" for k, v in rd["r2"].get("test", {}).items()))
    out.append(result["intervals"])
    return "\n".join(out)

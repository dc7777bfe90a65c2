"""The demand-prediction ablation: percent error per hour, 15–21 h, with 95 % intervals.

For every day of the evaluated months (the test months, September–December,
unless asked for the validation months) and every sector, at each hour h of
the window, one prediction per row of the ablation:

* ``standard_nn``: a temporal/weather network fitted on all sector-hours, used
  everywhere (the paper's ablation baseline);
* ``metadata_nn``: where a sector has active events, a network on the base
  features plus the events' metadata (number, categories, venue capacities;
  no text), else the no-event network;
* ``shuffled_text_nn``: as the event system, but its event network was trained
  and is evaluated on texts shuffled across events (a fixed permutation):
  what the event network does with text that says nothing about its event;
* ``event_nn``: the paper's system: the event network (base features plus
  the text feature F_s) where the sector has active events, else the
  no-event network (temporal/weather, fitted on sector-hours without events);
* ``true_rate``: the noise floor, the world's own expected rate λ (the
  synthetic world knows it; a recorded world does not, and the row is absent).
  λ is the best forecast in squared error, not in PE: |y - ŷ|/y weighs
  low counts more, so a forecast biased below λ can score a lower PE, and
  a network may land under this "floor" at quiet hours;
* ``previous_hour``: the realised count of hour h-1 in the same sector
  (Garces et al. 2023).

The three event-sector systems differ only on sector-hours with an active
event, where they use networks of one width, trained on the same samples with
the same settings; so ``event_nn`` against ``metadata_nn`` is what the text adds
beyond what a listing's metadata says, and against ``shuffled_text_nn`` whether
the event network uses its text at all.

``PE_s = mean_X |y - ŷ| / y`` over the points X of sector s at hour h, then
averaged over sectors (``rows``); points with y = 0 are skipped and ``n``
counts the points used.  ``rows_event_sectors`` pools the sector-hours with an
active event (the mean over all such points, not per sector).

Intervals: 95 % percentile bootstrap over days (``n_boot`` resamples of the
evaluated days with replacement; a day keeps all its sectors and hours, so the
intervals respect the correlation within a day).  Paired differences against
``event_nn`` (``diff_<name>``: PE of ``event_nn`` minus PE of the other) use
the same resamples for both terms.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from predictor.dataset import YearData, event_inputs

SCHEMA = "surge.predictor.eval/1"
HOURS = tuple(range(15, 22))
#: Rows of the ablation in display order: key, label.
ROWS = (
    ("standard_nn", "Standard NN"),
    ("metadata_nn", "Metadata NN"),
    ("shuffled_text_nn", "Event NN, shuffled text"),
    ("event_nn", "Event NN (ours)"),
    ("true_rate", "True rate (noise floor)"),
    ("previous_hour", "Previous hour"),
)
#: The event-sector network behind each event-sector system.
_SYSTEMS = {"event_nn": "event", "metadata_nn": "metadata", "shuffled_text_nn": "event_shuffled"}
_INPUTS = {"event": "text", "metadata": "metadata", "event_shuffled": "shuffled_text"}


def percent_error(y: np.ndarray, yhat: np.ndarray, sector: np.ndarray, n_sectors: int) -> tuple[float, int]:
    """Mean over sectors of the per-sector mean |y-ŷ|/y (y = 0 skipped)."""
    ok = y > 0
    if not ok.any():
        return float("nan"), 0
    err = np.abs(y[ok] - yhat[ok]) / y[ok]
    s = sector[ok]
    tot = np.bincount(s, weights=err, minlength=n_sectors)
    cnt = np.bincount(s, minlength=n_sectors)
    per = tot[cnt > 0] / cnt[cnt > 0]
    return float(per.mean()), int(ok.sum())


def predictions(model, data: YearData, part: str = "test") -> dict[str, np.ndarray]:
    """ŷ for every hour of ``part`` and every sector, per row of the ablation: arrays ``(H_part, S)``."""
    r, S = data.hours(part), data.n_sectors
    H0, H = r.start, r.stop
    hours = np.repeat(np.arange(H0, H), S)
    sectors = np.tile(np.arange(S), H - H0)
    std = model.predict_standard(data.temporal[hours], data.weather[hours], sectors).reshape(H - H0, S)
    quiet = model.predict_no_event(data.temporal[hours], data.weather[hours], sectors).reshape(H - H0, S)
    rows = data.event_rows(part)
    h, s = data.ev_hour[rows], data.ev_sector[rows]
    out: dict[str, np.ndarray] = {"standard_nn": std}
    for key, net in _SYSTEMS.items():
        if model.network(net) is None:
            continue
        p = quiet.copy()
        if len(rows):
            p[h - H0, s] = model.predict_inputs(net, event_inputs(data, model.norm, rows, _INPUTS[net]))
        out[key] = p
    if data.expected is not None:
        out["true_rate"] = np.asarray(data.expected[H0:H], np.float64)
    out["previous_hour"] = np.asarray(data.counts[H0 - 1 : H - 1], np.float64) if H0 > 0 else np.vstack([data.counts[:1], data.counts[: H - 1]])
    return out


def bootstrap_weights(n_days: int, n_boot: int, seed: int) -> np.ndarray:
    """``(n_boot, n_days)`` multiplicities of each day in each resample."""
    rng = np.random.default_rng([seed, 2024])
    return rng.multinomial(n_days, np.full(n_days, 1.0 / n_days), size=n_boot).astype(np.float64)


def _per_sector_metric(err: np.ndarray, ok: np.ndarray, W: np.ndarray | None) -> np.ndarray:
    """Mean over sectors of per-sector mean errors; ``err``/``ok`` ``(D, S)``; one value per resample."""
    if W is None:
        W = np.ones((1, err.shape[0]))
    num, den = W @ err, W @ ok
    with np.errstate(invalid="ignore", divide="ignore"):
        per = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)
    valid = (den > 0).sum(axis=1)
    return np.where(valid > 0, np.nansum(per, axis=1) / np.maximum(valid, 1), np.nan)


def pooled_metric(err: np.ndarray, ok: np.ndarray, W: np.ndarray | None) -> np.ndarray:
    e, k = err.sum(axis=1), ok.sum(axis=1)
    if W is None:
        W = np.ones((1, err.shape[0]))
    num, den = W @ e, W @ k
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)


def percentile_ci(samples: np.ndarray) -> list[float]:
    s = samples[np.isfinite(samples)]
    if not len(s):
        return [float("nan"), float("nan")]
    lo, hi = np.percentile(s, [2.5, 97.5])
    return [float(lo), float(hi)]


def _rows(y: np.ndarray, preds: dict[str, np.ndarray], mask: np.ndarray, metric, W: np.ndarray, hour) -> dict:
    """One row: point estimate and 95 % CI per prediction, and paired differences against event_nn."""
    ok = (y > 0) & mask
    row: dict = {"hour": hour, "n": int(ok.sum())}
    boots: dict[str, np.ndarray] = {}
    safe = np.where(ok, y, 1.0)
    for name, p in preds.items():
        err = np.where(ok, np.abs(y - p) / safe, 0.0)
        # err, ok: (D, S) after summing the hours of each day
        e2, k2 = err.sum(axis=1), ok.sum(axis=1).astype(np.float64)
        row[f"pe_{name}"] = float(metric(e2, k2, None)[0])
        boots[name] = metric(e2, k2, W)
        row[f"ci_{name}"] = percentile_ci(boots[name])
    if "event_nn" in boots:
        for name in boots:
            if name == "event_nn":
                continue
            d = boots["event_nn"] - boots[name]
            row[f"diff_{name}"] = {"mean": float(row["pe_event_nn"] - row[f"pe_{name}"]), "ci": percentile_ci(d), "share_event_nn_lower": float(np.mean(d[np.isfinite(d)] < 0)) if np.isfinite(d).any() else float("nan")}
    return row


def evaluate(model, data: YearData, hours=HOURS, *, part: str = "test", n_boot: int = 1000, seed: int = 0) -> dict:
    """The ablation on ``part`` (``test`` for the figures, ``val`` for design choices); see the module notes."""
    r, S = data.hours(part), data.n_sectors
    H0, H = r.start, r.stop
    if (H - H0) % 24 or H0 % 24:
        raise ValueError(f"{part} months must be whole days, got hours {H0}..{H}")
    preds = predictions(model, data, part)
    D = (H - H0) // 24
    y = data.counts[H0:H].reshape(D, 24, S).astype(np.float64)
    has = data.has_event()[H0:H].reshape(D, 24, S)
    P = {k: v.reshape(D, 24, S) for k, v in preds.items()}
    W = bootstrap_weights(D, n_boot, seed)
    everywhere = np.ones_like(has)

    def at(hrs):
        idx = list(hrs)
        return y[:, idx], {k: v[:, idx] for k, v in P.items()}

    rows, ev_rows = [], []
    for hr in hours:
        yy, pp = at([hr])
        rows.append(_rows(yy, pp, everywhere[:, [hr]], _per_sector_metric, W, hr))
        ev_rows.append(_rows(yy, pp, has[:, [hr]], pooled_metric, W, hr))
    yy, pp = at(hours)
    pooled = {
        "all_sector_hours": _rows(yy, pp, everywhere[:, list(hours)], _per_sector_metric, W, f"{hours[0]}-{hours[-1]}"),
        "event_sector_hours": _rows(yy, pp, has[:, list(hours)], pooled_metric, W, f"{hours[0]}-{hours[-1]}"),
    }
    return {
        "schema": SCHEMA,
        "part": part,
        "rows": rows,
        "rows_event_sectors": ev_rows,
        "pooled": pooled,
        "predictors": [k for k, _ in ROWS if k in preds],
        "test" if part == "test" else "validation": {"first_hour": int(H0), "hours": int(H - H0), "days": int(D), "sectors": int(S), "event_sector_hours": int(has.sum())},
        "metric": "PE = mean |y - yhat| / y per sector (y = 0 skipped), averaged over sectors; event sector-hours: mean over all such points",
        "intervals": f"95% percentile bootstrap over the {D} days ({n_boot} resamples, seed {seed}); diff_X = PE(event_nn) - PE(X) on the same resamples",
        "noise_floor": "true_rate: the world's expected rate lambda" if "true_rate" in preds else "absent: the world has no expected rate apart from its realised counts",
    }


def format_table(result: dict) -> str:
    """Terminal tables: PE [95 % CI] per hour on all and on event sector-hours, then event_nn minus each row."""
    names = [k for k in result.get("predictors", [k for k, _ in ROWS]) if f"pe_{k}" in result["rows"][0]]
    out = []
    for title, rows, key in (("all sector-hours (mean over sectors)", result["rows"], "all_sector_hours"), ("event sector-hours", result.get("rows_event_sectors", []), "event_sector_hours")):
        rows = list(rows) + ([result["pooled"][key]] if "pooled" in result else [])
        out.append(f"PE on {title}, {result.get('part', 'test')} months: estimate [95% CI]")
        out.append("hour   " + "".join(f"{k:>24}" for k in names) + "      n")
        for r in rows:
            cells = []
            for k in names:
                lo, hi = r.get(f"ci_{k}", [float("nan")] * 2)
                cells.append(f"{r[f'pe_{k}']:8.3f} [{lo:5.3f},{hi:5.3f}]")
            out.append(f"{str(r['hour']):>5}  " + "".join(f"{c:>24}" for c in cells) + f"  {r['n']:5d}")
        others = [k for k in names if k != "event_nn" and f"diff_{k}" in rows[0]]
        if others:
            out.append("       event_nn minus:" + "".join(f"{k:>24}" for k in others))
            for r in rows:
                cells = [f"{r[f'diff_{k}']['mean']:+7.3f} [{r[f'diff_{k}']['ci'][0]:+.3f},{r[f'diff_{k}']['ci'][1]:+.3f}]" for k in others]
                out.append(f"{str(r['hour']):>5}  " + " " * 15 + "".join(f"{c:>24}" for c in cells))
        out.append("")
    out.append(result.get("intervals", ""))
    return "\n".join(out)


def write_json(result: dict, path: str | Path) -> None:
    Path(path).write_text(json.dumps(result, indent=1))


def plot(result: dict, path: str | Path, title: str = "") -> None:
    """Two panels (all sector-hours, event sector-hours): PE per hour with 95 % bands, one line per row."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    styles = {"standard_nn": "s--", "metadata_nn": "d-.", "shuffled_text_nn": "x:", "event_nn": "o-", "true_rate": "k-", "previous_hour": "^:"}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), dpi=120, sharey=False)
    for ax, key, sub in ((axes[0], "rows", "all sector-hours"), (axes[1], "rows_event_sectors", "event sector-hours")):
        rows = result.get(key) or []
        if not rows:
            continue
        hrs = [r["hour"] for r in rows]
        for name, label in ROWS:
            if f"pe_{name}" not in rows[0]:
                continue
            est = [100 * r[f"pe_{name}"] for r in rows]
            line = ax.plot(hrs, est, styles[name], label=label, lw=1.4 if name != "true_rate" else 1.0, ms=4)[0]
            if f"ci_{name}" in rows[0]:
                ax.fill_between(hrs, [100 * r[f"ci_{name}"][0] for r in rows], [100 * r[f"ci_{name}"][1] for r in rows], color=line.get_color(), alpha=0.12, lw=0)
        ax.set_xlabel("hour of day")
        ax.set_ylabel("mean percent error PE (%)")
        ax.set_xticks(hrs)
        ax.set_xticklabels([f"{h}h" for h in hrs])
        ax.grid(alpha=0.3)
        ax.set_title(sub, fontsize=10)
    axes[0].legend(fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)

"""The paper's demand-prediction ablation (§5.4.1): percent error per hour, 15–21 h.

For every test day (September–December) and sector, at each hour h of the
window:

* ``pe_event_nn``: the paper's system: the event network where the sector has
  an active event in that hour, else the no-event network (temporal/weather
  features, fitted on sector-hours without events);
* ``pe_standard_nn``: the ablation: a temporal/weather network fitted on all
  sector-hours, used everywhere;
* ``pe_previous_hour``: the realised count of hour h-1 in the same sector
  (Garces et al. 2023).

``PE_s = mean_X |y - ŷ| / y`` over the test points X of sector s at hour h,
then averaged over sectors; points with y = 0 are skipped (PE is undefined
there) and ``n`` counts the points used.  Rows of ``rows_event_sectors`` are
the same metrics restricted to sector-hours with an active event (averaged
over all such points, not per sector), where the two networks differ.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from predictor.dataset import YearData

SCHEMA = "surge.predictor.eval/1"
HOURS = tuple(range(15, 22))


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


def predictions(model, data: YearData) -> dict[str, np.ndarray]:
    """ŷ for every test hour and sector from the system and the baselines: arrays ``(H_test, S)``."""
    H0, H, S = data.split_hour, data.n_hours, data.n_sectors
    hours = np.repeat(np.arange(H0, H), S)
    sectors = np.tile(np.arange(S), H - H0)
    std = model.predict_standard(data.temporal[hours], data.weather[hours], sectors).reshape(H - H0, S)
    ev = model.predict_no_event(data.temporal[hours], data.weather[hours], sectors).reshape(H - H0, S)
    sel = data.ev_hour >= H0
    if sel.any():
        h, s = data.ev_hour[sel], data.ev_sector[sel]
        ev[h - H0, s] = model.predict_event(data.temporal[h], data.weather[h], s, data.ev_F[sel])
    prev = data.counts[H0 - 1 : H - 1]
    return {"event_nn": ev, "standard_nn": std, "previous_hour": prev}


def evaluate(model, data: YearData, hours=HOURS) -> dict:
    H0, H, S = data.split_hour, data.n_hours, data.n_sectors
    preds = predictions(model, data)
    y = data.counts[H0:H]
    has = data.has_event()[H0:H]
    hod = (np.arange(H0, H) % 24)
    rows, ev_rows = [], []
    for hr in hours:
        idx = np.flatnonzero(hod == hr)
        yy = y[idx].ravel()
        sec = np.tile(np.arange(S), len(idx))
        row = {"hour": hr}
        for name, p in preds.items():
            row[f"pe_{name}"], n = percent_error(yy, p[idx].ravel(), sec, S)
        row["n"] = n
        rows.append(row)
        m = has[idx].ravel() & (yy > 0)
        erow = {"hour": hr, "n": int(m.sum())}
        for name, p in preds.items():
            pp = p[idx].ravel()
            erow[f"pe_{name}"] = float(np.mean(np.abs(yy[m] - pp[m]) / yy[m])) if m.any() else float("nan")
        ev_rows.append(erow)
    return {
        "schema": SCHEMA,
        "rows": rows,
        "rows_event_sectors": ev_rows,
        "test": {"first_hour": int(H0), "hours": int(H - H0), "sectors": int(S), "event_sector_hours": int(has.sum())},
        "metric": "PE = mean |y - yhat| / y per sector (y = 0 skipped), averaged over sectors",
    }


def format_table(result: dict) -> str:
    lines = ["hour  pe_event_nn  pe_standard_nn  pe_previous_hour      n   | event sector-hours: event_nn  standard_nn  prev_hour    n"]
    for r, e in zip(result["rows"], result.get("rows_event_sectors", [{}] * len(result["rows"]))):
        lines.append(
            f"{r['hour']:>4}  {r['pe_event_nn']:11.4f}  {r['pe_standard_nn']:14.4f}  {r['pe_previous_hour']:16.4f}  {r['n']:5d}   |"
            f"                     {e.get('pe_event_nn', float('nan')):8.4f}  {e.get('pe_standard_nn', float('nan')):11.4f}  {e.get('pe_previous_hour', float('nan')):9.4f}  {e.get('n', 0):4d}"
        )
    return "\n".join(lines)


def write_json(result: dict, path: str | Path) -> None:
    Path(path).write_text(json.dumps(result, indent=1))


def plot(result: dict, path: str | Path, title: str = "") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["rows"]
    hrs = [r["hour"] for r in rows]
    fig, ax = plt.subplots(figsize=(6, 3.6), dpi=120)
    for key, label, style in (
        ("pe_event_nn", "Event NN (ours)", "o-"),
        ("pe_standard_nn", "Standard NN", "s--"),
        ("pe_previous_hour", "Previous hour", "^:"),
    ):
        ax.plot(hrs, [100 * r[key] for r in rows], style, label=label)
    ax.set_xlabel("hour of day")
    ax.set_ylabel("mean percent error PE (%)")
    ax.set_xticks(hrs)
    ax.set_xticklabels([f"{h}h" for h in hrs])
    ax.grid(alpha=0.3)
    ax.legend()
    if title:
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)

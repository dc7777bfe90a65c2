"""The temporal/weather network on real hours: Manhattan's real 2022 hourly trip totals (torch).

The network is the project's standard one (:data:`predictor.nets.STANDARD_HIDDEN`,
trained by :func:`predictor.train.fit` with the paper's settings and early
stopping on the validation months) on the project's features: hour, weekday,
month and holiday (:func:`predictor.features.temporal_features`) and the real
hourly weather of the scenario's file.  Its target is one series, the city's
real trips of each hour.  Split as everywhere: January–June train,
July–August validation, September–December test.

Two feature sets are trained: all of them, and all but the month's sine and
cosine (January–June never show the test months' values of those two, so a
network may extrapolate them badly).  The one with the lower percent error
at 15–21 h on the validation months is the network the table compares;
both are reported.

Baselines on the same test hours: the previous hour's count, the same hour a
week before, and the 2018 profile (:data:`city.demand.profile.PROFILE` ×
:data:`~city.demand.profile.MONTH_FACTOR`, holidays on the Sunday row) scaled
by its mean ratio to the real counts over the training months.  The error of
an hour is |y − ŷ| / y; the table gives its mean per hour of day, 15–21 h,
with 95 % CIs from resampling test days (1,000 resamples), and the paired
difference of each baseline against the network with its CI.

Per zone, January 2022 (:func:`zone_surges`): the real yellow pickups per
zone and hour are too short a series (one month) to train the network on, so
the per-zone figure is the error of each zone's usual level (the median of
the other days of the same weekday at that hour, holidays as Sundays) at 15–21 h, and the zone
evenings that surge furthest beyond it.

Run ``python -m predictor.real_hours DATA_DIR [OUT_DIR]``; it writes
``OUT_DIR/real-demand-predictor/predictor.json``.
"""

from __future__ import annotations

import datetime as dt
import json
import sys
from pathlib import Path

import numpy as np

from predictor.features import temporal_features, weather_matrix

#: Hours of day in the table.
HOURS = tuple(range(15, 22))
#: Months of each part of the split.
PARTS = {"train": range(1, 7), "validation": range(7, 9), "test": range(9, 13)}
N_BOOT = 1000


def real_series(data_dir: Path | str, year: int = 2022) -> tuple[np.ndarray, np.ndarray, frozenset[dt.date], str]:
    """The real hourly totals of ``year``, the real weather ``(H, 3)``, the holidays, and the totals' file name, from the ``nyc`` scenario."""
    from city.demand.dates import holiday_dates
    from city.io.hourly_totals import read_hourly_totals
    from city.io.weather import read_weather_csv
    from city.scenario import scenario_spec

    spec = scenario_spec("nyc", data_dir)
    hourly = next(t for t in spec.trips if t.kind == "hourly-totals" and t.files)
    totals = read_hourly_totals(hourly.files[0], columns=hourly.columns).year(year)
    w = spec.weather
    weather = read_weather_csv(w.file, station=w.station or "LGA", year=year, columns=w.columns, timezone=spec.timezone)
    return totals, weather_matrix(weather, len(totals)), holiday_dates(year), hourly.files[0].name


def profile_forecast(year: int, holidays: frozenset[dt.date]) -> np.ndarray:
    """``(H,)`` the 2018 profile's level of every hour (unscaled)."""
    from city.demand.profile import day_factors

    return day_factors(year, holidays).ravel()


def _day_ci(err: np.ndarray, rng: np.random.Generator) -> list[float]:
    """95 % CI of the mean of ``err`` (one value per test day) from resampling days."""
    idx = rng.integers(0, len(err), size=(N_BOOT, len(err)))
    lo, hi = np.percentile(err[idx].mean(axis=1), [2.5, 97.5])
    return [round(float(lo) * 100, 2), round(float(hi) * 100, 2)]


def run(data_dir: Path | str, seed: int = 0, epochs: int = 100, device: str = "cpu") -> dict:
    """Train, forecast the test months and tabulate; see the module docstring."""
    from predictor.nets import STANDARD_HIDDEN
    from predictor.train import TrainConfig, fit, predict

    year = 2022
    y, weather, holidays, source = real_series(data_dir, year)
    H = len(y)
    when = [dt.datetime(year, 1, 1) + dt.timedelta(hours=h) for h in range(H)]
    month = np.array([t.month for t in when])
    part = {name: np.isin(month, list(months)) for name, months in PARTS.items()}
    temporal = np.stack([temporal_features(t, holidays) for t in when])
    mu, sd = weather[part["train"]].mean(axis=0), weather[part["train"]].std(axis=0) + 1e-6
    X = np.hstack([temporal, (weather - mu) / sd]).astype(np.float32)
    scale = float(y[part["train"]].mean())
    hour = np.arange(H) % 24
    evening_val = part["validation"] & np.isin(hour, HOURS)
    variants: dict[str, dict] = {}
    for name, cols in (("all_features", np.arange(X.shape[1])), ("without_month", np.setdiff1d(np.arange(X.shape[1]), [31, 32]))):
        result = fit(f"real_hours_{name}", X[part["train"]][:, cols], (y[part["train"]] / scale).astype(np.float32), STANDARD_HIDDEN,
                     TrainConfig(epochs=epochs, seed=seed, device=device),
                     X_val=X[part["validation"]][:, cols], y_val=(y[part["validation"]] / scale).astype(np.float32), log=None)
        forecast = predict(result.net, X[:, cols]) * scale
        variants[name] = {"forecast": forecast, "epochs_run": len(result.losses), "best_epoch": result.best_epoch,
                          "validation_pe_pct_15_21h": round(float(np.mean(np.abs(y - forecast)[evening_val] / y[evening_val])) * 100, 2)}
    chosen = min(variants, key=lambda k: variants[k]["validation_pe_pct_15_21h"])
    net = variants[chosen]["forecast"]
    prof = profile_forecast(year, holidays)
    prof = prof * float(np.mean(y[part["train"]] / prof[part["train"]]))
    forecasts = {"temporal_nn": net, **{f"nn_{k}": v["forecast"] for k, v in variants.items()}, "previous_hour": np.concatenate([[y[0]], y[:-1]]),
                 "same_hour_last_week": np.concatenate([np.full(168, np.nan), y[:-168]]), "profile_2018": prof}
    rng = np.random.default_rng([seed, 48])
    table: dict = {}
    for h in HOURS:
        sel = part["test"] & (hour == h)
        row: dict = {"test_days": int(sel.sum())}
        errs = {k: np.abs(y[sel] - f[sel]) / y[sel] for k, f in forecasts.items()}
        for k, e in errs.items():
            row[k] = {"pe_pct": round(float(e.mean()) * 100, 2), "ci95": _day_ci(e, rng)}
            if k in ("previous_hour", "same_hour_last_week", "profile_2018"):
                for label, ref in (("nn", "temporal_nn"), ("nn_without_month", "nn_without_month")):
                    diff = e - errs[ref]
                    row[k][f"minus_{label}_pp"] = round(float(diff.mean()) * 100, 2)
                    row[k][f"minus_{label}_ci95"] = _day_ci(diff, rng)
                    row[k][f"{label}_better_days"] = int((diff > 0).sum())
        table[h] = row
    test_eve = np.flatnonzero(part["test"] & np.isin(hour, HOURS))
    missed = {}
    for name, v in variants.items():
        surplus = y[test_eve] / v["forecast"][test_eve] - 1
        order = np.argsort(-surplus)[:10]
        missed[name] = [{"when": f"{when[i]:%Y-%m-%d %a} {when[i].hour} h", "real": int(y[i]), "network": round(float(v["forecast"][i])),
                         "above_pct": round(float(surplus[k] * 100), 1)} for k, i in zip(order, test_eve[order])]
    return {"question": "How well does the temporal/weather network forecast real hourly trip totals (Manhattan 2022), 15-21 h of the test months?",
            "series": source, "split": {k: f"months {min(v)}-{max(v)}" for k, v in PARTS.items()},
            "network": {"hidden": list(STANDARD_HIDDEN), "seed": seed, "chosen_on_validation": chosen,
                        "variants": {k: {x: v for x, v in d.items() if x != "forecast"} for k, d in variants.items()},
                        "features": "hour, weekday, month (sin, cos), holiday; real LGA temperature, precipitation, wind "
                        "(standardised on the training months); without_month drops the month's sine and cosine"},
            "columns": "temporal_nn is the variant chosen on validation (nn_<variant> both); minus_nn_pp: baseline error minus "
                       "the chosen network's, per cent points (negative: the baseline is better), nn_better_days: days the network "
                       "was closer; the same against nn_without_month",
            "metric": "mean over test days of |y - yhat| / y, in per cent; CIs resample test days",
            "by_hour": table, "largest_misses_test_15_21h": missed}


def zone_surges(data_dir: Path | str, min_usual: float = 50.0) -> dict:
    """Per-zone January 2022: the usual level's percent error at 15–21 h, and the evenings (17–22 h) furthest above usual.

    ``usual`` of a zone, day and hour is the median of the other January days
    of the same weekday (holidays as Sundays) at that hour; an evening counts when its usual is at least ``min_usual`` pickups.
    """
    from city.demand.dates import day_kind, holiday_dates
    from city.io.zone_hourly import read_zone_hourly
    from city.scenario import load_city, scenario_spec

    spec = scenario_spec("nyc", data_dir)
    city = load_city("nyc", data_dir)
    zonal = next(t for t in spec.trips if t.kind == "zone-hourly" and t.files)
    z = read_zone_hourly(zonal.files[0], columns=zonal.columns, timezone=spec.timezone)
    holidays = holiday_dates(2022)
    lookup = {int(v): k for k, v in enumerate(city.sector_ids)}
    S, D = city.n_sectors, 31
    counts = np.zeros((D, 24, S))
    day = (z.time.astype("datetime64[D]") - np.datetime64("2022-01-01")).astype(np.int64)
    hour = (z.time - z.time.astype("datetime64[D]").astype("datetime64[h]")).astype(np.int64)
    keep = np.array([int(v) in lookup for v in z.zone]) & (day >= 0) & (day < D)
    np.add.at(counts, (day[keep], hour[keep], np.array([lookup[int(v)] for v in z.zone[keep]])), z.count[keep])
    dates = [dt.date(2022, 1, 1) + dt.timedelta(days=d) for d in range(D)]
    kind = np.array([day_kind(d, holidays) for d in dates])
    usual = np.zeros_like(counts)
    for d in range(D):
        others = (kind == kind[d]) & (np.arange(D) != d)
        usual[d] = np.median(counts[others], axis=0)
    eve = counts[:, 17:23].sum(axis=1)
    eve_usual = usual[:, 17:23].sum(axis=1)
    ok = eve_usual >= min_usual
    ratio = np.where(ok, eve / np.maximum(eve_usual, 1e-9), 0.0)
    top = np.dstack(np.unravel_index(np.argsort(-ratio, axis=None)[:12], ratio.shape))[0]
    hours = counts[:, 15:22]
    valid = hours > 0
    pe = np.where(valid, np.abs(hours - usual[:, 15:22]) / np.where(valid, hours, 1.0), np.nan)
    per_zone = np.nanmean(pe, axis=(0, 1))
    return {"file": z.source, "metric": "mean over days and 15-21 h of |y - usual| / y per zone (y > 0), in per cent",
            "usual_pe_pct": {"mean_over_zones": round(float(np.nanmean(per_zone)) * 100, 1),
                             "median_over_zones": round(float(np.nanmedian(per_zone)) * 100, 1),
                             "worst_zones": [{"zone": int(city.sector_ids[s]), "name": city.sector_names[s], "pe_pct": round(float(per_zone[s]) * 100, 1)}
                                             for s in np.argsort(-per_zone)[:5]]},
            "evenings_above_usual": [{"date": f"{dates[d]:%Y-%m-%d %a}", "zone": int(city.sector_ids[s]), "name": city.sector_names[s],
                                      "pickups_17_22h": int(eve[d, s]), "usual": round(float(eve_usual[d, s]), 1), "ratio": round(float(ratio[d, s]), 2)}
                                     for d, s in top]}


def main(argv: list[str]) -> int:
    """``DATA_DIR [OUT_DIR]``: write the table's JSON under ``OUT_DIR`` (default ``benchmarks``)."""
    from city.fingerprint import machine

    if not 1 <= len(argv) <= 2:
        print("usage: python -m predictor.real_hours DATA_DIR [OUT_DIR]", file=sys.stderr)
        return 2
    out = Path(argv[1] if len(argv) > 1 else "benchmarks") / "real-demand-predictor"
    out.mkdir(parents=True, exist_ok=True)
    doc = {"command": f"python -m predictor.real_hours {' '.join(argv)}", "date": dt.date.today().isoformat(), "machine": machine(),
           **run(argv[0]), "january_zones": zone_surges(argv[0])}
    (out / "predictor.json").write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {out / 'predictor.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

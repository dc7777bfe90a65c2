"""How close a scenario's hourly demand level is to the real hourly trip totals of its year.

For every hour of the year the scenario's level is its expected requests
summed over sectors; the real level is the hourly-totals file's count.  The
two differ in scale (the fleet's share, and a 38-zone map against all of
Manhattan), so the check reports the correlation (scale-free) and the MAPE of
the scenario level divided by one constant, the mean ratio scenario/real over
January–June (the training months), so no test month sets it.  It compares the
world built with the hourly totals and the world built without them (the
zone profile with month, weather and holiday factors), both from the same
scenario file and world seed.

Run ``python -m city.demand.level_check DATA_DIR [OUT_DIR]``; it writes
``OUT_DIR/real-demand-level/level.json`` and
``OUT_DIR/real-demand-split/split.json`` (:mod:`city.demand.split_check`).
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import sys
from pathlib import Path

import numpy as np

from city.demand.dates import holiday_dates
from city.demand.real_level import REFERENCE_MONTHS, day_kinds

#: Dates named in the level table: storms (the wettest and snowiest days of 2022 at Central Park, NOAA daily), holidays,
#: the paper's Thursday, an ordinary weekday and Saturday.
NAMED = (("2022-01-29", "Saturday blizzard, 7.3 in snow"), ("2022-07-18", "Monday, 1.85 in rain"), ("2022-10-04", "Tuesday, 1.85 in rain"),
         ("2022-07-04", "Independence Day"), ("2022-11-24", "Thanksgiving"), ("2022-12-25", "Christmas (Sunday)"),
         ("2022-11-17", "the paper's Thursday"), ("2022-03-09", "a Wednesday"), ("2022-05-14", "a Saturday"))
#: Hours of day whose scenario/real ratio spread is reported (few events: the ratio is the base level's).
QUIET_HOURS = (8, 13)
WEEKDAYS = ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")


def worlds(data_dir: Path | str, seed: int = 0) -> tuple[object, object, np.ndarray]:
    """The ``nyc`` world with and without the real hourly totals, and the real totals of 2022."""
    from city.io.hourly_totals import read_hourly_totals
    from city.scenario import build_world, load_city, scenario_spec

    spec = scenario_spec("nyc", data_dir)
    city = load_city("nyc", data_dir)
    after = build_world(spec, city, seed=seed)
    before = build_world(dataclasses.replace(spec, trips=tuple(t for t in spec.trips if t.kind in ("fhvhv", "zone-od"))), city, seed=seed)
    hourly = next(t for t in spec.trips if t.kind == "hourly-totals")
    totals = read_hourly_totals(hourly.files[0], columns=hourly.columns).year(2022)
    return before, after, totals


def _stats(model: np.ndarray, real: np.ndarray) -> dict:
    """Correlation and MAPE (%) of ``model`` (already divided by its scale) against ``real``, and the ratio's spread."""
    ratio = model / real
    return {"hours": int(len(real)), "r": round(float(np.corrcoef(model, real)[0, 1]), 4),
            "mape_pct": round(float(np.mean(np.abs(ratio - 1)) * 100), 2),
            "ratio_cv_pct": round(float(np.std(ratio) / np.mean(ratio) * 100), 2)}


def level_table(world: object, totals: np.ndarray, year: int = 2022) -> dict:
    """The level check of one world: overall, by month, by weekday (holidays apart), by hour, quiet hours and named dates."""
    level = world.expected_rate().sum(axis=1)
    events = world.event_rate().sum(axis=1)
    days = len(totals) // 24
    date = np.array([dt.date(year, 1, 1) + dt.timedelta(days=d) for d in range(days)])
    month = np.repeat([d.month for d in date], 24)
    weekday = np.repeat([d.weekday() for d in date], 24)
    holiday = np.repeat([d in holiday_dates(year) for d in date], 24)
    hour = np.tile(np.arange(24), days)
    train = np.isin(month, list(REFERENCE_MONTHS))
    scale = float(np.mean(level[train] / totals[train]))
    model = level / scale
    awake = hour >= 6  # the night hours' small totals would dominate a MAPE
    out = {"scale": scale, "all_hours": _stats(model, totals), "hours_6_to_23": _stats(model[awake], totals[awake]),
           "by_month": {m: _stats(model[(month == m) & awake], totals[(month == m) & awake]) for m in range(1, 13)},
           "by_weekday": {WEEKDAYS[k]: _stats(model[(weekday == k) & ~holiday & awake], totals[(weekday == k) & ~holiday & awake])
                          for k in range(7)},
           "holidays": _stats(model[holiday & awake], totals[holiday & awake]),
           "by_hour": {h: _stats(model[hour == h], totals[hour == h]) for h in range(24)}}
    quiet = {}
    for h in QUIET_HOURS:
        sel = (hour == h) & (events < 0.05 * level)
        quiet[h] = {**_stats(model[sel], totals[sel]), "share_of_days": round(float(sel.sum() / days), 3)}
    out["quiet_hours"] = quiet
    out["named"] = []
    for text, label in NAMED:
        d = dt.date.fromisoformat(text)
        for h in (8, 13, 19):
            i = (d - dt.date(year, 1, 1)).days * 24 + h
            weekday_ratio = float(np.median((model / totals)[(hour == h) & (weekday < 5) & ~holiday]))
            out["named"].append({"date": text, "what": label, "hour": h, "real": int(totals[i]), "scenario_scaled": round(float(model[i]), 1),
                                 "ratio_vs_usual_weekday": round(float(model[i] / totals[i] / weekday_ratio), 3)})
    return out


def check_level(data_dir: Path | str) -> dict:
    """Both worlds' level tables, with what they are built from."""
    before, after, totals = worlds(data_dir)
    kinds = day_kinds(2022, after.holidays)
    return {"question": "How close is the nyc scenario's hourly demand level to the real 2022 Manhattan hourly trip totals?",
            "before": {"demand_source": before.demand_source, **level_table(before, totals)},
            "after": {"demand_source": after.demand_source, **level_table(after, totals)},
            "days_by_kind": {WEEKDAYS[k]: int((kinds == k).sum()) for k in range(7)}}


def main(argv: list[str]) -> int:
    """``DATA_DIR [OUT_DIR]``: write both checks' JSON under ``OUT_DIR`` (default ``benchmarks``)."""
    from city.demand.split_check import check_split
    from city.fingerprint import machine

    if not 1 <= len(argv) <= 2:
        print("usage: python -m city.demand.level_check DATA_DIR [OUT_DIR]", file=sys.stderr)
        return 2
    data, out = Path(argv[0]), Path(argv[1] if len(argv) > 1 else "benchmarks")
    meta = {"command": f"python -m city.demand.level_check {' '.join(argv)}", "date": dt.date.today().isoformat(), "machine": machine()}
    for folder, name, doc in (("real-demand-level", "level.json", check_level(data)), ("real-demand-split", "split.json", check_split(data))):
        (out / folder).mkdir(parents=True, exist_ok=True)
        (out / folder / name).write_text(json.dumps({**meta, **doc}, indent=1) + "\n")
        print(f"wrote {out / folder / name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

"""How close a scenario's split of demand over sectors is to real per-zone pickups (January 2022 yellow cabs).

For each hour of day it compares, across the map's sectors, the pickup shares
a world uses with the real shares of the zone-hourly file: the correlation
across sectors and the mean absolute share error (mean over sectors of
|share − real share|, in percentage points).  Splits compared:

* ``profile``: the zone profile's business-day shares (what the scenario
  uses on business days), against real business days;
* ``synthetic``: the synthetic map's sector intensity and evening tilt (the
  split of a map without a zone profile), against real business days;
* the yellow file's own first-half shares against its second half: how
  consistent the real split is, and how large its weekend shift is;
* on weekends (Saturdays, Sundays and holidays): the weekday-mean profile
  shares (the split without a zone-hourly file) and the scenario's weekend
  split (weekday mean × weekend ratio), the ratio taken from the first half of
  January and judged on the second half, so the file does not judge itself.

Caveat: the real file is yellow cabs only (about a third of 2022's Manhattan
trips) in an Omicron month; the profile holds 2018's trips.  Run with
:mod:`city.demand.level_check`.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np

from city.demand.real_level import sector_split

#: Hours of day over which the per-sector errors are averaged to name the sectors the profile gets most wrong.
DAY_HOURS = range(7, 23)


def _compare(model: np.ndarray, real: np.ndarray) -> dict:
    """Per hour of day: correlation across sectors and mean absolute share error (percentage points)."""
    rows = {}
    for h in range(24):
        p, q = model[h] / model[h].sum(), real[h] / real[h].sum()
        rows[h] = {"r": round(float(np.corrcoef(p, q)[0, 1]), 3), "mae_pp": round(float(np.mean(np.abs(p - q)) * 100), 3)}
    day = [rows[h] for h in DAY_HOURS]
    return {"by_hour": rows, "mean_7_to_22": {"r": round(float(np.mean([x["r"] for x in day])), 3),
                                               "mae_pp": round(float(np.mean([x["mae_pp"] for x in day])), 3)}}


def _shares(by_type: np.ndarray) -> np.ndarray:
    total = by_type.sum(axis=-1, keepdims=True)
    return by_type / np.where(total > 0, total, 1.0)


def check_split(data_dir: Path | str) -> dict:
    """The split table of ``nyc`` against the January 2022 per-zone pickups; see the module docstring."""
    from city.demand import synthetic_world
    from city.demand.dates import holiday_dates
    from city.io.zone_hourly import ZoneHourly, read_zone_hourly
    from city.scenario import load_city, load_zone_profile, scenario_spec

    spec = scenario_spec("nyc", data_dir)
    city = load_city("nyc", data_dir)
    profile_spec = next(t for t in spec.trips if t.kind == "zone-od")
    zonal_spec = next(t for t in spec.trips if t.kind == "zone-hourly")
    profile = load_zone_profile(profile_spec.files[0], city).rate()
    zones = read_zone_hourly(zonal_spec.files[0], columns=zonal_spec.columns, timezone=spec.timezone)
    holidays = holiday_dates(2022)
    real, days = zones.by_day_type(city.sector_ids, holidays)

    plain = synthetic_world(city, seed=0)
    weekday = [h for h in range(24 * 3, 24 * 4)]  # 2022-01-04, a Tuesday
    synthetic = plain.base_rate()[weekday]
    out = {"question": "How close is the nyc scenario's split of pickups over its 38 sectors to the real January 2022 yellow pickups per zone?",
           "real_file": zones.source, "days_by_type": {"business": int(days[0]), "saturday": int(days[1]), "sunday_or_holiday": int(days[2])},
           "business_days": {"profile": _compare(profile.mean(axis=0), real[0]), "synthetic": _compare(synthetic, real[0])}}

    def half(first: bool) -> ZoneHourly:
        cut = np.datetime64("2022-01-16T00", "h")
        keep = (zones.time < cut) if first else (zones.time >= cut)
        return ZoneHourly(zones.time[keep], zones.zone[keep], zones.count[keep], zones.source)

    early, _ = half(True).by_day_type(city.sector_ids, holidays)
    late, late_days = half(False).by_day_type(city.sector_ids, holidays)
    split = sector_split(profile, early, synthetic)
    out["weekends_second_half_of_january"] = {
        "days": {"saturday": int(late_days[1]), "sunday_or_holiday": int(late_days[2])},
        "weekday_mean_profile": {"saturday": _compare(profile.mean(axis=0), late[1]), "sunday_or_holiday": _compare(profile.mean(axis=0), late[2])},
        "profile_times_weekend_ratio": {"saturday": _compare(split[5], late[1]), "sunday_or_holiday": _compare(split[6], late[2])},
        # How large the real weekend shift is, within the yellow file: its own first-half shares of each day type.
        "yellow_first_half_business_days": {"saturday": _compare(early[0], late[1]), "sunday_or_holiday": _compare(early[0], late[2])},
        "yellow_first_half_same_day_type": {"saturday": _compare(early[1], late[1]), "sunday_or_holiday": _compare(early[2], late[2])},
    }
    out["business_days_yellow_first_half"] = _compare(early[0], late[0])
    p, q = _shares(profile.mean(axis=0)), _shares(real[0])
    err = (p - q)[list(DAY_HOURS)].mean(axis=0) * 100
    order = np.argsort(-np.abs(err))[:8]
    out["most_wrong_business_days"] = [{"zone": int(city.sector_ids[s]), "name": city.sector_names[s], "profile_pp": round(float(p[list(DAY_HOURS), s].mean() * 100), 2),
                                        "real_pp": round(float(q[list(DAY_HOURS), s].mean() * 100), 2), "error_pp": round(float(err[s]), 2)}
                                       for s in order]
    out["profile_filled_zones"] = [int(city.sector_ids[s]) for s in load_zone_profile(profile_spec.files[0], city).filled]
    out["note"] = (f"real: {zones.source}, yellow cabs only, {dt.date(2022, 1, 1):%B %Y}; shares over the {city.n_sectors} sectors; "
                   "mae_pp is the mean over sectors of |share - real share| in percentage points (a sector's mean share is "
                   f"{100 / city.n_sectors:.2f} pp)")
    return out

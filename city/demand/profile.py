"""Base demand (no events) by sector and hour: the citywide profile from real trip data, and its scale.

The hourly shape is not tuned: :data:`PROFILE` is computed from real trips
(see :func:`derive_tables`, which recomputes it from the files when they are
present; ``tests/test_demand_profile.py`` checks that it matches):

* Monday … Friday (rows 0–4): ``manhattan_zone_od_15min_2018.csv`` (TLC
  trips between Manhattan zones, summed over the business days of 2018),
  all zones, summed per weekday and hour (4 slots), divided by the number of
  business days of that weekday in 2018 (the weekday's days minus US
  federal holidays, from the ``holidays`` package: 46, 51, 51, 51, 52), and
  divided by the mean over Monday … Friday of the 19 h value (30,354 trips).
* Saturday, Sunday (rows 5, 6): the zone file has business days only, so
  the weekend rows are the Monday–Friday mean row times the weekend/weekday
  ratio per hour in ``yellow_2016_sample.csv`` (5,000 real yellow-cab trips),
  each hourly histogram per day smoothed with the circular kernel
  (1, 2, 3, 2, 1)/9 first (the sample has ≈ 700 trips per weekend day type).
* :data:`MONTH_FACTOR`: ``daily_trips_by_geography_2009_2017.csv``, geo
  ``manhattan``, all operators, 2017: mean trips per day of each month over
  the mean of the twelve.

Holidays run on the Sunday row.  The real profile of a typical weekday
already holds the average event demand; the synthetic world's events come on
top of it, so its surges are surges over the usual level.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np

from city.demand.climate import weather_factor
from city.demand.dates import day_kind
from city.io.weather import HourlyWeather

#: Citywide base requests per hour at the reference point (the mean weekday at 19:00, dry
#: weather, month factor 1) at the default share.  Sized for a 100-taxi fleet on the ≈2,200-node
#: map (the paper's setup).
REF_RATE = 290.0
#: Real trips at 19 h on a business day with both ends in the 38 ``manhattan_below_60`` zones
#: (``manhattan_zone_od_15min_2018.csv``, per business day as in :data:`PROFILE`; mean of Mon–Fri).
REAL_TRIPS_19H = 16966.0
#: The fleet's share of the real market: what 100 taxis serve of Manhattan's taxi and app-car trips
#: (≈ 1.7 %; "a few per cent", as the paper's setup implies).  The default ``--share`` of the real
#: zone profile, and the factor that turns event-goers' trips into the fleet's.
FLEET_SHARE = REF_RATE / REAL_TRIPS_19H

# fmt: off
#: Base demand by day (Mon … Sun) and hour relative to the mean weekday's 19 h; computed as the
#: module docstring says (rounded to 3 decimals).
PROFILE = np.array([
    [0.208, 0.119, 0.076, 0.051, 0.053, 0.114, 0.338, 0.627, 0.802, 0.741, 0.614, 0.594,
     0.610, 0.607, 0.648, 0.689, 0.689, 0.841, 0.962, 0.874, 0.759, 0.704, 0.596, 0.401],
    [0.237, 0.131, 0.080, 0.051, 0.053, 0.124, 0.372, 0.701, 0.891, 0.804, 0.666, 0.648,
     0.672, 0.670, 0.717, 0.748, 0.736, 0.909, 1.058, 0.968, 0.859, 0.820, 0.726, 0.505],
    [0.301, 0.165, 0.101, 0.063, 0.060, 0.125, 0.373, 0.709, 0.903, 0.826, 0.690, 0.681,
     0.704, 0.698, 0.723, 0.742, 0.729, 0.915, 1.069, 1.016, 0.901, 0.861, 0.775, 0.577],
    [0.343, 0.192, 0.116, 0.073, 0.066, 0.127, 0.373, 0.716, 0.904, 0.824, 0.695, 0.687,
     0.700, 0.693, 0.735, 0.748, 0.733, 0.915, 1.075, 1.037, 0.939, 0.917, 0.851, 0.688],
    [0.469, 0.288, 0.180, 0.112, 0.086, 0.127, 0.347, 0.657, 0.857, 0.812, 0.701, 0.705,
     0.726, 0.718, 0.765, 0.776, 0.763, 0.933, 1.076, 1.105, 0.960, 0.908, 0.932, 0.879],
    [0.577, 0.446, 0.357, 0.228, 0.138, 0.132, 0.229, 0.364, 0.494, 0.539, 0.563, 0.676,
     0.758, 0.724, 0.700, 0.702, 0.736, 0.930, 1.012, 0.856, 0.733, 0.747, 0.838, 0.831],
    [0.387, 0.352, 0.322, 0.225, 0.132, 0.111, 0.140, 0.228, 0.332, 0.459, 0.512, 0.631,
     0.675, 0.653, 0.682, 0.716, 0.701, 0.796, 0.831, 0.734, 0.615, 0.556, 0.531, 0.500],
])
#: Mean trips per day by month relative to the year (January … December), as the docstring says.
MONTH_FACTOR = np.array([0.946, 1.001, 1.008, 0.999, 0.994, 1.005, 0.924, 0.917, 1.004, 1.061, 1.060, 1.080])
#: Evening (+) versus morning (−) weight by hour; a sector's tilt scales it (nightlife versus offices).
#: Only spreads demand between sectors: the tilts are centred, so the citywide total keeps PROFILE.
TILT = np.array([.8, .6, .3, 0, 0, 0, -.4, -1, -1, -1, -.6, -.3,
                 -.2, -.2, -.2, -.1, .2, .5, .8, 1, 1, 1, 1, 1])
# fmt: on
#: Circular smoothing kernel of the weekend histograms (offsets −2 … +2).
WEEKEND_KERNEL = np.array([1, 2, 3, 2, 1]) / 9.0


def day_factors(year: int, holidays: frozenset[dt.date] | None = None) -> np.ndarray:
    """``(days, 24)`` citywide base level of every hour of ``year``, relative to the reference point.

    ``holidays`` (default: US federal, :func:`~city.demand.dates.day_kind`) run on the Sunday row.
    """
    days = (dt.date(year + 1, 1, 1) - dt.date(year, 1, 1)).days
    out = np.empty((days, 24))
    for d in range(days):
        date = dt.date(year, 1, 1) + dt.timedelta(days=d)
        out[d] = PROFILE[day_kind(date, holidays)] * MONTH_FACTOR[date.month - 1]
    return out


def base_rate(year: int, weather: HourlyWeather, intensity: np.ndarray, tilt: np.ndarray, share: float = FLEET_SHARE,
              holidays: frozenset[dt.date] | None = None) -> np.ndarray:
    """Expected requests per sector-hour without events: the real 19 h trips × share × profile × month × weather × sector.

    With the default share the reference point is :data:`REF_RATE` requests per hour.
    """
    citywide = day_factors(year, holidays)
    days = citywide.shape[0]
    citywide = citywide.ravel() * weather_factor(weather) * REAL_TRIPS_19H * share
    shape = 1.0 + tilt[None, :] * np.tile(TILT, days)[:, None]
    return citywide[:, None] * intensity[None, :] * shape


def profile_base_rate(year: int, weather: HourlyWeather, hourly: np.ndarray, share: float,
                      holidays: frozenset[dt.date] | None = None) -> np.ndarray:
    """Base rate from a real zone profile: ``hourly`` ``(5, 24, S)`` trips per business day × share.

    Business days use their weekday's row; Saturdays, Sundays and holidays
    the Monday–Friday mean scaled by :data:`PROFILE`'s weekend-to-weekday
    ratio of the hour.  Month and weather factors as on the synthetic map.
    """
    days = (dt.date(year + 1, 1, 1) - dt.date(year, 1, 1)).days
    mean = hourly.mean(axis=0)
    weekday_mean = PROFILE[:5].mean(axis=0)
    S = hourly.shape[2]
    out = np.empty((days, 24, S))
    for d in range(days):
        date = dt.date(year, 1, 1) + dt.timedelta(days=d)
        k = day_kind(date, holidays)
        row = hourly[k] if k < 5 else mean * (PROFILE[k] / weekday_mean)[:, None]
        out[d] = row * MONTH_FACTOR[date.month - 1]
    return out.reshape(days * 24, S) * weather_factor(weather)[:, None] * share


def derive_tables(od_csv: Path | str, yellow_csv: Path | str, daily_csv: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """Recompute :data:`PROFILE` and :data:`MONTH_FACTOR` from the real files (as the module docstring says)."""
    import pandas as pd

    from city.io.trips import business_days

    od = pd.read_csv(od_csv, usecols=["dow", "t_15min", "n_trips"])
    n_days = business_days(2018).astype(float)
    counts = np.zeros((5, 24))
    np.add.at(counts, (od["dow"].to_numpy(), od["t_15min"].to_numpy() // 4), od["n_trips"].to_numpy())
    weekdays = counts / n_days[:, None]
    weekdays = weekdays / weekdays[:, 19].mean()
    mean = weekdays.mean(axis=0)
    when = pd.to_datetime(pd.read_csv(yellow_csv, usecols=["pickup_datetime"])["pickup_datetime"])
    dow, hour, day = when.dt.day_of_week.to_numpy(), when.dt.hour.to_numpy(), when.dt.normalize()

    def per_day(sel: np.ndarray) -> np.ndarray:
        hist = np.bincount(hour[sel], minlength=24).astype(np.float64)
        smooth = sum(w * np.roll(hist, s) for w, s in zip(WEEKEND_KERNEL, range(-2, 3)))
        return smooth / day[sel].nunique()

    weekday_sample = per_day(dow < 5)
    rows = [*weekdays, mean * per_day(dow == 5) / weekday_sample, mean * per_day(dow == 6) / weekday_sample]
    daily = pd.read_csv(daily_csv)
    daily = daily[daily["geo"] == "manhattan"].assign(date=lambda t: pd.to_datetime(t["date"]))
    daily = daily[daily["date"].dt.year == 2017].groupby("date")["trips"].sum()
    monthly = daily.groupby(daily.index.month).mean().to_numpy()
    return np.round(np.array(rows), 3), np.round(monthly / monthly.mean(), 3)


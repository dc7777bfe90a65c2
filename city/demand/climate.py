"""Seeded synthetic hourly weather, and how weather moves taxi demand."""

from __future__ import annotations

import numpy as np

from city.demand.dates import evaluation_date
from city.io.weather import HourlyWeather, hours_in_year


def synthetic_weather(year: int, seed: int) -> HourlyWeather:
    """Seeded hourly weather for ``year``: seasonal and daily temperature cycles, rain episodes, wind.

    New York-like: about 33 °F in January and 77 °F in July, some 120 rain
    episodes of 1–12 hours.  The evaluation evening (see
    :func:`evaluation_date`) is kept dry from noon so that its surge is an
    event surge, not a weather one.
    """
    rng = np.random.default_rng([seed, year, 16])
    n = hours_in_year(year)
    t = np.arange(n)
    days = n // 24
    doy, hod = t / 24.0, t % 24
    synoptic = _ar1(rng, days + 1, 0.8, 5.0)
    temp = (
        55.0
        - 22.0 * np.cos(2 * np.pi * (doy - 20) / 365.25)
        + 7.0 * np.cos(2 * np.pi * (hod - 15) / 24)
        + np.interp(doy, np.arange(days + 1), synoptic)
        + rng.normal(0.0, 1.0, n)
    )
    precip = np.zeros(n)
    n_rain = rng.poisson(120)
    for start, length, rate in zip(rng.integers(0, n, n_rain), np.minimum(rng.geometric(0.2, n_rain), 12), rng.exponential(0.05, n_rain)):
        stop = min(n, start + length)
        precip[start:stop] += rate * rng.gamma(2.0, 0.5, stop - start)
    wind = np.maximum(
        0.0,
        9.0 + 3.0 * np.cos(2 * np.pi * (doy - 20) / 365.25) + np.interp(doy, np.arange(days + 1), _ar1(rng, days + 1, 0.6, 3.0)) + rng.gamma(2.0, 1.0, n) - 2.0,
    )
    eve = (evaluation_date(year).timetuple().tm_yday - 1) * 24
    precip[eve + 12 : eve + 24] = 0.0
    return HourlyWeather(year=year, temp_f=temp, precip_in=np.round(precip, 3), wind_mph=wind, source=f"synthetic weather (seed {seed})")


def _ar1(rng: np.random.Generator, n: int, phi: float, sigma: float) -> np.ndarray:
    noise = rng.normal(0.0, sigma * np.sqrt(1 - phi**2), n)
    out = np.empty(n)
    out[0] = rng.normal(0.0, sigma)
    for i in range(1, n):
        out[i] = phi * out[i - 1] + noise[i]
    return out


def weather_factor(weather: HourlyWeather) -> np.ndarray:
    """Demand multiplier per hour: rain +15–30 %, below 25 °F +6 %, above 88 °F +5 %, gales +3 %."""
    rain = np.where(weather.precip_in >= 0.01, 0.15 + 0.15 * np.minimum(weather.precip_in / 0.25, 1.0), 0.0)
    return 1.0 + rain + 0.06 * (weather.temp_f < 25) + 0.05 * (weather.temp_f > 88) + 0.03 * (weather.wind_mph > 25)

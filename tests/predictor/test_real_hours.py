"""The temporal network on the real hourly totals: the table's baselines are what they say, and its CIs bracket its means."""

from __future__ import annotations

import datetime as dt
import os
from pathlib import Path

import numpy as np
import pytest

SHARED = Path(os.environ.get("SURGE_SHARED_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
needs_hourly = pytest.mark.skipif(not (SHARED / "nyc" / "trips" / "manhattan_hourly_trips_2019_2024.parquet").exists(),
                                  reason="../shared/data trips files not available")


@needs_hourly
def test_real_hours_table_on_one_epoch() -> None:
    from predictor.real_hours import HOURS, real_series, run

    doc = run(SHARED, epochs=1)
    y, weather, holidays, source = real_series(SHARED)
    assert source == "manhattan_hourly_trips_2019_2024.parquet" and weather.shape == (8760, 3)
    assert set(doc["network"]["variants"]) == {"all_features", "without_month"}
    hour = np.arange(8760) % 24
    test = np.array([(dt.datetime(2022, 1, 1) + dt.timedelta(hours=int(h))).month >= 9 for h in range(8760)])
    for h in HOURS:
        row = doc["by_hour"][h]
        sel = np.flatnonzero(test & (hour == h))
        assert row["test_days"] == len(sel) == 122
        previous = np.mean(np.abs(y[sel] - y[sel - 1]) / y[sel]) * 100
        week = np.mean(np.abs(y[sel] - y[sel - 168]) / y[sel]) * 100
        assert row["previous_hour"]["pe_pct"] == pytest.approx(previous, abs=0.006)
        assert row["same_hour_last_week"]["pe_pct"] == pytest.approx(week, abs=0.006)
        for key in ("temporal_nn", "nn_without_month", "previous_hour", "profile_2018"):
            lo, hi = row[key]["ci95"]
            assert lo <= row[key]["pe_pct"] <= hi

"""Tests of the demand world: determinism, exact counts, assignment, OD, the evaluation surge, text, records."""

from __future__ import annotations

import datetime as dt
import random
import re
import time

import numpy as np
import pytest

from city.demand import (
    EVAL_DATE,
    PROFILE,
    REF_RATE,
    RecordedWorld,
    SyntheticWorld,
    estimate_beta,
    evaluation_date,
    find_anchors,
    holiday_dates,
    surge_report,
    synthetic_weather,
    synthetic_world,
)
from city.demand.attendance import draw_attendance, write_events
from city.demand.venues import schedule
from city.errors import ConfigError
from city.graph import City
from city.io.occupancy import LOCALE_TYPES
from city.io.poi import Pois
from city.io.weather import HourlyWeather, hours_in_year
from tests.conftest import grid_edges

EVE_19 = dt.datetime.combine(EVAL_DATE, dt.time(19))


def grid_city(side: int = 8, names: tuple[str, ...] = ("Times Sq/Theatre District", "Penn Station/Madison Sq West", "Clinton West", "Battery Park")) -> City:
    """A two-way ``side × side`` grid in four quadrant sectors; the last node of each sector cannot pick up."""
    xy, u, v = grid_edges(side)
    half = side // 2 * 100.0
    sector = (xy[:, 0] >= half).astype(int) + 2 * (xy[:, 1] >= half).astype(int)
    pickup = np.ones(side * side, dtype=bool)
    for s in range(4):
        pickup[np.flatnonzero(sector == s)[-1]] = False
    return City.build("grid", xy, u, v, np.full(len(u), 100.0), sector, list(names), pickup=pickup)


@pytest.fixture(scope="module")
def grid() -> City:
    return grid_city()


@pytest.fixture(scope="module")
def grid_world(grid: City) -> SyntheticWorld:
    return synthetic_world(grid, seed=3)


@pytest.fixture(scope="module")
def synth_city() -> City:
    synthetic = pytest.importorskip("city.synthetic", reason="city/synthetic.py (the embedded map) is not importable yet")
    return synthetic.synthetic_city(seed=0)


@pytest.fixture(scope="module")
def world(synth_city: City) -> SyntheticWorld:
    return synthetic_world(synth_city, seed=0)


def _counts_by_sector(city: City, nodes: np.ndarray) -> np.ndarray:
    return np.bincount(city.node_sector[nodes], minlength=city.n_sectors)


# ----------------------------------------------------------------- determinism
def test_same_seed_same_world_and_requests(synth_city: City, world: SyntheticWorld) -> None:
    again = synthetic_world(synth_city, seed=0)
    np.testing.assert_array_equal(world.hourly_counts(), again.hourly_counts())
    np.testing.assert_array_equal(world.expected_rate(), again.expected_rate())
    assert [(e.title, e.description, e.reviews, e.start) for e in world.events[::97]] == [(e.title, e.description, e.reviews, e.start) for e in again.events[::97]]
    # Requests depend on the hour, not on what was drawn before.
    again.requests(dt.date(2022, 3, 1), 8)
    a, b = world.requests(EVAL_DATE, 19), again.requests(EVAL_DATE, 19)
    for name in ("pickup", "dropoff", "entry"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_different_seed_differs(synth_city: City, world: SyntheticWorld) -> None:
    other = synthetic_world(synth_city, seed=1)
    assert not np.array_equal(world.hourly_counts(), other.hourly_counts())
    assert [e.title for e in world.events[:200]] != [e.title for e in other.events[:200]]
    assert not np.array_equal(world.requests(EVAL_DATE, 19).pickup, other.requests(EVAL_DATE, 19).pickup)


# ----------------------------------------------------------------- requests
@pytest.mark.parametrize("when", [EVE_19, dt.datetime(2022, 1, 1, 0), dt.datetime(2022, 7, 4, 3), dt.datetime(2022, 12, 31, 23)])
def test_requests_match_hourly_counts(world: SyntheticWorld, when: dt.datetime) -> None:
    req = world.requests(when.date(), when.hour)
    counts = world.hourly_counts()[world.hour_index(when)]
    np.testing.assert_array_equal(_counts_by_sector(world.city, req.pickup), counts)
    assert world.city.pickup[req.pickup].all() and world.city.pickup[req.dropoff].all()
    assert req.entry.min() >= 0 and req.entry.max() < 60 and np.all(np.diff(req.entry) >= 0)


def test_requests_window_is_a_prefix_and_spans_hours(world: SyntheticWorld) -> None:
    full = world.requests(EVAL_DATE, 19)
    half = world.requests(EVAL_DATE, 19, minutes=30)
    assert len(half) == int((full.entry < 30).sum())
    assert set(zip(half.pickup, half.dropoff, half.entry)) <= set(zip(full.pickup, full.dropoff, full.entry))
    two = world.requests(EVAL_DATE, 19, minutes=120)
    nxt = world.requests(EVAL_DATE, 20)
    assert len(two) == len(full) + len(nxt)
    np.testing.assert_array_equal(np.sort(two.entry[two.entry >= 60] - 60), np.sort(nxt.entry))


def test_requests_are_fast(world: SyntheticWorld) -> None:
    world.requests(EVAL_DATE, 18)
    t0 = time.perf_counter()
    for h in range(24):
        world.requests(dt.date(2022, 5, 5), h)
    assert (time.perf_counter() - t0) / 24 < 0.05


def test_trips_are_short_to_medium(world: SyntheticWorld) -> None:
    req = world.requests(EVAL_DATE, 17)
    hops = world.city.dist[req.pickup, req.dropoff].mean()
    assert 8 <= hops <= 22


# ----------------------------------------------------------------- assignment and OD
@pytest.mark.parametrize("when", [dt.datetime(2022, 2, 2, 3), EVE_19, dt.datetime(2022, 8, 6, 12), dt.datetime(2022, 8, 7, 23)])
def test_rho_delta_sum_to_one_per_sector(grid_world: SyntheticWorld, when: dt.datetime) -> None:
    city = grid_world.city
    for dist in (grid_world.pickup_dist(when), grid_world.dropoff_dist(when)):
        assert dist.shape == (city.n_nodes,) and np.all(dist >= 0)
        np.testing.assert_allclose(np.bincount(city.node_sector, weights=dist, minlength=city.n_sectors), 1.0)
        assert np.all(dist[~city.pickup] == 0) and np.all(dist[city.pickup] > 0)


def test_rho_follows_occupancy(world: SyntheticWorld) -> None:
    """Hotels weigh more at night than at noon (occupancy schedules), so ρ changes with the hour."""
    night, noon = world.pickup_dist(dt.datetime(2022, 3, 2, 3)), world.pickup_dist(dt.datetime(2022, 3, 2, 12))
    hotel = world.locale_counts[:, LOCALE_TYPES.index("hotel")]
    assert hotel @ night > hotel @ noon


@pytest.mark.parametrize("when", [dt.datetime(2022, 1, 1, 0), EVE_19, dt.datetime(2022, 6, 8, 23)])
def test_beta_rows_sum_to_one(world: SyntheticWorld, when: dt.datetime) -> None:
    beta = world.od_matrix(when)
    S = world.city.n_sectors
    assert beta.shape == (S, S) and np.all(beta >= 0)
    np.testing.assert_allclose(beta.sum(axis=1), 1.0)


def test_beta_biased_toward_venue_before_start(world: SyntheticWorld) -> None:
    arena = world.anchors["arena"]
    nb = [s for s in world.city.local_sectors(arena) if s != arena]
    usual = world.od_matrix(dt.datetime(2022, 11, 17, 4))  # no event arrivals at 4 am: plain gravity
    event = world.od_matrix(EVE_19)
    assert np.all(event[nb, arena] > usual[nb, arena])


# ----------------------------------------------------------------- evaluation surge
def test_eval_date_is_the_paper_thursday() -> None:
    assert evaluation_date(2022) == EVAL_DATE == dt.date(2022, 11, 17) and EVAL_DATE.weekday() == 3


def test_eval_evening_has_broadway_arena_and_surge(world: SyntheticWorld) -> None:
    evening = [e for e in world.events if e.start.date() == EVAL_DATE and e.start.hour >= 18]
    kinds = {v.venue_id: v.kind for v in world.venues}
    assert any(e.category == "performing-arts" and kinds[e.venue_id] == "theatre" for e in evening)
    assert any(kinds[e.venue_id] == "arena" for e in evening)
    report = surge_report(world, EVAL_DATE, 19)
    # The expo's closing crowd is picked up at the convention centre: a clear pickup surge there.
    assert report[1]["ratio"] >= 2.0 and report[0]["events"] and report[1]["events"]
    assert world.anchors["expo"] in [r["sector"] for r in report[:3]]
    assert [r["ratio"] for r in report] == sorted((r["ratio"] for r in report), reverse=True)
    assert set(report[0]) == {"sector", "name", "expected", "usual", "ratio", "dropoffs", "usual_dropoffs", "events"}
    citywide, usual = sum(r["expected"] for r in report), sum(r["usual"] for r in report)
    assert citywide >= 1.15 * usual
    # The game's arrivals end at the arena: drop-offs into its sector run far above a usual Thursday.
    arena = world.anchors["arena"]
    h = world.hour_index(EVE_19)

    def into_arena(row: int) -> float:
        return float(world.expected_rate()[row] @ world.od_matrix(world.when(row))[:, arena])

    thursdays = [d * 24 + 19 for d in range(world.n_hours // 24) if world.when(d * 24).weekday() == 3]
    assert into_arena(h) >= 2.0 * np.median([into_arena(r) for r in thursdays])


def _tue_to_thu(world: SyntheticWorld, hour: int) -> np.ndarray:
    """Row indices of every Tuesday, Wednesday and Thursday of the year at ``hour`` (holidays left out)."""
    days = [d for d in range(world.n_hours // 24) if world.when(d * 24).weekday() in (1, 2, 3) and world.when(d * 24).date() not in holiday_dates(world.year)]
    return np.array(days) * 24 + hour


def test_base_profile_follows_the_real_data_shape(world: SyntheticWorld) -> None:
    """No planted dips: the citywide base of a typical weekday has the hourly shape of the real trips (PROFILE)."""
    base = world.base_rate()
    mean = np.array([base[_tue_to_thu(world, h)].sum(axis=1).mean() for h in range(24)])
    shape = PROFILE[1:4].mean(axis=0)
    np.testing.assert_allclose(mean / mean[19], shape / shape[19], rtol=0.04)
    assert 0.9 * REF_RATE <= mean[19] <= 1.15 * REF_RATE


def test_a_named_calendar_puts_its_holidays_on_the_sunday_profile() -> None:
    from city.demand.profile import MONTH_FACTOR, day_factors

    early_may = dt.date(2022, 5, 2)  # a UK bank holiday, a working Monday in the US
    assert early_may in holiday_dates(2022, "GB") and early_may not in holiday_dates(2022)
    row = early_may.timetuple().tm_yday - 1
    np.testing.assert_allclose(day_factors(2022, holiday_dates(2022, "GB"))[row], PROFILE[6] * MONTH_FACTOR[4])
    np.testing.assert_allclose(day_factors(2022)[row], PROFILE[0] * MONTH_FACTOR[4])


def test_calibration_of_a_typical_weekday(world: SyntheticWorld) -> None:
    """The documented target: events are 15–25 % of citywide demand at 19 h on a typical Tue–Thu
    (attendance × trips per attendee × the fleet's share; see city.demand.attendance)."""
    rate, base = world.expected_rate(), world.base_rate()
    totals = {h: rate[_tue_to_thu(world, h)].sum(axis=1).mean() for h in (15, 17, 19, 21)}
    assert totals[15] < totals[17] < totals[19] and totals[21] < totals[19]
    rows = _tue_to_thu(world, 19)
    share = 1.0 - base[rows].sum() / rate[rows].sum()
    assert 0.15 <= share <= 0.25, share
    # Afternoons carry little event demand; the evening's comes from shows, games and conferences ending.
    assert 1.0 - base[_tue_to_thu(world, 15)].sum() / rate[_tue_to_thu(world, 15)].sum() < 0.05


def test_events_are_the_unpredictable_evening_driver(world: SyntheticWorld) -> None:
    """Knowing the events pays where they are: on the test months' sector-hours at 17 h and 19 h
    where events add at least half the base, the true rate's percent error is well below the base
    rate's; and surges are spread over the map, on no fixed schedule."""
    rate, base, y = world.expected_rate(), world.base_rate(), world.hourly_counts().astype(np.float64)
    first_test = (dt.date(world.year, 9, 1) - dt.date(world.year, 1, 1)).days * 24
    S = world.city.n_sectors

    def pe(pred: np.ndarray, mask: np.ndarray) -> float:
        ok = mask & (y > 0)
        return float((np.abs(y - pred) / np.where(y > 0, y, 1.0))[ok].mean())

    for h in (17, 19):
        rows = np.zeros(rate.shape, dtype=bool)
        rows[np.arange(first_test + h, world.n_hours, 24)] = True
        surge = rows & (rate - base >= 0.5 * base)
        assert surge.sum() >= 100, h
        assert pe(rate, surge) < 0.8 * pe(base, surge), h
        doubled = (rate[rows[:, 0]] >= 2.0 * base[rows[:, 0]]).mean(axis=0)
        assert np.sum(doubled > 0) >= 0.2 * S, h
        assert doubled.max() < 0.6, h


def test_arrivals_end_at_the_venue_and_departures_start_there(world: SyntheticWorld) -> None:
    """The arena game (20:00–22:30): arrivals are drop-offs at the arena with pickups over the map;
    departures are pickups at the arena heading over the map; ρ and δ of the forecast say the same."""
    game = next(e for e in world.events if e.start.date() == EVAL_DATE and e.title.startswith("Knicks"))
    city = world.city
    before = world.requests(EVAL_DATE, 19)
    to_venue = before.dropoff == game.node
    assert to_venue.sum() >= 10 and (before.pickup == game.node).sum() <= 3
    assert len(np.unique(city.node_sector[before.pickup[to_venue]])) >= 5
    after = world.requests(EVAL_DATE, 22)
    from_venue = after.pickup == game.node
    assert from_venue.sum() >= 10 and (after.dropoff == game.node).sum() <= 3
    assert len(np.unique(city.node_sector[after.dropoff[from_venue]])) >= 5
    assert world.dropoff_dist(EVE_19)[game.node] > 0.2 and world.pickup_dist(EVE_19)[game.node] < 0.1
    assert world.pickup_dist(dt.datetime.combine(EVAL_DATE, dt.time(22)))[game.node] > 0.2


def test_text_does_not_depend_on_realised_attendance(grid: City) -> None:
    """Same events, different weather on the day (and so different realised attendance): identical text."""
    H = hours_in_year(2022)
    dry = HourlyWeather(2022, np.full(H, 60.0), np.zeros(H), np.full(H, 5.0), "dry")
    wet = HourlyWeather(2022, np.full(H, 60.0), np.full(H, 0.3), np.full(H, 5.0), "wet")
    a, b = synthetic_world(grid, seed=3, weather=dry), synthetic_world(grid, seed=3, weather=wet)
    att_a, att_b = (np.array([e.attendance for e in w.events]) for w in (a, b))
    assert np.mean(att_a != att_b) > 0.5
    assert [(e.title, e.description, e.reviews) for e in a.events] == [(e.title, e.description, e.reviews) for e in b.events]
    # And the text is written before attendance is drawn: the writer never sees it.
    venues = a.venues
    specs = schedule(venues, 2022, np.random.default_rng([3, 14]))
    events, ordered = write_events(specs, venues, random.Random("x"))
    with_att, _ = draw_attendance(ordered, events, venues, dry, seed=1)
    assert all(e.attendance is None for e in events) and all(e.attendance is not None for e in with_att)
    again, _ = write_events(specs, venues, random.Random("x"))
    assert [(e.title, e.description, e.reviews) for e in again] == [(e.title, e.description, e.reviews) for e in with_att]


def test_estimate_beta_uses_only_the_given_months(grid: City, grid_world: SyntheticWorld) -> None:
    trips_mod = pytest.importorskip("city.io.trips")
    times = np.array(["2022-01-10T08:00", "2022-01-11T09:00", "2022-10-03T08:00", "2022-10-04T08:00"], dtype="datetime64[m]")
    trips = trips_mod.TripTable(times, np.array([0, 0, 0, 0], np.int32), np.array([1, 1, 2, 3], np.int32), 4, 0)
    w = RecordedWorld(grid, trips, year=2022, seed=5)
    np.testing.assert_allclose(estimate_beta(w, months=range(1, 7))[0], [0, 1, 0, 0])
    np.testing.assert_allclose(estimate_beta(w, months=(10,))[0], [0, 0, 0.5, 0.5])
    beta = estimate_beta(grid_world, months=(1, 2))
    np.testing.assert_allclose(beta.sum(axis=1), 1.0)
    with pytest.raises(ConfigError, match="months"):
        estimate_beta(w, months=(0,))


def test_about_300_venues_and_thousands_of_events(world: SyntheticWorld) -> None:
    assert 250 <= len(world.venues) <= 350
    assert len(world.events) >= 2000
    assert {e.category for e in world.events} == {"conferences", "expos", "concerts", "festivals", "performing-arts", "community", "sports"}
    starts = [e.start for e in world.events]
    assert starts == sorted(starts)
    assert all(0 < len(e.reviews) <= 100 for e in world.events)


def test_events_active(world: SyntheticWorld) -> None:
    active = world.events_active(EVE_19)
    assert active and all(e.active(EVE_19) for e in active)
    assert {e.event_id for e in active} == {e.event_id for e in world.events if e.active(EVE_19)}


# ----------------------------------------------------------------- text
def test_text_carries_popularity_category_and_sentiment(world: SyntheticWorld) -> None:
    events = [e for e in world.events if e.category != "performing-arts"] + world.events[::20]
    att = np.array([e.attendance for e in events])
    n_reviews = np.array([len(e.reviews) for e in events])
    assert np.corrcoef(np.log1p(att), n_reviews)[0, 1] > 0.5
    hot = re.compile(r"sold.out|hottest|highly anticipated|few tickets|near-capacity", re.IGNORECASE)
    quiet = re.compile(r"quiet|small gathering|handful|modest turnout|plenty of tickets", re.IGNORECASE)
    for cat in ("concerts", "community", "sports", "expos"):
        sel = [e for e in events if e.category == cat]
        loud = [e.attendance for e in sel if hot.search(e.title + " " + e.description)]
        calm = [e.attendance for e in sel if quiet.search(e.description)]
        assert loud and calm and np.median(loud) > 1.5 * np.median(calm), cat
    vocab = {"sports": "game", "expos": "exhibitor", "concerts": "music", "conferences": "keynote"}
    for cat, word in vocab.items():
        sel = [e for e in events if e.category == cat]
        assert np.mean([word in (e.title + e.description).lower() for e in sel]) > 0.3, cat
    positive = re.compile(r"amazing|fantastic|incredible|wonderful|superb|outstanding|brilliant|loved", re.IGNORECASE)

    def pos_share(e) -> float:
        return np.mean([bool(positive.search(r)) for r in e.reviews])

    glowing = [pos_share(e) for e in events if "glowing" in e.description or "rave" in e.description]
    harsh = [pos_share(e) for e in events if "harsh" in e.description or "poor" in e.description]
    assert np.mean(glowing) > np.mean(harsh) + 0.2


# ----------------------------------------------------------------- options and errors
def test_demand_scale_and_given_weather(grid: City, grid_world: SyntheticWorld) -> None:
    H = hours_in_year(2022)
    dry = HourlyWeather(2022, np.full(H, 60.0), np.zeros(H), np.full(H, 5.0), "test")
    a = synthetic_world(grid, seed=3, weather=dry)
    b = synthetic_world(grid, seed=3, weather=dry, demand_scale=2.0)
    assert a.weather is dry
    np.testing.assert_allclose(b.expected_rate(), 2 * a.expected_rate())
    wet = HourlyWeather(2022, np.full(H, 60.0), np.full(H, 0.3), np.full(H, 5.0), "wet")
    c = synthetic_world(grid, seed=3, weather=wet)
    assert 1.15 < c.base_rate().sum() / a.base_rate().sum() < 1.35


def test_bad_arguments(grid: City, grid_world: SyntheticWorld) -> None:
    with pytest.raises(ConfigError, match="outside"):
        grid_world.requests(dt.date(2021, 12, 31), 10)
    with pytest.raises(ConfigError, match="hour"):
        grid_world.requests(EVAL_DATE, 24)
    with pytest.raises(ConfigError, match="minutes"):
        grid_world.requests(EVAL_DATE, 10, minutes=0)
    with pytest.raises(ConfigError, match="past the end"):
        grid_world.requests(dt.date(2022, 12, 31), 23, minutes=61)
    with pytest.raises(ConfigError, match="outside"):
        grid_world.hour_index(dt.datetime(2023, 1, 1))
    with pytest.raises(ConfigError, match="demand_scale"):
        synthetic_world(grid, demand_scale=0)
    with pytest.raises(ConfigError, match="weather"):
        synthetic_world(grid, year=2022, weather=synthetic_weather(2021, 0))


def test_anchors_from_info_names_or_size(grid: City, synth_city: City) -> None:
    assert find_anchors(grid) == {"theater": 0, "arena": 1, "expo": 2, "park": 3}
    assert find_anchors(synth_city) == {k: synth_city.info["anchors"][k] for k in ("theater", "arena", "expo", "park")}
    plain = grid_city(names=("a", "b", "c", "d"))
    assert sorted(find_anchors(plain).values()) == [0, 1, 2, 3]


def test_real_pois_without_restaurants(grid: City) -> None:
    """Restaurant counts are synthesised from retail when the POI file has (almost) none."""
    xy = grid.xy[::5]
    pois = Pois(xy[:, 0], xy[:, 1], np.array(["retail", "hotel"] * (len(xy) // 2) + ["retail"] * (len(xy) % 2)), np.array(["p"] * len(xy)))
    w = synthetic_world(grid, seed=3, pois=pois)
    retail, restaurant = (w.locale_counts[:, LOCALE_TYPES.index(k)] for k in ("retail", "restaurant"))
    np.testing.assert_allclose(restaurant, retail)
    assert any("restaurant" in n for n in w.notes)


# ----------------------------------------------------------------- recorded world
def test_recorded_world_reproduces_its_records(grid: City) -> None:
    trips_mod = pytest.importorskip("city.io.trips", reason="city/io/trips.py is not importable")
    times = np.array(
        ["2022-11-17T19:05", "2022-11-17T19:05", "2022-11-17T19:59", "2022-11-17T20:00", "2022-03-01T08:30", "2021-12-31T23:59"],
        dtype="datetime64[m]",
    )
    pu = np.array([0, 1, 1, 3, 2, 0], dtype=np.int32)
    do = np.array([1, 1, 2, 0, 3, 0], dtype=np.int32)
    trips = trips_mod.TripTable(request_time=times, pickup_sector=pu, dropoff_sector=do, n_read=6, n_dropped=0)
    w = RecordedWorld(grid, trips, year=2022, seed=5)
    counts = w.hourly_counts()
    h = w.hour_index(EVE_19)
    np.testing.assert_array_equal(counts[h], [1, 2, 0, 0])
    assert counts.sum() == 5  # the 2021 record is outside the year
    np.testing.assert_array_equal(w.expected_rate(), counts)
    req = w.requests(EVAL_DATE, 19)
    np.testing.assert_array_equal(np.sort(req.entry), [5, 5, 59])
    np.testing.assert_array_equal(_counts_by_sector(grid, req.pickup), [1, 2, 0, 0])
    np.testing.assert_array_equal(np.sort(grid.node_sector[req.dropoff]), [1, 1, 2])
    again = RecordedWorld(grid, trips, year=2022, seed=5).requests(EVAL_DATE, 19)
    np.testing.assert_array_equal(req.pickup, again.pickup)
    beta = w.od_matrix(EVE_19)
    np.testing.assert_allclose(beta.sum(axis=1), 1.0)
    np.testing.assert_allclose(beta[1], [0, 0.5, 0.5, 0])
    assert len(w.requests(dt.date(2022, 3, 1), 8, minutes=20)) == 0 and len(w.requests(dt.date(2022, 3, 1), 8)) == 1
    assert w.events == [] and w.locale_counts.shape == (grid.n_nodes, 4)

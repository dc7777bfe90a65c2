"""The text ceiling's parts: driver features from the world's own records, and the ridge reader of the text (< 30 s)."""

from __future__ import annotations

import numpy as np
import pytest

from city.demand import synthetic_world
from city.demand.attendance import fill_rate
from city.errors import ConfigError
from city.graph import City
from city.io.weather import hours_in_year
from predictor.ceiling import (
    ALPHAS,
    DRIVERS,
    FEATURES,
    TextReader,
    choose_alpha,
    event_drivers,
    out_of_fold,
    r2,
    sector_features,
)
from predictor.features import MetadataFeaturizer, events_by_hour_sector
from tests.conftest import grid_edges


def _grid_city(side: int = 8) -> City:
    """Four quadrant sectors named so that the world finds its theatre district, arena, convention centre and park."""
    xy, u, v = grid_edges(side)
    half = side // 2 * 100.0
    sector = (xy[:, 0] >= half).astype(int) + 2 * (xy[:, 1] >= half).astype(int)
    names = ["Times Sq/Theatre District", "Penn Station/Madison Sq West", "Clinton West", "Battery Park"]
    return City.build("grid", xy, u, v, np.full(len(u), 100.0), sector, names)


@pytest.fixture(scope="module")
def world():
    return synthetic_world(_grid_city(), seed=3)


def test_drivers_are_the_worlds_records(world) -> None:
    Y = event_drivers(world, world.events)
    assert Y.shape == (len(world.events), len(DRIVERS))
    for i in range(0, len(world.events), 997):
        s = world.event_specs[world.events[i].event_id]
        assert Y[i, 0] == pytest.approx(np.log1p(s.capacity * fill_rate(s.popularity, s.sentiment)))
        assert tuple(Y[i, 1:4]) == pytest.approx((s.popularity, s.sentiment, np.log1p(s.capacity)))
        assert (Y[i, 4], Y[i, 5]) == ((s.cue or "").startswith("Opening"), (s.cue or "").startswith("Final"))


def test_ceiling_features_are_nonzero_exactly_where_driver_events_are(world) -> None:
    H, S = hours_in_year(world.year), world.city.n_sectors
    groups = events_by_hour_sector(world.events, world.year, H, S)
    drivers = dict(zip((ev.event_id for ev in world.events), event_drivers(world, world.events)))
    rng = np.random.default_rng(0)
    hours, sectors = rng.integers(0, H, 20000), rng.integers(0, S, 20000)
    keys = list(zip(hours.tolist(), sectors.tolist()))
    F = sector_features(hours, sectors, groups, drivers)
    active = np.array([k in groups for k in keys])
    assert 100 < active.sum() < len(keys)
    assert np.array_equal((F != 0).any(axis=1), active)
    for col, cue in ((FEATURES.index("n_opening"), "Opening"), (FEATURES.index("n_final"), "Final")):
        with_cue = np.array([any((world.event_specs[ev.event_id].cue or "").startswith(cue) for ev in groups.get(k, [])) for k in keys])
        assert np.array_equal(F[:, col] > 0, with_cue)
    # a sector-hour's expected attendance is the sum over its events
    i = int(np.flatnonzero(active)[0])
    want = sum(float(np.expm1(drivers[ev.event_id][0])) for ev in groups[keys[i]])
    assert F[i, 0] == pytest.approx(np.log1p(want), rel=1e-5)


def test_the_drivers_tell_more_than_the_metadata(world) -> None:
    """Sector-hours the metadata network cannot tell apart (same count, categories, capacities) differ in their drivers."""
    H, S = hours_in_year(world.year), world.city.n_sectors
    groups = events_by_hour_sector(world.events, world.year, H, S)
    drivers = dict(zip((ev.event_id for ev in world.events), event_drivers(world, world.events)))
    meta = MetadataFeaturizer.from_world(world)
    seen: dict[bytes, set[bytes]] = {}
    for k in list(groups)[:3000]:
        f = sector_features(np.array([k[0]]), np.array([k[1]]), groups, drivers)[0]
        seen.setdefault(meta.sector_feature(groups[k]).tobytes(), set()).add(f.tobytes())
    assert max(len(v) for v in seen.values()) > 10


def test_a_world_without_records_is_refused(world) -> None:
    class Listed:
        events = world.events[:3]

    with pytest.raises(ConfigError, match="attendance drivers"):
        event_drivers(Listed(), Listed.events)


def test_reader_trains_and_predicts_in_shape() -> None:
    rng = np.random.default_rng(1)
    X = rng.normal(size=(240, 12))
    Z = X @ rng.normal(size=(12, 6)) * 0.05
    Y = np.column_stack([6 + 20 * Z[:, 0], 0.5 + Z[:, 1], 0.5 + Z[:, 2], 7 + 20 * Z[:, 3], 0.5 + Z[:, 4], 0.5 + Z[:, 5]])
    Y += rng.normal(scale=0.01, size=Y.shape)
    alpha, scores = choose_alpha(X[:160], Y[:160], X[160:200], Y[160:200])
    assert alpha in ALPHAS and set(scores) == {f"{a:g}" for a in ALPHAS}
    assert alpha <= 10.0  # nearly noiseless: little shrinkage wins
    reader = TextReader.fit(X[:160], Y[:160], alpha)
    P = reader.predict(X[200:])
    assert P.shape == (40, len(DRIVERS))
    assert (P[:, [1, 2, 4, 5]] >= 0).all() and (P[:, [1, 2, 4, 5]] <= 1).all() and (P[:, [0, 3]] >= 0).all()
    assert (r2(Y[200:], P) > 0.9).all()
    oof = out_of_fold(X[:160], Y[:160], alpha)
    assert oof.shape == (160, len(DRIVERS))
    assert not np.allclose(oof, reader.predict(X[:160]))
    assert (r2(Y[:160], oof) > 0.9).all()


def test_a_ceiling_job_names_its_training_seed_and_refuses_a_negative_one() -> None:
    from predictor.jobs import CeilingJob

    assert CeilingJob(model="m").command() == "surge predictor ceiling --model m"
    assert CeilingJob(model="m", train_seed=2).command() == "surge predictor ceiling --model m --train-seed 2"
    with pytest.raises(ConfigError, match="--train-seed must be >= 0, got -1"):
        CeilingJob(model="m", train_seed=-1).check()

"""Does the event network use the *text*?  Two tiny worlds that differ only in what their text says.

In both worlds every event is at the same venue, of the same category, at the
same hours, so the metadata network (event count, categories, capacities) sees
identical inputs for every event.  There is one every evening; half of them, drawn at random, triple the
evening demand around them; the rest add a fifth.  In the planted world the
description says which (a sold-out stadium show or a quiet acoustic set); in
the noise world the same descriptions are assigned by an independent coin.
The event network must beat the metadata network (95 % bootstrap CI of the
difference below zero) in the first and must not in the second.

Real parts: the packaged sentence-embedding model (offline), real torch
training with early stopping on the validation months, the real ablation.
Small networks and epoch caps keep it to seconds of training.
"""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest

from city.graph import City
from city.io.events import Event, Venue
from city.io.weather import HourlyWeather, hours_in_year
from tests.conftest import ListedWorld, grid_edges

BIG = ("Sold-out stadium concert tonight", "Every seat sold for the farewell tour", "Sold out: the biggest show of the year")
SMALL = ("Quiet acoustic set in the side room", "A small, half-empty matinee", "Low-key rehearsal open to a few guests")
VENUE_REVIEWS = ("Easy to reach by subway", "Clean venue, friendly staff", "Bars are pricey")


class TextSignalWorld(ListedWorld):
    """Two sectors, one venue, an event every evening; text planted or noise (see the module notes)."""

    def __init__(self, planted: bool, year: int = 2022, seed: int = 3) -> None:
        rng = np.random.default_rng(seed)
        xy, u, v = grid_edges(4)
        node_sector = (xy[:, 0] >= 200).astype(int)
        self.city = City.build("tiny", xy, u, v, np.full(len(u), 100.0), node_sector, ["west", "east"])
        self.year, self.seed = year, seed
        H = hours_in_year(year)
        hrs = np.arange(H) % 24
        # Flat weather: no seasonal trend for small networks to extrapolate from January-June into the
        # validation and test months, so the two worlds differ in their text alone.
        self.weather = HourlyWeather(year, np.full(H, 60.0), np.zeros(H), np.full(H, 5.0), "tiny")
        self.locale_counts = rng.integers(1, 4, size=(self.city.n_nodes, 4)).astype(float)
        self.venues = [Venue("arena", "Arena", 0, 0, 5000, "arena")]
        base = 20 + 15 * np.sin((hrs - 6) / 24 * 2 * np.pi).clip(0)
        rate = np.stack([base, 0.6 * base], axis=1)
        self.events: list[Event] = []
        self.big: list[bool] = []
        for k, day in enumerate(range(1, 364)):
            big = bool(rng.random() < 0.5)
            self.big.append(big)
            says_big = big if planted else bool(rng.random() < 0.5)
            start = dt.datetime(year, 1, 1) + dt.timedelta(days=day, hours=19)
            self.events.append(
                Event(
                    event_id=f"e{k}", title="Concert at the Arena", description=(BIG if says_big else SMALL)[k % 3],
                    category="concerts", start=start, end=start + dt.timedelta(hours=2), sector=0, node=0,
                    venue_id="arena", reviews=VENUE_REVIEWS,
                )
            )
            h0 = day * 24 + 17  # arrivals 17-19 h, the show, departures at 21 h
            rate[h0 : h0 + 5, 0] *= 3.0 if big else 1.2
        self._rate = rate
        self._counts = rng.poisson(rate)


def _text_gain(planted: bool, tmp_path) -> dict:
    """Pooled 15-21 h event-sector-hour row of the test months: event NN vs metadata NN."""
    from predictor.dataset import build_year_data
    from predictor.embed import Embedder
    from predictor.evaluate import evaluate
    from predictor.features import EventFeaturizer
    from predictor.model import train_model
    from predictor.train import TrainConfig

    world = TextSignalWorld(planted)
    data = build_year_data(world, EventFeaturizer(Embedder(None)), lead=2, lag=1)  # the surge's 17-21 h around the 19-21 h show
    # The standard and no-event networks do not enter event sector-hours: one epoch is enough for them.
    cfg = TrainConfig(epochs=1, lr=3e-3, batch_size=64, seed=0, patience=15)
    model = train_model(world, tmp_path, cfg=cfg, standard_hidden=(16, 16), event_hidden=(64, 64), event_epochs=150, scenario={"name": "tiny"}, beta_days=2, log=None, data=data)
    res = evaluate(model, data, n_boot=400)
    row = res["pooled"]["event_sector_hours"]
    assert row["n"] > 400 and model.meta["networks"]["metadata"]["n_train"] > 600
    return row


def test_text_features_differ_only_in_the_planted_world(tmp_path) -> None:
    """Sanity of the construction: identical metadata for every event; texts tell big from small only when planted."""
    from predictor.features import MetadataFeaturizer

    for planted in (True, False):
        w = TextSignalWorld(planted)
        meta = MetadataFeaturizer.from_world(w)
        assert len({meta.sector_feature([ev]).tobytes() for ev in w.events}) == 1
        big = np.array(w.big)
        says = np.array([ev.description in BIG for ev in w.events])
        agree = float(np.mean(big == says))
        assert agree == 1.0 if planted else 0.3 < agree < 0.7


@pytest.mark.parametrize("planted", [True, False], ids=["planted-signal", "noise-text"])
def test_event_network_beats_metadata_only_when_text_carries_signal(planted: bool, tmp_path) -> None:
    row = _text_gain(planted, tmp_path)
    d = row["diff_metadata_nn"]  # PE(event NN) - PE(metadata NN), bootstrap over test days
    if planted:
        assert d["ci"][1] < 0, row
        assert row["pe_event_nn"] < row["pe_shuffled_text_nn"], row  # it is the text, not the extra inputs
    else:
        assert d["ci"][1] >= 0, row  # no significant gain from noise text

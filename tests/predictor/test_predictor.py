"""Tests of the demand predictor on a tiny stand-in world (small settings, < 2 min on 2 cores)."""

from __future__ import annotations

import datetime as dt
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from city.graph import City
from city.io.events import Event
from city.io.weather import HourlyWeather, hours_in_year
from tests.conftest import ListedWorld, grid_edges

ROOT = Path(__file__).resolve().parents[2]


# --------------------------------------------------------------- stand-in world
class TinyWorld(ListedWorld):
    """A 4x4 grid in 2 sectors, a year of counts, and a few evening events with reviews."""

    def __init__(self, year: int = 2022, seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        side = 4
        xy, u, v = grid_edges(side)
        node_sector = (xy[:, 0] >= 200).astype(int)
        self.city = City.build("tiny", xy, u, v, np.full(len(u), 100.0), node_sector, ["west", "east"])
        self.year, self.seed = year, seed
        H = hours_in_year(year)
        hrs = np.arange(H) % 24
        self.weather = HourlyWeather(year, 50 + 20 * np.sin(np.arange(H) / H * 2 * np.pi), rng.exponential(0.01, H), rng.uniform(0, 15, H), "tiny")
        self.locale_counts = rng.integers(0, 4, size=(self.city.n_nodes, 4)).astype(float)
        base = 20 + 15 * np.sin((hrs - 6) / 24 * 2 * np.pi).clip(0)
        rate = np.stack([base, 0.6 * base], axis=1)
        good = ["Amazing show, loved every minute", "Fantastic performance and great seats", "Best night out in years"]
        bad = ["Terrible sound, long lines", "Overpriced and crowded", "Disappointing, would not return"]
        self.events: list[Event] = []
        for k, day in enumerate(range(3, 360, 4)):
            big = k % 2 == 0
            start = dt.datetime(year, 1, 1) + dt.timedelta(days=day, hours=18)
            ev = Event(
                event_id=f"e{k}",
                title=("Sold-out stadium concert" if big else "Quiet poetry reading"),
                description=("Huge crowds expected" if big else "A small gathering"),
                category="concerts",
                start=start,
                end=start + dt.timedelta(hours=2),
                sector=0,
                node=0,
                venue_id="v0" if big else "v1",
                reviews=tuple((good if big else bad) * 3),
                attendance=2000.0 if big else 50.0,
            )
            self.events.append(ev)
            h0 = day * 24 + 18
            rate[h0 : h0 + 2, 0] *= 3.0 if big else 1.1
        self._rate = rate
        self._counts = rng.poisson(rate)


@pytest.fixture(scope="module")
def world() -> TinyWorld:
    return TinyWorld()


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("surge-cache")


# --------------------------------------------------------------------- tests
def test_cli_import_is_light() -> None:
    code = "import sys, argparse, predictor, coordinator.cli.predictor; p=argparse.ArgumentParser(); coordinator.cli.predictor.add_parser(p.add_subparsers()); assert 'torch' not in sys.modules, 'torch imported'"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


def test_holidays_2022() -> None:
    from city.calendar import holidays_for
    from city.errors import ConfigError

    h = holidays_for(2022)
    for d in (dt.date(2022, 1, 17), dt.date(2022, 5, 30), dt.date(2022, 6, 20), dt.date(2022, 7, 4), dt.date(2022, 9, 5), dt.date(2022, 11, 24), dt.date(2022, 12, 26)):
        assert d in h, d
    assert dt.date(2022, 7, 5) not in h
    assert dt.date(2022, 2, 15) in holidays_for(2022, "US", "NY")  # Susan B. Anthony Day, New York only
    with pytest.raises(ConfigError, match="US has no subdivision 'ZZ'"):
        holidays_for(2022, "US", "ZZ")
    with pytest.raises(ConfigError, match="unknown country 'XX'"):
        holidays_for(2022, "XX")


def test_tiny_network_loss_falls(tmp_path: Path) -> None:
    from predictor.train import TrainConfig, fit

    rng = np.random.default_rng(0)
    X = rng.normal(size=(2000, 8)).astype(np.float32)
    y = (X @ rng.normal(size=8)).astype(np.float32)
    cfg = TrainConfig(epochs=4, lr=1e-3, batch_size=64, seed=0)
    res = fit("tiny", X, y, (32, 32), cfg, checkpoint=tmp_path / "ck.pt", log=None)
    assert res.losses[-1] < 0.5 * res.losses[0]
    # resume: a run that stopped after 2 epochs and resumed equals the straight run
    fit("tiny", X, y, (32, 32), TrainConfig(epochs=2, lr=1e-3, seed=0), checkpoint=tmp_path / "ck2.pt", log=None)
    res2 = fit("tiny", X, y, (32, 32), cfg, checkpoint=tmp_path / "ck2.pt", log=None)
    assert res2.resumed_from == 2
    assert np.allclose(res2.losses, res.losses)


def _train_tiny(world: TinyWorld, out: Path, cache: Path) -> Path:
    from predictor.model import train_model
    from predictor.train import TrainConfig

    # A window of 2 h before and 1 h after puts the tiny world's 18-20 h events on five of the hours 15-21.
    train_model(world, out, cfg=TrainConfig(epochs=2, lr=1e-3, seed=0, device="auto"), cache_dir=str(cache), standard_hidden=(32, 32),
                event_hidden=(64, 64), scenario={"name": "tiny"}, beta_days=3, lead_hours=2, lag_hours=1, log=None)
    return out


@pytest.fixture(scope="module")
def trained(world: TinyWorld, cache: Path, tmp_path_factory) -> Path:
    return _train_tiny(world, tmp_path_factory.mktemp("model"), cache)


def test_one_seed_trains_the_same_weights_whatever_the_cache_held(world: TinyWorld, trained: Path, tmp_path: Path) -> None:
    from predictor.embed import Embedder
    from predictor.features import event_text

    cache = tmp_path / "cache"
    # Half of the texts, in another order, embedded before training: their batches differ from training's own.
    Embedder(None, cache).embed([event_text(ev) for ev in world.events][::-2])
    again = _train_tiny(world, tmp_path / "model", cache)
    weights = sorted(f.name for f in trained.iterdir() if f.suffix in (".pt", ".npy"))
    assert weights and weights == sorted(f.name for f in again.iterdir() if f.suffix in (".pt", ".npy"))
    for name in weights:
        assert (trained / name).read_bytes() == (again / name).read_bytes(), name


def test_no_event_network_never_sees_event_hours(world: TinyWorld, cache: Path) -> None:
    from predictor.dataset import (
        Normaliser,
        build_year_data,
        event_training_set,
        standard_training_set,
    )
    from predictor.embed import Embedder
    from predictor.features import EventFeaturizer

    data = build_year_data(world, EventFeaturizer(Embedder(None, cache)))
    norm = Normaliser.fit(data)
    _, y_all = standard_training_set(data, norm)
    _, y_quiet = standard_training_set(data, norm, without_events=True)
    _, y_event = event_training_set(data, norm)
    assert len(y_event) > 0 and len(y_quiet) + len(y_event) == len(y_all)
    has = data.has_event()[: data.val_hour].ravel()
    assert np.array_equal(y_quiet, y_all[~has])


def test_a_model_embeds_on_the_kind_of_device_it_was_trained_on(trained: Path) -> None:
    from predictor.model import DemandModel

    m = DemandModel.load(trained)
    assert m.featurizer().embedder.device == m.meta["training"]["device_used"].split(":")[0]
    m.meta["training"]["device_used"] = "cuda:0"
    assert m.featurizer().embedder.device == ("cuda" if _has_cuda() else "cpu")


def test_saved_model_predicts_identically(world: TinyWorld, trained: Path, cache: Path) -> None:
    from predictor.dataset import build_year_data
    from predictor.evaluate import evaluate, predictions
    from predictor.model import DemandModel

    m1 = DemandModel.load(trained)
    m2 = DemandModel.load(trained)
    data = build_year_data(world, m1.featurizer(str(cache)), lead=m1.window[0], lag=m1.window[1])
    p1, p2 = predictions(m1, data), predictions(m2, data)
    for k in p1:
        assert np.array_equal(p1[k], p2[k])
    assert (p1["event_nn"] != p1["standard_nn"]).any()
    has = data.has_event()[data.split_hour :]
    H0, H, S = data.split_hour, data.n_hours, data.n_sectors
    hours = np.repeat(np.arange(H0, H), S)
    quiet = m1.predict_no_event(data.temporal[hours], data.weather[hours], np.tile(np.arange(S), H - H0)).reshape(H - H0, S)
    assert np.array_equal(p1["event_nn"][~has], quiet[~has])  # the system's no-event network outside events
    assert not np.array_equal(quiet, p1["standard_nn"])
    res = evaluate(m1, data, n_boot=200)
    assert [r["hour"] for r in res["rows"]] == list(range(15, 22))
    assert all(r["n"] > 0 and np.isfinite(r["pe_event_nn"]) for r in res["rows"])


def test_ablation_rows_and_intervals(world: TinyWorld, trained: Path, cache: Path, tmp_path: Path) -> None:
    from predictor.dataset import build_year_data
    from predictor.evaluate import (
        ROWS,
        evaluate,
        format_table,
        percent_error,
        plot,
        write_json,
    )
    from predictor.model import DemandModel

    model = DemandModel.load(trained)
    assert set(model.meta["networks"]) == {"standard", "no_event", "event", "metadata", "event_shuffled"}
    lead, lag = model.window
    data = build_year_data(world, model.featurizer(str(cache)), lead=lead, lag=lag)
    res = evaluate(model, data, n_boot=300, seed=1)
    assert res["schema"] == "surge.predictor.eval/1" and res["predictors"] == [k for k, _ in ROWS]
    S = data.n_sectors
    test = data.hours("test")
    assert sum(r["n"] > 0 for r in res["rows_event_sectors"]) >= 4
    for rows in (res["rows"], res["rows_event_sectors"]):
        for r in rows:
            if r["n"] == 0:  # no event sector-hours at this hour: no estimate
                assert np.isnan(r["pe_event_nn"])
                continue
            for k in res["predictors"]:
                lo, hi = r[f"ci_{k}"]
                assert lo <= r[f"pe_{k}"] <= hi, (k, r)
            assert lo < hi
            assert r["diff_metadata_nn"]["ci"][0] <= r["diff_metadata_nn"]["mean"] <= r["diff_metadata_nn"]["ci"][1]
    # the noise floor is the world's own λ, scored like the rest
    idx = np.array([h for h in test if h % 24 == 19])
    y = data.counts[idx].ravel()
    lam = world.expected_rate()[idx].ravel()
    pe, n = percent_error(y, lam, np.tile(np.arange(S), len(idx)), S)
    row19 = res["rows"][19 - 15]
    assert row19["pe_true_rate"] == pytest.approx(pe) and row19["n"] == n
    again = evaluate(model, data, n_boot=300, seed=1)
    assert json.dumps(again) == json.dumps(res)  # one seed, one result (NaN where no event sector-hours)
    assert "event_nn minus" in format_table(res)
    write_json(res, tmp_path / "pe.json")
    plot(res, tmp_path / "pe.png", title="tiny")
    assert (tmp_path / "pe.png").stat().st_size > 1000


def test_splits_are_disjoint_and_cover_the_year(world: TinyWorld, cache: Path) -> None:
    from predictor.assign import estimate_beta
    from predictor.dataset import (
        Normaliser,
        build_year_data,
        event_training_set,
        standard_training_set,
    )
    from predictor.embed import Embedder
    from predictor.features import EventFeaturizer, year_hours

    data = build_year_data(world, EventFeaturizer(Embedder(None, cache)))
    parts = {p: data.hours(p) for p in ("train", "val", "test")}
    when = year_hours(data.year)
    months = {p: {when[h].month for h in r} for p, r in parts.items()}
    assert months == {"train": set(range(1, 7)), "val": {7, 8}, "test": set(range(9, 13))}
    sets = [set(r) for r in parts.values()]
    assert not (sets[0] & sets[1]) and not (sets[0] & sets[2]) and not (sets[1] & sets[2])
    assert set().union(*sets) == set(range(data.n_hours))
    rows = [set(data.event_rows(p).tolist()) for p in parts]
    assert sum(map(len, rows)) == len(data.ev_hour) and not (rows[0] & rows[1]) and not (rows[1] & rows[2])
    # nothing outside the training months shapes the networks' inputs or targets
    norm = Normaliser.fit(data)
    later = data.val_hour
    data.counts = data.counts.copy()
    data.counts[later:] *= 7
    data.weather = data.weather.copy()
    data.weather[later:] += 40
    data.ev_F = data.ev_F.copy()
    data.ev_F[data.ev_hour >= later] += 1.0
    assert Normaliser.fit(data).to_json() == norm.to_json()
    Xs, ys = standard_training_set(data, norm)
    assert len(ys) == later * data.n_sectors
    _, ye = event_training_set(data, norm)
    assert len(ye) == len(data.event_rows("train"))
    _, yv = standard_training_set(data, norm, part="val")
    assert len(yv) == (data.split_hour - later) * data.n_sectors
    # β: trips requested outside January-June do not enter
    from city.io.trips import TripTable

    t = np.array(["2022-03-01T10:00", "2022-03-01T11:00", "2022-10-01T10:00"], dtype="datetime64[m]")
    trips = TripTable(t, np.array([0, 0, 0], np.int32), np.array([1, 1, 0], np.int32), 3, 0)
    beta, info = estimate_beta(world, trips=trips)
    assert beta[0].tolist() == [0.0, 1.0] and info["trips"] == 2 and info["trips_outside_training_months"] == 1


def test_early_stopping_keeps_the_best_validation_epoch(tmp_path: Path) -> None:
    import torch

    from predictor.train import TrainConfig, fit

    rng = np.random.default_rng(0)
    X = rng.normal(size=(600, 8)).astype(np.float32)
    w = rng.normal(size=8)
    y = (X @ w + 0.5 * rng.normal(size=600)).astype(np.float32)
    Xv = rng.normal(size=(300, 8)).astype(np.float32)
    yv = (-(Xv @ w)).astype(np.float32)  # validation disagrees: its loss rises as training fits
    cfg = TrainConfig(epochs=100, lr=3e-3, seed=0, patience=3)
    res = fit("es", X, y, (16,), cfg, X_val=Xv, y_val=yv, checkpoint=tmp_path / "es.pt", log=None)
    assert res.stopped_early and len(res.losses) == res.best_epoch + 3 < 100
    assert res.best_epoch == int(np.argmin(res.val_losses)) + 1
    with torch.no_grad():
        kept = float(((res.net(torch.from_numpy(Xv)) - torch.from_numpy(yv)) ** 2).mean())
    assert kept == pytest.approx(min(res.val_losses), rel=1e-4)
    again = fit("es", X, y, (16,), cfg, X_val=Xv, y_val=yv, checkpoint=tmp_path / "es.pt", log=None)  # resumed: already stopped
    assert again.resumed_from == len(res.losses) and again.best_epoch == res.best_epoch
    assert all(torch.equal(a, b) for a, b in zip(again.net.state_dict().values(), res.net.state_dict().values()))


def test_device_auto_falls_back_to_cpu(monkeypatch: pytest.MonkeyPatch) -> None:
    import torch

    from city.errors import ConfigError
    from predictor.train import resolve_device

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert resolve_device("auto").type == "cpu"
    with pytest.raises(ConfigError, match="no CUDA device"):
        resolve_device("cuda")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert resolve_device("auto").type == "cuda"
    with pytest.raises(ConfigError, match="choose from"):
        resolve_device("tpu")


def _has_cuda() -> bool:
    import torch

    return torch.cuda.is_available()


@pytest.mark.skipif(not _has_cuda(), reason="no CUDA device")
def test_cuda_training_repeats_itself_and_tracks_the_cpu(tmp_path: Path) -> None:
    """The GPU path: one seed gives one network on a GPU, and the same run as the CPU up to rounding."""
    import torch

    from predictor.embed import Embedder
    from predictor.train import TrainConfig, fit, predict

    rng = np.random.default_rng(0)
    X = rng.normal(size=(3000, 24)).astype(np.float32)
    y = (np.tanh(X[:, :6]).sum(1) + 0.3 * rng.normal(size=3000)).astype(np.float32)
    Xv = rng.normal(size=(500, 24)).astype(np.float32)
    yv = np.tanh(Xv[:, :6]).sum(1).astype(np.float32)
    runs = {}
    for label, device in (("cuda", "cuda"), ("cuda again", "cuda"), ("cpu", "cpu"), ("auto", "auto")):
        cfg = TrainConfig(epochs=4, lr=1e-3, seed=3, patience=0, device=device)
        runs[label] = fit("gpu", X, y, (64, 64), cfg, X_val=Xv, y_val=yv, log=None)
    assert runs["cuda"].device.startswith("cuda") and runs["auto"].device.startswith("cuda") and runs["cpu"].device == "cpu"
    for other in ("cuda again", "auto"):
        assert runs[other].losses == runs["cuda"].losses
        assert all(torch.equal(a, b) for a, b in zip(runs[other].net.state_dict().values(), runs["cuda"].net.state_dict().values()))
    np.testing.assert_allclose(runs["cuda"].losses, runs["cpu"].losses, rtol=1e-4)
    np.testing.assert_allclose(predict(runs["cuda"].net, Xv), predict(runs["cpu"].net, Xv), atol=1e-3)
    texts = ["Knicks vs. Celtics - Sold-Out Crowd Expected", "Terrible sound, long lines", "a quiet evening"]
    on_gpu = Embedder(cache_dir=tmp_path / "gpu", device="cuda").embed(texts)
    on_cpu = Embedder(cache_dir=tmp_path / "cpu", device="cpu").embed(texts)
    cosine = (on_gpu * on_cpu).sum(1) / np.linalg.norm(on_gpu, axis=1) / np.linalg.norm(on_cpu, axis=1)
    assert cosine.min() > 0.9999


def test_recorded_inputs_must_match(tmp_path: Path) -> None:
    from city.errors import ConfigError
    from predictor.inputs import record_inputs, recorded_paths

    data, model = tmp_path / "data", tmp_path / "runs" / "m"
    data.mkdir()
    model.mkdir(parents=True)
    ev = data / "events.csv"
    ev.write_text("event_id,title\n")
    meta = {"inputs": record_inputs(model, events=str(ev))}
    assert meta["inputs"]["events"]["path"] == "../../data/events.csv"
    assert recorded_paths(meta, model)["events"] == model / "../../data/events.csv"
    moved = tmp_path / "elsewhere"
    (tmp_path / "runs").rename(moved)  # the model moves with its data beside it: found through the absolute path
    assert recorded_paths(meta, moved / "m")["events"].resolve() == ev.resolve()
    ev.write_text("event_id,title\nx,changed\n")
    with pytest.raises(ConfigError, match="changed since the model"):
        recorded_paths(meta, moved / "m")
    ev.unlink()
    with pytest.raises(ConfigError, match="no longer there"):
        recorded_paths(meta, moved / "m")


def test_trips_with_synthetic_events_refused() -> None:
    from city.errors import ConfigError
    from predictor.inputs import load_world

    with pytest.raises(ConfigError, match="--trips needs the real events"):
        load_world("synthetic", None, trips=["whatever.parquet"])


def test_forecast_and_assignment(world: TinyWorld, trained: Path, cache: Path) -> None:
    from predictor.forecaster import load_forecaster

    fc = load_forecaster(trained, cache_dir=str(cache))
    when = world.events[-1].start  # an event hour in the test months
    f = fc.forecast(world, when)
    eta, rho, delta, beta = f.eta, f.rho, f.delta, f.beta
    S, n = world.city.n_sectors, world.city.n_nodes
    assert eta.shape == (S,) and (eta >= 0).all()
    assert rho.shape == (n,) and delta.shape == (n,)
    for s in range(S):
        sel = world.city.node_sector == s
        assert rho[sel].sum() == pytest.approx(1.0)
        assert delta[sel].sum() == pytest.approx(1.0)
    assert beta.shape == (S, S) and np.allclose(beta.sum(axis=1), 1.0)


def test_malformed_event_file_clear_error(tmp_path: Path, world: TinyWorld) -> None:
    from city.errors import DataError
    from city.io.events import read_events

    bad = tmp_path / "events.csv"
    bad.write_text("event_id,title,start,end\nx1,Concert,not-a-date,2022-01-01 20:00\n")
    with pytest.raises(DataError) as info:
        read_events(bad, world.city)
    msg = str(info.value)
    assert "events.csv" in msg and "row" in msg, msg


def test_model_forecasts_from_the_events_it_was_trained_with(world: TinyWorld, trained: Path, tmp_path: Path) -> None:
    """A model trained with --events forecasts from that file's events, not the world's; a changed file is refused."""
    import shutil

    from city.errors import ConfigError
    from predictor.forecaster import ModelForecaster
    from predictor.inputs import record_inputs

    lon, lat = np.meshgrid(-73.990 + 0.001 * np.arange(4), 40.755 + 0.001 * np.arange(4))
    xy, u, v = grid_edges(4)
    city = City.build("tiny-lonlat", np.column_stack([lon.ravel(), lat.ravel()]), u, v, np.full(len(u), 100.0), (xy[:, 0] >= 200).astype(int), ["west", "east"], crs="lonlat")

    class Quiet:  # the served world: same sectors and weather, no events of its own
        def __init__(self) -> None:
            self.city, self.weather, self.locale_counts, self.events = city, world.weather, world.locale_counts, []
            self.holidays, self.schedules = world.holidays, world.schedules

    events = tmp_path / "events.json"
    events.write_text(json.dumps([{"id": "gig", "title": "Sold-out stadium concert", "description": "Huge crowds expected", "category": "concerts",
                                   "start": "2022-10-14 19:00", "end": "2022-10-14 21:00", "lat": 40.7555, "lon": -73.9895}]))
    model_dir = tmp_path / "model"
    shutil.copytree(trained, model_dir)
    meta = json.loads((model_dir / "model.json").read_text())
    meta["inputs"] = record_inputs(model_dir, events=str(events))
    (model_dir / "model.json").write_text(json.dumps(meta))
    when = dt.datetime(2022, 10, 14, 19)
    _, has_world = ModelForecaster(trained).predict_counts(Quiet(), when)
    with pytest.warns(UserWarning, match="forecasts from the 1 events it was trained with .--events., not this world's 0"):
        _, has_file = ModelForecaster(model_dir).predict_counts(Quiet(), when)
    assert not has_world.any() and has_file.tolist() == [True, False]
    events.write_text(events.read_text().replace("Huge", "Small"))
    with pytest.raises(ConfigError, match="changed since the model"):
        ModelForecaster(model_dir).predict_counts(Quiet(), when)

"""Shared fixtures: tiny hand-built cities and the real data directory."""

from __future__ import annotations

import datetime as dt
import os
from pathlib import Path

import numpy as np
import pytest

from city.graph import City
from city.sim import Requests

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


@pytest.fixture(autouse=True, scope="session")
def _isolated_cache(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Keep test artefacts out of the user's cache, but share them across the session."""
    os.environ.setdefault("SURGE_CACHE", str(tmp_path_factory.mktemp("surge-cache")))


@pytest.fixture(autouse=True, scope="session")
def _logging_as_the_cli_shows_it() -> None:
    """surge's log lines on stderr at INFO, one line each, as under the ``surge`` command (tests read them with capsys)."""
    from city.logs import setup

    setup("INFO")


def line_city(n: int = 5, two_way: bool = True, sectors: int = 1) -> City:
    """Nodes 0..n-1 on a line (a ring when one-way, so it stays strongly connected)."""
    u = list(range(n - 1))
    v = list(range(1, n))
    if two_way:
        u, v = u + v, v + u
    else:
        u.append(n - 1)
        v.append(0)
    xy = np.column_stack([np.arange(n) * 100.0, np.zeros(n)])
    node_sector = (np.arange(n) * sectors // n).astype(np.int32)
    lengths = np.full(len(u), 100.0)
    return City.build("line", xy, np.array(u), np.array(v), lengths, node_sector, [f"s{k}" for k in range(sectors)])


def grid_edges(side: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coordinates (100 m spacing) and two-way edges of a ``side × side`` street grid."""
    xy = np.array([(i % side, i // side) for i in range(side * side)], dtype=float) * 100.0
    u, v = [], []
    for i in range(side * side):
        x, y = i % side, i // side
        if x + 1 < side:
            u += [i, i + 1]
            v += [i + 1, i]
        if y + 1 < side:
            u += [i, i + side]
            v += [i + side, i]
    return xy, np.array(u), np.array(v)


class ListedWorld:
    """The stand-in worlds' common reading side: hourly counts, true rates and events held in lists.

    Subclasses set ``city``, ``year``, ``events``, ``_rate`` and ``_counts``; requests are the realised counts spread uniformly.
    They keep the default calendar: US federal holidays and the built-in occupancy schedules.
    """

    holidays = None
    schedules = None

    def hour_index(self, when: dt.datetime) -> int:
        return (when.date() - dt.date(self.year, 1, 1)).days * 24 + when.hour

    def hourly_counts(self) -> np.ndarray:
        return self._counts

    def expected_rate(self) -> np.ndarray:
        return self._rate

    def events_active(self, when: dt.datetime) -> list:
        return [ev for ev in self.events if ev.active(when)]

    def requests(self, date: dt.date, hour: int, minutes: int = 60) -> Requests:
        """The hour's realised count, spread uniformly over the map and the minutes (seeded by the hour)."""
        h = self.hour_index(dt.datetime.combine(date, dt.time(hour)))
        rng = np.random.default_rng(h)
        n = int(self._counts[h].sum() * minutes / 60)
        pick = rng.integers(0, self.city.n_nodes, n)
        drop = rng.integers(0, self.city.n_nodes, n)
        return Requests.sorted(pick, drop, rng.integers(0, minutes, n))


@pytest.fixture
def line5() -> City:
    return line_city(5)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(f"{SHARED_DATA} not found")
    return SHARED_DATA


@pytest.fixture(scope="session")
def synthetic_scenario():
    """The embedded synthetic city and its demand world (built once per session)."""
    from city.scenario import load_scenario

    return load_scenario("synthetic")


@pytest.fixture(scope="session")
def compiled_kernels(synthetic_scenario) -> None:
    """Compile the rollout kernels into numba's on-disk cache once, here, before agent processes need them.

    On a fresh checkout every spawned agent would otherwise compile them at once, on two cores.
    """
    from agents.rollout import warm_up

    warm_up(synthetic_scenario.city)

"""Venues and events: what the demand world generates and what users' event files hold."""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field

#: The event categories of the paper (PredictHQ names).
CATEGORIES: tuple[str, ...] = (
    "conferences",
    "expos",
    "concerts",
    "festivals",
    "performing-arts",
    "community",
    "sports",
)


@dataclass(frozen=True)
class Venue:
    venue_id: str
    name: str
    node: int
    sector: int
    capacity: int
    kind: str


@dataclass(frozen=True)
class Event:
    """One event at one venue; times are local, naive datetimes.

    ``attendance`` is known for synthetic events (ground truth that drives the
    surge) and ``None`` for real listings.
    """

    event_id: str
    title: str
    description: str
    category: str
    start: dt.datetime
    end: dt.datetime
    sector: int
    node: int
    venue_id: str = ""
    reviews: tuple[str, ...] = field(default_factory=tuple)
    attendance: float | None = None

    def active(self, hour_start: dt.datetime) -> bool:
        """Whether the event overlaps the hour beginning at ``hour_start``."""
        return self.start < hour_start + dt.timedelta(hours=1) and self.end > hour_start

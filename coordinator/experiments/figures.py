"""Figures of ``surge reproduce``: bars per hour and policy, the city map at the 7 pm surge, and a GIF of a surge hour."""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from city.graph import City
from city.logs import steps
from city.sim import FleetSim, Requests


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _streets(ax, city: City) -> None:
    from matplotlib.collections import LineCollection

    src = np.repeat(np.arange(city.n_nodes), np.diff(city.indptr))
    segs = np.stack([city.xy[src], city.xy[city.indices]], axis=1)
    ax.add_collection(LineCollection(segs, colors="#bbbbbb", linewidths=0.3, zorder=1))
    ax.set_aspect("equal" if city.crs != "lonlat" else 1 / np.cos(np.deg2rad(city.xy[:, 1].mean())))
    ax.set_xticks([])
    ax.set_yticks([])


def _size(city: City, panels: int = 1, extra: float = 0.0) -> tuple[float, float]:
    """A figure size following the city's aspect ratio, ``panels`` side by side."""
    span = np.ptp(city.xy, axis=0)
    aspect = float(span[1] / max(span[0], 1e-9))
    if city.crs == "lonlat":
        aspect /= np.cos(np.deg2rad(city.xy[:, 1].mean()))
    h = 7.5
    return (panels * h / max(aspect, 0.3) + extra + 0.5, h + 0.8)


def surge_map(city: City, world, date: dt.date, hour: int, taxis: np.ndarray, path: str | Path) -> None:
    """Sector demand of ``date`` ``hour`` as a heat map over the street graph, with the taxis and the venues of active events."""
    from city.demand import surge_report

    plt = _plt()
    expected = np.zeros(city.n_sectors)
    for row in surge_report(world, date, hour):
        expected[row["sector"]] = row["expected"]
    fig, ax = plt.subplots(figsize=_size(city, extra=1.8), dpi=110)
    _streets(ax, city)
    sc = ax.scatter(city.xy[:, 0], city.xy[:, 1], c=expected[city.node_sector], cmap="inferno_r", s=5, zorder=2)
    fig.colorbar(sc, ax=ax, shrink=0.7, label="expected requests in the hour (sector)")
    when = dt.datetime.combine(date, dt.time(hour))
    events = world.events_active(when)
    if events:
        nodes = np.array([e.node for e in events])
        ax.scatter(city.xy[nodes, 0], city.xy[nodes, 1], marker="*", s=160, c="#1f77b4", edgecolors="white", zorder=4,
                   label=f"venues with an event ({len(events)})")
    ax.scatter(city.xy[taxis, 0], city.xy[taxis, 1], marker="s", s=14, c="#2ca02c", edgecolors="black", linewidths=0.3, zorder=3,
               label=f"taxis ({len(taxis)})")
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(f"{city.name}: demand at {date} {hour:02d}:00,\ntaxis and event venues", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


@dataclass
class Track:
    """Per minute, where the taxis are and which requests wait, under one policy."""

    label: str
    pos: np.ndarray  # (T, m)
    busy: np.ndarray  # (T, m) bool
    waiting: list[np.ndarray]  # request indices per minute
    cost: list[int]
    served: int = 0


def track(city: City, policy, requests: Requests, start: np.ndarray, context, label: str) -> Track:
    """Run ``policy`` and record every minute (the same loop as :func:`coordinator.experiments.evaluate.run_episode`)."""
    from dataclasses import replace

    sim = FleetSim(city, requests, start)
    policy.reset(replace(context, future=requests) if policy.clairvoyant else context)
    pos, busy, waiting, cost = [], [], [], []
    with steps(context.minutes, "minute", f"replay {label}") as minutes:
        for _ in range(context.minutes):
            obs = sim.observe()
            pos.append(obs.pos.copy())
            busy.append(obs.tau > 0)
            waiting.append(obs.req_index.copy())
            cost.append(sim.step(policy.act(obs)))
            minutes.update()
    return Track(label, np.array(pos), np.array(busy), waiting, cost, int((sim.state.picked_at >= 0).sum()))


def surge_gif(city: City, requests: Requests, tracks: list[Track], path: str | Path, title: str) -> None:
    """Side-by-side animation of the tracks: taxis moving (free green, busy grey) and waiting requests (red)."""
    plt = _plt()
    from matplotlib.animation import FuncAnimation, PillowWriter

    fig, axes = plt.subplots(1, len(tracks), figsize=_size(city, len(tracks), extra=0.6), dpi=90)
    axes = np.atleast_1d(axes)
    artists = []
    for ax, tr in zip(axes, tracks):
        _streets(ax, city)
        req = ax.scatter([], [], s=10, c="#d62728", zorder=2)
        taxi = ax.scatter(city.xy[tr.pos[0], 0], city.xy[tr.pos[0], 1], s=12, marker="s", zorder=3)
        ax.autoscale_view()
        artists.append((ax, req, taxi, tr))
    fig.suptitle(title, fontsize=10)

    def frame(t: int):
        out = []
        for ax, req, taxi, tr in artists:
            w = tr.waiting[t]
            req.set_offsets(city.xy[requests.pickup[w]] if w.size else np.empty((0, 2)))
            taxi.set_offsets(city.xy[tr.pos[t]])
            taxi.set_color(np.where(tr.busy[t], "#7f7f7f", "#2ca02c"))
            ax.set_title(f"{tr.label}: minute {t}\nwaiting {w.size}, cost so far {sum(tr.cost[:t + 1])}", fontsize=8)
            out += [req, taxi]
        return out

    anim = FuncAnimation(fig, frame, frames=len(tracks[0].pos), blit=False)
    with steps(len(tracks[0].pos), "frame", f"GIF {Path(path).name}") as frames:
        anim.save(path, writer=PillowWriter(fps=4), progress_callback=lambda _i, _n: frames.update())
    plt.close(fig)

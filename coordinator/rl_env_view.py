"""The fleet environments' global state (for centralised critics) and their map drawing (``render``).

Kept apart from :mod:`coordinator.rl_env` because neither is part of an agent's
view: ``state()`` is what a centralised critic (MAPPO, QMIX) sees, and
``render()`` is for people.  Both read one episode's simulator observation.

The state vector, all entries in ``[0, 1]`` except the counts and rates::

    [0 : 6N]        per taxi i (N taxis), at 6i: x, y (0..1 over the map),
                    minutes until free / max hops, free, destination x, y (0 while free)
    [6N : 6N+S]     requests waiting in each of the S sectors
    [6N+S : 6N+2S]  the forecast rate η (requests a minute) of each sector
    [6N+2S]         minutes played / episode minutes
"""

from __future__ import annotations

import os
import sys

import numpy as np

from city.errors import ConfigError
from city.graph import City
from city.sim import Observation

TAXI_FEATURES = 6
#: The largest rate or count a state entry may hold: a finite bound keeps the Box well formed.
STATE_CAP = float(np.finfo(np.float32).max)


def display_available() -> bool:
    """Whether a window can be opened (``render_mode="human"``): macOS and Windows always, elsewhere with an X or Wayland display."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def render_modes() -> list[str]:
    """``rgb_array`` everywhere; ``human`` only where a display exists."""
    return ["rgb_array", "human"] if display_available() else ["rgb_array"]


def check_render_mode(mode: str | None) -> str | None:
    """The mode itself, or a one-line :class:`ConfigError` for a mode this machine cannot draw."""
    if mode is None or mode == "rgb_array":
        return mode
    if mode == "human":
        if not display_available():
            raise ConfigError("render_mode='human' needs a display (no DISPLAY or WAYLAND_DISPLAY); use render_mode='rgb_array'")
        return mode
    raise ConfigError(f"render_mode={mode!r} is not one of {render_modes()}")


def state_size(taxis: int, sectors: int) -> int:
    return TAXI_FEATURES * taxis + 2 * sectors + 1


def state_bounds(taxis: int, sectors: int) -> tuple[np.ndarray, np.ndarray]:
    """The state Box's low and high: fractions in [0, 1], counts and rates up to :data:`STATE_CAP`."""
    high = np.ones(state_size(taxis, sectors), dtype=np.float32)
    high[TAXI_FEATURES * taxis : TAXI_FEATURES * taxis + 2 * sectors] = STATE_CAP
    return np.zeros_like(high), high


def global_state(city: City, unit_xy: np.ndarray, obs: Observation, eta: np.ndarray, max_hops: float, minutes: int) -> np.ndarray:
    """The state vector of the module docstring for simulator observation ``obs``."""
    n, s = len(obs.pos), city.n_sectors
    out = np.zeros(state_size(n, s), dtype=np.float32)
    taxis = out[: TAXI_FEATURES * n].reshape(n, TAXI_FEATURES)
    taxis[:, 0:2] = unit_xy[obs.pos]
    taxis[:, 2] = np.minimum(obs.tau / max_hops, 1.0)
    busy = obs.tau > 0
    taxis[:, 3] = ~busy
    taxis[busy, 4:6] = unit_xy[obs.dest[busy]]
    base = TAXI_FEATURES * n
    out[base : base + s] = np.bincount(city.node_sector[obs.req_pickup], minlength=s)[:s]
    out[base + s : base + 2 * s] = np.clip(eta, 0.0, STATE_CAP)
    out[-1] = min(obs.t / max(1, minutes), 1.0)
    return out


def draw(city: City, obs: Observation, title: str) -> np.ndarray:
    """The map as an RGB image (uint8, height x width x 3): streets grey, free taxis green, busy blue, waiting requests red."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    span = np.ptp(city.xy, axis=0)
    aspect = float(np.clip(span[0] / span[1], 0.5, 2.0)) if span[1] > 0 else 1.0
    fig = Figure(figsize=(6 * min(1.0, aspect), 6 * min(1.0, 1 / aspect)), dpi=80, layout="tight")
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    _paint(ax, city, obs, title)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[:, :, :3].copy()


def show(city: City, obs: Observation, title: str, state: dict) -> None:
    """Draw the map in a window kept in ``state`` across calls (``render_mode="human"``)."""
    import matplotlib.pyplot as plt

    if "fig" not in state or not plt.fignum_exists(state["fig"].number):
        state["fig"] = plt.figure(figsize=(6, 6))
    fig = state["fig"]
    fig.clf()
    _paint(fig.add_subplot(), city, obs, title)
    fig.canvas.draw_idle()
    plt.pause(0.001)


def close(state: dict) -> None:
    if "fig" in state:
        import matplotlib.pyplot as plt

        plt.close(state.pop("fig"))


def _paint(ax, city: City, obs: Observation, title: str) -> None:
    from matplotlib.collections import LineCollection

    src = np.repeat(np.arange(city.n_nodes), np.diff(city.indptr))
    segments = np.stack([city.xy[src], city.xy[city.indices]], axis=1)
    ax.add_collection(LineCollection(segments, colors="0.8", linewidths=0.5, zorder=1))
    if obs.req_pickup.size:
        pts = city.xy[obs.req_pickup]
        ax.scatter(pts[:, 0], pts[:, 1], s=14, c="tab:red", marker="x", label="waiting request", zorder=2)
    free = obs.tau == 0
    for mask, colour, label in ((free, "tab:green", "free taxi"), (~free, "tab:blue", "busy taxi")):
        pts = city.xy[obs.pos[mask]]
        ax.scatter(pts[:, 0], pts[:, 1], s=22, c=colour, label=label, zorder=3)
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title, fontsize=9)
    ax.legend(loc="upper right", fontsize=7)

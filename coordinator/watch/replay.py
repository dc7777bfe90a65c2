"""A finished run played back from its results file: the world replayed with the run's committed controls, no bus.

The results file of ``surge fleet --json``, ``surge coordinator --json`` or
``surge demo`` holds every minute's joint control (``controls``), its
dependency waves (``waves``) and the run's settings (``config``); the
requests, start positions and forecast are rebuilt from those settings, as
the coordinator built them.  Each minute plays as one frame per wave (that
wave's taxis deciding), then one with every control committed.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from city.errors import ConfigError, DataError
from city.sim import FleetSim, decisions_hash
from coordinator.watch.citymap import city_map
from coordinator.watch.view import FleetView


@dataclass
class Replay:
    """Every frame of a run, encoded once; ``minute_ends[t]`` is the frame where minute ``t``'s controls are all in."""

    map: dict
    frames: list[str]
    minute_ends: list[int]
    summary: dict


def run_config(doc: dict, path: Path, fallback):
    """The run's :class:`~coordinator.run_config.FleetConfig`: its ``config`` entry, else ``fallback`` sized by the file."""
    from coordinator.run_config import FleetConfig

    known = {f.name for f in dataclasses.fields(FleetConfig)}
    if "config" in doc:
        extra = sorted(set(doc["config"]) - known)
        if extra:
            raise DataError(f"{path}: key 'config' has unknown settings {', '.join(extra)}")
        return FleetConfig(**doc["config"])
    return dataclasses.replace(fallback, taxis=int(doc["taxis"]), minutes=int(doc["minutes"]), policy=doc.get("policy", "surge"))


def read_results(path: str | Path) -> dict:
    """The results file, checked for what a replay needs."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text())
    except FileNotFoundError:
        raise ConfigError(f"--replay {p}: no such file") from None
    except ValueError as exc:
        raise DataError(f"{p}: not JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise DataError(f"{p}: expected a run's results (an object with 'controls'), as `surge fleet --json` writes")
    for k in ("controls", "taxis", "minutes"):
        if k not in doc:
            raise DataError(f"{p}: no key '{k}': not a run's results (`surge fleet --json`, `surge coordinator --json`, `surge demo`)")
    controls = np.asarray(doc["controls"], dtype=np.int64)
    if controls.ndim != 2 or controls.shape[1] != doc["taxis"]:
        raise DataError(f"{p}: key 'controls' must be one row of {doc['taxis']} controls per minute")
    if "decisions_sha256" in doc and decisions_hash(controls) != doc["decisions_sha256"]:
        raise DataError(f"{p}: key 'controls' does not hash to its 'decisions_sha256': the file was altered")
    return doc


def build_replay(path: str | Path, fallback) -> Replay:
    """Replay the results file at ``path`` into frames; ``fallback`` is the config to use when the file records none."""
    from agents.forecast_providers import make_provider

    p = Path(path)
    doc = read_results(p)
    cfg = run_config(doc, p, fallback)
    if doc.get("share") is not None:
        from city.scenario import SHARE_ENV

        os.environ[SHARE_ENV] = repr(float(doc["share"]))  # the world the run was built with (surge demo scales it)
    controls = np.asarray(doc["controls"], dtype=np.int32)
    scen, requests, start, _ = cfg.instance()
    city = scen.city
    provider = make_provider(cfg.forecast_name(), cfg.options.get("model"))
    played = len(controls)
    view = FleetView(city, cfg.taxis, played)
    episode_start = dt.datetime.combine(dt.date.fromisoformat(cfg.date), dt.time(cfg.hour))
    for h in range(-(-max(played, 1) // 60)):
        eta = provider.forecast(scen.world, episode_start + dt.timedelta(hours=h)).eta
        for s, v in enumerate(np.asarray(eta).tolist()):
            view.forecast(h, s, v)
    waves = doc.get("waves") or [[] for _ in range(played)]
    fell = {(int(t), int(a)) for t, a in doc.get("fallback_turns", [])}
    sim = FleetSim(city, requests, start)
    frames: list[str] = []
    minute_ends: list[int] = []
    costs: list[int] = []
    previous: set[int] = set()
    for t in range(played):
        obs = sim.observe()
        now = set(obs.req_index.tolist())
        new = np.array(sorted(now - previous), dtype=np.int64)
        picked = np.array(sorted(previous - now), dtype=np.int64)
        previous = now
        view.state(t, t == 0, obs.pos, obs.tau, (new, requests.pickup[new], requests.entry[new]), picked, len(now))
        order = [w["agents"] for w in waves[t]] if t < len(waves) else []
        for k, agents in enumerate(order):
            for a in agents:
                view.turn(t, a, k)
            frames.append(json.dumps(view.frame()))
            for a in agents:
                view.commit(t, a, int(controls[t, a]), "base" if (t, a) in fell else "agent")
        for a in np.flatnonzero(obs.tau == 0).tolist():
            view.commit(t, a, int(controls[t, a]), "base" if (t, a) in fell else "agent")
        frames.append(json.dumps(view.frame()))
        minute_ends.append(len(frames) - 1)
        try:
            costs.append(sim.step(controls[t]))
        except ValueError as exc:
            raise DataError(f"{p}: minute {t}: {exc}; the controls do not fit the run rebuilt from "
                            f"{cfg.scenario} {cfg.date} {cfg.hour}:00 seed {cfg.seed} (a file without 'config' "
                            f"needs the run's --scenario, --date, --hour and --seed)") from None
    res = sim.result(costs, controls, [])
    view.stop(played, "done", cost=res.total_cost, served=res.served)
    final = view.frame()
    frames.append(json.dumps(final))
    minute_ends.append(len(frames) - 1)
    if "total_cost" in doc and doc["total_cost"] != res.total_cost and played == doc["minutes"]:
        raise DataError(f"{p}: the replayed run costs {res.total_cost}, the file says {doc['total_cost']}: "
                        f"not the run rebuilt from {cfg.scenario} {cfg.date} {cfg.hour}:00 seed {cfg.seed}")
    summary = {"run": doc.get("run"), "policy": cfg.policy, "scenario": cfg.scenario, "date": cfg.date, "hour": cfg.hour,
               "seed": cfg.seed, "taxis": cfg.taxis, "minutes": played, "total_cost": res.total_cost, "served": res.served}
    return Replay(map=city_map(city, scen.world, dt.date.fromisoformat(cfg.date), cfg.hour, played), frames=frames,
                  minute_ends=minute_ends, summary=summary)

"""The coordinator's checkpoint: after each minute, everything a resumed coordinator needs to play the next one.

A run is a pure function of its :class:`~coordinator.run_config.FleetConfig`
and the controls committed so far, so the checkpoint holds the config, the
ground-truth fleet state after the last finished minute (positions, busy
times, destinations, which request each taxi picked up when) and the tally
the result is built from.  Each minute's rollout draws its random numbers
from ``(seed, t, agent)`` alone, so a coordinator resumed from minute ``t``
and agents that rejoin it make the decisions of an uninterrupted run.

The file is JSON, written to a temporary name and renamed over the old one,
so a coordinator killed while writing leaves the previous minute's
checkpoint intact.  It also keeps the writer's run epoch, so that a resumed
coordinator's epoch is higher even where clocks disagree.

A coordinator holds the run directory's lock file (:func:`locked`, a POSIX
``fcntl`` lock, which also holds across NFS) while it plays: a second one on
the same directory is refused in one line naming the holder.
"""

from __future__ import annotations

import datetime as dt
import fcntl
import json
import os
import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from city.errors import ConfigError, DataError
from city.sim import FleetSim, FleetState
from coordinator.metrics import Traffic

CHECKPOINT = "checkpoint.json"
LOCK = "lock"
VERSION = 2


@dataclass
class Tally:
    """What the run has done so far: the joint controls and what its result reports."""

    controls: np.ndarray
    costs: list[int] = field(default_factory=list)
    step_s: list[float] = field(default_factory=list)
    plan_s: list[float] = field(default_factory=list)
    planned: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    fallbacks: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    rss: np.ndarray = field(default_factory=lambda: np.zeros(0))
    stale: int = 0
    #: ``[minute, agent]`` of each turn the base control filled.
    fallen: list[list[int]] = field(default_factory=list)
    #: Per minute, its dependency waves as the result reports them (agents, seconds, agents' planning seconds).
    waves: list[list[dict]] = field(default_factory=list)
    traffic: Traffic = field(default_factory=Traffic)
    #: Each partition the clock paused for: its minute, the tokens gone, the seconds paused.
    partitions: list[dict] = field(default_factory=list)

    @staticmethod
    def fresh(minutes: int, taxis: int) -> Tally:
        return Tally(controls=np.zeros((minutes, taxis), dtype=np.int32), planned=np.zeros(taxis, dtype=np.int64),
                     fallbacks=np.zeros(taxis, dtype=np.int64), rss=np.zeros(taxis))


def save(run_dir: Path, config: dict, sim: FleetSim, tally: Tally, epoch: int = 0) -> Path:
    """Write the checkpoint of ``sim`` (after its last finished minute, by the coordinator of run epoch ``epoch``) atomically; its path."""
    s = sim.state
    doc = {
        "version": VERSION,
        "config": config,
        "epoch": epoch,
        "t": int(s.t),
        "sim": {"pos": s.pos.tolist(), "tau": s.tau.tolist(), "dest": s.dest.tolist(), "picked_at": s.picked_at.tolist()},
        "tally": {"controls": tally.controls[: s.t].tolist(), "costs": tally.costs, "step_s": tally.step_s,
                  "plan_s": tally.plan_s, "planned": tally.planned.tolist(), "fallbacks": tally.fallbacks.tolist(),
                  "rss": tally.rss.tolist(), "stale": tally.stale, "fallen": tally.fallen, "waves": tally.waves,
                  "traffic": asdict(tally.traffic), "partitions": tally.partitions},
    }
    run_dir.mkdir(parents=True, exist_ok=True)
    path = run_dir / CHECKPOINT
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(doc))
    os.replace(tmp, path)
    return path


def minutes_done(run_dir: Path) -> int:
    """How many minutes the checkpoint in ``run_dir`` holds (0 before the first): for a watcher of a run."""
    return int(_read(run_dir)["t"]) if (run_dir / CHECKPOINT).is_file() else 0


def epoch_of(run_dir: Path) -> int:
    """The run epoch of the coordinator that wrote the checkpoint in ``run_dir`` (0 if none is recorded)."""
    epoch = _read(run_dir).get("epoch", 0)
    if not isinstance(epoch, int) or isinstance(epoch, bool) or epoch < 0:
        raise DataError(f"field 'epoch' is {epoch!r}, expected a non-negative integer", path=run_dir / CHECKPOINT)
    return epoch


@contextmanager
def locked(run_dir: Path, run: str, epoch: int, wait_s: float = 0.0) -> Iterator[Path]:
    """Hold ``run_dir``'s lock file while the block runs, waiting up to ``wait_s`` seconds for another holder to let go.

    The lock file says who holds it (process, host, run, since when), for
    the one-line message a refused coordinator prints.  The kernel releases
    the lock when its holder exits, however it exits.
    """
    run_dir.mkdir(parents=True, exist_ok=True)
    path = run_dir / LOCK
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        deadline = time.monotonic() + wait_s
        while True:
            try:
                fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except OSError:
                if time.monotonic() >= deadline:
                    waited = f" (waited {wait_s:g} s)" if wait_s else ""
                    raise ConfigError(f"run directory {run_dir} is locked by {_holder(path)}{waited}: one coordinator plays "
                                      f"from a run directory; wait for it to end, or choose another --run-dir") from None
                time.sleep(0.2)
        since = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "run": run, "epoch": epoch,
                                  "since": since}).encode() + b"\n", 0)
        yield path
    finally:
        os.close(fd)  # releases the lock


def _holder(path: Path) -> str:
    """Who the lock file says holds it, in words."""
    try:
        doc = json.loads(path.read_text())
        return f"the coordinator of run {doc['run']!r} (process {doc['pid']} on {doc['host']}, since {doc['since']})"
    except (OSError, ValueError, KeyError, TypeError):
        return "another process"


def read_config(run_dir: Path) -> dict:
    """The run's config as the checkpoint in ``run_dir`` holds it."""
    return _read(run_dir)["config"]


def restore(run_dir: Path, sim: FleetSim, minutes: int) -> Tally:
    """Put ``sim`` in the checkpoint's state and return its tally; a checkpoint of another instance is an error."""
    path = run_dir / CHECKPOINT
    doc = _read(run_dir)
    try:
        t, raw, tal = int(doc["t"]), doc["sim"], doc["tally"]
        state = FleetState(t=t, pos=np.asarray(raw["pos"], dtype=np.int32), tau=np.asarray(raw["tau"], dtype=np.int32),
                           dest=np.asarray(raw["dest"], dtype=np.int32), picked_at=np.asarray(raw["picked_at"], dtype=np.int32))
        taxis = sim.n_taxis
        controls = np.zeros((minutes, taxis), dtype=np.int32)
        done = np.asarray(tal["controls"], dtype=np.int32).reshape(-1, taxis)
        tally = Tally(controls=controls, costs=[int(c) for c in tal["costs"]], step_s=[float(x) for x in tal["step_s"]],
                      plan_s=[float(x) for x in tal["plan_s"]], planned=np.asarray(tal["planned"], dtype=np.int64),
                      fallbacks=np.asarray(tal["fallbacks"], dtype=np.int64), rss=np.asarray(tal["rss"], dtype=float),
                      stale=int(tal["stale"]), fallen=[[int(t), int(a)] for t, a in tal["fallen"]], waves=list(tal["waves"]),
                      traffic=Traffic(**{k: int(v) for k, v in tal["traffic"].items()}),
                      partitions=[dict(p) for p in tal["partitions"]])
    except (AttributeError, KeyError, TypeError, ValueError) as exc:
        raise DataError(f"not a checkpoint of this version ({type(exc).__name__}: {exc})", path=path) from None
    if state.pos.shape != (taxis,) or state.tau.shape != (taxis,) or state.dest.shape != (taxis,):
        raise DataError(f"field 'sim' holds {state.pos.shape[0]} taxis, the run has {taxis}", path=path)
    if state.picked_at.shape != sim.state.picked_at.shape:
        raise DataError(f"field 'sim' holds {state.picked_at.shape[0]} requests, the run's instance has "
                        f"{sim.state.picked_at.shape[0]}: the data or the code changed since", path=path)
    if not 0 <= t <= minutes or done.shape[0] != t or len(tally.costs) != t:
        raise DataError(f"field 't' is {t} with {done.shape[0]} minutes of controls, the run has {minutes} minutes", path=path)
    for name in ("planned", "fallbacks", "rss"):
        if getattr(tally, name).shape != (taxis,):
            raise DataError(f"field 'tally.{name}' does not have one entry per taxi", path=path)
    controls[:t] = done
    sim.state = state
    return tally


def _read(run_dir: Path) -> dict:
    path = run_dir / CHECKPOINT
    if not path.is_file():
        raise DataError("no such file: nothing to resume (a coordinator writes it each minute with --run-dir)", path=path)
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise DataError(f"not readable as JSON ({exc})", path=path) from None
    if not isinstance(doc, dict) or doc.get("version") != VERSION or not isinstance(doc.get("config"), dict):
        raise DataError(f"not a surge checkpoint of version {VERSION}", path=path)
    return doc


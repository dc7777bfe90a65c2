"""The local multi-process fleet: a router, a coordinator and one process per taxi, on loopback.

The router, coordinator and predictor are started with the ``spawn`` context
of ``multiprocess`` (the stdlib API, pickling with dill); the agents are
forked by a fork server that has preloaded what every agent loads
(:func:`agent_context`, :mod:`agents.preload`), so that they share those
pages.  Every process opens its own zenoh session, after it starts; this
launcher and the fork server open none.  The bus is secured unless asked otherwise: the
launcher makes the run's credentials in the run's directory, and every
process joins over mutual TLS with its own certificate, under the router's
access control.  With ``check``, the same instance also runs in-process and
the two runs' decisions are compared.
"""

from __future__ import annotations

import json
import logging
import socket
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import multiprocess as mp
import numpy as np

from bus.certs import fleet_size, make_certs, taxi_name
from bus.router import free_tcp_port, router_main, wait_for_tcp
from bus.session import SessionArgs
from city.errors import ConfigError, SurgeError
from coordinator.run_config import FleetConfig

_logger = logging.getLogger(__name__)


def agent_context():
    """The context that starts agent processes: forked by a fork server that imported :mod:`agents.preload` first.

    The fork server is a fresh process (not a fork of this one, which may hold
    threads or a running OpenMP runtime); it opens no zenoh session, so each
    agent opens its own after the fork (``tests/coordinator/test_fleet_scale.py``).
    """
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(["agents.preload"])
    return ctx


def agent_entry(index: int, run: str, bus: SessionArgs, join_timeout_s: float, data_dir: str | None = None,
                 grace_s: float = 30.0, threads: int | str = "share") -> None:
    from agents.taxi import AgentConfig, agent_main

    sys.exit(agent_main(AgentConfig(index=index, run=run, bus=bus, join_timeout_s=join_timeout_s, data_dir=data_dir,
                                    grace_s=grace_s, threads=threads)))


def _coordinator_entry(cfg: FleetConfig, bus: SessionArgs, result_path: str, run_dir: str | None = None, resume: bool = False) -> None:
    import signal

    from coordinator.runtime import coordinator_main
    from coordinator.terminal import inherit as show_as_parent

    signal.signal(signal.SIGTERM, lambda signum, _: sys.exit(128 + signum))  # unwinds, so the run's stop goes out
    show_as_parent()  # the command's level, and a bar of the run's minutes where it shows bars
    try:
        coordinator_main(cfg, bus, result_path, run_dir=run_dir, resume=resume)
    except SurgeError as exc:
        _logger.error("%s", exc, extra={"who": "coordinator"})
        sys.exit(2)
    except KeyboardInterrupt:
        sys.exit(130)


def in_process(cfg: FleetConfig) -> dict:
    """The same instance under the in-process policy: the reference the distributed run must match."""
    from city.episode import run_episode

    scen, requests, start, context = cfg.instance()
    res = run_episode(scen.city, cfg.make_policy(scen.city), requests, start, context, show="in-process replay")
    return {"total_cost": res.total_cost, "served": res.served, "decisions_sha256": res.decisions_sha256,
            "step_seconds": {"median": float(np.median(res.plan_seconds)), "max": float(np.max(res.plan_seconds))}}


@dataclass
class RouterRestart:
    """Kill the run's router once the coordinator has checkpointed minute ``after_minute``, and start it again ``down_s`` later.

    A fault drill for a benchmark: every token vanishes at once, so the
    coordinator must take it for a partition and pause the clock.  The
    launcher fills in when the router went and came back (epoch seconds).
    """

    after_minute: int
    down_s: float = 1.0
    killed_at: float | None = None
    restarted_at: float | None = None

    def due(self, run_dir: str) -> bool:
        from coordinator.checkpoint import minutes_done

        return self.killed_at is None and minutes_done(Path(run_dir)) >= self.after_minute

    def summary(self) -> dict:
        return {"after_minute": self.after_minute, "down_s": self.down_s, "killed_at": self.killed_at,
                "restarted_at": self.restarted_at}


def check_port_free(port: int) -> None:
    """One-line :class:`ConfigError` when loopback ``port`` is taken, before any process starts."""
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError as exc:
            raise ConfigError(f"--port {port}: cannot listen on 127.0.0.1:{port} ({exc.strerror})") from None


def run_local_fleet(cfg: FleetConfig, *, secure: bool = True, certs: str | None = None, startup_timeout_s: float = 60.0,
                    watch: Callable[[list[int]], None] | None = None, run_dir: str | None = None,
                    resume: bool = False, agent_threads: int | str = "share", restart: RouterRestart | None = None,
                    port: int | None = None) -> dict:
    """Run ``cfg`` as real processes over a loopback router (on ``port``, default a free one); the coordinator's result.

    ``secure`` runs the bus with mutual TLS and access control, with the
    credentials in ``certs`` or, by default, new ones made in the run's
    temporary directory.  ``watch`` is called with the agents' process ids
    about once a second while the coordinator runs (a benchmark samples
    their memory).  The coordinator checkpoints each minute to ``run_dir``;
    ``resume`` continues the run checkpointed there, with a new router and
    new agents (they hold nothing a snapshot does not give them).
    ``agent_threads``: each agent's kernel threads (:attr:`agents.taxi.AgentConfig.threads`).
    ``restart`` kills and restarts the router mid-run (it needs ``run_dir``,
    whose checkpoint tells the minute).
    """
    from agents.rollout import warm_up

    if port is not None:
        check_port_free(port)
    warm_up()  # compile once here, not in every agent at once
    with tempfile.TemporaryDirectory(prefix="surge-fleet-") as tmp:
        if secure and certs is None:
            certs = str(Path(tmp) / "certs")
            make_certs(certs, cfg.taxis)
        elif secure and fleet_size(certs) < cfg.taxis:
            raise ConfigError(f"--certs {certs}: credentials for {fleet_size(certs)} taxis, the run has {cfg.taxis}")
        if restart is not None and run_dir is None:
            run_dir = str(Path(tmp) / "run")
        return _launch(cfg, certs if secure else None, str(Path(tmp) / "result.json"), startup_timeout_s, watch, run_dir, resume,
                       agent_threads, restart, port)


def _launch(cfg: FleetConfig, certs: str | None, result_path: str, startup_timeout_s: float,
            watch: Callable[[list[int]], None] | None = None, run_dir: str | None = None, resume: bool = False,
            agent_threads: int | str = "share", restart: RouterRestart | None = None, port: int | None = None) -> dict:
    ctx = mp.get_context("spawn")
    port = port or free_tcp_port()
    endpoint = f"{'tcp' if certs is None else 'tls'}/127.0.0.1:{port}"
    client = SessionArgs(mode="client", connect=[endpoint], certs=certs)
    procs: list = []
    router_args = SessionArgs(mode="router", listen=[endpoint], certs=certs, identity="router", run=cfg.run)

    def start_router():
        p = ctx.Process(target=router_main, args=(router_args,), name="surge-router")
        p.start()
        procs.append(p)
        return p

    router = start_router()
    try:
        wait_for_tcp("127.0.0.1", port, startup_timeout_s)
        if cfg.predictor:
            from predictor.serve import ServeConfig, serve_main

            serve = ServeConfig(run=cfg.run, scenario=cfg.scenario, data_dir=cfg.data_dir, world_seed=cfg.world_seed,
                                forecast=cfg.forecast_name(), model=cfg.options.get("model"))
            procs.append(ctx.Process(target=serve_main, args=(serve, client.as_identity("predictor")), name="surge-predictor"))
            procs[-1].start()
        coord = ctx.Process(target=_coordinator_entry, args=(cfg, client.as_identity("coordinator"), result_path, run_dir, resume),
                            name="surge-coordinator")
        coord.start()
        procs.append(coord)
        forks = agent_context()
        agents = [forks.Process(target=agent_entry, args=(i, cfg.run, client.as_identity(taxi_name(i)), cfg.join_timeout_s, None,
                                                           cfg.grace_s, agent_threads), name=f"surge-agent-{i}") for i in range(cfg.taxis)]
        launched_at = time.time()
        for p in agents:
            p.start()
        procs.extend(agents)
        while coord.is_alive():
            coord.join(1.0)
            if watch is not None:
                watch([p.pid for p in agents if p.pid is not None])
            if restart is not None and run_dir is not None and restart.due(run_dir):
                router.kill()
                router.join(10)
                restart.killed_at = time.time()
                time.sleep(restart.down_s)
                router = start_router()
                wait_for_tcp("127.0.0.1", port, startup_timeout_s)
                restart.restarted_at = time.time()
        if coord.exitcode != 0:
            raise ConfigError(f"the coordinator failed (exit code {coord.exitcode}); see its message above")
        result = json.loads(Path(result_path).read_text())
        deadline = time.monotonic() + 30
        for p in agents:
            p.join(max(0.1, deadline - time.monotonic()))
        result["agents_exit_codes"] = [p.exitcode for p in agents]
        result["launched_at"] = launched_at
        result["secured"] = certs is not None
        return result
    finally:
        for p in procs:
            if p.is_alive():
                p.terminate()
        for p in procs:
            p.join(10)




def resumed_config(run_dir: str) -> FleetConfig:
    """The config of the run checkpointed in ``run_dir``: a resumed run is the same run."""
    import dataclasses

    from coordinator.checkpoint import CHECKPOINT, read_config

    raw = read_config(Path(run_dir))
    names = {f.name for f in dataclasses.fields(FleetConfig)}
    unknown = sorted(set(raw) - names)
    if unknown:
        raise ConfigError(f"{Path(run_dir) / CHECKPOINT}: field 'config' has unknown settings {', '.join(unknown)}")
    return FleetConfig(**raw)



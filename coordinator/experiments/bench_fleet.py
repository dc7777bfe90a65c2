"""``surge bench fleet``: the distributed runtime against the sequential in-process policy, side by side in one session.

One command runs the instance twice on this machine, first as real processes
over a loopback router (one per taxi, turns in dependency waves), then
in-process with strictly sequential turns, and reports:

- whether the decisions are identical;
- the median minute of each, and their ratio;
- the agents' total memory as PSS (proportional set size: a page shared by
  ``k`` processes counts ``1/k`` to each), at its peak, sampled every 5 s,
  and the system memory in use at that peak against before launch;
- the seconds from launching the agents until all had joined;
- the messages and payload bytes through the coordinator per minute (the
  agents talk only to it);
- each minute's critical path (its number of waves) and the minute projected
  for the same agents on more hosts like this one
  (:func:`coordinator.metrics.project_minutes`): each wave's measured time
  split by the busiest host's share of its agents, never below its slowest
  agent planning alone in the sequential run;
- with ``--restart-router-after M``, the router killed once minute ``M`` is
  checkpointed and started again: how long the clock paused for the
  partition, how long the minute it hit took, and whether the decisions
  still equal the in-process ones.

It prints and writes JSON; it asserts nothing.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from city.logs import steps
from coordinator.metrics import median, project_minutes
from coordinator.run_config import FleetConfig


class PssSampler:
    """The peak over samples of the processes' total PSS, and the system memory in use then.

    Samples at most every ``interval_s`` seconds: reading a process's PSS walks
    its page tables, which takes CPU from the run being measured.
    """

    def __init__(self, interval_s: float = 5.0) -> None:
        self.before_mb = system_used_mb()
        self.peak_mb = 0.0
        self.per_agent_mb: list[float] = []
        self.system_mb = self.before_mb
        self.samples = 0
        self.interval_s = interval_s
        self._last = -float("inf")

    def __call__(self, pids: list[int]) -> None:
        if time.monotonic() - self._last < self.interval_s:
            return
        self._last = time.monotonic()
        sizes = [pss_mb(pid) for pid in pids]
        sizes = [s for s in sizes if s is not None]
        self.samples += 1
        if sum(sizes) > self.peak_mb:
            self.peak_mb, self.per_agent_mb, self.system_mb = sum(sizes), sizes, system_used_mb()

    def summary(self) -> dict:
        return {"agents_pss_mb": self.peak_mb, "agent_pss_mb_median": median(self.per_agent_mb),
                "agents_measured": len(self.per_agent_mb), "system_used_mb_before": self.before_mb,
                "system_used_mb_at_peak": self.system_mb, "samples": self.samples}


def pss_mb(pid: int) -> float | None:
    """A process's PSS in MB from ``/proc/PID/smaps_rollup``; ``None`` once it is gone."""
    try:
        for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines():
            if line.startswith("Pss:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def system_used_mb() -> float:
    """``MemTotal - MemAvailable`` from ``/proc/meminfo``, in MB."""
    info = {}
    for line in Path("/proc/meminfo").read_text().splitlines():
        name, _, rest = line.partition(":")
        info[name] = int(rest.split()[0])
    return (info["MemTotal"] - info["MemAvailable"]) / 1024


def sequential_in_process(cfg: FleetConfig) -> dict:
    """The instance in-process with strictly sequential turns (as ``RolloutPolicy.act`` without workers), each agent timed."""
    from agents.rollout import plan_agent
    from city.sim import FleetSim, decisions_hash
    from coordinator.experiments.results import demand_source

    scen, requests, start, context = cfg.instance()
    policy = cfg.make_policy(scen.city)
    policy.reset(context)
    sim = FleetSim(scen.city, requests, start)
    controls = np.zeros((cfg.minutes, cfg.taxis), dtype=np.int32)
    minute_s: list[float] = []
    plan_s: dict[tuple[int, int], float] = {}
    with steps(cfg.minutes, "minute", "in-process replay") as minutes:
        for t in range(cfg.minutes):
            obs = sim.observe()
            t0 = time.perf_counter()
            ctx = policy.step_context(obs)
            u = ctx.base_controls.copy()
            for agent in np.flatnonzero(obs.tau == 0).tolist():
                a0 = time.perf_counter()
                u[agent] = plan_agent(ctx, u[:agent], agent)
                plan_s[(t, agent)] = time.perf_counter() - a0
            minute_s.append(time.perf_counter() - t0)
            controls[t] = u
            sim.step(u)
            minutes.update()
    return {"decisions_sha256": decisions_hash(controls), "minute_seconds": minute_s, "plan_s": plan_s,
            "demand_source": demand_source(scen.world)}


def restart_report(dist: dict, restart: dict) -> dict:
    """The router drill's figures: the partitions the coordinator paused for, and the wall time of each minute they hit."""
    parts = dist["partitions"]
    return {**restart, "partitions": parts, "paused_s": sum(p["paused_s"] for p in parts),
            "hit_minute_seconds": [dist["minute_seconds"][p["minute"]] for p in parts],
            "router_away_s": (restart["restarted_at"] - restart["killed_at"]) if restart["killed_at"] else None}


def fleet_report(cfg: FleetConfig, dist: dict, seq: dict, memory: dict, hosts: list[int], agent_threads: int | str = "share",
                 restart: dict | None = None) -> dict:
    """The benchmark's figures from the two runs (see the module docstring).

    Per minute, the agents' own planning seconds (summed) stand beside the
    sequential planner's, so that planning slowed by sharing the cores is
    told from time lost between turns.
    """
    in_waves = [sum(w["seconds"] for w in minute) for minute in dist["waves"]]
    overhead = [max(0.0, m - w) for m, w in zip(dist["minute_seconds"], in_waves)]
    projected = {str(h): project_minutes(dist["waves"], seq["plan_s"], overhead, cfg.taxis, h) for h in hosts}
    projected["one per agent"] = project_minutes(dist["waves"], seq["plan_s"], overhead, cfg.taxis, None)
    d_med, s_med = median(dist["minute_seconds"]), median(seq["minute_seconds"])
    return {
        "schema": "surge.bench.fleet/1",
        "config": {"scenario": cfg.scenario, "taxis": cfg.taxis, "minutes": cfg.minutes, "date": cfg.date, "hour": cfg.hour,
                   "policy": cfg.policy, "options": cfg.options, "secured": dist.get("secured"), "agent_threads": agent_threads},
        "demand_source": seq["demand_source"],
        "same_decisions": dist["decisions_sha256"] == seq["decisions_sha256"],
        "decisions_sha256": {"distributed": dist["decisions_sha256"], "in_process": seq["decisions_sha256"]},
        "fallbacks": dist["fallbacks"],
        "minute_seconds": {"distributed_median": d_med, "sequential_in_process_median": s_med,
                           "ratio": d_med / s_med if s_med else None},
        "memory": memory,
        "ready_seconds": dist["joined_at"] - dist["launched_at"],
        "traffic": dist["traffic"],
        "critical_path": dist["critical_path"],
        "free_per_minute": dist["free_per_minute"],
        "projected_minute_seconds_median": {h: median(v) for h, v in projected.items()},
        "router_restart": restart_report(dist, restart) if restart is not None else None,
        "per_minute": [{"t": t, "free": dist["free_per_minute"][t], "critical_path": dist["critical_path"][t],
                        "distributed_s": dist["minute_seconds"][t], "sequential_s": seq["minute_seconds"][t],
                        "outside_waves_s": overhead[t],
                        "agents_plan_s": sum(p for w in dist["waves"][t] for p in w["plan_s"] if p is not None),
                        "sequential_plan_s": sum(s for (m, _), s in seq["plan_s"].items() if m == t),
                        **{f"projected_{h}_s": v[t] for h, v in projected.items()}}
                       for t in range(cfg.minutes)],
    }


def print_report(rep: dict) -> None:
    c, m, mem = rep["config"], rep["minute_seconds"], rep["memory"]
    hosts = [h for h in rep["projected_minute_seconds_median"]]
    print(f"{c['taxis']} agent processes ({c['agent_threads']} kernel threads each), {c['scenario']}, {c['minutes']} min from "
          f"{c['date']} {c['hour']}:00, {c['policy']}; "
          f"decisions {'identical' if rep['same_decisions'] else 'DIFFERENT'} ({rep['fallbacks']} fallbacks)")
    print(f"  {'t':>3} {'free':>4} {'waves':>5} {'distributed':>11} {'sequential':>10} {'agents plan':>11} {'seq. plan':>9} "
          + " ".join(f"{'on ' + h:>13}" for h in hosts))
    for row in rep["per_minute"]:
        print(f"  {row['t']:>3} {row['free']:>4} {row['critical_path']:>5} {row['distributed_s']:>10.3f}s {row['sequential_s']:>9.3f}s "
              f"{row['agents_plan_s']:>10.3f}s {row['sequential_plan_s']:>8.3f}s "
              + " ".join(f"{row[f'projected_{h}_s']:>12.3f}s" for h in hosts))
    ratio = m["ratio"]
    print(f"  median minute: distributed {m['distributed_median']:.3f} s, sequential in-process {m['sequential_in_process_median']:.3f} s, "
          f"ratio {ratio if ratio is None else f'{ratio:.2f}'}")
    print(f"  agents' memory: {mem['agents_pss_mb'] / 1024:.2f} GB PSS in all at the peak ({mem['agents_measured']} processes, median "
          f"{mem['agent_pss_mb_median'] or 0:.0f} MB each); system memory in use {mem['system_used_mb_at_peak'] / 1024:.2f} GB "
          f"(before launch {mem['system_used_mb_before'] / 1024:.2f} GB)")
    tr = rep["traffic"]
    print(f"  all agents ready {rep['ready_seconds']:.1f} s after launch; through the coordinator {tr['messages_per_minute']:.0f} messages "
          f"and {tr['bytes_per_minute'] / 1024:.1f} KiB per minute")
    print("  projected median minute: " + ", ".join(f"{h} hosts {v:.3f} s" if h.isdigit() else f"{h} {v:.3f} s"
                                                     for h, v in rep["projected_minute_seconds_median"].items()))
    r = rep["router_restart"]
    if r is None:
        return
    if r["killed_at"] is None:
        print(f"  router restart: the run ended before minute {r['after_minute']} was checkpointed; the router was not killed")
        return
    hits = ", ".join(f"the clock paused {p['paused_s']:.1f} s in minute {p['minute'] + 1} ({p['tokens_gone']} tokens gone; the minute "
                     f"took {s:.1f} s)" for p, s in zip(r["partitions"], r["hit_minute_seconds"])) or "the coordinator saw no partition"
    print(f"  router killed after minute {r['after_minute']} and back {r['router_away_s']:.1f} s later: {hits}")



"""What ``surge demo`` shows after the distributed run: surge against greedy on the same instance, a map and a GIF."""

from __future__ import annotations

from pathlib import Path


def surge_vs_greedy(cfg, fleet: dict, out: Path) -> list[str]:
    """Table lines comparing the distributed ``surge`` run, its in-process replay and ``greedy``; writes the map and the GIF.

    ``cfg`` is the run's :class:`coordinator.run_config.FleetConfig`; ``fleet`` the distributed run's result.
    """
    from agents.base import make_policy
    from coordinator.experiments import figures
    from coordinator.experiments.tables import text_table

    scen, requests, start, context = cfg.instance()
    city = scen.city
    tracks = [figures.track(city, cfg.make_policy(city), requests, start, context, cfg.policy),
              figures.track(city, make_policy("greedy", city), requests, start, context, "greedy")]
    out.mkdir(parents=True, exist_ok=True)
    map_path, gif_path = out / "demo-surge-map.png", out / "demo-surge-vs-greedy.gif"
    figures.surge_map(city, scen.world, context.date, cfg.hour, tracks[0].pos[len(tracks[0].pos) // 2], map_path)
    figures.surge_gif(city, requests, tracks, gif_path, f"{cfg.scenario} {cfg.date} {cfg.hour}:00, {cfg.taxis} taxis")
    rows = [(f"{cfg.policy} (distributed)", fleet["total_cost"], fleet["outstanding_end"], fleet["served"])]
    note = f"{cfg.policy} plans with the {cfg.forecast_name()} forecast ({cfg.rollout_config().approximations()}); greedy uses none"
    rows += [(f"{t.label} (in-process)", sum(t.cost), t.cost[-1], t.served) for t in tracks]
    n = len(requests)
    lines = [f"{cfg.taxis} taxis, {n} requests in {cfg.minutes} min from {cfg.date} {cfg.hour}:00 (same instance for every row)",
             text_table([("policy", "left"), ("total cost", "right"), ("outstanding end", "right"), ("served", "right")],
                        [[label, str(cost), str(end), f"{served} ({100 * served / max(n, 1):.0f} %)"] for label, cost, end, served in rows])]
    lines.append(note)
    g = sum(tracks[1].cost)
    lines.append(f"{cfg.policy} costs {100 * (sum(tracks[0].cost) - g) / max(g, 1):+.1f} % against greedy")
    lines += [f"wrote {map_path}", f"wrote {gif_path}"]
    return lines

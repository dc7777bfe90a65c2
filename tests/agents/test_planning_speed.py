"""Planning speed-ups: the exact shortcuts change no decision, approximations are deterministic, waves are sequential-equivalent."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import statistics
from pathlib import Path

import numpy as np
import pytest

from agents.base import make_policy
from agents.rollout import (
    DemandTables,
    HourInputs,
    RolloutConfig,
    Shortcuts,
    plan_agent,
    prepare_step,
)
from agents.rollout_config import default_prune
from agents.rollout_policy import EXACT
from agents.waves import plan_waves
from city.forecast import Forecast
from city.graph import City
from city.scenario import load_city
from city.sim import Observation
from tests.conftest import SHARED_DATA

H = 6
SAMPLES = 48


@pytest.fixture(scope="module", params=["synthetic", "nyc"])
def city(request: pytest.FixtureRequest) -> City:
    if request.param == "nyc":
        data = Path(os.environ.get("SURGE_TEST_DATA", SHARED_DATA))
        if not data.is_dir():
            pytest.skip("../shared/data not available")
        return load_city("nyc", data)
    return load_city("synthetic")


def forecast(city: City, rng: np.random.Generator) -> Forecast:
    """Uneven rates (some sectors below one request a minute, some above) and pickup weights."""
    S, n = city.n_sectors, city.n_nodes
    beta = rng.random((S, S)) + 0.1
    return Forecast(eta=rng.choice([0.0, 0.2, 0.6, 1.5], S), rho=rng.random(n), delta=rng.random(n), beta=beta / beta.sum(1, keepdims=True))


def seeded_state(city: City, seed: int, taxis: int = 60, requests: int = 50) -> Observation:
    """A mid-episode state: taxis clustered in part of the map (others far away), a third busy, requests waiting."""
    rng = np.random.default_rng(seed)
    nodes = np.flatnonzero(city.pickup)
    centre = nodes[rng.integers(nodes.size)]
    near = nodes[np.argsort(city.dist[centre, nodes], kind="stable")[: max(40, nodes.size // 6)]]
    pos = np.where(rng.random(taxis) < 0.75, rng.choice(near, taxis), rng.choice(nodes, taxis)).astype(np.int32)
    busy = rng.random(taxis) < 0.3
    dest = np.where(busy, rng.choice(nodes, taxis), -1).astype(np.int32)
    busy &= dest != pos
    dest[~busy] = -1
    tau = np.where(busy, np.maximum(1, city.dist[pos, np.maximum(dest, 0)]), 0).astype(np.int32)
    pick = rng.choice(near, requests).astype(np.int32)
    free = np.flatnonzero(~busy)[:4]
    pick[: free.size] = pos[free]
    drop = rng.choice(nodes, requests).astype(np.int32)
    entry = np.sort(rng.integers(0, 8, requests)).astype(np.int32)
    return Observation(8, pos, tau, dest, np.arange(requests), pick, drop, entry)


def decisions(city: City, obs: Observation, fc: Forecast, shortcuts: Shortcuts, **cfg) -> tuple[str, object]:
    """Every free agent's control in turn order, hashed, and the minute's counters."""
    config = RolloutConfig(horizon=H, samples=SAMPLES, prune=default_prune(H), **cfg)
    ctx = prepare_step(city, config, obs, DemandTables.build(city, fc, config.ce, config.seed), obs.t % 60, shortcuts)
    u = ctx.base_controls.copy()
    for agent in np.flatnonzero(obs.tau == 0):
        u[agent] = plan_agent(ctx, u[:agent], int(agent))
    return hashlib.sha256(u.tobytes()).hexdigest(), ctx.stats


SWITCHES = [f.name for f in dataclasses.fields(Shortcuts)]


def shortcuts_settled(city: City, seeds: range, **cfg) -> int:
    """Assert that all shortcuts, and each one flipped, give the decisions of none; count what they settled."""
    settled = 0
    for seed in seeds:
        obs = seeded_state(city, seed)
        fc = forecast(city, np.random.default_rng(seed))
        reference, _ = decisions(city, obs, fc, Shortcuts.none(), seed=seed, **cfg)
        full, stats = decisions(city, obs, fc, Shortcuts(), seed=seed, **cfg)
        assert full == reference, (seed, "all shortcuts")
        for name in SWITCHES:
            flipped = dataclasses.replace(Shortcuts(), **{name: not getattr(Shortcuts(), name)})
            assert decisions(city, obs, fc, flipped, seed=seed, **cfg)[0] == reference, (seed, name)
        settled += stats.shadowed + stats.skipped
    return settled


@pytest.mark.parametrize("base", ["greedy", "ia"])
def test_exact_shortcuts_change_no_decision(city: City, base: str) -> None:
    extra = {} if base == "greedy" else {"scope": "map", "ce": "standard"}
    settled = shortcuts_settled(city, range(2 if base == "greedy" else 1), base=base, **extra)
    if base == "greedy":
        assert settled > 0  # the shortcuts did take over work, so the comparison means something


@pytest.mark.parametrize("approx", [{"cap": 4}, {"adaptive": 2.0, "batch": 16, "cap": 6}])
def test_exact_shortcuts_change_no_decision_under_the_approximations(city: City, approx: dict) -> None:
    # Seed 0 binds the cap where ``reach`` drops taxis: when the cap ranked taxis after ``reach`` had
    # dropped some, flipping ``reach`` changed a decision here.
    assert shortcuts_settled(city, range(2), **approx) > 0


@pytest.mark.parametrize("approx", [{"adaptive": 2.0, "batch": 16}, {"cap": 8}])
def test_approximations_are_deterministic_for_a_seed(city: City, approx: dict) -> None:
    obs = seeded_state(city, 5)
    fc = forecast(city, np.random.default_rng(5))
    runs = [decisions(city, obs, fc, Shortcuts(), seed=3, **approx)[0] for _ in range(2)]
    assert runs[0] == runs[1]


GREEDY_LOCAL = {"base": "greedy", "scope": "local"}


@pytest.mark.parametrize(("name", "options", "approx"), [
    ("surge", {**EXACT, **GREEDY_LOCAL, "keep": None}, GREEDY_LOCAL),
    ("surge", {"batch": 16, **GREEDY_LOCAL}, {"adaptive": 1.0, "batch": 16, "cap": 12, "keep": 2.0, **GREEDY_LOCAL}),  # the approximations, in several batches
    ("surge", {"batch": 16}, {"adaptive": 1.0, "batch": 16, "cap": 12, "keep": 2.0, "base": "rebalance", "scope": "map"}),  # surge's defaults
    ("garces2023", {}, {"base": "ia", "scope": "map", "ce": "standard"}),
])
def test_waves_match_sequential_turns(city: City, name: str, options: dict, approx: dict) -> None:
    obs = seeded_state(city, 7, taxis=80)
    fc = forecast(city, np.random.default_rng(7))
    config = RolloutConfig(horizon=H, samples=SAMPLES, prune=default_prune(H), seed=1, **approx)
    hour = HourInputs.of(city, fc) if config.base == "rebalance" else None
    ctx = prepare_step(city, config, obs, DemandTables.build(city, fc, config.ce, config.seed), obs.t % 60, hour=hour)
    sequential = ctx.base_controls.copy()
    for agent in np.flatnonzero(obs.tau == 0):
        sequential[agent] = plan_agent(ctx, sequential[:agent], int(agent))
    waves = plan_waves(city, obs, config.prune)
    assert waves.critical_path < waves.agents.size  # some agents do plan side by side
    policy = make_policy(name, city, forecast="true-rate", workers=2, horizon=H, samples=SAMPLES, seed=1, **options)
    assert policy.config == config
    u = ctx.base_controls.copy()
    policy._act_waves(ctx, u)
    np.testing.assert_array_equal(u, sequential)
    assert plan_waves(city, obs, None).critical_path == waves.agents.size


def test_bench_plan_reports_variants_side_by_side(tmp_path: Path) -> None:
    from tests.coordinator.test_cli import run_cli

    out = tmp_path / "plan.json"
    proc = run_cli("bench", "plan", "--taxis", "12", "--samples", "8", "--horizon", "3", "--steps", "2", "--warmup", "2",
                   "--policies", "surge", "--forecast", "true-rate", "--variants", "all", "none", "with-minute_lists", "--workers", "2", "--json", str(out))
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(out.read_text())
    assert doc["demand_source"].startswith("synthetic profile")  # what the timed states' demand was made of
    res = doc["policies"]["surge"]
    assert set(res["variants"]) == {"all", "none", "with-minute_lists"}
    assert res["variants"]["all"]["hashes"] == res["variants"]["none"]["hashes"] == res["variants"]["with-minute_lists"]["hashes"]
    assert len(res["free_taxis"]) == len(res["critical_path"]) == len(res["seconds_per_free_taxi"]) == 2
    assert "ms per free taxi" in proc.stdout and "same decisions" in proc.stdout
    assert res["approximations"] == "adaptive=1 in batches of 50, cap=12" and res["rollout"]["cap"] == 12
    assert "surge (rebalance base, H=3, 8 samples, adaptive=1 in batches of 50, cap=12): free taxis" in proc.stdout
    bad = run_cli("bench", "plan", "--variants", "no-magic")
    assert bad.returncode != 0 and "unknown variant 'no-magic'" in bad.stderr


def test_bench_plan_times_central_policies_beside_rollout(tmp_path: Path) -> None:
    """``match`` and ``rebalance`` compute the joint control at once: timed like the rollout policies, one wave a step."""
    from tests.coordinator.test_cli import run_cli

    out = tmp_path / "plan.json"
    proc = run_cli("bench", "plan", "--taxis", "12", "--samples", "8", "--horizon", "3", "--steps", "2", "--warmup", "2",
                   "--policies", "match", "rebalance", "--forecast", "true-rate", "--json", str(out))
    assert proc.returncode == 0, proc.stderr
    res = json.loads(out.read_text())["policies"]
    for name in ("match", "rebalance"):
        assert res[name]["approximations"] == "exact" and res[name]["rollout"] is None
        assert res[name]["critical_path"] == [1, 1] and len(res[name]["plan_seconds"]) == 2


def test_bench_plan_pools_rounds_taken_in_turn(tmp_path: Path) -> None:
    """``--rounds 2``: each policy runs twice on the same states; the steps are pooled and each run's median kept."""
    from tests.coordinator.test_cli import run_cli

    out = tmp_path / "plan.json"
    proc = run_cli("bench", "plan", "--taxis", "12", "--samples", "8", "--horizon", "3", "--steps", "2", "--warmup", "2",
                   "--policies", "surge", "match", "--forecast", "true-rate", "--rounds", "2", "--json", str(out))
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(out.read_text())
    assert doc["config"]["rounds"] == 2
    for name in ("surge", "match"):
        res = doc["policies"][name]
        assert len(res["plan_seconds"]) == len(res["cpu_seconds"]) == 4 and len(res["round_medians"]) == 2
        assert res["same_in_every_round"] and len(res["hashes"]) == len(res["free_taxis"]) == 2
        assert res["plan_seconds_per_step"]["median"] == statistics.median(res["plan_seconds"])
    assert proc.stdout.count("run medians") == 2 and "DIFFERENT" not in proc.stdout
    bad = run_cli("bench", "plan", "--rounds", "0")
    assert bad.returncode != 0 and "--rounds" in bad.stderr


def test_kernel_cache_is_keyed_by_every_kernel_source(tmp_path: Path) -> None:
    """A change to any module that defines a kernel moves numba's cache; other modules do not."""
    import subprocess
    import sys

    import agents
    from agents import kernel_cache_dir

    package = Path(agents.__file__).parent
    for path in package.glob("*.py"):
        (tmp_path / path.name).write_bytes(path.read_bytes())
    first = kernel_cache_dir(tmp_path)
    assert first.parent == tmp_path / "__pycache__"
    (tmp_path / "waves.py").write_text((tmp_path / "waves.py").read_text() + "\n# a comment\n")
    assert kernel_cache_dir(tmp_path) == first
    (tmp_path / "_basesim.py").write_text((tmp_path / "_basesim.py").read_text() + "\n# a comment\n")
    assert kernel_cache_dir(tmp_path) != first
    # The package points numba there on import, unless the user chose a folder.
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    probe = "import agents._kernels, numba; print(numba.config.CACHE_DIR)"
    shown = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, check=True).stdout.strip()
    assert shown == str(kernel_cache_dir(package))
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "mine")
    shown = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, check=True).stdout.strip()
    assert shown == str(tmp_path / "mine")

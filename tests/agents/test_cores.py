"""Agents on one host share its cores: the count of planners, and controls that do not depend on the threads."""

from __future__ import annotations

import hashlib
import itertools
import os
import subprocess
import sys
import uuid

import numpy as np
import pytest

from agents.cores import CoreShare
from agents.rollout import DemandTables, RolloutConfig, plan_agent, prepare_step
from agents.rollout_config import default_prune
from city.scenario import load_city
from tests.agents.test_planning_speed import SAMPLES, H, forecast, seeded_state


def test_a_share_counts_the_live_planners_of_its_run_and_drops_dead_markers() -> None:
    run = f"test-{uuid.uuid4().hex}"
    share = CoreShare(run, 2)
    share.dir.mkdir(mode=0o700)
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    try:
        (share.dir / str(sleeper.pid)).touch()
        (share.dir / str(dead.pid)).touch()
        (CoreShare(f"other-{run}", 2).dir).mkdir(mode=0o700)
        with share.planning():
            assert share.me.exists()
            assert share.planners() == sorted([os.getpid(), sleeper.pid])  # the dead one's marker is gone
            assert not (share.dir / str(dead.pid)).exists()
            assert share.threads() == 1
            assert CoreShare(run, 4).threads() == 2
            # 5 cores for 2 planners: the lower process id takes the odd one, so that every core is used.
            assert CoreShare(run, 5).threads() == (3 if os.getpid() < sleeper.pid else 2)
        assert not share.me.exists()
        assert share.planners() == sorted([os.getpid(), sleeper.pid])
        sleeper.kill()
        sleeper.wait()
        assert share.planners() == [os.getpid()] and share.threads() == 2  # alone: every core
        share.close()
        assert not share.dir.exists()  # the last agent of the run takes its directory along
        share.close()
    finally:
        sleeper.kill()
        for d in (share.dir, CoreShare(f"other-{run}", 2).dir):
            if d.exists():
                for f in d.iterdir():
                    f.unlink()
                d.rmdir()


def test_a_share_needs_a_core() -> None:
    with pytest.raises(ValueError, match="cores must be at least 1, got 0"):
        CoreShare("x", 0)


@pytest.mark.parametrize("base", ["greedy", "ia"])
def test_controls_do_not_depend_on_the_threads_each_chunk_of_samples_runs_on(base: str) -> None:
    city = load_city("synthetic")
    extra = {} if base == "greedy" else {"scope": "map", "ce": "standard"}
    obs = seeded_state(city, 11)
    fc = forecast(city, np.random.default_rng(11))
    config = RolloutConfig(horizon=H, samples=SAMPLES, prune=default_prune(H), base=base, seed=2, **extra)
    ctx = prepare_step(city, config, obs, DemandTables.build(city, fc, config.ce, config.seed), obs.t % 60)
    hashes = []
    for threads in (None, itertools.cycle([1, 2, 1]).__next__):
        u = ctx.base_controls.copy()
        for agent in np.flatnonzero(obs.tau == 0):
            u[agent] = plan_agent(ctx, u[:agent], int(agent), threads=threads)
        hashes.append(hashlib.sha256(u.tobytes()).hexdigest())
    assert hashes[0] == hashes[1]


def test_a_share_that_cannot_write_its_directory_plans_as_if_alone(tmp_path) -> None:  # noqa: ANN001
    share = CoreShare("x", 2)
    share.dir = tmp_path / "not-a-directory"
    share.dir.write_text("")  # a file where the directory should be: nothing can be marked there
    share.me = share.dir / str(os.getpid())
    with share.planning():
        assert share.threads() == 2
    share.close()

"""``surge evaluate --cluster``: a local Dask cluster of two workers gives exactly what ``--jobs 2`` gives."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import pytest

distributed = pytest.importorskip("distributed")

from city.errors import ConfigError  # noqa: E402 - after the importorskip, so the module skips without dask
from city.logs import LEVEL_ENV  # noqa: E402 - after the importorskip, so the module skips without dask
from coordinator.cli import main  # noqa: E402 - after the importorskip, so the module skips without dask
from coordinator.experiments.evaluate import EvalConfig, evaluate  # noqa: E402 - after the importorskip, so the module skips without dask

POLICIES = ["greedy", "surge:forecast=true-rate,samples=16,horizon=3", "oracle"]
SAME = ("hour", "seed", "policy", "total_cost", "served", "outstanding_end", "oracle_cost", "decisions_sha256")


def _rows(doc: dict) -> list[dict]:
    return [{k: e[k] for k in SAME} for e in doc["episodes"]]


def _steps(messages: list[str]) -> list[str]:
    return [re.sub(r" \(\d+\.\d s\)$", "", m) for m in messages]


@pytest.fixture(scope="module")
def cluster() -> str:
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as lc:
        yield lc.scheduler_address


def test_two_dask_workers_match_two_jobs_with_resume_and_progress(cluster: str, tmp_path: Path) -> None:
    base = dict(hours=[19], seeds=3, taxis=12, minutes=15, policies=POLICIES)
    jobs_log: list[str] = []
    by_jobs = evaluate(EvalConfig(**base, jobs=2), progress=jobs_log.append)
    dask_log: list[str] = []
    by_dask = evaluate(EvalConfig(**base, cluster=cluster), progress=dask_log.append)
    assert _rows(by_dask) == _rows(by_jobs)
    assert _steps(dask_log) == _steps(jobs_log)

    results = tmp_path / "results.json"
    evaluate(EvalConfig(**{**base, "seeds": 1}, cluster=cluster), progress=lambda _m: None, checkpoint=results)
    resumed_log: list[str] = []
    resumed = evaluate(EvalConfig(**base, cluster=cluster), progress=resumed_log.append, checkpoint=results, resume=True)
    assert _rows(resumed) == _rows(by_jobs)
    assert resumed_log[0].startswith(f"resuming from {results}: 1 instances done") and len(resumed_log) == 3


def test_cluster_errors_are_one_line(capsys: pytest.CaptureFixture) -> None:
    assert main(["evaluate", "--cluster", "tcp://127.0.0.1:9", "--jobs", "2"]) == 2
    assert capsys.readouterr().err.strip() == "surge: error: --cluster and --jobs are exclusive: the cluster's workers run the instances"
    from coordinator.experiments.sweeps import run_on_cluster

    with pytest.raises(ConfigError, match=r"--cluster tcp://127.0.0.1:9: no Dask scheduler answers there"):
        list(run_on_cluster("tcp://127.0.0.1:9", abs, [1], timeout_s=1))


def surge_level(logger: str) -> int:
    """The level a worker shows ``logger``'s records at (a module function, so that the workers can import it)."""
    return logging.getLogger(logger).getEffectiveLevel()


def test_workers_take_the_commands_log_level(cluster: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """``surge -q``/``-v`` reach a worker that was started apart from the command."""
    from coordinator.experiments.sweeps import run_on_cluster

    for level, number in (("WARNING", logging.WARNING), ("DEBUG", logging.DEBUG)):
        monkeypatch.setenv(LEVEL_ENV, level)
        assert list(run_on_cluster(cluster, surge_level, ["coordinator", "agents"])) == [number, number]

"""The demo's path runs without torch (``make demo`` installs surge without the predictor extra)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# Torch and the text encoder cannot be imported at all in this process: any import on the demo's path fails loudly.
SCRIPT = r"""
import importlib.abc, sys

class NoTorch(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in ("torch", "sentence_transformers"):
            raise ImportError(f"the demo imported {name}")
        return None

sys.meta_path.insert(0, NoTorch())
import tempfile
from pathlib import Path

import agents.preload, agents.taxi, bus.router, coordinator.runtime  # noqa: F401 - the agent, router and coordinator processes
from coordinator.cli import build_parser
from coordinator.cli.fleet import fleet_config
from coordinator.experiments.demo import surge_vs_greedy
from coordinator.fleet import in_process

ns = build_parser().parse_args(["fleet", "--run", "demo", "--hour", "17", "--minutes", "3", "--taxis", "3",
                                "--policy", "surge", "--forecast", "previous-hour", "--insecure"])
cfg = fleet_config(ns)
result = in_process(cfg)
with tempfile.TemporaryDirectory() as out:
    # The distributed run's row needs its outstanding count; this test checks imports, so the in-process result stands in.
    lines = surge_vs_greedy(cfg, {**result, "outstanding_end": 0}, Path(out))
assert "torch" not in sys.modules
print("ok", result["total_cost"], len(lines))
"""


def test_demo_path_imports_no_torch() -> None:
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True, text=True, timeout=600,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "MPLBACKEND": "Agg"})
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.startswith("ok ")

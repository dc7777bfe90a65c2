"""The feed-forward demand networks of the paper (torch).

* temporal/weather network: base features f → 2 hidden layers of 256 (ReLU) → 1
  (the system's no-event network and the ablation's standard network)
* event network: [f, F_s] → 2 hidden layers of 4096 (ReLU) → 1
"""

from __future__ import annotations

import os

import torch
from torch import nn

STANDARD_HIDDEN = (256, 256)
EVENT_HIDDEN = (4096, 4096)

_configured = False


def configure_threads(n: int | None = None) -> int:
    """Use the machine's cores for intra-op work (``$SURGE_TORCH_THREADS`` overrides).

    On a 2-core machine this is 2 intra-op threads and 1 inter-op thread: more
    threads than cores only adds contention.
    """
    global _configured
    if n is None:
        env = os.environ.get("SURGE_TORCH_THREADS")
        n = int(env) if env else max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))
    torch.set_num_threads(n)
    if not _configured:
        try:
            torch.set_num_interop_threads(1)
        except RuntimeError:  # already set once parallel work started
            pass
        _configured = True
    return n


class DemandMLP(nn.Module):
    def __init__(self, n_in: int, hidden: tuple[int, ...]) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        prev = n_in
        for h in hidden:
            layers += [nn.Linear(prev, h), nn.ReLU()]
            prev = h
        layers.append(nn.Linear(prev, 1))
        self.net = nn.Sequential(*layers)
        self.n_in = n_in
        self.hidden = tuple(hidden)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x).squeeze(-1)


def build(n_in: int, hidden: tuple[int, ...], seed: int) -> DemandMLP:
    torch.manual_seed(seed)
    return DemandMLP(n_in, tuple(hidden))

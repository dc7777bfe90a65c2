"""Instances on a Dask distributed cluster (``pip install surge[cluster]``): ``surge evaluate --cluster ADDRESS``.

Dask's scheduler hands each instance to a free worker; results come back in
task order, so the results file, resume and progress read exactly as with
``--jobs``.  Every worker needs surge installed and the scenario's files at
the same paths (or the same ``--data`` directory).  Each task carries the
command's log level (``surge -q``/``-v``), which a worker, started apart from
the command, cannot inherit.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator
from functools import partial
from typing import Any

from city.errors import ConfigError
from city.logs import LEVEL_ENV, setup

#: Seconds to wait for the scheduler to answer.
CONNECT_TIMEOUT_S = 20


def run_on_cluster(address: str, fn: Callable[[Any], Any], items: Iterable[Any], *, timeout_s: float = CONNECT_TIMEOUT_S) -> Iterator[Any]:
    """``fn(item)`` for every item on the Dask scheduler at ``address``, yielded in item order.

    Leaving the iteration early (an error, Ctrl-C) cancels the instances not yet run.

    Raises
    ------
    ConfigError
        Dask is not installed, or no scheduler answers at ``address``.
    """
    try:
        from dask.distributed import Client
    except ImportError:
        raise ConfigError("--cluster needs Dask distributed: pip install 'surge[cluster]'") from None
    try:
        client = Client(address, timeout=timeout_s)
    except (OSError, TimeoutError, ValueError) as exc:
        raise ConfigError(f"--cluster {address}: no Dask scheduler answers there ({exc})") from None
    with client:
        futures = client.map(partial(at_level, os.environ.get(LEVEL_ENV), fn), list(items), pure=False)
        try:
            for future in futures:
                yield future.result()
        finally:
            client.cancel(futures)


def at_level(level: str | None, fn: Callable[[Any], Any], item: Any) -> Any:
    """``fn(item)`` on a worker, its surge messages shown at the command's ``level`` (none set: as the worker has them)."""
    if level is not None:
        setup(level)
    return fn(item)

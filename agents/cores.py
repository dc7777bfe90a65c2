"""The cores of one host, shared by the agents of a run that plan on it at the same time.

An agent alone at its turn spreads its samples over every core.  Turns that do
not depend on each other run side by side (:mod:`agents.waves`); each of those
agents then takes its share of the cores instead, so that neither do the
kernels oversubscribe the host (a parallel region ends with its slowest
thread, which another agent's threads keep descheduling) nor does a lone
agent leave a core idle.

Agents count each other through marker files, one per planning process, in a
directory of the run that they share (under ``/dev/shm`` where there is one).
The count decides only how many threads a chunk of samples runs on, never what
it computes (:func:`agents._kernels.rollout_costs`), so a stale marker, or a
host whose agents cannot see each other's files, costs speed but no decision.
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def share_dir(run: str) -> Path:
    """Where the agents of ``run`` on this host, and of this user, mark that they are planning."""
    shm = Path("/dev/shm")
    root = shm if shm.is_dir() and os.access(shm, os.W_OK | os.X_OK) else Path(tempfile.gettempdir())
    return root / f"surge-{os.getuid()}-{re.sub(r'[^A-Za-z0-9_.-]', '_', run)}-planning"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class CoreShare:
    """This process's share of the host's cores while it plans.

    Parameters
    ----------
    run : str
        The run's name: agents of other runs on the host are not counted.
    cores : int
        The cores to share (numba's thread count, at most the host's).
    """

    def __init__(self, run: str, cores: int) -> None:
        if cores < 1:
            raise ValueError(f"cores must be at least 1, got {cores}")
        self.dir = share_dir(run)
        self.cores = cores
        self.me = self.dir / str(os.getpid())

    @contextmanager
    def planning(self) -> Iterator[CoreShare]:
        """Marks this process as planning for the duration of the block (unmarked where the directory cannot be written)."""
        with contextlib.suppress(OSError):
            self.dir.mkdir(mode=0o700, exist_ok=True)
            self.me.touch()
        try:
            yield self
        finally:
            with contextlib.suppress(OSError):
                self.me.unlink()

    def planners(self) -> list[int]:
        """Process ids of the run planning on this host now, ascending, this one included; markers of dead processes are removed."""
        pids = {os.getpid()}
        if not self.dir.is_dir():
            return [os.getpid()]
        with os.scandir(self.dir) as entries:
            for entry in entries:
                if not entry.name.isdigit():
                    continue
                pid = int(entry.name)
                if pid not in pids and not _alive(pid):
                    Path(entry.path).unlink(missing_ok=True)
                    continue
                pids.add(pid)
        return sorted(pids)

    def close(self) -> None:
        """Leave the host: the run's directory goes with its last agent."""
        with contextlib.suppress(OSError):
            self.me.unlink()
        with contextlib.suppress(OSError):
            self.dir.rmdir()

    def threads(self) -> int:
        """The threads this process's next chunk of samples runs on: its share of the cores, at least one.

        The cores that do not divide evenly go one each to the planners of
        lowest process id, so that together they use every core.
        """
        pids = self.planners()
        n, rank = len(pids), pids.index(os.getpid())
        return max(1, self.cores // n + (rank < self.cores % n))

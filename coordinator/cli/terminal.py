"""The terminal side of logging and progress: the ``--quiet``/``--verbose`` level, and tqdm bars on a terminal.

The library logs and counts its steps (:mod:`city.logs`); this module shows
them.  A bar goes to stderr and only where stderr is a terminal (tqdm's
``disable=None``); log lines are written above the bars.  Where stderr is a
pipe or a file (CI, ``2> log``), there is no bar and each finished step's log
line (one per instance, epoch or embedding chunk, at INFO) is the progress.
"""

from __future__ import annotations

import logging
import sys
from typing import TextIO

from tqdm import tqdm

from city.logs import StderrHandler, set_steps, setup


class BarSafeHandler(StderrHandler):
    """Writes each record through ``tqdm.write``, so that a line never tears a progress bar."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            tqdm.write(self.format(record), file=self.stream)
        except Exception:  # logging's own contract: a failing handler reports and goes on
            self.handleError(record)


def bar(total: int, unit: str, desc: str, file: TextIO | None = None) -> tqdm:
    """A progress bar with rate and ETA on ``file`` (stderr), disabled where that is not a terminal."""
    return tqdm(total=total, unit=unit, desc=desc, file=file or sys.stderr, disable=None, dynamic_ncols=True, leave=None)


def level_of(quiet: bool, verbose: bool) -> int:
    """WARNING with ``--quiet``, DEBUG with ``--verbose``, INFO otherwise."""
    return logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO


def configure(quiet: bool = False, verbose: bool = False) -> int:
    """Set the surge packages' level and handler, and bars for long work unless ``--quiet``; returns the level."""
    level = setup(level_of(quiet, verbose), BarSafeHandler())
    set_steps(None if quiet else bar)
    return level

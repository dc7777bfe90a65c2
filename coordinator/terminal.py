"""The terminal side of logging and progress: the ``--quiet``/``--verbose`` level, and tqdm bars on a terminal.

The library logs and counts its steps (:mod:`city.logs`); this module shows
them.  A bar goes to stderr and only where stderr is a terminal (tqdm's
``disable=None``); log lines are written above the bars.  Where stderr is a
pipe or a file (CI, ``2> log``), there is no bar and each finished step's log
line (one per instance, epoch or embedding chunk, at INFO) is the progress.

A process the command spawns to do long work of its own (the fleet's
coordinator, which counts the run's minutes) calls :func:`inherit`: it shows
the same level, and bars where the command shows them.
"""

from __future__ import annotations

import logging
import os
import sys
from typing import TextIO

from tqdm import tqdm

from city.logs import LEVEL_ENV, StderrHandler, bars_wanted, set_steps, setup


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
    if quiet:
        set_steps(None)
    else:
        set_steps(bar, echo)
    return level


def echo(line: str) -> None:
    """A result line on stdout, written above the bars."""
    tqdm.write(line, file=sys.stdout)


def inherit() -> None:
    """In a process the command spawned: its level (:data:`city.logs.LEVEL_ENV`), and bars if it shows them."""
    if LEVEL_ENV not in os.environ:
        return
    if bars_wanted():
        setup(None, BarSafeHandler())
        set_steps(bar, echo)
    else:
        setup()

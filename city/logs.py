"""How surge's messages and progress reach the user, decided in one place.

Library code says what happens and never how it is shown: it logs through
``logging.getLogger(__name__)`` and counts the steps of long work with
:func:`steps`.  The application decides the rest: the ``surge`` command
(:mod:`coordinator.cli`) calls :func:`setup` with its ``--quiet``/``--verbose``
level and, on a terminal, installs a progress bar with ETA (:func:`set_steps`).
Without either, a library caller sees warnings only (Python's default) and no
bars.

Processes that surge spawns (the fleet's roles, evaluation workers) call
:func:`inherit`: they take the parent's level from :data:`LEVEL_ENV`, which
:func:`setup` exports, so ``surge -q fleet`` quiets every process.  Whether
the parent shows bars travels in :data:`BARS_ENV`, for a spawned process that
counts long work of its own (the fleet's coordinator counts its minutes).

Result lines that a command prints while a bar runs go through :func:`echo`,
so that they never tear the bar.

Python ``warnings`` (notes about users' data, such as interpolated weather
hours) stay warnings, so that library callers can filter or catch them; under
:func:`setup` each is shown as one ``surge: warning: …`` line, without the
source line Python prints by default.
"""

from __future__ import annotations

import logging
import os
import sys
import warnings
from collections.abc import Callable
from typing import Protocol

#: The loggers :func:`setup` configures: each top-level package, and ``surge`` for the command's own notes and warnings.
PACKAGES = ("surge", "city", "bus", "agents", "predictor", "coordinator")
#: The level spawned processes inherit, as a level name.
LEVEL_ENV = "SURGE_LOG_LEVEL"
#: Set to ``1`` where the application shows bars (:func:`set_steps`), for the processes it spawns.
BARS_ENV = "SURGE_BARS"
_HANDLER = "surge"


class LineFormatter(logging.Formatter):
    """One line a record: INFO and DEBUG as they are; ``surge: warning: …`` (or ``error``) above them.

    A record with a ``who`` attribute (``extra={"who": "agent 3"}``) names the
    process that wrote it: ``surge agent 3: …``, as every fleet role prints.
    """

    def format(self, record: logging.LogRecord) -> str:
        msg = record.getMessage()
        if record.exc_info:
            msg += "\n" + self.formatException(record.exc_info)
        who = getattr(record, "who", None)
        level = f"{record.levelname.lower()}: " if record.levelno >= logging.WARNING else ""
        if who is None and not level:
            return msg
        return f"surge{' ' + who if who else ''}: {level}{msg}"


class StderrHandler(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is when a record comes (a test's capture, a redirected stream)."""

    @property
    def stream(self):  # type: ignore[override]
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:  # StreamHandler.__init__ sets it; the current sys.stderr always wins
        pass


def _one_line(message, category, filename, lineno, file=None, line=None) -> None:
    logging.getLogger("surge.warnings").warning("%s", message)


def setup(level: int | str | None = None, handler: logging.Handler | None = None) -> int:
    """Show the surge packages' records at ``level`` and above through ``handler`` (default: stderr), one line each.

    ``level`` defaults to :data:`LEVEL_ENV`, else INFO; it is exported to
    :data:`LEVEL_ENV` for the processes spawned from here.  Calling it again
    replaces the earlier handler.  Returns the level.
    """
    if level is None:
        level = os.environ.get(LEVEL_ENV, "INFO")
    number = level if isinstance(level, int) else logging.getLevelName(str(level).upper())
    if not isinstance(number, int):
        number = logging.INFO
    os.environ[LEVEL_ENV] = logging.getLevelName(number)
    handler = handler or StderrHandler()
    handler.setFormatter(LineFormatter())
    handler.set_name(_HANDLER)
    for name in PACKAGES:
        logger = logging.getLogger(name)
        for old in [h for h in logger.handlers if h.get_name() == _HANDLER]:
            logger.removeHandler(old)
        logger.addHandler(handler)
        logger.setLevel(number)
    warnings.showwarning = _one_line
    return number


def inherit() -> None:
    """In a spawned process: the parent's :func:`setup`, where it made one (the level travels in :data:`LEVEL_ENV`)."""
    if LEVEL_ENV in os.environ:
        setup()


class Steps(Protocol):
    """A count of finished steps of long work (a tqdm bar is one)."""

    def update(self, n: int = 1) -> object: ...

    def close(self) -> None: ...

    def __enter__(self) -> Steps: ...

    def __exit__(self, *exc: object) -> object: ...


class _NoSteps:
    """The counter where nothing shows steps."""

    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self) -> _NoSteps:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


#: Makes a step counter from ``total`` and ``unit`` (``"instance"``, ``"epoch"``) and ``desc`` (what the work is).
StepsFactory = Callable[..., Steps]
_factory: StepsFactory | None = None
_echo: Callable[[str], None] | None = None


def set_steps(factory: StepsFactory | None, echo: Callable[[str], None] | None = None) -> None:
    """Show the steps of long work with ``factory`` (the CLI's progress bar), or nowhere (``None``).

    ``echo`` prints a result line to stdout without tearing a bar (tqdm's
    ``write``).  The choice is exported in :data:`BARS_ENV` for spawned processes.
    """
    global _factory, _echo
    _factory, _echo = factory, echo
    if factory is None:
        os.environ.pop(BARS_ENV, None)
    else:
        os.environ[BARS_ENV] = "1"


def bars_wanted() -> bool:
    """Whether the process that spawned this one shows bars (:data:`BARS_ENV`)."""
    return os.environ.get(BARS_ENV) == "1"


def echo(line: str) -> None:
    """Print a result line on stdout, above any bar that is running."""
    if _echo is None:
        print(line, flush=True)
    else:
        _echo(line)


def steps(total: int, unit: str, desc: str) -> Steps:
    """A counter for ``total`` steps of long work, to be closed when it ends (it is a context manager).

    Shown only where the application installed a factory (:func:`set_steps`)
    and there is work to count; the work's own log lines say what each step
    did either way.
    """
    return _factory(total=total, unit=unit, desc=desc) if _factory is not None and total > 0 else _NoSteps()

"""The key-expression scheme of one run: everything lives under ``surge/<run>/``.

=========================  ==========================  ==============================
key                        who writes                  what
=========================  ==========================  ==============================
``spec``                   coordinator (queryable)     :class:`~bus.wire.RunSpec`
``snapshot``               coordinator (queryable)     :class:`~bus.wire.Snapshot`
``state``                  coordinator                 :class:`~bus.wire.State` each minute
``forecast``               coordinator                 :class:`~bus.wire.ForecastMsg` each hour
``turn/<agent>``           coordinator                 :class:`~bus.wire.Turn`
``control/<agent>``        agent                       proposed :class:`~bus.wire.Control`
``committed/<agent>``      coordinator                 committed :class:`~bus.wire.Control`
``alive/<agent>``          agent (liveliness token)    present while the agent runs
``predictor``              predictor (queryable)       :class:`~bus.wire.ForecastMsg` for a :class:`~bus.wire.ForecastRequest`
``stop``                   coordinator                 :class:`~bus.wire.Stop`
=========================  ==========================  ==============================
"""

from __future__ import annotations

import re

from city.errors import ConfigError

PREFIX = "surge"
_RUN = re.compile(r"^[A-Za-z0-9_.-]+$")


class Keys:
    """Key expressions of run ``run``."""

    def __init__(self, run: str) -> None:
        if not _RUN.match(run):
            raise ConfigError(f"run name {run!r}: use letters, digits, '_', '.' or '-'")
        self.run = run
        self.root = f"{PREFIX}/{run}"
        self.spec = f"{self.root}/spec"
        self.snapshot = f"{self.root}/snapshot"
        self.state = f"{self.root}/state"
        self.forecast = f"{self.root}/forecast"
        self.stop = f"{self.root}/stop"
        self.predictor = f"{self.root}/predictor"
        self.all_controls = f"{self.root}/control/*"
        self.all_committed = f"{self.root}/committed/*"
        self.all_alive = f"{self.root}/alive/*"

    def turn(self, agent: int) -> str:
        return f"{self.root}/turn/{agent}"

    def control(self, agent: int) -> str:
        return f"{self.root}/control/{agent}"

    def committed(self, agent: int) -> str:
        return f"{self.root}/committed/{agent}"

    def alive(self, agent: int) -> str:
        return f"{self.root}/alive/{agent}"

    @staticmethod
    def agent_of(key: str) -> int | None:
        """The agent index a per-agent key ends with, or ``None``."""
        last = str(key).rsplit("/", 1)[-1]
        return int(last) if last.isdigit() else None

"""The ``bus`` fixture: a secured router for three taxis on a free loopback port, closed after the test."""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import pytest

from tests.coordinator.fault_rig import Bus


@pytest.fixture
def bus(tmp_path: Path) -> Iterator[Bus]:
    b = Bus(tmp_path, 3)
    try:
        yield b
    finally:
        b.close()

"""Content hashes that let two hosts check they hold the same city and run the same planner, and the host's name for its figures."""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import platform
from importlib import metadata
from pathlib import Path

import numpy as np

from city.graph import City

#: The arrays that define a city; the rest (hop counts, next hops, path lengths) are computed from them.
_DEFINING = ("xy", "indptr", "indices", "edge_length", "node_sector", "sector_ids", "pickup", "sector_adj")


def city_sha256(city: City) -> str:
    """SHA-256 of the city's defining arrays (dtype, shape and bytes) and sector names, as hex.

    Two cities with the same sizes but another street, sector or pickup
    intersection hash differently, so an agent can refuse to plan on a map
    that is not the coordinator's.
    """
    h = hashlib.sha256(json.dumps({"name": city.name, "sectors": list(city.sector_names)}).encode())
    for name in _DEFINING:
        arr = np.ascontiguousarray(getattr(city, name))
        h.update(f"{name}:{arr.dtype.str}:{arr.shape}".encode())
        h.update(arr.tobytes())
    return h.hexdigest()


@functools.cache
def code_version() -> str:
    """``surge <version>+<hash>``: the package version and a hash of the sources that make decisions (city/, agents/).

    Hosts with the same string plan identically on the same city; the hash
    catches a checkout that differs from the coordinator's without a new version.
    Computed once a process: the sources do not change under it.
    """
    try:
        version = metadata.version("surge")
    except metadata.PackageNotFoundError:
        version = "unknown"
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for path in sorted([*root.glob("city/**/*.py"), *root.glob("agents/*.py")]):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(path.read_bytes())
    return f"surge {version}+{h.hexdigest()[:12]}"


@functools.cache
def machine() -> str:
    """This host's processor and core count, kept with timings and trained weights: arithmetic and speed differ between hosts."""
    name = platform.processor() or platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                name = line.split(":", 1)[1].strip()
                break
    return f"{name} x{os.cpu_count()}"

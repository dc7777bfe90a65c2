"""Taxi agents: routing policies, the policy registry and (per taxi) one-agent-at-a-time rollout."""

import hashlib
import os
import shutil
import sys
from pathlib import Path


def kernel_cache_dir(package: Path) -> Path:
    """Where numba caches the kernels of ``package``: a folder named by a hash of every module that defines one.

    numba checks only the file that defines a function, so a kernel whose
    callee in another file changed (a ``git pull`` or a branch switch that
    touches ``_basesim.py`` alone) would load stale machine code, and could
    crash.  A folder per version of the kernel sources cannot.
    """
    digest = hashlib.sha256()
    for path in sorted(package.glob("*.py")):
        text = path.read_bytes()
        if b"\n@njit" in text:
            digest.update(path.name.encode() + b"\0" + text)
    return package / "__pycache__" / f"numba-{digest.hexdigest()[:16]}"


def _use_kernel_cache() -> None:
    """Point numba at :func:`kernel_cache_dir`, unless the user set ``NUMBA_CACHE_DIR``; drop older versions' files."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    cache = kernel_cache_dir(Path(__file__).parent)
    pycache = cache.parent
    if not cache.is_dir() and pycache.is_dir():
        for old in [*pycache.glob("numba-*"), *pycache.glob("*.nbi"), *pycache.glob("*.nbc")]:
            if old.name == cache.name:
                continue  # made meanwhile by another process of these sources
            if old.is_dir():
                shutil.rmtree(old, ignore_errors=True)
            else:
                old.unlink(missing_ok=True)
    os.environ["NUMBA_CACHE_DIR"] = str(cache)
    if "numba" in sys.modules:
        sys.modules["numba"].config.CACHE_DIR = str(cache)


_use_kernel_cache()

"""Every shell example in README.md and docs/*.md runs: as written, or as the small version its page gives.

Each ```sh or ```bash block must follow a marker comment (blank lines between are allowed)::

    <!-- test: run -->            the block runs as written
    <!-- test: small
    surge evaluate --seeds 1 ...
    -->                           these lines run instead: a small version of a long block

Blocks run with bash (``set -euo pipefail``) in one temporary directory per page, in page order,
with ``surge`` on the path and ``$REPO`` set to the repository root. See tests/README.md.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: docs/results.md is generated: its commands record how each result file was made, at full size.
PAGES = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").glob("*.md") if p.name != "results.md")]
FENCE = re.compile(r"^```(sh|bash)\s*$")
MARKER = re.compile(r"<!--\s*test:\s*(run|small)\b(.*?)-->", re.DOTALL)


@dataclass(frozen=True)
class Example:
    page: Path
    line: int  # 1-based line of the opening fence
    script: str  # what runs: the block itself, or its small version


def examples(page: Path) -> tuple[list[Example], list[str]]:
    """The page's shell blocks with what each runs, and an error naming the line of each block without a marker."""
    text = page.read_text()
    lines = text.splitlines()
    out, errors = [], []
    i = 0
    while i < len(lines):
        if not FENCE.match(lines[i]):
            i += 1
            continue
        start = i
        end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
        block = "\n".join(lines[start + 1:end])
        before = "\n".join(lines[:start]).rstrip()
        marker = None
        if before.endswith("-->"):
            opening = before.rfind("<!--")
            marker = MARKER.fullmatch(before[opening:])
        script = None if marker is None else block if marker.group(1) == "run" else marker.group(2).strip()
        if not script:
            errors.append(f"{page.relative_to(ROOT)}:{start + 1}: a shell block without a '<!-- test: run -->' "
                          "or '<!-- test: small COMMANDS -->' comment before it (tests/README.md)")
        else:
            out.append(Example(page, start + 1, script))
        i = end + 1
    return out, errors


ALL = [ex for page in PAGES for ex in examples(page)[0]]


@pytest.fixture(scope="module")
def workdirs(tmp_path_factory: pytest.TempPathFactory) -> dict[Path, Path]:
    return {page: tmp_path_factory.mktemp(page.stem) for page in PAGES}


def test_every_shell_block_is_marked() -> None:
    errors = [e for page in PAGES for e in examples(page)[1]]
    assert ALL and not errors, "\n".join(errors) or "no shell examples found"


@pytest.mark.timeout(900)
@pytest.mark.parametrize("example", ALL, ids=[f"{ex.page.relative_to(ROOT)}:{ex.line}" for ex in ALL])
def test_the_example_runs(example: Example, workdirs: dict[Path, Path]) -> None:
    bindir = str(Path(sys.executable).parent)
    env = {**os.environ, "REPO": str(ROOT), "PATH": bindir + os.pathsep + os.environ.get("PATH", ""),
           "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    run = subprocess.run(["bash", "-c", "set -euo pipefail\n" + example.script], cwd=workdirs[example.page], env=env,
                         check=False, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, (f"{example.page.relative_to(ROOT)}:{example.line} failed ({run.returncode}):\n"
                                 f"{example.script}\n--- stdout ---\n{run.stdout[-3000:]}\n--- stderr ---\n{run.stderr[-3000:]}")

"""Plain-text tables for the terminal, laid out by rich: columns as wide as their content, no colour, one header rule."""

from __future__ import annotations

import io
from collections.abc import Iterable, Sequence


def text_table(columns: Sequence[tuple[str, str]], rows: Iterable[Sequence[str]]) -> str:
    """``columns`` as (header, ``"left"``/``"right"``) pairs; every cell already formatted as text.

    The same text on a terminal, in a pipe and in a file: no colour codes, no
    wrapping, no trailing spaces.
    """
    from rich import box
    from rich.console import Console
    from rich.table import Table

    table = Table(box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False, header_style="none", expand=False)
    for header, justify in columns:
        table.add_column(header, justify=justify, no_wrap=True)  # type: ignore[arg-type]
    for row in rows:
        table.add_row(*row)
    out = io.StringIO()
    Console(file=out, width=100_000, color_system=None, force_terminal=False, highlight=False, emoji=False).print(table)
    return "\n".join(line.rstrip() for line in out.getvalue().splitlines())

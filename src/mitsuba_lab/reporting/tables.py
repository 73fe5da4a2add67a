"""Tables: Markdown for the reports' summaries, CSV for their data files."""
from __future__ import annotations

import csv
from collections.abc import Iterable, Sequence

from ..images import atomic_path


def markdown_table(header: Sequence[str], rows: Iterable[Sequence]) -> list[str]:
    """Lines of a Markdown table: the header, the ``|---|`` rule and one line per row (cells
    are ``str``-ed as given; format numbers first with ``numbers.fmt``)."""
    line = lambda cells: "| " + " | ".join(str(c) for c in cells) + " |"   # noqa: E731
    return [line(header), "|" + "---|" * len(header), *(line(r) for r in rows)]


def write_csv(path: str, columns: Sequence[str], rows: Iterable[Sequence]) -> None:
    """A CSV file with a header row (``columns``) and ``rows`` (sequences; None is written as
    an empty cell), replaced atomically so a reader never sees half a file."""
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        writer.writerows(rows)


def dict_rows(rows: Iterable[dict], columns: Sequence[str]) -> list[list]:
    """Dict rows as lists in ``columns``' order (a missing key gives an empty cell)."""
    return [[row.get(c) for c in columns] for row in rows]

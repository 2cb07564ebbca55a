"""Fixed-column CSV tables (``angles.csv``, ``joint_residuals.csv``): a header row naming the
columns, then rows of exactly that many cells; written atomically, read with the header and
every row's length checked (an :class:`~acs_cli.errors.InputError` naming the file and line).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Sequence
from pathlib import Path

from acs_cli.errors import InputError
from acs_cli.io.atomic import atomic_path

__all__ = ["read_csv_table", "write_csv_table"]


def write_csv_table(
    path: str | Path, columns: Sequence[str], rows: Iterable[Sequence[str]]
) -> None:
    """Write the header ``columns`` and ``rows`` (cells as text) to ``path`` atomically."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    w.writerows(rows)
    with atomic_path(path) as tmp:
        tmp.write_text(buf.getvalue(), encoding="utf-8")


def read_csv_table(path: str | Path, columns: Sequence[str], name: str) -> list[list[str]]:
    """The rows after the header of a table with ``columns``; ``name`` is the file's kind in
    messages (``angles.csv``).

    Raises
    ------
    InputError
        The file cannot be read, its header is not ``columns`` or a row has another length.
    """
    p = Path(path)
    try:
        rows = list(csv.reader(p.read_text(encoding="utf-8").splitlines()))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read ({exc})", path=p) from exc
    if not rows or tuple(rows[0]) != tuple(columns):
        article = "an" if name[:1] in "aeiou" else "a"
        raise InputError(f"not {article} {name}: its header is not {','.join(columns)}", path=p)
    for n, row in enumerate(rows[1:], start=2):
        if len(row) != len(columns):
            raise InputError(f"{len(row)} cells, expected {len(columns)}", path=p, line=n)
    return rows[1:]

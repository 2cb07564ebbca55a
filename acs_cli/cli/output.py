"""What the CLI prints: its two consoles and the ``--json`` result document.

Human text goes through :data:`out` (stdout) and :data:`err` (stderr). Neither wraps nor
cuts a line when its stream is not a terminal, so ``acscal ... | grep wrote`` finds a whole
path however long it is.

With ``--json`` a command prints one JSON document on stdout and nothing else there: its
human text moves to stderr (:func:`json_option_callback` redirects :data:`out` as soon as
the option is parsed) and :func:`emit` writes the document when the command ends::

    {"schema": "acscal/cli-result", "schema_version": 1, "command": "joint",
     "ok": true, "exit_code": 0, "result": {...}, "written": [...], "warnings": [...]}

When the command fails (exit 2 or 3), the one-line message still goes to stderr and
:func:`emit_error` prints ``{"ok": false, "exit_code": 2, "error": {"type": ...,
"message": ...}, ...}`` on stdout. Numbers that are not finite (an infinite standard
deviation) are ``null``, so every JSON reader accepts the document.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console, ConsoleDimensions
from rich.text import Text

__all__ = [
    "JSON_SCHEMA",
    "UNWRAPPED_WIDTH",
    "JsonOpt",
    "StreamConsole",
    "artifact_result",
    "emit",
    "emit_error",
    "err",
    "json_option_callback",
    "out",
    "reset",
    "warn",
]

#: The ``schema`` of the ``--json`` document.
JSON_SCHEMA = "acscal/cli-result"

#: Width a console takes when its stream is not a terminal: no line is ever wrapped.
UNWRAPPED_WIDTH = 1_000_000


class StreamConsole(Console):
    """A rich :class:`~rich.console.Console` that wraps only on a terminal.

    On a terminal it is rich's console (its width the terminal's). On a pipe or a file it
    is :data:`UNWRAPPED_WIDTH` columns wide: a line of text stays one line and a table
    takes its natural width, whatever ``COLUMNS`` says.
    """

    @property
    def size(self) -> ConsoleDimensions:
        """The console's width and height (width :data:`UNWRAPPED_WIDTH` off a terminal)."""
        dims = Console.size.fget(self)  # type: ignore[attr-defined]
        if self.is_terminal:
            return dims
        return ConsoleDimensions(UNWRAPPED_WIDTH, dims.height)

    @size.setter
    def size(self, new_size: tuple[int, int]) -> None:
        Console.size.fset(self, new_size)  # type: ignore[attr-defined]


#: Human output (stdout; stderr under ``--json``).
out = StreamConsole(highlight=False)
#: Warnings, notes and progress (stderr).
err = StreamConsole(stderr=True, highlight=False)


@dataclass
class _JsonMode:
    active: bool = False
    command: str = "acscal"


_MODE = _JsonMode()


def reset() -> None:
    """Back to human output on stdout (the start of every :func:`acs_cli.cli.main.main`)."""
    _MODE.active = False
    _MODE.command = "acscal"
    out.file = None  # type: ignore[assignment]  # rich: None is sys.stdout, looked up per print


def json_option_callback(ctx: typer.Context, value: bool) -> bool:
    """``--json``'s callback (eager): switch to JSON mode before any other option is read.

    Parameters
    ----------
    ctx : typer.Context
        The command's context (its name goes into the document).
    value : bool
        Whether ``--json`` was given.

    Returns
    -------
    bool
        ``value``, unchanged.
    """
    if value:
        _MODE.active = True
        _MODE.command = ctx.info_name or "acscal"
        out.file = sys.stderr
    return value


AcceptWeakOpt = Annotated[
    bool,
    typer.Option(
        "--accept-weak",
        help="Write a result the data hardly determine (past a refusal level of "
        "docs/degeneracy.md) instead of exiting 3; the artifact and every export of it are "
        "marked weak.",
    ),
]
JsonOpt = Annotated[
    bool,
    typer.Option(
        "--json",
        is_eager=True,
        callback=json_option_callback,
        help="Print one JSON document on stdout (schema acscal/cli-result: the key numbers, "
        "the files written, the warnings) and nothing else there; the usual text goes to "
        "stderr. Exit codes are unchanged.",
    ),
]


def _finite(obj: Any) -> Any:
    """``obj`` (already plain) with every non-finite float replaced by None."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_finite(v) for v in obj]
    return obj


def _print_document(doc: Mapping[str, Any]) -> None:
    from acs_cli.io.artifacts import to_plain

    text = json.dumps(_finite(to_plain(doc)), allow_nan=False)
    sys.stdout.write(text + "\n")
    sys.stdout.flush()


def warn(warnings: Iterable[str], prefix: str = "warning") -> None:
    """Print each warning on stderr as ``warning: ...`` (``prefix`` replaces the label)."""
    for w in warnings:
        err.print(Text.assemble((f"{prefix}:", "yellow"), " ", w))


def _document(exit_code: int, **body: Any) -> dict[str, Any]:
    """The ``acscal/cli-result`` document: its header, ``ok`` and ``exit_code``, then
    ``body`` (``result`` or ``error``, ``written``, ``warnings``)."""
    head = {"schema": JSON_SCHEMA, "schema_version": 1, "command": _MODE.command}
    return head | {"ok": exit_code == 0, "exit_code": exit_code} | body


def emit(
    result: Mapping[str, Any],
    *,
    written: Iterable[str | Path] = (),
    warnings: Iterable[str] = (),
) -> None:
    """Under ``--json``, print the command's result document on stdout; otherwise nothing.

    Parameters
    ----------
    result : mapping
        The key numbers, from the stage's typed result or artifact (numpy arrays, paths
        and dataclasses are converted by :func:`acs_cli.io.artifacts.to_plain`).
    written : iterable of str or Path
        Every file (or folder) the command wrote, in the order written.
    warnings : iterable of str
        The run's warnings (also printed on stderr).
    """
    if not _MODE.active:
        return
    paths = [str(p) for p in written]
    _print_document(_document(0, result=dict(result), written=paths, warnings=list(warnings)))


def emit_error(
    exit_code: int, kind: str, message: str, details: Mapping[str, Any] | None = None
) -> None:
    """Under ``--json``, print the error document on stdout (the CLI's error path).

    Parameters
    ----------
    exit_code : int
        The exit code the CLI ends with (2 bad input, 3 degenerate motion).
    kind : str
        The error's class name (``InputError``, ``DegenerateMotionError``, ...).
    message : str
        The one-line message, as printed on stderr.
    details : mapping, optional
        Machine-readable facts of a :class:`~acs_cli.errors.DegenerateMotionError`.
    """
    if not _MODE.active:
        return
    error = {"type": kind, "message": message, "details": dict(details or {})}
    _print_document(_document(exit_code, error=error, written=[], warnings=[]))


def artifact_result(doc: Mapping[str, Any]) -> dict[str, Any]:
    """The ``result`` of a command that wrote one YAML artifact, from the artifact itself.

    Parameters
    ----------
    doc : mapping
        The artifact as the stage returns it (header and body, already plain: the typed
        artifact's ``to_doc()`` through :func:`~acs_cli.io.artifacts.to_plain`).

    Returns
    -------
    dict
        ``schema``, ``method`` and ``units`` from the header, then every key of the body
        but ``warnings`` (which the document holds at its top level), as the file has them.
    """
    from acs_cli.io.base import HEADER_KEYS

    head = {k: doc.get(k) for k in ("schema", "method", "units")}
    return head | {k: v for k, v in doc.items() if k not in HEADER_KEYS and k != "warnings"}

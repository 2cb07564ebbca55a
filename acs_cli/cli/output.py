"""What the CLI prints: its two consoles and the ``--json`` result document.

Human text goes through :data:`out` (stdout) and :data:`err` (stderr). Neither wraps nor
cuts a line when its stream is not a terminal, so ``acscal ... | grep wrote`` finds a whole
path however long it is; and neither reads rich's markup or emoji codes in what it prints,
so a path such as ``run[v2]/intrinsics.yaml`` or ``a:smile:b`` is printed as it is (colour
comes from :class:`rich.text.Text` styles, never from text). Off a terminal a line of plain
text is written as it is, without importing rich (40-70 ms of every command's start):
rich is imported for tables, styled text and terminals.

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
import os
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TextIO

import typer

if TYPE_CHECKING:
    from rich.console import Console

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


def _stream_console_class() -> type[Console]:
    """The rich console class behind :class:`StreamConsole` (rich imported then)."""
    from rich.console import Console, ConsoleDimensions

    class UnwrappedConsole(Console):
        """A rich :class:`~rich.console.Console` that wraps only on a terminal.

        On a terminal it is rich's console (its width the terminal's). On a pipe or a file
        it is :data:`UNWRAPPED_WIDTH` columns wide: a line of text stays one line and a
        table takes its natural width, whatever ``COLUMNS`` says.
        """

        @property
        def size(self) -> ConsoleDimensions:
            """The console's width and height (:data:`UNWRAPPED_WIDTH` off a terminal)."""
            dims = Console.size.fget(self)  # type: ignore[attr-defined]
            if self.is_terminal:
                return dims
            return ConsoleDimensions(UNWRAPPED_WIDTH, dims.height)

        @size.setter
        def size(self, new_size: tuple[int, int]) -> None:
            Console.size.fset(self, new_size)  # type: ignore[attr-defined]

    return UnwrappedConsole


#: What rich changes in plain text (tabs expanded, control codes stripped): text with any
#: of them goes through rich.
_RICH_CHANGES = frozenset("\t\x07\x08\x0b\x0c\r")


class StreamConsole:
    """A console on stdout or stderr: rich's :class:`~rich.console.Console` (no markup, no
    emoji codes, no highlighting; unwrapped off a terminal), made when first needed.

    :meth:`print` of plain text to a stream that is not a terminal writes the text itself,
    as rich would, without importing rich; everything else (tables, styled text, other
    options, a terminal) goes to the rich console: :attr:`rich`, whose attributes this
    console also answers.

    Parameters
    ----------
    stderr : bool
        Print on stderr (else stdout).
    """

    def __init__(self, stderr: bool = False) -> None:
        self._stderr = stderr
        self._file: TextIO | None = None
        self._rich: Console | None = None

    @property
    def file(self) -> TextIO:
        """The stream printed on: the one set, else the process's stdout or stderr, looked
        up at each print."""
        if self._file is not None:
            return self._file
        return sys.stderr if self._stderr else sys.stdout

    @file.setter
    def file(self, stream: TextIO | None) -> None:
        self._file = stream
        if self._rich is not None:
            self._rich.file = stream  # type: ignore[assignment]  # rich: None is the default

    @property
    def rich(self) -> Console:
        """The rich console (made, and rich imported, on first use)."""
        if self._rich is None:
            self._rich = _stream_console_class()(
                stderr=self._stderr, highlight=False, markup=False, emoji=False
            )
            if self._file is not None:
                self._rich.file = self._file
        return self._rich

    @property
    def is_terminal(self) -> bool:
        """Whether the stream takes a terminal's escape codes, as rich decides it
        (``TTY_COMPATIBLE``, ``FORCE_COLOR``, else ``isatty``)."""
        if self._rich is not None:
            return bool(self._rich.is_terminal)
        tty = os.environ.get("TTY_COMPATIBLE", "")
        if tty in ("0", "1"):
            return tty == "1"
        force = os.environ.get("FORCE_COLOR")
        if force is not None:
            return force != ""
        isatty = getattr(self.file, "isatty", None)
        try:
            return False if isatty is None else bool(isatty())
        except ValueError:
            return False

    def print(self, *objects: Any, sep: str = " ", end: str = "\n", **options: Any) -> None:
        """Print ``objects`` as rich's ``Console.print`` does (markup, emoji codes and
        highlighting off unless asked for)."""
        plain = (
            not options.keys() - {"markup", "emoji", "highlight", "soft_wrap"}
            and not any(options.get(k) for k in ("markup", "emoji", "highlight"))
            and all(type(o) is str for o in objects)
            and type(sep) is str
            and end == "\n"
            and not self.is_terminal
        )
        if plain:
            text = sep.join(objects)
            if _RICH_CHANGES.isdisjoint(text):
                stream = self.file
                stream.write(text + end)
                stream.flush()
                return
        self.rich.print(*objects, sep=sep, end=end, **options)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.rich, name)


#: Human output (stdout; stderr under ``--json``).
out = StreamConsole()
#: Warnings, notes and progress (stderr).
err = StreamConsole(stderr=True)


@dataclass
class _JsonMode:
    active: bool = False
    command: str = "acscal"


_MODE = _JsonMode()


def reset() -> None:
    """Back to human output on stdout (the start of every :func:`acs_cli.cli.main.main`)."""
    _MODE.active = False
    _MODE.command = "acscal"
    out.file = None  # None: sys.stdout, looked up per print


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
        if err.is_terminal:
            from rich.text import Text

            err.print(Text.assemble((f"{prefix}:", "yellow"), " ", w))
        else:
            err.print(f"{prefix}: {w}")


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

"""How ``acscal --help`` reads: plain text that wraps at any width, in workflow order.

The help is click's plain layout (the app sets ``rich_markup_mode=None``): a boolean option
shows as the flag it is (``--force``, ``--bundle / --no-bundle``), never ``<bool>``, and a
long option name or word moves the description to the next line instead of being cut, at
80 columns or fewer. :class:`AcsGroup` lists the commands in the order a calibration runs
(:data:`WORKFLOW`) with their whole first sentence; :class:`AcsCommand` prints indented
paragraphs (the examples) as written, so a command line is never re-flowed.

This module imports no rich and nothing heavy: ``acscal --help`` stays fast.
"""

from __future__ import annotations

import inspect
from typing import Any

from typer import _click
from typer.core import TyperCommand, TyperGroup, TyperOption

from acs_cli.cli.coercion import install

__all__ = ["WORKFLOW", "AcsCommand", "AcsGroup", "keep_examples"]

#: The commands in the order a calibration uses them; others follow in registration order.
WORKFLOW = (
    "intrinsics",
    "poses",
    "joint",
    "relpose",
    "trajectory",
    "run",
    "export",
    "report",
    "simulate",
)

_NO_LIMIT = 10_000


def keep_examples(text: str) -> str:
    """Mark each indented paragraph of a help text to be printed as written.

    Click re-flows every paragraph to the terminal's width, which would break a command
    line over two lines; a paragraph whose first line is ``\\b`` is kept as it is.

    Parameters
    ----------
    text : str
        A help text, dedented (``inspect.cleandoc``), paragraphs separated by blank lines.

    Returns
    -------
    str
        The same text with ``\\b`` before every paragraph that starts with a space.
    """
    paragraphs = text.split("\n\n")
    return "\n\n".join(
        f"\b\n{p}" if p.startswith(" ") and not p.startswith("\b") else p for p in paragraphs
    )


def _help_false(option: TyperOption | None) -> TyperOption | None:
    """A ``--help`` option with the default False rather than None.

    Typer coerces an option's value through pydantic unless it is already a bool; a
    ``--help`` left at None made ``acscal joint --help`` import pydantic (0.1-0.4 s) just to
    read the group's options, and every command build a pydantic adapter for it.
    """
    if option is not None and option.default is None:
        option.default = False
    return option


class AcsCommand(TyperCommand):
    """A Typer command whose examples (indented paragraphs) are printed as written, and
    whose plain options are coerced without pydantic (:mod:`acs_cli.cli.coercion`)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        install(self.params)

    def get_help_option(self, ctx: _click.Context) -> TyperOption | None:
        """``--help``, with the default False (:func:`_help_false`)."""
        return _help_false(super().get_help_option(ctx))

    def format_help_text(self, ctx: _click.Context, formatter: _click.HelpFormatter) -> None:
        """Write the command's help text, examples kept on their own lines."""
        text = inspect.cleandoc(self.help or "").partition("\f")[0]
        if text:
            formatter.write_paragraph()
            with formatter.indentation():
                formatter.write_text(keep_examples(text))


class AcsGroup(TyperGroup):
    """The ``acscal`` group: commands in :data:`WORKFLOW` order, descriptions whole."""

    def list_commands(self, ctx: _click.Context) -> list[str]:
        """The command names, those of :data:`WORKFLOW` first and in its order."""
        names = list(self.commands)
        rank = {name: i for i, name in enumerate(WORKFLOW)}
        return sorted(names, key=lambda n: (rank.get(n, len(WORKFLOW)), names.index(n)))

    def get_help_option(self, ctx: _click.Context) -> TyperOption | None:
        """``--help``, with the default False (:func:`_help_false`)."""
        return _help_false(super().get_help_option(ctx))

    def format_commands(self, ctx: _click.Context, formatter: _click.HelpFormatter) -> None:
        """List each command with its first sentence, wrapped, never cut short."""
        rows = []
        for name in self.list_commands(ctx):
            cmd = self.get_command(ctx, name)
            if cmd is not None and not cmd.hidden:
                rows.append((name, cmd.get_short_help_str(limit=_NO_LIMIT)))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

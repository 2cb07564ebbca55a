"""Typer's coercion of option values, without pydantic, for the plain types acscal uses.

Typer (0.29) turns each option's text into its type through a pydantic ``TypeAdapter``
built on first use. Importing pydantic and building a command's adapters costs 0.15-0.2 s
of every command's start on a small machine: a tenth of ``acscal intrinsics`` on 30 frames.
acscal's options are plain (``str``, ``int`` and ``float`` with ``min``/``max``, ``Path``,
enums, lists of ``str``), and :func:`install` gives those a coercion that follows the same
rules and gives the same messages: ASCII text stripped of surrounding blanks, an ``int``
also from ``"3.0"`` or ``"1_000"``, a ``float`` also ``nan`` and ``inf`` (which a bound then
refuses), an enum
by its value (typer's own :func:`coerce_cli_choice`), a path by typer's own
:func:`coerce_cli_path`. Any other type, or a value that is not text (a default, an
environment variable's list), goes to typer's own coercion.

It relies on two private names of typer (a parameter's ``_runtime_param`` and
``typer._coercion.RuntimeParam``). If a typer release renames them, :func:`install` does
nothing and typer's coercion runs: slower, never different (``tests/unit/test_cli_coercion.py``
compares the two on every option type acscal has).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any, get_args, get_origin

__all__ = ["install", "plain_kind"]

try:  # private to typer: see the module's docstring
    from typer._click.exceptions import BadParameter
    from typer._coercion import RuntimeParam, TypeDescriptor, build_runtime_param
    from typer._display import _escape_control_characters
    from typer._param_types import coerce_cli_choice, coerce_cli_path
except ImportError:  # pragma: no cover - another typer: its own coercion runs
    RuntimeParam = None  # type: ignore[assignment,misc]


class _Refused(ValueError):
    """A value the type refuses: the message is typer's (pydantic's) for it."""


def _bound(v: float) -> str:
    """A ``min`` or ``max`` as pydantic prints it (``0`` for ``0.0``)."""
    return str(int(v)) if float(v).is_integer() else repr(float(v))


#: An ``int`` as text: digits (``_`` allowed between them), a decimal part of zeros allowed.
_INT = re.compile(r"([+-]?[0-9_]+)(?:\.0+)?")


def _number(kind: str, text: str, lo: float | None, hi: float | None) -> int | float:
    """``text`` as an ``int`` or ``float`` within ``[lo, hi]`` (pydantic's lax rules:
    ASCII only, blanks around ignored; the upper bound is checked first, as pydantic does,
    which decides the message for ``nan``)."""
    s = text.strip()
    value: int | float
    if kind == "int":
        m = _INT.fullmatch(s) if s.isascii() else None
        try:
            value = int(m.group(1)) if m else int("!")
        except ValueError:
            raise _Refused(
                "Input should be a valid integer, unable to parse string as an integer"
            ) from None
    else:
        try:
            value = float(s if s.isascii() else "!")
        except ValueError:
            raise _Refused(
                "Input should be a valid number, unable to parse string as a number"
            ) from None
    if hi is not None and not value <= hi:
        raise _Refused(f"Input should be less than or equal to {_bound(hi)}")
    if lo is not None and not value >= lo:
        raise _Refused(f"Input should be greater than or equal to {_bound(lo)}")
    return value


def plain_kind(descriptor: Any) -> str | None:
    """Which plain coercion a typer parameter's type descriptor takes: ``"str"``,
    ``"int"``, ``"float"``, ``"path"``, ``"enum"``, ``"str_list"``, or None (typer's
    own)."""
    info = descriptor.parameter_info
    if info.parser is not None or getattr(info, "click_type", None) is not None or info.clamp:
        return None
    if descriptor.file_annotation is not None:
        return None
    ann = descriptor.annotation
    if ann is str:
        return "str"
    if ann is int or ann is float:
        return ann.__name__
    if ann is Path:
        return "path"
    if isinstance(ann, type) and issubclass(ann, Enum):
        return "enum"
    if get_origin(ann) is list and get_args(ann) == (str,):
        return "str_list"
    return None


if RuntimeParam is not None:

    @dataclass(frozen=True)
    class _PlainParam(RuntimeParam):
        """Coercion of one plain parameter (:func:`plain_kind`); typer's for the rest."""

        kind: str
        descriptor: TypeDescriptor

        def _coerce_value(self, value: Any, param: Any, ctx: Any) -> Any:
            info = self.parameter_info
            try:
                if self.kind == "str_list" and isinstance(value, (list, tuple)):
                    if all(isinstance(v, str) for v in value):
                        return list(value)
                elif self.kind == "path" and isinstance(value, str | Path):
                    return coerce_cli_path(Path(value), info, path_type=Path, param=param, ctx=ctx)
                elif self.kind == "enum":
                    return coerce_cli_choice(
                        value,
                        choices=list(self.annotation),
                        case_sensitive=info.case_sensitive,
                        ctx=ctx,
                    )
                elif isinstance(value, str):
                    if self.kind == "str":
                        return value
                    return _number(self.kind, value, info.min, info.max)
            except _Refused as exc:
                raise BadParameter(str(exc), ctx=ctx, param=param) from None
            except ValueError as exc:  # coerce_cli_choice: pydantic's wording
                raise BadParameter(
                    _escape_control_characters(f"Value error, {exc}"), ctx=ctx, param=param
                ) from None
            # not text (a default, a value from elsewhere): typer's own coercion
            return build_runtime_param(self.descriptor)._coerce_value(value, param, ctx)


def install(params: Iterable[Any]) -> int:
    """Give each plain parameter of a command (:func:`plain_kind`) the coercion above.

    Parameters
    ----------
    params : iterable
        A typer command's ``params``.

    Returns
    -------
    int
        How many parameters took it (0 with a typer this module does not know).
    """
    if RuntimeParam is None:  # pragma: no cover - another typer
        return 0
    n = 0
    for p in params:
        descriptor = getattr(p, "type_descriptor", None)
        if descriptor is None or getattr(p, "_runtime_param", False) is not None:
            continue
        kind = plain_kind(descriptor)
        if kind is None:
            continue
        p._runtime_param = _PlainParam(
            parameter_info=descriptor.parameter_info,
            annotation=descriptor.annotation,
            kind=kind,
            descriptor=descriptor,
        )
        n += 1
    return n

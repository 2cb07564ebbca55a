"""Typer's coercion of option values, without pydantic, for the plain types acscal uses.

Typer (0.29) turns each option's value into its type through a pydantic ``TypeAdapter``
built on first use, its defaults too. Importing pydantic and building a command's adapters
costs 0.15-0.2 s of every command's start on a small machine: a tenth of ``acscal
intrinsics`` on 30 frames. acscal's options are plain (``str``, ``int`` and ``float`` with
``min``/``max``, ``Path`` without typer's path checks, enums, lists of ``str``, flags),
and
:func:`install` gives those a coercion that follows pydantic's rules for them: ASCII text
stripped of surrounding blanks, an ``int`` also from ``"3.0"`` or ``"1_000"``, a ``float``
also ``nan`` and ``inf`` (which a bound then refuses), a number given as a number (a
default) checked against the bounds, an enum by its value (typer's own
:func:`coerce_cli_choice`), a path by typer's own :func:`coerce_cli_path`; with the same
messages. ``tests/unit/test_cli_coercion.py`` compares the two on every option of every
command, on the values people type and some they should not. Known differences, on input
no one types: underscores in odd places of a float (``1._0``), integers of thousands of
digits (another message). Any other type or value goes to typer's own coercion.

It relies on private names of typer (a parameter's ``_runtime_param``,
``typer._coercion.RuntimeParam`` and what it asks of a subclass). If a typer release changes
them, :func:`install` does nothing and typer's coercion runs: slower, never different.
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
    """A ``min`` or ``max`` as pydantic prints it (``0`` for ``0.0``, ``0.00001``)."""
    f = float(v)
    if f.is_integer():
        return str(int(f))
    return format(f, "f").rstrip("0") if 1e-4 <= abs(f) < 1e16 else format(f, ".20f").rstrip("0")


#: What pydantic strips around a number (``str.strip`` would strip more: ``\x1c``-``\x1f``).
_BLANKS = " \t\n\r\x0b\x0c"
#: An ``int`` as text: digits (``_`` allowed between them), a decimal part of zeros allowed.
_INT = re.compile(r"([+-]?[0-9_]+)(?:\.0+)?")


def _bounded(value: int | float, lo: float | None, hi: float | None) -> int | float:
    """``value`` within ``[lo, hi]`` (the upper bound checked first, as pydantic does, which
    decides the message for ``nan``)."""
    if hi is not None and not value <= hi:
        raise _Refused(f"Input should be less than or equal to {_bound(hi)}")
    if lo is not None and not value >= lo:
        raise _Refused(f"Input should be greater than or equal to {_bound(lo)}")
    return value


def _number(kind: str, text: str, lo: float | None, hi: float | None) -> int | float:
    """``text`` as an ``int`` or ``float`` within ``[lo, hi]`` (pydantic's lax rules: ASCII
    only, blanks around ignored)."""
    s = text.strip(_BLANKS)
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
    return _bounded(value, lo, hi)


def plain_kind(descriptor: Any) -> str | None:
    """Which plain coercion a typer parameter's type descriptor takes: ``"bool"``,
    ``"str"``, ``"int"``, ``"float"``, ``"path"``, ``"enum"``, ``"str_list"``, or None
    (typer's own)."""
    info = descriptor.parameter_info
    if info.parser is not None or getattr(info, "click_type", None) is not None or info.clamp:
        return None
    if descriptor.file_annotation is not None:
        return None
    ann = descriptor.annotation
    if ann is bool:  # a flag's value is already a bool; an unset optional one is None
        return "bool"
    if ann is str:
        return "str"
    if ann is int or ann is float:
        return ann.__name__
    if ann is Path:
        checks = (info.exists, not info.file_okay, not info.dir_okay, info.writable,
                  info.resolve_path, info.allow_dash, info.path_type is not None)  # fmt: skip
        return None if any(checks) else "path"
    if isinstance(ann, type) and issubclass(ann, Enum):
        return "enum"
    if get_origin(ann) is list and get_args(ann) == (str,):
        return "str_list"
    return None


def _is_number(value: Any, kind: str) -> bool:
    """Whether a value that is not text is taken as it is: an ``int`` (not a ``bool``) for
    either kind, a ``float`` for a ``float``."""
    if isinstance(value, bool):
        return False
    return isinstance(value, int) or (kind == "float" and isinstance(value, float))


if RuntimeParam is not None:

    @dataclass(frozen=True)
    class _PlainParam(RuntimeParam):
        """Coercion of one plain parameter (:func:`plain_kind`); typer's for the rest."""

        kind: str
        descriptor: TypeDescriptor

        def _coerce_value(self, value: Any, param: Any, ctx: Any) -> Any:
            info = self.parameter_info
            try:
                if self.kind == "bool" and isinstance(value, bool):
                    return value
                elif self.kind == "str_list" and isinstance(value, (list, tuple)):
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
                elif isinstance(value, str) and self.kind in ("str", "int", "float"):
                    if self.kind == "str":
                        return value
                    return _number(self.kind, value, info.min, info.max)
                elif self.kind in ("int", "float") and _is_number(value, self.kind):
                    v = value if self.kind == "int" else float(value)
                    return _bounded(v, info.min, info.max)
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
        try:
            fast = _PlainParam(
                parameter_info=descriptor.parameter_info,
                annotation=descriptor.annotation,
                kind=kind,
                descriptor=descriptor,
            )
        except TypeError:  # pragma: no cover - a typer whose RuntimeParam asks for more
            return n
        p._runtime_param = fast
        n += 1
    return n

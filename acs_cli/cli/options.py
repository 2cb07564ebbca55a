"""Values of the command line's list and ``NAME=VALUE`` options (kept apart from the stages
so that parsing an option imports nothing heavy)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from acs_cli.errors import InputError

__all__ = ["parse_list_option", "parse_named_option"]


def parse_list_option(
    values: Iterable[str], allowed: Sequence[str], option: str
) -> tuple[str, ...]:
    """The values of a list option given comma-separated, repeated or both, in order, once each.

    ``["ros,opencv"]`` and ``["ros", "opencv"]`` are both ``("ros", "opencv")``.

    Raises
    ------
    InputError
        A value not in ``allowed``, or an empty item (``ros,``).
    """
    out: list[str] = []
    for value in values:
        for item in str(value).split(","):
            item = item.strip()
            if item not in allowed:
                raise InputError(
                    f"{option} {value!r}: {item!r} is not one of {', '.join(allowed)} "
                    f"(give a comma-separated list, or repeat {option})"
                )
            if item not in out:
                out.append(item)
    return tuple(out)


def parse_named_option(values: Iterable[str], option: str, what: str) -> dict[str, str]:
    """``NAME=VALUE`` items (a repeated option) as a mapping.

    Raises
    ------
    InputError
        An item without ``=``, an empty name or value, or a name given twice.
    """
    out: dict[str, str] = {}
    for item in values:
        name, sep, value = str(item).partition("=")
        name, value = name.strip(), value.strip()
        if not sep or not name or not value:
            raise InputError(f"{option} {item!r}: write it as CAMERA={what}")
        if name in out:
            raise InputError(f"{option}: camera {name} given twice")
        out[name] = value
    return out

"""acscal's coercion of plain option values (:mod:`acs_cli.cli.coercion`) against typer's
own (pydantic's): the same value or the same message, on every option of every command."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import typer
from typer import _click
from typer._coercion import build_runtime_param
from typer.main import get_command

from acs_cli.cli import coercion
from acs_cli.cli.main import app

TEXTS = [
    "3", " 2 ", "+3", "1_0.0", "3.0e0", "0.", "Infinity", "\uff13", "03", "1__0", "-0", "-4",
    "3.0", "3.", "3.5", "1e3", "1_000", "0x10", "", " ", "abc", "nan", "inf", "-inf", "1e-3",
    ".5", "0.0", "12", "\u0661\u0662", "3\n", "pinhole", "RATIONAL", "rational", "fisheye",
    "tum", "a\x1bb", "../x/y.yaml", "-",
]  # fmt: skip


def _params() -> list[tuple[str, Any]]:
    cmd = get_command(app)
    out = []
    for name, sub in cmd.commands.items():  # type: ignore[attr-defined]
        subs = getattr(sub, "commands", {name: sub})
        for sname, s in subs.items():
            for p in s.params:
                if getattr(p, "type_descriptor", None) is not None:
                    out.append((f"{sname} {p.name}", p))
    return out


PARAMS = _params()
PLAIN = [(n, p) for n, p in PARAMS if coercion.plain_kind(p.type_descriptor) is not None]
CTX = _click.Context(get_command(app))


def _outcome(runtime: Any, value: Any, param: Any) -> tuple[str, Any]:
    try:
        got = runtime.coerce(value, param=param, ctx=CTX)
    except _click.exceptions.BadParameter as exc:
        return "error", exc.message
    return type(got).__name__, "nan" if isinstance(got, float) and got != got else got


def test_every_plain_option_takes_the_fast_coercion() -> None:
    kinds = {n: coercion.plain_kind(p.type_descriptor) for n, p in PARAMS}
    assert {k for k in kinds.values()} >= {"str", "int", "float", "path", "enum", "str_list"}
    # what is left to typer: the boolean flags, whose values typer does not coerce
    left = {n for n, k in kinds.items() if k is None}
    assert all(p.type_descriptor.annotation is bool for n, p in PARAMS if n in left)


@pytest.mark.parametrize(("name", "param"), PLAIN, ids=[n for n, _ in PLAIN])
def test_the_same_value_or_message_as_typer(name: str, param: Any) -> None:
    kind = coercion.plain_kind(param.type_descriptor)
    assert kind is not None
    ours = coercion._PlainParam(
        parameter_info=param.type_descriptor.parameter_info,
        annotation=param.type_descriptor.annotation,
        kind=kind,
        descriptor=param.type_descriptor,
    )
    theirs = build_runtime_param(param.type_descriptor)
    values: list[Any] = [(t,) for t in TEXTS] if kind == "str_list" else list(TEXTS)
    values += [None, param.default] + ([Path("a/b")] if kind == "path" else [])
    if kind == "str_list":
        values += [("a", "b,c"), ()]
    for v in values:
        assert _outcome(ours, v, param) == _outcome(theirs, v, param), (name, v)


def test_a_command_coerces_through_it() -> None:
    cmd = get_command(app).commands["intrinsics"]  # type: ignore[attr-defined]
    fast = [p for p in cmd.params if isinstance(p._runtime_param, coercion._PlainParam)]
    assert len(fast) >= 10
    with pytest.raises(_click.exceptions.BadParameter, match="greater than or equal to 1"):
        cmd.make_context("intrinsics", ["x", "-o", "y.yaml", "--workers", "0"])


def test_another_type_is_left_to_typer() -> None:
    sub = typer.Typer()

    @sub.command()
    def cmd(when: float = 1.0, flag: bool = False, pair: tuple[int, int] = (1, 2)) -> None:
        pass

    params = get_command(sub).params
    assert coercion.install(params) == 1  # the float; the bool and the tuple stay typer's

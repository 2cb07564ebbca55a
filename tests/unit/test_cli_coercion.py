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
    "tum", "a\x1bb", "../x/y.yaml", "-", "\x1c3", "3\x1f",
]  # fmt: skip
#: Values that are not text (defaults, values from elsewhere).
VALUES = [0, 3, -2, 2.5, 0.0, -1.0, float("nan"), float("inf"), True, False]


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
    assert set(kinds.values()) == {"bool", "str", "int", "float", "path", "enum", "str_list"}


def _both(param: Any) -> tuple[str, Any, Any]:
    """A parameter's plain kind, our coercion of it and typer's own."""
    kind = coercion.plain_kind(param.type_descriptor)
    assert kind is not None
    ours = coercion._PlainParam(
        parameter_info=param.type_descriptor.parameter_info,
        annotation=param.type_descriptor.annotation,
        kind=kind,
        descriptor=param.type_descriptor,
    )
    return kind, ours, build_runtime_param(param.type_descriptor)


@pytest.mark.parametrize(("name", "param"), PLAIN, ids=[n for n, _ in PLAIN])
def test_the_same_value_or_message_as_typer(name: str, param: Any) -> None:
    kind, ours, theirs = _both(param)
    values: list[Any] = [(t,) for t in TEXTS] if kind == "str_list" else list(TEXTS)
    values += [None, param.default, *VALUES] + ([Path("a/b")] if kind == "path" else [])
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


def test_bounds_are_printed_as_pydantic_prints_them() -> None:
    sub = typer.Typer(add_completion=False)

    @sub.command()
    def cmd(
        a: float = typer.Option(1.0, min=1e-5),
        b: float = typer.Option(1.0, max=0.25),
        c: int = typer.Option(5, min=2, max=9),
        d: float = typer.Option(1.0, min=1e-20),
    ) -> None:
        pass

    params = get_command(sub).params
    for p in params:
        kind, ours, theirs = _both(p)
        assert kind in ("int", "float")
        for v in ["-1", "1e-6", "0.3", "10", "nan", -1, 0.3, 10, "1e-30"]:
            assert _outcome(ours, v, p) == _outcome(theirs, v, p), (p.name, v)


def test_no_command_s_defaults_need_pydantic() -> None:
    """Typer coerces the defaults too: a number given as a number stays out of pydantic."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from typer.main import get_command\n"
        "from acs_cli.cli.main import app\n"
        "group = get_command(app)\n"
        "for name, cmd in group.commands.items():\n"
        "    cmd.make_context(name, [], resilient_parsing=True)\n"
        "print('pydantic' in sys.modules)\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split()[-1] == "False"


def test_another_type_is_left_to_typer() -> None:
    sub = typer.Typer(add_completion=False)

    @sub.command()
    def cmd(when: float = 1.0, flag: bool = False, pair: tuple[int, int] = (1, 2)) -> None:
        pass

    params = get_command(sub).params
    assert coercion.install(params) == 2  # the float and the flag; the tuple stays typer's

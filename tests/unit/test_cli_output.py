"""The CLI's consoles (:mod:`acs_cli.cli.output`): plain text printed as it is, as rich's
console would print it, without importing rich off a terminal."""

from __future__ import annotations

import io

import pytest
from hypothesis import given
from hypothesis import strategies as st

from acs_cli.cli.output import StreamConsole, _stream_console_class


def _ours(*objects: object, **options: object) -> str:
    buf = io.StringIO()
    console = StreamConsole()
    console.file = buf
    console.print(*objects, **options)
    return buf.getvalue()


def _rich(*objects: object, **options: object) -> str:
    buf = io.StringIO()
    console = _stream_console_class()(file=buf, highlight=False, markup=False, emoji=False)
    console.print(*objects, **options)
    return buf.getvalue()


@given(st.lists(st.text(), max_size=3), st.sampled_from([" ", ", ", "\t"]))
def test_plain_text_prints_as_rich_prints_it(texts: list[str], sep: str) -> None:
    assert _ours(*texts, sep=sep) == _rich(*texts, sep=sep)
    assert _ours(*texts, sep=sep, markup=False, soft_wrap=True) == _rich(
        *texts, sep=sep, markup=False, soft_wrap=True
    )


@pytest.mark.parametrize(
    "text",
    [
        "wrote out/run[v2]/intrinsics.yaml",  # rich's markup would take [v2] for a style
        "wrote out/[/v2]/x.yaml",  # ... and fail on a closing tag
        "wrote a:smile:b.yaml",  # ... and its emoji codes would make this a smiley
        "tab\there, bell\x07, return\r",  # rich's own changes (it prints these)
        "x" * 300,  # off a terminal no line is wrapped
    ],
)
def test_what_rich_would_read_as_markup_is_printed_as_it_is(text: str) -> None:
    assert _ours(text) == _rich(text)
    if not any(c in text for c in "\t\x07\r"):
        assert _ours(text) == text + "\n"


def test_the_stream_is_looked_up_at_each_print_unless_set(
    capsys: pytest.CaptureFixture[str],
) -> None:
    console = StreamConsole(stderr=True)
    console.print("to stderr")
    buf = io.StringIO()
    console.file = buf
    console.print("to the buffer")
    console.rich.print("[bold]not markup[/bold]")  # the rich console follows the file set
    console.file = None  # type: ignore[assignment]
    console.print("back to stderr")
    assert capsys.readouterr().err == "to stderr\nback to stderr\n"
    assert buf.getvalue() == "to the buffer\n[bold]not markup[/bold]\n"


@pytest.mark.parametrize(
    ("env", "expected"),
    [
        ({}, False),
        ({"FORCE_COLOR": "1"}, True),
        ({"FORCE_COLOR": ""}, False),
        ({"TTY_COMPATIBLE": "1"}, True),
        ({"TTY_COMPATIBLE": "0", "FORCE_COLOR": "1"}, False),
    ],
)
def test_a_terminal_is_told_as_rich_tells_it(
    monkeypatch: pytest.MonkeyPatch, env: dict[str, str], expected: bool
) -> None:
    for key in ("FORCE_COLOR", "TTY_COMPATIBLE"):
        monkeypatch.delenv(key, raising=False)
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    lazy = StreamConsole()
    lazy.file = io.StringIO()
    assert lazy.is_terminal is expected
    assert lazy.rich.is_terminal is expected  # made now: rich's own answer
    assert lazy.is_terminal is expected

"""docs/python_api.md cannot rot: every ``acs_cli`` name it writes imports, with the
parameters the page gives it, and its code blocks run."""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import re
import tempfile
from pathlib import Path
from typing import Any

import pytest

PAGE = Path(__file__).resolve().parents[2] / "docs" / "python_api.md"
FENCE = re.compile(r"```(\w*)\n(.*?)```", re.S)
#: a name in backticks, with the call's parameters when the page gives them
SPAN = re.compile(r"^\s*(acs_cli(?:\.\w+)+)\s*(?:\((.*)\))?\s*$", re.S)


def _text() -> str:
    return PAGE.read_text(encoding="utf-8")


def _spans() -> list[str]:
    prose = FENCE.sub("", _text())
    return [s for s in re.findall(r"`([^`]+)`", prose) if "acs_cli." in s]


def resolve(dotted: str) -> Any:
    """The object a dotted name names: the longest importable module, then attributes."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ModuleNotFoundError:
            continue
        for name in parts[i:]:
            obj = getattr(obj, name)
        return obj
    raise ModuleNotFoundError(dotted)


def _split(params: str) -> list[str]:
    """Top-level comma-separated parts of a parameter list."""
    out, depth, cur = [], 0, ""
    for ch in params:
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        if ch == "," and depth == 0:
            out.append(cur.strip())
            cur = ""
        else:
            cur += ch
    if cur.strip():
        out.append(cur.strip())
    return out


def test_the_page_names_acs_cli_objects() -> None:
    names = {m.group(1) for s in _spans() if (m := SPAN.match(s))}
    assert len(names) > 30  # the parse found the page's names
    for s in _spans():
        # a span that mentions acs_cli is a name, or a name with its parameters
        assert SPAN.match(s), f"not a dotted name: `{s}`"


@pytest.mark.parametrize("span", _spans(), ids=lambda s: s.split("(")[0].strip())
def test_a_name_imports_with_the_page_s_signature(span: str) -> None:
    m = SPAN.match(span)
    assert m is not None
    obj = resolve(m.group(1))
    if m.group(2) is None:
        return
    sig = inspect.signature(obj)
    real = [p for p in sig.parameters.values() if p.name != "self"]
    documented = _split(m.group(2))
    keyword_only = False
    names = []
    for d in documented:
        if d == "*":
            keyword_only = True
            continue
        name, _, default = (x.strip() for x in d.partition("="))
        names.append((name, default, keyword_only))
    assert [n for n, _, _ in names] == [p.name for p in real], span
    for (name, default, kw), p in zip(names, real, strict=True):
        assert kw == (p.kind is inspect.Parameter.KEYWORD_ONLY), f"{span}: {name}"
        assert bool(default) == (p.default is not inspect.Parameter.empty), f"{span}: {name}"
        factory = getattr(dataclasses, "_HAS_DEFAULT_FACTORY", None)
        if default and p.default is not factory:
            assert ast.literal_eval(default) == p.default, f"{span}: {name}"


def test_the_code_blocks_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # the page's mkdtemp
    blocks = [code for lang, code in FENCE.findall(_text()) if lang == "python"]
    assert len(blocks) >= 6
    namespace: dict[str, Any] = {"__name__": "python_api_doc"}
    for i, code in enumerate(blocks):
        exec(compile(code, f"{PAGE.name}, python block {i + 1}", "exec"), namespace)

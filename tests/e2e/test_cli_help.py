"""``acscal --help`` as a person reads it in an 80-column terminal or a pipe (issue 12).

Booleans show as flags, no description is cut, examples stay on one line, and the commands
are listed in the order a calibration uses them.
"""

from __future__ import annotations

import os
import re
import subprocess
from functools import cache

import pytest
import typer.main
from cli_runner import ACSCAL

from acs_cli.cli.help_format import WORKFLOW
from acs_cli.cli.main import app

GROUP = typer.main.get_command(app)
COMMANDS = sorted(GROUP.commands)  # type: ignore[attr-defined]


@cache
def help_of(*args: str) -> str:
    """``acscal ARGS --help`` at 80 columns, stdout piped."""
    res = subprocess.run(
        [str(ACSCAL), *args, "--help"],
        capture_output=True,
        text=True,
        env=dict(os.environ, COLUMNS="80", NO_COLOR="1"),
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    return res.stdout


def squeeze(text: str) -> str:
    """``text`` without any whitespace: wrapping cannot hide a cut word."""
    return "".join(text.split())


def test_commands_are_listed_in_workflow_order() -> None:
    text = help_of()
    section = text.split("Commands:\n", 1)[1]
    listed = re.findall(r"^  (\w+)  ", section, flags=re.MULTILINE)
    assert listed == [c for c in WORKFLOW if c in COMMANDS] + [
        c for c in COMMANDS if c not in WORKFLOW
    ]
    assert listed[:6] == ["intrinsics", "poses", "joint", "relpose", "trajectory", "run"]
    assert sorted(listed) == COMMANDS


def test_command_descriptions_are_whole() -> None:
    text = squeeze(help_of())
    for name in COMMANDS:
        cmd = GROUP.commands[name]  # type: ignore[attr-defined]
        first = cmd.help.split("\n\n")[0]
        assert squeeze(first) in text, name
    commands = help_of().split("Commands:\n", 1)[1]
    assert "..." not in commands and "…" not in commands


@pytest.mark.parametrize("name", COMMANDS)
def test_booleans_show_as_flags(name: str) -> None:
    text = help_of(name)
    assert "<bool>" not in text and "BOOLEAN" not in text
    flags = [
        p
        for p in GROUP.commands[name].params  # type: ignore[attr-defined]
        if getattr(p, "is_flag", False)
    ]
    for p in flags:
        shown = " / ".join([*p.opts, *p.secondary_opts])
        # the flag's names, then at least two spaces (or the end of the line): no value
        assert re.search(rf"^\s+{re.escape(shown)}(\s{{2,}}|$)", text, re.MULTILINE), shown


@pytest.mark.parametrize("name", COMMANDS)
def test_option_descriptions_are_not_cut_at_80_columns(name: str) -> None:
    text = help_of(name)
    assert "…" not in text
    whole = squeeze(text)
    for p in GROUP.commands[name].params:  # type: ignore[attr-defined]
        if getattr(p, "help", None):
            assert squeeze(p.help) in whole, (name, p.name)
    # only the examples (kept as written, to be copied) may pass the 80th column
    long = [ln for ln in text.splitlines() if len(ln) > 80 and "acscal " not in ln]
    assert long == []


def test_examples_stay_on_one_line() -> None:
    text = help_of("joint")
    example = "acscal joint --fixed-joint --poses-a cam_a.tum --poses-b cam_b.tum -o joint.yaml"
    assert f"      {example}\n" in text
    assert "--force  " in help_of("run") and "--bundle / --no-bundle" in help_of("relpose")


def test_every_command_takes_json() -> None:
    for name in COMMANDS:
        opts = {o for p in GROUP.commands[name].params for o in p.opts}  # type: ignore[attr-defined]
        assert "--json" in opts, name

"""Ctrl-C (issue 13): exit 130 with a message, never exit 0 with nothing (Typer returns the
interrupt's 130 instead of raising it when not standalone)."""

from __future__ import annotations

from pathlib import Path

import pytest

from acs_cli.cli.main import INTERRUPTED, main


def test_an_interrupted_command_exits_130_and_says_so(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import acs_cli.stages.simulate as simulate

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(simulate, "run_simulate", interrupted)
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--trials", "1", "-o", str(tmp_path / "sim")])
    assert exc.value.code == INTERRUPTED == 130
    assert "interrupted" in capsys.readouterr().err
    assert not (tmp_path / "sim").exists()


def test_help_still_exits_0() -> None:
    main(["--help"])  # returns: exit status 0

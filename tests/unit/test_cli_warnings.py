"""A library warning that escapes reaches the user as one line of acscal's (issue 20), and
still raises where warnings are errors (pytest, ``-W error``)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from acs_cli.cli.main import main


def _nan_study(*args: object, **kwargs: object) -> None:
    _ = np.float64(np.inf) - np.float64(np.inf)  # the warning is the point
    raise SystemExit(0)


def test_an_escaping_warning_is_one_line_of_acscal(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import acs_cli.stages.simulate as simulate

    monkeypatch.setattr(simulate, "run_simulate", _nan_study)
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # as a user runs acscal
        shown = warnings.showwarning
        with pytest.raises(SystemExit):
            main(["simulate", "--trials", "1", "-o", str(tmp_path / "sim")])
        assert warnings.showwarning is shown  # restored on leaving
    lines = capsys.readouterr().err.splitlines()
    assert lines == [
        "acscal: warning: numerical trouble in acs_cli.cli.main.simulate "
        f"(tests/unit/test_cli_warnings.py:{_nan_study.__code__.co_firstlineno + 1}): "
        "invalid value encountered in scalar subtract"
    ]


def test_where_warnings_are_errors_they_still_raise(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    import acs_cli.stages.simulate as simulate

    monkeypatch.setattr(simulate, "run_simulate", _nan_study)
    with pytest.raises(RuntimeWarning, match="invalid value"):
        main(["simulate", "--trials", "1", "-o", str(tmp_path / "sim")])

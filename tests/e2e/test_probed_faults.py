"""Faults found by probing (issue 13) that ended in a traceback: each now exits 2 with one
line naming the option."""

from __future__ import annotations

from pathlib import Path

import yaml
from cli_runner import acscal


def test_a_board_too_large_for_opencv_is_refused(tmp_path: Path) -> None:
    (tmp_path / "imgs").mkdir()
    (tmp_path / "imgs" / "a.png").write_bytes(b"")
    res = acscal("intrinsics", tmp_path / "imgs", "--board", "99999999999999999999x6",
                 "--square", "0.025", "-o", tmp_path / "i.yaml")  # fmt: skip
    assert res.returncode == 2 and "at most 1000 inner corners" in res.stderr
    assert "Traceback" not in res.stderr


def test_a_run_config_board_too_large_is_named(tmp_path: Path) -> None:
    cfg = tmp_path / "run.yaml"
    cfg.write_text(
        yaml.safe_dump(
            {
                "schema": "acscal/run-config",
                "schema_version": 1,
                "output": "out/",
                "board": {"cols": 10**20, "rows": 6, "square": 0.025},
                "cameras": {"a": {"images": "imgs"}},
                "joint": {"scenario": "fixed_joint"},
            }
        )
    )
    res = acscal("run", cfg)
    assert res.returncode == 2 and "board.cols" in res.stderr, res.stderr
    assert "Traceback" not in res.stderr


def test_simulation_noise_beyond_reason_is_refused(tmp_path: Path) -> None:
    res = acscal("simulate", "--max-trans", "1e300", "-o", tmp_path / "sim")
    assert res.returncode == 2 and "--max-trans" in res.stderr
    assert "Traceback" not in res.stderr

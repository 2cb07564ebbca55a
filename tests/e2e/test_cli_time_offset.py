"""``acscal relpose --estimate-time-offset``: cameras on separate clocks (issue 10)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cli_runner import acscal

from acs_cli.io.relpose import RelposeArtifact
from acs_cli.io.trajectory import read_trajectory, write_kitti, write_tum
from sample_data_gen.acs_sim import add_pose_noise, make_rig, smooth_general_sequence


def _offset_files(root: Path, n: int) -> tuple[Path, Path]:
    rng = np.random.default_rng(11)
    seq = smooth_general_sequence(rng, make_rig(rng), n, time_offset_s=0.037)
    t = 1700000000.0 + seq.timestamps  # epoch seconds, as a real recording's
    write_tum(root / "a.tum", t, add_pose_noise(rng, seq.T_wa_a, 0.1, 0.005))
    write_tum(root / "b.tum", t, add_pose_noise(rng, seq.T_wb_b, 0.1, 0.005))
    return root / "a.tum", root / "b.tum"


@pytest.fixture(scope="module")
def offset_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    return _offset_files(tmp_path_factory.mktemp("offset"), 240)


def test_the_offset_is_estimated_and_written(
    offset_files: tuple[Path, Path], tmp_path: Path
) -> None:
    a, b = offset_files
    out = tmp_path / "relpose.yaml"
    res = acscal(
        "relpose", "--self-calibrate", "--estimate-time-offset", "--max-offset", "0.2",
        "--poses-a", a, "--poses-b", b, "-o", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    art = RelposeArtifact.load(out)
    assert art.time_offset is not None
    assert abs(art.time_offset.time_offset_s - 0.037) < 1e-3
    std = art.time_offset.time_offset_s_std
    assert std is not None and 0 < std < 2e-3
    assert art.time_offset.max_offset_s == pytest.approx(0.2)
    assert "time_offset_s" in res.stdout and "interpolated" in res.stderr
    assert "time offset" in art.summary()


def test_without_the_option_the_offset_is_warned(tmp_path: Path) -> None:
    a, b = _offset_files(tmp_path, 120)  # half the frames: the check's fits are the cost
    out = tmp_path / "relpose.yaml"
    res = acscal("relpose", "--self-calibrate", "--poses-a", a, "--poses-b", b, "-o", out)
    assert res.returncode == 0, res.stderr
    assert "probably not synchronised" in res.stderr
    assert "--estimate-time-offset" in res.stderr
    assert RelposeArtifact.load(out).time_offset is None


def test_the_offset_needs_timestamps_and_the_refined_method(
    offset_files: tuple[Path, Path], tmp_path: Path
) -> None:
    a, b = offset_files
    kitti = tmp_path / "b.kitti"
    write_kitti(kitti, read_trajectory(b, "tum").T_world_cam)  # KITTI files carry no timestamps
    res = acscal(
        "relpose", "--self-calibrate", "--estimate-time-offset", "--poses-a", a,
        "--poses-b", kitti, "--format-b", "kitti", "-o", tmp_path / "x.yaml",
    )  # fmt: skip
    assert res.returncode == 2 and "needs timestamps" in res.stderr
    assert not (tmp_path / "x.yaml").exists()
    res = acscal(
        "relpose", "--joint", a, "--method", "paper", "--estimate-time-offset",
        "--poses-a", a, "--poses-b", b, "-o", tmp_path / "y.yaml",
    )  # fmt: skip
    assert res.returncode == 2

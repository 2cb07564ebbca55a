"""A wrong --board is named (issue 13) in `acscal intrinsics` and `acscal poses`, on OpenCV's
photographs of a 9x6 board: squares counted for corners exit 2 naming 9x6; a part of the
board (8x6, which OpenCV does find in it) is a warning for intrinsics and exit 2 for poses,
whose board frame would jump."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from cli_runner import acscal

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "opencv_chessboard"

pytestmark = pytest.mark.skipif(
    not DATA.is_dir(), reason=f"OpenCV sample photographs not found at {DATA}"
)


@pytest.fixture(scope="module")
def images(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("board_size") / "left"
    d.mkdir()
    for p in sorted(DATA.glob("left0[1-8].jpg")):
        shutil.copy(p, d / p.name)
    return d


def test_squares_counted_for_corners_are_named(images: Path, tmp_path: Path) -> None:
    out = tmp_path / "i.yaml"
    res = acscal("intrinsics", images, "--board", "10x7", "--square", "0.025", "-o", out)
    assert res.returncode == 2, res.stderr
    assert "give --board 9x6" in res.stderr and "Traceback" not in res.stderr
    assert not out.exists()


def test_a_part_of_the_board_warns_in_intrinsics_and_is_refused_in_poses(
    images: Path, tmp_path: Path
) -> None:
    intr = tmp_path / "i.yaml"
    res = acscal("intrinsics", images, "--board", "8x6", "--square", "0.025", "-o", intr)
    assert res.returncode == 0, res.stderr
    assert "of which --board 8x6 is a part" in res.stderr
    good = tmp_path / "good.yaml"
    res = acscal("intrinsics", images, "--board", "9x6", "--square", "0.025", "-o", good)
    assert res.returncode == 0 and "is a part" not in res.stderr
    poses = tmp_path / "p.npz"
    res = acscal("poses", images, "--intrinsics", good, "--board", "8x6", "-o", poses)
    assert res.returncode == 2 and "give --board 9x6" in res.stderr
    assert not poses.exists()

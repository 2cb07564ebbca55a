"""``acscal poses`` times (issue 11) end to end on OpenCV's photographs, checked with evo's
TUM reader: nanosecond names keep their digits, frame numbers are marked as such, --fps and
--timestamps give seconds."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
from cli_runner import acscal

from acs_cli.io.poses import PosesArtifact
from acs_cli.io.trajectory import read_trajectory

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "opencv_chessboard"
#: EuRoC-like names (nanoseconds, 50 ms apart with odd digits at the end)
NS0 = 1403636579763555584

pytestmark = pytest.mark.skipif(
    not DATA.is_dir(), reason=f"OpenCV sample photographs not found at {DATA}"
)


@pytest.fixture(scope="module")
def left(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """OpenCV's left photographs, calibrated once."""
    d = tmp_path_factory.mktemp("times")
    imgs = d / "frames"
    imgs.mkdir()
    for p in sorted(DATA.glob("left0[1-6].jpg")):
        shutil.copy(p, imgs / p.name)
    intr = d / "intrinsics.yaml"
    res = acscal("intrinsics", imgs, "--board", "9x6", "--square", "0.025", "-o", intr)
    assert res.returncode == 0, res.stderr
    ns = d / "ns"
    ns.mkdir()
    for k, p in enumerate(sorted(imgs.iterdir())):
        shutil.copy(p, ns / f"{NS0 + 50_000_017 * k}.jpg")
    return {"dir": d, "frames": imgs, "ns": ns, "intr": intr}


def _poses(
    left: dict[str, Path], folder: str, name: str, *extra: str | Path
) -> tuple[subprocess.CompletedProcess[str], Path, Path]:
    out = left["dir"] / f"{name}.npz"
    tum = left["dir"] / f"{name}.tum"
    res = acscal(
        "poses", left[folder], "--intrinsics", left["intr"], "-o", out, "--tum", tum, *extra
    )
    return res, out, tum


def test_nanosecond_names_keep_every_digit(left: dict[str, Path]) -> None:
    from evo.tools import file_interface

    res, out, tum = _poses(left, "ns", "ns")
    assert res.returncode == 0, res.stderr
    first = next(ln for ln in tum.read_text().splitlines() if not ln.startswith("#"))
    assert first.split()[0] == "1403636579.763555584"
    traj = file_interface.read_tum_trajectory_file(str(tum))
    assert traj.num_poses == 6
    assert traj.timestamps[1] - traj.timestamps[0] == pytest.approx(0.050000017, abs=1e-6)
    header = PosesArtifact.load(out).header
    assert header["timestamps_from"] == "file names (nanoseconds)"
    assert read_trajectory(out).timestamps_ns[0] == NS0
    res, _, _ = _poses(left, "ns", "ns_fps", "--fps", "20")
    assert res.returncode == 2 and "drop --fps" in res.stderr


def test_frame_numbers_are_said_to_be_frame_numbers(left: dict[str, Path]) -> None:
    res, out, tum = _poses(left, "frames", "frames")
    assert res.returncode == 0, res.stderr
    assert "frame numbers" in res.stderr and "--fps" in res.stderr  # the warning
    assert "# times are frame numbers" in tum.read_text()
    assert read_trajectory(tum).time_unit == "frame"
    assert PosesArtifact.load(out).header["units"]["timestamps"].startswith("frame number")


def test_fps_and_a_timestamps_file_give_seconds(left: dict[str, Path]) -> None:
    from evo.tools import file_interface

    res, _, tum = _poses(left, "frames", "fps", "--fps", "10")
    assert res.returncode == 0, res.stderr
    assert "frame numbers" not in tum.read_text()
    traj = file_interface.read_tum_trajectory_file(str(tum))
    assert traj.timestamps[0] == pytest.approx(0.1) and traj.timestamps[-1] == pytest.approx(0.6)
    csv = left["dir"] / "times.csv"
    names = sorted(p.name for p in left["frames"].iterdir())
    csv.write_text("name,seconds\n" + "".join(f"{n},{12.5 + k}\n" for k, n in enumerate(names)))
    res, out, _ = _poses(left, "frames", "csv", "--timestamps", csv)
    assert res.returncode == 0, res.stderr
    assert read_trajectory(out).timestamps.tolist() == [12.5 + k for k in range(6)]
    csv.write_text("name,seconds\n" + f"{names[0]},1.0\n")
    res, _, _ = _poses(left, "frames", "csv2", "--timestamps", csv)
    assert res.returncode == 2 and names[1] in res.stderr

"""``acscal intrinsics`` and ``acscal poses`` end to end on OpenCV's sample photographs."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from cli_runner import acscal

from acs_cli.io.poses import PosesArtifact
from acs_cli.io.trajectory import read_trajectory

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "opencv_chessboard"

needs_data = pytest.mark.skipif(
    not DATA.is_dir(), reason=f"OpenCV sample photographs not found at {DATA}"
)


def _copy(pattern: str, dest: Path) -> Path:
    dest.mkdir(parents=True, exist_ok=True)
    for p in sorted(DATA.glob(pattern)):
        shutil.copy(p, dest / p.name)
    return dest


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Both cameras calibrated and their poses solved (once for the module; every test that
    uses it is marked ``needs_data``)."""
    d = tmp_path_factory.mktemp("stereo")
    files: dict[str, Path] = {"dir": d}
    for cam in ("left", "right"):
        imgs = _copy(f"{cam}*.jpg", d / cam)
        intr = d / cam / "out" / "intrinsics.yaml"
        res = acscal(
            "intrinsics", imgs, "--board", "9x6", "--square", "0.025", "-o", intr,
            "--export", "ros", "--export", "opencv",
        )  # fmt: skip
        assert res.returncode == 0, res.stderr
        poses = d / f"{cam}_poses.npz"
        res = acscal(
            "poses", imgs, "--intrinsics", intr, "--board", "9x6", "--square", "0.025",
            "-o", poses, "--tum", d / f"{cam}_poses.txt",
        )  # fmt: skip
        assert res.returncode == 0, res.stderr
        files |= {f"{cam}_images": imgs, f"{cam}_intr": intr, f"{cam}_poses": poses}
    return files


@needs_data
def test_intrinsics_on_real_photos(calibrated: dict[str, Path]) -> None:
    doc = yaml.safe_load(calibrated["left_intr"].read_text())
    assert doc["schema"] == "acscal/intrinsics"
    assert doc["image_size"] == [640, 480]
    assert doc["rms_px"] < 0.5
    K = np.array(doc["camera_matrix"])
    assert abs(K[0, 0] - 535.0) < 6.0 and abs(K[1, 1] - 535.0) < 6.0
    assert len(doc["distortion"]) == 5
    assert set(doc["std"]) >= {"fx", "fy", "cx", "cy", "distortion"}
    assert 0 < doc["std"]["fx"] < 5
    assert len(doc["per_view_rms_px"]) == len(doc["images"]["used"])
    assert doc["board"] == {"cols": 9, "rows": 6, "square": 0.025, "units": "m"}
    assert doc["units"]["square"] == "m"
    out = calibrated["left_intr"].parent
    assert (out / "intrinsics.detections.npz").is_file()
    ros = yaml.safe_load((out / "intrinsics_camera_info.yaml").read_text())
    assert ros["distortion_model"] == "plumb_bob" and ros["image_width"] == 640
    assert ros["camera_matrix"]["data"][0] == pytest.approx(K[0, 0])
    fs = cv2.FileStorage(str(out / "intrinsics_opencv.yaml"), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("camera_matrix").mat(), K)
    fs.release()


@needs_data
def test_rerun_uses_the_cache(calibrated: dict[str, Path], tmp_path: Path) -> None:
    first = yaml.safe_load(calibrated["left_intr"].read_text())
    again = tmp_path / "again.yaml"
    shutil.copy(
        calibrated["left_intr"].with_name("intrinsics.detections.npz"),
        tmp_path / "again.detections.npz",
    )
    res = acscal("intrinsics", calibrated["left_images"], "--board", "9x6", "-o", again)
    assert res.returncode == 0, res.stderr
    assert "13 detections from the cache" in res.stdout
    assert yaml.safe_load(again.read_text())["camera_matrix"] == first["camera_matrix"]


@needs_data
def test_poses_on_real_photos(calibrated: dict[str, Path]) -> None:
    traj = read_trajectory(calibrated["left_poses"])
    assert len(traj) == 13
    assert traj.names[0] == "left01.jpg" and traj.timestamps[0] == 1.0
    # the camera is in front of the board (board z points away from the camera)
    assert np.all(traj.T_world_cam[:, 2, 3] < 0)
    with np.load(calibrated["left_poses"]) as z:
        assert z["reprojection_rms"].shape == (13,) and z["reprojection_rms"].max() < 0.5
        assert z["skipped_images"].shape == (0,)
    header = PosesArtifact.load(calibrated["left_poses"]).header
    assert header["schema"] == "acscal/poses"
    assert header["board"]["square"] == 0.025
    tum = read_trajectory(calibrated["dir"] / "left_poses.txt")
    np.testing.assert_allclose(tum.T_world_cam, traj.T_world_cam, atol=1e-9)


@needs_data
def test_rigid_stereo_pair_joint_is_unobservable(
    calibrated: dict[str, Path], tmp_path: Path
) -> None:
    j = tmp_path / "j.yaml"
    res = acscal(
        "joint", "--overlap", "--poses-a", calibrated["left_poses"],
        "--poses-b", calibrated["right_poses"], "-o", j,
    )  # fmt: skip
    assert res.returncode == 3, res.stderr
    assert "cannot be observed" in res.stderr
    assert not j.exists()
    # the same pair with the right camera's board labelled the other way round (as a camera
    # rolled by more than 90 degrees would): still a rigid pair, and said to be one
    from acs_cli.core.pnp import reversed_order_transform

    with np.load(calibrated["right_poses"], allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["T_world_cam"] = (
        np.linalg.inv(reversed_order_transform(9, 6, 0.025)) @ arrays["T_world_cam"]
    )
    arrays["corners"] = arrays["corners"][:, ::-1]
    turned = tmp_path / "right_turned.npz"
    np.savez(turned, **arrays)
    res = acscal(
        "joint", "--overlap", "--poses-a", calibrated["left_poses"], "--poses-b", turned,
        "-o", j,
    )  # fmt: skip
    assert res.returncode == 3, res.stderr
    assert "opposite orders" in res.stderr and "rigidly" in res.stderr
    assert not j.exists()


def _bad_folder(kind: str, root: Path) -> tuple[Path, list[str]]:
    d = root / "imgs"
    d.mkdir()
    board = ["--board", "9x6"]
    if kind == "no_images":
        (d / "notes.txt").write_text("no images here")
    elif kind == "corrupt_png":
        shutil.copy(DATA / "left01.jpg", d / "a.jpg")
        (d / "x.png").write_bytes(np.random.default_rng(1).bytes(2000))
    elif kind == "truncated_jpeg":
        shutil.copy(DATA / "left01.jpg", d / "a.jpg")
        data = (DATA / "left02.jpg").read_bytes()
        (d / "b.jpg").write_bytes(data[: len(data) // 2])
    elif kind == "sizes":
        shutil.copy(DATA / "left01.jpg", d / "a.jpg")
        small = cv2.resize(cv2.imread(str(DATA / "left02.jpg")), (320, 240))
        cv2.imwrite(str(d / "b.jpg"), small)
    elif kind == "wrong_board":
        _copy("left0*.jpg", d)
        board = ["--board", "8x5"]
    return d, board


@needs_data
@pytest.mark.parametrize(
    ("kind", "message"),
    [
        ("empty", "empty"),
        ("no_images", "no images"),
        ("corrupt_png", "x.png: corrupt image"),
        ("truncated_jpeg", "b.jpg: corrupt image: truncated JPEG"),
        ("sizes", "differs"),
        ("wrong_board", "no 8x5 board found in any of 9 images"),
    ],
)
def test_bad_image_inputs(kind: str, message: str, tmp_path: Path) -> None:
    folder, board = _bad_folder(kind, tmp_path)
    out = tmp_path / "out" / "intrinsics.yaml"
    res = acscal("intrinsics", folder, *board, "--square", "0.025", "-o", out)
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("acscal: error: "), res.stderr
    assert message in lines[0]
    assert not out.exists()


@needs_data
def test_poses_rejects_another_artifact(calibrated: dict[str, Path], tmp_path: Path) -> None:
    bogus = tmp_path / "joint.yaml"
    bogus.write_text("schema: acscal/joint\nschema_version: 1\n")
    out = tmp_path / "p.npz"
    res = acscal("poses", calibrated["left_images"], "--intrinsics", bogus, "-o", out)
    assert res.returncode == 2 and "expected acscal/intrinsics" in res.stderr
    assert not out.exists()


def test_help_has_examples() -> None:
    for cmd in ("intrinsics", "poses"):
        res = acscal(cmd, "--help")
        assert res.returncode == 0, res.stderr
        assert "Example" in res.stdout

"""A rigid stereo pair as a rig (issue 19): OpenCV's 13 real stereo photographs, both cameras
seeing one board (``world: shared``), a ``rigid`` joint between them: stereo calibration."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from cli_runner import acscal

from acs_cli.core import se3
from acs_cli.io.rig import RigArtifact

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "opencv_chessboard"
needs_data = pytest.mark.skipif(
    not DATA.is_dir(), reason=f"OpenCV sample photographs not found at {DATA}"
)

CONFIG = """\
schema_version: 2
output: out/
board: {cols: 9, rows: 6, square: 0.025}
world: shared
cameras:
  left: {images: left}
  right: {images: right}
joints:
  stereo: {between: [left, right], type: rigid}
"""


@pytest.fixture(scope="module")
def stereo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("stereo")
    for side in ("left", "right"):
        (root / side).mkdir()
        for f in sorted(DATA.glob(f"{side}*.jpg")):
            (root / side / f.name).symlink_to(f)
    (root / "config.yaml").write_text(CONFIG)
    return root


def _stereo_calibrate(root: Path) -> np.ndarray:
    """``T_right_left`` by ``cv2.stereoCalibrate`` on acscal's own detections, with acscal's
    intrinsics held fixed."""
    from acs_cli.io.intrinsics import IntrinsicsArtifact

    obs = {s: np.load(root / "out" / f"cam_{s}" / "poses.npz") for s in ("left", "right")}
    K = {s: IntrinsicsArtifact.load(root / "out" / f"cam_{s}" / "intrinsics.yaml")
         for s in ("left", "right")}  # fmt: skip
    X = obs["left"]["board_points"].astype(np.float32)
    n = obs["left"]["corners"].shape[0]
    flags = cv2.CALIB_FIX_INTRINSIC
    _, *_, R, t, _, _ = cv2.stereoCalibrate(
        [X] * n,
        [c.astype(np.float32) for c in obs["left"]["corners"]],
        [c.astype(np.float32) for c in obs["right"]["corners"]],
        K["left"].camera_matrix, K["left"].distortion,
        K["right"].camera_matrix, K["right"].distortion,
        (640, 480), flags=flags,
    )  # fmt: skip
    return se3.transforms_from_rt(R, t.ravel())


@needs_data
def test_a_rigid_pair_seeing_one_board_is_stereo_calibration(stereo: Path) -> None:
    res = acscal("run", stereo / "config.yaml")
    assert res.returncode == 0, res.stderr
    rig = RigArtifact.load(stereo / "out" / "rig.yaml")
    T = rig.T_a_b("right", "left")
    ref = _stereo_calibrate(stereo)
    # the baseline (about 8.3 cm) within a millimetre of OpenCV's stereo calibration
    assert np.linalg.norm(T[:3, 3] - ref[:3, 3]) < 0.001
    assert se3.rotation_angle_deg((T[:3, :3].T @ ref[:3, :3])[None])[0] < 0.2
    assert rig.recordings["default"].shared_world
    # refined on both cameras' corners, with one board for both (no world between them)
    assert set(rig.bundle_adjustment) == {"left", "right"}
    assert all(b.rms_px < 0.25 for b in rig.bundle_adjustment.values())


@needs_data
def test_a_camera_that_labelled_the_board_the_other_way_is_turned(
    stereo: Path, tmp_path: Path
) -> None:
    if not (stereo / "out" / "rig.yaml").is_file():
        assert acscal("run", stereo / "config.yaml").returncode == 0
    # the right camera's poses in the board's other order (turned half a turn about its
    # normal, corners reversed): the same board, labelled the other way
    for side in ("left", "right"):
        d = dict(np.load(stereo / "out" / f"cam_{side}" / "poses.npz", allow_pickle=False))
        if side == "right":
            X = d["board_points"]
            F = np.diag([-1.0, -1.0, 1.0, 1.0])
            F[:3, 3] = X[0] + X[-1]
            d["T_world_cam"] = F @ d["T_world_cam"]
            d["corners"] = d["corners"][:, ::-1]
        np.savez(tmp_path / f"{side}.npz", **d)
    (tmp_path / "config.yaml").write_text(
        "schema_version: 2\noutput: out/\nworld: shared\npair_by: index\ncameras:\n"
        "  left: {poses: left.npz}\n  right: {poses: right.npz}\n"
        "joints:\n  stereo: {between: [left, right], type: rigid}\n"
    )
    res = acscal("run", tmp_path / "config.yaml")
    assert res.returncode == 0, res.stderr
    assert "labelled the shared board in the other order" in res.stderr
    a = RigArtifact.load(stereo / "out" / "rig.yaml").T_a_b("right", "left")
    b = RigArtifact.load(tmp_path / "out" / "rig.yaml").T_a_b("right", "left")
    np.testing.assert_allclose(a, b, atol=1e-6)

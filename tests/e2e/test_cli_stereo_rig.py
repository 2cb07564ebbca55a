"""A rigid stereo pair as a rig (issue 19): OpenCV's 13 real stereo photographs, both cameras
seeing one board (``world: shared``), a ``rigid`` joint between them: stereo calibration."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from cli_runner import acscal

from acs_cli.core import se3
from acs_cli.io.intrinsics import IntrinsicsArtifact
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


def _stereo_calibrate(root: Path, flags: int = cv2.CALIB_FIX_INTRINSIC) -> np.ndarray:
    """``T_right_left`` by ``cv2.stereoCalibrate`` on acscal's own detections, with acscal's
    intrinsics held fixed."""
    obs = {s: np.load(root / "out" / f"cam_{s}" / "poses.npz") for s in ("left", "right")}
    K = {s: IntrinsicsArtifact.load(root / "out" / f"cam_{s}" / "intrinsics.yaml")
         for s in ("left", "right")}  # fmt: skip
    X = obs["left"]["board_points"].astype(np.float32)
    n = obs["left"]["corners"].shape[0]
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
    # the run's report (issue 22, item 5): each camera's reprojection errors, corners and
    # coverage as a pair's, the rigid joint's residual per frame; no angle, no skip notes
    figures = {p.name for p in (stereo / "out" / "report_files").iterdir()}
    assert figures == {"rig_cameras.png", "joint_residuals.png", "reprojection.png",
                       "corner_errors.png", "coverage.png"}  # fmt: skip
    html = (stereo / "out" / "report.html").read_text(encoding="utf-8")
    for stage in ("intrinsics, camera left", "poses, camera right", "camera left fx"):
        assert stage in html
    assert "Sections skipped" not in html and "No joint.yaml" not in html


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


#: Three of the 13 pairs (frames 7 and 8 one apart: ``max_dt: 0.5`` keeps both).
FEW = ("07", "08", "11")


def _few_pairs(root: Path, model: str) -> RigArtifact:
    """``acscal run`` on the pairs :data:`FEW` with camera model ``model``; its rig."""
    for side in ("left", "right"):
        (root / side).mkdir()
        for p in FEW:
            (root / side / f"{side}{p}.jpg").symlink_to(DATA / f"{side}{p}.jpg")
    config = CONFIG.replace("world: shared", "world: shared\nmax_dt: 0.5")
    config = config.replace("images: left}", f"images: left, model: {model}}}")
    (root / "config.yaml").write_text(
        config.replace("images: right}", f"images: right, model: {model}}}")
    )
    res = acscal("run", root / "config.yaml")
    assert res.returncode == 0, res.stderr
    (root / "stderr.txt").write_text(res.stderr)
    return RigArtifact.load(root / "out" / "rig.yaml")


def _predicted_rms(
    stereo: Path, T: np.ndarray, K: dict[str, tuple[np.ndarray, np.ndarray]]
) -> float:
    """RMS (px) of the right camera's corners of the pairs not in :data:`FEW` (the 13-pair
    run's detections in ``stereo``), predicted from the left camera's (its board pose by PnP)
    through ``T_right_left``."""
    obs = {s: np.load(stereo / "out" / f"cam_{s}" / "poses.npz") for s in ("left", "right")}
    X = obs["left"]["board_points"]
    err = []
    for i, name in enumerate(obs["left"]["image_names"]):
        if str(name)[4:6] in FEW:
            continue
        _, rv, tv = cv2.solvePnP(X, obs["left"]["corners"][i], *K["left"])
        T_rb = T @ se3.transforms_from_rt(cv2.Rodrigues(rv)[0], tv.ravel())
        px, _ = cv2.projectPoints(X, cv2.Rodrigues(T_rb[:3, :3])[0], T_rb[:3, 3], *K["right"])
        err.append(px.reshape(-1, 2) - obs["right"]["corners"][i])
    assert len(err) == 10
    return float(np.sqrt(np.mean(np.sum(np.concatenate(err) ** 2, axis=1))))


@needs_data
def test_three_pairs_refine_the_intrinsics_and_beat_stereo_calibrate(
    stereo: Path, tmp_path: Path
) -> None:
    """3 pairs: the rig's bundle adjustment refines both cameras' intrinsics with ``T`` on
    the corners, and predicts the 10 other pairs better than ``stereoCalibrate``
    FIX_INTRINSIC with each camera's own intrinsics (benchmarks/bench_stereo.py: 0.305
    against 0.449 px on these 3)."""
    rig = _few_pairs(tmp_path, "pinhole")
    ba = rig.bundle_adjustment
    assert set(ba) == {"left", "right"} and all(b.frames == 3 for b in ba.values())
    assert not any(b.intrinsics_held for b in ba.values())
    own = {s: IntrinsicsArtifact.load(tmp_path / "out" / f"cam_{s}" / "intrinsics.yaml")
           for s in ("left", "right")}  # fmt: skip
    T_fix = _stereo_calibrate(tmp_path)
    if not (stereo / "out" / "rig.yaml").is_file():  # the 13 pairs' detections
        assert acscal("run", stereo / "config.yaml").returncode == 0
    K = {s: (b.camera_matrix, b.distortion) for s, b in ba.items()}
    ours = _predicted_rms(stereo, rig.T_a_b("right", "left"), K)
    K = {s: (a.camera_matrix, a.distortion) for s, a in own.items()}
    fix = _predicted_rms(stereo, T_fix, K)
    assert ours < 0.8 * fix, (ours, fix)


@needs_data
def test_three_pairs_of_a_rational_lens_hold_the_intrinsics(tmp_path: Path) -> None:
    """3 pairs do not determine a rational lens's distortion: the bundle holds each camera's
    intrinsics (its file's, with the file's std), fitting ``T`` on the corners as
    ``stereoCalibrate`` FIX_INTRINSIC does, and says so."""
    rig = _few_pairs(tmp_path, "rational")
    assert "held every camera's intrinsics" in (tmp_path / "stderr.txt").read_text()
    assert "intrinsics held" in rig.summary()
    for s, b in rig.bundle_adjustment.items():
        own = IntrinsicsArtifact.load(tmp_path / "out" / f"cam_{s}" / "intrinsics.yaml")
        assert b.intrinsics_held and b.frames == 3
        np.testing.assert_array_equal(b.camera_matrix, own.camera_matrix)
        np.testing.assert_array_equal(b.distortion, own.distortion)
        assert own.std is not None
        assert b.intrinsics_std["fx"] == own.std["fx"]
        assert b.intrinsics_std["k6"] == own.std["distortion"][7]
    T = rig.T_a_b("right", "left")
    ref = _stereo_calibrate(tmp_path, cv2.CALIB_FIX_INTRINSIC | cv2.CALIB_RATIONAL_MODEL)
    assert np.linalg.norm(T[:3, 3] - ref[:3, 3]) < 1e-6  # the same fit: 1 um (measured 2 nm)
    assert se3.rotation_angle_deg((T[:3, :3].T @ ref[:3, :3])[None])[0] < 1e-4

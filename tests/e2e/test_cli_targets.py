"""``acscal intrinsics --target`` and ``acscal poses --target`` on rendered AprilGrid and
ChArUco sequences (half the frames show part of the target)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from cli_runner import acscal

from acs_cli.io.poses import PosesArtifact
from sample_data_gen.target_render import default_target, render_target_sequence

FRAMES = 6


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("targets")
    return {
        kind: render_target_sequence(
            root / kind, default_target(kind), seed=5, frames=FRAMES, size=(480, 360)
        )
        for kind in ("aprilgrid", "charuco")
    }


def _truth(folder: Path) -> dict[str, object]:
    return dict(yaml.safe_load((folder / "truth.yaml").read_text()))


@pytest.mark.parametrize("kind", ["aprilgrid", "charuco"])
def test_intrinsics_and_poses_on_a_target(rendered: dict[str, Path], kind: str) -> None:
    folder = rendered[kind]
    truth = _truth(folder)
    K_true = np.asarray(truth["camera"]["camera_matrix"])  # type: ignore[index]
    intr = folder / "out" / "intrinsics.yaml"
    # the Kalibr / OpenCV target file for one, the short form for the other
    spec = str(folder / "target.yaml") if kind == "aprilgrid" else default_target(kind).short()
    res = acscal("intrinsics", folder / "images", "--target", spec, "-o", intr)
    assert res.returncode == 0, res.stderr
    assert int(res.stdout.split(" of ")[0]) >= FRAMES - 1  # all views, an outlier aside
    doc = yaml.safe_load(intr.read_text())
    assert doc["target"]["target_type"] == kind
    K = np.asarray(doc["camera_matrix"])
    np.testing.assert_allclose(K[[0, 1], [0, 1]], K_true[[0, 1], [0, 1]], rtol=3e-3)
    np.testing.assert_allclose(K[:2, 2], K_true[:2, 2], atol=2.0)
    assert doc["rms_px"] < 0.1

    # poses: the target is given again (ChArUco), or comes from the intrinsics (AprilGrid)
    extra = ["--target", spec] if kind == "charuco" else []
    poses = folder / "out" / "poses.npz"
    res = acscal("poses", folder / "images", "--intrinsics", intr, "-o", poses, *extra)
    assert res.returncode == 0, res.stderr
    art = PosesArtifact.load(poses)
    target = default_target(kind)
    assert art.corners is not None and art.board_points is not None
    assert art.corners.shape == (FRAMES, target.n_corners, 2)
    np.testing.assert_allclose(art.board_points, target.points())
    seen = np.all(np.isfinite(art.corners), axis=2)
    assert not seen[1::2].all()  # the partial views miss corners: NaN there
    assert seen.sum(axis=1).min() >= 8
    assert art.header["target"]["target_type"] == kind
    T_true = np.asarray(truth["T_world_cam"])
    np.testing.assert_allclose(art.trajectory.T_world_cam[:, :3, 3], T_true[:, :3, 3], atol=5e-3)
    # column j is corner j: the stored corners are the true projections
    true_px = np.load(folder / "truth_corners.npz")["corners"]
    err = np.linalg.norm(art.corners[seen] - true_px[seen], axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.05


def test_wrong_family_exits_2_naming_it(rendered: dict[str, Path], tmp_path: Path) -> None:
    res = acscal(
        "intrinsics", rendered["aprilgrid"] / "images", "--target",
        "charuco:11x8:0.03:0.022:DICT_5X5_100", "-o", tmp_path / "i.yaml",
    )  # fmt: skip
    assert res.returncode == 2, res.stdout + res.stderr
    assert "DICT_APRILTAG_36h11" in res.stderr


def test_blank_images_exit_3_with_advice(tmp_path: Path) -> None:
    images = tmp_path / "blank"
    images.mkdir()
    for i in range(4):
        cv2.imwrite(str(images / f"img_{i:03d}.png"), np.full((240, 320), 90 + 20 * i, np.uint8))
    res = acscal("intrinsics", images, "--target", "aprilgrid:6x6:0.088:0.3", "-o", tmp_path / "i")
    assert res.returncode == 3, res.stdout + res.stderr
    assert "no aprilgrid" in res.stderr and "record the target" in res.stderr
    assert not (tmp_path / "i").exists()


def test_bad_target_options_exit_2(rendered: dict[str, Path], tmp_path: Path) -> None:
    images = rendered["aprilgrid"] / "images"
    res = acscal(
        "intrinsics", images, "--target", "aprilgrid:6x6:0.088:0.3", "--board", "9x6",
        "-o", tmp_path / "i.yaml",
    )  # fmt: skip
    assert res.returncode == 2 and "--board" in res.stderr
    bad = tmp_path / "bad.yaml"
    bad.write_text("target_type: circlegrid\ntargetCols: 6\n")
    res = acscal("intrinsics", images, "--target", bad, "-o", tmp_path / "i.yaml")
    assert res.returncode == 2 and "'target_type'" in res.stderr


def test_run_config_with_a_target(rendered: dict[str, Path], tmp_path: Path) -> None:
    cfg = tmp_path / "run.yaml"
    cfg.write_text(
        "schema: acscal/run-config\nschema_version: 1\noutput: out\n"
        "target: charuco:11x8:0.03:0.022:DICT_5X5_100\n"
        f"cameras:\n  a: {{images: {rendered['charuco'] / 'images'}}}\n"
        "joint: {scenario: fixed_joint}\n"
    )
    for stage in ("intrinsics", "poses"):
        res = acscal("run", cfg, "--only", stage)
        assert res.returncode == 0, res.stdout + res.stderr
    art = PosesArtifact.load(tmp_path / "out" / "cam_a" / "poses.npz")
    assert art.header["target"]["target_type"] == "charuco"
    assert len(art) == FRAMES


def test_report_of_partial_views_without_intrinsics(
    rendered: dict[str, Path], tmp_path: Path
) -> None:
    """A run folder whose camera has only a target's poses (NaN where a corner was not seen)
    and no intrinsics.yaml: the coverage takes the seen corners (it crashed on NaN)."""
    folder = rendered["aprilgrid"]
    intr = tmp_path / "intrinsics.yaml"
    res = acscal("intrinsics", folder / "images", "--target", folder / "target.yaml", "-o", intr)
    assert res.returncode == 0, res.stderr
    run = tmp_path / "run"
    (run / "cam_a").mkdir(parents=True)
    res = acscal(
        "poses", folder / "images", "--intrinsics", intr, "-o", run / "cam_a" / "poses.npz"
    )
    assert res.returncode == 0, res.stderr
    res = acscal("report", run)
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr

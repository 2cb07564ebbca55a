"""The articulated renderer filming AprilGrids and ChArUco boards (sample_data_gen.render's
``target``): the checkerboard standing in for the target, the truth in the target's frames,
and ``--target`` of the render CLI."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from acs_cli.core import se3
from acs_cli.core.targets import AprilGrid, Charuco, detect_target
from acs_cli.io.target import read_target_yaml
from sample_data_gen.render import SCENE_TARGETS, _build_camera, board_corners, render_scenario
from sample_data_gen.render_cli import main
from sample_data_gen.target_render import board_proxy, project_corners


def test_a_charucos_proxy_is_its_inner_corners() -> None:
    target = Charuco(7, 5, 0.035, 0.026, "DICT_5X5_100")
    board, T = board_proxy(target)
    assert (board.cols, board.rows, board.square) == (6, 4, 0.035)
    np.testing.assert_allclose(
        se3.transform_points(T, board_corners(board)), target.points(), atol=1e-8
    )  # the points are float32


def test_an_aprilgrids_proxy_covers_its_corners_printed_side_towards_the_camera() -> None:
    target = AprilGrid(4, 3, 0.045, 0.3)
    board, T = board_proxy(target)
    assert board.square == pytest.approx(0.045 * 1.3)
    q = se3.transform_points(se3.invert_transforms(T), target.points())
    lo, hi = board_corners(board).min(axis=0), board_corners(board).max(axis=0)
    assert np.all(q >= lo - 1e-12) and np.all(q <= hi + 1e-12)
    assert np.ptp(q[:, 0]) > hi[0] - lo[0] - board.square  # within one pitch
    # the proxy's z runs into the board, Kalibr's out of it: a camera in front of the proxy
    # (z < 0) is on the target's +z side
    assert se3.transform_points(T, np.array([[0.0, 0.0, -1.0]]))[0, 2] > 0


@pytest.mark.parametrize("kind", ["charuco", "aprilgrid"])
def test_rendered_corners_and_truth_agree(tmp_path: Path, kind: str) -> None:
    """The corners detected in the images are the target's points projected through the
    truth's camera and pose (world = the target's frame), and the joint stays put in it."""
    target = SCENE_TARGETS[kind]
    out = render_scenario(
        tmp_path, "fixed_joint", seed=1, frames=3, target=target, supersample=1,
        partial_fraction=0.0, missing_fraction=0.0,
    )  # fmt: skip
    assert read_target_yaml(out / "target.yaml") == target
    truth = yaml.safe_load((out / "truth.yaml").read_text(encoding="utf-8"))
    assert truth["boards"]["board_a"]["short"] == target.short()
    for name, cam in (("cam_a", "a"), ("cam_b", "b")):
        doc = truth[name]
        camera = _build_camera(np.array(doc["K"]), np.array(doc["dist"]), (640, 480), 1)
        T = np.array(doc["T_world_cam"])
        joint = se3.transform_points(T, np.asarray(truth["joint"][f"position_in_{cam}"]))
        world = "a" if cam == "a" else "b"
        np.testing.assert_allclose(
            joint, np.tile(truth["joint"][f"position_in_world_{world}"], (3, 1)), atol=1e-9
        )
        errors = []
        for i in range(3):
            image = cv2.imread(str(out / name / f"img_{i:05d}.png"), cv2.IMREAD_GRAYSCALE)
            found = detect_target(np.asarray(image), target).dense(target.n_corners)
            true = project_corners(camera, T[i], target.points())
            seen = np.isfinite(found).all(axis=1)
            assert seen.sum() >= 8, (name, i)
            errors.append(np.linalg.norm(found[seen] - true[seen], axis=1))
        rms = float(np.sqrt(np.mean(np.concatenate(errors) ** 2)))
        print(f"{kind} {name}: corner error {rms:.3f} px RMS")
        assert rms < 0.1


def test_the_cli_takes_a_target_and_refuses_a_checkerboard(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    with pytest.raises(SystemExit) as exc:
        main([str(tmp_path), "--target", "checkerboard:9x6:0.025"])
    assert exc.value.code == 2
    assert "AprilGrid or a ChArUco" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([str(tmp_path), "--target", "aprilgrid:4x3"])

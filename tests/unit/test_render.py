"""Rendered checkerboard sequences: files, truth, corner accuracy, visibility, determinism."""

from __future__ import annotations

import hashlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.io.artifacts import read_yaml_artifact
from sample_data_gen.render import Board, board_corners, render_scenario
from sample_data_gen.render_cli import main

SIZE = (320, 240)


def _truth(folder: Path) -> dict:
    return read_yaml_artifact(folder / "truth.yaml", "render_truth")


def _corner_rms(img: np.ndarray, cam: dict, board: Board, T_world_cam: np.ndarray) -> float:
    found, corners = cv2.findChessboardCorners(img, (board.cols, board.rows))
    assert found
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    corners = cv2.cornerSubPix(img, corners, (5, 5), (-1, -1), crit).reshape(-1, 2)
    T = se3.invert_transforms(T_world_cam)
    rvec, _ = cv2.Rodrigues(T[:3, :3])
    K, dist = np.array(cam["K"]), np.array(cam["dist"])
    uv, _ = cv2.projectPoints(board_corners(board), rvec, T[:3, 3], K, dist)
    uv = uv.reshape(-1, 2)
    # OpenCV may list the corners from either end of the board
    return min(
        float(np.sqrt(np.mean(np.sum((c - uv) ** 2, axis=1)))) for c in (corners, corners[::-1])
    )


@pytest.fixture(scope="module")
def general(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("render")
    return render_scenario(
        out,
        "general",
        seed=3,
        frames=10,
        size=SIZE,
        board_distance=0.45,
        partial_fraction=0.2,
        missing_fraction=0.1,
    )


def test_files_and_truth_written(general: Path) -> None:
    truth = _truth(general)
    assert truth["scenario"] == "general"
    assert truth["image_size"] == list(SIZE)
    for name in ("cam_a", "cam_b"):
        cam = truth[name]
        assert cam["model"] == "pinhole-radtan"
        assert np.array(cam["K"]).shape == (3, 3)
        assert len(cam["dist"]) == 5
        assert np.array(cam["T_world_cam"]).shape == (10, 4, 4)
        for i in range(10):
            img = cv2.imread(str(general / name / f"img_{i:05d}.png"), cv2.IMREAD_UNCHANGED)
            assert img is not None and img.shape == (SIZE[1], SIZE[0]) and img.dtype == np.uint8
        assert (general / f"{name}_truth.tum").is_file()


def test_truth_is_consistent_with_the_joint(general: Path) -> None:
    truth = _truth(general)
    T_a = np.array(truth["cam_a"]["T_world_cam"])
    T_b = np.array(truth["cam_b"]["T_world_cam"])
    T_wb_wa = np.array(truth["T_wb_wa"])
    o_a = np.array(truth["joint"]["position_in_a"])
    o_b = np.array(truth["joint"]["position_in_b"])
    assert 0.2 < np.linalg.norm(o_a) < 0.3 and 0.2 < np.linalg.norm(o_b) < 0.3
    # the joint is one physical point for both cameras in every frame
    j_a = se3.transform_points(T_wb_wa @ T_a, o_a)
    j_b = se3.transform_points(T_b, o_b)
    np.testing.assert_allclose(j_a, j_b, atol=1e-9)
    T_a_b = se3.invert_transforms(T_a) @ se3.invert_transforms(T_wb_wa) @ T_b
    np.testing.assert_allclose(np.array(truth["T_a_b"]), T_a_b, atol=1e-9)
    np.testing.assert_allclose(
        np.array(truth["relative_pose"]["T_b_a"]), se3.invert_transforms(T_a_b[0]), atol=1e-9
    )
    # general motion: the joint moves
    assert np.ptp(j_a, axis=0).max() > 0.05


def test_partial_and_missing_frames_marked(general: Path) -> None:
    truth = _truth(general)
    n_corners = 9 * 6
    for name in ("cam_a", "cam_b"):
        vis = truth[name]["visibility"]
        n_in = truth[name]["corners_in_view"]
        assert vis[0] == "full"
        assert vis.count("partial") == 2 and vis.count("none") == 1
        for i, kind in enumerate(vis):
            img = cv2.imread(str(general / name / f"img_{i:05d}.png"), cv2.IMREAD_GRAYSCALE)
            if kind == "none":
                assert n_in[i] == 0
            if kind == "partial":
                assert 0.2 * n_corners <= n_in[i] <= 0.8 * n_corners
            if kind != "full":
                found, _ = cv2.findChessboardCorners(img, (9, 6))
                assert not found


def test_noise_free_corners_match_the_true_projection(tmp_path: Path) -> None:
    folder = render_scenario(
        tmp_path,
        "overlap",
        seed=1,
        frames=3,
        size=SIZE,
        board_distance=0.45,
        blur=False,
        noise_sigma=0.0,
        partial_fraction=0.0,
        missing_fraction=0.0,
    )
    truth = _truth(folder)
    assert truth["boards"]["shared"] is True
    np.testing.assert_allclose(np.array(truth["T_wb_wa"]), np.eye(4), atol=1e-12)
    bd = truth["boards"]["board_a"]
    board = Board(bd["cols"], bd["rows"], bd["square"])
    errors = []
    for name in ("cam_a", "cam_b"):
        cam = truth[name]
        assert cam["visibility"] == ["full"] * 3
        for i in range(3):
            img = cv2.imread(str(folder / name / f"img_{i:05d}.png"), cv2.IMREAD_GRAYSCALE)
            errors.append(_corner_rms(img, cam, board, np.array(cam["T_world_cam"][i])))
    assert max(errors) < 0.15, errors


def _hashes(folder: Path) -> dict[str, str]:
    return {
        p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*.png"))
    }


def test_same_seed_same_images(tmp_path: Path) -> None:
    kw = {"seed": 5, "frames": 2, "size": (160, 120), "board_distance": 0.9}
    a = _hashes(render_scenario(tmp_path / "a", "fixed_joint", **kw))
    b = _hashes(render_scenario(tmp_path / "b", "fixed_joint", **kw))
    c = _hashes(render_scenario(tmp_path / "c", "fixed_joint", **{**kw, "seed": 6}))
    assert len(a) == 4
    assert a == b
    assert a != c


def test_fixed_joint_keeps_the_joint_still(tmp_path: Path) -> None:
    folder = render_scenario(tmp_path, "fixed_joint", seed=2, frames=5, size=SIZE)
    truth = _truth(folder)
    for name, o, key in (
        ("cam_a", "position_in_a", "position_in_world_a"),
        ("cam_b", "position_in_b", "position_in_world_b"),
    ):
        T = np.array(truth[name]["T_world_cam"])
        p = se3.transform_points(T, np.array(truth["joint"][o]))
        np.testing.assert_allclose(p, np.tile(truth["joint"][key], (5, 1)), atol=1e-9)


def test_cli_writes_a_scenario(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = [str(tmp_path), "--scenario", "overlap", "--size", "200x150", "--frames", "2"]
    assert main([*args, "--board", "7x5", "--square", "0.03", "--no-blur"]) == 0
    truth = _truth(tmp_path / "overlap")
    assert truth["image_size"] == [200, 150]
    assert truth["boards"]["board_a"]["cols"] == 7
    assert "overlap" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main([str(tmp_path), "--size", "bad"])


def test_cli_writes_the_cameras_as_videos(tmp_path: Path) -> None:
    from acs_cli.io.video import read_video_frames

    args = [str(tmp_path), "--scenario", "overlap", "--size", "200x150", "--frames", "3"]
    assert main([*args, "--video", "mkv", "--video-fps", "20"]) == 0
    folder = tmp_path / "overlap"
    for cam in ("cam_a", "cam_b"):
        frames = list(read_video_frames(folder / f"{cam}.mkv"))
        assert [f.ref.time_ns for f in frames] == [0, 50_000_000, 100_000_000]
        png = cv2.imread(str(sorted((folder / cam).glob("*.png"))[1]), cv2.IMREAD_GRAYSCALE)
        np.testing.assert_array_equal(frames[1].image, png)  # FFV1: lossless


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="unknown scenario"):
        render_scenario("/nonexistent", "nope")
    with pytest.raises(ValueError, match="frames"):
        render_scenario("/nonexistent", "overlap", frames=0)

"""Fixed-joint bundle adjustment on corner observations (acs_cli.core.bundle)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.bundle import intrinsics_vector, right_jacobians
from acs_cli.core.camera_models import camera_model
from acs_cli.core.joint import estimate_joint_fixed
from acs_cli.core.paper import algorithm_2_pivot
from acs_cli.core.rig_bundle import bundle_adjust_fixed_joint
from acs_cli.errors import InputError
from acs_cli.io.artifacts import make_header, to_plain
from acs_cli.io.intrinsics import IntrinsicsArtifact
from acs_cli.io.joint import BundleSection
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.trajectory import Trajectory
from acs_cli.stages.bundle import bundle_fixed_joint
from sample_data_gen.acs_sim import random_unit_vectors

W, H = 1024, 768
BOARD = np.array([[c * 0.04, r * 0.04, 0.0] for r in range(6) for c in range(9)])

PINHOLE = camera_model("pinhole")


#: A lens of each model: focal length (px) and distortion (the pinhole one is drawn).
LENSES = {
    "rational": (800.0, np.array([0.3, -0.1, 5e-4, -5e-4, 0.01, 0.55, -0.05, 0.02])),
    "fisheye": (420.0, np.array([0.03, -0.012, 0.004, -0.001])),
}


def _scene(rng: np.random.Generator, sigma_px: float, n: int = 20, model: str = "pinhole") -> dict:
    """A camera turning about a joint 0.25 m away, looking at a board 0.75 m away."""
    f0 = 900.0 if model == "pinhole" else LENSES[model][0]
    K = np.array([[f0 * rng.uniform(0.95, 1.05), 0, 512 + rng.normal(0, 5)],
                  [0, f0 * rng.uniform(0.95, 1.05), 384 + rng.normal(0, 5)],
                  [0, 0, 1]])  # fmt: skip
    dist = np.array([rng.uniform(-0.25, 0.05), rng.uniform(-0.05, 0.1), *rng.normal(0, 1e-3, 2), 0])
    if model != "pinhole":
        dist = LENSES[model][1]
    o = random_unit_vectors(rng, 1)[0] * 0.25
    R_rest = se3.matrix_from_rotvec(rng.normal(0, 0.1, 3))
    centre = BOARD.mean(axis=0)
    p_w = R_rest @ o + centre - R_rest @ np.array([0, 0, 0.75])
    Rs, obs = [], []
    while len(Rs) < n:
        angle = np.radians(rng.uniform(5, 25))
        R = se3.matrix_from_rotvec(random_unit_vectors(rng, 1)[0] * angle) @ R_rest
        x_cam = (BOARD - p_w) @ R + o
        uv = camera_model(model).project(x_cam, intrinsics_vector(K, dist, model))
        if np.any(uv < 5) or np.any(uv[:, 0] > W - 5) or np.any(uv[:, 1] > H - 5):
            continue
        Rs.append(R)
        obs.append(uv + rng.normal(0, sigma_px, uv.shape))
    R = np.array(Rs)
    T = se3.transforms_from_rt(R, p_w - se3.rotate(R, o))
    return {"K": K, "dist": dist, "o": o, "p_w": p_w, "T": T, "obs": np.array(obs),
            "intrinsics": intrinsics_vector(K, dist, model)}  # fmt: skip


def hide_corners(rng: np.random.Generator, corners: np.ndarray) -> np.ndarray:
    """The corners with 30-70% of them NaN (not seen) in every other frame: a partial view
    of the target, a different part each time (a band of rows or columns, or scattered)."""
    out = corners.copy()
    m = corners.shape[1]
    for i in range(0, corners.shape[0], 2):
        k = round(rng.uniform(0.3, 0.7) * m)
        if i % 4 == 0:  # one side of the board out of the image
            start = int(rng.integers(0, m - k + 1))
            out[i, start : start + k] = np.nan
        else:  # scattered: occlusions, corners not identified
            out[i, rng.choice(m, k, replace=False)] = np.nan
    return out


def _plain_chain(s: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """OpenCV calibrateCamera + the linear pivot: the baseline the issue measures."""
    n = s["obs"].shape[0]
    _, K0, d0, rv, tv = cv2.calibrateCamera(
        [BOARD.astype(np.float32)] * n,
        [o.reshape(-1, 1, 2).astype(np.float32) for o in s["obs"]],
        (W, H), None, None,
    )  # fmt: skip
    T_cb = se3.transforms_from_rt(
        se3.matrix_from_rotvec(np.array(rv).reshape(-1, 3)), np.array(tv).reshape(-1, 3)
    )
    T_wc = se3.invert_transforms(T_cb)
    piv = algorithm_2_pivot(T_wc)
    return intrinsics_vector(K0, d0.ravel()), T_wc, piv.position_in_cam, piv.position_in_world


def test_projection_jacobians_match_finite_differences(rng: np.random.Generator) -> None:
    intr = np.array([900, 910, 500, 380, -0.2, 0.05, 0.001, -0.002, 0.01])
    X = rng.normal(size=(6, 3)) * 0.3 + [0, 0, 1.0]
    Di, Dp = PINHOLE.jacobians(X, intr)
    h, project = 1e-6, PINHOLE.project
    num_i = np.stack([(project(X, intr + e * h) - project(X, intr - e * h)) / (2 * h)
                      for e in np.eye(9)], axis=-1)  # fmt: skip
    num_p = np.stack([(project(X + e * h, intr) - project(X - e * h, intr)) / (2 * h)
                      for e in np.eye(3)], axis=-1)  # fmt: skip
    np.testing.assert_allclose(Di, num_i, atol=1e-4)
    np.testing.assert_allclose(Dp, num_p, atol=1e-3)
    # the projection is OpenCV's
    K = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1]])
    uv, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, intr[4:])
    np.testing.assert_allclose(PINHOLE.project(X, intr), uv.reshape(-1, 2), atol=1e-9)


def test_right_jacobian(rng: np.random.Generator) -> None:
    phi = rng.normal(size=(4, 3))
    Jr = right_jacobians(phi)
    for i in range(4):
        for k in range(3):
            d = np.zeros(3)
            d[k] = 1e-7
            lhs = se3.rotvec_from_matrix(
                se3.matrix_from_rotvec(phi[i]).T @ se3.matrix_from_rotvec(phi[i] + d)
            )
            np.testing.assert_allclose(lhs / 1e-7, Jr[i, :, k], atol=1e-6)


def test_exact_on_noise_free_corners(rng: np.random.Generator) -> None:
    s = _scene(rng, sigma_px=0.0)
    intr0, T0, o0, pw0 = _plain_chain(s)
    valid = np.ones(s["obs"].shape[:2], dtype=bool)
    ba = bundle_adjust_fixed_joint(s["obs"], valid, BOARD, intr0, T0, o0, pw0)
    np.testing.assert_allclose(ba.joint_in_cam, s["o"], atol=1e-7)
    np.testing.assert_allclose(ba.joint_in_world, s["p_w"], atol=1e-7)
    np.testing.assert_allclose(ba.intrinsics, intrinsics_vector(s["K"], s["dist"]), atol=1e-5)
    assert ba.rms_px < 1e-6


def test_missing_corners_are_handled(rng: np.random.Generator) -> None:
    s = _scene(rng, sigma_px=0.0)
    intr0, T0, o0, pw0 = _plain_chain(s)
    valid = rng.uniform(size=s["obs"].shape[:2]) > 0.2
    obs = np.where(valid[:, :, None], s["obs"], np.nan)  # missing corners carry no data
    ba = bundle_adjust_fixed_joint(obs, valid, BOARD, intr0, T0, o0, pw0)
    np.testing.assert_allclose(ba.joint_in_cam, s["o"], atol=1e-7)


@pytest.mark.parametrize("model", ["pinhole", "rational", "fisheye"])
def test_models_and_partial_views_recover_the_truth(rng: np.random.Generator, model: str) -> None:
    """Each camera model, with 30-70% of the corners missing (NaN) in half the frames,
    from intrinsics 1-2% off, poses 0.6 deg off and the joint 1 cm off: the corners'
    own intrinsics and joint, exactly on noise-free corners."""
    s = _scene(rng, sigma_px=0.0, model=model)
    obs = hide_corners(rng, s["obs"])
    assert np.isnan(obs).any(axis=2).sum() > 0.15 * obs[..., 0].size
    truth = s["intrinsics"]
    intr0 = truth.copy()
    intr0[:4] *= [1.02, 0.98, 1.01, 0.99]
    free = camera_model(model).free()  # the rational model holds k4 k5 k6: start them true
    intr0[free[4:]] *= 0.9
    turn = se3.matrix_from_rotvec(rng.normal(0, 0.01, (len(s["T"]), 3)))
    T0 = np.matmul(s["T"], se3.transforms_from_rt(turn, np.zeros((len(turn), 3))))
    ba = bundle_adjust_fixed_joint(
        obs, None, BOARD, intr0, T0, s["o"] + rng.normal(0, 0.01, 3),
        s["p_w"] + rng.normal(0, 0.01, 3), model=model,
    )  # fmt: skip
    assert ba.success and ba.model == model and ba.rms_px < 1e-6
    np.testing.assert_allclose(ba.joint_in_cam, s["o"], atol=1e-7)
    np.testing.assert_allclose(ba.joint_in_world, s["p_w"], atol=1e-7)
    np.testing.assert_allclose(ba.intrinsics[:4], truth[:4], rtol=1e-7)
    np.testing.assert_allclose(ba.intrinsics[4:], truth[4:], atol=1e-6)
    assert ba.intrinsics_covariance.shape == (truth.size, truth.size)
    assert ba.intrinsics_std.shape == truth.shape
    # a frame seeing too few corners is refused, naming it
    obs[3, 3:] = np.nan
    with pytest.raises(InputError, match="fewer than 4 corners at frame"):
        bundle_adjust_fixed_joint(obs, None, BOARD, intr0, T0, s["o"], s["p_w"], model=model)


def test_the_stage_refines_a_fisheye_camera_on_partial_views(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    """``acscal joint``'s fixed-joint bundle from a poses NPZ whose corners are NaN where not
    seen and a fisheye intrinsics file: the joint within its std, the section naming the
    fisheye model's parameters, through a YAML round trip."""
    s = _scene(rng, sigma_px=0.05, model="fisheye")
    K0 = s["K"].copy()
    K0[0, 0] *= 1.01
    K0[1, 1] *= 0.99
    intr = IntrinsicsArtifact(
        model="fisheye", image_size=(W, H), camera_matrix=K0, distortion=0.9 * s["dist"]
    )
    header = make_header("intrinsics", {}, "test", {}, {})
    dataclasses.replace(intr, header=header).save(tmp_path / "intrinsics.yaml")
    turn = se3.matrix_from_rotvec(rng.normal(0, 0.005, (len(s["T"]), 3)))
    T = np.matmul(s["T"], se3.transforms_from_rt(turn, rng.normal(0, 0.002, (len(turn), 3))))
    PosesArtifact(
        trajectory=Trajectory(np.arange(len(T)) / 30.0, T, "x", "npz", True),
        corners=hide_corners(rng, s["obs"]),
        board_points=BOARD,
        header=make_header("poses", {}, "test", {}, {})
        | {"intrinsics_file": str(tmp_path / "intrinsics.yaml")},
    ).save(tmp_path / "poses.npz")
    est = estimate_joint_fixed(T)
    poses = PosesArtifact.load(tmp_path / "poses.npz")
    refined, section, notes = bundle_fixed_joint(poses, T, est, "a")
    assert section is not None and not notes
    err = np.linalg.norm(refined.position_in_a - s["o"])
    assert err < 4 * np.linalg.norm(refined.std_a) and err < 0.002, err
    assert err < 0.5 * np.linalg.norm(est.position_in_a - s["o"])
    back = BundleSection.parse(to_plain(section.to_plain()), "section", None)
    assert back.model == "fisheye" and list(back.intrinsics_std) == list(
        camera_model("fisheye").names
    )
    assert list(back.values()) == list(camera_model("fisheye").names)
    np.testing.assert_allclose(back.values()["fx"], s["K"][0, 0], rtol=1e-3)


@pytest.mark.slow
def test_beats_the_plain_chain() -> None:
    """At the renderer's corner noise (0.05 px) the joint error drops well below the plain
    OpenCV chain's and below the issue's bar of 0.6% of |O|."""
    errs = []
    for i in range(12):
        rng = np.random.default_rng([77, i])
        s = _scene(rng, sigma_px=0.05)
        intr0, T0, o0, pw0 = _plain_chain(s)
        valid = np.ones(s["obs"].shape[:2], dtype=bool)
        ba = bundle_adjust_fixed_joint(s["obs"], valid, BOARD, intr0, T0, o0, pw0)
        norm = np.linalg.norm(s["o"])
        errs.append(
            [np.linalg.norm(o0 - s["o"]) / norm, np.linalg.norm(ba.joint_in_cam - s["o"]) / norm]
        )
    e = np.mean(errs, axis=0)
    assert e[1] < 0.75 * e[0]
    assert e[1] < 0.006


def test_an_identified_target_is_never_relabelled(tmp_path: Path) -> None:
    """A half turn relabels a checkerboard's corners, never an AprilGrid's (ids are read)."""
    from acs_cli.core.intrinsics import board_points
    from acs_cli.io.target import parse_target, target_to_mapping
    from acs_cli.io.trajectory import Trajectory, write_npz_poses
    from acs_cli.stages.bundle import shared_board_flip

    T = np.tile(np.eye(4), (3, 1, 1))
    T[:, 2, 3] = 1.0
    traj = Trajectory(np.arange(3.0), T, "x", "npz", True)

    def save(name: str, X: np.ndarray, header: dict) -> PosesArtifact:
        path = tmp_path / name
        corners = np.zeros((3, X.shape[0], 2))
        write_npz_poses(path, traj, {"corners": corners, "board_points": X}, header=header)
        return PosesArtifact.load(path)

    X = board_points(4, 4, 0.03)
    board = (save("a.npz", X, {}), save("b.npz", X, {}))
    assert shared_board_flip(board) is not None  # a square checkerboard: two labellings
    grid = parse_target("aprilgrid:3x3:0.05:0.3")
    G = grid.points()
    head = {"target": target_to_mapping(grid)}
    tags = (save("c.npz", G, head), save("d.npz", G, head))
    assert shared_board_flip(tags) is None


def test_frames_rejected_on_their_poses_are_judged_again_on_their_corners(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    """Partial views whose (noisier) poses the pose-based fit rejected come back into the
    fixed-joint bundle when their corners fit; a frame taken with the joint moved by 2 cm
    stays out. The section and the estimate's inliers count the frames used."""
    s = _scene(rng, sigma_px=0.1, n=16)
    corners = hide_corners(rng, s["obs"])
    moved = 5  # a frame taken with the joint elsewhere: its corners fit no rotation
    R = s["T"][moved, :3, :3]
    x_cam = (BOARD - (s["p_w"] + np.array([0.02, -0.01, 0.0]))) @ R + s["o"]
    corners[moved] = PINHOLE.project(x_cam, s["intrinsics"]) + rng.normal(0, 0.1, (54, 2))
    intr = IntrinsicsArtifact(
        model="pinhole", image_size=(W, H), camera_matrix=s["K"], distortion=s["dist"]
    )
    header = make_header("intrinsics", {}, "test", {}, {})
    dataclasses.replace(intr, header=header).save(tmp_path / "intrinsics.yaml")
    turn = se3.matrix_from_rotvec(rng.normal(0, 0.003, (len(s["T"]), 3)))
    T = np.matmul(s["T"], se3.transforms_from_rt(turn, rng.normal(0, 0.001, (len(turn), 3))))
    PosesArtifact(
        trajectory=Trajectory(np.arange(len(T)) / 30.0, T, "x", "npz", True),
        corners=corners,
        board_points=BOARD,
        header=make_header("poses", {}, "test", {}, {})
        | {"intrinsics_file": str(tmp_path / "intrinsics.yaml")},
    ).save(tmp_path / "poses.npz")
    est = estimate_joint_fixed(T)
    rejected = np.zeros(len(T), dtype=bool)
    rejected[[0, 2, 6, 10, moved]] = True  # partial views (even frames) and the moved one
    est = dataclasses.replace(est, inliers={"a": ~rejected})
    poses = PosesArtifact.load(tmp_path / "poses.npz")
    refined, section, notes = bundle_fixed_joint(poses, T, est, "a")
    assert section is not None and not notes
    expected = np.ones(len(T), dtype=bool)
    expected[moved] = False
    np.testing.assert_array_equal(refined.inliers["a"], expected)
    assert section.frames == len(T) - 1
    err = np.linalg.norm(refined.position_in_a - s["o"])
    assert err < 4 * np.linalg.norm(refined.std_a), err
    # the frames the poses kept alone determine the joint less well
    only = bundle_adjust_fixed_joint(
        corners[~rejected], None, BOARD, s["intrinsics"], T[~rejected], est.position_in_a,
        est.position_in_world["a"],
    )  # fmt: skip
    assert np.linalg.norm(refined.std_a) < 0.95 * np.linalg.norm(only.joint_std)

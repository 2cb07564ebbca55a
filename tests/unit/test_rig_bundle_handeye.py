"""Bodies without corners in the rig's bundle adjustment (issue 19, item 3): a camera on a
robot's flange (eye-in-hand, ``AX = ZB``) and a fixed camera seeing a board on the gripper
(eye-to-hand, the robot's poses inverted); the hand-eye transform ``X``, the board's pose
in the robot's world ``Z`` and the robot's pose noise recovered within their stds, and the
same answer however the rig is written down."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.rig import rig_topology
from acs_cli.core.rig_bundle import (
    CameraViews,
    RigBundle,
    RigidEdgeEstimate,
    bundle_adjust_rig,
)
from acs_cli.core.rig_solve import CameraTrack, estimate_rig
from acs_cli.errors import InputError

NOISE_PX = 0.2
ROBOT_ROT_DEG = 0.05
ROBOT_TRANS = 3e-4


@dataclass(frozen=True)
class HandEye:
    """A simulated hand-eye recording: the camera's corners and PnP poses, the robot's
    noisy poses (``T_base_flange``, or inverted for eye-to-hand), and the truth."""

    corners: np.ndarray
    board: np.ndarray
    intrinsics: np.ndarray
    intrinsics0: np.ndarray
    T_board_cam: np.ndarray
    robot: np.ndarray
    X: np.ndarray  # T_flange_cam (eye-in-hand) or T_base_cam (eye-to-hand)
    Z: np.ndarray  # T_base_board (eye-in-hand) or T_flange_board (eye-to-hand)

    def views(self) -> dict[str, CameraViews]:
        ok = np.isfinite(self.corners).all(axis=2)
        return {"cam": CameraViews(self.corners, ok, self.board, self.intrinsics0)}

    def tracks(self, body: str) -> dict[str, CameraTrack]:
        ok = np.ones(self.robot.shape[0], bool)
        return {"cam": CameraTrack(self.T_board_cam, ok), body: CameraTrack(self.robot, ok)}


def _noisy(rng: np.random.Generator, T: np.ndarray) -> np.ndarray:
    out = T.copy()
    dR = se3.matrix_from_rotvec(rng.normal(scale=np.radians(ROBOT_ROT_DEG), size=(len(T), 3)))
    out[:, :3, :3] = np.matmul(T[:, :3, :3], dR)
    out[:, :3, 3] += rng.normal(scale=ROBOT_TRANS, size=(len(T), 3))
    return out


def simulate(rng: np.random.Generator, n: int = 30) -> HandEye:
    """Camera poses all around an 8x6 board (0.03 m squares) at 0.6-0.9 m, tilted up to
    35 deg and rolled freely; 640x480 pinhole with distortion, corners with 0.2 px noise;
    intrinsics to start from 0.3% off; the robot's poses with 0.05 deg and 0.3 mm noise."""
    gx, gy = np.meshgrid(np.arange(8), np.arange(6))
    board = np.stack([gx.ravel() * 0.03, gy.ravel() * 0.03, np.zeros(gx.size)], axis=1)
    centre = board.mean(axis=0)
    K = np.array([[800.0, 0, 320.0], [0, 801.0, 240.0], [0, 0, 1]])
    dist = np.array([-0.15, 0.05, 1e-3, -1e-3, 0.0])
    T_board_cam = np.zeros((n, 4, 4))
    for i in range(n):
        axis = rng.normal(size=2)
        tilt = np.radians(rng.uniform(10, 35)) * np.append(axis / np.linalg.norm(axis), 0.0)
        R = se3.matrix_from_rotvec(tilt) @ se3.matrix_from_rotvec(
            [0, 0, rng.uniform(-np.pi, np.pi)]
        )
        T_board_cam[i] = se3.transforms_from_rt(R, centre - rng.uniform(0.6, 0.9) * R[:, 2])
    T_cam_board = se3.invert_transforms(T_board_cam)
    px = np.stack(
        [
            cv2.projectPoints(board, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], K, dist)[0][:, 0]
            for T in T_cam_board
        ]
    )
    if np.any(np.abs(px - [320, 240]) > [320, 240]):
        raise ValueError("a corner outside the image: change the simulation")
    px = px + rng.normal(scale=NOISE_PX, size=px.shape)
    intr = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *dist])
    intr0 = intr * np.array([1.003, 1.003, 1, 1, 0.95, 0.95, 0.95, 0.95, 1]) + [
        0,
        0,
        1,
        -1,
        0,
        0,
        0,
        0,
        0,
    ]
    K0 = np.array([[intr0[0], 0, intr0[2]], [0, intr0[1], intr0[3]], [0, 0, 1]])
    pnp = np.zeros_like(T_board_cam)
    for i in range(n):
        _ok, rv, tv = cv2.solvePnP(board, px[i], K0, intr0[4:])
        pnp[i] = se3.invert_transforms(se3.transforms_from_rt(cv2.Rodrigues(rv)[0], tv.ravel()))
    X = se3.transforms_from_rt(se3.matrix_from_rotvec([0.3, -0.2, 1.2]), [0.04, -0.06, 0.12])
    Z = se3.transforms_from_rt(se3.matrix_from_rotvec([2.5, 0.4, -0.3]), [0.7, 0.2, -0.1])
    # eye-in-hand: T_base_flange = Z T_board_cam X^-1. Eye-to-hand: T_base_flange =
    # X T_cam_board Z^-1, given inverted (T_flange_base): the same expression
    robot = Z @ T_board_cam @ se3.invert_transforms(X)
    return HandEye(px, board, intr, intr0, pnp, _noisy(rng, robot), X, Z)


def solve(
    rec: HandEye, *, body: str = "flange", swap: bool = False, reference: str = "cam"
) -> RigBundle:
    between = [body, "cam"] if swap else ["cam", body]
    topo = rig_topology(["cam", body], [("handeye", between, "rigid")], reference)
    est = estimate_rig(topo, rec.tracks(body))
    frames = np.arange(rec.robot.shape[0])
    return bundle_adjust_rig(topo, rec.views(), est, frames, {body: rec.tracks(body)[body]})


def hand_eye(ba: RigBundle, body: str = "flange") -> tuple[np.ndarray, np.ndarray]:
    """``T_body_cam`` and its covariance, whichever way the joint is written."""
    e = ba.estimate.edges["handeye"]
    assert isinstance(e, RigidEdgeEstimate)
    if e.joint.between == ("cam", body):
        return e.T_q_p, e.T_q_p_covariance
    # T_q_p is T_cam_body: its inverse (compared by value only)
    return se3.invert_transforms(e.T_q_p), np.full((6, 6), np.nan)


def _errors_in_std(truth: np.ndarray, T: np.ndarray, C: np.ndarray) -> np.ndarray:
    rot = se3.rotvec_from_matrix(T[:3, :3].T @ truth[:3, :3])
    err = np.concatenate([rot, truth[:3, 3] - T[:3, 3]])
    return err / np.sqrt(np.diag(C))


@pytest.fixture(scope="module")
def eye_in_hand() -> tuple[HandEye, RigBundle]:
    rec = simulate(np.random.default_rng(20240607))
    return rec, solve(rec)


def test_eye_in_hand_recovers_x_and_z_within_their_stds(eye_in_hand: tuple) -> None:
    rec, ba = eye_in_hand
    assert ba.success
    X, CX = hand_eye(ba)
    zx = _errors_in_std(rec.X, X, CX)
    assert np.all(np.abs(zx) < 4), zx
    body = ba.pose_bodies["flange"]
    zz = _errors_in_std(rec.Z, body.T_world_board["cam"], body.T_world_board_covariance["cam"])
    assert np.all(np.abs(zz) < 4), zz
    # the stds are sensible: not inflated (some error near its std), sub-millimetre and a
    # fraction of a degree here
    assert max(np.abs(zx).max(), np.abs(zz).max()) > 0.3, (zx, zz)
    assert np.all(np.sqrt(np.diag(CX))[3:] < 1e-3) and np.all(np.sqrt(np.diag(CX))[:3] < 0.01)
    assert np.linalg.norm(X[:3, 3] - rec.X[:3, 3]) < 1e-3
    # the robot's pose noise and the corner noise, by maximum likelihood
    assert body.sigma_rot_deg == pytest.approx(ROBOT_ROT_DEG, rel=0.25)
    assert body.sigma_trans == pytest.approx(ROBOT_TRANS, rel=0.25)
    assert ba.sigma_px == pytest.approx(NOISE_PX, rel=0.1)
    assert set(ba.intrinsics) == {"cam"}
    err = np.abs(ba.intrinsics["cam"][:4] - rec.intrinsics[:4])
    assert np.all(err < 4 * ba.intrinsics_std["cam"][:4]), (err, ba.intrinsics_std["cam"])


def test_the_answer_does_not_depend_on_how_the_rig_is_written(eye_in_hand: tuple) -> None:
    rec, ba = eye_in_hand
    X = hand_eye(ba)[0]
    Z = ba.pose_bodies["flange"].T_world_board["cam"]
    for kw in ({"swap": True}, {"reference": "flange"}, {"swap": True, "reference": "flange"}):
        other = solve(rec, **kw)  # type: ignore[arg-type]
        X2 = hand_eye(other)[0]
        Z2 = other.pose_bodies["flange"].T_world_board["cam"]
        # to 1e-6 rad and 1e-7 m (~1e-4 of their stds: where the finite-difference Jacobian
        # leaves the flattest directions)
        for a, b in ((X, X2), (Z, Z2)):
            assert np.linalg.norm(se3.rotvec_from_matrix(a[:3, :3].T @ b[:3, :3])) < 1e-6, kw
            assert np.linalg.norm(a[:3, 3] - b[:3, 3]) < 1e-7, kw
        diff = np.abs(other.intrinsics["cam"] - ba.intrinsics["cam"])
        assert np.all(diff <= 1e-3 * ba.intrinsics_std["cam"]), (kw, diff)
        assert other.pose_bodies["flange"].sigma_trans == pytest.approx(
            ba.pose_bodies["flange"].sigma_trans, rel=1e-4
        )
        if not kw.get("swap"):
            np.testing.assert_allclose(hand_eye(other)[1], hand_eye(ba)[1], rtol=1e-3, atol=1e-16)


def test_eye_to_hand_is_the_same_graph_with_the_robot_inverted() -> None:
    """A fixed camera and the board on the gripper: the robot's poses inverted
    (``T_flange_base``) make the base a body moving in the flange's world; the rigid joint
    is then the camera in the base (``X``), and the base body's world holds the board on
    the flange (``Z``)."""
    rec = simulate(np.random.default_rng(5))
    ba = solve(rec, body="base")
    X, CX = hand_eye(ba, "base")
    assert np.all(np.abs(_errors_in_std(rec.X, X, CX)) < 4)
    body = ba.pose_bodies["base"]
    zz = _errors_in_std(rec.Z, body.T_world_board["cam"], body.T_world_board_covariance["cam"])
    assert np.all(np.abs(zz) < 4), zz


def test_pose_only_bodies_are_checked(eye_in_hand: tuple) -> None:
    rec, _ba = eye_in_hand
    topo = rig_topology(["cam", "flange"], [("handeye", ["cam", "flange"], "rigid")], "cam")
    est = estimate_rig(topo, rec.tracks("flange"))
    frames = np.arange(rec.robot.shape[0])
    track = rec.tracks("flange")["flange"]
    with pytest.raises(InputError, match=r"no corners for camera.*no poses"):
        bundle_adjust_rig(topo, rec.views(), est, frames)
    with pytest.raises(InputError, match="no camera of the rig has corners"):
        bundle_adjust_rig(topo, {}, est, frames, rec.tracks("flange"))
    gap = CameraTrack(track.T_w_c, track.valid & (frames != 3))
    with pytest.raises(InputError, match="flange has no pose at frame"):
        bundle_adjust_rig(topo, rec.views(), est, frames, {"flange": gap})
    short = CameraTrack(track.T_w_c[:5], track.valid[:5])
    with pytest.raises(InputError, match="not on the rig's timeline"):
        bundle_adjust_rig(topo, rec.views(), est, frames, {"flange": short})

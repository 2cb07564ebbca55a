"""Joint angles per frame (acs_cli.core.angles, issue 22 item 1)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from acs_cli.core import se3
from acs_cli.core.angles import (
    articulation_from_orientations,
    ball_angles,
    hinge_angle_range_deg,
    hinge_angles,
)
from acs_cli.errors import InputError
from sample_data_gen.acs_sim import add_pose_noise, random_rotations


def _hinge_motion(rng: np.random.Generator, n: int, wobble_deg: float = 0.0):  # type: ignore[no-untyped-def]
    """Body p turning anyhow, q hinged to it about u_p by theta (beyond +-180 deg too)."""
    u_p = rng.normal(size=3)
    u_p /= np.linalg.norm(u_p)
    theta = np.radians(np.linspace(-40.0, 250.0, n))
    R_w_p = random_rotations(rng, n, 180.0)
    R_p_q0 = random_rotations(rng, 1, 180.0)[0]
    off = np.cross(u_p, rng.normal(size=3))
    off /= np.linalg.norm(off)
    W = se3.matrix_from_rotvec(np.radians(wobble_deg) * np.sin(theta)[:, None] * off)
    R_p_q = W @ se3.matrix_from_rotvec(theta[:, None] * u_p) @ R_p_q0
    return R_w_p, R_w_p @ R_p_q, u_p, np.degrees(theta)


def test_a_hinge_angle_is_its_turn_about_the_axis_by_the_right_hand_rule(
    rng: np.random.Generator,
) -> None:
    R_w_p, R_w_q, u_p, truth = _hinge_motion(rng, 60)
    k = 7
    h = hinge_angles(articulation_from_orientations(R_w_p, R_w_q, k), u_p, 0.1, k)
    assert np.abs(h.angle_deg - (truth - truth[k])).max() < 1e-9  # past 180 deg, unwrapped
    assert h.wobble_rms_deg < 1e-9
    assert h.angle_std_deg[k] == 0.0 and np.all(h.angle_std_deg[np.arange(60) != k] == 0.2)
    # the other way round the axis, the other sign
    flipped = hinge_angles(articulation_from_orientations(R_w_p, R_w_q, k), -u_p, 0.1, k)
    assert np.allclose(flipped.angle_deg, -h.angle_deg)


def test_a_hinge_angle_range_is_zero_at_the_pose_given(rng: np.random.Generator) -> None:
    """The range a URDF's limits are made of: zero at the rig's pose at the reference
    instant (here q's start, R_p_q0), past 180 deg unwrapped, the axis's sign its sense."""
    R_w_p, R_w_q, u_p, truth = _hinge_motion(rng, 60)
    R_p_q = np.einsum("nji,njk->nik", R_w_p, R_w_q)
    R_p_q0 = se3.matrix_from_rotvec(np.radians(truth[0]) * u_p).T @ R_p_q[0]  # theta = 0
    lo, hi = hinge_angle_range_deg(R_w_p, R_w_q, R_p_q0, u_p)
    assert (lo, hi) == pytest.approx((truth.min(), truth.max()), abs=1e-9)
    assert hinge_angle_range_deg(R_w_p, R_w_q, R_p_q0, -3.0 * u_p) == pytest.approx((-hi, -lo))
    # another zero: the rig's pose 30 deg further on
    turned = se3.matrix_from_rotvec(np.radians(30.0) * u_p) @ R_p_q0
    assert hinge_angle_range_deg(R_w_p, R_w_q, turned, u_p) == pytest.approx((lo - 30, hi - 30))
    # a range about half a turn: its middle within half a turn of the zero, whichever branch
    # the first frame's twist fell on
    back = hinge_angle_range_deg(R_w_p[::-1], R_w_q[::-1], R_p_q0, u_p)
    assert back == pytest.approx((lo, hi), abs=1e-9)
    with pytest.raises(InputError, match="at least one frame"):
        hinge_angle_range_deg(R_w_p[:0], R_w_q[:0], R_p_q0, u_p)


def test_a_wobbling_hinge_reports_its_wobble(rng: np.random.Generator) -> None:
    R_w_p, R_w_q, u_p, truth = _hinge_motion(rng, 200, wobble_deg=2.0)
    h = hinge_angles(articulation_from_orientations(R_w_p, R_w_q, 0), u_p, 0.1, 0)
    assert 1.0 < h.wobble_rms_deg < 2.5
    assert np.abs(h.angle_deg - (truth - truth[0])).max() < 0.5


def _noisy(rng: np.random.Generator, R: np.ndarray, sigma: float) -> np.ndarray:
    T = se3.transforms_from_rt(R, np.zeros((R.shape[0], 3)))
    return add_pose_noise(rng, T, sigma, 0.0)[:, :3, :3]


def test_the_hinge_angle_std_matches_the_noise(rng: np.random.Generator) -> None:
    """Over 300 noise draws of a 12-frame recording (the reference's own noise shifts every
    angle of a draw alike, so one draw alone cannot tell)."""
    R_w_p, R_w_q, u_p, truth = _hinge_motion(rng, 12)
    sigma, z = 0.3, []
    for _ in range(300):
        D = articulation_from_orientations(_noisy(rng, R_w_p, sigma), _noisy(rng, R_w_q, sigma), 0)
        h = hinge_angles(D, u_p, sigma, 0)
        z.append((h.angle_deg - (truth - truth[0]))[1:] / h.angle_std_deg[1:])
    assert 0.9 < float(np.sqrt(np.mean(np.square(z)))) < 1.1


def test_ball_angles_are_the_articulation_in_the_sequence_asked(rng: np.random.Generator) -> None:
    n, k = 300, 3
    R_w_p = random_rotations(rng, n, 180.0)
    D = random_rotations(rng, n, 60.0)
    D[k] = np.eye(3)
    R_p_q0 = random_rotations(rng, 1, 180.0)[0]
    R_w_q = R_w_p @ D @ R_p_q0
    b = ball_angles(articulation_from_orientations(R_w_p, R_w_q, k), 0.2, k, "ZXY")
    assert np.abs(b.rotvec_deg - np.degrees(se3.rotvec_from_matrix(D))).max() < 1e-8
    assert np.abs(b.euler_deg - Rotation.from_matrix(D).as_euler("ZXY", degrees=True)).max() < 1e-8
    assert b.euler_std_deg[k].tolist() == [0.0, 0.0, 0.0]
    # the Euler angles' stds over noise draws (away from the sequence's gimbal lock)
    sigma, z = 0.2, []
    for _ in range(100):
        D_noisy = articulation_from_orientations(
            _noisy(rng, R_w_p[:20], sigma), _noisy(rng, R_w_q[:20], sigma), k
        )
        noisy = ball_angles(D_noisy, sigma, k, "ZXY")
        keep = (np.arange(20) != k) & np.all(np.isfinite(noisy.euler_std_deg), axis=1)
        z.append((noisy.euler_deg - b.euler_deg[:20])[keep] / noisy.euler_std_deg[keep])
    ratio = np.sqrt(np.mean(np.concatenate(z) ** 2, axis=0))
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio


def test_ball_angles_without_a_noise_level(rng: np.random.Generator) -> None:
    """sigma NaN (rig.yaml records none): the same angles, every std NaN but 0 at the
    reference, as the derivatives times NaN gave."""
    n, k = 50, 7
    D = random_rotations(rng, n, 170.0)
    D[k] = np.eye(3)
    D[3] = se3.matrix_from_rotvec([0.0, 0.0, 0.3])  # the sequence's gimbal lock
    known, unknown = ball_angles(D, 0.2, k, "zxz"), ball_angles(D, float("nan"), k, "zxz")
    assert np.array_equal(unknown.rotvec_deg, known.rotvec_deg)
    assert np.array_equal(unknown.euler_deg, known.euler_deg)
    for std in (unknown.rotvec_std_deg, unknown.euler_std_deg):
        assert np.all(np.isnan(np.delete(std, k, axis=0))) and std[k].tolist() == [0.0] * 3


def test_bad_angle_requests_are_input_errors(rng: np.random.Generator) -> None:
    D = random_rotations(rng, 5, 30.0)
    with pytest.raises(InputError, match="not a direction"):
        hinge_angles(D, np.zeros(3), 0.1, 0)
    with pytest.raises(InputError, match="'ABC' is not an Euler sequence"):
        ball_angles(D, 0.1, 0, "ABC")

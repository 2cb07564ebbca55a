"""A hinge joint from a fixed-joint recording (acs_cli.core.joint.estimate_hinge_fixed)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.joint import (
    HINGE_RATIO,
    HingeEstimate,
    estimate_hinge_fixed,
    estimate_joint_fixed,
    joint_motion_warnings,
    perpendicular_basis,
    rejected_runs,
    weakest_direction,
)
from acs_cli.errors import DegenerateMotionError, InputError
from acs_cli.io.artifacts import to_plain
from acs_cli.io.joint import JointArtifact
from acs_cli.io.trajectory import write_tum
from acs_cli.stages.joint import JointConfig, run_joint
from sample_data_gen import acs_sim as sim

SIGMA_ROT_DEG = 0.3
SIGMA_TRANS = 0.01
N_FRAMES = 100
N_TRIALS = 30
HINGE_ANGLE_DEG = 60.0


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240921)


@dataclass(frozen=True)
class HingeSession:
    """A camera turning about a hinge fixed in the world (truth)."""

    T_w_c: np.ndarray  # (n, 4, 4)
    axis_in_cam: np.ndarray  # (3,) unit
    nearest_point: np.ndarray  # (3,) the axis point nearest the optical centre
    axis_in_world: np.ndarray  # (3,)
    point_in_world: np.ndarray  # (3,) where nearest_point stays
    angles_deg: np.ndarray  # (n,)


def _hinge_session(
    rng: np.random.Generator,
    n: int,
    point: np.ndarray,
    axis: np.ndarray,
    max_angle_deg: float = HINGE_ANGLE_DEG,
) -> HingeSession:
    """Poses ``T_w_c`` of a camera whose body turns about the line ``{point + s axis}``
    (camera frame), the line fixed in a random world."""
    u = axis / np.linalg.norm(axis)
    near = point - (point @ u) * u
    R0 = sim.random_rotations(rng, 1)[0]
    a_w = R0 @ u
    angles = rng.uniform(-max_angle_deg, max_angle_deg, size=n)
    R = se3.matrix_from_rotvec(np.radians(angles)[:, None] * a_w) @ R0
    p_w = rng.uniform(-1.0, 1.0, size=3)
    t = p_w - np.einsum("nij,j->ni", R, near)
    return HingeSession(se3.transforms_from_rt(R, t), u, near, a_w, p_w, angles)


def _random_hinge(rng: np.random.Generator, n: int = N_FRAMES) -> HingeSession:
    u = sim.random_unit_vectors(rng, 1)[0]
    point = sim.random_unit_vectors(rng, 1)[0] * rng.uniform(1.0, 2.0)
    return _hinge_session(rng, n, point, u)


def _noisy(rng: np.random.Generator, T: np.ndarray) -> np.ndarray:
    return np.asarray(sim.add_pose_noise(rng, T, SIGMA_ROT_DEG, SIGMA_TRANS))


def _axis_error_deg(est: HingeEstimate, u: np.ndarray) -> float:
    """Angle between the estimated and the true axis, up to sign."""
    c = min(abs(float(est.axis_in_cam @ u)), 1.0)
    return float(np.degrees(np.arccos(c)))


def _check_exact(est: HingeEstimate, s: HingeSession, n: int) -> None:
    sign = np.sign(est.axis_in_cam @ s.axis_in_cam)
    np.testing.assert_allclose(est.axis_in_cam, sign * s.axis_in_cam, atol=1e-9)
    np.testing.assert_allclose(est.point_in_cam, s.nearest_point, atol=1e-9)
    np.testing.assert_allclose(est.axis_in_world, sign * s.axis_in_world, atol=1e-9)
    np.testing.assert_allclose(est.point_in_world, s.point_in_world, atol=1e-9)
    assert abs(est.point_in_cam @ est.axis_in_cam) < 1e-12
    assert est.residual_rms < 1e-9
    assert est.inliers.shape == (n,) and est.inliers.all()
    assert est.angle_range_deg == pytest.approx(np.ptp(s.angles_deg), abs=1e-6)
    assert est.covariance_axis.shape == (3, 3) and est.covariance_point.shape == (3, 3)


# ----------------------------------------------------------------------------- exact recovery


@pytest.mark.parametrize("method", ["refined", "paper"])
def test_noiseless_recovery(rng: np.random.Generator, method: str) -> None:
    s = _random_hinge(rng, 30)
    est = estimate_hinge_fixed(s.T_w_c, method=method)
    _check_exact(est, s, 30)
    assert est.method == method


def test_noiseless_recovery_with_three_frames(rng: np.random.Generator) -> None:
    s = _random_hinge(rng, 3)
    _check_exact(estimate_hinge_fixed(s.T_w_c), s, 3)


def test_any_point_of_the_axis_gives_the_nearest_point(rng: np.random.Generator) -> None:
    u = sim.random_unit_vectors(rng, 1)[0]
    near = np.cross(u, sim.random_unit_vectors(rng, 1)[0])
    s = _hinge_session(rng, 20, near + 3.0 * u, u)  # built from a point 3 m along the axis
    np.testing.assert_allclose(s.nearest_point, near, atol=1e-12)
    est = estimate_hinge_fixed(s.T_w_c)
    np.testing.assert_allclose(est.point_in_cam, near, atol=1e-9)


def test_camera_on_the_axis(rng: np.random.Generator) -> None:
    u = sim.random_unit_vectors(rng, 1)[0]
    s = _hinge_session(rng, 20, 0.5 * u, u)
    est = estimate_hinge_fixed(s.T_w_c)
    np.testing.assert_allclose(est.point_in_cam, np.zeros(3), atol=1e-9)


def test_axis_sign_convention(rng: np.random.Generator) -> None:
    """The largest-magnitude component of the axis is positive, whichever way it turns."""
    s = _random_hinge(rng, 20)
    est = estimate_hinge_fixed(s.T_w_c)
    assert est.axis_in_cam[np.argmax(np.abs(est.axis_in_cam))] > 0.0
    flipped = _hinge_session(rng, 20, s.nearest_point, -s.axis_in_cam)
    np.testing.assert_allclose(estimate_hinge_fixed(flipped.T_w_c).axis_in_cam, est.axis_in_cam)


# ----------------------------------------------------------------------------- with noise


def test_noisy_accuracy(rng: np.random.Generator) -> None:
    s = _random_hinge(rng)
    est = estimate_hinge_fixed(_noisy(rng, s.T_w_c))
    assert _axis_error_deg(est, s.axis_in_cam) < 1.0
    assert np.linalg.norm(est.point_in_cam - s.nearest_point) < 0.03
    assert abs(est.point_in_cam @ est.axis_in_cam) < 1e-12
    assert est.noise["sigma_rot_deg"] == pytest.approx(SIGMA_ROT_DEG, rel=0.2)
    assert est.noise["sigma_trans"] == pytest.approx(SIGMA_TRANS, rel=0.2)
    # the axis covariance lies across the axis (rank 2), the std in degrees
    assert np.linalg.norm(est.covariance_axis @ est.axis_in_cam) < 1e-12
    assert np.linalg.matrix_rank(est.covariance_axis, tol=1e-6 * est.axis_std_deg**2) == 2
    assert 0.0 < est.axis_std_deg < 1.0
    assert np.all(np.linalg.eigvalsh(est.covariance_point) > 0.0)
    assert est.angle_range_deg == pytest.approx(np.ptp(s.angles_deg), abs=1.0)


@pytest.mark.slow
def test_reported_std_is_honest(rng: np.random.Generator) -> None:
    """Error over reported std, RMS over seeded trials, is near 1 for axis and point."""
    axis_z, point_z, axis_err, point_err = [], [], [], []
    for _ in range(N_TRIALS):
        s = _random_hinge(rng)
        est = estimate_hinge_fixed(_noisy(rng, s.T_w_c))
        e_axis = _axis_error_deg(est, s.axis_in_cam)
        e_point = float(np.linalg.norm(est.point_in_cam - s.nearest_point))
        axis_err.append(e_axis)
        point_err.append(e_point)
        axis_z.append(e_axis / est.axis_std_deg)
        point_z.append(e_point / np.sqrt(np.trace(est.covariance_point)))
    assert max(axis_err) < 1.0 and max(point_err) < 0.03
    axis_ratio = float(np.sqrt(np.mean(np.square(axis_z))))
    point_ratio = float(np.sqrt(np.mean(np.square(point_z))))
    assert 0.7 < axis_ratio < 1.4
    assert 0.7 < point_ratio < 1.4


def test_outlier_frames_rejected(rng: np.random.Generator) -> None:
    s = _random_hinge(rng)
    clean = _noisy(rng, s.T_w_c)
    bad = np.array([7, 42])  # a 30 degree rotation error, a 1 m translation error
    T = np.asarray(sim.corrupt_poses(rng, clean, s.nearest_point, bad))
    est = estimate_hinge_fixed(T)
    assert not est.inliers[bad].any()
    assert est.inliers.sum() >= N_FRAMES - 3
    ref = estimate_hinge_fixed(clean)
    assert _axis_error_deg(est, s.axis_in_cam) < 1.0
    assert np.linalg.norm(est.point_in_cam - s.nearest_point) < 0.03
    # as good as without the outliers
    assert np.linalg.norm(est.point_in_cam - ref.point_in_cam) < 3.0 * np.sqrt(
        np.trace(ref.covariance_point)
    )


# ----------------------------------------------------------------------------- refused


def test_ball_joint_refused(rng: np.random.Generator) -> None:
    rig = sim.make_rig(rng)
    seq = sim.fixed_joint_sequence(rng, rig, 30)
    with pytest.raises(DegenerateMotionError, match="ball joint") as info:
        estimate_hinge_fixed(_noisy(rng, seq.T_wa_a), "camera A")
    assert "more than one axis" in info.value.message
    assert "camera A" in info.value.message
    assert "estimate_pivot" in info.value.message


def test_too_few_frames_refused(rng: np.random.Generator) -> None:
    s = _random_hinge(rng, 2)
    with pytest.raises(DegenerateMotionError, match="at least 3"):
        estimate_hinge_fixed(s.T_w_c)


def test_too_little_rotation_refused(rng: np.random.Generator) -> None:
    u = sim.random_unit_vectors(rng, 1)[0]
    s = _hinge_session(rng, 30, np.array([0.0, 0.0, 1.0]), u, max_angle_deg=1.0)
    with pytest.raises(DegenerateMotionError, match="too little rotation"):
        estimate_hinge_fixed(s.T_w_c)


def test_unknown_method_refused(rng: np.random.Generator) -> None:
    s = _random_hinge(rng, 10)
    with pytest.raises(InputError, match="unknown method"):
        estimate_hinge_fixed(s.T_w_c, method="best")


# ----------------------------------------------------------------------------- two cameras


def test_pair_on_one_hinge(rng: np.random.Generator) -> None:
    """A hinged rig: each camera's body turns about the hinge in its own session."""
    rig = sim.make_rig(rng, hinge=True)
    assert rig.hinge_axis_a is not None
    u_a = rig.hinge_axis_a
    u_b = rig.R0.T @ u_a  # the hinge axis in B's frame (R_a_b = Q R0, Q about u_a)
    a = _hinge_session(rng, 40, rig.o_a, u_a)
    b = _hinge_session(rng, 25, rig.o_b, u_b)  # not paired with A's
    est_a, est_b = estimate_hinge_fixed(a.T_w_c), estimate_hinge_fixed(b.T_w_c)
    assert est_a.method == "refined"
    _check_exact(est_a, a, 40)
    _check_exact(est_b, b, 25)
    # the two nearest points are one point of the rig only when the joint is there: both
    # lie on the same line, so B's point maps onto A's line
    T_a_b = rig.T_a_b(np.eye(3)[None])[0]
    p = se3.transform_points(T_a_b, est_b.point_in_cam)
    d = p - est_a.point_in_cam
    np.testing.assert_allclose(d - (d @ u_a) * u_a, np.zeros(3), atol=1e-9)
    one = estimate_hinge_fixed(a.T_w_c, method="paper")
    assert one.method == "paper"
    np.testing.assert_allclose(one.point_in_cam, a.nearest_point, atol=1e-9)


def test_a_refusal_names_the_camera(rng: np.random.Generator) -> None:
    a = _random_hinge(rng, 20)
    with pytest.raises(DegenerateMotionError, match="camera B"):
        estimate_hinge_fixed(a.T_w_c[:2], "camera B")


# ----------------------------------------------------------------------------- a near-hinge


@dataclass(frozen=True)
class KneeSession:
    T_w_c: np.ndarray  # (n, 4, 4)
    axis_in_cam: np.ndarray  # (3,) the flexion axis
    centre_in_cam: np.ndarray  # (3,) the centre of rotation over most of the range


def _knee_session(rng: np.random.Generator, n: int = 300, slide: float = 0.01) -> KneeSession:
    """A camera on the shank of a knee, 30 cm from it, the thigh held still (issue 13).

    Two flexion cycles of +-17.4 deg (12.3 deg RMS) about the axis ``u``; a smooth wobble
    of 0.85 deg RMS about each of the two other axes; and a centre of rotation that rolls
    by ``slide`` (metres, across the axis) over the last tenth of the flexion, as a knee's
    does near full flexion. Pose noise 0.05 deg, 0.5 mm."""
    u = sim.random_unit_vectors(rng, 1)[0]
    d = perpendicular_basis(u)[:, 0]
    o = sim.random_unit_vectors(rng, 1)[0] * 0.3
    s = np.arange(n) / n
    amplitude = np.radians(17.4)
    phi = amplitude * np.sin(4.0 * np.pi * s)
    w = sim.smooth_rotvecs(rng, 20.0 * s, 1.0)[:, :2]
    w *= np.radians(0.85) / np.sqrt(np.mean(w**2, axis=0))
    R = sim.random_rotations(rng, 1)[0] @ se3.matrix_from_rotvec(
        phi[:, None] * u + w @ perpendicular_basis(u).T
    )
    centre = o + slide * np.clip(phi / amplitude - 0.9, 0.0, None)[:, None] / 0.1 * d
    t = rng.uniform(-1.0, 1.0, size=3) - np.einsum("nij,nj->ni", R, centre)
    T = sim.add_pose_noise(rng, se3.transforms_from_rt(R, t), 0.05, 0.0005)
    return KneeSession(np.asarray(T), u, o)


def test_near_hinge_is_reported_with_its_numbers(rng: np.random.Generator) -> None:
    """A knee-like motion passes as a point (the wobble fixes it to a few mm) but is
    reported: the hinge axis, the rotation about each axis, the weak direction and its
    std, and the rejected frames as runs of misfit, not outliers."""
    knee = _knee_session(rng)
    est = estimate_joint_fixed(knee.T_w_c)
    m = est.motion["a"]
    assert m.near_hinge and m.ratio < HINGE_RATIO
    assert abs(m.dominant_axis @ knee.axis_in_cam) > np.cos(np.radians(1.0))
    assert m.spread_deg[0] == pytest.approx(12.3, abs=0.3)
    assert np.all((m.spread_deg[1:] > 0.5) & (m.spread_deg[1:] < 1.2)), m.spread_deg
    weak, std = weakest_direction(est.covariance_a)
    assert abs(weak @ knee.axis_in_cam) > 0.99  # least determined along the hinge axis
    assert std == pytest.approx(np.sqrt(np.linalg.eigvalsh(est.covariance_a)[-1]))
    runs = rejected_runs(est.inliers["a"])
    long = sorted(runs[runs >= 5].tolist(), reverse=True)
    assert len(long) == 2, runs  # one run near each of the two full flexions
    (text,) = joint_motion_warnings(est, "m")
    axis = "[" + " ".join(f"{x:+.3f}" for x in m.dominant_axis) + "]"
    for part in (
        f"camera A: near-hinge motion (rotation ratio {m.ratio:.3f} < {HINGE_RATIO})",
        f"it turns {m.spread_deg[0]:.3g} deg (RMS) about the axis {axis} in A's frame",
        f"only {m.spread_deg[1]:.2g} and {m.spread_deg[2]:.2g} deg about the two others",
        "weakly determined along [" + " ".join(f"{x:+.3f}" for x in weak) + "] in A",
        f"(std {std:.3g} m)",
        "type: hinge",
        f"the rejected frames form 2 contiguous runs of {long[0]} and {long[1]} frames",
        "model misfit, not outliers",
    ):
        assert part in text, (part, text)


def test_knee_without_rolling_has_no_misfit_note(rng: np.random.Generator) -> None:
    est = estimate_joint_fixed(_knee_session(rng, slide=0.0).T_w_c)
    assert est.inliers["a"].all()
    (text,) = joint_motion_warnings(est, "m")
    assert "near-hinge motion" in text and "misfit" not in text


def test_near_hinge_in_joint_yaml(rng: np.random.Generator, tmp_path: Path) -> None:
    """``acscal joint``'s stage writes the motion summary and the warning; it loads back."""
    knee = _knee_session(rng, n=200)
    poses = tmp_path / "knee.tum"
    write_tum(poses, np.arange(200) / 30.0, knee.T_w_c)
    run = run_joint(poses, None, tmp_path / "joint.yaml", JointConfig(length_unit="m"))
    art = JointArtifact.load(tmp_path / "joint.yaml")
    motion = art.quality.motion["a"]
    assert motion.near_hinge and abs(motion.dominant_axis @ knee.axis_in_cam) > 0.999
    est = run.estimate
    np.testing.assert_allclose(motion.rotation_spread_deg, est.motion["a"].spread_deg)
    np.testing.assert_allclose(motion.other_axes, est.motion["a"].axes[1:])
    weak, std = weakest_direction(est.covariance_a)
    np.testing.assert_allclose(motion.weak_direction, weak)
    assert motion.weak_std == pytest.approx(std)
    assert motion.rotation_ratio == pytest.approx(est.motion["a"].ratio)
    assert any("near-hinge motion" in w for w in art.warnings)
    again = tmp_path / "again.yaml"
    art.save(again)
    reloaded = JointArtifact.load(again).quality.motion["a"].to_plain()
    assert to_plain(reloaded) == to_plain(motion.to_plain())

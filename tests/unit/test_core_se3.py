"""Rigid transforms, rotations and their conversions (acs_cli.core.se3)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from acs_cli.core import se3
from acs_cli.errors import InputError

# ----------------------------------------------------------------------------- strategies

_unit = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)


@st.composite
def quaternions(draw: st.DrawFn) -> np.ndarray:
    """Unit quaternions (x, y, z, w), any sign of w, not too close to w = 0."""
    q = np.array([draw(_unit) for _ in range(4)])
    n = np.linalg.norm(q)
    if n < 0.1 or abs(q[3]) / n < 1e-3:
        q = np.array([0.1, -0.2, 0.3, 0.9])
        n = np.linalg.norm(q)
    return q / n


@st.composite
def rotations(draw: st.DrawFn) -> np.ndarray:
    return np.asarray(se3.matrix_from_quat_xyzw(draw(quaternions()))[0])


@st.composite
def transforms(draw: st.DrawFn) -> np.ndarray:
    t = np.array([draw(st.floats(-100.0, 100.0)) for _ in range(3)])
    return np.asarray(se3.transforms_from_rt(draw(rotations()), t))


def _Rx(a: float) -> np.ndarray:
    c, s = np.cos(np.radians(a)), np.sin(np.radians(a))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _Ry(a: float) -> np.ndarray:
    c, s = np.cos(np.radians(a)), np.sin(np.radians(a))
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _Rz(a: float) -> np.ndarray:
    c, s = np.cos(np.radians(a)), np.sin(np.radians(a))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return np.asarray(se3.matrix_from_quat_xyzw(q / np.linalg.norm(q, axis=1, keepdims=True)))


def _random_transforms(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.asarray(se3.transforms_from_rt(_random_rotations(rng, n), rng.uniform(-5, 5, (n, 3))))


# ----------------------------------------------------------------------------- quaternions


def test_quaternion_order_is_xyzw() -> None:
    # 90 degrees about z: (x, y, z, w) = (0, 0, sin 45, cos 45); maps x to y
    s = np.sqrt(0.5)
    R = se3.matrix_from_quat_xyzw([0.0, 0.0, s, s])[0]
    np.testing.assert_allclose(R, _Rz(90.0), atol=1e-12)
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(se3.quat_xyzw_from_matrix(_Rx(90.0)), [s, 0, 0, s], atol=1e-12)
    np.testing.assert_allclose(se3.matrix_from_quat_xyzw([0, 0, 0, 1])[0], np.eye(3))


@given(quaternions())
def test_quaternion_round_trip(q: np.ndarray) -> None:
    R = se3.matrix_from_quat_xyzw(q)
    assert R.shape == (1, 3, 3)
    q2 = se3.quat_xyzw_from_matrix(R)
    assert q2.shape == (1, 4)
    assert q2[0, 3] >= 0.0  # acscal writes w >= 0
    np.testing.assert_allclose(q2[0], q * np.sign(q[3]), atol=1e-9)
    np.testing.assert_allclose(se3.matrix_from_quat_xyzw(q2), R, atol=1e-9)


def test_quaternion_stack_and_single_shapes(rng: np.random.Generator) -> None:
    R = _random_rotations(rng, 7)
    q = se3.quat_xyzw_from_matrix(R)
    assert q.shape == (7, 4)
    assert np.all(q[:, 3] >= 0)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(se3.matrix_from_quat_xyzw(q), R, atol=1e-12)
    assert se3.quat_xyzw_from_matrix(R[0]).shape == (4,)


def test_quaternion_norm_is_checked() -> None:
    # within the tolerance: normalised
    R = se3.matrix_from_quat_xyzw([0, 0, 0, 1.0005])
    np.testing.assert_allclose(R[0], np.eye(3), atol=1e-12)
    with pytest.raises(InputError, match="norm"):
        se3.matrix_from_quat_xyzw([[0, 0, 0, 1], [0, 0, 0, 2.0]])
    with pytest.raises(InputError, match=r"\(n, 4\)"):
        se3.matrix_from_quat_xyzw([0, 0, 1])
    with pytest.raises(InputError, match="NaN"):
        se3.matrix_from_quat_xyzw([0, 0, np.nan, 1])


# ----------------------------------------------------------------------------- roll, pitch, yaw


def test_rpy_convention_is_zyx() -> None:
    roll, pitch, yaw = 10.0, -25.0, 130.0
    expected = _Rz(yaw) @ _Ry(pitch) @ _Rx(roll)
    np.testing.assert_allclose(se3.matrix_from_rpy_deg([roll, pitch, yaw]), expected, atol=1e-12)
    np.testing.assert_allclose(se3.rpy_deg_from_matrix(expected), [roll, pitch, yaw], atol=1e-10)
    # a pure yaw is a rotation about z, a pure roll about x
    np.testing.assert_allclose(se3.matrix_from_rpy_deg([0, 0, 90]), _Rz(90), atol=1e-12)
    np.testing.assert_allclose(se3.matrix_from_rpy_deg([90, 0, 0]), _Rx(90), atol=1e-12)


@given(
    st.floats(-179.9, 179.9),
    st.floats(-89.5, 89.5),
    st.floats(-179.9, 179.9),
)
def test_rpy_round_trip(roll: float, pitch: float, yaw: float) -> None:
    R = se3.matrix_from_rpy_deg([roll, pitch, yaw])
    np.testing.assert_allclose(R, _Rz(yaw) @ _Ry(pitch) @ _Rx(roll), atol=1e-12)
    np.testing.assert_allclose(se3.rpy_deg_from_matrix(R), [roll, pitch, yaw], atol=1e-7)


@given(rotations())
def test_matrix_rpy_matrix_round_trip(R: np.ndarray) -> None:
    assume(abs(R[2, 0]) < 1.0 - 1e-6)  # away from gimbal lock (pitch = +-90 deg)
    rpy = se3.rpy_deg_from_matrix(R)
    assert rpy.shape == (3,)
    assert -90.0 <= rpy[1] <= 90.0
    np.testing.assert_allclose(se3.matrix_from_rpy_deg(rpy), R, atol=1e-9)


@pytest.mark.parametrize("pitch", [90.0, -90.0])
def test_rpy_at_gimbal_lock(pitch: float) -> None:
    R = se3.matrix_from_rpy_deg([20.0, pitch, 50.0])
    rpy = se3.rpy_deg_from_matrix(R)
    assert rpy[1] == pytest.approx(pitch)
    np.testing.assert_allclose(se3.matrix_from_rpy_deg(rpy), R, atol=1e-9)


def test_rpy_stack_shapes(rng: np.random.Generator) -> None:
    R = _random_rotations(rng, 5)
    rpy = se3.rpy_deg_from_matrix(R)
    assert rpy.shape == (5, 3)
    back = se3.matrix_from_rpy_deg(rpy)
    assert back.shape == (5, 3, 3)
    np.testing.assert_allclose(back, R, atol=1e-9)
    assert se3.matrix_from_rpy_deg(np.zeros((2, 4, 3))).shape == (2, 4, 3, 3)


# ----------------------------------------------------------------------------- rotation vectors


@given(st.tuples(_unit, _unit, _unit), st.floats(0.0, np.pi - 1e-3))
def test_rotvec_round_trip(axis: tuple[float, float, float], angle: float) -> None:
    a = np.array(axis)
    if np.linalg.norm(a) < 1e-3:
        a = np.array([0.0, 0.0, 1.0])
    v = a / np.linalg.norm(a) * angle
    R = se3.matrix_from_rotvec(v)
    assert R.shape == (3, 3)
    # Rodrigues
    K = se3.skew(a / np.linalg.norm(a))
    np.testing.assert_allclose(
        R, np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K, atol=1e-12
    )
    np.testing.assert_allclose(se3.rotvec_from_matrix(R), v, atol=1e-8)
    assert se3.rotation_angle_deg(R) == pytest.approx(np.degrees(angle), abs=1e-5)


def test_rotvec_stack_shapes(rng: np.random.Generator) -> None:
    v = rng.normal(size=(6, 3))
    v *= (rng.uniform(0, 3.0, 6) / np.linalg.norm(v, axis=1))[:, None]
    R = se3.matrix_from_rotvec(v)
    assert R.shape == (6, 3, 3)
    np.testing.assert_allclose(se3.rotvec_from_matrix(R), v, atol=1e-10)
    np.testing.assert_allclose(
        se3.rotation_angle_deg(R), np.degrees(np.linalg.norm(v, axis=1)), atol=1e-6
    )


def test_skew_is_cross_product(rng: np.random.Generator) -> None:
    v, w = rng.normal(size=(2, 3))
    np.testing.assert_allclose(se3.skew(v) @ w, np.cross(v, w), atol=1e-12)
    V = rng.normal(size=(4, 3))
    S = se3.skew(V)
    assert S.shape == (4, 3, 3)
    np.testing.assert_allclose(S @ w, np.cross(V, w), atol=1e-12)
    np.testing.assert_allclose(S, -np.swapaxes(S, 1, 2))


# ----------------------------------------------------------------------------- transforms


@given(transforms())
def test_invert_transforms_single(T: np.ndarray) -> None:
    Ti = se3.invert_transforms(T)
    assert Ti.shape == (4, 4)
    np.testing.assert_allclose(T @ Ti, np.eye(4), atol=1e-9)
    np.testing.assert_allclose(Ti @ T, np.eye(4), atol=1e-9)
    np.testing.assert_allclose(Ti, np.linalg.inv(T), atol=1e-9)


def test_invert_transforms_stack(rng: np.random.Generator) -> None:
    T = _random_transforms(rng, 9)
    Ti = se3.invert_transforms(T)
    assert Ti.shape == (9, 4, 4)
    np.testing.assert_allclose(T @ Ti, np.broadcast_to(np.eye(4), (9, 4, 4)), atol=1e-12)
    np.testing.assert_allclose(Ti[:, 3], np.broadcast_to([0, 0, 0, 1.0], (9, 4)))
    # T_a_c = T_a_b @ T_b_c  =>  inv(T_a_c) = inv(T_b_c) @ inv(T_a_b)
    np.testing.assert_allclose(se3.invert_transforms(T[0] @ T[1]), Ti[1] @ Ti[0], atol=1e-12)


def test_transforms_from_rt(rng: np.random.Generator) -> None:
    R = _random_rotations(rng, 4)
    t = rng.normal(size=(4, 3))
    T = se3.transforms_from_rt(R, t)
    assert T.shape == (4, 4, 4)
    np.testing.assert_array_equal(T[:, :3, :3], R)
    np.testing.assert_array_equal(T[:, :3, 3], t)
    np.testing.assert_array_equal(T[:, 3], np.broadcast_to([0, 0, 0, 1.0], (4, 4)))
    assert se3.transforms_from_rt(R[0], t[0]).shape == (4, 4)
    with pytest.raises(InputError, match="4 rotations but 3 translations"):
        se3.transforms_from_rt(R, t[:3])


def test_transform_points(rng: np.random.Generator) -> None:
    T = _random_transforms(rng, 5)
    p = rng.normal(size=(5, 3))
    homo = np.concatenate([p, np.ones((5, 1))], axis=1)
    expected = np.einsum("nij,nj->ni", T, homo)[:, :3]
    # pairwise
    np.testing.assert_allclose(se3.transform_points(T, p), expected, atol=1e-12)
    # one transform, many points
    np.testing.assert_allclose(se3.transform_points(T[2], p), (T[2] @ homo.T).T[:, :3], atol=1e-12)
    # many transforms, one point
    np.testing.assert_allclose(
        se3.transform_points(T, p[1]), np.einsum("nij,j->ni", T, homo[1])[:, :3], atol=1e-12
    )
    # p_a = T_a_b p_b, p_b = T_b_a p_a
    pb = se3.transform_points(se3.invert_transforms(T), se3.transform_points(T, p))
    np.testing.assert_allclose(pb, p, atol=1e-12)


def test_rotate(rng: np.random.Generator) -> None:
    R = _random_rotations(rng, 6)
    v = rng.normal(size=3)
    out = se3.rotate(R, v)
    assert out.shape == (6, 3)
    np.testing.assert_allclose(out, np.einsum("nij,j->ni", R, v), atol=1e-12)
    assert se3.rotate(R[0], v).shape == (1, 3)
    np.testing.assert_allclose(se3.rotate(R[0], v)[0], R[0] @ v, atol=1e-12)


@pytest.mark.parametrize("k", [1, 3, 6])
def test_left_multiply(rng: np.random.Generator, k: int) -> None:
    A = rng.normal(size=(3, 3))
    M = rng.normal(size=(5, 3, k))
    out = se3.left_multiply(A, M)
    assert out.shape == (5, 3, k)
    np.testing.assert_allclose(out, np.einsum("ij,njk->nik", A, M), atol=1e-12)


# ----------------------------------------------------------------------------- projection


@given(rotations(), st.floats(0.05, 20.0), st.integers(0, 2**32 - 1))
def test_project_to_rotation_recovers_rotation_and_scale(
    R: np.ndarray, phi: float, seed: int
) -> None:
    eps = 1e-6
    noise = np.random.default_rng(seed).normal(scale=eps, size=(3, 3))
    Rp, s = se3.project_to_rotation(phi * R + phi * noise)
    assert Rp.shape == (3, 3) and s.shape == (3,)
    np.testing.assert_allclose(Rp.T @ Rp, np.eye(3), atol=1e-12)
    assert np.linalg.det(Rp) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(Rp, R, atol=20 * eps)
    np.testing.assert_allclose(s, phi, rtol=20 * eps)
    assert np.mean(s) == pytest.approx(phi, rel=20 * eps)


def test_project_to_rotation_exact_and_reflection(rng: np.random.Generator) -> None:
    R = _random_rotations(rng, 4)
    Rp, s = se3.project_to_rotation(2.5 * R)
    assert Rp.shape == (4, 3, 3) and s.shape == (4, 3)
    np.testing.assert_allclose(Rp, R, atol=1e-12)
    np.testing.assert_allclose(s, 2.5, atol=1e-12)
    # a reflection is turned into the nearest proper rotation
    F = R[0] @ np.diag([1.0, 1.0, -1.0])
    Rf, _ = se3.project_to_rotation(F)
    assert np.linalg.det(Rf) == pytest.approx(1.0)
    np.testing.assert_allclose(Rf.T @ Rf, np.eye(3), atol=1e-12)


def test_rotation_angle_deg() -> None:
    assert se3.rotation_angle_deg(np.eye(3)) == pytest.approx(0.0)
    np.testing.assert_allclose(
        se3.rotation_angle_deg(np.stack([_Rx(30), _Ry(-100), _Rz(180)])),
        [30, 100, 180],
        atol=1e-6,
    )


# ----------------------------------------------------------------------------- validators


def test_input_error_is_value_error() -> None:
    assert issubclass(InputError, ValueError)


@pytest.mark.parametrize(
    ("bad", "expected_shape", "got"),
    [
        (np.zeros((3, 4)), r"\(n, 3, 3\)", r"\(1, 3, 4\)"),
        (np.zeros((5, 3, 4)), r"\(n, 3, 3\)", r"\(5, 3, 4\)"),
        (np.zeros((2, 2, 3, 3)), r"\(n, 3, 3\)", r"\(2, 2, 3, 3\)"),
        (np.zeros(9), r"\(n, 3, 3\)", r"\(9,\)"),
    ],
)
def test_check_rotations_shape(bad: np.ndarray, expected_shape: str, got: str) -> None:
    with pytest.raises(InputError, match=f"my_R must have shape {expected_shape}, got {got}"):
        se3.check_rotations(bad, name="my_R")


def test_check_rotations_values(rng: np.random.Generator) -> None:
    R = _random_rotations(rng, 4)
    out = se3.check_rotations(R)
    np.testing.assert_array_equal(out, R)
    assert se3.check_rotations(R[0]).shape == (1, 3, 3)
    # tiny deviations are accepted
    se3.check_rotations(R + 1e-9)
    bad = R.copy()
    bad[2, 0, 0] = np.nan
    with pytest.raises(InputError, match="my_R contains NaN"):
        se3.check_rotations(bad, name="my_R")
    bad = R.copy()
    bad[1, 0, 0] = np.inf
    with pytest.raises(InputError, match="NaN or inf"):
        se3.check_rotations(bad, name="my_R")
    bad = R.copy()
    bad[2] *= 1.01
    with pytest.raises(InputError, match=r"my_R\[2\] is not a rotation matrix"):
        se3.check_rotations(bad, name="my_R")
    bad = R.copy()
    bad[3] = -bad[3]  # orthonormal, determinant -1
    with pytest.raises(InputError, match=r"my_R\[3\] is not a rotation matrix"):
        se3.check_rotations(bad, name="my_R")


def test_check_transforms(rng: np.random.Generator) -> None:
    T = _random_transforms(rng, 3)
    np.testing.assert_array_equal(se3.check_transforms(T), T)
    assert se3.check_transforms(T[0]).shape == (1, 4, 4)
    with pytest.raises(InputError, match=r"poses must have shape \(n, 4, 4\), got \(3, 3, 4\)"):
        se3.check_transforms(T[:, :3], name="poses")
    with pytest.raises(InputError, match=r"poses must have shape \(n, 4, 4\), got \(1, 4, 3\)"):
        se3.check_transforms(T[0][:, :3], name="poses")
    bad = T.copy()
    bad[1, 0, 3] = np.nan
    with pytest.raises(InputError, match="poses contains NaN"):
        se3.check_transforms(bad, name="poses")
    bad = T.copy()
    bad[0, 3, 0] = 0.5
    with pytest.raises(InputError, match=r"last row of \[0, 0, 0, 1\]"):
        se3.check_transforms(bad, name="poses")
    bad = T.copy()
    bad[2, :3, :3] *= 2.0
    with pytest.raises(InputError, match=r"poses rotation\[2\] is not a rotation matrix"):
        se3.check_transforms(bad, name="poses")


def test_check_vectors() -> None:
    assert se3.check_vectors([1.0, 2.0, 3.0]).shape == (1, 3)
    assert se3.check_vectors(np.zeros((5, 3))).shape == (5, 3)
    assert se3.check_vectors(np.zeros((5, 4)), dim=4).shape == (5, 4)
    with pytest.raises(InputError, match=r"pts must have shape \(n, 3\), got \(5, 2\)"):
        se3.check_vectors(np.zeros((5, 2)), name="pts")
    with pytest.raises(InputError, match=r"pts must have shape \(n, 3\), got \(2, 2, 3\)"):
        se3.check_vectors(np.zeros((2, 2, 3)), name="pts")
    with pytest.raises(InputError, match="pts contains NaN"):
        se3.check_vectors([[0.0, np.nan, 1.0]], name="pts")


# ------------------------------------------------- numpy conversions against scipy's Rotation


def test_conversions_agree_with_scipy_everywhere(rng: np.random.Generator) -> None:
    """se3's own Exp, Log, quaternions and roll-pitch-yaw (scipy.spatial costs every command
    half a second to import) give scipy's numbers: near the identity, near a half turn, on
    matrices that are not quite orthogonal."""
    axes = rng.normal(size=(300, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate(
        [
            np.geomspace(1e-12, 1e-2, 100),
            np.pi - np.geomspace(1e-12, 1e-2, 100),
            rng.uniform(0.0, np.pi, 100),
        ]
    )
    rv = axes * angles[:, None]
    R = Rotation.from_rotvec(rv).as_matrix()
    assert np.abs(se3.matrix_from_rotvec(rv) - R).max() < 1e-14
    R = np.concatenate([R, Rotation.random(500, random_state=1).as_matrix()])
    assert np.abs(se3.rotvec_from_matrix(R) - Rotation.from_matrix(R).as_rotvec()).max() < 1e-12
    q = Rotation.from_matrix(R).as_quat()
    q = np.where(q[:, 3:4] < 0, -q, q)
    assert np.abs(se3.quat_xyzw_from_matrix(R) - q).max() < 1e-14
    assert np.abs(se3.matrix_from_quat_xyzw(q) - R).max() < 1e-14
    M = R + 1e-3 * rng.normal(size=R.shape)  # not orthogonal: its nearest rotation's
    assert np.abs(se3.rotvec_from_matrix(M) - Rotation.from_matrix(M).as_rotvec()).max() < 1e-9
    ypr = Rotation.from_matrix(R).as_euler("ZYX", degrees=True)
    assert np.abs(se3.rpy_deg_from_matrix(R) - ypr[:, ::-1]).max() < 1e-9
    assert np.abs(se3.matrix_from_rpy_deg(ypr[:, ::-1]) - R).max() < 1e-14


@pytest.mark.parametrize("pitch", [90.0, -90.0])
def test_roll_pitch_yaw_at_gimbal_lock_puts_the_turn_in_yaw(pitch: float) -> None:
    R = se3.matrix_from_rpy_deg(np.array([20.0, pitch, 30.0]))
    rpy = se3.rpy_deg_from_matrix(R)
    assert rpy[0] == 0.0 and rpy[1] == pytest.approx(pitch)
    assert np.abs(se3.matrix_from_rpy_deg(rpy) - R).max() < 1e-12


def test_a_reflection_is_not_a_rotation() -> None:
    with pytest.raises(ValueError, match="non-positive determinant"):
        se3.rotvec_from_matrix(np.diag([1.0, 1.0, -1.0])[None])

"""Joint angles per frame: how the articulation bends over time (issue 22).

Two bodies ``p`` and ``q`` joined by a joint (``between = (p, q)``), their orientations
``R_w_p``, ``R_w_q`` ``(n, 3, 3)`` in one world (or each in a world of its own, mapped into
one by the calibration, :mod:`acs_cli.core.acs_trajectory`). ``q``'s orientation in ``p``'s
frame is ``R_p_q[i] = R_w_p[i]^T R_w_q[i]``; the articulation since the reference instant
``k``, in ``p``'s frame, is

    D[i] = R_p_q[i] R_p_q[k]^T        (D[k] = I)

A hinge of unit axis ``u_p`` (in ``p``) turns ``D[i] = Exp(theta[i] u_p)``: ``theta`` is the
hinge angle, ``q`` turning relative to ``p`` about ``u_p`` by the right-hand rule. With real
poses ``D[i]`` also turns off the axis: its swing-twist decomposition about ``u_p`` gives the
twist (the angle) and the swing (the off-axis wobble). A ball joint's ``D[i]`` is reported as a
rotation vector (in ``p``'s frame) and in an Euler sequence.

Uncertainty: the angle depends on the calibration only at second order (a small error of the
axis direction, or of the rotation that maps B's world into A's, changes the twist by the
square of the error), so its std comes from the poses' rotation noise: ``sigma`` per axis and
body, so ``sqrt(2) sigma`` on ``R_p_q[i]`` and ``2 sigma`` on ``D[i]`` (frame ``i`` and the
reference both noisy), 0 at the reference.

Every function is pure and vectorised over frames (numpy; scipy's ``Rotation`` only for Euler
sequences).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from acs_cli.core import se3
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError

__all__ = [
    "EULER_SEQUENCES",
    "BallAngles",
    "HingeAngles",
    "articulation_from_orientations",
    "ball_angles",
    "check_euler_sequence",
    "hinge_angle_range_deg",
    "hinge_angles",
]

#: Euler sequences a ball joint's angles may be reported in: intrinsic (upper case, each
#: rotation about the axes as turned by the previous ones) or extrinsic (lower case), any of
#: the twelve orders. Biomechanics (ISB) reports the hip and shoulder as ``ZXY``/``YXY``-like
#: intrinsic sequences of the proximal segment's axes.
EULER_SEQUENCES = tuple(
    s
    for order in (
        "XYZ",
        "XZY",
        "YXZ",
        "YZX",
        "ZXY",
        "ZYX",
        "XYX",
        "XZX",
        "YXY",
        "YZY",
        "ZXZ",
        "ZYZ",
    )
    for s in (order, order.lower())
)


def check_euler_sequence(sequence: str, option: str = "") -> None:
    """Refuse a sequence not in :data:`EULER_SEQUENCES` (``InputError``; ``option`` names
    where it came from, e.g. ``"--euler "``)."""
    if sequence not in EULER_SEQUENCES:
        raise InputError(
            f"{option}{sequence!r} is not an Euler sequence: one of "
            f"{', '.join(EULER_SEQUENCES)} (upper case intrinsic, lower case extrinsic)"
        )


def articulation_from_orientations(
    R_w_p: FloatArray, R_w_q: FloatArray, reference: int
) -> FloatArray:
    """``D`` ``(n, 3, 3)``: ``q``'s rotation relative to ``p`` since the reference instant, in
    ``p``'s frame (module doc); ``D[reference]`` is the identity."""
    R_p_q = np.einsum("nji,njk->nik", R_w_p, R_w_q)
    return np.einsum("nij,kj->nik", R_p_q, R_p_q[reference])


@dataclass(frozen=True)
class HingeAngles:
    """A hinge's angle per frame (see :func:`hinge_angles`).

    Attributes
    ----------
    angle_deg : ndarray, shape (n,)
        About the axis, right-hand rule, 0 at the reference; continuous over frames (it may
        pass +-180 deg).
    angle_std_deg : ndarray, shape (n,)
        One sigma from the poses' rotation noise (0 at the reference).
    wobble_deg : ndarray, shape (n,)
        The rotation off the axis (the swing), deg.
    """

    angle_deg: FloatArray
    angle_std_deg: FloatArray
    wobble_deg: FloatArray

    @property
    def wobble_rms_deg(self) -> float:
        """The off-axis rotation's RMS over the frames, deg."""
        return float(np.sqrt(np.mean(self.wobble_deg**2)))


def hinge_angles(
    D: FloatArray, axis_p: FloatArray, sigma_rot_deg: float, reference: int
) -> HingeAngles:
    """The hinge angle of each articulation ``D`` ``(n, 3, 3)`` about ``axis_p`` ``(3,)``.

    The twist of ``D[i]`` about the axis (swing-twist decomposition of its quaternion
    ``(v, w)``: twist ``2 atan2(v . u, w)``), unwrapped over frames; the swing's angle is the
    wobble. ``sigma_rot_deg`` is each body's rotation noise per axis.

    Raises
    ------
    InputError
        An axis that is not a finite non-zero vector.
    """
    u = _direction(axis_p)
    twist = _twist(D, u)
    twist -= twist[reference]
    # the swing: D with the twist taken out, D Exp(-twist u)
    swing = D @ se3.matrix_from_rotvec(-twist[:, None] * u)
    wobble = np.linalg.norm(se3.rotvec_from_matrix(swing), axis=1)
    std = np.full(D.shape[0], 2.0 * float(sigma_rot_deg))
    std[reference] = 0.0
    return HingeAngles(np.degrees(twist), std, np.degrees(wobble))


def _direction(axis: FloatArray) -> FloatArray:
    """``axis`` ``(3,)`` as a unit vector; InputError when it is not a direction."""
    u = np.asarray(axis, dtype=float)
    norm = float(np.linalg.norm(u))
    if not (np.isfinite(norm) and norm > 0):
        raise InputError(f"the hinge axis {u.tolist()} is not a direction")
    return u / norm


def _twist(D: FloatArray, u: FloatArray) -> FloatArray:
    """The twist (rad) of each ``D`` ``(n, 3, 3)`` about the unit ``u``, unwrapped over the
    frames (swing-twist of its quaternion ``(v, w)``: ``2 atan2(v . u, w)``)."""
    q = se3.quat_xyzw_from_matrix(D)  # w >= 0
    return np.asarray(np.unwrap(2.0 * np.arctan2(q[:, :3] @ u, q[:, 3])))


def hinge_angle_range_deg(
    R_w_p: FloatArray, R_w_q: FloatArray, R_p_q0: FloatArray, axis_p: FloatArray
) -> tuple[float, float]:
    """The smallest and largest hinge angle over frames (deg), zero at the pose ``R_p_q0``.

    The angle of frame ``i`` is the twist about ``axis_p`` of ``R_p_q[i] R_p_q0^T`` (as
    :func:`hinge_angles`, with the rig's own relative rotation at the reference instant,
    ``R_p_q0``, as the zero rather than a measured one): ``q`` turning relative to ``p`` by
    the right-hand rule. A URDF revolute joint whose zero is that pose has its angle in this
    range over the recording (the limits of :func:`acs_cli.io.rig_export.urdf_from_rig`).

    Parameters
    ----------
    R_w_p, R_w_q : ndarray, shape (n, 3, 3)
        The two bodies' orientations at the frames, in one world (n >= 1).
    R_p_q0 : ndarray, shape (3, 3)
        ``q``'s orientation in ``p``'s frame at the zero.
    axis_p : ndarray, shape (3,)
        The hinge axis in ``p``'s frame.

    Returns
    -------
    (float, float)
        ``(lowest, highest)`` in degrees.

    Raises
    ------
    InputError
        No frame, or an axis that is not a direction.
    """
    if R_w_p.shape[0] == 0:
        raise InputError("a hinge's angle range needs at least one frame")
    R_p_q = np.einsum("nji,njk->nik", R_w_p, R_w_q)
    twist = np.degrees(_twist(np.einsum("nij,kj->nik", R_p_q, R_p_q0), _direction(axis_p)))
    # the unwrapping starts from the first frame's branch: put the range's middle within
    # half a turn of the zero
    twist -= 360.0 * np.round(0.5 * (float(twist.min()) + float(twist.max())) / 360.0)
    return float(twist.min()), float(twist.max())


@dataclass(frozen=True)
class BallAngles:
    """A ball joint's articulation per frame (see :func:`ball_angles`).

    Attributes
    ----------
    rotvec_deg, rotvec_std_deg : ndarray, shape (n, 3)
        ``D[i]`` as a rotation vector (axis x angle, deg) in ``p``'s frame, and its std.
    sequence : str
        The Euler sequence (:data:`EULER_SEQUENCES`).
    euler_deg, euler_std_deg : ndarray, shape (n, 3)
        ``D[i]`` in that sequence (deg), and the std of each angle (undefined, NaN, at the
        sequence's gimbal lock).
    """

    rotvec_deg: FloatArray
    rotvec_std_deg: FloatArray
    sequence: str
    euler_deg: FloatArray
    euler_std_deg: FloatArray


def _euler(D: FloatArray, sequence: str) -> FloatArray:
    from scipy.spatial.transform import Rotation  # lazily: only ball angles need it

    # scipy warns at gimbal lock and picks one split of the angles; the std says NaN there
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Gimbal lock", category=UserWarning)
        return np.asarray(Rotation.from_matrix(D).as_euler(sequence, degrees=False))


def ball_angles(
    D: FloatArray, sigma_rot_deg: float, reference: int, sequence: str = "ZXY"
) -> BallAngles:
    """A ball joint's articulation ``D`` ``(n, 3, 3)`` as rotation vectors and Euler angles.

    Stds: ``D[i]``'s noise is ``2 sigma`` per axis (module doc), a right perturbation; each
    Euler angle's std is its derivative along the three axes (central differences) times
    that. ``sigma_rot_deg`` is each body's rotation noise per axis; NaN when it is not known:
    every std is then NaN, but 0 at the reference.

    Raises
    ------
    InputError
        An unknown sequence.
    """
    check_euler_sequence(sequence)
    n = D.shape[0]
    s = np.radians(2.0 * float(sigma_rot_deg))
    rv = se3.rotvec_from_matrix(D)
    rv_std = np.full((n, 3), np.degrees(s))
    e = _euler(D, sequence)
    if np.isnan(s):  # no noise level (rig.yaml records none): no std, and no derivatives
        e_std = np.full((n, 3), np.nan)
    else:
        # central differences of the angles along each body axis of D (right perturbations)
        h = 1e-6
        J = np.empty((n, 3, 3))
        for a in range(3):
            step = np.zeros(3)
            step[a] = h
            plus = _euler(D @ se3.matrix_from_rotvec(step), sequence)
            minus = _euler(D @ se3.matrix_from_rotvec(-step), sequence)
            d = plus - minus
            d = (d + np.pi) % (2.0 * np.pi) - np.pi  # across the +-180 deg seam
            J[:, :, a] = d / (2.0 * h)
        e_std = s * np.sqrt(np.sum(J**2, axis=2))
        bad = ~np.all(np.isfinite(J), axis=(1, 2)) | (np.max(np.abs(J), axis=(1, 2)) > 1e3)
        e_std[bad] = np.nan
    rv_std[reference] = 0.0
    e_std[reference] = 0.0
    return BallAngles(np.degrees(rv), rv_std, sequence, np.degrees(e), np.degrees(e_std))
